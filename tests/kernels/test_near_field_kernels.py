"""Single scattering and photon beam diffusion on the half-space (meshshade.kernels.single_scattering,
meshshade.kernels.beam_diffusion).

References: mpmath quadrature of the defining integrals (Fresnel moments, the single-scattering depth integral),
the closed-form totals, the planar dipole (a single Jensen source at depth 1), and the exact half-space Monte Carlo's
order-1 ring tallies (an independent simulation).
"""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from meshshade.errors import MaterialError
from meshshade.kernels.beam_diffusion import (beam_diffusion_profile, beam_diffusion_ring, beam_diffusion_total,
                                              dipole_variant, fresnel_moments, point_source_reflectance)
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.single_scattering import (single_scattering_profile, single_scattering_ring,
                                                 single_scattering_total)
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile

mp.mp.dps = 30


def mp_fresnel_inside(mu, eta):
    """Unpolarised Fresnel reflectance from inside (index eta) at cosine mu, in mpmath."""
    sin_t = eta * mp.sqrt(1 - mu * mu)
    if sin_t >= 1:
        return mp.mpf(1)
    cos_t = mp.sqrt(1 - sin_t * sin_t)
    rs = (eta * mu - cos_t) / (eta * mu + cos_t)
    rp = (eta * cos_t - mu) / (eta * cos_t + mu)
    return (rs * rs + rp * rp) / 2


def mp_single_scattering(r, a, eta, g, cos_t=1.0):
    """R1(r) by mpmath quadrature of the depth integral (physics.md eqs. (71), (81)): first scattering at depth z
    with density (sigma_s/cos_t) exp(-sigma_t z/cos_t), then straight out through the Fresnel boundary."""
    sigma_s = a / (1 - g)
    sigma_t = sigma_s + 1 - a

    def integrand(z):
        l = mp.sqrt(r * r + z * z)
        c = -z / l
        p = (1 - g * g) / (4 * mp.pi * (1 + g * g - 2 * g * c) ** 1.5)
        return mp.exp(-sigma_t * (z / cos_t + l)) * p * (1 - mp_fresnel_inside(z / l, mp.mpf(eta))) * z / l ** 3
    mu_c = math.sqrt(1 - 1 / eta ** 2)   # total internal reflection below: a kink at z_c, split there
    z_c = r * mu_c / math.sqrt(1 - mu_c * mu_c)
    return sigma_s / cos_t * mp.quad(integrand, sorted({0, z_c, r, 10 * r + 1}) + [mp.inf])


@pytest.mark.parametrize("eta", [1.1, 1.3, 1.33, 1.5, 2.0])
def test_fresnel_moments_against_mpmath(eta):
    e = mp.mpf(eta)
    mu_c = mp.sqrt(1 - 1 / (e * e))
    c1 = mu_c ** 2 / 2 + mp.quad(lambda m: mp_fresnel_inside(m, e) * m, [mu_c, 1])
    c2 = mu_c ** 3 / 3 + mp.quad(lambda m: mp_fresnel_inside(m, e) * m * m, [mu_c, 1])
    got = fresnel_moments(eta)
    assert got[0] == pytest.approx(float(c1), rel=1e-9) and got[1] == pytest.approx(float(c2), rel=1e-9)
    assert fresnel_moments(1.0) == (0.0, 0.0)


@pytest.mark.parametrize("a, eta", [(0.99, 1.3), (0.9, 1.0), (0.999, 1.4), (0.6, 1.3)])
def test_jensen_source_at_depth_one_is_the_planar_dipole(a, eta):
    r = np.array([0.0, 0.05, 0.5, 2.0, 10.0])
    np.testing.assert_allclose(a * point_source_reflectance(r, 1.0, albedo_prime=a, eta=eta, variant="jensen"),
                               dipole_profile(r, albedo_prime=a, eta=eta), rtol=1e-13)


@pytest.mark.parametrize("variant", ["jensen", "better"])
@pytest.mark.parametrize("a, eta", [(0.99, 1.3), (0.9, 1.0), (0.999, 1.4), (0.7, 1.33)])
def test_beam_profile_integrates_to_the_closed_form_total(variant, a, eta):
    f = lambda r: 2 * math.pi * r * beam_diffusion_profile(r, albedo_prime=a, eta=eta, variant=variant)  # noqa: E731
    total = sum(quad(f, lo, hi, limit=400, epsrel=1e-11)[0] for lo, hi in ((0, 0.1), (0.1, 1), (1, 10), (10, 400)))
    assert total == pytest.approx(beam_diffusion_total(albedo_prime=a, eta=eta, variant=variant), rel=1e-8)


@pytest.mark.parametrize("a, eta, g", [(0.99, 1.3, 0.0), (0.9, 1.0, 0.8), (0.7, 1.4, 0.5)])
def test_ring_averages_are_averages_of_the_profiles(a, eta, g):
    for lo, hi in ((0.0, 0.05), (0.05, 0.15), (0.45, 0.55), (1.8, 2.2)):
        area = math.pi * (hi * hi - lo * lo)
        for ring, prof in ((single_scattering_ring, lambda r: single_scattering_profile(r, albedo_prime=a, eta=eta,
                                                                                        g=g)),
                           (lambda lo_, hi_, **k: beam_diffusion_ring(lo_, hi_, albedo_prime=a, eta=eta),
                            lambda r: beam_diffusion_profile(r, albedo_prime=a, eta=eta))):
            want = quad(lambda r: 2 * math.pi * r * prof(r), lo, hi, limit=200, epsrel=1e-10)[0] / area
            got = ring(lo, hi, albedo_prime=a, eta=eta, g=g) if ring is single_scattering_ring else ring(lo, hi)
            assert float(got) == pytest.approx(want, rel=2e-6), (ring, lo, hi)


