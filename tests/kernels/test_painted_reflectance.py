"""The painted colour's inversion (docs/physics.md §17, eqs. (105)-(106)): the model's total diffuse reflectance,
vectorised, against an independent route (the quadrature of the near-field profile over the plane), and its
inverse by round trips, a hypothesis property over the physical range, and the presets' own albedos."""
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import quad

from meshshade.errors import MaterialError
from meshshade.kernels.near_field import near_field_model, near_field_profile
from meshshade.kernels.painted_reflectance import (ALBEDO_MAX, albedo_for_reflectance, model_total_reflectance,
                                                   reflectance_range)
from meshshade.materials import Material


@pytest.mark.parametrize("albedo, eta, g", [(0.6, 1.3, 0.0), (0.95, 1.4, 0.5), (0.999, 1.0, 0.0),
                                            (0.3, 2.2, 0.8)])
def test_total_against_the_profile_integrated_over_the_plane(albedo, eta, g):
    # independent route: int_0^inf 2 pi r R_near(r) dr of the pointwise profile (single scattering's angular
    # integral and the dipoles' point values), by adaptive quadrature in u = ln r; not the closed-form totals
    f = lambda u: 2.0 * math.pi * math.exp(2.0 * u) * float(near_field_profile(math.exp(u), albedo_prime=albedo,
                                                                               eta=eta, g=g))  # noqa: E731
    pieces = [(-30.0, -5.0), (-5.0, 0.0), (0.0, 3.0), (3.0, 6.0)]
    ref = sum(quad(f, a, b, epsabs=0.0, epsrel=1e-10, limit=400)[0] for a, b in pieces)
    got = float(model_total_reflectance(albedo, eta, g))
    assert got == pytest.approx(ref, rel=2e-6)


def test_total_matches_the_near_field_models_total_per_medium():
    a = np.array([0.0, 0.1, 0.5, 0.77, 0.9, 0.99, 0.999, ALBEDO_MAX, 1.0])
    for eta, g in ((1.0, 0.0), (1.33, 0.0), (1.6, 0.4), (2.5, 0.9)):
        ref = np.array([near_field_model(x, eta, g).total() for x in a])
        np.testing.assert_allclose(model_total_reflectance(a, eta, g), ref, rtol=1e-13, atol=0)


def test_round_trip_and_shape():
    C = np.array([[0.05, 0.2, 0.5], [0.8, 0.95, 0.5]])
    a = albedo_for_reflectance(C, 1.3)
    assert a.shape == C.shape
    np.testing.assert_allclose(model_total_reflectance(a, 1.3), C, rtol=0, atol=1e-14)
    assert a[0, 2] == a[1, 2]                      # a repeated value is solved once, the same
    assert np.all(np.diff(albedo_for_reflectance(np.linspace(0.03, 0.9, 50), 1.3)) > 0)   # monotone


@given(eta=st.floats(1.0, 2.5), g=st.floats(0.0, 0.9), u=st.floats(1e-6, 1.0 - 1e-6))
def test_inversion_over_the_physical_range(eta, g, u):
    lo, hi = reflectance_range(eta, g)
    C = lo + u * (hi - lo)
    a = float(albedo_for_reflectance(C, eta, g))
    assert 0.0 <= a <= ALBEDO_MAX
    assert float(model_total_reflectance(a, eta, g)) == pytest.approx(C, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("name", ["skin1", "marble", "wholemilk", "apple", "cream"])
def test_a_presets_own_reflectance_gives_its_albedo(name):
    m = Material.preset(name)
    C = model_total_reflectance(m.albedo_prime, m.eta, m.g)
    np.testing.assert_allclose(albedo_for_reflectance(C, m.eta, m.g), m.albedo_prime, rtol=0, atol=1e-10)


@pytest.mark.parametrize("bad", [0.0, 1.0, -0.1, 1e-5, 0.9999, float("nan")])
def test_colours_no_medium_has_are_refused(bad):
    with pytest.raises(MaterialError, match="painted colour must lie in"):
        albedo_for_reflectance(np.array([0.5, bad]), 1.3)
