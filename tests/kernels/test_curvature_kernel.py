"""First-order curvature kernel (meshshade.kernels.curvature) against mpmath references, closed forms,
docs/physics.md §11 tables and the exact sphere, cylinder and spherical-cavity solutions.

References: tests/data/curvature_aux_reference.csv and curvature_coefficients_reference.csv, written offline
by tools/references/precompute_curvature_references.py (mpmath quadrature of the t-integrals of
docs/physics.md §7.2 at 40-50 digits; provenance in the CSV headers).
Tables quoted from docs/physics.md §11.3, §11.6, §11.7 (skin test case
sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3: sigma_t' = 1.01 /mm, alpha' = 1/1.01); lengths in mm are
converted with rho_opt = 1.01 rho_mm and C_mm = C_opt/1.01.

The exact solution for the *concave* side (medium outside a spherical cavity) is not in the package; it is
implemented here (``_cavity_profile``) from the exterior Green's function, by the ratio recurrences of
docs/physics.md §5.4, and checked against a brute-force mpmath evaluation of the same series (slow test).
"""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import special

from meshshade.kernels import curvature as cv
from meshshade.kernels.curvature import (CurvatureTable, aux_integral, aux_integral_drho_over_rho,
                                         curvature_coefficients, curvature_factor, curvature_profile, curvature_ratios,
                                         curvature_relative_coefficient, curvature_validity)
from meshshade.kernels.cylinder import cylinder_exact_profile_geodesic
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.optics import diffusion_params
from meshshade.kernels.sphere import sphere_series_profile

EPS = np.finfo(np.float64).eps
ST = 1.01
SKIN = {"albedo_prime": 1.0 / 1.01, "eta": 1.3}
MATERIALS = {  # (albedo_prime, eta) for sigma_s', sigma_a [1/mm] of Jensen 2001 / docs/physics.md §11.2
    "skin": (1.0 / 1.01, 1.3),
    "skin_eta1.0": (1.0 / 1.01, 1.0),
    "skin_eta2.0": (1.0 / 1.01, 2.0),
    "marble_R": (2.19 / (2.19 + 0.0021), 1.3),
    "potato_B": (0.55 / (0.55 + 0.12), 1.3),
    "ketchup_B": (0.03 / (0.03 + 1.45), 1.3),
    "albedo1": (1.0, 1.3),
}


def _read(reference_csv, name):
    """Rows of tests/data/<name> through the shared loader (it checks the generator's sha256)."""
    header, rows = reference_csv(name)
    assert header["generator"] == "tools/references/precompute_curvature_references.py"
    assert header["dps"].startswith("40 ")
    return rows


@pytest.fixture(scope="module")
def aux_rows(reference_csv):
    return _read(reference_csv, "curvature_aux_reference.csv")


@pytest.fixture(scope="module")
def coef_rows(reference_csv):
    return _read(reference_csv, "curvature_coefficients_reference.csv")


# --------------------------------------------------------------------------------------------------
# reference data
# --------------------------------------------------------------------------------------------------
def test_reference_grid_covers_the_requested_points(aux_rows):
    rho = {float(r["rho"]) for r in aux_rows}
    h = {float(r["h"]) for r in aux_rows}
    mu = {float(r["mu"]) for r in aux_rows}
    assert {0.0, 1e-6, 1e-3, 0.1, 1.0, 5.0, 50.0} <= rho
    assert 0.0 in h and 1e-3 in h and len(h) >= 5  # h = 0 (rho > 0 only), small, z_v values
    assert mu == {1e-5, 0.17, 1.0, 3.0}
    assert not any(float(r["rho"]) == 0 and float(r["h"]) == 0 for r in aux_rows)
    assert max(float(r["rel_err_est"]) for r in aux_rows) <= 1e-25
    assert sum(bool(r["closed_form_checked"]) for r in aux_rows) >= 60


def _aux_tol(rho, h, mu):
    """1.5e-15 for the quadrature itself plus the conditioning of e^{-mu d}: d = hypot(rho, h) is rounded
    (<= eps/2 relative), and the result inherits that as mu d eps (measured 2.2e-14 at mu d = 60)."""
    return 3e-15 + 2.0 * EPS * mu * math.hypot(rho, h)


def test_aux_integral_matches_mpmath(aux_rows):
    n = 0
    for row in aux_rows:
        rho, h, mu = float(row["rho"]), float(row["h"]), float(row["mu"])
        ref_i, ref_j = float(row["I"]), float(row["J"])
        got_i, got_j = aux_integral(rho, h, mu), aux_integral_drho_over_rho(rho, h, mu)
        if ref_i < 1e-300:  # mu d = 900: the reference is below the float64 range
            assert got_i == 0.0 and got_j == 0.0
            continue
        tol = _aux_tol(rho, h, mu)
        assert abs(got_i / ref_i - 1) <= tol, (rho, h, mu, got_i, ref_i)
        assert abs(got_j / ref_j - 1) <= tol, (rho, h, mu, got_j, ref_j)
        n += 1
    assert n >= 250


def test_aux_integral_vectorised_equals_scalar(aux_rows):
    rho = np.array([float(r["rho"]) for r in aux_rows])
    h = np.array([float(r["h"]) for r in aux_rows])
    mu = np.array([float(r["mu"]) for r in aux_rows])
    vec = aux_integral(rho, h, mu)
    np.testing.assert_array_equal(vec, [aux_integral(a, b, c) for a, b, c in zip(rho, h, mu)])
    grid = aux_integral_drho_over_rho(rho[:, None], 4.4, np.array([0.0, 0.17, 3.0]))
    assert grid.shape == (rho.size, 3) and grid.dtype == np.float64