@pytest.mark.parametrize("a, eta, g", [(0.99, 1.3, 0.0), (0.9, 1.0, 0.8), (0.6, 1.5, 0.5)])
def test_single_scattering_profile_against_mpmath(a, eta, g):
    for r in (0.01, 0.3, 2.0):
        ref = mp_single_scattering(r, a, eta, g)
        got = single_scattering_profile(r, albedo_prime=a, eta=eta, g=g)
        assert got == pytest.approx(float(ref), rel=1e-7), r
    tot = quad(lambda r: 2 * math.pi * r * single_scattering_profile(r, albedo_prime=a, eta=eta, g=g), 0, 50,
               limit=400, points=(0.1, 1, 5))[0]
    assert single_scattering_total(albedo_prime=a, eta=eta, g=g) == pytest.approx(tot, rel=1e-7)


def test_single_scattering_is_the_monte_carlo_first_order():
    """Independent simulation: the exact half-space Monte Carlo's order-1 ring tallies (mm units)."""
    m = Material(1.5, 0.05, 1.3, 0.6)
    s = np.array([0.03, 0.1, 0.3])
    mc = shape_mc_profile(m, s, shape="plane", photons=300_000, seed=9)
    st_ = float(m.sigma_t_prime[0])
    model = single_scattering_ring(mc.lo * st_, mc.hi * st_, albedo_prime=float(m.albedo_prime[0]), eta=m.eta,
                                   g=m.g) * st_ * st_
    assert np.all(np.abs(model - mc.single[0]) < 4 * mc.single_stderr[0]), (model, mc.single[0])


@settings(max_examples=60, deadline=None)
@given(a=st.floats(0.05, 0.99999), eta=st.floats(1.0, 2.5), g=st.floats(-0.9, 0.95),
       r=st.floats(1e-6, 1e3))
def test_profiles_are_finite_positive_and_bounded_by_the_totals(a, eta, g, r):
    ss = single_scattering_profile(r, albedo_prime=a, eta=eta, g=g)
    bd = beam_diffusion_profile(r, albedo_prime=a, eta=eta)
    assert np.isfinite(ss) and ss >= 0 and np.isfinite(bd) and bd >= 0
    assert 0 < single_scattering_total(albedo_prime=a, eta=eta, g=g) < 1
    assert 0 < beam_diffusion_total(albedo_prime=a, eta=eta) < 1.5
    v = dipole_variant(a, eta)
    assert v.D > 0 and v.z_b > 0 and v.c_phi > 0 and v.c_E > 0


def test_bad_material_is_refused():
    with pytest.raises(MaterialError):
        single_scattering_profile(1.0, albedo_prime=1.2, eta=1.3)
    with pytest.raises(MaterialError):
        single_scattering_profile(1.0, albedo_prime=0.9, eta=1.3, g=1.0)
    with pytest.raises(MaterialError):
        beam_diffusion_profile(1.0, albedo_prime=0.9, eta=3.0)


@pytest.mark.parametrize("a, eta, t", [(0.99, 1.3, 0.03), (0.7, 1.0, 1.0), (0.999, 2.0, 4.0), (0.5, 1.4, 0.01)])
def test_point_source_ring_and_total_closed_forms(a, eta, t):
    from meshshade.kernels.beam_diffusion import point_source_ring, point_source_total

    f = lambda r: 2 * math.pi * r * point_source_reflectance(r, t, albedo_prime=a, eta=eta)  # noqa: E731
    for lo, hi in ((0.0, 0.01), (0.05, 0.15), (2.0, 3.0)):
        want = quad(f, lo, hi, epsrel=1e-12, limit=200)[0] / (math.pi * (hi * hi - lo * lo))
        assert point_source_ring(lo, hi, t, albedo_prime=a, eta=eta) == pytest.approx(want, rel=1e-9)
    total = sum(quad(f, lo, hi, epsrel=1e-12, limit=400)[0] for lo, hi in ((0, t), (t, 10 * t + 1), (10 * t + 1, 2e3)))
    assert point_source_total(t, albedo_prime=a, eta=eta) == pytest.approx(total, rel=1e-8)


@pytest.mark.parametrize("a, eta, g, cos_t", [(0.99, 1.3, 0.0, 0.7), (0.9, 1.0, 0.8, 0.3), (0.6, 1.5, 0.5, 0.85)])
def test_oblique_single_scattering_against_mpmath(a, eta, g, cos_t):
    """eq. (81): first scattering at depth z with density (sigma_s/cos_t) exp(-sigma_t z/cos_t), the rest as at
    normal incidence; the depth integral in mpmath, the ring and total from the profile by quadrature."""
    for r in (0.01, 0.3, 2.0):
        ref = mp_single_scattering(r, a, eta, g, cos_t)
        got = single_scattering_profile(r, albedo_prime=a, eta=eta, g=g, cos_t=cos_t)
        assert got == pytest.approx(float(ref), rel=1e-7), r
    prof = lambda r: 2 * math.pi * r * single_scattering_profile(r, albedo_prime=a, eta=eta, g=g, cos_t=cos_t)  # noqa: E731
    tot = quad(prof, 0, 50, limit=400, points=(0.1, 1, 5))[0]
    assert single_scattering_total(albedo_prime=a, eta=eta, g=g, cos_t=cos_t) == pytest.approx(tot, rel=1e-7)
    ring = quad(prof, 0.2, 0.7, limit=200)[0] / (math.pi * (0.7 ** 2 - 0.2 ** 2))
    assert float(single_scattering_ring(0.2, 0.7, albedo_prime=a, eta=eta, g=g, cos_t=cos_t)) == pytest.approx(
        ring, rel=1e-7)
