"""Exact infinite-cylinder reference (meshshade.kernels.cylinder): addition theorem, boundary condition, PDE,
flux, energy, mpmath references, planar limit and the first-order curvature kernel (docs/physics.md §5-§7)."""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special

from meshshade.errors import MeshshadeError
from meshshade.kernels import cylinder as cyl
from meshshade.kernels.curvature import curvature_coefficients
from meshshade.kernels.cylinder import cylinder_exact_profile, cylinder_exact_profile_geodesic
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.optics import diffusion_params

SIGMA_T = 1.01                     # skin test case: sigma_s' = 1, sigma_a = 0.01 /mm
SKIN = dict(albedo_prime=1.0 / SIGMA_T, eta=1.3)


def _slope(x, y):
    """Least-squares log-log slope of |y| against x."""
    return float(np.polyfit(np.log(x), np.log(np.abs(y)), 1)[0])


# ------------------------------------------------------------------------------------------------------
# the expansion itself
# ------------------------------------------------------------------------------------------------------

def test_addition_theorem_matches_closed_form_mpmath():
    """e^{-mu|x-x'|}/|x-x'| = (2/pi) int dq cos(qz) sum_n eps_n cos(n theta) I_n(k r<) K_n(k r>), at 20 digits."""
    with mp.workdps(20):
        mu, r1, r2 = mp.mpf("0.7"), mp.mpf("0.3"), mp.mpf("1.5")
        th, z = mp.mpf("0.9"), mp.mpf("0.6")
        d = mp.sqrt(r1**2 + r2**2 - 2 * r1 * r2 * mp.cos(th) + z**2)
        closed = mp.exp(-mu * d) / d

        def integrand(q):
            k = mp.sqrt(mu**2 + q**2)
            x1, x2 = k * r1, k * r2
            k_prev, k_cur = mp.besselk(0, x2), mp.besselk(1, x2)
            total = mp.besseli(0, x1) * k_prev
            n = 1
            while True:
                term = 2 * mp.cos(n * th) * mp.besseli(n, x1) * k_cur
                total += term
                if n > 3 and abs(term) < mp.mpf(10) ** -22 * abs(total):
                    break
                k_prev, k_cur = k_cur, k_prev + 2 * n / x2 * k_cur
                n += 1
            return mp.cos(q * z) * total

        series = 2 / mp.pi * mp.quad(integrand, [0, 3, 10, 34])   # tail beyond q = 34: < e^{-1.2*34} ~ 1e-18
        assert abs(series - closed) < mp.mpf(10) ** -17 * closed


def test_ratios_backward_matches_mpmath():
    """t_n(x) = I_{n+1}(x)/I_n(x) by backward recurrence from the Amos-bound start, n <= 299, x up to 2e4."""
    out = np.empty(300)
    with mp.workdps(30):
        for x in [1e-3, 0.5, 7.0, 120.0, 3000.0, 2.0e4]:
            cyl._ratios_backward(x, 300, out)
            for n in (0, 1, 7, 60, 299):
                ref = mp.besseli(n + 1, x) / mp.besseli(n, x)
                assert abs(out[n] - float(ref)) <= 1e-15 * float(ref), (x, n)


# ------------------------------------------------------------------------------------------------------
# boundary value problem: Psi = 0 on r = R, PDE, flux = -D dPsi/dr, energy
# ------------------------------------------------------------------------------------------------------

CASES = [(3.0, 1.0 / 1.01, 1.3), (0.7, 0.9, 1.0), (20.0, 0.99, 1.5)]   # 0.7: source past the axis


@pytest.mark.parametrize("R0, alb, eta", CASES)
def test_cylinder_fluence_vanishes_on_extrapolated_cylinder(R0, alb, eta):
    p = diffusion_params(alb, eta)
    R = R0 + float(p.z_b)
    th = np.array([0.0, 0.3, 1.0, np.pi])
    z = np.array([0.0, 0.5, 2.0, 0.1])
    psi = cyl._cylinder_fluence(R, th, z, R0_opt=R0, albedo_prime=alb, eta=eta, rtol=1e-14)
    d = np.sqrt(R**2 + (R0 - 1.0) ** 2 - 2 * R * (R0 - 1.0) * np.cos(th) + z**2)
    free = np.exp(-float(p.mu) * d) / d / (4 * np.pi / 3)        # each of the two cancelling terms
    assert np.all(np.abs(psi) < 1e-13 * free)