def test_coefficients_match_mpmath(coef_rows):
    """A, B and the ratios a, b against the mpmath evaluation of docs/physics.md eqs. (49)-(50). A and B are each
    compared relative to |A| + |B| (B changes sign near rho ~ 1, so a plain relative error is meaningless
    there). Tolerance 2e-13: the bracket of A + B cancels ~2 digits at rho = 50-200 (g(d_r) - g(d_v))."""
    assert len(coef_rows) >= 70
    worst = 0.0
    for row in coef_rows:
        a_p, eta, rho = float(row["albedo_prime"]), float(row["eta"]), float(row["rho_opt"])
        A, B = curvature_coefficients(rho, albedo_prime=a_p, eta=eta)
        ra, rb = curvature_ratios(rho, albedo_prime=a_p, eta=eta)
        refA, refB, refa, refb = (float(row[k]) for k in ("A", "B", "a_ratio", "b_ratio"))
        scale, rscale = abs(refA) + abs(refB), abs(refa) + abs(refb)
        err = max(abs(A - refA) / scale, abs(B - refB) / scale, abs(ra - refa) / rscale, abs(rb - refb) / rscale)
        worst = max(worst, err)
        assert err <= 2e-13, (row["case"], rho, err)
    assert worst > 0  # the comparison is live


def test_relative_coefficient_is_sum_of_ratios(coef_rows):
    for row in coef_rows[::7]:
        a_p, eta, rho = float(row["albedo_prime"]), float(row["eta"]), float(row["rho_opt"])
        C = curvature_relative_coefficient(rho, albedo_prime=a_p, eta=eta)
        ref = float(row["a_ratio"]) + float(row["b_ratio"])
        assert abs(C - ref) <= 2e-13 * (abs(float(row["a_ratio"])) + abs(float(row["b_ratio"])))


# --------------------------------------------------------------------------------------------------
# closed forms and limits of the auxiliary integral
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mu", [1e-5, 0.17, 1.0, 3.0])
def test_aux_integral_h0_is_bessel_k(mu):
    """scipy's k0/k1 are themselves good to ~1e-15; tolerance as for the mpmath comparison."""
    rho = np.geomspace(1e-6, 100, 41)
    tol = 1e-14 + 2 * EPS * mu * rho
    assert np.all(np.abs(aux_integral(rho, 0.0, mu) / special.k0(mu * rho) - 1) <= tol)
    assert np.all(np.abs(aux_integral_drho_over_rho(rho, 0.0, mu) / (-mu * special.k1(mu * rho) / rho) - 1) <= tol)


@pytest.mark.parametrize("mu", [1e-5, 0.17, 1.0, 3.0])
def test_aux_integral_at_rho0_is_exponential_integral(mu):
    h = np.geomspace(1e-4, 50, 31)
    assert np.all(np.abs(aux_integral(0.0, h, mu) / special.exp1(mu * h) - 1) <= 1e-14 + 2 * EPS * mu * h)
    j0 = aux_integral_drho_over_rho(0.0, h, mu)
    # rho -> 0 is an ordinary point: I(rho, h) = I(0, h) + J(0, h) rho^2/2 + O(rho^4), no 1/rho
    rho = 1e-5 * h
    step = aux_integral(rho, h, mu) - aux_integral(0.0, h, mu)
    i0 = aux_integral(0.0, h, mu)
    assert np.all(np.abs(step - j0 * rho**2 / 2) <= (1e-14 + 4 * EPS * mu * h) * i0)  # step ~ 2.5e-11
    np.testing.assert_allclose(j0, -(mu * special.expn(2, mu * h) / h + special.expn(3, mu * h) / h**2),
                               rtol=1e-13)


def test_aux_integral_mu0_limits():
    """mu = 0: I diverges (returned as +inf); (1/rho) dI/drho = -1/(d (d + h)) exactly; I ~ -ln(mu) as mu -> 0
    while mu^2 I -> 0, which is the limit the coefficients use."""
    rho, h = np.array([0.0, 0.3, 1.0, 7.0, 40.0]), 4.4
    assert np.all(aux_integral(rho, h, 0.0) == np.inf)
    d = np.hypot(rho, h)
    np.testing.assert_allclose(aux_integral_drho_over_rho(rho, h, 0.0), -1.0 / (d * (d + h)), rtol=1e-14)
    mus = np.array([1e-4, 1e-6, 1e-8, 1e-10])
    i = aux_integral(1.0, h, mus)
    # logarithmic divergence: I = -gamma - ln(mu (d + h)/2) + O(mu (d + h))
    d1 = math.hypot(1.0, h)
    assert np.all(np.abs(np.diff(i) - np.log(100.0)) <= 2 * mus[:-1] * (d1 + h))
    assert abs(i[-1] - (-np.euler_gamma - np.log(mus[-1] * (d1 + h) / 2))) <= 1e-9 * i[-1]
    assert np.all(np.diff(mus**2 * i) < 0) and mus[-1] ** 2 * i[-1] < 1e-17
    # below mu (d + h) = 1e-20 the closed forms are used: continuous across the switch
    lo, hi = aux_integral(1.0, h, [0.99e-20 / (d1 + h), 1.01e-20 / (d1 + h)])
    assert abs(lo - hi - np.log(1.01 / 0.99)) <= 1e-14 * lo


def test_aux_integral_edges_are_inf_or_zero_never_nan():
    assert aux_integral(0.0, 0.0, 0.5) == np.inf
    assert aux_integral_drho_over_rho(0.0, 0.0, 0.5) == -np.inf
    far = aux_integral(np.array([1e3, 1e5]), np.array([0.0, 4.4]), 3.0)
    assert np.all(far == 0.0)
    far_j = aux_integral_drho_over_rho(np.array([1e3, 1e5]), 4.4, 3.0)
    assert np.all(far_j == 0.0)
    with pytest.raises(ValueError):
        aux_integral(-1.0, 1.0, 0.1)
    with pytest.raises(ValueError):
        aux_integral(1.0, np.nan, 0.1)


def test_aux_integral_height_derivative_is_minus_E():
    """dI/dh = -E(rho, h) = -exp(-mu d)/d (docs/physics.md §7.2), by a central difference."""
    rho, h, mu, step = 1.3, 2.0, 0.4, 1e-4
    fd = (aux_integral(rho, h + step, mu) - aux_integral(rho, h - step, mu)) / (2 * step)
    d = math.hypot(rho, h)
    assert abs(fd + math.exp(-mu * d) / d) <= 1e-8


