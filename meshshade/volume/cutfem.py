"""P1 finite elements on the lattice's cubes, cut by the surface (docs/physics.md §15.2, eqs. (90) and (99)).

The weak form of eq. (90) is integrated over the part of each tetrahedron that lies inside (the depth, linear on
the tetrahedron through its corners' values, positive): a cube wholly inside takes the reference cube's matrices
(Kuhn's six tetrahedra: its stiffness couples only the cube's edges, so inside the volume the stiffness is the
7-point Laplacian), a cut cube has each of its tetrahedra clipped by the plane where the interpolated depth
vanishes, the inside part split into sub-tetrahedra (1, 3 or 3 of them) over which the P1 integrals are exact, and
the cut surface (1 or 2 triangles per tetrahedron) carries the boundary term phi v / (2A) (the "cut-cell" or
"unfitted" finite element method). The matrices are channel-independent:

    S_ij = int_in grad l_i . grad l_j,   m_i = int_in l_i   (lumped mass),   B_ij = int_cut l_i l_j   (consistent),

so each channel's matrix is K_c = D_c S + sigma_a,c diag(m) + B / (2 A_c) (:class:`meshshade.volume.multigrid.ChannelOperator`).
Hanging nodes are eliminated as they are assembled (each is the mean of two others), so the matrices act on the
lattice's free nodes; nodes with no inside in their support are dropped.

A tetrahedron cut so that only a sliver of it is inside leaves its outside corners' rows nearly empty; a small
fraction ``GHOST`` of the full tetrahedron's stiffness and mass on the part outside (the finite cell method's
fictitious material) keeps them definite without moving the solution (measured: 1e-2 and 1e-3 agree to 1e-4).

Compiled loops (numba) on the worker threads: chunks of cubes write every entry (row, column, value) into each
cube's own slots; the rows are counted and filled per block of entries (keeping the entries' order within a row),
the duplicates summed row by row into CSR. No Python loop over cells or nodes, no sort, and the same sums for any
number of threads.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.pacing import default_threads, parallel_for

__all__ = ["Assembly", "assemble", "cut_tetrahedron", "GHOST", "constraint_map"]

#: fictitious stiffness and mass on the outside part of a cut tetrahedron (fraction of the real ones)
GHOST = 1e-3

# reference cube (unit side) of Kuhn's six tetrahedra: stiffness (8, 8) and lumped mass (8,)
_KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]], dtype=np.int64)
_CORNERS = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=np.float64)


def _reference_cube():
    S = np.zeros((8, 8))
    m = np.zeros(8)
    for t in _KUHN:
        E = _CORNERS[t[1:]] - _CORNERS[t[0]]
        vol = abs(np.linalg.det(E)) / 6.0
        inv = np.linalg.inv(E)
        g = np.vstack([-inv.T.sum(axis=0), inv.T])
        S[np.ix_(t, t)] += vol * g @ g.T
        m[t] += vol / 4.0
    S[np.abs(S) < 1e-15] = 0.0
    return S, m


_S_REF, _M_REF = _reference_cube()
_REF_PAIRS = np.array([(i, j) for i in range(8) for j in range(i + 1, 8) if _S_REF[i, j] != 0.0], dtype=np.int64)
_REF_DIAG = np.diag(_S_REF).copy()
_REF_VALUES = np.array([_S_REF[i, j] for i, j in _REF_PAIRS])


class Assembly:
    """The channel-independent matrices on the free, active nodes: ``S``, ``B`` (CSR on one pattern: ``indptr``,
    ``indices``, ``s_data``, ``b_data``), the lumped mass ``m``; ``free`` (n,) the lattice node of each unknown;
    ``expand`` (N, k) -> the value at every lattice node from the unknowns (:meth:`to_nodes`); ``volume`` and
    ``area`` of the discrete domain (mm^3, mm^2)."""

    def __init__(self, indptr, indices, s_data, b_data, m, free, cmap, volume, area):
        self.indptr, self.indices = indptr, indices
        self.s_data, self.b_data, self.m = s_data, b_data, m
        self.free = free
        self._cptr, self._cidx, self._cw = cmap
        self.volume, self.area = volume, area

    @property
    def n(self) -> int:
        return int(self.m.shape[0])

    def to_nodes(self, x):
        """(N, k) values at every lattice node of the unknowns ``x`` (n, k) (hanging nodes interpolated; nodes of
        no unknown 0)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.zeros((self._cptr.size - 1, x.shape[1]))
        _expand(self._cptr, self._cidx, self._cw, x, out)
        return out

    def to_unknowns(self, b):
        """(n, k) loads on the unknowns of nodal loads ``b`` (N, k) (the transpose of :meth:`to_nodes`)."""
        b = np.ascontiguousarray(b, dtype=np.float64)
        out = np.zeros((self.n, b.shape[1]))
        _gather(self._cptr, self._cidx, self._cw, b, out)
        return out


