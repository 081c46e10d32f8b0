"""What is inside a surface mesh, watertight or not (docs/physics.md §15.2): the generalised winding number.

The winding number w(x) of a closed, consistently oriented surface is 1 inside and 0 outside; for an open
surface with holes, overlapping or nested parts, self-intersections, duplicated faces or non-manifold edges it
is a smooth harmonic function that jumps by one across every sheet and is about 1/2 across a hole (Jacobson,
Kavan and Sorkine-Hornung 2013, "Robust inside-outside segmentation using generalized winding numbers"). The
volume is {w > 1/2}: the union of overlapping parts, holes closed by the smooth continuation, a duplicated face
changing nothing. A hierarchy of the triangles (:mod:`meshshade.volume.triangle_tree`) evaluates it (Barill et
al. 2018's fast winding number) and the distance to the nearest face, in blocks on every core;
:class:`SurfaceVolume` combines them into the signed depth the lattice is built from
(:mod:`meshshade.volume.lattice`).

Pure array work; no I/O.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError
from meshshade.geometry.topology import vertex_components
from meshshade.pacing import default_threads
from meshshade.volume.triangle_tree import TriangleTree

__all__ = ["SurfaceVolume", "WINDING_FAST", "WINDING_EXACT", "WINDING_MARGIN"]

#: accuracy scales of the fast winding number (its Barnes-Hut parameter beta, as libigl's: 2 is its recommended
#: accuracy, within 0.004 of the exact sum on a sphere and the head scan); the quick pass errs by at most 0.2, so a
#: value within WINDING_MARGIN of 1/2 is recomputed at WINDING_EXACT
WINDING_FAST, WINDING_EXACT, WINDING_MARGIN = 1.0, 2.0, 0.3


class SurfaceVolume:
    """The volume {w > 1/2} of the triangles ``faces`` (F, 3) over ``vertices`` (V, 3) mm.

    :meth:`depth` is the signed distance to the nearest triangle (positive inside), clipped; :meth:`winding` the
    winding number itself. ``queries`` counts the points asked about (for the stats)."""

    def __init__(self, vertices, faces, points=None, spacing: float | None = None):
        """``points`` (q, 3): points of the surface no farther than ``spacing`` from every point of it (the
        vertices of the surface with its long edges split), for the quick distance bound of :meth:`depth`."""
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._points = None if points is None else cKDTree(np.asarray(points, dtype=np.float64))
        self._slack = 0.0 if spacing is None else float(spacing) / math.sqrt(3.0)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.faces.shape[0] == 0:
            raise MeshshadeError("the volume needs a triangle mesh with at least one face")
        self.queries = 0
        self.winding_queries = 0
        self._tree = None

    @property
    def tree(self) -> TriangleTree:
        """The hierarchy of the triangles (built at the first query)."""
        if self._tree is None:
            self._tree = TriangleTree(self.vertices, self.faces)
        return self._tree

    def winding(self, points) -> np.ndarray:
        """(p,) generalised winding number at ``points`` (p, 3) mm: the hierarchy's quick estimate (accuracy
        scale WINDING_FAST), refined (WINDING_EXACT) where it lies within WINDING_MARGIN of 1/2."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if P.shape[0] == 0:
            return np.zeros(0)
        w = self.tree.winding(P, WINDING_FAST)
        unsure = np.flatnonzero(np.abs(w - 0.5) < WINDING_MARGIN)
        if unsure.size:
            w[unsure] = self.tree.winding(P[unsure], WINDING_EXACT)
        return w

    def buried(self, vertices, normals, offset: float) -> np.ndarray:
        """(n,) bool: vertices of the mesh inside *another* of its parts (eyes in a head, overlapping armour),
        which are not on the exposed surface: ``offset`` mm outside the vertex along its normal, both the whole
        mesh's winding number and the other parts' (the whole less the vertex's own part's) are above 1/2. The
        second keeps a part folded into itself (common in scans) from burying anything, so a defect elsewhere
        cannot change it; the first keeps a cavity's wall (a closed part nested inside another, oriented inward)
        exposed to its cavity. Parts are the connected components of ``vertices`` (the mesh's, in order)."""
        V = np.asarray(vertices, dtype=np.float64)
        out = np.zeros(V.shape[0], dtype=bool)
        n_parts, label = vertex_components(V.shape[0], self.faces)
        if n_parts < 2:
            return out
        q = V + float(offset) * np.asarray(normals, dtype=np.float64)
        used = np.flatnonzero(label >= 0)
        w = self.winding(q[used])
        face_part = label[self.faces[:, 0]]
        own = np.zeros(used.size)
        for p in range(n_parts):
            mine = np.flatnonzero(label[used] == p)
            own[mine] = TriangleTree(self.vertices, self.faces[face_part == p]).winding(q[used[mine]], WINDING_EXACT)
        out[used] = (w > 0.5) & ((w - own) > 0.5)
        return out

    def depth(self, points, bound: float, sign=None, exact: bool | None = True) -> np.ndarray:
        """(p,) signed distance (mm) from ``points`` (p, 3) to the surface, positive where w > 1/2, its magnitude
        clipped to ``bound`` (beyond it only the sign is meaningful). ``sign`` (p,) int: the side where already
        known (+1 inside, -1 outside, 0 unknown: only those take the winding number). ``exact=False``: the
        magnitude is a lower bound instead, the distance to the nearest of the surface's points less their
        spacing over sqrt(3) (the point of a triangle farthest from its corners), which is what the lattice's
        coarse decisions need (every one of them errs on the side of more cubes); ``exact=None``: only the side,
        +-``bound``."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if P.shape[0] == 0:
            return np.zeros(0)
        self.queries += P.shape[0]
        if sign is None:
            inside = self.winding(P) > 0.5
        else:
            sign = np.asarray(sign)
            inside = sign > 0
            ask = np.flatnonzero(sign == 0)
            self.winding_queries += ask.size
            if ask.size:
                inside[ask] = self.winding(P[ask]) > 0.5
        if exact is None:
            return np.where(inside, float(bound), -float(bound))
        if not exact and self._points is not None:
            d, _ = self._points.query(P, distance_upper_bound=float(bound) + self._slack, workers=default_threads())
            d = np.clip(d - self._slack, 0.0, bound)
        else:
            d = self.tree.distance(P, float(bound))
        return np.where(inside, d, -d)
