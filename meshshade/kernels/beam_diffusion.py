"""Photon beam diffusion on the half-space (Habel, Christensen & Jarosz 2013; docs/physics.md §13, eqs.
(73)-(75)), in optical units (sigma_t' = 1): multiple scattering from point sources spread along the refracted
beam instead of one source at depth z_r = 1/sigma_t'.

Under a pencil beam at normal incidence, first (reduced) scattering events happen at depth t with density
alpha' exp(-t) per unit entering power. Each is an isotropic point source, and the half-space's response to a
source at depth t is a dipole: the real source at t and the image at -(t + 2 z_b). The exitance is a combination
of the fluence phi and the flux E at the surface (:class:`DipoleVariant`):

    R_t(r) = C_phi phi_t(r) + C_E E_t(r),
    phi_t(r) = [exp(-mu d_r) / d_r - exp(-mu d_v) / d_v] / (4 pi D),
    E_t(r)   = [t (1 + mu d_r) exp(-mu d_r) / d_r^3 + (t + 2 z_b) (1 + mu d_v) exp(-mu d_v) / d_v^3] / (4 pi),

with d_r = sqrt(r^2 + t^2), d_v = sqrt(r^2 + (t + 2 z_b)^2), mu = sqrt((1 - alpha') / D), and

    R_beam(r) = int_0^inf alpha' exp(-t) R_t(r) dt.

Variants: ``"jensen"`` is Jensen et al. 2001's flux-only dipole (D = 1/3, C_phi = 0, C_E = 1, A from the
diffuse Fresnel fit), so that a single source at t = 1 gives back :func:`meshshade.kernels.dipole.dipole_profile`;
``"better"`` is d'Eon 2012's "better dipole": D = (2 - alpha') / 3 (Grosjean), the exitance as the P1 radiance
leaving through the Fresnel boundary, C_phi = (1 - 2 C1) / 4 and C_E = (1 - 3 C2) / 2, and A = (1 + 3 C2) /
(1 - 2 C1), with C1 = int_0^1 F(mu) mu dmu and C2 = int_0^1 F(mu) mu^2 dmu the moments of the internal Fresnel
reflectance (:func:`fresnel_moments`).

Quadrature. Pointwise (:func:`beam_diffusion_profile`), with t = r sinh x the real-source terms are smooth and
decay double-exponentially in x at any r > 0 (at r = 0 the profile is infinite: the source density reaches the
surface); the image terms are smooth in t. Over a ring (:func:`beam_diffusion_ring`),
the real-source terms are done in polar
coordinates (r, t) = rho (sin a, cos a), where the rho integral is exact; the image terms by Gauss-Legendre in r
and Gauss-Laguerre in t. :func:`beam_diffusion_total` is the closed form of int R_beam 2 pi r dr.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.optics import check_material, diffusion_params

__all__ = ["DipoleConstants", "dipole_constants", "DipoleVariant", "dipole_variant", "fresnel_moments",
           "point_source_reflectance", "point_source_ring", "point_source_total", "beam_diffusion_profile", "beam_diffusion_ring", "beam_diffusion_total", "VARIANTS"]

VARIANTS = ("jensen", "better")

_GL_U, _GL_W = np.polynomial.legendre.leggauss(128)
_GL_U, _GL_W = 0.5 * (_GL_U + 1.0), 0.5 * _GL_W     # [0, 1]
_LAG_T, _LAG_W = np.polynomial.laguerre.laggauss(64)  # int_0^inf e^-t f(t) dt
_R_U, _R_W = np.polynomial.legendre.leggauss(32)
_R_U, _R_W = 0.5 * (_R_U + 1.0), 0.5 * _R_W


class DipoleConstants(NamedTuple):
    """The constants of a point source's dipole (a variant of :data:`VARIANTS`), optical units (sigma_t' = 1),
    broadcast arrays: diffusion coefficient ``D``, ``mu`` = sigma_tr / sigma_t' = sqrt((1 - alpha') / D),
    extrapolation distance ``z_b`` = 2 A D, boundary mismatch ``A``, and the weights ``c_phi``, ``c_E`` of fluence
    and flux in the exitance."""

    D: np.ndarray
    mu: np.ndarray
    z_b: np.ndarray
    A: np.ndarray
    c_phi: np.ndarray
    c_E: np.ndarray


def dipole_constants(albedo_prime, eta, variant: str = "better") -> DipoleConstants:
    """:class:`DipoleConstants` of ``variant`` for reduced albedo ``albedo_prime`` in [0, 1] and index ``eta``
    (array_like, broadcast; not validated: :func:`~meshshade.kernels.optics.check_material` first).

    ``"jensen"``: D = 1/3, A from the diffuse Fresnel fit (:func:`~meshshade.kernels.optics.diffusion_params`),
    C_phi = 0, C_E = 1. ``"better"`` (d'Eon 2012): D = (2 - alpha') / 3, A = (1 + 3 C2) / (1 - 2 C1),
    C_phi = (1 - 2 C1) / 4, C_E = (1 - 3 C2) / 2 with the Fresnel moments C1, C2 (:func:`fresnel_moments`, per
    distinct eta); docs/physics.md eqs. (73)-(75)."""
    if variant not in VARIANTS:
        raise ValueError(f"dipole variant must be one of {VARIANTS}, got {variant!r}")
    a = np.asarray(albedo_prime, dtype=np.float64)
    e = np.asarray(eta, dtype=np.float64)
    if variant == "jensen":
        p = diffusion_params(a, e)
        one = np.ones(p.mu.shape)
        return DipoleConstants(p.D, p.mu, p.z_b, p.A, 0.0 * one, one)
    if e.ndim == 0:
        c1, c2 = (np.float64(x) for x in fresnel_moments(float(e)))
    else:   # one pair of moments per distinct index
        values, inverse = np.unique(e, return_inverse=True)
        moments = np.array([fresnel_moments(float(x)) for x in values])
        c1, c2 = moments[inverse, 0].reshape(e.shape), moments[inverse, 1].reshape(e.shape)
    D = (2.0 - a) / 3.0
    A = (1.0 + 3.0 * c2) / (1.0 - 2.0 * c1)
    mu = np.sqrt(np.maximum(0.0, 1.0 - a) / D)
    shape = np.broadcast(a, e).shape
    full = lambda x: np.broadcast_to(x, shape).astype(np.float64)  # noqa: E731
    return DipoleConstants(full(D), full(mu), full(2.0 * A * D), full(A), full((1.0 - 2.0 * c1) / 4.0),
                           full((1.0 - 3.0 * c2) / 2.0))


@dataclass(frozen=True)
class DipoleVariant:
    """A point source's dipole of one medium channel, optical units: the numbers of :class:`DipoleConstants`
    (diffusion coefficient ``D``, ``mu`` = sigma_tr / sigma_t', extrapolation distance ``z_b`` = 2 A D, the
    weights ``c_phi``, ``c_E`` of fluence and flux), with the exitance of a unit point source at depth t
    (:meth:`reflectance`), its ring averages (:meth:`ring`) and its total (:meth:`total`) as methods. Made by
    :func:`dipole_variant` from a medium's numbers, or read from a :class:`meshshade.medium.Medium`."""

    name: str
    albedo_prime: float
    D: float
    mu: float
    z_b: float
    c_phi: float
    c_E: float

    def reflectance(self, r_opt, depth_opt):
        """R_t(r) = C_phi phi_t(r) + C_E E_t(r) of a unit isotropic point source at depth t (arrays broadcast)."""
        r = np.asarray(r_opt, dtype=np.float64)
        t = np.asarray(depth_opt, dtype=np.float64)
        d = np.sqrt(r * r + t * t)
        e = np.exp(-self.mu * d)
        real = (self.c_phi * e / (4.0 * math.pi * self.D * d)
                + self.c_E * t * (1.0 + self.mu * d) * e / (4.0 * math.pi * d ** 3))
        return (real + _image_terms(r, t, self))[()]

    def ring(self, lo, hi, depth_opt):
        """Average of :meth:`reflectance` over the ring lo <= r < hi, in closed form (arrays; depth > 0)."""
        lo, hi, t = np.broadcast_arrays(np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64),
                                        np.asarray(depth_opt, dtype=np.float64))
        zv = t + 2.0 * self.z_b
        real = _ring_integral(np.hypot(lo, t), np.hypot(hi, t), t, self, 1.0)
        image = _ring_integral(np.hypot(lo, zv), np.hypot(hi, zv), zv, self, -1.0)
        return ((real + image) / (math.pi * (hi * hi - lo * lo)))[()]

    def total(self, depth_opt):
        """int R_t 2 pi r dr: C_E (e^{-mu t} + e^{-mu (t + 2 z_b)}) / 2
        + C_phi (e^{-mu t} - e^{-mu (t + 2 z_b)}) / (2 D mu)."""
        t = np.asarray(depth_opt, dtype=np.float64)
        e_r, e_v = np.exp(-self.mu * t), np.exp(-self.mu * (t + 2.0 * self.z_b))
        phi = (e_r - e_v) / (2.0 * self.D * self.mu) if self.mu > 0 else 2.0 * self.z_b / (2.0 * self.D) + 0.0 * t
        return (self.c_E * 0.5 * (e_r + e_v) + self.c_phi * phi)[()]