@numba.njit(cache=True)
def _expand(cptr, cidx, cw, x, out):
    for i in range(cptr.size - 1):
        for q in range(cptr[i], cptr[i + 1]):
            for c in range(x.shape[1]):
                out[i, c] += cw[q] * x[cidx[q], c]


@numba.njit(cache=True)
def _gather(cptr, cidx, cw, b, out):
    for i in range(cptr.size - 1):
        for q in range(cptr[i], cptr[i + 1]):
            for c in range(b.shape[1]):
                out[cidx[q], c] += cw[q] * b[i, c]


def constraint_map(n_nodes: int, hanging, parents):
    """(cptr (N+1,), cidx, cw, n_free): each lattice node as a combination of free nodes (a free node itself; a
    hanging node the mean of its parents, resolved until every term is free)."""
    is_h = np.zeros(n_nodes, dtype=bool)
    is_h[hanging] = True
    free = np.flatnonzero(~is_h)
    fidx = np.full(n_nodes, -1, dtype=np.int64)
    fidx[free] = np.arange(free.size)
    hpos = np.full(n_nodes, -1, dtype=np.int64)
    hpos[hanging] = np.arange(hanging.size)
    rows, cols, ws = [free], [fidx[free]], [np.ones(free.size)]
    r = np.concatenate([hanging, hanging])
    p = np.concatenate([parents[:, 0], parents[:, 1]])
    w = np.full(r.size, 0.5)
    for _ in range(64):
        h = is_h[p]
        rows.append(r[~h])
        cols.append(fidx[p[~h]])
        ws.append(w[~h])
        if not h.any():
            break
        r, p, w = r[h], p[h], w[h]
        k = hpos[p]
        r = np.concatenate([r, r])
        p = np.concatenate([parents[k, 0], parents[k, 1]])
        w = np.concatenate([0.5 * w, 0.5 * w])
    else:
        raise MeshshadeError("hanging nodes of the volume's lattice do not resolve (the grading is not 2:1)")
    rows, cols, ws = np.concatenate(rows), np.concatenate(cols), np.concatenate(ws)
    order = np.lexsort((cols, rows))
    rows, cols, ws = rows[order], cols[order], ws[order]
    cptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.add.at(cptr, rows + 1, 1)
    return np.cumsum(cptr), cols.astype(np.int64), ws, int(free.size)


@numba.njit(cache=True, inline="always")
def _det3(a0, a1, a2, b0, b1, b2, c0, c1, c2):
    return a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)


@numba.njit(cache=True, inline="always")
def _sub(B, i0, i1, i2, i3, vol_full, m):
    """Add int of each barycentric over the sub-tetrahedron with barycentric corners rows i0..i3 of B to m;
    return its volume."""
    v = abs(_det3(B[i1, 1] - B[i0, 1], B[i1, 2] - B[i0, 2], B[i1, 3] - B[i0, 3],
                  B[i2, 1] - B[i0, 1], B[i2, 2] - B[i0, 2], B[i2, 3] - B[i0, 3],
                  B[i3, 1] - B[i0, 1], B[i3, 2] - B[i0, 2], B[i3, 3] - B[i0, 3])) * vol_full
    for k in range(4):
        m[k] += v * 0.25 * (B[i0, k] + B[i1, k] + B[i2, k] + B[i3, k])
    return v