@given(rho=st.floats(0.0, 1e4), h=st.floats(0.0, 1e4), mu=st.floats(0.0, 10.0))
def test_aux_integral_finite_and_signed(rho, h, mu):
    i = aux_integral(rho, h, mu)
    j = aux_integral_drho_over_rho(rho, h, mu)
    if rho == 0 and h == 0:
        assert i == np.inf and j == -np.inf
        return
    assert not np.isnan(i) and i >= 0 and (np.isfinite(i) or mu == 0)
    # J ~ -1/(d (d + h)) overflows float64 (correctly) only where d = hypot(rho, h) < 1e-154
    assert j <= 0 and (np.isfinite(j) or math.hypot(rho, h) < 1e-154)


# --------------------------------------------------------------------------------------------------
# structure of the kernel
# --------------------------------------------------------------------------------------------------
RHO = np.concatenate([[0.0, 1e-8, 1e-3], np.geomspace(0.01, 3000, 300)])


@pytest.mark.parametrize("name", list(MATERIALS))
def test_curvature_profile_flat_is_the_dipole(name):
    """k1 = k2 = 0: the planar dipole (same closed form; at most a few ulp from numpy's exp/pow)."""
    a_p, eta = MATERIALS[name]
    phi = np.linspace(0, 7, RHO.size)
    R = curvature_profile(RHO, phi, k1_opt=0.0, k2_opt=0.0, albedo_prime=a_p, eta=eta)
    D = dipole_profile(RHO, albedo_prime=a_p, eta=eta)
    pos = D > 0
    assert np.all(R[~pos] == 0)
    assert np.max(np.abs(R[pos] / D[pos] - 1)) <= 1e-15


def test_entry_point_has_no_direction_dependence():
    # A(0) = (A + B) - B from two different formulas; A + B at rho = 0 is a sum of terms ~30x larger than A
    A, B = curvature_coefficients(0.0, **SKIN)
    assert abs(A - B) <= 1e-13 * abs(A)
    for name, (a_p, eta) in MATERIALS.items():
        a, b = curvature_ratios(0.0, albedo_prime=a_p, eta=eta)
        assert abs(a - b) <= 1e-13 * abs(a), name
    phi = np.linspace(0, 2 * np.pi, 9)
    R = curvature_profile(0.0, phi, k1_opt=0.2, k2_opt=-0.1, **SKIN)
    assert np.ptp(R) <= 1e-14 * R[0]  # a(0) - b(0) from the table: interpolation residue (< 1e-11 of a(0))


@given(rho=st.floats(0.0, 60.0), phi=st.floats(-10.0, 10.0), k1=st.floats(-0.3, 0.3), k2=st.floats(-0.3, 0.3))
def test_curvature_profile_swap_symmetry(rho, phi, k1, k2):
    """(k1, k2, phi) and (k2, k1, phi + pi/2) describe the same surface."""
    for policy in ("soft", "exp", "clamp"):
        r1 = curvature_profile(rho, phi, k1_opt=k1, k2_opt=k2, **SKIN, policy=policy)
        r2 = curvature_profile(rho, phi + np.pi / 2, k1_opt=k2, k2_opt=k1, **SKIN, policy=policy)
        assert abs(r1 - r2) <= 1e-13 * abs(r1) + 1e-300


def test_curvature_profile_first_order_matches_coefficients():
    """d R/d k at k = 0 is alpha' [cos^2 phi A + sin^2 phi B] for k1 (central difference, every policy)."""
    rho = np.array([0.0, 0.5, 1.0, 3.0, 10.0, 30.0])
    phi = 0.4
    A, B = curvature_coefficients(rho, **SKIN)
    want = SKIN["albedo_prime"] * (np.cos(phi) ** 2 * A + np.sin(phi) ** 2 * B)
    # step 1e-6: rounding costs eps_mach R_d/step ~ 1e-10 R_d, i.e. 1.4e-7 of the derivative at rho = 0 where
    # a(0) = 7e-4; the O(step^2 a^3) truncation is < 1e-10
    step = 1e-6
    for policy in ("soft", "exp", "clamp"):
        up = curvature_profile(rho, phi, k1_opt=step, k2_opt=0.0, **SKIN, policy=policy)
        dn = curvature_profile(rho, phi, k1_opt=-step, k2_opt=0.0, **SKIN, policy=policy)
        np.testing.assert_allclose((up - dn) / (2 * step), want, rtol=3e-7)


def test_appendix_setting_laplace_limit():
    """docs/physics.md §7.3, eq. (48) (z_b = 0) at mu -> 0 reproduces the exact Poisson-kernel result of a ball:
    A0 + B0 = a^2 (2 rho^2 - a^2)/(4 pi d^5), a = z_r = 1. At mu = 0 the kernel uses mu^2 I = 0 (its limit);
    for small mu > 0 the error is O(mu^2 ln(1/mu))."""
    rho = np.array([0.0, 0.3, 0.7071, 1.0, 2.0, 5.0, 20.0])
    d = np.hypot(rho, 1.0)
    want = (2 * rho**2 - 1) / d**5  # 4 pi (A0 + B0), a = 1
    for mu, tol in ((0.0, 1e-14), (1e-4, 3e-7), (1e-6, 4e-11)):
        got = np.array([sum(cv._coeffs_scaled(r, mu, 1.0, 0.0)[:2]) * math.exp(-mu * r) for r in rho])
        assert np.max(np.abs(got - want)) <= tol * np.max(np.abs(want)), mu


def test_coefficients_continuous_at_albedo_one():
    """alpha' -> 1: the ratios approach their mu = 0 values; the difference is O(mu^2 (rho^2 + z_v^2))
    (from g, p and mu^2 I ~ mu^2 ln(1/mu)), 1e-9 here at mu = 1.7e-7."""
    rho = np.array([0.0, 0.5, 2.0, 10.0, 50.0])
    a1, b1 = curvature_ratios(rho, albedo_prime=1.0, eta=1.3)
    a2, b2 = curvature_ratios(rho, albedo_prime=1.0 - 1e-14, eta=1.3)
    scale = np.abs(a1) + np.abs(b1)
    assert np.all(np.abs(a1 - a2) <= 1e-9 * scale) and np.all(np.abs(b1 - b2) <= 1e-9 * scale)