@lru_cache(maxsize=256)
def fresnel_moments(eta: float) -> tuple[float, float]:
    """(C1, C2) = (int_0^1 F mu dmu, int_0^1 F mu^2 dmu) of the Fresnel reflectance seen from inside a medium of
    relative index ``eta`` (F = 1 below the critical cosine; Gauss-Legendre above it, with mu = mu_c +
    (1 - mu_c) u^2 for the square-root edge)."""
    eta = float(eta)
    if eta == 1.0:
        return 0.0, 0.0
    mu_c = math.sqrt(max(0.0, 1.0 - 1.0 / (eta * eta)))
    mu = mu_c + (1.0 - mu_c) * _GL_U * _GL_U
    w = 2.0 * (1.0 - mu_c) * _GL_U * _GL_W
    F = fresnel_reflectance(mu, eta, 1.0)
    c1 = 0.5 * mu_c * mu_c + float(np.sum(w * F * mu))
    c2 = mu_c ** 3 / 3.0 + float(np.sum(w * F * mu * mu))
    return c1, c2


def dipole_variant(albedo_prime: float, eta: float, variant: str = "better") -> DipoleVariant:
    """The :class:`DipoleVariant` ``variant`` ("jensen" or "better") of a medium channel (computed once per
    distinct albedo, index and variant; a material's are made once with it, :class:`meshshade.medium.Medium`)."""
    if variant not in VARIANTS:
        raise ValueError(f"dipole variant must be one of {VARIANTS}, got {variant!r}")
    return _dipole_variant(float(albedo_prime), float(eta), variant)


