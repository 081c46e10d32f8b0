"""Conjugate gradients for the volume's diffusion systems, all material channels in one pass (compiled loops).

The channels' matrices K_c = D_c S + sigma_a,c M + B / (2 A_c) share one sparsity pattern, so one CSR index
structure serves them all and each sweep over it does the work of every channel (the solve is bound by memory
traffic). Preconditioner: the diagonal (Jacobi). Measured on spot's volume (63k nodes, 1.0M non-zeros, one
channel, scipy's CG, 2 cores): Jacobi 550 iterations in 1.3 s; pyamg's smoothed aggregation 90 iterations in 3.1 s
plus 0.4 s set-up (its V-cycle costs 15 matrix-vector products on these layered tetrahedra); three channels at once
here take 2.6-2.8 s.
Each channel stops at its own relative residual ``rtol``; the iteration counts are returned.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["pcg_jacobi"]


#: row blocks of the parallel loops (their partial sums are added in block order: the result does not depend on
#: the number of threads)
_BLOCKS = 128


@numba.njit(cache=True, parallel=True)
def _matvec_dot(indptr, indices, data, p, q, pq):
    """q = K p per channel and pq[c] = p_c . q_c, in one pass."""
    n, k = p.shape
    size = (n + _BLOCKS - 1) // _BLOCKS
    part = np.zeros((_BLOCKS, k))
    for t in numba.prange(_BLOCKS):
        for i in range(t * size, min(n, (t + 1) * size)):
            if k == 3:
                a0 = a1 = a2 = 0.0
                for j in range(indptr[i], indptr[i + 1]):
                    col = indices[j]
                    a0 += data[j, 0] * p[col, 0]
                    a1 += data[j, 1] * p[col, 1]
                    a2 += data[j, 2] * p[col, 2]
                q[i, 0], q[i, 1], q[i, 2] = a0, a1, a2
            else:
                for c in range(k):
                    a = 0.0
                    for j in range(indptr[i], indptr[i + 1]):
                        a += data[j, c] * p[indices[j], c]
                    q[i, c] = a
            for c in range(k):
                part[t, c] += p[i, c] * q[i, c]
    for c in range(k):
        pq[c] = 0.0
        for t in range(_BLOCKS):
            pq[c] += part[t, c]


@numba.njit(cache=True, parallel=True)
def _update_dots(x, r, p, q, z, inv_diag, alpha, rr, rz):
    """x += alpha p, r -= alpha q, z = r / diag, and rr[c] = r_c . r_c, rz[c] = r_c . z_c, in one pass."""
    n, k = x.shape
    size = (n + _BLOCKS - 1) // _BLOCKS
    part = np.zeros((_BLOCKS, 2 * k))
    for t in numba.prange(_BLOCKS):
        for i in range(t * size, min(n, (t + 1) * size)):
            for c in range(k):
                x[i, c] += alpha[c] * p[i, c]
                ri = r[i, c] - alpha[c] * q[i, c]
                r[i, c] = ri
                zi = inv_diag[i, c] * ri
                z[i, c] = zi
                part[t, c] += ri * ri
                part[t, k + c] += ri * zi
    for c in range(k):
        rr[c] = 0.0
        rz[c] = 0.0
        for t in range(_BLOCKS):
            rr[c] += part[t, c]
            rz[c] += part[t, k + c]


@numba.njit(cache=True, parallel=True)
def _direction(p, z, beta):
    n, k = p.shape
    for i in numba.prange(n):
        for c in range(k):
            p[i, c] = z[i, c] + beta[c] * p[i, c]


@numba.njit(cache=True)
def _pcg(indptr, indices, data, inv_diag, b, rtol, maxiter):
    """Preconditioned conjugate gradients per channel; a converged channel's step sizes are 0 from then on."""
    n, k = b.shape
    x = np.zeros((n, k))
    r = b.copy()
    z = inv_diag * r
    p = z.copy()
    q = np.zeros((n, k))
    rz = np.zeros(k)
    bb = np.zeros(k)
    rr = np.zeros(k)
    pq = np.zeros(k)
    alpha = np.zeros(k)
    beta = np.zeros(k)
    its = np.zeros(k, dtype=np.int64)
    for c in range(k):
        for i in range(n):
            rz[c] += r[i, c] * z[i, c]
            bb[c] += b[i, c] * b[i, c]
    active = bb > 0.0
    for it in range(maxiter):
        if not active.any():
            break
        _matvec_dot(indptr, indices, data, p, q, pq)
        for c in range(k):
            alpha[c] = rz[c] / pq[c] if active[c] and pq[c] > 0.0 else 0.0
        rz_old = rz.copy()
        _update_dots(x, r, p, q, z, inv_diag, alpha, rr, rz)
        for c in range(k):
            if active[c]:
                its[c] = it + 1
                if rr[c] <= rtol * rtol * bb[c]:
                    active[c] = False
            beta[c] = rz[c] / rz_old[c] if active[c] and rz_old[c] > 0.0 else 0.0
        _direction(p, z, beta)
    return x, its, active


def pcg_jacobi(indptr, indices, data, b, *, rtol=1e-7, maxiter=20000):
    """Solve K_c x_c = b_c for every channel c: ``data`` (nnz, k) the channels' values on one CSR structure
    (``indptr``, ``indices``), ``b`` (n, k). Returns (x (n, k), iterations (k,), converged (k,) bool)."""
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    indices = np.ascontiguousarray(indices, dtype=np.int64)
    data = np.ascontiguousarray(data, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    rows = np.repeat(np.arange(b.shape[0]), np.diff(indptr))
    diag = np.zeros(b.shape)
    on = rows == indices
    diag[rows[on]] = data[on]
    x, its, active = _pcg(indptr, indices, data, 1.0 / diag, b, float(rtol), int(maxiter))
    return x, its, ~active
