"""The fitted curvature model (docs/physics.md §14, eqs. (82)-(84)): its exact limits, the compiled loop against
the numpy twin, positivity and bounds over the full physical range, and its saturation.

The Monte Carlo checks (held-out shapes, the exact sphere and cylinder) are in test_fitted_curvature_mc.py."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.kernels import fitted_curvature_table as table
from meshshade.kernels.curvature import CurvatureTable, curvature_profile, curvature_ratios
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.fitted_curvature import (E_LIN, E_SAT, FEATURES, N_BASE, N_SWITCH, effective_coefficients,
                                                fitted_curvature_factor, fitted_curvature_profile,
                                                fitted_dipole_profile, fitted_exponent, fitted_features,
                                                fitted_row_table, fitted_saturation, matched_table,
                                                near_source_functions, normal_curvatures)
from meshshade.kernels.near_field import near_field_profile
from meshshade.kernels.optics import diffusion_params

MEDIA = [(0.99, 1.3, 0.0), (0.8, 1.0, 0.0), (0.999, 1.5, 0.8)]


@pytest.mark.parametrize("a,eta,g", MEDIA)
def test_flat_surface_is_the_near_field_base_exactly(a, eta, g):
    r = np.geomspace(1e-3, 60.0, 50)
    np.testing.assert_array_equal(fitted_curvature_factor(r, 0.7, 0.0, 0.0, albedo_prime=a, eta=eta), 1.0)
    np.testing.assert_array_equal(fitted_curvature_profile(r, 0.7, 0.0, 0.0, albedo_prime=a, eta=eta, g=g),
                                  near_field_profile(r, albedo_prime=a, eta=eta, g=g))
    tab = CurvatureTable(a, eta, 80.0)
    np.testing.assert_array_equal(fitted_dipole_profile(tab, r, 0.3, k1_opt=0.0, k2_opt=0.0),
                                  dipole_profile(r, albedo_prime=a, eta=eta))


@pytest.mark.parametrize("a,eta", [(0.99, 1.3), (0.9, 1.0)])
def test_first_order_term_is_the_kernel_and_the_rest_is_second_order(a, eta):
    """ln F = delta + (near-source first-order terms) + O(k^2): the remainder after the first-order part falls by 4
    when k halves, and far from the source (r = 30, where e3 = e^-10) the first-order part is the kernel's delta,
    i.e. F = 1 + delta + O(k^2) against the §7 kernel's own R/R_d."""
    r = np.array([0.2, 1.0, 3.0, 10.0, 30.0])
    phi = 0.4
    k1, k2 = 0.8, -0.3
    aa, bb = curvature_ratios(r, albedo_prime=a, eta=eta)
    a1, b1 = curvature_ratios(r, albedo_prime=a, eta=1.0)
    Am1 = float(diffusion_params(a, eta).A) - 1.0
    th = table.COEF
    first_order = [0, 1, 2, 3] + [N_BASE + N_SWITCH + j for j in range(4)]   # the near-source terms
    rem = []
    for eps in (4e-5, 2e-5, 1e-5):   # small enough that the third-order switches are < 1 % of the remainder
        ka, kc, t2 = normal_curvatures(phi, eps * k1, eps * k2)
        X = fitted_features(r, ka, kc, t2, aa, bb, a1, b1, Am1)
        first = ka * aa + kc * bb + X[..., first_order] @ th[first_order]
        # the model's own numpy form (direct-quadrature ratios): at k ~ 1e-5 the remainder is ~1e-10 of ln F, below
        # the compiled kernel's table error (test_compiled_loop_matches_the_numpy_twin checks the two agree)
        lnF = fitted_exponent(r, ka, kc, t2, aa, bb, a1, b1, Am1)
        rem.append(lnF - first)
    rem = np.array(rem)
    ok = np.abs(rem[0]) > 1e-12
    np.testing.assert_allclose(rem[0][ok] / rem[1][ok], 4.0, rtol=0.02)
    np.testing.assert_allclose(rem[1][ok] / rem[2][ok], 4.0, rtol=0.02)
    eps = 1e-3
    F = fitted_curvature_factor(30.0, phi, eps * k1, eps * k2, albedo_prime=a, eta=eta)
    R1 = curvature_profile(30.0, phi, k1_opt=eps * k1, k2_opt=eps * k2, albedo_prime=a, eta=eta, policy="clamp")
    delta = R1 / dipole_profile(30.0, albedo_prime=a, eta=eta) - 1.0   # "clamp" is R_d (1 + delta) exactly here
    assert abs(delta) > 1e-3
    assert abs(math.log(F) - delta) < 2.0 * delta ** 2 + 1e-6