def test_ratios_finite_where_coefficients_underflow():
    rho = np.array([500.0, 5e3, 4e4])
    A, B = curvature_coefficients(rho, albedo_prime=0.3, eta=1.3)  # mu = 1.45: e^{-mu rho} underflows
    assert np.all(np.abs(A) < 1e-300) and np.all(np.abs(B) < 1e-300) and A[1] == 0 and B[2] == 0
    a, b = curvature_ratios(rho, albedo_prime=0.3, eta=1.3)
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(a > 0)


def test_curvature_profile_broadcasts():
    rho = np.linspace(0, 20, 7)[:, None]
    phi = np.array([0.0, 0.5, 1.0])
    R = curvature_profile(rho, phi, k1_opt=0.05, k2_opt=np.array([0.0, -0.05, 0.05]), **SKIN)
    assert R.shape == (7, 3) and R.dtype == np.float64
    for i in range(7):
        for j in range(3):
            one = curvature_profile(rho[i, 0], phi[j], k1_opt=0.05, k2_opt=[0.0, -0.05, 0.05][j], **SKIN)
            assert abs(one - R[i, j]) <= 1e-15 * R[i, j]
    mats = curvature_profile(2.0, 0.0, k1_opt=0.1, k2_opt=0.1, albedo_prime=np.array([0.9, 0.99, 1.0]), eta=1.3)
    for m, a_p in zip(mats, (0.9, 0.99, 1.0)):
        assert m == curvature_profile(2.0, 0.0, k1_opt=0.1, k2_opt=0.1, albedo_prime=a_p, eta=1.3)


def test_curvature_profile_many_materials_uses_direct_quadrature():
    a_p = np.linspace(0.5, 0.999, 12)  # > 8 distinct materials: coefficients by direct quadrature
    rho = np.full(12, 3.0)
    many = curvature_profile(rho, 0.3, k1_opt=0.1, k2_opt=-0.02, albedo_prime=a_p, eta=1.3)
    one = [curvature_profile(3.0, 0.3, k1_opt=0.1, k2_opt=-0.02, albedo_prime=a, eta=1.3) for a in a_p]
    np.testing.assert_allclose(many, one, rtol=1e-11)


def test_curvature_profile_rejects_bad_input():
    with pytest.raises(ValueError):
        curvature_profile(-1.0, 0.0, k1_opt=0.1, k2_opt=0.0, **SKIN)
    with pytest.raises(ValueError):
        curvature_profile(1.0, np.nan, k1_opt=0.1, k2_opt=0.0, **SKIN)
    with pytest.raises(ValueError):
        curvature_profile(1.0, 0.0, k1_opt=np.inf, k2_opt=0.0, **SKIN)
    with pytest.raises(ValueError):
        curvature_profile(1.0, 0.0, k1_opt=0.1, k2_opt=0.0, **SKIN, policy="linear")
    with pytest.raises(ValueError):
        curvature_profile(1.0, 0.0, k1_opt=0.1, k2_opt=0.0, albedo_prime=1.5, eta=1.3)
    with pytest.raises(ValueError, match="reduce angles"):
        curvature_profile(1.0, 1e6, k1_opt=0.1, k2_opt=0.0, **SKIN)
    with pytest.raises(ValueError, match="exactly one"):
        curvature_profile(1.0, 0.0, cos2phi=1.0, k1_opt=0.1, k2_opt=0.0, **SKIN)


def test_kernel_cosine_matches_numpy():
    """The branch-free cos used for cos(2 phi) in the compiled loop: within 2.3e-16 of numpy over its domain."""
    x = np.concatenate([np.linspace(-8e5, 8e5, 200_001), np.linspace(-10, 10, 100_001),
                        np.arange(-64, 65) * np.pi / 4])
    out = np.empty_like(x)
    cv._cos_many(x, out)
    assert np.max(np.abs(out - np.cos(x))) <= 2.3e-16


# --------------------------------------------------------------------------------------------------
# docs/physics.md §11.6 tables (skin test case, mm)
# --------------------------------------------------------------------------------------------------
def _digits_tol(quoted: str) -> float:
    """Half a unit in the last printed digit of a docs/physics.md §11 entry."""
    frac = quoted.split(".")[1] if "." in quoted else ""
    return 0.5 * 10.0 ** (-len(frac))


@pytest.mark.parametrize("s_mm, quoted", [("0", "0.00148"), ("0.1", "0.0208"), ("1", "1.127"), ("2", "2.231"),
                                          ("5", "3.384"), ("10", "5.807"), ("20", "15.89")])
def test_relative_coefficient_physics_md_e3_table(s_mm, quoted):
    """docs/physics.md §11.6: C(s) = alpha'(A+B)/R_d in mm, C_mm = C_opt/sigma_t'."""
    C = curvature_relative_coefficient(float(s_mm) * ST, **SKIN) / ST
    assert abs(C - float(quoted)) <= _digits_tol(quoted), (s_mm, C)


@pytest.mark.parametrize("s_mm, quoted", [(0.1, 0.020787), (1.0, 1.127472), (5.0, 3.383681), (20.0, 15.8856)])
def test_relative_coefficient_physics_md_c_table(s_mm, quoted):
    """docs/physics.md §11.3, row "C(s), first-order theory" (6-7 digits)."""
    C = curvature_relative_coefficient(s_mm * ST, **SKIN) / ST
    assert abs(C - quoted) <= _digits_tol(repr(quoted))