@numba.njit(cache=True, inline="always")
def _tri(B, P, i0, i1, i2, bm, bb):
    """Add int over the triangle (barycentric corners i0, i1, i2) of l_k (to bm) and of l_k l_j (to bb); return
    its area."""
    x = np.zeros((3, 3))
    for r, i in enumerate((i0, i1, i2)):
        for d in range(3):
            x[r, d] = B[i, 0] * P[0, d] + B[i, 1] * P[1, d] + B[i, 2] * P[2, d] + B[i, 3] * P[3, d]
    ux, uy, uz = x[1, 0] - x[0, 0], x[1, 1] - x[0, 1], x[1, 2] - x[0, 2]
    wx, wy, wz = x[2, 0] - x[0, 0], x[2, 1] - x[0, 1], x[2, 2] - x[0, 2]
    cx, cy, cz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    area = 0.5 * math.sqrt(cx * cx + cy * cy + cz * cz)
    for k in range(4):
        sk = B[i0, k] + B[i1, k] + B[i2, k]
        bm[k] += area * sk / 3.0
        for j in range(4):
            sj = B[i0, j] + B[i1, j] + B[i2, j]
            bb[k, j] += area / 12.0 * (B[i0, k] * B[i0, j] + B[i1, k] * B[i1, j] + B[i2, k] * B[i2, j] + sk * sj)
    return area


@numba.njit(cache=True)
def cut_tetrahedron(P, s, m, bm, bb):
    """The inside {sum_i l_i s_i > 0} of the tetrahedron ``P`` (4, 3) with corner depths ``s`` (4,): adds
    int_in l_i to ``m`` (4,), int_cut l_i to ``bm`` (4,) and int_cut l_i l_j to ``bb`` (4, 4); returns
    (inside volume, full volume, cut area). Exact for the linearly interpolated depth."""
    vol_full = abs(_det3(P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2],
                         P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2],
                         P[3, 0] - P[0, 0], P[3, 1] - P[0, 1], P[3, 2] - P[0, 2])) / 6.0
    pos = np.zeros(4, np.int64)
    neg = np.zeros(4, np.int64)
    npos = 0
    nneg = 0
    for k in range(4):
        if s[k] > 0.0:
            pos[npos] = k
            npos += 1
        else:
            neg[nneg] = k
            nneg += 1
    if npos == 4:
        for k in range(4):
            m[k] += 0.25 * vol_full
        return vol_full, vol_full, 0.0
    if npos == 0:
        return 0.0, vol_full, 0.0
    B = np.zeros((6, 4))
    if npos == 1 or npos == 3:
        one = pos[0] if npos == 1 else neg[0]
        B[0, one] = 1.0
        for j in range(3):
            o = neg[j] if npos == 1 else pos[j]
            t = s[one] / (s[one] - s[o])
            B[1 + j, one] = 1.0 - t
            B[1 + j, o] = t
        small = np.zeros(4)
        v = _sub(B, 0, 1, 2, 3, vol_full, small)
        area = _tri(B, P, 1, 2, 3, bm, bb)
        if npos == 1:
            for k in range(4):
                m[k] += small[k]
            return v, vol_full, area
        for k in range(4):
            m[k] += 0.25 * vol_full - small[k]
        return vol_full - v, vol_full, area
    a, b, c, d = pos[0], pos[1], neg[0], neg[1]
    # the inside is the prism a q_ac q_ad | b q_bc q_bd (rows 0 1 2 | 3 4 5), three tetrahedra
    B[0, a] = 1.0
    B[3, b] = 1.0
    for row, x, y in ((1, a, c), (2, a, d), (4, b, c), (5, b, d)):
        t = s[x] / (s[x] - s[y])
        B[row, x] = 1.0 - t
        B[row, y] = t
    v = _sub(B, 0, 1, 2, 3, vol_full, m) + _sub(B, 1, 2, 3, 4, vol_full, m) + _sub(B, 2, 3, 4, 5, vol_full, m)
    area = _tri(B, P, 1, 4, 5, bm, bb) + _tri(B, P, 1, 5, 2, bm, bb)
    return v, vol_full, area


