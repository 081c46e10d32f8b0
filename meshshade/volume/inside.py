"""What is inside a surface mesh, watertight or not (docs/physics.md §15.2): the generalised winding number.

The winding number w(x) of a closed, consistently oriented surface is 1 inside and 0 outside; for an open
surface with holes, overlapping or nested parts, self-intersections, duplicated faces or non-manifold edges it
is a smooth harmonic function that jumps by one across every sheet and is about 1/2 across a hole (Jacobson,
Kavan and Sorkine-Hornung 2013, "Robust inside-outside segmentation using generalized winding numbers"). The
volume is {w > 1/2}: the union of overlapping parts, holes closed by the smooth continuation, a duplicated face
changing nothing. libigl's ``fast_winding_number`` evaluates it (Barill et al. 2018), and its AABB tree the
distance to the nearest face; :class:`SurfaceVolume` combines them into the signed depth the lattice is built
from (:mod:`meshshade.volume.lattice`).

Pure array work over the libigl calls; no I/O.
"""
from __future__ import annotations

import igl
import numpy as np

from meshshade.errors import MeshshadeError

__all__ = ["SurfaceVolume"]


class SurfaceVolume:
    """The volume {w > 1/2} of the triangles ``faces`` (F, 3) over ``vertices`` (V, 3) mm.

    :meth:`depth` is the signed distance to the nearest triangle (positive inside), clipped; :meth:`winding` the
    winding number itself. ``queries`` counts the points asked about (for the stats)."""

    def __init__(self, vertices, faces):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.faces.shape[0] == 0:
            raise MeshshadeError("the volume needs a triangle mesh with at least one face")
        self.queries = 0

    def winding(self, points) -> np.ndarray:
        """(p,) generalised winding number at ``points`` (p, 3) mm."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if P.shape[0] == 0:
            return np.zeros(0)
        return igl.fast_winding_number(self.vertices, self.faces, P)

    def depth(self, points, bound: float) -> np.ndarray:
        """(p,) signed distance (mm) from ``points`` (p, 3) to the surface, positive where w > 1/2, its magnitude
        clipped to ``bound`` (beyond it only the sign is meaningful)."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if P.shape[0] == 0:
            return np.zeros(0)
        self.queries += P.shape[0]
        inside = self.winding(P) > 0.5
        d = igl.signed_distance(P, self.vertices, self.faces, sign_type=igl.SIGNED_DISTANCE_TYPE_UNSIGNED,
                                upper_bound=float(bound))[0]
        d = np.where(np.isfinite(d), np.minimum(d, bound), bound)
        return np.where(inside, d, -d)
