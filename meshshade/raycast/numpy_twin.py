"""The pure-numpy float64 backend: :class:`NumpyScene`, the reference that checks the Embree fast path.

Brute force over rays x faces (the float64 Moller-Trumbore test lives in :class:`meshshade.raycast.scene._SceneBase`,
which ``EmbreeScene.first_hit(..., exact=True)`` shares); fine for tiny meshes and used by the tests.
"""
from __future__ import annotations

import numpy as np

from meshshade.raycast.scene import _SceneBase

__all__ = ["NumpyScene"]


class NumpyScene(_SceneBase):
    """Pure-numpy float64 twin of :class:`~meshshade.raycast.embree.EmbreeScene` (brute force, O(rays x faces)).

    Moller & Trumbore (1997), "Fast, minimum storage ray-triangle intersection", J. Graphics Tools 2(1).
    Triangles are widened by 1e-12 in barycentric units (``u, v >= -1e-12``, ``u + v <= 1 + 1e-12``) so that a
    ray through a shared edge or vertex hits one of its faces despite rounding (watertight, like Embree's robust
    mode); the reported (u, v) are clipped back onto the triangle. Ties go to the lowest face index. ``chunk``
    bounds the number of ray-triangle pairs held in memory at once.
    """

    backend = "numpy"

    def __init__(self, vertices, faces, *, chunk: int = 1 << 18):
        super().__init__(vertices, faces)
        self.chunk = int(chunk)

    def _first_hit_faces(self, o, d):
        return self._brute_first_hit_faces(o, d)

    def _occluded(self, o, d, t_max):
        result = np.zeros(o.shape[0], dtype=bool)
        for rs, fs in self._chunks(o.shape[0]):
            t = self._pair_t(o[rs], d[rs], fs)
            result[rs] |= np.any(t < t_max[rs, None], axis=1)
        return result
