"""``--model auto``: decide per entry sample which effects the scene calls for (simulate only what is needed).

Every entry sample i (where light enters, with principal curvatures k1 >= k2 and the neighbourhood radius
rho_c of each channel c) gets two decisions, both from closed-form bounds, never from a trial evaluation:

**Kernel.** The first-order kernel's relative correction is ``delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho)``
(docs/physics.md eq. (51)), so over the whole neighbourhood ``|delta| <= kmax (|a| + |b|)``
with ``kmax = max(|k1|, |k2|)``
and ``|a| + |b|`` taken at its largest on [0, rho_c] (:func:`curvature_bound_mm`; for a sphere it is C(rho_c),
the issue's ``|k| C(rho_cut)``). Then

* ``dipole`` — the surface is flat on the scale of transport: ``kmax W <= curvature_tol`` (default 1e-2, so the
  curvature terms would change no pair by more than 1 %); the planar dipole of the geodesic distance
  (the curved kernel at k = 0, exactly) is used;
* ``exact-sphere`` — convex and umbilic (``k1 - k2 <= umbilic_tol k1``) with every principal curvature
  within the cutoff inside ``umbilic_tol`` of the mean curvature (the neighbourhood *is* that sphere; a sphere
  fitted to one umbilic point of a bumpy surface would fill its whole neighbourhood with light), *and* too
  curved for first order (``kmax (W + 1/sigma_t') > validity_tol``, the kernel's own validity measure,
  kernels/curvature.py): the exact sphere series with the local radius 2/(k1 + k2);
* ``fitted`` — too curved for first order but not a sphere: the curvature model fitted to Monte Carlo beyond
  first order (kernels/fitted_curvature.py);
* ``curved`` — everything else: the first-order k1/k2 kernel.

**Geodesic distance.** Exact polyhedral geodesics cost ~2 us per pair; the "arc" method (curvature-corrected
chords over an edge-path search, geometry/geodesics/arc.py) is 4-5x cheaper and agrees with exact to 1e-4
wherever the surface between source and receiver is a smooth normal section, but undershoots where the surface
in between is bumpy or folded. The decision therefore looks at the *largest* curvature within the
neighbourhood, not only at the source: ``kn_i`` = max of ``kmax`` over the vertices within about rho of the
source (graph dilation, :func:`dilated_max`). Where ``kn_i rho <= geodesic_tol`` (default 0.3: even an
uncorrected chord would be short by at most (k rho)^2/24 = 0.4 %) the arc method is used, otherwise the exact one.

The other choices of the issue need no per-sample decision and are made elsewhere: the neighbourhood radius per
channel from the dipole's tail (gather.cutoff_radii), shadow rays skipped where the mesh cannot occlude
(light/samples.py), equal channels computed once (pair_kernel.PairKernel), the far field summed by clusters
(farfield.py), Monte Carlo never unless asked. ``AutoPlan.counts()`` reports the decisions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from meshshade.geometry.topology import vertex_adjacency
from meshshade.kernels.curvature import VALIDITY_TOL, curvature_ratios
from meshshade.materials import Material
from meshshade.surface.models import KERNEL_NAMES, Kernel

#: defaults (see module docstring; the validity tolerance is the curvature kernel's own, VALIDITY_TOL)
CURVATURE_TOL = 1e-2
GEODESIC_TOL = 0.3
UMBILIC_TOL = 0.1


@dataclass(frozen=True)
class AutoPlan:
    """Per entry sample: ``kernel`` (k,) int8, a :class:`~meshshade.surface.models.Kernel` 0-3 (named by
    KERNEL_NAMES); ``exact_geodesic`` (k,) bool (exact geodesics in the near zone); ``far_dipole`` (k,) bool (the
    surface is flat on the scale of the cutoff around the sample, so its far field may be summed by clusters with
    the planar dipole of the chord)."""

    kernel: np.ndarray
    exact_geodesic: np.ndarray
    far_dipole: np.ndarray

    def counts(self) -> dict:
        """Counts per decision, for metadata and ``--verbose``."""
        out = {f"auto_kernel_{name}": int(np.sum(self.kernel == i)) for i, name in enumerate(KERNEL_NAMES)}
        out["auto_geodesic_exact"] = int(self.exact_geodesic.sum())
        out["auto_geodesic_arc"] = int(self.exact_geodesic.size - self.exact_geodesic.sum())
        return out

    def describe(self) -> str:
        c = self.counts()
        return (f"auto: kernel dipole {c['auto_kernel_dipole']}, curved {c['auto_kernel_curved']}, "
                f"exact-sphere {c['auto_kernel_exact-sphere']}, fitted {c['auto_kernel_fitted']} entry samples; "
                f"geodesics exact "
                f"{c['auto_geodesic_exact']}, arc {c['auto_geodesic_arc']}")


def curvature_bound_mm(material: Material, radius_mm) -> np.ndarray:
    """(3,) mm: per channel, ``W_c = max over rho in [0, radius_c] of (|a(rho)| + |b(rho)|)`` in mm.

    ``kmax W_c`` bounds the first-order relative correction |delta| of every pair within the radius.
    ``radius_mm``: scalar or (3,). The maximum is taken on a 64-point grid plus the end point (a and b are
    smooth and grow nearly linearly, so the end point is the maximum in practice).
    """
    radius = np.broadcast_to(np.asarray(radius_mm, dtype=np.float64), (3,))
    out = np.empty(3)
    for c in range(3):
        ch = material.channel(c)
        st = ch["sigma_t_prime"]
        rho = np.linspace(0.0, radius[c] * st, 65)
        a, b = curvature_ratios(rho, albedo_prime=ch["albedo_prime"], eta=ch["eta"])
        out[c] = float(np.max(np.abs(a) + np.abs(b))) / st
    return out


def dilated_max(values, indptr, indices, rings: int) -> np.ndarray:
    """Per vertex, the max of ``values`` ((n,) or (n, m)) over the vertices within ``rings`` edges (vectorised;
    O(rings E))."""
    out = np.asarray(values, dtype=np.float64).copy()
    has = np.diff(indptr) > 0
    starts = indptr[:-1][has]
    rows = np.flatnonzero(has)
    for _ in range(int(rings)):
        if indices.size == 0:
            break
        new = out.copy()
        new[rows] = np.maximum(out[has], np.maximum.reduceat(out[indices], starts, axis=0))
        if np.array_equal(new, out):
            break
        out = new
    return out


def plan_sources(k1, k2, k_near, k_far, material: Material, near_mm, cutoff_mm, *, kmin_far=None,
                 curvature_tol: float = CURVATURE_TOL, geodesic_tol: float = GEODESIC_TOL,
                 umbilic_tol: float = UMBILIC_TOL, validity_tol: float = VALIDITY_TOL) -> AutoPlan:
    """Decide kernel, near-zone geodesic method and far-field treatment per entry sample (module docstring).

    k1, k2 : (k,) 1/mm, the sample's principal curvatures (k1 >= k2); k_near, k_far : (k,) 1/mm, the largest
    |principal curvature| within about the near radius and the cutoff of the sample; near_mm : (k,) mm, the
    radius of the sample's near zone (its cutoff where there is no far field); cutoff_mm : scalar or (3,) mm,
    the neighbourhood radius per channel; kmin_far : (k,) 1/mm or None, the smallest principal curvature
    within the cutoff (the exact sphere is chosen only where the whole neighbourhood is that sphere: all
    principal curvatures within ``umbilic_tol`` of the sample's; None: k2).
    """
    for name, v in (("curvature_tol", curvature_tol), ("geodesic_tol", geodesic_tol),
                    ("umbilic_tol", umbilic_tol), ("validity_tol", validity_tol)):
        if not v >= 0:  # also rejects NaN; inf switches a decision off
            raise ValueError(f"{name} must be a number >= 0 (inf allowed), got {v}")
    k1 = np.asarray(k1, dtype=np.float64)
    k2 = np.asarray(k2, dtype=np.float64)
    kmax = np.maximum(np.abs(k1), np.abs(k2))
    W = curvature_bound_mm(material, cutoff_mm)
    inv_st = 1.0 / np.asarray(material.sigma_t_prime, dtype=np.float64)
    flat = kmax * W.max() <= curvature_tol
    out_of_range = kmax * (W + inv_st).max() > validity_tol
    kmin_far = k2 if kmin_far is None else np.asarray(kmin_far, dtype=np.float64)
    H = 0.5 * (k1 + k2)
    umbilic = ((k2 > 0) & (k1 - k2 <= umbilic_tol * k1) & (np.asarray(k_far) <= (1 + umbilic_tol) * H)
               & (kmin_far >= (1 - umbilic_tol) * H))
    kernel = np.full(k1.shape, Kernel.CURVED, dtype=np.int8)
    kernel[flat] = Kernel.DIPOLE_SURFACE
    kernel[~flat & out_of_range & umbilic] = Kernel.EXACT_SPHERE
    kernel[~flat & out_of_range & ~umbilic] = Kernel.FITTED
    near = np.broadcast_to(np.asarray(near_mm, dtype=np.float64), k1.shape)
    exact_geo = np.asarray(k_near, dtype=np.float64) * near > geodesic_tol
    far_dipole = np.asarray(k_far, dtype=np.float64) * W.max() <= curvature_tol
    return AutoPlan(kernel, exact_geo, far_dipole)


def neighbourhood_curvature(samples, vertex_values, vertices, faces, radii_mm, mean_edge_mm: float, *,
                            max_rings: int = 256, ball_query_below: int = 256) -> list:
    """Per entry sample, the max of each column of ``vertex_values`` (n, m) over the vertices within about each
    radius of ``radii_mm`` (a list of scalars or (k,) arrays); returns a list (one per radius) of (k, m) arrays.

    Few samples (beams, fewer than ``ball_query_below``): a k-d tree ball query around each sample (the
    Euclidean ball contains the geodesic one, so the max is conservative). Many samples: one vectorised graph
    dilation over the whole mesh (rings of the mean edge length; a face sample takes the max over its corners),
    read off at each radius's ring count.
    """
    vals = np.asarray(vertex_values, dtype=np.float64)
    vals = vals[:, None] if vals.ndim == 1 else vals
    k = len(samples)
    radii = [np.broadcast_to(np.asarray(r, dtype=np.float64), (k,)) for r in radii_mm]
    out = [np.empty((k, vals.shape[1])) for _ in radii]
    if k == 0:
        return out
    if k < ball_query_below:
        tree = cKDTree(vertices)
        for r, o in zip(radii, out):
            for i, nb in enumerate(tree.query_ball_point(samples.positions, r)):
                o[i] = vals[nb].max(axis=0) if len(nb) else vals[np.asarray(faces)[samples.face[i]]].max(axis=0)
        return out
    rings_of = {}
    for r in radii:
        for x in np.unique(r):
            rings_of[x] = int(min(max_rings, np.ceil(x / max(mean_edge_mm, 1e-300)) + 1))
    wanted = sorted(set(rings_of.values()))
    indptr, indices = vertex_adjacency(len(vals), faces)
    at_v = samples.vertex >= 0
    F = np.asarray(faces)
    dil, done = vals.copy(), 0
    per_ring = {}
    for target in wanted:
        dil = dilated_max(dil, indptr, indices, target - done)
        done = target
        per_ring[target] = dil
    for r, o in zip(radii, out):
        for x in np.unique(r):
            d = per_ring[rings_of[x]]
            sel = r == x
            o[sel & at_v] = d[samples.vertex[sel & at_v]]
            tri = sel & ~at_v
            if np.any(tri):
                o[tri] = d[F[samples.face[tri]]].max(axis=1)
    return out