@numba.njit(cache=True, inline="always")
def _put(i, j, sv, bv, cptr, cidx, cw, rows, cols, s_val, b_val, q):
    """Add (sv, bv) at lattice nodes (i, j), i != j, to the free nodes' entries: triplets (row <= col; a pair
    landing on one free node adds twice its value on the diagonal)."""
    for qi in range(cptr[i], cptr[i + 1]):
        for qj in range(cptr[j], cptr[j + 1]):
            a, b = cidx[qi], cidx[qj]
            w = cw[qi] * cw[qj]
            rows[q] = min(a, b)
            cols[q] = max(a, b)
            f = 2.0 if a == b else 1.0
            s_val[q] = f * sv * w
            b_val[q] = f * bv * w
            q += 1
    return q


@numba.njit(cache=True, inline="always")
def _put_diagonal(i, sv, bv, mv, cptr, cidx, cw, rows, cols, s_val, b_val, q):
    """Add (sv, bv) at (i, i) and the mass mv at i to the free nodes' entries (the mass as a triplet of column
    -1); of the pairs (a, b) and (b, a) of i's expansion one triplet (row <= col) is written."""
    for qi in range(cptr[i], cptr[i + 1]):
        a = cidx[qi]
        rows[q] = a
        cols[q] = -1
        s_val[q] = mv * cw[qi]
        b_val[q] = 0.0
        q += 1
        for qj in range(cptr[i], cptr[i + 1]):
            b = cidx[qj]
            if a > b:
                continue
            w = cw[qi] * cw[qj]
            rows[q] = a
            cols[q] = b
            s_val[q] = sv * w
            b_val[q] = bv * w
            q += 1
    return q


@numba.njit(cache=True, inline="always")
def _gradients(E, G):
    """G[1:] = the gradients of the barycentrics l_1..l_3 of the tetrahedron with edge vectors E (rows: corner k
    minus corner 0): the rows of E^-T (adjugate over the determinant); G[0] = -(G[1] + G[2] + G[3])."""
    a, b, c = E[0, 0], E[0, 1], E[0, 2]
    d, e, f = E[1, 0], E[1, 1], E[1, 2]
    g, h, k = E[2, 0], E[2, 1], E[2, 2]
    A, B, C = e * k - f * h, f * g - d * k, d * h - e * g
    inv_det = 1.0 / (a * A + b * B + c * C)
    # (E^-1)[:, r] is the gradient of l_{r+1}
    G[1, 0], G[1, 1], G[1, 2] = A * inv_det, B * inv_det, C * inv_det
    G[2, 0], G[2, 1], G[2, 2] = (c * h - b * k) * inv_det, (a * k - c * g) * inv_det, (b * g - a * h) * inv_det
    G[3, 0], G[3, 1], G[3, 2] = (b * f - c * e) * inv_det, (c * d - a * f) * inv_det, (a * e - b * d) * inv_det
    for j in range(3):
        G[0, j] = -(G[1, j] + G[2, j] + G[3, j])


@numba.njit(cache=True, inline="always")
def _diagonal_slots(i, cptr, cidx):
    """The triplets :func:`_put_diagonal` writes for lattice node i."""
    n = 0
    for qi in range(cptr[i], cptr[i + 1]):
        n += 1
        for qj in range(cptr[i], cptr[i + 1]):
            if cidx[qi] <= cidx[qj]:
                n += 1
    return n


