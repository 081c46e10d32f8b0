"""The one compiled kernel evaluation (meshshade/surface/kernel_evaluation.py) against independent routes.

References: the curved kernel written out here from its definition (docs/physics.md eqs. (49)-(53), soft policy
and entry-point cap) with the ratios a, b by direct quadrature (``curvature_ratios``, not the table the evaluation
reads); the fitted model's public profile (``fitted_dipole_profile``, its own blockwise loop); the exact sphere
series at each pair (``sphere_series_profile``); the planar dipole in numpy from Jensen's formula. PairKernel
(the near field and the direct sum) and the far field's per-pair call must give the same numbers because they
are the same function; these tests check that function.
"""
from __future__ import annotations

import inspect

import numpy as np
import pytest

from meshshade.kernels.curvature import curvature_ratios
from meshshade.kernels.curvature.policies import DELTA_SAT
from meshshade.kernels.fitted_curvature import fitted_dipole_profile, matched_table
from meshshade.kernels.curvature import CurvatureTable
from meshshade.kernels.optics import diffusion_params
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.materials import Material
from meshshade.surface import hierarchy_loops
from meshshade.surface.auto import AutoPlan
from meshshade.surface.kernel_evaluation import SphereTables, kernel_params, kernel_values
from meshshade.surface.models import KERNEL_NAMES, MODEL_KERNEL, Kernel
from meshshade.surface.pair_kernel import PairKernel, SourceFrames

MAT = Material([1.0, 0.8, 0.5], [0.01, 0.03, 0.1], 1.3, name="three channels")


def _pairs(n=400, seed=1, k=0.08):
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.0, 12.0, n)
    s[:5] = [0.0, 1e-6, 0.05, 0.3, 30.0]
    phi = rng.uniform(-np.pi, np.pi, n)
    k1, k2 = rng.uniform(-k, k, n), rng.uniform(-k, k, n)
    return s, phi, k1, k2


def _values(kind, c, s, chord, kn, knp, t2, row, params):
    out = np.empty(s.size)
    kernel_values(int(kind), c, chord, s, kn, knp, t2, row, params, out)
    return out


def _dipole_numpy(r, albedo_prime, eta):
    """Jensen et al. 2001 eq. 4 (docs/physics.md eq. (15)), optical units, written out independently."""
    p = diffusion_params(albedo_prime, eta)
    mu, zr, zv = float(p.mu), float(p.z_r), float(p.z_v)
    dr, dv = np.sqrt(r * r + zr * zr), np.sqrt(r * r + zv * zv)
    return albedo_prime / (4 * np.pi) * (zr * (mu * dr + 1) * np.exp(-mu * dr) / dr ** 3
                                         + zv * (mu * dv + 1) * np.exp(-mu * dv) / dv ** 3)


@pytest.mark.parametrize("c", [0, 1, 2])
def test_dipole_kernels_are_jensens_formula(c):
    s, phi, k1, k2 = _pairs()
    chord = 0.9 * s
    p = kernel_params(MAT, 20.0)
    st = MAT.sigma_t_prime[c]
    z = np.zeros(s.size)
    row = np.full(s.size, -1, np.int64)
    ref = _dipole_numpy(s * st, MAT.albedo_prime[c], MAT.eta) * st * st
    np.testing.assert_allclose(_values(Kernel.DIPOLE_SURFACE, c, s, chord, k1, k2, z, row, p), ref, rtol=1e-13)
    ref_chord = _dipole_numpy(chord * st, MAT.albedo_prime[c], MAT.eta) * st * st
    np.testing.assert_allclose(_values(Kernel.DIPOLE_CHORD, c, s, chord, k1, k2, z, row, p), ref_chord, rtol=1e-13)