@lru_cache(maxsize=1024)
def _dipole_variant(a: float, eta: float, variant: str) -> DipoleVariant:
    """:func:`dipole_variant` of checked arguments (``variant`` one of VARIANTS)."""
    k = dipole_constants(a, eta, variant)
    return DipoleVariant(variant, a, float(k.D), float(k.mu), float(k.z_b), float(k.c_phi), float(k.c_E))


def point_source_reflectance(r_opt, depth_opt, *, albedo_prime, eta, variant="better"):
    """R_t(r) = C_phi phi_t(r) + C_E E_t(r) of a unit isotropic point source at depth t (optical units, arrays
    broadcast): :meth:`DipoleVariant.reflectance`. With ``variant="jensen"`` and t = 1, alpha' R_t is the planar
    dipole (:func:`meshshade.kernels.dipole.dipole_profile`)."""
    check_material(albedo_prime, eta)
    return dipole_variant(albedo_prime, eta, variant).reflectance(r_opt, depth_opt)


def _ring_integral(d0, d1, z, v: DipoleVariant, sign: float):
    """int_{r0}^{r1} 2 pi r [sign C_phi e^{-mu d}/(4 pi D d) + C_E z (1 + mu d) e^{-mu d}/(4 pi d^3)] dr with
    d^2 = r^2 + z^2 (r dr = d dd), in closed form from d0 to d1."""
    e0, e1 = np.exp(-v.mu * d0), np.exp(-v.mu * d1)
    if v.mu > 0:
        phi = (e0 - e1) / (2.0 * v.D * v.mu)
    else:
        phi = (d1 - d0) / (2.0 * v.D)
    return sign * v.c_phi * phi + v.c_E * 0.5 * z * (e0 / d0 - e1 / d1)


def point_source_ring(lo, hi, depth_opt, *, albedo_prime, eta, variant="better"):
    """Average of :func:`point_source_reflectance` over the ring lo <= r < hi, in closed form (arrays broadcast;
    depth > 0): :meth:`DipoleVariant.ring`."""
    check_material(albedo_prime, eta)
    return dipole_variant(albedo_prime, eta, variant).ring(lo, hi, depth_opt)


def point_source_total(depth_opt, *, albedo_prime, eta, variant="better"):
    """int R_t 2 pi r dr of a unit point source at depth t (:meth:`DipoleVariant.total`)."""
    check_material(albedo_prime, eta)
    return dipole_variant(albedo_prime, eta, variant).total(depth_opt)


def _image_terms(r, t, v: DipoleVariant):
    """C_phi phi + C_E E of the image source (at height t + 2 z_b) for arrays r, t (broadcast)."""
    zv = t + 2.0 * v.z_b
    d = np.sqrt(r * r + zv * zv)
    e = np.exp(-v.mu * d)
    return -v.c_phi * e / (4.0 * math.pi * v.D * d) + v.c_E * zv * (1.0 + v.mu * d) * e / (4.0 * math.pi * d ** 3)