@numba.njit(cache=True, nogil=True)
def _slots(cell_nodes, depth, cptr, cidx, ref_pairs, kuhn, out, c0, c1):
    """out[c + 1] = the triplets cube c writes (every tetrahedron of a cut cube counted), cubes c0..c1."""
    for c in range(c0, c1):
        cut = False
        for k in range(8):
            if depth[cell_nodes[c, k]] <= 0.0:
                cut = True
        n = 0
        if not cut:
            for r in range(ref_pairs.shape[0]):
                i, j = cell_nodes[c, ref_pairs[r, 0]], cell_nodes[c, ref_pairs[r, 1]]
                n += (cptr[i + 1] - cptr[i]) * (cptr[j + 1] - cptr[j])
            for k in range(8):
                n += _diagonal_slots(cell_nodes[c, k], cptr, cidx)
        else:
            for t in range(6):
                for a in range(4):
                    i = cell_nodes[c, kuhn[t, a]]
                    n += _diagonal_slots(i, cptr, cidx)
                    for b in range(a + 1, 4):
                        j = cell_nodes[c, kuhn[t, b]]
                        n += (cptr[i + 1] - cptr[i]) * (cptr[j + 1] - cptr[j])
        out[c + 1] = n


@numba.njit(cache=True, nogil=True)
def _entries(nodes, depth, cell_nodes, level, h0, cptr, cidx, cw, ref_pairs, ref_values, ref_diag, m_ref, ghost,
             start, rows, cols, s_val, b_val, totals, c0, c1):
    """The triplets of cubes c0..c1 (whole chunks of CHUNK cubes) in free-node numbering (hanging nodes
    expanded), each cube's in its slots start[c]..start[c + 1] (unused slots row -1): the upper triangle and
    diagonal as (row <= col) triplets, the lumped mass as (row, -1); totals[chunk] the inside volume and the cut
    area."""
    kuhn = _KUHN
    P = np.zeros((4, 3))
    s = np.zeros(4)
    G = np.zeros((4, 3))
    E = np.zeros((3, 3))
    be = np.zeros((4, 4))
    mloc = np.zeros(4)
    bm = np.zeros(4)
    gid = np.zeros(4, np.int64)
    for c in range(c0, c1):
        ch = c // CHUNK
        q = start[c]
        h = h0 * (2.0 ** level[c])
        cut = False
        for k in range(8):
            if depth[cell_nodes[c, k]] <= 0.0:
                cut = True
                break
        if not cut:
            totals[ch, 0] += h * h * h
            for r in range(ref_pairs.shape[0]):
                q = _put(cell_nodes[c, ref_pairs[r, 0]], cell_nodes[c, ref_pairs[r, 1]], h * ref_values[r], 0.0,
                         cptr, cidx, cw, rows, cols, s_val, b_val, q)
            for k in range(8):
                q = _put_diagonal(cell_nodes[c, k], h * ref_diag[k], 0.0, h * h * h * m_ref[k], cptr, cidx, cw,
                                  rows, cols, s_val, b_val, q)
        else:
            for t in range(6):
                for k in range(4):
                    n = cell_nodes[c, kuhn[t, k]]
                    gid[k] = n
                    for d in range(3):
                        P[k, d] = nodes[n, d]
                    s[k] = depth[n]
                for k in range(4):
                    mloc[k] = 0.0
                    bm[k] = 0.0
                    for j in range(4):
                        be[k, j] = 0.0
                vin, vfull, area = cut_tetrahedron(P, s, mloc, bm, be)
                totals[ch, 0] += vin
                totals[ch, 1] += area
                if vin <= 0.0 and area <= 0.0:
                    continue
                for r in range(3):
                    for d in range(3):
                        E[r, d] = P[r + 1, d] - P[0, d]
                _gradients(E, G)
                w = vin + ghost * (vfull - vin)
                for a in range(4):
                    ma = mloc[a] + ghost * (0.25 * vfull - mloc[a])
                    sa = w * (G[a, 0] * G[a, 0] + G[a, 1] * G[a, 1] + G[a, 2] * G[a, 2])
                    q = _put_diagonal(gid[a], sa, be[a, a], ma, cptr, cidx, cw, rows, cols, s_val, b_val, q)
                    for b in range(a + 1, 4):
                        sab = w * (G[a, 0] * G[b, 0] + G[a, 1] * G[b, 1] + G[a, 2] * G[b, 2])
                        q = _put(gid[a], gid[b], sab, be[a, b], cptr, cidx, cw, rows, cols, s_val, b_val, q)
        for k in range(q, start[c + 1]):
            rows[k] = -1
            cols[k] = 0


