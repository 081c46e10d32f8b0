"""The assembled diffusion operator of one material channel on one tetrahedral mesh, solved for many sources.

The matrix of eq. (90) depends on the mesh and the material only, so :class:`DiffusionOperator` assembles it once
and keeps its algebraic-multigrid hierarchy (smoothed aggregation, PyAMG): each further source set (a light, a
channel's sources of a new bake) costs one preconditioned conjugate-gradient solve.
"""
from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse.linalg as spla

from meshshade.errors import MeshshadeError
from meshshade.volume.fem import assemble_diffusion, boundary_faces, tet_geometry

__all__ = ["DiffusionOperator", "SOLVE_RTOL"]

#: relative residual of the conjugate-gradient solves
SOLVE_RTOL = 1e-10


class DiffusionOperator:
    """K phi = b for ``nodes`` (N, 3) mm, ``tets`` (T, 4), one channel's D (mm), sigma_a (1/mm) and A.

    ``faces``: the boundary faces (default: every face of one tetrahedron only). ``solve(b)``: fluence phi (N,)
    W/mm^2 for the load ``b`` (N,) W (or (N, k) for k source sets at once).
    """

    def __init__(self, nodes, tets, *, D, sigma_a, A, faces=None):
        self.nodes = np.ascontiguousarray(nodes, dtype=np.float64)
        self.tets = np.ascontiguousarray(tets, dtype=np.int64)
        self.faces = boundary_faces(self.tets, self.nodes) if faces is None else np.asarray(faces, dtype=np.int64)
        self.D, self.sigma_a, self.A = float(D), float(sigma_a), float(A)
        self.geometry = tet_geometry(self.nodes, self.tets)
        self.matrix = assemble_diffusion(self.nodes, self.tets, self.faces, D=self.D, sigma_a=self.sigma_a, A=self.A,
                                         geometry=self.geometry)
        self._amg = pyamg.smoothed_aggregation_solver(self.matrix, symmetry="symmetric", max_coarse=500)
        self._M = self._amg.aspreconditioner(cycle="V")

    def solve(self, b):
        b = np.asarray(b, dtype=np.float64)
        if b.ndim == 2:
            return np.stack([self.solve(b[:, j]) for j in range(b.shape[1])], axis=1)
        norm = float(np.linalg.norm(b))
        if norm == 0.0:
            return np.zeros_like(b)
        x, info = spla.cg(self.matrix, b, rtol=SOLVE_RTOL, M=self._M, maxiter=500)
        if info != 0:
            raise MeshshadeError(f"the volume diffusion solve did not converge (conjugate gradients, info={info})")
        return x
