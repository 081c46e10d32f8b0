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

Compiled loops (numba): one pass over the cubes writes every entry (row, column, value) into arrays; one sort per
row sums the duplicates into CSR. No Python loop over cells or nodes.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from meshshade.errors import MeshshadeError

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
        return int(self.m.size)

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


@numba.njit(cache=True)
def _sub(B, i0, i1, i2, i3, vol_full, m):
    """Add int of each barycentric over the sub-tetrahedron with barycentric corners rows i0..i3 of B to m;
    return its volume."""
    v = abs(_det3(B[i1, 1] - B[i0, 1], B[i1, 2] - B[i0, 2], B[i1, 3] - B[i0, 3],
                  B[i2, 1] - B[i0, 1], B[i2, 2] - B[i0, 2], B[i2, 3] - B[i0, 3],
                  B[i3, 1] - B[i0, 1], B[i3, 2] - B[i0, 2], B[i3, 3] - B[i0, 3])) * vol_full
    for k in range(4):
        m[k] += v * 0.25 * (B[i0, k] + B[i1, k] + B[i2, k] + B[i3, k])
    return v


@numba.njit(cache=True)
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
def _put(i, j, sv, bv, cptr, cidx, cw, rows, cols, s_val, b_val, s_diag, b_diag, q):
    """Add (sv, bv) at lattice nodes (i, j), i != j, to the free nodes' entries (upper triangle, diagonal apart)."""
    for qi in range(cptr[i], cptr[i + 1]):
        for qj in range(cptr[j], cptr[j + 1]):
            a, b = cidx[qi], cidx[qj]
            w = cw[qi] * cw[qj]
            if a == b:
                s_diag[a] += 2.0 * sv * w
                b_diag[a] += 2.0 * bv * w
            else:
                rows[q] = min(a, b)
                cols[q] = max(a, b)
                s_val[q] = sv * w
                b_val[q] = bv * w
                q += 1
    return q


@numba.njit(cache=True)
def _entries(nodes, depth, cell_nodes, level, h0, cptr, cidx, cw, ref_pairs, ref_values, ref_diag, m_ref, ghost,
             rows, cols, s_val, b_val, s_diag, b_diag, m_free, totals):
    """Every cell's entries in free-node numbering (hanging nodes expanded): the strict upper triangle as
    (row < col) triplets, the diagonals and the lumped mass into dense arrays; returns the triplets written."""
    kuhn = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
    q = 0
    P = np.zeros((4, 3))
    s = np.zeros(4)
    G = np.zeros((4, 3))
    E = np.zeros((3, 3))
    be = np.zeros((4, 4))
    mloc = np.zeros(4)
    bm = np.zeros(4)
    gid = np.zeros(4, np.int64)
    for c in range(cell_nodes.shape[0]):
        h = h0 * (2.0 ** level[c])
        cut = False
        for k in range(8):
            if depth[cell_nodes[c, k]] <= 0.0:
                cut = True
                break
        if not cut:
            totals[0] += h * h * h
            for r in range(ref_pairs.shape[0]):
                q = _put(cell_nodes[c, ref_pairs[r, 0]], cell_nodes[c, ref_pairs[r, 1]], h * ref_values[r], 0.0,
                         cptr, cidx, cw, rows, cols, s_val, b_val, s_diag, b_diag, q)
            for k in range(8):
                i = cell_nodes[c, k]
                for qi in range(cptr[i], cptr[i + 1]):
                    for qj in range(cptr[i], cptr[i + 1]):
                        a, b = cidx[qi], cidx[qj]
                        v = h * ref_diag[k] * cw[qi] * cw[qj]
                        if a == b:
                            s_diag[a] += v
                        elif a < b:
                            rows[q] = a
                            cols[q] = b
                            s_val[q] = v
                            b_val[q] = 0.0
                            q += 1
                    m_free[cidx[qi]] += h * h * h * m_ref[k] * cw[qi]
            continue
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
            totals[0] += vin
            totals[1] += area
            if vin <= 0.0 and area <= 0.0:
                continue
            for r in range(3):
                for d in range(3):
                    E[r, d] = P[r + 1, d] - P[0, d]
            inv = np.linalg.inv(E)
            for r in range(3):
                for d in range(3):
                    G[r + 1, d] = inv[d, r]
            for d in range(3):
                G[0, d] = -(G[1, d] + G[2, d] + G[3, d])
            w = vin + ghost * (vfull - vin)
            for a in range(4):
                i = gid[a]
                ma = mloc[a] + ghost * (0.25 * vfull - mloc[a])
                sa = w * (G[a, 0] * G[a, 0] + G[a, 1] * G[a, 1] + G[a, 2] * G[a, 2])
                for qi in range(cptr[i], cptr[i + 1]):
                    m_free[cidx[qi]] += ma * cw[qi]
                    for qj in range(cptr[i], cptr[i + 1]):
                        x, y = cidx[qi], cidx[qj]
                        ww = cw[qi] * cw[qj]
                        if x == y:
                            s_diag[x] += sa * ww
                            b_diag[x] += be[a, a] * ww
                        elif x < y:
                            rows[q] = x
                            cols[q] = y
                            s_val[q] = sa * ww
                            b_val[q] = be[a, a] * ww
                            q += 1
                for b in range(a + 1, 4):
                    sab = w * (G[a, 0] * G[b, 0] + G[a, 1] * G[b, 1] + G[a, 2] * G[b, 2])
                    q = _put(i, gid[b], sab, be[a, b], cptr, cidx, cw, rows, cols, s_val, b_val, s_diag, b_diag, q)
    return q