@pytest.mark.parametrize("rho_mm, qa, qb", [(1, "1.129", "-0.0015"), (5, "3.80", "-0.42"), (20, "19.1", "-3.2")])
def test_ratios_physics_md_e3_table(rho_mm, qa, qb):
    """docs/physics.md §11.6: alpha'A/R_d and alpha'B/R_d in mm."""
    a, b = curvature_ratios(rho_mm * ST, **SKIN)
    assert abs(a / ST - float(qa)) <= _digits_tol(qa)
    assert abs(b / ST - float(qb)) <= _digits_tol(qb)


# --------------------------------------------------------------------------------------------------
# table (fast path)
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(MATERIALS))
def test_curvature_table_interpolation_error(name):
    """max(|a_tab - a|, |b_tab - b|)/(|a| + |b|) < 1e-10 (measured 1e-12 .. 3e-11) against direct quadrature."""
    a_p, eta = MATERIALS[name]
    table = CurvatureTable(a_p, eta, 400.0)
    assert table.max_interpolation_error(n=3000, seed=1) < 1e-10


def test_curvature_table_continuous_at_its_edge():
    table = CurvatureTable(*MATERIALS["skin"], 30.0)
    edge = (table.n_intervals / 16) ** 2
    rho = np.array([np.nextafter(edge, 0), edge, edge * 1.001])
    ta, tb = table.ratios(rho)
    da, db = curvature_ratios(rho, **SKIN)
    np.testing.assert_allclose(ta, da, rtol=1e-11)
    np.testing.assert_allclose(tb, db, rtol=1e-11)


def test_curvature_table_profile_equals_direct_coefficients():
    table = CurvatureTable(*MATERIALS["skin"], 100.0)
    rng = np.random.default_rng(3)
    rho = rng.random(500) * 120  # part beyond the table
    phi = rng.random(500) * 7
    k1, k2 = rng.normal(size=500) * 0.05, rng.normal(size=500) * 0.05
    R = table.profile(rho, phi, k1_opt=k1, k2_opt=k2, policy="exp")
    a, b = curvature_ratios(rho, **SKIN)
    c2 = np.cos(2 * phi)
    delta = 0.5 * (k1 + k2) * (a + b) + 0.5 * (k1 - k2) * c2 * (a - b)
    want = dipole_profile(rho, **SKIN) * np.exp(delta)
    np.testing.assert_allclose(R, want, rtol=1e-10)
    # the kernel's own cos(2 phi) is within 2e-16 of numpy's
    np.testing.assert_allclose(table.profile(rho, cos2phi=c2, k1_opt=k1, k2_opt=k2, policy="exp"), R, rtol=1e-13)
    # curvature_profile tabulates up to max(rho) = 120 (the table above: 100, direct beyond)
    np.testing.assert_allclose(curvature_profile(rho, cos2phi=c2, k1_opt=k1, k2_opt=k2, policy="exp", **SKIN), R,
                               rtol=1e-10)
    # the default "soft" policy saturates delta: exp(delta / sqrt(1 + (delta / 2)^2)) (module constant DELTA_SAT
    # = 2, written out here so that a changed constant fails); |delta| reaches ~10 here, deep in saturation
    assert np.max(np.abs(delta)) > 5
    soft = dipole_profile(rho, **SKIN) * np.exp(delta / np.sqrt(1 + (delta / 2.0) ** 2))
    np.testing.assert_allclose(table.profile(rho, phi, k1_opt=k1, k2_opt=k2), soft, rtol=1e-10)
    np.testing.assert_allclose(curvature_profile(rho, phi, k1_opt=k1, k2_opt=k2, **SKIN), soft, rtol=1e-10)
    assert "CurvatureTable(" in repr(table) and "intervals=" in repr(table)


# --------------------------------------------------------------------------------------------------
# policy
# --------------------------------------------------------------------------------------------------
def test_every_policy_is_tested():
    """The policy tests below name the policies literally: a new policy must be added to them."""
    assert set(cv.POLICIES) == {"soft", "exp", "clamp"}


@pytest.mark.parametrize("policy", ["soft", "exp", "clamp"])
def test_curvature_factor_is_identity_to_first_order(policy):
    d = np.array([-1e-4, 0.0, 1e-4])
    f = curvature_factor(d, policy)
    assert f[1] == 1.0
    np.testing.assert_allclose(f, 1 + d, atol=1e-8)
    # far outside first order: exp(-50) (exp), 0 (clamp), exp(-50/sqrt(1 + 25^2)) = exp(-1.998402...) (soft)
    far = {"exp": math.exp(-50.0), "clamp": 0.0, "soft": math.exp(-50.0 / math.sqrt(626.0))}[policy]
    assert curvature_factor(-50.0, policy) == pytest.approx(far, rel=1e-14, abs=0.0)
    assert np.isfinite(curvature_factor(1e6, policy))


def test_soft_policy_stays_within_e_to_the_two_of_the_dipole():
    """The "soft" policy (the default of every bake): f = exp(delta/sqrt(1 + (delta/2)^2)).
    The exponent is odd, increasing
    and bounded by 2 in magnitude, so f lies in [e^-2, e^2] for every delta and tends to e^{+-2} as delta -> +-inf:
    at delta = 1e6 the exponent is 2/sqrt(1 + 4e-12) = 2 (1 - 2e-12), f = e^2 (1 - 4e-12)."""
    e2 = math.exp(2.0)  # 7.389056098930650
    delta = np.concatenate([-np.geomspace(1e12, 1e-3, 301), [0.0], np.geomspace(1e-3, 1e12, 301)])  # sorted
    f = curvature_factor(delta, "soft")
    assert np.all(f >= (1 - 1e-15) / e2) and np.all(f <= e2 * (1 + 1e-15))
    assert np.all(np.diff(f) >= -4 * EPS * f[1:])  # non-decreasing (to rounding where it saturates at e^{+-2})
    for d, want in ((1e6, e2), (-1e6, 1 / e2)):
        assert abs(curvature_factor(d, "soft") / want - 1) <= 1e-11
    # inside first-order range it is not saturated yet: delta = 1 gives exp(1/sqrt(1.25)) = exp(0.894427...)
    assert curvature_factor(1.0, "soft") == pytest.approx(math.exp(1.0 / math.sqrt(1.25)), rel=1e-15)


