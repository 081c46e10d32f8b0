"""The medium of a material: every per-channel constant the transports read, computed once, where the material is
made (docs/physics.md §2.1, §2.3, §13, §15).

A :class:`Medium` holds, for each colour channel (the last axis of every array: r, g, b):

* the coefficients [1/mm]: sigma_s', sigma_a, sigma_t' = sigma_s' + sigma_a, the reduced albedo alpha' =
  sigma_s' / sigma_t' and the real scattering coefficient sigma_s = sigma_s' / (1 - g) (the Monte Carlo's); the
  relative index eta and the anisotropy g;
* d'Eon's diffusion (the volume's and the near field's, eqs. (73)-(75)): the diffusion coefficient
  D = (2 - alpha') / (3 sigma_t') [mm], the decay constant kappa = sqrt(sigma_a / D) [1/mm], the boundary mismatch
  A = (1 + 3 C2) / (1 - 2 C1), the extrapolation distance z_b = 2 A D [mm], the Fresnel moments C1, C2, and in
  optical units the whole dipole (``better``: :class:`~meshshade.kernels.beam_diffusion.DipoleConstants`);
* Jensen's dipole (the surface models', eq. (10)), optical units (``jensen``:
  :class:`~meshshade.kernels.optics.DiffusionParams`);
* the near field (eq. (76)): the beam's fitted sources' depths and strengths, whether the medium lies outside the
  fit's grid, and the incidence table's ratios (eq. (86)).

The kernels stay functions of numbers: :meth:`Medium.dipole` and :meth:`Medium.near_field` hand one channel's
constants to them as the kernels' own small records (:class:`~meshshade.kernels.beam_diffusion.DipoleVariant`,
:class:`~meshshade.kernels.near_field.NearFieldModel`), read from the arrays here, computed nowhere else.

Media that vary over the object (a colour map inverted per texel, parts of different media): every per-channel
array has the shape ``(..., 3)`` and eta and g the shape ``(...)``; a homogeneous material's are ``(3,)`` and
``()``. :func:`medium_of` is vectorised over the leading axes, so ``n`` media make one Medium of shape ``(n, 3)``;
:meth:`Medium.take` picks one per vertex, cell or region by index (the lattice's coefficients per cell), and the
near field's records are made per distinct medium and channel (``near_field(c, i)``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from meshshade.kernels.beam_diffusion import DipoleConstants, DipoleVariant, dipole_constants, fresnel_moments
from meshshade.kernels.near_field import NearFieldModel, incidence_ratios, near_field_sources
from meshshade.kernels.optics import DiffusionParams, check_material, diffusion_params
from meshshade.kernels.single_scattering import single_scattering

__all__ = ["Medium", "medium_of"]


def _frozen(x) -> np.ndarray:
    """A read-only copy of ``x``, float64 (booleans stay boolean)."""
    a = np.array(x)
    if a.dtype != bool:
        a = a.astype(np.float64)
    a.flags.writeable = False
    return a


def _at(index, c: int) -> tuple:
    """The index of channel ``c`` of medium ``index`` (() for a homogeneous medium, an int or a tuple in a stack)."""
    return (*np.atleast_1d(np.asarray(index, dtype=np.int64)).tolist(), c)


@dataclass(frozen=True, eq=False)
class Medium:
    """Per-channel constants of a material (module docstring); arrays read-only, float64, the channel last.

    sigma_s_prime, sigma_a, sigma_t_prime, sigma_s : (..., 3) 1/mm
    albedo_prime : (..., 3) reduced albedo alpha'
    eta, g : (...) relative index of refraction, Henyey-Greenstein anisotropy
    D : (..., 3) mm, d'Eon's diffusion coefficient (2 - alpha') / (3 sigma_t')
    kappa : (..., 3) 1/mm, the fluence's decay constant sqrt(sigma_a / D)
    A : (..., 3) d'Eon's boundary mismatch (1 + 3 C2) / (1 - 2 C1) (the same in every channel; formed as
        z_b / (2 D), as the volume's Robin condition reads it)
    z_b : (..., 3) mm, extrapolation distance 2 A D
    C1, C2 : (...) the Fresnel moments of the inside's reflectance (:func:`~meshshade.kernels.beam_diffusion.fresnel_moments`)
    better : DipoleConstants of (..., 3) arrays, optical units: d'Eon's dipole (D, mu, z_b, A, c_phi, c_E)
    jensen : DiffusionParams of (..., 3) arrays, optical units: Jensen's planar dipole (mu, F_dr, A, z_b, z_v...)
    near_depths : (K,) optical depths of the near field's fitted sources; near_strengths : (..., 3, K) their
        strengths; near_clamped : (..., 3) bool, outside the fit's grid (its nearest node used)
    incidence_rho : (..., 3, n) the incidence table's ratios at its angles
    """

    sigma_s_prime: np.ndarray
    sigma_a: np.ndarray
    eta: np.ndarray
    g: np.ndarray
    sigma_t_prime: np.ndarray
    albedo_prime: np.ndarray
    sigma_s: np.ndarray
    D: np.ndarray
    kappa: np.ndarray
    A: np.ndarray
    z_b: np.ndarray
    C1: np.ndarray
    C2: np.ndarray
    better: DipoleConstants
    jensen: DiffusionParams
    near_depths: np.ndarray
    near_strengths: np.ndarray
    near_clamped: np.ndarray
    incidence_rho: np.ndarray

    @property
    def shape(self) -> tuple:
        """The leading shape: () for a homogeneous material, (n,) for a stack of n media."""
        return self.sigma_a.shape[:-1]

    def dipole(self, c: int, index=(), variant: str = "better") -> DipoleVariant:
        """Channel ``c``'s dipole (``variant`` "better", d'Eon's, or "jensen"), optical units, as the kernels' record
        (of medium ``index`` of a stack)."""
        at = _at(index, c)
        if variant == "better":
            k = self.better
            return DipoleVariant("better", float(self.albedo_prime[at]), float(k.D[at]), float(k.mu[at]),
                                 float(k.z_b[at]), float(k.c_phi[at]), float(k.c_E[at]))
        if variant == "jensen":
            p = self.jensen
            return DipoleVariant("jensen", float(self.albedo_prime[at]), float(p.D[at]), float(p.mu[at]),
                                 float(p.z_b[at]), 0.0, 1.0)
        raise ValueError(f"dipole variant must be better or jensen, got {variant!r}")

    def near_field(self, c: int, index=()) -> NearFieldModel:
        """Channel ``c``'s near-field model (of medium ``index`` of a stack), optical units, as the kernels' record."""
        at = _at(index, c)
        lead = at[:-1]
        return NearFieldModel(float(self.albedo_prime[at]), float(self.eta[lead]), float(self.g[lead]),
                              self.dipole(c, index), self.near_depths, self.near_strengths[at],
                              bool(self.near_clamped[at]), self.incidence_rho[at],
                              single_scattering(float(self.albedo_prime[at]), float(self.eta[lead]),
                                                float(self.g[lead])))

    def take(self, index) -> "Medium":
        """The media at ``index`` (an integer array into the leading axis, e.g. a region per vertex or cell):
        a Medium of shape ``index.shape``."""
        if not self.shape:
            raise ValueError("a homogeneous medium has no leading axis to index")
        idx = np.asarray(index, dtype=np.int64)
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "near_depths":
                out[f.name] = v
            elif isinstance(v, tuple):   # the records of arrays
                out[f.name] = type(v)(*(_frozen(x[idx]) for x in v))
            else:
                out[f.name] = _frozen(v[idx])
        return Medium(**out)

    def describe(self) -> str:
        """One line: d'Eon's D, kappa and A per channel (of a homogeneous medium; the shape of a stack)."""
        if self.shape:
            return f"<Medium: {int(np.prod(self.shape))} media of shape {self.shape}>"
        fmt = lambda v: "/".join(f"{x:.4g}" for x in v)  # noqa: E731
        return (f"<Medium: D {fmt(self.D)} mm, kappa {fmt(self.kappa)} 1/mm, A {float(self.A[0]):.4g}, "
                f"z_b {fmt(self.z_b)} mm (r/g/b)>")

    __repr__ = describe


def medium_of(sigma_s_prime, sigma_a, eta, g=0.0) -> Medium:
    """The :class:`Medium` of coefficients ``sigma_s_prime``, ``sigma_a`` (..., 3) [1/mm], index ``eta`` and
    anisotropy ``g`` (broadcast to the leading shape ...): the one place where the per-channel constants are
    computed (vectorised over every axis; the near field's sources per medium and channel). The coefficients are
    expected valid (:class:`meshshade.materials.Material` checks them); alpha' and eta are checked again by
    :func:`~meshshade.kernels.optics.check_material` (MaterialError)."""
    s = np.asarray(sigma_s_prime, dtype=np.float64)
    a = np.asarray(sigma_a, dtype=np.float64)
    s, a = np.broadcast_arrays(s, a)
    lead = s.shape[:-1]
    eta = np.broadcast_to(np.asarray(eta, dtype=np.float64), lead)
    g = np.broadcast_to(np.asarray(g, dtype=np.float64), lead)
    st = s + a
    alb = s / st
    check_material(alb, eta)
    better = dipole_constants(alb, eta[..., None], "better")
    jensen = diffusion_params(alb, eta[..., None])
    D = better.D / st
    A = better.z_b / (2.0 * better.D)
    c12 = np.array([fresnel_moments(float(e)) for e in eta.ravel()]).reshape(*lead, 2)
    depths = None
    strengths = np.empty((*lead, 3, 0))
    clamped = np.zeros((*lead, 3), dtype=bool)
    rho = None
    for at in np.ndindex(*lead, 3):
        e, gg = float(eta[at[:-1]]), float(g[at[:-1]])
        d, w, cl = near_field_sources(float(alb[at]), e, gg)
        r = incidence_ratios(float(alb[at]), e, gg)
        if depths is None:
            depths = d
            strengths = np.empty((*lead, 3, w.size))
            rho = np.empty((*lead, 3, r.size))
        strengths[at], clamped[at], rho[at] = w, cl, r
    return Medium(sigma_s_prime=_frozen(s), sigma_a=_frozen(a), eta=_frozen(eta), g=_frozen(g),
                  sigma_t_prime=_frozen(st), albedo_prime=_frozen(alb), sigma_s=_frozen(s / (1.0 - g[..., None])),
                  D=_frozen(D), kappa=_frozen(np.sqrt(a / D)), A=_frozen(A), z_b=_frozen(better.z_b / st),
                  C1=_frozen(c12[..., 0]), C2=_frozen(c12[..., 1]), better=DipoleConstants(*map(_frozen, better)),
                  jensen=DiffusionParams(*map(_frozen, jensen)), near_depths=_frozen(depths),
                  near_strengths=_frozen(strengths), near_clamped=_frozen(clamped), incidence_rho=_frozen(rho))