@numba.njit(cache=True)
def _count(cell_nodes, depth, cptr, n_ref_pairs):
    """Upper bound of the entries :func:`_entries` writes."""
    total = 0
    for c in range(cell_nodes.shape[0]):
        mult = 1
        for k in range(8):
            i = cell_nodes[c, k]
            mult = max(mult, cptr[i + 1] - cptr[i])
        cut = False
        for k in range(8):
            if depth[cell_nodes[c, k]] <= 0.0:
                cut = True
        total += (6 * 16 if cut else n_ref_pairs + 8) * mult * mult
    return total


@numba.njit(cache=True)
def _to_csr(n, rows, cols, s_val, b_val, s_diag, b_diag):
    """The symmetric CSR (columns sorted, diagonal included) of the strict upper triangle triplets (duplicates
    summed) and the dense diagonals."""
    count = np.zeros(n + 1, np.int64)
    for q in range(rows.size):
        count[rows[q] + 1] += 1
        count[cols[q] + 1] += 1
    for i in range(n):
        count[i + 1] += count[i] + 1          # + the diagonal
    fill = np.empty(n, np.int64)
    for i in range(n):
        fill[i] = count[i] + 1
    other = np.empty(count[n], np.int64)
    sv = np.empty(count[n])
    bv = np.empty(count[n])
    for i in range(n):
        other[count[i]] = i
        sv[count[i]] = s_diag[i]
        bv[count[i]] = b_diag[i]
    for q in range(rows.size):
        for a, b in ((rows[q], cols[q]), (cols[q], rows[q])):
            k = fill[a]
            other[k] = b
            sv[k] = s_val[q]
            bv[k] = b_val[q]
            fill[a] = k + 1
    indptr = np.zeros(n + 1, np.int64)
    indices = np.empty(count[n], np.int64)
    sd = np.empty(count[n])
    bd = np.empty(count[n])
    mark = np.full(n, -1, np.int64)           # the row that last met column c, and where it put it
    slot = np.empty(n, np.int64)
    k = 0
    for i in range(n):
        start = k
        for t in range(count[i], count[i + 1]):   # duplicates summed as they come (a row has ~27 columns)
            c = other[t]
            if mark[c] != i:
                mark[c] = i
                slot[c] = k
                indices[k] = c
                sd[k] = sv[t]
                bd[k] = bv[t]
                k += 1
            else:
                sd[slot[c]] += sv[t]
                bd[slot[c]] += bv[t]
        for t in range(start + 1, k):             # insertion sort of the row's distinct columns
            x, xs, xb = indices[t], sd[t], bd[t]
            u = t - 1
            while u >= start and indices[u] > x:
                indices[u + 1], sd[u + 1], bd[u + 1] = indices[u], sd[u], bd[u]
                u -= 1
            indices[u + 1], sd[u + 1], bd[u + 1] = x, xs, xb
        indptr[i + 1] = k
    return indptr, indices[:k], sd[:k], bd[:k]


def assemble(lattice, *, ghost: float = GHOST) -> Assembly:
    """The matrices of eq. (99) on ``lattice`` (:class:`meshshade.volume.lattice.Lattice`)."""
    cptr, cidx, cw, n_free = constraint_map(lattice.n_nodes, lattice.hanging, lattice.parents)
    size = int(_count(lattice.cell_nodes, lattice.depth, cptr, _REF_PAIRS.shape[0]))
    rows = np.empty(size, np.int32)
    cols = np.empty(size, np.int32)
    s_val = np.empty(size)
    b_val = np.empty(size)
    s_diag, b_diag, m_free = np.zeros(n_free), np.zeros(n_free), np.zeros(n_free)
    totals = np.zeros(2)
    q = _entries(lattice.nodes, lattice.depth, lattice.cell_nodes, lattice.level, float(lattice.grading.h0),
                 cptr, cidx, cw, _REF_PAIRS, _REF_VALUES, _REF_DIAG, _M_REF, float(ghost), rows, cols, s_val, b_val,
                 s_diag, b_diag, m_free, totals)
    indptr, indices, sd, bd = _to_csr(n_free, rows[:q], cols[:q], s_val[:q], b_val[:q], s_diag, b_diag)
    del rows, cols, s_val, b_val
    # unknowns: free nodes with something inside their support
    diag = np.zeros(n_free)
    r = np.repeat(np.arange(n_free), np.diff(indptr))
    on = indices == r
    diag[r[on]] = sd[on]
    active = (diag > 0.0) | (m_free > 0.0)
    if not active.any():
        raise MeshshadeError("the volume's lattice holds no inside")
    newid = np.full(n_free, -1, dtype=np.int64)
    newid[active] = np.arange(int(active.sum()))
    keep = active[r] & active[indices]
    counts = np.bincount(newid[r[keep]], minlength=int(active.sum()))
    indptr2 = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    # the constraint map in unknown numbering (free nodes that are not active drop out)
    cidx2 = newid[cidx]
    ok = cidx2 >= 0
    row_of = np.repeat(np.arange(lattice.n_nodes), np.diff(cptr))
    cptr2 = np.concatenate([[0], np.cumsum(np.bincount(row_of[ok], minlength=lattice.n_nodes))])
    free_nodes = np.flatnonzero(np.isin(np.arange(lattice.n_nodes), lattice.hanging, invert=True))[active]
    return Assembly(indptr2, newid[indices[keep]], sd[keep], bd[keep], m_free[active], free_nodes,
                    (cptr2.astype(np.int64), cidx2[ok], cw[ok]), float(totals[0]), float(totals[1]))