@numba.njit(cache=True, nogil=True)
def _row_counts(rows, cols, counts, t0, t1):
    """counts[r] += the entries row r takes from triplets t0..t1 (an off-diagonal triplet counts in both rows)."""
    for q in range(t0, t1):
        r, c = rows[q], cols[q]
        if r < 0 or c < 0:
            continue
        counts[r] += 1
        if c != r:
            counts[c] += 1


@numba.njit(cache=True, nogil=True)
def _scatter(rows, cols, s_val, b_val, pos, other, sv, bv, t0, t1):
    """Each triplet of t0..t1 into its rows' next places (pos[r], advanced): in triplet order within a row."""
    for q in range(t0, t1):
        r, c = rows[q], cols[q]
        if r < 0 or c < 0:
            continue
        k = pos[r]
        other[k] = c
        sv[k] = s_val[q]
        bv[k] = b_val[q]
        pos[r] = k + 1
        if c != r:
            k = pos[c]
            other[k] = r
            sv[k] = s_val[q]
            bv[k] = b_val[q]
            pos[c] = k + 1


@numba.njit(cache=True, nogil=True)
def _combine_rows(ptr, other, sv, bv, distinct, r0, r1):
    """Rows r0..r1 in place: duplicates summed in order, the distinct columns sorted at the row's start;
    distinct[r] their count."""
    mark = np.full(ptr.size - 1, -1, np.int64)
    for i in range(r0, r1):
        start = ptr[i]
        k = start
        for t in range(ptr[i], ptr[i + 1]):
            c = other[t]
            if mark[c] < start:          # marks of earlier rows lie before this row's start
                mark[c] = k
                other[k] = c
                sv[k] = sv[t]
                bv[k] = bv[t]
                k += 1
            else:
                sv[mark[c]] += sv[t]
                bv[mark[c]] += bv[t]
        for t in range(start + 1, k):             # insertion sort of the row's distinct columns
            x, xs, xb = other[t], sv[t], bv[t]
            u = t - 1
            while u >= start and other[u] > x:
                other[u + 1], sv[u + 1], bv[u + 1] = other[u], sv[u], bv[u]
                u -= 1
            other[u + 1], sv[u + 1], bv[u + 1] = x, xs, xb
        distinct[i] = k - start


@numba.njit(cache=True, nogil=True)
def _diagonal(ptr, other, sv, distinct, diag, r0, r1):
    for i in range(r0, r1):
        diag[i] = 0.0
        for t in range(ptr[i], ptr[i] + distinct[i]):
            if other[t] == i:
                diag[i] = sv[t]


@numba.njit(cache=True, nogil=True)
def _compact(ptr, other, sv, bv, distinct, newid, out_ptr, indices, sd, bd, r0, r1):
    """The active rows of r0..r1 (newid >= 0) with their active columns, renumbered, at out_ptr[newid[i]]."""
    for i in range(r0, r1):
        ni = newid[i]
        if ni < 0:
            continue
        k = out_ptr[ni]
        for t in range(ptr[i], ptr[i] + distinct[i]):
            nc = newid[other[t]]
            if nc >= 0:
                indices[k] = nc
                sd[k] = sv[t]
                bd[k] = bv[t]
                k += 1


@numba.njit(cache=True, nogil=True)
def _active_counts(ptr, other, distinct, newid, counts, r0, r1):
    for i in range(r0, r1):
        ni = newid[i]
        if ni < 0:
            continue
        n = 0
        for t in range(ptr[i], ptr[i] + distinct[i]):
            if newid[other[t]] >= 0:
                n += 1
        counts[ni] = n