@pytest.mark.parametrize("a,eta", [(0.99, 1.3), (0.6, 1.5)])
def test_compiled_loop_matches_the_numpy_twin(a, eta):
    rng = np.random.default_rng(7)
    n = 4000
    r = np.concatenate([rng.random(n) * 80.0, [0.0, 1e-9]])
    phi = rng.uniform(-np.pi, np.pi, r.size)
    k1, k2 = rng.normal(0, 0.4, r.size), rng.normal(0, 0.4, r.size)
    tab = CurvatureTable(a, eta, 40.0)   # shorter than r: the direct quadrature beyond the table is exercised
    aa, bb = curvature_ratios(r, albedo_prime=a, eta=eta)
    a1, b1 = curvature_ratios(r, albedo_prime=a, eta=1.0)
    Am1 = float(diffusion_params(a, eta).A) - 1.0
    ka, kc, t2 = normal_curvatures(phi, k1, k2)
    for theta in (table.COEF, rng.normal(0, 1, len(FEATURES))):
        got = fitted_dipole_profile(tab, r, phi, k1_opt=k1, k2_opt=k2, coef=theta)
        want = dipole_profile(r, albedo_prime=a, eta=eta) * np.exp(
            fitted_exponent(r, ka, kc, t2, aa, bb, a1, b1, Am1, theta))
        m = want > 1e-280
        # the compiled table's cubic pieces (test below) bound the difference: ~1e-7 here, formula slips are > 1e-3
        np.testing.assert_allclose(got[m], want[m], rtol=2e-6)
        got2 = fitted_dipole_profile(tab, r, cos2phi=np.cos(2 * phi), k1_opt=k1, k2_opt=k2, coef=theta)
        np.testing.assert_allclose(got2[m], want[m], rtol=2e-6)
        # the factor the profiles use is the same compiled evaluation
        F = fitted_curvature_factor(r, phi, k1, k2, albedo_prime=a, eta=eta, coef=theta)
        np.testing.assert_allclose(F, np.exp(fitted_exponent(r, ka, kc, t2, aa, bb, a1, b1, Am1, theta)), rtol=2e-6)


@pytest.mark.parametrize("a,eta", [(0.99, 1.3), (0.6, 1.5), (0.999, 1.0)])
def test_compiled_table_interpolates_its_functions(a, eta):
    """fitted_row_table: the material's a, b as the curvature table (degree 7), the matched boundary's a1, b1 and
    the near-source functions g, e2 as cubics; against their direct evaluation (quadrature, exponentials) at random
    distances, within 1e-8 (a1, b1) and 3e-6 (g, e2) of the largest value, and a, b within 1e-9."""
    tab = CurvatureTable(a, eta, 60.0)
    th = effective_coefficients(table.COEF, float(diffusion_params(a, eta).A) - 1.0)
    row = fitted_row_table(tab, matched_table(tab), th)
    r = np.random.default_rng(5).random(3000) * 60.0
    u = np.sqrt(r) * 16.0
    iu = u.astype(int)
    t = 2.0 * (u - iu) - 1.0
    c = row[iu]
    got = [sum(c[:, 2 * j + q] * t ** j for j in range(8)) for q in (0, 1)]
    got += [sum(c[:, 16 + 4 * j + f] * t ** j for j in range(4)) for f in range(4)]
    aa, bb = curvature_ratios(r, albedo_prime=a, eta=eta)
    a1, b1 = curvature_ratios(r, albedo_prime=a, eta=1.0)
    g, e2 = near_source_functions(r, th)
    for name, x, want, tol in (("a", got[0], aa, 1e-9), ("b", got[1], bb, 1e-9), ("a1", got[2], a1, 1e-8),
                               ("b1", got[3], b1, 1e-8), ("g", got[4], g, 3e-6), ("e2", got[5], e2, 3e-6)):
        assert np.max(np.abs(x - want)) <= tol * np.max(np.abs(want)), name


