"""The near-field model of the half-space: exact single scattering plus diffusion from sources spread along the beam
with strengths fitted to exact transport (docs/physics.md §13, eq. (76)), in optical units (sigma_t' = 1).

    R_near(r) = R^(1)(r) + sum_k w_k R_{t_k}(r)

R^(1) is the exact single scattering (:mod:`meshshade.kernels.single_scattering`). R_t is d'Eon's dipole for a
unit isotropic point source at depth t (:func:`meshshade.kernels.beam_diffusion.point_source_reflectance`). The
depths t_k are fixed, and the strengths w_k >= 0 were fitted, per medium of a grid in (log10(1 - alpha'), eta, g),
to the exact half-space Monte Carlo's orders >= 2 and total (``tools/tables/make_near_field_table.py``, whose output is
:mod:`meshshade.kernels.near_field_table`, with its provenance). Between grid nodes the strengths are interpolated
trilinearly. The model is linear in them, so that interpolates the fitted models themselves. Each term is a point
source's dipole at a known depth, so a curvature kernel or an exact shape solution for a source at depth a can be
summed over the same sources.

Domain of the fit: alpha' in [0.018, 0.999] (below 0.5 since issue 47's sweep: ketchup's green and blue took alpha' =
0.5's sources and came out 3-12 times too bright), eta in [1, 2.5], g in [0, 0.9]. Outside it the nearest node's sources
are used (:func:`near_field_sources` says when it clamps). Within it the fit is good for eta <= 1.6 (held-out
media within 3.4 % of Monte Carlo) and poorer at eta >= 2 and at low albedo with g >= 0.7
(``near_field_table.FIT_ERROR``, docs/validation.md "Near the light").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from meshshade.kernels import incidence_table
from meshshade.kernels import near_field_table as table
from meshshade.kernels.beam_diffusion import DipoleVariant, dipole_variant
from meshshade.kernels.cylinder import cylinder_point_source_exitance
from meshshade.kernels.optics import check_material
from meshshade.kernels.sphere import sphere_point_source_exitance
from meshshade.kernels.single_scattering import SingleScattering, real_coefficients, single_scattering

__all__ = ["NearFieldModel", "near_field_model", "near_field_sources", "incidence_ratios", "near_field_profile",
           "near_field_ring", "near_field_total", "incidence_gain", "near_field_sphere_profile", "near_field_cylinder_profile", "FIT_DOMAIN"]

#: (alpha', eta, g) ranges of the fitted grid
FIT_DOMAIN = {"albedo_prime": (1.0 - 10.0 ** float(table.X_NODES[-1]), 1.0 - 10.0 ** float(table.X_NODES[0])),
              "eta": (float(table.ETA_NODES[0]), float(table.ETA_NODES[-1])),
              "g": (float(table.G_NODES[0]), float(table.G_NODES[-1]))}


def _bracket(nodes: np.ndarray, x: float) -> tuple[int, float, bool]:
    """(left index, fraction in [0, 1], clamped) of ``x`` among increasing ``nodes``."""
    clamped = x < nodes[0] or x > nodes[-1]
    x = min(max(x, float(nodes[0])), float(nodes[-1]))
    i = int(np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2))
    return i, (x - nodes[i]) / (nodes[i + 1] - nodes[i]), clamped


def _trilinear(grid, values, albedo_prime, eta, g) -> tuple[np.ndarray, bool]:
    """(values[i, j, k] interpolated trilinearly at (log10(1 - alpha'), eta, g) on ``grid``'s X_NODES, ETA_NODES,
    G_NODES, clamped): the tables' common lookup (clamped to the nearest node outside the grid)."""
    x = math.log10(max(1.0 - float(albedo_prime), 1e-300))
    (i, fx, cx), (j, fe, ce), (k, fg, cg) = (_bracket(grid.X_NODES, x), _bracket(grid.ETA_NODES, float(eta)),
                                              _bracket(grid.G_NODES, float(g)))
    out = np.zeros(values.shape[3:])
    for di, wi in ((0, 1.0 - fx), (1, fx)):
        for dj, wj in ((0, 1.0 - fe), (1, fe)):
            for dk, wk in ((0, 1.0 - fg), (1, fg)):
                c = wi * wj * wk
                if c:
                    out += c * values[i + di, j + dj, k + dk]
    return out, bool(cx or ce or cg)


def near_field_sources(albedo_prime: float, eta: float, g: float = 0.0) -> tuple[np.ndarray, np.ndarray, bool]:
    """(depths (K,), strengths (K,), clamped): the beam's fitted point sources for a medium (optical units);
    ``clamped`` is True when the medium lies outside :data:`FIT_DOMAIN` and the nearest node's sources are used."""
    check_material(albedo_prime, eta)
    real_coefficients(float(albedo_prime), float(g))   # validates g
    w, clamped = _trilinear(table, table.WEIGHTS, albedo_prime, eta, g)
    return table.DEPTHS.copy(), w, clamped


def incidence_ratios(albedo_prime: float, eta: float, g: float = 0.0) -> np.ndarray:
    """(n,): RHO of :mod:`meshshade.kernels.incidence_table` at the medium, one per tabulated incidence angle
    (``incidence_table.ANGLES``): the fraction of eq. (81)'s growth in total reflectance that exact transport
    shows (interpolated trilinearly in (log10(1 - alpha'), eta, g), clamped to the grid)."""
    return _trilinear(incidence_table, incidence_table.RHO, albedo_prime, eta, g)[0]


@dataclass(frozen=True, eq=False)
class NearFieldModel:
    """The near-field model of one medium channel (eq. (76)), optical units: the medium's ``albedo_prime``,
    ``eta`` and ``g``, its d'Eon dipole ``dipole`` (:class:`~meshshade.kernels.beam_diffusion.DipoleVariant`), the
    beam's fitted sources ``depths`` and ``strengths`` (K,) (``clamped``: outside :data:`FIT_DOMAIN`, the nearest
    node's), the incidence table's ratios ``rho`` (:func:`incidence_ratios`) and its exact single scattering
    ``single`` (:class:`~meshshade.kernels.single_scattering.SingleScattering`). The numbers are made once
    (:func:`near_field_model`, or read from a :class:`meshshade.medium.Medium`); its methods are the model's
    profile, ring averages, total and incidence gain, pure functions of arrays."""

    albedo_prime: float
    eta: float
    g: float
    dipole: DipoleVariant
    depths: np.ndarray
    strengths: np.ndarray
    clamped: bool
    rho: np.ndarray
    single: SingleScattering

    def profile(self, r_opt, cos_t=1.0):
        """R_near(r) per unit entering power (:func:`near_field_profile`); inf at r = 0."""
        r = np.asarray(r_opt, dtype=np.float64)
        ms = sum(wk * self.dipole.reflectance(r, cos_t * t) for t, wk in zip(self.depths, self.strengths) if wk > 0)
        return self.single.profile(r, cos_t) + ms

    def ring(self, lo, hi, cos_t=1.0):
        """Average of R_near over the ring lo <= r < hi (:func:`near_field_ring`)."""
        ms = sum(wk * self.dipole.ring(lo, hi, cos_t * t) for t, wk in zip(self.depths, self.strengths) if wk > 0)
        return self.single.ring(lo, hi, cos_t) + ms

    def total(self, cos_t=1.0) -> float:
        """int R_near 2 pi r dr per unit entering power (:func:`near_field_total`)."""
        ms = float(sum(wk * self.dipole.total(cos_t * t) for t, wk in zip(self.depths, self.strengths)))
        return self.single.total(cos_t) + ms

    def incidence_gain(self, cos_t=1.0) -> float:
        """T(theta) / T(0) of light entering at refracted angle theta_t (:func:`incidence_gain`, eq. (86))."""
        cos_t = float(cos_t)
        if cos_t >= 1.0:
            return 1.0
        w81 = self.total(cos_t) / self.total()
        sin_i = min(1.0, float(self.eta) * math.sqrt(max(0.0, 1.0 - cos_t * cos_t)))
        theta_i = math.degrees(math.asin(sin_i))
        r = float(np.interp(theta_i, incidence_table.ANGLES, self.rho))
        return 1.0 + r * (w81 - 1.0)


def near_field_model(albedo_prime: float, eta: float, g: float = 0.0) -> NearFieldModel:
    """The :class:`NearFieldModel` of a medium (validated: MaterialError outside albedo' in [0, 1], eta in
    [1, 2.5], g in (-1, 1))."""
    depths, w, clamped = near_field_sources(albedo_prime, eta, g)
    return NearFieldModel(float(albedo_prime), float(eta), float(g), dipole_variant(albedo_prime, eta, "better"),
                          depths, w, clamped, incidence_ratios(albedo_prime, eta, g),
                          single_scattering(albedo_prime, eta, g))


def near_field_profile(r_opt, *, albedo_prime, eta, g=0.0, cos_t=1.0):
    """R_near(r) per unit entering power, optical units (times sigma_t'^2 for mm^-2); inf at r = 0.

    ``cos_t`` < 1 (oblique incidence, docs/physics.md eq. (81)): the light travels inside at acos(cos_t) from the
    normal; the beam's sources keep their distances t_k along it, so they lie at depths cos_t t_k, and single
    scattering follows the same depth density. Azimuthally averaged about the entry point (the sources' lateral
    offset t_k sin_t is left out). :meth:`NearFieldModel.profile` of :func:`near_field_model`."""
    return near_field_model(albedo_prime, eta, g).profile(r_opt, cos_t)


def near_field_ring(lo, hi, *, albedo_prime, eta, g=0.0, cos_t=1.0):
    """Average of R_near over the ring lo <= r < hi (optical units, arrays; ``cos_t`` as :func:`near_field_profile`)."""
    return near_field_model(albedo_prime, eta, g).ring(lo, hi, cos_t)


def near_field_total(*, albedo_prime, eta, g=0.0, cos_t=1.0) -> float:
    """int R_near 2 pi r dr (per unit entering power; ``cos_t`` as :func:`near_field_profile`)."""
    return near_field_model(albedo_prime, eta, g).total(cos_t)


def incidence_gain(*, albedo_prime, eta, g=0.0, cos_t=1.0) -> float:
    """T(theta) / T(0): how much more of the light entering at refracted angle theta_t (``cos_t``) the half-space
    returns than of light entering along the normal (docs/physics.md eq. (86)). Eq. (81)'s depth projection gives
    W_81 = near_field_total(cos_t) / near_field_total(1); exact transport shows only the fraction RHO of that growth
    (:mod:`meshshade.kernels.incidence_table`, fitted to the exact half-space Monte Carlo per incidence angle by
    ``tools/tables/make_incidence_table.py``), interpolated trilinearly in (log10(1 - alpha'), eta, g) and linearly in
    the incidence angle outside, sin(theta_i) = eta sin(theta_t) (below the first tabulated angle its value, where
    the gain itself is small; beyond the last, the last)."""
    return near_field_model(albedo_prime, eta, g).incidence_gain(cos_t)


def _variant_kw(v: DipoleVariant) -> dict:
    return {"mu": v.mu, "D": v.D, "z_b": v.z_b, "c_phi": v.c_phi, "c_E": v.c_E}


def near_field_sphere_profile(theta, *, R0_opt, albedo_prime, eta, g=0.0, rtol=1e-10):
    """The near-field model on a sphere of radius R0 (docs/physics.md eq. (78)), optical units:

        R_near,sph(theta) = R^(1)(chord) + sum_k w_k R_sph,t_k(theta),

    the fitted beam's sources (:func:`near_field_sources`) each with the sphere's exact Green's function
    (:func:`meshshade.kernels.sphere.sphere_point_source_exitance`; a source beyond the far side of the ball,
    t_k >= 2 R0, has left it and is dropped), and the half-space's single scattering at the chord
    2 R0 sin(theta/2). theta in [0, pi]; inf at theta = 0 (the single scattering's r^-1 peak)."""
    R0 = float(R0_opt)
    model = near_field_model(albedo_prime, eta, g)
    depths, w, kw = model.depths, model.strengths, _variant_kw(model.dipole)
    th = np.asarray(theta, dtype=np.float64)
    ms = sum(wk * sphere_point_source_exitance(th, R0_opt=R0, depth_opt=t, rtol=rtol, **kw)
             for t, wk in zip(depths, w) if wk > 0)
    chord = 2.0 * R0 * np.sin(0.5 * th)
    return model.single.profile(chord) + ms


def near_field_cylinder_profile(theta, z, *, R0_opt, albedo_prime, eta, g=0.0, rtol=1e-8):
    """The near-field model on an infinite cylinder of radius R0 (docs/physics.md eq. (78)), optical units: the
    fitted beam's sources each with the cylinder's exact Green's function
    (:func:`meshshade.kernels.cylinder.cylinder_point_source_exitance`), plus the half-space's single scattering
    at the chord. theta (around the axis) and z (along it) broadcast."""
    R0 = float(R0_opt)
    model = near_field_model(albedo_prime, eta, g)
    depths, w, kw = model.depths, model.strengths, _variant_kw(model.dipole)
    th, zz = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(z, dtype=np.float64))
    ms = sum(wk * cylinder_point_source_exitance(th, zz, R0_opt=R0, depth_opt=t, rtol=rtol, **kw)
             for t, wk in zip(depths, w) if wk > 0)
    chord = np.hypot(2.0 * R0 * np.sin(0.5 * th), zz)
    return model.single.profile(chord) + ms