@numba.njit(cache=True, nogil=True)
def _scale_by_cube(start, cols, s_val, D, scaled, c0, c1):
    """Cubes c0..c1: each stiffness triplet times its cube's D per channel (scaled[c]); a mass triplet's stiffness
    columns 0."""
    for q in range(c0, c1):
        for k in range(start[q], start[q + 1]):
            v = s_val[k]
            if cols[k] >= 0:
                for c in range(3):
                    scaled[c, k] = v * D[q, c]
            else:
                for c in range(3):
                    scaled[c, k] = 0.0


@numba.njit(cache=True, nogil=True)
def _mass_by_cube(start, rows, cols, s_val, sig_a, out):
    """out[row, c] = sum of each mass triplet's value times its cube's sigma_a per channel, in triplet order (the
    order of a bincount over the triplets: the same sums to the bit); one pass, no (3, triplets) array."""
    for q in range(start.shape[0] - 1):
        for k in range(start[q], start[q + 1]):
            if cols[k] == -1 and rows[k] >= 0:
                v = s_val[k]
                r = rows[k]
                for c in range(3):
                    out[r, c] += v * sig_a[q, c]


#: cubes per chunk of the assembly (the unit of its partial sums)
CHUNK = 4096


def _block_edges(k: int, n: int):
    return [round(i * k / n) for i in range(n + 1)]


