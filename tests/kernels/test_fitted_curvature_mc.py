"""The fitted curvature model against Monte Carlo it was not fitted to (docs/physics.md §14).

Reference: fresh exact-shape Monte Carlo runs (meshshade.montecarlo.shapes; another seed than the training set's,
so independent photons) on shapes of radius 1/sigma_tr, the radius the fit held out, and in a medium it held out;
the curvature factor is the ratio to the half-space run on the same rings, as in the training set. Where first
order is out of range (nu > 0.25) the fitted model's mean error over these rings, as a fraction of the first-order
kernel's, was measured at 0.25 (held-out radius, alpha' = 0.9) and 0.30 (held-out medium alpha' = 0.95, eta = 1.4,
radii 1 and 4 / sigma_tr; over the whole held-out set of tools/tables/fit_curvature_model.py: 0.32 and 0.26); the test
asserts the issue's target, 0.5, and no worse than first order (+0.5 % for noise) within its range (measured 1.6 %
against 2.5 %). With the fitted terms zeroed (the exponentiated first order) both fail.

The held-out medium case (two radii, 13 runs of 1e6 photons: about 25 s of CPU) is slow; the default suite keeps
the held-out radius case (5 runs, about 8 s). Fewer photons is no cheaper way: the rings kept (relative standard
error below 2 %) thin out to the ones near the entry point (measured at 3e5: 22-29 out of range, fewer than the 30
asked for), so the test would no longer see where first order fails most."""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.kernels.curvature import curvature_factor, curvature_ratios
from meshshade.kernels.fitted_curvature import fitted_curvature_factor, helix_chord_curvature, normal_curvatures
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile, shape_mc_profiles

SEED = 11
PHOTONS = 1_000_000


def _material(albedo, eta):
    return Material(np.full(3, 1.0), np.full(3, (1.0 - albedo) / albedo), eta, 0.0)


@pytest.mark.parametrize("albedo,eta,radii,inside,ratio", [
    pytest.param(0.9, 1.3, (1.0,), False, 0.5, marks=pytest.mark.slow),   # statistical, 11 s
    pytest.param(0.95, 1.4, (1.0, 4.0), True, 0.5, marks=pytest.mark.slow)], ids=["held-out radius", "held-out medium"])
def test_fitted_model_beats_first_order_on_held_out_shapes(albedo, eta, radii, inside, ratio):
    m = _material(albedo, eta)
    st, tr = float(m.sigma_t_prime[0]), float(m.sigma_tr[0])
    s = np.geomspace(0.1, 5.0, 14) / tr
    plane = shape_mc_profile(m, s, shape="plane", photons=PHOTONS, seed=SEED)
    err_fit, err_first, nu_all = [], [], []
    for R, shape, k1, k2, azimuths in ((c / tr, *x) for c in radii for x in (
            ("sphere", tr / c, tr / c, (0.0,)), ("cavity", -tr / c, -tr / c, (0.0,)),
            ("cylinder", tr / c, 0.0, (0.0, 45.0, 90.0)), ("bore", 0.0, -tr / c, (0.0, 90.0)))):
        ss = s[s * 1.1 + 0.05 < np.pi * R] if shape in ("sphere", "cavity") else s
        runs = shape_mc_profiles(m, ss, shape=shape, radius_mm=R, azimuths_deg=azimuths, photons=PHOTONS,
                                 seed=SEED, sector_deg=10.0)
        for az, p in zip(azimuths, runs):
            n = ss.size
            y = p.reflectance[0] / plane.reflectance[0, :n]
            sig = np.hypot(p.stderr[0] / p.reflectance[0], plane.stderr[0, :n] / plane.reflectance[0, :n])
            phi = np.radians(90.0 - az if shape == "bore" else az)   # from the first principal direction
            r = ss * st
            along = None
            if shape in ("cylinder", "bore"):
                sign = 1.0 if shape == "cylinder" else -1.0
                along = sign * helix_chord_curvature(r, np.radians(az), R * st)
            fit = fitted_curvature_factor(r, phi, k1 / st, k2 / st, albedo_prime=albedo, eta=eta, k_along_opt=along)
            a, b = curvature_ratios(r, albedo_prime=albedo, eta=eta)
            ka, kc, _ = normal_curvatures(phi, k1 / st, k2 / st)
            first = curvature_factor(ka * a + kc * b, "soft")
            nu = max(abs(k1), abs(k2)) / st * (np.abs(a) + np.abs(b) + 1.0)
            ok = np.isfinite(y) & (sig < 0.02)
            err_fit.append(np.abs(fit / y - 1)[ok])
            err_first.append(np.abs(first / y - 1)[ok])
            nu_all.append(nu[ok])
    ef, e1, nu = (np.concatenate(x) for x in (err_fit, err_first, nu_all))
    out = nu > 0.25
    assert out.sum() > 30
    assert ef[out].mean() <= ratio * e1[out].mean(), (ef[out].mean(), e1[out].mean())
    if inside:
        assert (~out).sum() > 5
        assert ef[~out].mean() <= e1[~out].mean() + 0.005, (ef[~out].mean(), e1[~out].mean())


def test_hollow_shapes_tend_to_the_half_space():
    """A cavity and a bore of 10 m radius are the half-space on a 10 mm scale: their profiles and totals agree with
    the plane's within the runs' errors (same seed, so mostly the same photons: the cavity's rings match to 0.1 %;
    the bore's tally only a 15-degree sector of azimuths, so they carry their own noise)."""
    m = _material(0.99, 1.3)
    s = np.array([0.3, 1.0, 3.0, 10.0])
    plane = shape_mc_profile(m, s, shape="plane", photons=200_000, seed=SEED)
    for shape in ("cavity", "bore"):
        p = shape_mc_profile(m, s, shape=shape, radius_mm=1e4, photons=200_000, seed=SEED)
        assert np.all(np.abs(p.reflectance[0] - plane.reflectance[0])
                      <= 3.0 * p.stderr[0] + 1e-3 * plane.reflectance[0])
        assert p.total[0] == pytest.approx(plane.total[0], abs=3 * plane.total_stderr[0] + 1e-3)