@pytest.mark.parametrize("R0, alb, eta", CASES)
def test_cylinder_exact_profile_is_minus_D_dpsi_dr(R0, alb, eta):
    """The analytic flux (I_n' = I_{n+1} + n/x I_n) equals a 4th-order finite difference of the fluence."""
    th = np.array([0.0, 0.3, 1.0, np.pi])
    z = np.array([0.0, 0.5, 2.0, 0.1])
    h = 1e-3
    psi = [cyl._cylinder_fluence(R0 + k * h, th, z, R0_opt=R0, albedo_prime=alb, eta=eta, rtol=1e-14)
           for k in (-2, -1, 1, 2)]
    dpsi = (psi[0] - 8 * psi[1] + 8 * psi[2] - psi[3]) / (12 * h)
    fd = alb * (-(1.0 / 3.0) * dpsi)
    exact = cylinder_exact_profile(th, z, R0_opt=R0, albedo_prime=alb, eta=eta, rtol=1e-14)
    np.testing.assert_allclose(fd, exact, rtol=2e-9)


@pytest.mark.parametrize("R0, alb, eta", CASES)
def test_cylinder_fluence_pde_residual(R0, alb, eta):
    """Lap Psi - mu^2 Psi = 0 away from the source (cylindrical Laplacian, 4th-order differences)."""
    mu = float(diffusion_params(alb, eta).mu)
    r0, t0, z0, h = (0.6 * R0 if R0 > 1 else 0.3), 0.7, 0.4, 2e-3

    def psi(r, t, z):
        return cyl._cylinder_fluence(r, t, z, R0_opt=R0, albedo_prime=alb, eta=eta, rtol=1e-14)[()]

    def d2(f, x):
        return (-f(x - 2 * h) + 16 * f(x - h) - 30 * f(x) + 16 * f(x + h) - f(x + 2 * h)) / (12 * h * h)

    def d1(f, x):
        return (f(x - 2 * h) - 8 * f(x - h) + 8 * f(x + h) - f(x + 2 * h)) / (12 * h)

    p_rr = d2(lambda r: psi(r, t0, z0), r0)
    p_r = d1(lambda r: psi(r, t0, z0), r0)
    p_tt = d2(lambda t: psi(r0, t, z0), t0)
    p_zz = d2(lambda z: psi(r0, t0, z), z0)
    residual = p_rr + p_r / r0 + p_tt / r0**2 + p_zz - mu**2 * psi(r0, t0, z0)
    scale = abs(p_rr) + abs(p_r / r0) + abs(p_tt / r0**2) + abs(p_zz)
    assert abs(residual) < 1e-8 * scale


@pytest.mark.parametrize("R0, alb, eta", [(3.0, 0.7, 1.3), (0.8, 0.7, 1.6)])
def test_cylinder_exact_profile_energy_closed_form(R0, alb, eta):
    """int R dA = alpha' R0 mu I0(mu r') [K1(mu R0) + K0(mu R) I1(mu R0)/I0(mu R)] (only n = 0, q = 0 survive)."""
    p = diffusion_params(alb, eta)
    mu, R, r_src = float(p.mu), R0 + float(p.z_b), R0 - 1.0
    closed = alb * R0 * mu * special.iv(0, mu * r_src) * (
        special.kv(1, mu * R0) + special.kv(0, mu * R) * special.iv(1, mu * R0) / special.iv(0, mu * R))
    edges = np.array([0, 0.5, 1, 2, 4, 8, 16, 24, 32, 40, 48.0])   # R ~ e^{-mu z}: < 1e-18 beyond z = 48
    x, w = np.polynomial.legendre.leggauss(16)
    half = 0.5 * (edges[1:, None] - edges[:-1, None])
    zs = (half * x + 0.5 * (edges[1:, None] + edges[:-1, None])).ravel()
    wz = (half * w).ravel()
    n_theta = 160                                                   # periodic trapezoid: spectral in theta
    th = 2 * np.pi * np.arange(n_theta) / n_theta
    vals = cylinder_exact_profile(th[None, :], zs[:, None], R0_opt=R0, albedo_prime=alb, eta=eta, rtol=1e-12)
    numeric = 2.0 * np.sum(wz[:, None] * vals) * (2 * np.pi / n_theta) * R0
    assert numeric == pytest.approx(closed, rel=1e-12)


# ------------------------------------------------------------------------------------------------------
# mpmath references (tools/references/precompute_cylinder_references.py)
# ------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def reference_rows(reference_csv):
    """Rows of tests/data/cylinder_reference.csv (the shared loader checks the generator's sha256)."""
    header, rows = reference_csv("cylinder_reference.csv")
    assert header["generator"] == "tools/references/precompute_cylinder_references.py" and header["dps"] == "34"
    assert "function" in header and len(rows) >= 20
    return rows


@pytest.mark.parametrize("rtol, tol", [(1e-14, 1e-14), (1e-8, 1e-8)])
def test_cylinder_exact_profile_matches_mpmath(reference_rows, rtol, tol):
    rows = reference_rows
    for row in rows:
        ref = float(row["R"])
        val, err = cylinder_exact_profile(float(row["theta"]), float(row["z"]), R0_opt=float(row["R0_opt"]),
                                          albedo_prime=float(row["albedo_prime"]), eta=float(row["eta"]),
                                          rtol=rtol, full_output=True)
        assert abs(val - ref) <= tol * ref, row
        assert abs(val - ref) <= err, row         # the returned error bound is honest