@pytest.mark.parametrize("c", [0, 2])
def test_curved_kernel_is_its_definition(c):
    """R_d(rho) exp(S(delta)), delta = k_along a + k_across b, S the soft saturation, capped at the entry-point
    value R_d(0) exp(S(max((k1 + k2) a(0), 0))); large curvatures reach the saturation and the cap."""
    s, phi, k1, k2 = _pairs(k=3.0)
    s[5:100] = np.linspace(0.0, 0.5, 95)   # close pairs of strongly curved sources: the cap
    st = MAT.sigma_t_prime[c]
    alb, eta = float(MAT.albedo_prime[c]), MAT.eta
    ka = k1 * np.cos(phi) ** 2 + k2 * np.sin(phi) ** 2
    kc = k1 * np.sin(phi) ** 2 + k2 * np.cos(phi) ** 2
    a, b = curvature_ratios(s * st, albedo_prime=alb, eta=eta)
    soft = lambda d: d / np.sqrt(1 + (d / DELTA_SAT) ** 2)   # noqa: E731
    R = _dipole_numpy(s * st, alb, eta) * np.exp(soft((ka * a + kc * b) / st))
    a0, _ = curvature_ratios(0.0, albedo_prime=alb, eta=eta)
    cap = _dipole_numpy(0.0, alb, eta) * np.exp(soft(np.maximum((ka + kc) / st * a0, 0.0)))
    ref = np.where(R > _dipole_numpy(0.0, alb, eta), np.minimum(R, cap), R) * st * st
    got = _values(Kernel.CURVED, c, s, s, ka, kc, np.zeros(s.size), np.full(s.size, -1, np.int64),
                  kernel_params(MAT, 20.0))
    assert np.sum(ref < R * st * st * (1 - 1e-3)) >= 5   # the cap is reached by some pairs
    np.testing.assert_allclose(got, ref, rtol=1e-9)   # the table's interpolation error is ~3e-11 of |a| + |b|


def test_fitted_kernel_is_the_fitted_profile():
    s, phi, k1, k2 = _pairs()
    c = 1
    st = MAT.sigma_t_prime[c]
    alb, eta = float(MAT.albedo_prime[c]), MAT.eta
    tab = CurvatureTable(alb, eta, 20.0 * st * 1.25)
    ref = fitted_dipole_profile(tab, s * st, phi, k1_opt=k1 / st, k2_opt=k2 / st, matched=matched_table(tab)) * st * st
    ka = k1 * np.cos(phi) ** 2 + k2 * np.sin(phi) ** 2
    kc = k1 * np.sin(phi) ** 2 + k2 * np.cos(phi) ** 2
    t2 = (0.5 * (k1 - k2) * np.sin(2 * phi)) ** 2
    got = _values(Kernel.FITTED, c, s, s, ka, kc, t2, np.full(s.size, -1, np.int64), kernel_params(MAT, 20.0))
    np.testing.assert_allclose(got, ref, rtol=1e-12)


def test_exact_sphere_kernel_is_the_series_and_the_chord_dipole_where_not_convex():
    H = np.array([1 / 20.0, 1 / 20.0001, 1 / 7.0, -0.01])
    tables = SphereTables(MAT)
    rows = tables.rows(H)
    assert rows[0] == rows[1] and rows[2] != rows[0] and rows[3] == -1   # 20 and 20.0001 mm share a 1e-3 bin
    p = kernel_params(MAT, 20.0, tables)
    s = np.linspace(0.0, 40.0, 57)
    for c in range(3):
        st = MAT.sigma_t_prime[c]
        for i in (0, 2):
            R0 = SphereTables.bin_radius(SphereTables.bin_keys(H[i:i + 1])[0])
            ref = sphere_series_profile(np.minimum(s / R0, np.pi), R0_opt=R0 * st, albedo_prime=MAT.albedo_prime[c],
                                        eta=MAT.eta, rtol=1e-12) * st * st
            got = _values(Kernel.EXACT_SPHERE, c, s, s, s, s, s, np.full(s.size, rows[i]), p)
            np.testing.assert_allclose(got, ref, rtol=2e-5)
        got = _values(Kernel.EXACT_SPHERE, c, s, 0.5 * s, s, s, s, np.full(s.size, -1, np.int64), p)
        np.testing.assert_allclose(got, _dipole_numpy(0.5 * s * st, MAT.albedo_prime[c], MAT.eta) * st * st,
                                   rtol=1e-13)


def test_one_enumeration_names_the_plan_codes_and_the_models():
    assert [Kernel(i).name.lower().replace("_", "-") for i in range(1, 4)] == list(KERNEL_NAMES[1:])
    assert Kernel.DIPOLE_SURFACE == 0 and KERNEL_NAMES[0] == "dipole"   # auto's dipole: the surface distance
    assert MODEL_KERNEL["dipole"] == Kernel.DIPOLE_CHORD


