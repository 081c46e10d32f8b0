"""The near-field model of the half-space: exact single scattering plus diffusion from sources spread along the beam
with strengths fitted to exact transport (docs/physics.md §13, eq. (76)), in optical units (sigma_t' = 1).

    R_near(r) = R^(1)(r) + sum_k w_k R_{t_k}(r)

R^(1) is the exact single scattering (:mod:`meshshade.kernels.single_scattering`). R_t is d'Eon's dipole for a
unit isotropic point source at depth t (:func:`meshshade.kernels.beam_diffusion.point_source_reflectance`). The
depths t_k are fixed, and the strengths w_k >= 0 were fitted, per medium of a grid in (log10(1 - alpha'), eta, g),
to the exact half-space Monte Carlo's orders >= 2 and total (``tools/make_near_field_table.py``, whose output is
:mod:`meshshade.kernels.near_field_table`, with its provenance). Between grid nodes the strengths are interpolated
trilinearly. The model is linear in them, so that interpolates the fitted models themselves. Each term is a point
source's dipole at a known depth, so a curvature kernel or an exact shape solution for a source at depth a can be
summed over the same sources.

Domain of the fit: alpha' in [0.5, 0.999], eta in [1, 2.5], g in [0, 0.9]. Outside it the nearest node's sources
are used (:func:`near_field_sources` says when it clamps). Within it the fit is good for eta <= 1.6 (held-out
media within 3.4 % of Monte Carlo) and poorer at eta >= 2 and at low albedo with g >= 0.7
(``near_field_table.FIT_ERROR``, docs/validation.md "Near the light").
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.kernels import near_field_table as table
from meshshade.kernels.beam_diffusion import point_source_reflectance, point_source_ring, point_source_total
from meshshade.kernels.optics import check_material
from meshshade.kernels.single_scattering import (real_coefficients, single_scattering_profile,
                                                 single_scattering_ring, single_scattering_total)

__all__ = ["near_field_sources", "near_field_profile", "near_field_ring", "near_field_total", "FIT_DOMAIN"]

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


def near_field_sources(albedo_prime: float, eta: float, g: float = 0.0) -> tuple[np.ndarray, np.ndarray, bool]:
    """(depths (K,), strengths (K,), clamped): the beam's fitted point sources for a medium (optical units);
    ``clamped`` is True when the medium lies outside :data:`FIT_DOMAIN` and the nearest node's sources are used."""
    check_material(albedo_prime, eta)
    real_coefficients(float(albedo_prime), float(g))   # validates g
    x = math.log10(max(1.0 - float(albedo_prime), 1e-300))
    (i, fx, cx), (j, fe, ce), (k, fg, cg) = (_bracket(table.X_NODES, x), _bracket(table.ETA_NODES, float(eta)),
                                              _bracket(table.G_NODES, float(g)))
    W = table.WEIGHTS
    w = np.zeros(table.DEPTHS.size)
    for di, wi in ((0, 1.0 - fx), (1, fx)):
        for dj, wj in ((0, 1.0 - fe), (1, fe)):
            for dk, wk in ((0, 1.0 - fg), (1, fg)):
                c = wi * wj * wk
                if c:
                    w += c * W[i + di, j + dj, k + dk]
    return table.DEPTHS.copy(), w, bool(cx or ce or cg)


def near_field_profile(r_opt, *, albedo_prime, eta, g=0.0):
    """R_near(r) per unit entering power, optical units (times sigma_t'^2 for mm^-2); inf at r = 0."""
    depths, w, _ = near_field_sources(albedo_prime, eta, g)
    r = np.asarray(r_opt, dtype=np.float64)
    ms = sum(wk * point_source_reflectance(r, t, albedo_prime=albedo_prime, eta=eta)
             for t, wk in zip(depths, w) if wk > 0)
    return single_scattering_profile(r, albedo_prime=albedo_prime, eta=eta, g=g) + ms


def near_field_ring(lo, hi, *, albedo_prime, eta, g=0.0):
    """Average of R_near over the ring lo <= r < hi (optical units, arrays)."""
    depths, w, _ = near_field_sources(albedo_prime, eta, g)
    ms = sum(wk * point_source_ring(lo, hi, t, albedo_prime=albedo_prime, eta=eta)
             for t, wk in zip(depths, w) if wk > 0)
    return single_scattering_ring(lo, hi, albedo_prime=albedo_prime, eta=eta, g=g) + ms


def near_field_total(*, albedo_prime, eta, g=0.0) -> float:
    """int R_near 2 pi r dr (per unit entering power)."""
    depths, w, _ = near_field_sources(albedo_prime, eta, g)
    ms = float(sum(wk * point_source_total(t, albedo_prime=albedo_prime, eta=eta) for t, wk in zip(depths, w)))
    return single_scattering_total(albedo_prime=albedo_prime, eta=eta, g=g) + ms
