"""The Robin half-space (docs/physics.md eq. (96)) against independent routes.

* eq. (93)'s Hankel integral by scipy quadrature, itself checked against mpmath at 25 digits;
* the closed-form total exp(-mu t) / (1 + 2 A D mu) of eq. (93) (the transform at k = 0);
* the disc integral against an adaptive quadrature of the pointwise exitance;
* the two limits of the Robin length l = 2 A D: Dirichlet (phi -> 0) and Neumann (twice the free-space fluence);
* hypothesis: positive, decreasing in rho, the disc integral increasing to the total, over the physical range.
"""
import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, special

from meshshade.errors import MaterialError
from meshshade.kernels.beam_diffusion import dipole_variant
from meshshade.kernels.robin_halfspace import (robin_point_source_disc, robin_point_source_exitance,
                                               robin_point_source_total)

D, MU, A = 0.4, 0.5, 2.3


def hankel(rho, t, D=D, mu=MU, A=A):
    """Eq. (93) by scipy quadrature: 1/(2 pi) int k J0(k rho) exp(-m t) / (1 + 2 A D m) dk, m = sqrt(k^2 + mu^2)."""
    def f(k):
        m = math.sqrt(k * k + mu * mu)
        return k * special.j0(k * rho) * math.exp(-m * t) / (1.0 + 2.0 * A * D * m)
    return integrate.quad(f, 0.0, 60.0 / t, limit=4000, epsabs=1e-15, epsrel=1e-12)[0] / (2.0 * math.pi)


def test_hankel_reference_against_mpmath():
    mp.mp.dps = 25
    for rho, t in ((0.5, 0.3), (2.0, 1.0)):
        f = lambda k: k * mp.besselj(0, k * rho) * mp.exp(-mp.sqrt(k * k + MU ** 2) * t) / (  # noqa: E731
            1 + 2 * A * D * mp.sqrt(k * k + MU ** 2))
        ref = mp.quad(f, mp.linspace(0, 80, 81) + [mp.inf]) / (2 * mp.pi)
        assert hankel(rho, t) == pytest.approx(float(ref), rel=1e-9)


@pytest.mark.parametrize("t", [0.01, 0.3, 1.0, 3.0])
@pytest.mark.parametrize("rho", [0.0, 0.01, 0.5, 2.0, 8.0])
def test_exitance_equals_the_hankel_integral(rho, t):
    """Measured within 1e-12 everywhere (machine precision near the peak)."""
    assert robin_point_source_exitance(rho, t, D=D, mu=MU, A=A) == pytest.approx(hankel(rho, t), rel=1e-10)


@pytest.mark.parametrize("t", [0.01, 0.3, 2.0])
def test_total_and_disc(t):
    total = math.exp(-MU * t) / (1.0 + 2.0 * A * D * MU)
    assert robin_point_source_total(t, D=D, mu=MU, A=A) == pytest.approx(total, rel=1e-14)
    assert robin_point_source_disc(np.inf, t, D=D, mu=MU, A=A) == pytest.approx(total, rel=1e-14)
    assert robin_point_source_disc(80.0, t, D=D, mu=MU, A=A) == pytest.approx(total, rel=1e-10)
    for a in (0.05, 1.0, 5.0):
        quad = integrate.quad(lambda r: 2 * math.pi * r * robin_point_source_exitance(r, t, D=D, mu=MU, A=A), 0, a,
                              points=[t] if t < a else None, limit=500, epsrel=1e-11)[0]
        assert robin_point_source_disc(a, t, D=D, mu=MU, A=A) == pytest.approx(quad, rel=1e-9)


def test_dirichlet_and_neumann_limits():
    rho, t = np.array([0.2, 1.0, 3.0]), 0.7
    d = np.hypot(rho, t)
    free = np.exp(-MU * d) / (4 * math.pi * D * d)
    # l = 2 A D -> 0: phi -> 0 on the surface; M = phi / (2A) -> the flux, -D dphi/dn = 2 D d/dt of the free field
    small_A = 1e-7
    m = robin_point_source_exitance(rho, t, D=D, mu=MU, A=small_A)
    flux = 2 * D * t * (1 + MU * d) * np.exp(-MU * d) / (4 * math.pi * D * d ** 3)
    np.testing.assert_allclose(m, flux, rtol=1e-5)
    big_A = 1e7
    phi = 2 * big_A * robin_point_source_exitance(rho, t, D=D, mu=MU, A=big_A)
    np.testing.assert_allclose(phi, 2 * free, rtol=1e-5)


def test_bad_parameters_raise():
    with pytest.raises(MaterialError):
        robin_point_source_exitance(1.0, 0.0, D=D, mu=MU, A=A)
    with pytest.raises(MaterialError):
        robin_point_source_exitance(1.0, 1.0, D=-1.0, mu=MU, A=A)


@settings(max_examples=60, deadline=None)
@given(albedo=st.floats(0.01, 0.9999), eta=st.floats(1.0, 2.5), t=st.floats(1e-4, 20.0))
def test_shape_over_the_physical_range(albedo, eta, t):
    """Optical units, d'Eon's D = (2 - alpha')/3 and A from the Fresnel moments of eta (as the volume uses)."""
    v = dipole_variant(albedo, eta, "better")
    kw = dict(D=v.D, mu=v.mu, A=v.z_b / (2 * v.D))
    rho = np.geomspace(1e-4, 60.0, 200)
    m = robin_point_source_exitance(rho, t, **kw)
    assert np.all(np.isfinite(m)) and np.all(m >= 0)
    assert np.all(np.diff(m) <= 1e-12 * m[:-1])
    disc = robin_point_source_disc(rho, t, **kw)
    assert np.all(np.diff(disc) >= -1e-15) and disc[-1] <= robin_point_source_total(t, **kw) * (1 + 1e-12)