def _auto_sources(k1, k2, pairs):
    """Sources with principal curvatures k1, k2 in the xy plane, auto plan codes 0, 1, 2, 3, 0, ... and ``pairs``
    pairs each (s in [0, 10] mm, phi in [-3, 3])."""
    n = len(k1)
    frames = SourceFrames(np.asarray(k1), np.asarray(k2), np.tile([1.0, 0, 0], (n, 1)), np.tile([0, 1.0, 0], (n, 1)),
                          np.tile([0, 0, 1.0], (n, 1)))
    plan = AutoPlan(np.arange(n, dtype=np.int8) % 4, np.ones(n, bool), np.zeros(n, bool))
    return (frames, plan, np.repeat(np.arange(n), pairs), np.tile(np.linspace(0.0, 10.0, pairs), n),
            np.tile(np.linspace(-3.0, 3.0, pairs), n))


def test_pair_kernel_takes_each_sources_kernel_from_the_auto_plan():
    """One call over sources of all four auto kernels equals each source's kernel evaluated alone."""
    rng = np.random.default_rng(3)
    k1, k2 = rng.uniform(0.01, 0.1, 8), rng.uniform(0.01, 0.1, 8)
    frames, plan, src, s, phi = _auto_sources(k1, k2, 50)
    n, d1 = 8, frames.d1
    pk = PairKernel("auto", MAT, frames, plan=plan, reach_mm=20.0)
    got = pk.evaluate(0, src, s, 0.95 * s, phi)
    for i in range(n):
        model = KERNEL_NAMES[plan.kernel[i]]
        one = PairKernel(model if model != "dipole" else "curved", MAT,
                         SourceFrames(*(np.asarray(x)[i:i + 1] for x in (k1, k2, d1, frames.d2, frames.normals))),
                         reach_mm=20.0)
        if model == "dipole":   # auto's dipole is the curved kernel of a flat source: the surface distance
            one.frames = SourceFrames(np.zeros(1), np.zeros(1), d1[:1], frames.d2[:1], frames.normals[:1])
        sel = src == i
        want = one.evaluate(0, np.zeros(sel.sum(), np.int64), s[sel], 0.95 * s[sel], phi[sel])
        np.testing.assert_allclose(got[sel], want, rtol=1e-12, err_msg=model)


def test_the_far_traversal_takes_records_not_positional_tuples():
    for kind in Kernel:
        params = inspect.signature(hierarchy_loops.FAR_TRAVERSE[int(kind)].py_func).parameters
        assert len(params) <= 12, list(params)


def test_compiled_loops_hold_one_kernel_each():
    """One compiled loop per kernel kind, compiled on first use only (a dipole bake compiles no other kernel)."""
    from meshshade.surface import kernel_evaluation

    for table in (kernel_evaluation._VALUES, hierarchy_loops.FAR_TRAVERSE):
        assert set(table) == {int(k) for k in Kernel}
        assert len({id(f) for f in table.values()}) == len(Kernel)
        closure = {f.py_func.__closure__[0].cell_contents for f in table.values()}
        assert closure == {int(k) for k in Kernel}


def test_pair_kernel_reads_sphere_tables_it_grows_in_the_same_call():
    """Mixed kernels with the exact sphere read from tables built during the call (sphere_series_pairs=0, as the
    hierarchical near field): equal to the series at each pair (the bake's default for few pairs)."""
    k = np.linspace(0.02, 0.09, 8)
    frames, plan, src, s, phi = _auto_sources(k, k, 40)
    tables = PairKernel("auto", MAT, frames, plan=plan, reach_mm=20.0, sphere_series_pairs=0)
    series = PairKernel("auto", MAT, frames, plan=plan, reach_mm=20.0)
    for c in range(3):
        got, want = tables.evaluate(c, src, s, s, phi), series.evaluate(c, src, s, s, phi)
        assert np.all(np.isfinite(got))
        # the log-linear table's error peaks near s = 0 on the larger spheres (measured 9.9e-5 at s = 0.26 mm,
        # R0 = 50 mm); tables read before they are built give garbage or NaN
        np.testing.assert_allclose(got, want, rtol=2e-4)
    assert tables.sphere.r0.size == 2   # sources 2 and 6 (plan code 2): two radius bins
