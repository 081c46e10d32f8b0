"""Shadow rays of directional and point lights, with the ones that provably cannot hit the mesh skipped."""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from meshshade.geometry.convexity import is_convex
from meshshade.geometry.mesh import face_normals

__all__ = ["ShadowCuller"]


class ShadowCuller:
    """Decides which shadow rays can be skipped, and casts the rest.

    Rule: the ray from a surface vertex ``p`` toward the light (unit ``L``) cannot meet the mesh if ``p`` lies on a
    *supporting plane* of the mesh (the whole mesh on its back side, outward normal ``n``) with ``n . L > 1e-6``:
    every point ``p + t L``, ``t > 0``, is then strictly in front of that plane, hence off the mesh. This holds for
    a directional light and for the segment to a point light alike. Supporting planes come from:

    * a convex mesh: every face plane supports it, so a vertex is skipped if an adjacent face has
      ``n_f . L > 1e-6``. With vertex normals that are positive combinations of the adjacent face normals (area-
      or angle-weighted), every vertex with ``n_v . L > 0`` has one unless all its faces are within 1e-6 of
      grazing. Convexity is certified in O(faces), see :func:`meshshade.geometry.convexity.is_convex`;
    * the convex hull (scipy/qhull): a hull vertex is skipped if an incident hull facet has ``n . L > 1e-6``.
      Used only with the brute-force ``NumpyScene``, where a ray costs O(faces): with Embree a shadow ray costs
      ~0.3 us while qhull needs seconds on a 1e5-vertex near-spherical mesh, so computing the hull to save rays
      would be a loss.

    Everything else is cast with the scene's ``occluded`` from the vertex, offset along its normal.

    Parameters
    ----------
    vertices : (n, 3) float64 mm; faces : (m, 3) int64, outward
    get_scene : callable () -> EmbreeScene or NumpyScene of the same mesh, called only when a ray must be cast
    use_hull : bool, try the convex-hull rule when the mesh is not convex

    Notes
    -----
    ``stats`` counts ``shadow_rays_cast``, ``shadow_rays_skipped`` (= ``skipped_convex`` + ``skipped_hull``);
    ``convex`` is None until the first query.
    """

    COS_TOL = 1e-6

    def __init__(self, vertices, faces, get_scene, use_hull: bool):
        self.V, self.F = vertices, faces
        self._get_scene = get_scene
        self.use_hull = bool(use_hull)
        self._ready = False
        self.convex: bool | None = None
        self.stats = {"shadow_rays_cast": 0, "shadow_rays_skipped": 0, "skipped_convex": 0, "skipped_hull": 0}

    def _prepare(self):
        if self._ready:
            return
        V, F = self.V, self.F
        self.face_normals = face_normals(V, F)
        self.convex = is_convex(V, F)
        self.hull_simplices = np.zeros((0, 3), dtype=np.int64)
        self.hull_normals = np.zeros((0, 3))
        if self.use_hull and not self.convex:
            try:
                hull = ConvexHull(V)
                self.hull_simplices = hull.simplices.astype(np.int64)
                self.hull_normals = hull.equations[:, :3]
            except (QhullError, ValueError):  # flat or degenerate point sets: no hull, cast every ray
                pass
        self._ready = True

    def _supported(self, idx, L, simplices, normals):
        """(k,) bool: vertex idx[j] lies on a plane in (simplices, normals) with normal . L[j] > COS_TOL."""
        if simplices.shape[0] == 0:
            return np.zeros(idx.size, dtype=bool)
        pos = np.full(self.V.shape[0], -1, dtype=np.int64)
        pos[idx] = np.arange(idx.size)
        pv = pos[simplices.reshape(-1)]
        pf = np.repeat(np.arange(simplices.shape[0]), 3)
        keep = pv >= 0
        pv, pf = pv[keep], pf[keep]
        best = np.full(idx.size, -np.inf)
        np.maximum.at(best, pv, np.einsum("ij,ij->i", normals[pf], L[pv]))
        return best > self.COS_TOL

    def visible(self, idx, normals, target=None, direction=None) -> np.ndarray:
        """(k,) bool: vertex idx[j] sees the light (a point ``target`` (3,) mm, or a unit ``direction`` (3,)).

        normals : (k, 3) unit vertex normals (shadow rays start offset along them).
        """
        k = idx.size
        if k == 0:
            return np.zeros(0, dtype=bool)
        self._prepare()
        p = self.V[idx]
        if target is not None:
            L = target - p
            L /= np.linalg.norm(L, axis=1, keepdims=True)
        else:
            L = np.broadcast_to(direction, (k, 3))
        if self.convex:
            skip = self._supported(idx, L, self.F, self.face_normals)
            self.stats["skipped_convex"] += int(skip.sum())
        else:
            skip = self._supported(idx, L, self.hull_simplices, self.hull_normals)
            self.stats["skipped_hull"] += int(skip.sum())
        self.stats["shadow_rays_skipped"] += int(skip.sum())
        visible = np.ones(k, dtype=bool)
        cast = np.flatnonzero(~skip)
        if cast.size:
            scene = self._get_scene()
            origins = scene.offset_origins(p[cast], normals[cast], +1.0)
            if target is not None:
                to_light = target - origins
                t_max = np.linalg.norm(to_light, axis=1)
                visible[cast] = ~scene.occluded(origins, to_light, t_max)
            else:
                visible[cast] = ~scene.occluded(origins, L[cast], np.inf)
            self.stats["shadow_rays_cast"] += int(cast.size)
        return visible