def beam_diffusion_profile(r_opt, *, albedo_prime, eta, variant="better"):
    """R_beam(r) per unit entering power, optical units (times sigma_t'^2 for mm^-2); inf at r = 0."""
    check_material(albedo_prime, eta)
    v = dipole_variant(albedo_prime, eta, variant)
    r = np.asarray(r_opt, dtype=np.float64)
    rr = np.where(r > 0, r, 1.0)[..., None]
    # real source, t = r sinh x (d = r cosh x): phi dt = e^{-mu d} / (4 pi D) dx and
    # E dt = sinh x (1 + mu d) e^{-mu d} / (4 pi r cosh^2 x) dx, both times e^{-t}; x up to where e^{-t} < e^{-60}
    X = np.arcsinh(60.0 / rr)
    x = X * _GL_U
    wx = X * _GL_W
    ch, sh = np.cosh(x), np.sinh(x)
    t, d = rr * sh, rr * ch
    decay = np.exp(-t - v.mu * d)
    real = np.sum((v.c_E * sh * (1.0 + v.mu * d) / (4.0 * math.pi * rr * ch * ch)
                   + v.c_phi / (4.0 * math.pi * v.D)) * decay * wx, axis=-1)
    # image source: Gauss-Laguerre in t (the e^-t of the source density is the weight)
    image = _image_terms(rr, _LAG_T, v) @ _LAG_W
    out = v.albedo_prime * (real + image)
    return np.where(r > 0, out, np.inf)[()]


def beam_diffusion_ring(lo, hi, *, albedo_prime, eta, variant="better"):
    """Average of R_beam over lo <= r < hi (optical units, arrays)."""
    check_material(albedo_prime, eta)
    v = dipole_variant(albedo_prime, eta, variant)
    lo, hi = np.broadcast_arrays(np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))
    area = math.pi * (hi * hi - lo * lo)
    # real source in polar coordinates (r, t) = rho (sin a, cos a), a in (0, pi/2): the integrand times 2 pi r dr dt
    #   E part:   (1/2) sin a cos a (1 + mu rho) e^{-k rho} drho da,   phi part: sin a rho e^{-k rho} / (2 D) ...
    a = 0.5 * math.pi * _GL_U
    wa = 0.5 * math.pi * _GL_W
    sa, ca = np.sin(a), np.cos(a)
    k = v.mu + ca
    r1, r2 = lo[..., None] / sa, hi[..., None] / sa

    def prim_E(rho):   # antiderivative of (1 + mu rho) e^{-k rho}, with the sign: -e^{-k rho}((1 + mu rho)/k + mu/k^2)
        return -np.exp(-k * rho) * ((1.0 + v.mu * rho) / k + v.mu / (k * k))

    def prim_phi(rho):   # antiderivative of rho e^{-k rho}
        return -np.exp(-k * rho) * (rho / k + 1.0 / (k * k))

    real = (v.c_E * 0.5 * sa * ca * (prim_E(r2) - prim_E(r1))
            + v.c_phi / (2.0 * v.D) * sa * (prim_phi(r2) - prim_phi(r1))) @ wa
    # image source: Gauss-Legendre in r over the ring, Gauss-Laguerre in t
    rn = lo[..., None] + (hi - lo)[..., None] * _R_U                               # (..., 32)
    img = _image_terms(rn[..., None], _LAG_T, v) @ _LAG_W                         # (..., 32)
    image = (img * 2.0 * math.pi * rn) @ _R_W * (hi - lo)
    return albedo_prime * (real + image) / area


def beam_diffusion_total(*, albedo_prime, eta, variant="better"):
    """int R_beam 2 pi r dr in closed form: alpha' / (1 + mu) [C_E (1 + e^{-2 mu z_b}) / 2
    + C_phi (1 - e^{-2 mu z_b}) / (2 D mu)] (the phi term's limit 2 z_b C_phi / (2 D) at mu = 0)."""
    check_material(albedo_prime, eta)
    v = dipole_variant(albedo_prime, eta, variant)
    e = math.exp(-2.0 * v.mu * v.z_b)
    phi = (1.0 - e) / (2.0 * v.D * v.mu) if v.mu > 0 else v.z_b / v.D
    return v.albedo_prime / (1.0 + v.mu) * (v.c_E * 0.5 * (1.0 + e) + v.c_phi * phi)
