"""Single scattering of a half-space under a pencil beam at normal incidence (Jensen et al. 2001's first-order
term; docs/physics.md §13, eqs. (71)-(72)), in optical units (sigma_t' = 1).

A photon that enters at the origin travels straight down (normal incidence: no refraction), scatters once at
depth z with probability sigma_s exp(-sigma_t z) dz, is sent by the Henyey-Greenstein phase function p (per
steradian) towards the exit point at distance r, survives the path l = sqrt(r^2 + z^2) with exp(-sigma_t l) and
leaves with Fresnel transmittance 1 - F. The exitance per unit entering power is

    R1(r) = sigma_s int_0^inf exp(-sigma_t (z + l)) p(-z/l) (1 - F(z/l)) z / l^3 dz.

With the exit angle a from the normal (z = r cot a, l = r / sin a) it is a smooth integral over a in
[0, a_c] (a_c the critical angle; beyond it F = 1):

    R1(r) = (sigma_s / r) int_0^{a_c} exp(-sigma_t r (1 + cos a) / sin a) p(-cos a) (1 - F(cos a)) cos a da,

which is :func:`single_scattering_profile` (R1 ~ 1/r at the source: integrable over any ring). Over a ring
lo <= r < hi, in polar coordinates (r, z) = rho (sin a, cos a) the rho integral is exact and
:func:`single_scattering_ring` is a smooth 1-D integral. Both use Gauss-Legendre nodes in u with a = a_c (1 - u^2)
near the critical angle, where F has a square-root edge.

Coefficients: sigma_s = alpha' / (1 - g) and sigma_t = sigma_s + (1 - alpha') in optical units (the real, not the
reduced, scattering: the phase function carries g).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from meshshade.errors import MaterialError
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.optics import check_material

__all__ = ["SingleScattering", "single_scattering", "single_scattering_profile", "single_scattering_ring",
           "single_scattering_total", "hg_phase", "real_coefficients"]

#: Gauss-Legendre nodes of the angular integrals
NODES = 96
_U, _W = np.polynomial.legendre.leggauss(NODES)
_U, _W = 0.5 * (_U + 1.0), 0.5 * _W          # on [0, 1]


def hg_phase(cos_theta, g):
    """Henyey-Greenstein phase function per steradian: (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2))."""
    c = np.asarray(cos_theta, dtype=np.float64)
    return (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * c) ** 1.5)


def real_coefficients(albedo_prime: float, g: float) -> tuple[float, float]:
    """(sigma_s, sigma_t) in optical units (sigma_t' = 1) from the reduced albedo and the anisotropy g."""
    if not (math.isfinite(g) and -1.0 < g < 1.0):
        raise MaterialError(f"anisotropy g must be in (-1, 1), got {g!r}")
    sigma_s = albedo_prime / (1.0 - g)
    return sigma_s, sigma_s + (1.0 - albedo_prime)


def _angles(eta: float):
    """(a (k,), weights (k,)) on [0, a_c]: a = a_c (1 - u^2), da = 2 a_c u du."""
    a_c = math.asin(1.0 / eta) if eta > 1.0 else 0.5 * math.pi
    a = a_c * (1.0 - _U * _U)
    return a, 2.0 * a_c * _U * _W


def _angular_factor(a, sigma_s, g, eta):
    c = np.cos(a)
    return sigma_s * hg_phase(-c, g) * (1.0 - fresnel_reflectance(c, eta, 1.0)) * c


def _check_cos_t(cos_t) -> float:
    c = float(cos_t)
    if not 0.0 < c <= 1.0:
        raise ValueError(f"cos_t (cosine of the refracted direction) must lie in (0, 1], got {cos_t!r}")
    return c


@dataclass(frozen=True, eq=False)
class SingleScattering:
    """Exact single scattering of one medium channel, optical units: the real coefficients ``sigma_s``,
    ``sigma_t`` (:func:`real_coefficients`), the anisotropy ``g``, the relative index ``eta``, the angular
    quadrature's exit angles ``a`` and weights ``w`` on [0, a_c], and the angular factor at them, ``factor`` =
    sigma_s p(-cos a) (1 - F(cos a)) cos a. Made and checked once (:func:`single_scattering`); its methods are
    the profile, ring averages and total of eqs. (71)-(72), pure functions of arrays."""

    sigma_s: float
    sigma_t: float
    g: float
    eta: float
    a: np.ndarray
    w: np.ndarray
    factor: np.ndarray

    def profile(self, r_opt, cos_t=1.0):
        """R1(r) per unit entering power (:func:`single_scattering_profile`); inf at r = 0."""
        ct = _check_cos_t(cos_t)
        r = np.asarray(r_opt, dtype=np.float64)
        f = self.factor * self.w / ct
        ratio = (1.0 + np.cos(self.a) / ct) / np.sin(self.a)
        with np.errstate(divide="ignore"):
            inv = np.where(r > 0, 1.0 / np.where(r > 0, r, 1.0), np.inf)
        e = np.exp(-self.sigma_t * r[..., None] * ratio)
        return np.where(r > 0, inv * (e @ f), np.inf)[()]

    def ring(self, lo, hi, cos_t=1.0):
        """Average of R1 over the ring lo <= r < hi (:func:`single_scattering_ring`)."""
        ct = _check_cos_t(cos_t)
        lo, hi = np.broadcast_arrays(np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))
        a = self.a
        f = 2.0 * math.pi * self.factor * np.sin(a) * self.w / ct
        k = self.sigma_t * (1.0 + np.cos(a) / ct)
        s = np.sin(a)
        inner = (np.exp(-k * lo[..., None] / s) - np.exp(-k * hi[..., None] / s)) / k
        return (inner @ f) / (math.pi * (hi * hi - lo * lo))

    def total(self, cos_t=1.0) -> float:
        """int R1 2 pi r dr per unit entering power (:func:`single_scattering_total`)."""
        ct = _check_cos_t(cos_t)
        a = self.a
        f = 2.0 * math.pi * self.factor * np.sin(a) * self.w / ct
        return float(f @ (1.0 / (self.sigma_t * (1.0 + np.cos(a) / ct))))


