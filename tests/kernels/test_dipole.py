"""Planar dipole R_d (meshshade.kernels.dipole) against mpmath references, closed forms and invariants.

References: tests/data/dipole_reference.csv, written by tools/references/precompute_dipole_references.py (an independent
mpmath implementation at 50 digits; provenance in the CSV header). Formulas: docs/physics.md §2 and §4.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import integrate

from meshshade.errors import DiffusionValidityWarning
from meshshade.kernels.dipole import (dipole_cutoff_radius, dipole_diffuse_reflectance, dipole_profile,
                                      dipole_tail_reflectance, dipole_total_reflectance)
from meshshade.kernels.optics import diffusion_params
from meshshade.materials import Material

EPS = np.finfo(np.float64).eps


@pytest.fixture(scope="module")
def reference(reference_csv):
    """Rows of tests/data/dipole_reference.csv (the shared loader checks the generator's sha256)."""
    header, rows = reference_csv("dipole_reference.csv")
    assert header["generator"] == "tools/references/precompute_dipole_references.py" and header["dps"].startswith("50 ")
    return rows


def _profile_rows(reference):
    out = []
    for row in reference:
        if row["quantity"] != "R_d":
            continue
        a, eta, r = float(row["albedo_prime"]), float(row["eta"]), float(row["r_opt"])
        out.append((row["case"], a, eta, r, float(row["value"]), math.sqrt(3.0 * (1.0 - a)) * r))
    return out


def test_reference_csv_covers_the_requested_grid(reference):
    cases = {row["case"] for row in reference}
    assert {"skin_test_eta1.3", "skin_test_eta1.0", "marble_R", "potato_B", "ketchup_B", "albedo1",
            "skin_test_eta2.0"} <= cases
    for case in cases:
        radii = sorted(float(r["r_opt"]) for r in reference if r["case"] == case and r["quantity"] == "R_d")
        assert radii == [0.0, 1e-8, 1e-3, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 300.0]
        assert sum(r["quantity"] == "total_quad" for r in reference if r["case"] == case) == 1


def test_dipole_profile_matches_mpmath(reference):
    """rtol 1e-13 wherever the exponent mu r is at most 100 (the bulk of the table)."""
    rows = [row for row in _profile_rows(reference) if row[5] <= 100.0]
    assert len(rows) > 80
    for case, a, eta, r, ref, _ in rows:
        got = dipole_profile(r, albedo_prime=a, eta=eta)
        np.testing.assert_allclose(got, ref, rtol=1e-13, atol=0, err_msg=f"{case} r_opt={r}")


def test_dipole_profile_matches_mpmath_large_exponent(reference):
    """Known-weak region, its own tolerance: for x = mu r > 100 (ketchup B at r_opt 50..300, potato B at 300)
    exp(-x) has condition number x, so the rounding of x = mu * d alone costs about x * eps (1e-13 at x = 500;
    measured 7.6e-14 for ketchup B at r_opt = 300). Tolerance 4 x eps, i.e. a few ulps of the argument."""
    rows = [row for row in _profile_rows(reference) if row[5] > 100.0]
    assert len(rows) >= 3
    for case, a, eta, r, ref, x in rows:
        got = dipole_profile(r, albedo_prime=a, eta=eta)
        assert ref > 1e-300  # the references are well inside the normal range
        np.testing.assert_allclose(got, ref, rtol=4 * x * EPS, atol=0, err_msg=f"{case} r_opt={r} mu r={x:.0f}")


def test_dipole_profile_broadcasts_like_a_ufunc(reference):
    rows = _profile_rows(reference)
    a = np.array([row[1] for row in rows])
    eta = np.array([row[2] for row in rows])
    r = np.array([row[3] for row in rows])
    got = dipole_profile(r, albedo_prime=a, eta=eta)
    assert got.shape == r.shape and got.dtype == np.float64
    np.testing.assert_array_equal(got, [dipole_profile(ri, albedo_prime=ai, eta=ei) for ri, ai, ei in zip(r, a, eta)])
    grid = dipole_profile(r[:, None], albedo_prime=np.array([0.5, 0.9, 0.99]), eta=1.3)
    assert grid.shape == (r.size, 3)


# --- total diffuse reflectance ------------------------------------------------------------------------

def test_dipole_total_reflectance_matches_mpmath_quadrature(reference):
    """Closed form (alpha'/2)(e^{-mu z_r} + e^{-mu z_v}) vs the CSV's 50-digit tanh-sinh quadrature of R_d 2 pi r."""
    rows = [row for row in reference if row["quantity"] == "total_quad"]
    assert len(rows) >= 7
    for row in rows:
        got = dipole_total_reflectance(albedo_prime=float(row["albedo_prime"]), eta=float(row["eta"]))
        np.testing.assert_allclose(got, float(row["value"]), rtol=1e-14, atol=0, err_msg=row["case"])


@pytest.mark.parametrize(
    "sigma_s_prime, sigma_a, eta, quoted",
    [
        (1.0, 0.01, 1.3, 0.6458266279762992),   # docs/physics.md §11.2: skin, eta 1.3
        (1.0, 0.01, 1.0, 0.7475659848543464),   # docs/physics.md §11.2: eta 1.0
        (0.55, 0.12, 1.3, 0.2127065470419267),  # docs/physics.md §11.2: potato B
        # the original notes gave 0.8301914562772948 for "marble R" without its eta (docs/physics.md §11.2).
        # The mpmath generator shows it is
        # the eta = 1.5 value (eta = 1.3, the Jensen 2001 preset index, gives 0.866540582666390).
        (2.19, 0.0021, 1.5, 0.8301914562772948),
    ],
)
def test_dipole_total_reflectance_physics_md_digits(sigma_s_prime, sigma_a, eta, quoted):
    """The 16 printed digits of docs/physics.md §11.2. They are at exact decimal coefficients; passing the double
    alpha' = s/(s+a) perturbs the result by up to 3.6e-15 (marble: 1 - alpha' ~ 1e-3 amplifies alpha''s
    rounding, checked with mpmath), hence rtol 1e-14 rather than 1e-16."""
    got = dipole_total_reflectance(albedo_prime=sigma_s_prime / (sigma_s_prime + sigma_a), eta=eta)
    np.testing.assert_allclose(got, quoted, rtol=1e-14, atol=0)


def test_dipole_total_reflectance_marble_eta13_is_not_the_quoted_value():
    """Guards the note above: the marble digits of docs/physics.md §11.2 do not belong to eta 1.3."""
    got = dipole_total_reflectance(albedo_prime=2.19 / 2.1921, eta=1.3)
    assert abs(got - 0.8301914562772948) > 1e-2


def _scipy_total(albedo_prime, eta):
    z_v = float(diffusion_params(albedo_prime, eta).z_v)  # only used as a breakpoint
    f = lambda r: 2.0 * np.pi * r * float(dipole_profile(r, albedo_prime=albedo_prime, eta=eta))  # noqa: E731
    kw = dict(epsabs=0.0, epsrel=1e-13, limit=200)
    total = 0.0
    edges = [0.0, 1.0, z_v, 10.0, 30.0, 100.0]
    for lo, hi in zip(edges[:-1], edges[1:]):
        total += integrate.quad(f, lo, hi, **kw)[0]
    return total + integrate.quad(f, edges[-1], np.inf, **kw)[0]


@pytest.mark.parametrize(
    "albedo_prime, eta",
    [(1 / 1.01, 1.3), (1 / 1.01, 1.0), (1 / 1.01, 2.0), (2.19 / 2.1921, 1.3), (0.55 / 0.67, 1.3),
     (0.03 / 1.48, 1.3), (1.0, 1.3)],
)
def test_dipole_profile_quadrature_equals_total_reflectance(albedo_prime, eta):
    """scipy.integrate.quad of R_d 2 pi r over [0, inf) equals the closed form to 1e-10 (docs/physics.md eq. (16))."""
    np.testing.assert_allclose(_scipy_total(albedo_prime, eta),
                               dipole_total_reflectance(albedo_prime=albedo_prime, eta=eta), rtol=1e-10, atol=0)


# --- invariants ---------------------------------------------------------------------------------------

R_GRID = np.concatenate([[0.0], np.geomspace(1e-4, 1e4, 400)])


@pytest.mark.parametrize("albedo_prime", [0.0202, 0.5, 0.8209, 1 / 1.01, 0.999042, 1.0])
@pytest.mark.parametrize("eta", [1.0, 1.3, 2.0])
def test_dipole_profile_positive_and_decreasing(albedo_prime, eta):
    R = dipole_profile(R_GRID, albedo_prime=albedo_prime, eta=eta)
    small = R_GRID <= 20.0  # no underflow there for any albedo listed
    assert np.all(R[small] > 0)
    assert np.all(np.isfinite(R)) and np.all(R >= 0)
    assert np.all(np.diff(R) <= 0)
    assert np.all(np.diff(R[small]) < 0)  # strictly, where the values are not yet flushed to 0


def test_dipole_profile_albedo_one_has_cubic_tail():
    """mu = 0: R_d -> alpha'/(4 pi) (z_r + z_v)/r^3 for r >> z_v (docs/physics.md §4.2 with g(d) = 1/d^3)."""
    z_v = 1.0 + 4.0 / 3.0 * (1 + 0.444762840237) / (1 - 0.444762840237)
    r = 1e4
    np.testing.assert_allclose(dipole_profile(r, albedo_prime=1.0, eta=1.3), (1 + z_v) / (4 * np.pi) / r**3,
                               rtol=1e-6)


albedo_from_coefficients = st.tuples(
    st.floats(1e-2, 1e2, allow_nan=False, allow_infinity=False),   # sigma_s' [1/mm]
    st.floats(1e-6, 10.0, allow_nan=False, allow_infinity=False),  # sigma_a [1/mm]
).map(lambda sa: sa[0] / (sa[0] + sa[1]))
etas = st.floats(1.0, 2.0, allow_nan=False, allow_infinity=False)


@given(albedo_prime=albedo_from_coefficients, eta=etas,
       r_opt=st.floats(0.0, 1e4, allow_nan=False, allow_infinity=False))
def test_dipole_profile_finite_nonnegative(albedo_prime, eta, r_opt):
    R = dipole_profile(r_opt, albedo_prime=albedo_prime, eta=eta)
    assert np.isfinite(R) and R >= 0  # underflow to 0 far out is allowed, NaN is not


@given(albedo_prime=albedo_from_coefficients, eta=etas)
def test_dipole_profile_decreasing_property(albedo_prime, eta):
    R = dipole_profile(R_GRID, albedo_prime=albedo_prime, eta=eta)
    assert np.all(np.isfinite(R)) and np.all(R >= 0)
    assert R[0] > 0
    assert np.all(np.diff(R) <= 0)


@given(albedo_prime=albedo_from_coefficients, eta=etas)
def test_dipole_total_reflectance_bounded_by_albedo(albedo_prime, eta):
    """0 < T <= alpha' (both exponentials are <= 1): the dipole never reflects more than is scattered."""
    T = dipole_total_reflectance(albedo_prime=albedo_prime, eta=eta)
    assert 0 < T <= albedo_prime


# --- units: R in mm^-2 = R_opt(r sigma_t') sigma_t'^2 --------------------------------------------------

def _dipole_mm(material: Material, r_mm, ch=0):
    """docs/physics.md eq. (15) written directly in millimetres from the Material's dimensional quantities."""
    mu, z_r, z_v, a = (material.sigma_tr[ch], material.z_r[ch], material.z_v[ch], material.albedo_prime[ch])
    d_r, d_v = np.hypot(r_mm, z_r), np.hypot(r_mm, z_v)
    g = lambda d: (mu * d + 1) * np.exp(-mu * d) / d**3  # noqa: E731
    return a / (4 * np.pi) * (z_r * g(d_r) + z_v * g(d_v))


def _albedo_rounding_rtol(albedo_prime, r_opt_max):
    """Tolerance for comparisons whose two sides see alpha' rounded differently (alpha' = s/(s+a) in double).

    The kernel's only material input is alpha', and mu = sqrt(3(1 - alpha')) magnifies its rounding as
    alpha' -> 1 (cream R: 1 - alpha' = 2.7e-5). First-order propagation of a 1-ulp error in alpha' through
    R_d: |d ln R/d alpha'| <= 1/alpha' + (3/2) d^2/(mu d + 1) with d <= r_opt + z_v (z_v < 5 for eta <= 2).
    This is about 1e-13 for the skin case and 5e-12 for cream R at r = 10 mm.
    """
    mu = math.sqrt(3.0 * (1.0 - albedo_prime))
    d = r_opt_max + 5.0
    return 1e-13 + 4 * EPS * (1.0 / albedo_prime + 1.5 * d * d / (mu * d + 1.0))


SCALE_CASES = [(1.0, 0.01, 1.3), (2.19, 0.0021, 1.3), (0.55, 0.12, 1.3), (1.0, 0.01, 1.0), (7.38, 0.0002, 2.0)]


@pytest.mark.parametrize("s, a, eta", SCALE_CASES)
def test_dipole_profile_optical_units_equal_millimetre_formula(s, a, eta):
    m = Material(s, a, eta)
    r_mm = np.array([0.0, 0.01, 0.3, 1.0, 4.0, 25.0])
    st_ = m.sigma_t_prime[0]
    R_opt = dipole_profile(r_mm * st_, albedo_prime=m.albedo_prime[0], eta=eta)
    rtol = _albedo_rounding_rtol(m.albedo_prime[0], r_mm[-1] * st_)  # sigma_tr from sigma_a vs mu from alpha'
    np.testing.assert_allclose(R_opt * st_**2, _dipole_mm(m, r_mm), rtol=rtol, atol=0)


@pytest.mark.parametrize("s, a, eta", SCALE_CASES)
@pytest.mark.parametrize("c", [2.0**-10, 0.1, 25.4, 1e3])
def test_dipole_profile_unit_scaling(s, a, eta, c):
    """Scaling sigma_s', sigma_a by c and distances by 1/c scales R [mm^-2] by c^2 (e.g. a change of length unit)."""
    base, scaled = Material(s, a, eta), Material(c * s, c * a, eta)
    r_mm = np.array([0.0, 0.05, 0.5, 2.0, 10.0])

    def R_mm(m, r):
        st_ = m.sigma_t_prime[0]
        return dipole_profile(r * st_, albedo_prime=m.albedo_prime[0], eta=eta) * st_**2

    # c s/(c s + c a) may round differently from s/(s+a) unless c is a power of two
    rtol = _albedo_rounding_rtol(base.albedo_prime[0], r_mm[-1] * base.sigma_t_prime[0])
    if math.log2(c).is_integer():
        assert scaled.albedo_prime[0] == base.albedo_prime[0]
        rtol = 4 * EPS
    np.testing.assert_allclose(R_mm(scaled, r_mm / c), c**2 * R_mm(base, r_mm), rtol=rtol, atol=0)
    np.testing.assert_allclose(_dipole_mm(scaled, r_mm / c), c**2 * _dipole_mm(base, r_mm), rtol=1e-13, atol=0)


def test_dipole_profile_ketchup_material_warns_but_is_finite():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = Material.preset("ketchup")
    assert any(issubclass(w.category, DiffusionValidityWarning) for w in caught)
    R = dipole_profile(np.array([0.0, 1.0, 1e3]), albedo_prime=m.albedo_prime[2], eta=m.eta)
    assert np.all(np.isfinite(R)) and R[0] > R[1] > R[2] >= 0


# --- tail and cutoff (used to choose neighbourhood radii) ---------------------------------------------------
@pytest.mark.parametrize("albedo,eta", [(1 / 1.01, 1.3), (0.999, 1.0), (0.5, 2.0), (0.02, 1.3)])
def test_dipole_tail_reflectance_matches_quadrature(albedo, eta):
    for r in (0.0, 0.7, 3.0, 12.0):
        num, _ = integrate.quad(lambda x: 2 * np.pi * x * dipole_profile(x, albedo_prime=albedo, eta=eta), r, np.inf,
                      epsabs=0, epsrel=1e-12, limit=400)
        assert dipole_tail_reflectance(r, albedo_prime=albedo, eta=eta) == pytest.approx(num, rel=1e-9)
    assert dipole_tail_reflectance(0.0, albedo_prime=albedo, eta=eta) == pytest.approx(
        dipole_total_reflectance(albedo_prime=albedo, eta=eta), rel=1e-15)


@pytest.mark.parametrize("tol", [1e-2, 1e-4, 1e-6])
def test_dipole_cutoff_radius_leaves_tol_of_energy(tol):
    kw = dict(albedo_prime=1 / 1.01, eta=1.3)
    r = dipole_cutoff_radius(tol, **kw)
    total = dipole_total_reflectance(**kw)
    assert dipole_tail_reflectance(r, **kw) <= tol * total * (1 + 1e-9)
    assert dipole_tail_reflectance(r * (1 - 1e-6), **kw) > tol * total


# --- one implementation of the closed form (kernels/dipole.py: dipole_diffuse_reflectance) ------------------
R_FORM = np.concatenate([[0.0, 1e-300, 1e-8], np.geomspace(1e-3, 3e3, 600)])
MATERIALS_OPT = [(1 / 1.01, 1.3), (1.0, 1.0), (0.3, 2.0), (0.02, 1.3)]


@pytest.mark.parametrize("albedo,eta", MATERIALS_OPT)
def test_dipole_profile_is_the_compiled_scalar_closed_form(albedo, eta):
    """dipole_profile evaluates dipole_diffuse_reflectance elementwise (through a compiled ufunc)."""
    p = diffusion_params(albedo, eta)
    want = [dipole_diffuse_reflectance(r, float(p.albedo_prime), float(p.mu), float(p.z_r), float(p.z_v))
            for r in R_FORM]
    np.testing.assert_allclose(dipole_profile(R_FORM, albedo_prime=albedo, eta=eta), want, rtol=1e-15, atol=0)


@pytest.mark.parametrize("albedo,eta", MATERIALS_OPT)
def test_dipole_profile_agrees_with_the_numpy_closed_form(albedo, eta):
    """The same expression in numpy (the former implementation, with d**3 by pow): within 1e-15 relative."""
    p = diffusion_params(albedo, eta)
    d_r = np.sqrt(R_FORM**2 + p.z_r**2)
    d_v = np.sqrt(R_FORM**2 + p.z_v**2)
    g = lambda d: (p.mu * d + 1.0) * np.exp(-p.mu * d) / d**3  # noqa: E731
    want = p.albedo_prime / (4.0 * np.pi) * (p.z_r * g(d_r) + p.z_v * g(d_v))
    np.testing.assert_allclose(dipole_profile(R_FORM, albedo_prime=albedo, eta=eta), want, rtol=1e-15, atol=0)


def test_dipole_diffuse_reflectance_log_gain_scales_the_profile():
    """log_gain = 0 is R_d bit for bit; otherwise R_d e^log_gain, without overflow of e^log_gain alone."""
    p = diffusion_params(1 / 1.01, 1.3)
    args = (float(p.albedo_prime), float(p.mu), float(p.z_r), float(p.z_v))
    for r in (0.0, 0.5, 7.0, 40.0):
        rd = dipole_diffuse_reflectance(r, *args)
        assert dipole_diffuse_reflectance(r, *args, 0.0) == rd
        for gain in (-3.0, 0.25, 5.0):
            assert dipole_diffuse_reflectance(r, *args, gain) == pytest.approx(rd * math.exp(gain), rel=4e-15)
    # e^800 overflows, R_d(8000) e^800 does not (mu r ~ 1400)
    far = dipole_diffuse_reflectance(8000.0, *args, 800.0)
    assert 0.0 < far < math.inf


def test_dipole_profile_broadcasts_material_arrays():
    albedo = np.array([[0.5], [0.9], [1.0]])
    r = np.array([0.0, 1.0, 10.0, 100.0])
    got = dipole_profile(r, albedo_prime=albedo, eta=1.3)
    assert got.shape == (3, 4) and got.dtype == np.float64
    for i, a in enumerate(albedo[:, 0]):
        np.testing.assert_array_equal(got[i], dipole_profile(r, albedo_prime=a, eta=1.3))
    scalar = dipole_profile(2.0, albedo_prime=0.9, eta=1.3)
    assert np.ndim(scalar) == 0 and scalar == dipole_profile([2.0], albedo_prime=0.9, eta=1.3)[0]