def test_cylinder_exact_profile_continuous_through_source_on_axis():
    """R0 = z_r puts the source on the axis (only n = 0 survives); R0 < z_r moves it past the axis."""
    th = np.array([0.0, 0.8, np.pi])
    z = np.array([0.0, 0.3, 1.0])
    vals = [cylinder_exact_profile(th, z, R0_opt=R0, albedo_prime=0.95, eta=1.2, rtol=1e-14)
            for R0 in (1.0 - 1e-7, 1.0, 1.0 + 1e-7)]
    np.testing.assert_allclose(vals[0], vals[1], rtol=1e-6)
    np.testing.assert_allclose(vals[2], vals[1], rtol=1e-6)
    assert np.ptp(vals[1]) > 0.1 * vals[1][0]   # not trivially flat: depends on theta, z


# ------------------------------------------------------------------------------------------------------
# geodesic parametrisation, input validation
# ------------------------------------------------------------------------------------------------------

def test_cylinder_exact_profile_geodesic_is_unrolled_helix():
    R0 = 7.0
    rho = np.array([0.5, 2.0, 4.0])
    phi = np.array([0.0, 0.6, np.pi / 2])
    got = cylinder_exact_profile_geodesic(rho, phi, R0_opt=R0, **SKIN)
    want = cylinder_exact_profile(rho * np.cos(phi) / R0, rho * np.sin(phi), R0_opt=R0, **SKIN)
    np.testing.assert_array_equal(got, want)
    # around (phi = 0) the convex direction reflects more than along the flat axis (phi = pi/2)
    around = cylinder_exact_profile_geodesic(3.0, 0.0, R0_opt=R0, **SKIN)
    along = cylinder_exact_profile_geodesic(3.0, np.pi / 2, R0_opt=R0, **SKIN)
    assert around > along


@pytest.mark.parametrize("kwargs", [dict(R0_opt=0.5), dict(R0_opt=0.2), dict(R0_opt=[3.0, 4.0]),
                                    dict(R0_opt=3.0, albedo_prime=1.5), dict(R0_opt=3.0, eta=-1.0),
                                    dict(R0_opt=float("nan"))])
def test_cylinder_exact_profile_rejects_bad_parameters(kwargs):
    args = dict(albedo_prime=0.9, eta=1.3)
    args.update(kwargs)
    with pytest.raises(MeshshadeError):
        cylinder_exact_profile(0.0, 0.0, **args)


def test_cylinder_exact_profile_broadcasts():
    th = np.linspace(0, 1, 3)[:, None]
    z = np.linspace(0, 2, 4)[None, :]
    out = cylinder_exact_profile(th, z, R0_opt=4.0, **SKIN)
    assert out.shape == (3, 4) and out.dtype == np.float64
    np.testing.assert_array_equal(out[1], cylinder_exact_profile(th[1, 0], z[0], R0_opt=4.0, **SKIN))


# ------------------------------------------------------------------------------------------------------
# planar limit and first-order curvature theory
# ------------------------------------------------------------------------------------------------------

def test_cylinder_planar_limit_rate_and_first_order_coefficients():
    """R_cyl/R_d - 1 ~ 1/R0 at fixed geodesic distance; R0 (ratio - 1) -> alpha' A/R_d around the cylinder and
    alpha' B/R_d along it (k1 = 1/R0, k2 = 0), against the docs/physics.md §11.6 table (skin, mm)."""
    rho_mm = np.array([1.0, 5.0, 20.0])
    rho = rho_mm * SIGMA_T
    Rd = dipole_profile(rho, **SKIN)
    table = {0.0: ([1.129, 3.80, 19.1], [0.0005, 0.005, 0.05]),            # alpha'A/R_d [mm]
             np.pi / 2: ([-0.0015, -0.42, -3.2], [0.00005, 0.005, 0.05])}  # alpha'B/R_d [mm]
    for phi, (want, tol) in table.items():
        scaled = {}
        for R0_mm in (500.0, 1000.0, 2000.0):
            R = cylinder_exact_profile_geodesic(rho, phi, R0_opt=R0_mm * SIGMA_T, rtol=1e-12, **SKIN)
            scaled[R0_mm] = R0_mm * (R / Rd - 1.0)
        rel = [scaled[r] / r for r in (500.0, 1000.0, 2000.0)]
        slopes = [_slope([500.0, 1000.0, 2000.0], [x[i] for x in rel]) for i in range(len(rho))]
        check = [0, 1, 2] if phi == 0.0 else [1, 2]       # B(1 mm) is ~1e-3 of A: its 1/R0^2 part shows
        np.testing.assert_allclose(np.asarray(slopes)[check], -1.0, atol=0.03)
        richardson = 2.0 * scaled[2000.0] - scaled[1000.0]
        assert np.all(np.abs(richardson - np.asarray(want)) <= np.asarray(tol)), (phi, richardson)


