"""Safe-distance grid of the Monte Carlo walk: free flights that cannot reach the surface need no ray cast.

A conservative distance-to-surface grid (``SafeDistanceGrid``) bounds, for every point of a voxel, the distance
to the nearest triangle from below: voxels touched by a triangle's bounding box are marked, the Euclidean
distance transform gives the distance ``e`` from a voxel's centre to the nearest marked centre, and for a point
x in voxel v and a surface point y in marked voxel w, |x - y| >= |c_v - c_w| - |x - c_v| - |y - c_w|
>= e - sqrt(3) h. While a sampled free path is shorter than that bound the photon scatters without Embree
(:func:`meshshade.montecarlo_kernels.interior_run`); otherwise the free path is kept (``pending``) and handed to
the boundary test, so every free path is drawn exactly once from the exponential law (no bias).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

class SafeDistanceGrid:
    """Lower bound of the distance to the mesh surface on a cubic voxel grid (mm).

    vertices : (n, 3) float64 mm; faces : (m, 3) int; resolution : voxels along the largest extent.
    """

    def __init__(self, vertices, faces, resolution: int = 96):
        from scipy.ndimage import distance_transform_edt  # noqa: PLC0415

        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        lo, hi = V.min(axis=0), V.max(axis=0)
        h = float((hi - lo).max()) / resolution
        pad = 2.0 * h
        self.origin = lo - pad
        self.h = h
        shape = np.maximum(np.ceil((hi - lo + 2 * pad) / h).astype(np.int64), 1)
        marked = np.zeros(tuple(shape), dtype=np.bool_)
        tri = V[F]
        i0 = np.clip(np.floor((tri.min(axis=1) - self.origin) / h).astype(np.int64), 0, shape - 1)
        i1 = np.clip(np.floor((tri.max(axis=1) - self.origin) / h).astype(np.int64), 0, shape - 1)
        _mark(marked, i0, i1)
        edt = distance_transform_edt(~marked) * h
        self.safe = np.ascontiguousarray(np.maximum(edt - math.sqrt(3.0) * h * 1.001, 0.0))

    def __repr__(self) -> str:
        return f"SafeDistanceGrid(shape={self.safe.shape}, h={self.h:.4g} mm, free={np.mean(self.safe > 0):.2f})"


@njit(cache=True)
def _mark(marked, i0, i1):
    for f in range(i0.shape[0]):
        for a in range(i0[f, 0], i1[f, 0] + 1):
            for b in range(i0[f, 1], i1[f, 1] + 1):
                for c in range(i0[f, 2], i1[f, 2] + 1):
                    marked[a, b, c] = True