def assemble(lattice, *, ghost: float = GHOST, media=None) -> Assembly:
    """The matrices of eq. (99) on ``lattice`` (:class:`meshshade.volume.lattice.Lattice`): each cube's entries
    as triplets into its own slots (chunks of cubes on the worker threads), then the symmetric CSR: rows counted
    and filled per block of triplets (within a row the triplets keep their order, so the sums do not depend on
    the number of threads), duplicates summed row by row, unknowns without inside dropped.

    ``media``: None (one medium: ``s_data`` (nnz,) and ``m`` (n,) shared by the channels), or (D (C, 3) mm,
    sigma_a (C, 3) 1/mm) per cube of the lattice, a medium varying over the volume (docs/physics.md eq. (107)):
    then ``s_data`` (nnz, 3) = sum over cubes of D_c S_cube and ``m`` (n, 3) = sum of sigma_a,c m_cube, per
    channel (the boundary's B shared: eta does not vary)."""
    cptr, cidx, cw, n_free = constraint_map(lattice.n_nodes, lattice.hanging, lattice.parents)
    cell_nodes, depth = lattice.cell_nodes, lattice.depth
    n_cells = cell_nodes.shape[0]
    n_chunks = -(-n_cells // CHUNK)
    start = np.zeros(n_cells + 1, dtype=np.int64)
    parallel_for(lambda a, b: _slots(cell_nodes, depth, cptr, cidx, _REF_PAIRS, _KUHN, start, a, b), n_cells,
                 min_block=CHUNK)
    np.cumsum(start, out=start)
    size = int(start[-1])
    rows = np.empty(size, np.int32)
    cols = np.empty(size, np.int32)
    s_val = np.empty(size)
    b_val = np.empty(size)
    totals = np.zeros((n_chunks, 2))
    args = (lattice.nodes, depth, cell_nodes, lattice.level, float(lattice.grading.h0), cptr, cidx, cw, _REF_PAIRS,
            _REF_VALUES, _REF_DIAG, _M_REF, float(ghost), start, rows, cols, s_val, b_val, totals)
    parallel_for(lambda a, b: _entries(*args, a * CHUNK, min(n_cells, b * CHUNK)), n_chunks, min_block=1)
    mass = (cols == -1) & (rows >= 0)
    m_free = np.bincount(rows[mass], weights=s_val[mass], minlength=n_free)
    passes = [(s_val, b_val)]
    m_media = None
    if media is not None:                      # a medium per cube: D_c S and sigma_a,c m per channel (eq. (107))
        D, sig_a = (np.ascontiguousarray(v, dtype=np.float64) for v in media)
        scaled = np.empty((3, size))
        parallel_for(lambda a, b: _scale_by_cube(start, cols, s_val, D, scaled, a, b), n_cells, min_block=CHUNK)
        m_media = np.zeros((n_free, 3))
        _mass_by_cube(start, rows, cols, s_val, sig_a, m_media)
        passes = [(scaled[0], b_val), (scaled[1], scaled[2])]
    # the symmetric CSR: rows counted per block of triplets, filled in triplet order
    n_blocks = max(1, min(default_threads(), size // 65536))
    edges = _block_edges(size, n_blocks)
    counts = np.zeros((n_blocks, n_free), dtype=np.int64)
    parallel_for(lambda a, b: [_row_counts(rows, cols, counts[t], edges[t], edges[t + 1]) for t in range(a, b)],
                 n_blocks, n_threads=n_blocks, min_block=1)
    per_row = counts.sum(axis=0)
    ptr = np.zeros(n_free + 1, dtype=np.int64)
    np.cumsum(per_row, out=ptr[1:])
    pos0 = np.cumsum(counts, axis=0) - counts + ptr[:-1][None, :]        # where each block's entries of a row go
    del counts
    rows_out = []
    for sv_in, bv_in in passes:                # the same pattern and order in every pass
        pos = pos0.copy() if len(passes) > 1 else pos0
        other = np.empty(int(ptr[-1]), dtype=np.int64)
        sv = np.empty(int(ptr[-1]))
        bv = np.empty(int(ptr[-1]))
        parallel_for(lambda a, b: [_scatter(rows, cols, sv_in, bv_in, pos[t], other, sv, bv, edges[t], edges[t + 1])
                                   for t in range(a, b)], n_blocks, n_threads=n_blocks, min_block=1)
        del pos
        distinct = np.zeros(n_free, dtype=np.int64)
        parallel_for(lambda a, b: _combine_rows(ptr, other, sv, bv, distinct, a, b), n_free, min_block=4096)
        rows_out.append((other, sv, bv, distinct))
    del rows, cols, s_val, b_val, pos0, passes
    other, sv, bv, distinct = rows_out[0]
    # unknowns: free nodes with something inside their support
    diag = np.empty(n_free)
    parallel_for(lambda a, b: _diagonal(ptr, other, sv, distinct, diag, a, b), n_free, min_block=4096)
    active = (diag > 0.0) | (m_free > 0.0)
    if not active.any():
        raise MeshshadeError("the volume's lattice holds no inside")
    n = int(active.sum())
    newid = np.full(n_free, -1, dtype=np.int64)
    newid[active] = np.arange(n)
    row_n = np.zeros(n, dtype=np.int64)
    parallel_for(lambda a, b: _active_counts(ptr, other, distinct, newid, row_n, a, b), n_free, min_block=4096)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(row_n, out=indptr[1:])
    data = []
    for other, sv, bv, distinct in rows_out:
        indices = np.empty(int(indptr[-1]), dtype=np.int64)
        sd = np.empty(int(indptr[-1]))
        bd = np.empty(int(indptr[-1]))
        parallel_for(lambda a, b: _compact(ptr, other, sv, bv, distinct, newid, indptr, indices, sd, bd, a, b),
                     n_free, min_block=4096)
        data.append((sd, bd))
    if m_media is None:
        sd, bd = data[0]
        m_out = m_free[active]
    else:
        sd = np.stack([data[0][0], data[1][0], data[1][1]], axis=1)
        bd = data[0][1]
        m_out = np.ascontiguousarray(m_media[active])
    # the constraint map in unknown numbering (free nodes that are not active drop out)
    cidx2 = newid[cidx]
    ok = cidx2 >= 0
    row_of = np.repeat(np.arange(lattice.n_nodes), np.diff(cptr))
    cptr2 = np.concatenate([[0], np.cumsum(np.bincount(row_of[ok], minlength=lattice.n_nodes))])
    is_hanging = np.zeros(lattice.n_nodes, dtype=bool)
    is_hanging[lattice.hanging] = True
    free_nodes = np.flatnonzero(~is_hanging)[active]
    vol, area = totals.sum(axis=0)
    return Assembly(indptr, indices, sd, bd, m_out, free_nodes,
                    (cptr2.astype(np.int64), cidx2[ok], cw[ok]), float(vol), float(area))