@pytest.mark.parametrize("delta", [0.01, 0.05, 0.1, 0.2, -0.01, -0.05, -0.1, -0.2])
def test_soft_policy_departs_from_exp_at_third_order(delta):
    """ln f_exp - ln f_soft = delta (1 - (1 + delta^2/4)^{-1/2}) = delta^3/8 - 3 delta^5/128 + ... (alternating,
    decreasing terms for |delta| < 2): the ratio to delta^3/8 lies in [1 - 3 delta^2/16, 1], and the factors differ
    by at most |delta|^3/8 of the larger one (mean value theorem)."""
    f_soft = curvature_factor(delta, "soft")
    f_exp = curvature_factor(delta, "exp")
    ratio = (delta - math.log(f_soft)) / (delta**3 / 8)
    assert 1 - 3 * delta**2 / 16 - 1e-9 <= ratio <= 1 + 1e-9, ratio
    assert abs(f_soft - f_exp) <= abs(delta) ** 3 / 8 * max(f_soft, f_exp) * (1 + 1e-9)


def test_soft_policy_profile_within_e_to_the_two_of_the_dipole():
    """Far outside first-order range (|k| up to 2 transport lengths^-1, rho to 60) the default profile stays
    within [e^-2, e^2] of the dipole on concave and convex surfaces (the entry-point cap only lowers convex
    values, never below R_d); the "exp" policy leaves that band (it is not saturated)."""
    rho = np.linspace(0.05, 60, 400)
    Rd = dipole_profile(rho, **SKIN)
    pos = Rd > 0
    e2 = math.exp(2.0)
    for k in (-2.0, -0.5, -0.05, 0.05, 0.5, 2.0):
        ratio = curvature_profile(rho, 0.3, k1_opt=k, k2_opt=k / 3, **SKIN)[pos] / Rd[pos]
        assert np.all(ratio >= (1 - 1e-12) / e2) and np.all(ratio <= e2 * (1 + 1e-12)), k
    concave = curvature_profile(rho, 0.3, k1_opt=-0.5, k2_opt=-0.5, **SKIN, policy="exp")[pos] / Rd[pos]
    assert np.min(concave) < 1e-3 / e2


def test_curvature_profile_never_exceeds_entry_value():
    """Strongly convex: the first-order term alone would exceed the peak; the cap keeps R <= R(0)."""
    rho = np.linspace(0, 60, 601)
    for policy in ("soft", "exp", "clamp"):
        R = curvature_profile(rho, 0.0, k1_opt=2.0, k2_opt=2.0, **SKIN, policy=policy)
        assert np.all(R <= R[0] * (1 + 1e-15)) and np.all(R >= 0)


def test_curvature_validity_mask():
    rho = np.array([0.5, 2.0, 20.0])
    ok = curvature_validity(rho, 0.02, **SKIN)
    a, b = curvature_ratios(rho, **SKIN)
    np.testing.assert_array_equal(ok, 0.02 * (np.abs(a) + np.abs(b) + 1) <= 0.25)
    assert ok[0] and not ok[2]
    R, valid = curvature_profile(rho, 0.3, k1_opt=0.02, k2_opt=-0.01, **SKIN, return_validity=True)
    np.testing.assert_array_equal(valid, ok)
    _, valid_flat = curvature_profile(rho, 0.3, k1_opt=0.0, k2_opt=0.0, **SKIN, return_validity=True)
    assert np.all(valid_flat)


albedo_from_coefficients = st.tuples(
    st.floats(1e-2, 1e2), st.floats(1e-6, 10.0),  # sigma_s', sigma_a [1/mm]
).map(lambda sa: (sa[0] + sa[1], sa[0] / (sa[0] + sa[1])))


@given(mat=albedo_from_coefficients, eta=st.floats(1.0, 2.0),
       k1=st.floats(-10.0, 10.0), k2=st.floats(-10.0, 10.0),
       rho_mm=st.lists(st.floats(0.0, 1e3), min_size=1, max_size=8), phi=st.floats(-7.0, 7.0),
       policy=st.sampled_from(["soft", "exp", "clamp"]))
def test_curvature_profile_finite_nonnegative(mat, eta, k1, k2, rho_mm, phi, policy):
    """Physical ranges of docs/physics.md §1.3: curvatures up to +-10/mm, any distance; mm -> optical units."""
    st_p, a_p = mat
    rho = np.array(rho_mm) * st_p
    R = curvature_profile(rho, phi, k1_opt=k1 / st_p, k2_opt=k2 / st_p, albedo_prime=a_p, eta=eta, policy=policy)
    assert np.all(np.isfinite(R)) and np.all(R >= 0)
    # never above the cap: the entry-point value R_d(0) f(delta_0) of a convex surface, delta_0 = (k1 + k2) a(0)
    a0, _ = curvature_ratios(0.0, albedo_prime=a_p, eta=eta)
    cap = dipole_profile(0.0, albedo_prime=a_p, eta=eta) * curvature_factor(max((k1 + k2) / st_p * a0, 0.0), policy)
    assert np.all(R <= cap * (1 + 1e-12))