def single_scattering(albedo_prime, eta, g=0.0) -> SingleScattering:
    """The :class:`SingleScattering` of a medium channel (validated: MaterialError outside albedo' in [0, 1],
    eta in [1, 2.5], g in (-1, 1))."""
    check_material(albedo_prime, eta)
    sigma_s, sigma_t = real_coefficients(float(albedo_prime), float(g))
    a, w = _angles(float(eta))
    return SingleScattering(sigma_s, sigma_t, float(g), float(eta), a, w, _angular_factor(a, sigma_s, g, float(eta)))


def single_scattering_profile(r_opt, *, albedo_prime, eta, g=0.0, cos_t=1.0):
    """R1(r) per unit entering power, optical units (multiply by sigma_t'^2 for mm^-2); inf at r = 0.

    ``cos_t`` < 1: the light travels inside at angle acos(cos_t) from the normal, so it first scatters at depth
    z with density (sigma_s / cos_t) exp(-sigma_t z / cos_t) (docs/physics.md eq. (81)); the profile is that of
    this depth density about the entry point, azimuthally averaged with the normal-incidence phase factor
    (exact for g = 0). :meth:`SingleScattering.profile` of :func:`single_scattering`."""
    return single_scattering(albedo_prime, eta, g).profile(r_opt, cos_t)


def single_scattering_ring(lo, hi, *, albedo_prime, eta, g=0.0, cos_t=1.0):
    """Average of R1 over the ring lo <= r < hi (optical units, arrays): int 2 pi r R1 dr / (pi (hi^2 - lo^2)).

    In (rho, a): 2 pi r R1 dr dz-weight becomes 2 pi sigma_s sin a cos a p (1 - F) exp(-k rho) drho da with
    k = sigma_t (1 + cos a / cos_t), and rho runs over [lo / sin a, hi / sin a]; ``cos_t`` as
    :func:`single_scattering_profile`."""
    return single_scattering(albedo_prime, eta, g).ring(lo, hi, cos_t)


def single_scattering_total(*, albedo_prime, eta, g=0.0, cos_t=1.0):
    """Total singly scattered reflectance int R1 2 pi r dr (per unit entering power; ``cos_t`` as
    :func:`single_scattering_profile`)."""
    return single_scattering(albedo_prime, eta, g).total(cos_t)