def _skin_residuals(s_mm, phi, radii_mm, A, B):
    rho = s_mm * SIGMA_T
    Rd = dipole_profile(rho, **SKIN)
    d0, d1 = [], []
    for R0_mm in radii_mm:
        k1 = 1.0 / (R0_mm * SIGMA_T)                      # optical curvature; k2 = 0 along the axis
        R = cylinder_exact_profile_geodesic(rho, phi, R0_opt=R0_mm * SIGMA_T, rtol=1e-12, **SKIN)
        R1 = SKIN["albedo_prime"] * (k1 * math.cos(phi) ** 2 * A + k1 * math.sin(phi) ** 2 * B)
        d0.append((R - Rd) / Rd)
        d1.append((R - Rd - R1) / Rd)
    return np.array(d0), np.array(d1)


@pytest.mark.parametrize("s_mm, phi", [(0.0, 0.0), (2.0, 0.0), (2.0, np.pi / 2)],
                         ids=["s0-checks-A0", "s2-around-checks-A", "s2-along-checks-B"])
def test_cylinder_vs_first_order_curvature_kernel(s_mm, phi):
    """docs/physics.md §11.7: d1 = (R_exact - R_d - R1)/R_d falls like 1/R0^2 (R0 = 20, 40, 80 mm); d0 like 1/R0."""
    A, B = curvature_coefficients(s_mm * SIGMA_T, **SKIN)
    radii = np.array([20.0, 40.0, 80.0])
    d0, d1 = _skin_residuals(s_mm, phi, radii, float(A), float(B))
    assert _slope(radii, d1) <= -1.8
    ratios = d1[:-1] / d1[1:]
    assert np.all((ratios > 3.5) & (ratios < 4.6))        # ~4x per doubling
    if s_mm > 0:                                           # at s = 0, A(0) is tiny: d0 is second order there
        assert -1.35 <= _slope(radii, d0) <= -0.9
        gain = np.abs(d1 / d0)                             # the first-order term removes a growing share
        assert np.all(gain < 0.5) and np.all((gain[:-1] / gain[1:] > 1.6) & (gain[:-1] / gain[1:] < 2.4))


def test_cylinder_richardson_limit_equals_curvature_coefficients():
    """lim R0 (R_cyl/R_d - 1) = alpha' A/R_d (around) and alpha' B/R_d (along), to 1e-4 relative."""
    rho = np.array([0.5, 2.0, 8.0])
    A, B = curvature_coefficients(rho, **SKIN)
    Rd = dipole_profile(rho, **SKIN)
    for phi, coef in ((0.0, A), (np.pi / 2, B)):
        f = [R0 * (cylinder_exact_profile_geodesic(rho, phi, R0_opt=R0, rtol=1e-12, **SKIN) / Rd - 1.0)
             for R0 in (1000.0, 2000.0)]
        np.testing.assert_allclose(2 * f[1] - f[0], SKIN["albedo_prime"] * coef / Rd, rtol=1e-4, atol=2e-6)


# ------------------------------------------------------------------------------------------------------
# property tests
# ------------------------------------------------------------------------------------------------------

_params = dict(
    R0=st.floats(0.5, 1e3, exclude_min=True),
    theta=st.floats(0.0, np.pi),
    z=st.floats(0.0, 50.0),
    alb=st.floats(0.5, 0.9999),
    eta=st.floats(1.0, 2.0),
)


def _check_finite_nonnegative(R0, theta, z, alb, eta, rtol):
    val, err = cylinder_exact_profile(np.array([0.0, theta]), np.array([0.0, z]), R0_opt=R0, albedo_prime=alb,
                                      eta=eta, rtol=rtol, full_output=True)
    assert np.all(np.isfinite(val)) and np.all(np.isfinite(err))
    assert val[0] > 0.0
    assert err[0] < 1e-6 * val[0]
    # non-negative up to the returned absolute error bound (the far tail is below the series' rounding floor)
    assert np.all(val >= -err)


@settings(max_examples=50)
@given(**_params)
def test_cylinder_exact_profile_finite_nonnegative(R0, theta, z, alb, eta):
    _check_finite_nonnegative(R0, theta, z, alb, eta, rtol=1e-8)


@pytest.mark.slow
@settings(max_examples=400)
@given(**_params)
def test_cylinder_exact_profile_finite_nonnegative_thorough(R0, theta, z, alb, eta):
    _check_finite_nonnegative(R0, theta, z, alb, eta, rtol=1e-13)