# --------------------------------------------------------------------------------------------------
# exact solutions: sphere (convex), cavity (concave), cylinder (anisotropic)
# --------------------------------------------------------------------------------------------------
def _cavity_profile(theta, *, R0_opt, albedo_prime, eta, rtol=1e-14):
    """Exact reflectance of the medium r > R0 outside a spherical cavity (concave surface, k = -1/R0).

    Extrapolated boundary at R = R0 - z_b, source at r' = R0 + z_r, flux alpha' D dPsi/dr on r = R0:

        R(theta) = alpha'/(4 pi) [ g(d) (z_r - 2 r' sin^2(theta/2)) + sum_m c_m P_m(cos theta) ],
        c_m = (2m+1) K_nu(mu r') K_nu(mu R0) I_nu(mu R) / (K_nu(mu R) sqrt(r' R0)) [mu K_{nu+1}/K_nu(mu R0) - m/R0],

    (the exterior Green's function e^{-mu d}/d - sum (2m+1) K(mu r') K(mu r) I(mu R)/(K(mu R) sqrt(r r')) P_m,
    nu = m + 1/2). Evaluated with the ratios of docs/physics.md §5.4: Q_m = K(x')K(x0)/K(xR)^2 by forward recurrence of
    u = K_{nu+1}/K_nu, W_m = I(xR) K(xR) with t = I_{nu+1}/I_nu by backward recurrence; the terms decay like
    (R^2/(r' R0))^m. Needs mu > 0 and R0 > z_b.
    """
    p = diffusion_params(albedo_prime, eta)
    mu, z_r, z_b, alb = float(p.mu), float(p.z_r), float(p.z_b), float(p.albedo_prime)
    R0 = float(R0_opt)
    R, rs = R0 - z_b, R0 + z_r
    assert R > 0 and mu > 0
    th = np.asarray(theta, dtype=np.float64)
    sin2 = np.sin(th / 2) ** 2
    d = np.sqrt(z_r**2 + 4 * R0 * rs * sin2)
    free = (mu * d + 1) * np.exp(-mu * d) / d**3 * (z_r - 2 * rs * sin2)
    x1, x0, xR = mu * rs, mu * R0, mu * R
    q = R * R / (rs * R0)
    M = int(1.5 * (math.log(1 / rtol) + 5) / (-math.log(q)) + 2 * xR + 100)
    top = M + 60 + int(2 * xR)
    t = xR / (top + 1.5 + math.sqrt((top + 1.5) ** 2 + xR**2))
    tt = np.empty(M + 1)
    for m in range(top, -1, -1):
        if m <= M:
            tt[m] = t
        t = 1.0 / (2 * (m + 0.5) / xR + t)
    u1, u0, uR = 1 + 1 / x1, 1 + 1 / x0, 1 + 1 / xR
    Q = (R / math.sqrt(rs * R0)) * math.exp(-mu * (z_r + 2 * z_b))
    W = -math.expm1(-2 * xR) / (2 * xR)
    c = np.cos(th)
    p_prev, p_cur = np.zeros_like(th), np.ones_like(th)
    series = np.zeros_like(th)
    total, small = 0.0, 0
    for m in range(M + 1):
        cm = (2 * m + 1) / math.sqrt(rs * R0) * Q * W * (mu * u0 - m / R0)
        series += cm * p_cur
        total += cm
        small = small + 1 if abs(cm) < rtol * abs(total) else 0
        if small >= 3:
            break
        nxt = m + 1.5
        Q *= u1 * u0 / (uR * uR)
        W *= tt[m] * uR
        u1, u0, uR = 1 / u1 + 2 * nxt / x1, 1 / u0 + 2 * nxt / x0, 1 / uR + 2 * nxt / xR
        p_prev, p_cur = p_cur, ((2 * m + 1) * c * p_cur - m * p_prev) / (m + 1)
    else:
        raise RuntimeError("cavity series did not converge")
    return alb / (4 * math.pi) * (free + series)


def _sphere(theta, R0_opt):
    return sphere_series_profile(theta, R0_opt=R0_opt, **SKIN, rtol=1e-14)


R0_MM = np.array([50.0, 100.0, 200.0, 500.0, 1000.0])
S_MM = np.array([1.0, 2.0, 5.0])


@pytest.mark.parametrize("kind", ["sphere", "cavity"])
@pytest.mark.parametrize("policy", ["soft", "exp", "clamp"])
def test_curved_kernel_converges_like_inverse_square_radius(kind, policy):
    """(exact - curved)/exact ~ 1/R0^2 (fitted slope <= -1.8 over R0 = 50..1000 mm at s = 1, 2, 5 mm) while
    (exact - dipole)/exact ~ 1/R0 (slope -1 +- 0.1); docs/physics.md §11.7 (skin case, geodesic s)."""
    s = S_MM * ST
    d1, d0 = [], []
    for R0 in R0_MM * ST:
        th = s / R0
        exact = _sphere(th, R0) if kind == "sphere" else _cavity_profile(th, R0_opt=R0, **SKIN)
        k = 1 / R0 if kind == "sphere" else -1 / R0
        curved = curvature_profile(s, 0.0, k1_opt=k, k2_opt=k, **SKIN, policy=policy)
        d1.append((exact - curved) / exact)
        d0.append((exact - dipole_profile(s, **SKIN)) / exact)
    d1, d0 = np.abs(d1), np.abs(d0)
    for j in range(S_MM.size):
        slope1 = np.polyfit(np.log(R0_MM), np.log(d1[:, j]), 1)[0]
        slope0 = np.polyfit(np.log(R0_MM), np.log(d0[:, j]), 1)[0]
        assert slope1 <= -1.8, (S_MM[j], slope1)
        assert -1.1 <= slope0 <= -0.9, (S_MM[j], slope0)
        assert d1[-1, j] < 1e-2 * d0[-1, j]  # at 1000 mm the first order removes > 99 % of the dipole error


def test_curved_kernel_matches_physics_md_sphere_residuals():
    """docs/physics.md §11.7 table d1 = (R_exact - R_d - R1)/R_d at R0 = 100 mm:
    1.6e-5, 9.7e-5, 4.0e-4 (s = 1, 2, 5)."""
    s = S_MM * ST
    R0 = 100 * ST
    exact = _sphere(s / R0, R0)
    Rd = dipole_profile(s, **SKIN)
    C = curvature_relative_coefficient(s, **SKIN)
    d1 = (exact - Rd * (1 + C / R0)) / Rd
    np.testing.assert_allclose(d1, [1.6e-5, 9.7e-5, 4.0e-4], rtol=0.05)


