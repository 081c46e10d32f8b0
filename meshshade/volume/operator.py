"""The assembled diffusion operators of a material's channels on one tetrahedral mesh, solved for many sources.

The matrices of eq. (90) depend on the mesh and the material only, and the channels' share one sparsity
pattern: :class:`DiffusionOperator` assembles them once on one CSR structure, and each source set (a light, the
channels' sources of a new bake) costs one conjugate-gradient solve of every channel at once
(:func:`meshshade.volume.solve.pcg_jacobi`).
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.volume.fem import assemble_channels, boundary_faces
from meshshade.volume.solve import pcg_jacobi

__all__ = ["DiffusionOperator", "SOLVE_RTOL"]

#: relative residual of the conjugate-gradient solves (measured on spot's volume: the surface values within 2e-6
#: of the peak of a 1e-12 solve)
SOLVE_RTOL = 1e-7


class DiffusionOperator:
    """K_c phi_c = b_c for ``nodes`` (N, 3) mm, ``tets`` (T, 4) and k channels' D (mm), sigma_a (1/mm) and A
    (numbers for one channel, or sequences of k).

    ``faces``: the boundary faces (default: every face of one tetrahedron only); ``lumped``: diagonal mass
    matrices (:func:`~meshshade.volume.fem.assemble_diffusion`). ``solve(b)``: fluence phi W/mm^2 for the load
    ``b`` W, (N,) for one channel or (N, k) for k.
    """

    def __init__(self, nodes, tets, *, D, sigma_a, A, faces=None, lumped=False):
        self.nodes = np.ascontiguousarray(nodes, dtype=np.float64)
        self.tets = np.ascontiguousarray(tets, dtype=np.int64)
        self.faces = boundary_faces(self.tets, self.nodes) if faces is None else np.asarray(faces, dtype=np.int64)
        self.D, self.sigma_a, self.A = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (D, sigma_a, A))
        self.channels = self.D.size
        self.indptr, self.indices, self.data = assemble_channels(self.nodes, self.tets, self.faces, D=self.D,
                                                                 sigma_a=self.sigma_a, A=self.A,
                                                                 lumped=lumped)
        self.iterations = None

    def solve(self, b, rtol: float = SOLVE_RTOL):
        b = np.asarray(b, dtype=np.float64)
        one = b.ndim == 1
        B = b[:, None] if one else b
        if B.shape != (self.nodes.shape[0], self.channels):
            raise MeshshadeError(f"the load must be ({self.nodes.shape[0]}, {self.channels}), got {b.shape}")
        x, self.iterations, converged = pcg_jacobi(self.indptr, self.indices, self.data, B, rtol=rtol)
        if not np.all(converged):
            raise MeshshadeError(f"the volume diffusion solve did not converge (conjugate gradients, "
                                 f"{int(self.iterations.max())} iterations)")
        return x[:, 0] if one else x