def test_saturation_is_identity_inside_and_smooth_and_bounded_outside():
    E = np.linspace(-E_LIN, E_LIN, 101)
    np.testing.assert_array_equal(fitted_saturation(E), E)
    big = np.array([E_LIN + 1e-6, 10.0, 1e3, 1e300, np.inf])
    s = fitted_saturation(np.concatenate([big, -big]))
    assert np.all(np.abs(s) <= E_SAT) and np.all(np.abs(s[:2]) < E_SAT)   # tanh rounds to 1 in float far out
    h = 1e-4   # slope and curvature continuous at E_LIN (C^2)
    f = lambda x: float(fitted_saturation(x))  # noqa: E731
    slope_out = (f(E_LIN + h) - f(E_LIN)) / h
    assert abs(slope_out - 1.0) < 1e-3
    curv_out = (f(E_LIN + 2 * h) - 2 * f(E_LIN + h) + f(E_LIN)) / h ** 2
    assert abs(curv_out) < 1e-2
    assert np.all(np.diff(fitted_saturation(np.linspace(-10, 10, 2001))) > 0)   # monotone
    assert np.all(np.diff(fitted_saturation(np.linspace(-1e3, 1e3, 2001))) >= 0)


@settings(max_examples=300, deadline=None)
@given(r=st.floats(0.0, 1e4), phi=st.floats(-math.pi, math.pi), k1=st.floats(-20.0, 20.0),
       k2=st.floats(-20.0, 20.0), a=st.floats(0.0, 1.0), eta=st.floats(1.0, 2.5))
def test_positive_finite_and_bounded_over_the_physical_range(r, phi, k1, k2, a, eta):
    """Any distance, curvature radius down to 1/20 of a transport length either sign, any albedo and index:
    the factor is finite, positive and within e^{+-E_SAT} (eq. (84)), and the compiled loop agrees."""
    F = float(fitted_curvature_factor(r, phi, k1, k2, albedo_prime=a, eta=eta))
    assert math.isfinite(F) and math.exp(-E_SAT) * (1 - 1e-12) <= F <= math.exp(E_SAT) * (1 + 1e-12)
    Rd = float(dipole_profile(r, albedo_prime=a, eta=eta))
    got = float(fitted_dipole_profile(CurvatureTable(a, eta, 10.0), r, phi, k1_opt=k1, k2_opt=k2))
    assert math.isfinite(got) and got >= 0.0
    if Rd > 1e-250:   # the compiled table's cubics: exponent errors ~2e-6 |H| (test above)
        assert got == pytest.approx(Rd * F, rel=3e-6 * (1.0 + abs(k1) + abs(k2)))


def test_rejects_bad_input_clearly():
    tab = CurvatureTable(0.9, 1.3, 10.0)
    for bad in (dict(rho_opt=-1.0, phi=0.0), dict(rho_opt=np.nan, phi=0.0), dict(rho_opt=1.0, phi=np.inf)):
        with pytest.raises(ValueError, match="finite"):
            fitted_dipole_profile(tab, bad["rho_opt"], bad["phi"], k1_opt=0.1, k2_opt=0.0)
    with pytest.raises(ValueError, match="finite"):
        fitted_dipole_profile(tab, 1.0, 0.0, k1_opt=np.nan, k2_opt=0.0)
    with pytest.raises(ValueError, match="exactly one"):
        fitted_dipole_profile(tab, 1.0, k1_opt=0.1, k2_opt=0.0)
    with pytest.raises(ValueError, match="coefficients"):
        fitted_dipole_profile(tab, 1.0, 0.0, k1_opt=0.1, k2_opt=0.0, coef=np.zeros(3))