def test_curved_kernel_anisotropic_against_exact_cylinder():
    """Exact infinite cylinder (k1 = 1/R0 around, k2 = 0 along): the residual of the curved kernel falls like
    1/R0^2 around (checks A), along the axis (checks B) and at the entry point (A(0)); docs/physics.md §11.7."""
    radii = np.array([40.0, 80.0, 160.0, 320.0])
    s = np.array([0.0, 2.0, 2.0, 5.0]) * ST
    phi = np.array([0.0, 0.0, np.pi / 2, np.pi / 2])
    res = []
    for R0 in radii * ST:
        exact = cylinder_exact_profile_geodesic(s, phi, R0_opt=R0, **SKIN, rtol=1e-11)
        curved = curvature_profile(s, phi, k1_opt=1 / R0, k2_opt=0.0, **SKIN)
        res.append(np.abs(exact - curved) / exact)
    slopes = np.polyfit(np.log(radii), np.log(np.array(res)), 1)[0]
    assert np.all(slopes <= -1.8), slopes


def _policy_errors(materials, radii_mm, s_mm):
    """Max |R_policy/R_exact - 1| over sphere and cavity pairs whose validity measure is <= tol."""
    rows = []
    for a_p, eta, st_p in materials:
        s = np.asarray(s_mm) * st_p
        a, b = curvature_ratios(s, albedo_prime=a_p, eta=eta)
        for R0_mm in radii_mm:
            R0 = R0_mm * st_p
            th = np.concatenate([[0.0], s / R0])
            th = th[th <= 0.999 * np.pi]
            for sign in (1, -1):
                if sign > 0:
                    exact = sphere_series_profile(th, R0_opt=R0, albedo_prime=a_p, eta=eta, rtol=1e-13)
                else:
                    if R0 <= 3 * float(diffusion_params(a_p, eta).z_b):
                        continue
                    exact = _cavity_profile(th, R0_opt=R0, albedo_prime=a_p, eta=eta, rtol=1e-13)
                # points on the sphere (not past the antipode) where the series has relative accuracy
                # (its error is ~1e-15 of the peak, so values below 1e-9 of the peak are skipped)
                ok = np.zeros(s.size, dtype=bool)
                ok[: th.size - 1] = exact[1:] > 1e-9 * exact[0]
                exact = exact[1:][ok[: th.size - 1]]
                k = sign / R0
                nu = abs(k) * (np.abs(a[ok]) + np.abs(b[ok]) + 1.0)
                for policy in ("exp", "clamp"):
                    R = curvature_profile(s[ok], 0.0, k1_opt=k, k2_opt=k, albedo_prime=a_p, eta=eta, policy=policy)
                    for n_, e_ in zip(nu, np.abs(R / exact - 1)):
                        rows.append((sign, policy, n_, e_))
    return rows


def _max_error(rows, sign, policy, tol):
    errs = [e for sg, p, n, e in rows if sg == sign and p == policy and n <= tol]
    assert len(errs) >= 5
    return max(errs)


def test_policy_error_against_exact_sphere_and_cavity_skin():
    """The documented bounds of the "exp" policy (module docstring), skin case, on a small grid."""
    rows = _policy_errors([(1 / 1.01, 1.3, 1.01)], [5, 10, 20, 50, 200], [0.25, 0.5, 1, 2, 3, 5, 8, 12, 20, 30])
    for sign in (1, -1):
        assert _max_error(rows, sign, "exp", 0.1) <= 2e-3
        assert _max_error(rows, sign, "exp", 0.25) <= 1.2e-2
        # the exponentiated first order is closer to the exact solutions than the clamped sum
        assert _max_error(rows, sign, "exp", 0.5) < _max_error(rows, sign, "clamp", 0.5)


@pytest.mark.slow
def test_policy_error_against_exact_sphere_and_cavity_materials():
    """Full grid of the module docstring: 5 materials, R0 = 3..1000 mm, s = 0.25..30 mm."""
    mats = [(s / (s + a), eta, s + a) for s, a, eta in
            [(1.0, 0.01, 1.3), (2.19, 0.0021, 1.3), (0.55, 0.12, 1.3), (1.0, 0.01, 1.0), (0.07, 0.97, 1.3)]]
    rows = _policy_errors(mats, [3, 4, 5, 7, 10, 15, 20, 30, 50, 100, 200, 1000],
                          [0.25, 0.5, 1, 1.5, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30])
    bounds = {0.05: 3e-4, 0.1: 1.5e-3, 0.25: 1.2e-2, 0.5: 4.5e-2}
    for sign in (1, -1):
        for tol, bound in bounds.items():
            assert _max_error(rows, sign, "exp", tol) <= bound, (sign, tol)


@pytest.mark.slow
def test_cavity_series_against_mpmath():
    """The exterior series above against a brute-force mpmath sum with I_nu, K_nu (30 digits), R0 = 5 mm."""
    p = diffusion_params(**SKIN)
    R0_f = 5 * ST
    for theta in (0.0, 0.1, 0.5):
        with mp.workdps(30):
            mu, z_r, z_b = mp.mpf(float(p.mu)), mp.mpf(1), mp.mpf(float(p.z_b))
            R0, th = mp.mpf(R0_f), mp.mpf(theta)
            R, rs = R0 - z_b, R0 + z_r
            d = mp.sqrt(rs**2 + R0**2 - 2 * rs * R0 * mp.cos(th))
            tot = (mu * d + 1) * mp.exp(-mu * d) / d**3 * (rs * mp.cos(th) - R0)
            for m in range(400):
                nu = m + mp.mpf(1) / 2
                dK = -mu * mp.besselk(nu + 1, mu * R0) + m / R0 * mp.besselk(nu, mu * R0)
                term = ((2 * m + 1) * mp.besselk(nu, mu * rs) * mp.besseli(nu, mu * R) / mp.besselk(nu, mu * R)
                        / mp.sqrt(rs * R0) * (-dK) * mp.legendre(m, mp.cos(th)))
                tot += term
                if abs(term) < mp.mpf(10) ** -25 * abs(tot):
                    break
            ref = float(mp.mpf(SKIN["albedo_prime"]) / (4 * mp.pi) * tot)
        got = _cavity_profile(np.array([theta]), R0_opt=R0_f, **SKIN)[0]
        assert abs(got / ref - 1) <= 1e-13
