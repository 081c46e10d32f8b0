"""P1 finite elements for diffusion in a volume with the extrapolated boundary (docs/physics.md §15, eqs. (89)-(92)).

Pure array functions on a tetrahedral mesh: ``nodes`` (N, 3) float64 mm, ``tets`` (T, 4) int64 (any orientation).
The weak form (eq. (90)): for every P1 test function v,

    integral_Omega D grad(phi) . grad(v) + sigma_a phi v dV + integral_dOmega phi v / (2 A) dS = integral Q v dV,

so the matrix is K = D S + sigma_a M + B / (2A) with S the stiffness, M the volume mass and B the boundary mass
matrix: symmetric positive definite (sigma_a > 0 or a boundary), depending on mesh and material only. A point
source of power P at x (eq. (91)) contributes P lambda_i(x) to the nodes i of the tetrahedron holding x (its
barycentric coordinates lambda). The exitance on the boundary is M = phi / (2A) (eq. (92)).

No Python loop over elements or nodes: the assembly's row loops are compiled (numba), serial over a range of
rows and run on blocks of the rows by the pacing threads (:func:`meshshade.pacing.run_in_blocks`; each row is
computed on its own), the rest vectorised numpy; :func:`tet_geometry` is the vectorised form of the same element
geometry (tests compare the two).
"""
from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError
from meshshade.pacing import run_in_blocks
from meshshade.volume.locate import FACE_NODES, tet_neighbours, walk_locate

__all__ = ["tet_geometry", "boundary_faces", "assemble_diffusion", "assemble_channels", "locate_points",
           "point_source_vector",
           "exitance_from_fluence"]

#: tetrahedra tried per point by :func:`locate_points` (nearest centroids)
LOCATE_CANDIDATES = 24


def tet_geometry(nodes, tets):
    """(volumes (T,) mm^3, gradients (T, 4, 3) 1/mm) of the P1 basis functions of every tetrahedron.

    Raises MeshshadeError for a degenerate (zero-volume) tetrahedron.
    """
    P = nodes[tets]                                   # (T, 4, 3)
    E = P[:, 1:] - P[:, :1]                           # (T, 3, 3) edges from node 0, as rows
    det = np.linalg.det(E)
    vol = np.abs(det) / 6.0
    if np.any(vol <= 1e-300):
        raise MeshshadeError(f"{int(np.sum(vol <= 1e-300))} degenerate tetrahedra (zero volume)")
    inv = np.linalg.inv(E)                            # columns: gradients of lambda_1..3 (E @ inv = I)
    g123 = np.transpose(inv, (0, 2, 1))               # (T, 3, 3): row k = grad lambda_{k+1}
    g0 = -g123.sum(axis=1, keepdims=True)
    return vol, np.concatenate([g0, g123], axis=1)


def boundary_faces(tets, nodes=None, neighbours=None):
    """(F, 3) int64 faces that belong to one tetrahedron only; with ``nodes``, oriented outward. ``neighbours``:
    :func:`~meshshade.volume.locate.tet_neighbours` of ``tets``, if already computed."""
    nb = tet_neighbours(tets) if neighbours is None else neighbours
    once = nb.reshape(-1) < 0                        # face f of tetrahedron t (row 4t + f) lies opposite node f
    out = tets[:, FACE_NODES].reshape(-1, 3)[once]  # outward for a positively oriented tetrahedron
    if nodes is not None:   # orient against the opposite node of the owning tetrahedron
        opp = nodes[tets.reshape(-1)[once]]
        a, b, c = nodes[out[:, 0]], nodes[out[:, 1]], nodes[out[:, 2]]
        n = np.cross(b - a, c - a)
        flip = np.einsum("ij,ij->i", n, opp - a) > 0.0
        out[flip] = out[flip][:, [0, 2, 1]]
    return out


def assemble_diffusion(nodes, tets, faces, *, D, sigma_a, A, lumped=False):
    """K = D S + sigma_a M + B/(2A) (eq. (90)) as a CSR matrix (N, N), float64.

    nodes : (N, 3) mm; tets : (T, 4); faces : (F, 3) boundary faces (:func:`boundary_faces`); D : diffusion
    constant in mm; sigma_a : 1/mm; A : boundary mismatch (docs/physics.md §2) of the material;
    ``lumped``: the mass matrices M and B diagonal
    (each element's mass shared equally by its nodes): the same second order at the nodes, and no negative
    fluence from the mass terms' coupling where the solution falls steeply (a sun's terminator in the blue).
    A node of no tetrahedron gets 1 on the diagonal (fluence 0, the matrix stays definite).
    """
    indptr, indices, data = assemble_channels(nodes, tets, faces, D=[D], sigma_a=[sigma_a], A=[A],
                                              lumped=lumped)
    N = nodes.shape[0]
    return sp.csr_matrix((data[:, 0], indices, indptr), shape=(N, N))


def assemble_channels(nodes, tets, faces, *, D, sigma_a, A, lumped=False):
    """Eq. (90)'s matrices of k channels (``D``, ``sigma_a``, ``A`` sequences of k) on one CSR structure:
    (indptr (N+1,), indices (nnz,), data (nnz, k)), rows sorted (see :func:`assemble_diffusion`).

    The pattern comes from the tetrahedra's edges (every node keeps its diagonal); the element matrices are
    formed and added in place by compiled loops (:func:`_add_elements` over blocks of rows on the pacing threads,
    then :func:`_add_faces`), so memory stays at the matrix's own size. A degenerate tetrahedron raises
    MeshshadeError naming the first one met in row order, whatever the blocks: of those with the lowest
    smallest node, the lowest index.
    """
    D, sigma_a, A = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (D, sigma_a, A))
    if not (np.all(D > 0.0) and np.all(sigma_a >= 0.0) and np.all(A >= 1.0)):
        raise MeshshadeError(f"diffusion needs D > 0, sigma_a >= 0 and A >= 1, got D={D}, sigma_a={sigma_a}, A={A}")
    N = nodes.shape[0]
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    indptr, indices, tet_ptr, tet_of = _pattern(tets, N)
    parts = np.zeros((3, indices.size))              # stiffness, volume mass, boundary mass
    nodes = np.ascontiguousarray(nodes, dtype=np.float64)
    lumped = bool(lumped)

    def rows(a, b):
        """Rows a:b (each node adds its own tetrahedra into its own row); run on blocks by the pacing threads."""
        return _add_elements(nodes, tets, tet_ptr, tet_of, indptr, indices, lumped, parts, a, b)

    bad = [int(t) for t in run_in_blocks(rows, N) if t >= 0]
    if bad:   # the first block's: the first met in row order, whatever the blocks
        raise MeshshadeError(f"degenerate tetrahedron {bad[0]} (zero volume)")
    _add_faces(nodes, faces, indptr, indices, lumped, parts)
    data = parts[0][:, None] * D[None, :] + parts[1][:, None] * sigma_a[None, :] + parts[2][:, None] / (2.0 * A)
    isolated = np.ones(N, dtype=bool)            # a node of no element gets 1 on its diagonal
    isolated[tets.reshape(-1)] = False
    diag = _diagonal_positions(indptr, indices)
    data[diag[isolated]] = 1.0
    return indptr, indices, data


def _pattern(tets, N):
    """(indptr, indices) int64 of the symmetric pattern: each node's diagonal and the tetrahedra's edges, rows
    sorted; with the node-to-tetrahedra incidence (tet_ptr, tet_of) it was built from."""
    tet_ptr, tet_of = _incidence(tets, N)
    counts = np.zeros(N, dtype=np.int64)
    none = np.zeros(1, dtype=np.int64)
    # each row on its own: blocks of rows on the pacing threads, a count pass then a fill pass
    run_in_blocks(lambda a, b: _row_neighbours(tets, tet_ptr, tet_of, none, counts, True, a, b), N)
    indptr = np.zeros(N + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(indptr[-1], dtype=np.int64)
    run_in_blocks(lambda a, b: _row_neighbours(tets, tet_ptr, tet_of, indptr, indices, False, a, b), N)
    return indptr, indices, tet_ptr, tet_of


@numba.njit(cache=True)
def _incidence(tets, N):
    """(tet_ptr (N+1,), tet_of): the tetrahedra of node i are tet_of[tet_ptr[i]:tet_ptr[i+1]] (a counting sort)."""
    ptr = np.zeros(N + 1, dtype=np.int64)
    for t in range(tets.shape[0]):
        for k in range(4):
            ptr[tets[t, k] + 1] += 1
    for i in range(N):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    out = np.empty(ptr[-1], dtype=np.int64)
    for t in range(tets.shape[0]):
        for k in range(4):
            out[fill[tets[t, k]]] = t
            fill[tets[t, k]] += 1
    return ptr, out


@numba.njit(cache=True, nogil=True)
def _row_neighbours(tets, tet_ptr, tet_of, indptr, out, count_only, lo, hi):
    """Nodes ``lo:hi``: each one's distinct neighbours through its tetrahedra, itself included: their count in
    ``out`` (N,) (``count_only``), or the sorted columns in ``out[indptr[i]:indptr[i+1]]``; serial, without the
    GIL. A row is kept sorted as it is collected (insertion: rows are short) and copied element by element:
    ``np.sort`` and slice assignments would cost seconds to compile."""
    row = np.empty(256, dtype=np.int64)
    for i in range(lo, hi):
        m = 1
        row[0] = i                  # the diagonal, even for a node of no tetrahedron
        for q in range(tet_ptr[i], tet_ptr[i + 1]):
            t = tet_of[q]
            for k in range(4):
                j = tets[t, k]
                r = m                   # row[:m] is sorted: j goes to row[r], after those below it
                while r > 0 and row[r - 1] > j:
                    r -= 1
                if r > 0 and row[r - 1] == j:
                    continue
                if m == row.size:
                    grown = np.empty(2 * row.size, dtype=np.int64)
                    for u in range(m):
                        grown[u] = row[u]
                    row = grown
                for u in range(m, r, -1):
                    row[u] = row[u - 1]
                row[r] = j
                m += 1
        if count_only:
            out[i] = m
        else:
            for u in range(m):
                out[indptr[i] + u] = row[u]


@numba.njit(cache=True)
def _position(indptr, indices, row, col):
    lo, hi = indptr[row], indptr[row + 1]
    while lo < hi:
        mid = (lo + hi) >> 1
        if indices[mid] < col:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _diagonal_positions(indptr, indices):
    n = indptr.size - 1
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        out[i] = _position(indptr, indices, i, i)
    return out


@numba.njit(cache=True, nogil=True)
def _add_elements(nodes, tets, tet_ptr, tet_of, indptr, indices, lumped, parts, lo, hi):
    """Rows ``lo:hi``: add each node's tetrahedra's stiffness vol grad_i . grad_j and mass vol (1 + delta_ij) / 20
    (lumped: vol / 4 on the diagonal) into the node's own row of ``parts[0]`` and ``parts[1]`` (nnz,) at the
    pattern's positions (no two rows share an entry); serial, without the GIL. Returns -1, or the first
    tetrahedron of zero volume met (rows in order, each row's tetrahedra in ``tet_of`` order), which is skipped."""
    g = np.empty((4, 3))
    E = np.empty((3, 3))
    bad = -1
    for node in range(lo, hi):
        for q in range(tet_ptr[node], tet_ptr[node + 1]):
            t = tet_of[q]
            a = tets[t, 0]
            for r in range(3):
                for d in range(3):
                    E[r, d] = nodes[tets[t, r + 1], d] - nodes[a, d]
            e00, e01, e02, e10, e11, e12 = E[0, 0], E[0, 1], E[0, 2], E[1, 0], E[1, 1], E[1, 2]
            e20, e21, e22 = E[2, 0], E[2, 1], E[2, 2]
            # rows of E are the edges; grad lambda_{k+1} is column k of E^-1: row k of the cofactors / det
            c00, c01, c02 = e11 * e22 - e12 * e21, e12 * e20 - e10 * e22, e10 * e21 - e11 * e20
            c10, c11, c12 = e02 * e21 - e01 * e22, e00 * e22 - e02 * e20, e01 * e20 - e00 * e21
            c20, c21, c22 = e01 * e12 - e02 * e11, e02 * e10 - e00 * e12, e00 * e11 - e01 * e10
            det = e00 * c00 + e01 * c01 + e02 * c02
            vol = abs(det) / 6.0
            if not vol > 1e-300:
                if bad < 0:
                    bad = t
                continue
            g[1, 0], g[1, 1], g[1, 2] = c00 / det, c01 / det, c02 / det
            g[2, 0], g[2, 1], g[2, 2] = c10 / det, c11 / det, c12 / det
            g[3, 0], g[3, 1], g[3, 2] = c20 / det, c21 / det, c22 / det
            for d in range(3):
                g[0, d] = -(g[1, d] + g[2, d] + g[3, d])
            i = 0
            while tets[t, i] != node:
                i += 1
            for j in range(4):
                p = _position(indptr, indices, node, tets[t, j])
                parts[0, p] += vol * (g[i, 0] * g[j, 0] + g[i, 1] * g[j, 1] + g[i, 2] * g[j, 2])
                if lumped:
                    if i == j:
                        parts[1, p] += 0.25 * vol
                else:
                    parts[1, p] += vol * (2.0 if i == j else 1.0) / 20.0
    return bad


@numba.njit(cache=True)
def _add_faces(nodes, faces, indptr, indices, lumped, parts):
    """Add every boundary face's mass area (1 + delta_ij) / 12 (lumped: area / 3) into ``parts[2]`` (nnz,) at the
    pattern's positions, faces in order (faces share entries: one serial loop)."""
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        u0, u1, u2 = nodes[b, 0] - nodes[a, 0], nodes[b, 1] - nodes[a, 1], nodes[b, 2] - nodes[a, 2]
        v0, v1, v2 = nodes[c, 0] - nodes[a, 0], nodes[c, 1] - nodes[a, 1], nodes[c, 2] - nodes[a, 2]
        n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        area = 0.5 * np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        for i in range(3):
            for j in range(3):
                if lumped:
                    if i == j:
                        parts[2, _position(indptr, indices, faces[f, i], faces[f, i])] += area / 3.0
                else:
                    parts[2, _position(indptr, indices, faces[f, i], faces[f, j])] += \
                        area * (2.0 if i == j else 1.0) / 12.0


def locate_points(nodes, tets, points, *, tree=None, neighbours=None, walk=True):
    """(tet (k,) int64, barycentric (k, 4) float64) of the tetrahedron holding each point.

    ``walk`` (default): the compiled neighbour walk of :mod:`meshshade.volume.locate` from the tetrahedron with
    the nearest centroid (a ``cKDTree`` of the centroids, and the face neighbours, built here or passed as
    ``tree`` and ``neighbours``); a point outside the mesh is clamped into the boundary tetrahedron through which
    the walk left (its barycentrics clipped). Points the walk cannot settle, and every point with ``walk=False``
    (the walk's test oracle), go to the candidate search: the tetrahedra with the nearest centroids,
    :data:`LOCATE_CANDIDATES` first, four times as many for the points not yet found, and so on; a point inside
    none of them takes the candidate it is least outside of, clipped likewise. Callers that must not move
    outside points (sources of light that has left the body) drop them first.
    """
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    if tree is None:
        tree = cKDTree(nodes[tets].mean(axis=1))
    n = points.shape[0]
    tet = np.zeros(n, dtype=np.int64)
    bary = np.zeros((n, 4))
    if walk and n:
        nb = tet_neighbours(tets) if neighbours is None else neighbours
        start = tree.query(points, k=1)[1].astype(np.int64)
        status = walk_locate(np.ascontiguousarray(nodes, dtype=np.float64),
                             np.ascontiguousarray(tets, dtype=np.int64), nb, np.ascontiguousarray(points), start, tet,
                             bary)
        settled = status >= 0   # found, or outside: clamped into the boundary tetrahedron the walk left by
        bary[settled] = np.clip(bary[settled], 0.0, None)
        bary[settled] /= bary[settled].sum(axis=1, keepdims=True)
        todo = np.flatnonzero(~settled)
    else:
        todo = np.arange(n)
    k = LOCATE_CANDIDATES
    while todo.size:
        k = min(k, tets.shape[0])
        t, b, inside = _best_candidates(nodes, tets, points[todo], tree, k)
        last = k == tets.shape[0] or k >= LOCATE_CANDIDATES * 4 ** 3
        done = inside | last
        tet[todo[done]], bary[todo[done]] = t[done], b[done]
        todo = todo[~done]
        k *= 4
    return tet, bary


def _best_candidates(nodes, tets, points, tree, k):
    """Among the k tetrahedra with the nearest centroids: (best tet, clipped barycentrics, inside?) per point."""
    _, cand = tree.query(points, k=k)
    cand = cand.reshape(points.shape[0], k)
    P = nodes[tets[cand]]                             # (n, k, 4, 3)
    E = P[:, :, 1:] - P[:, :, :1]                     # (n, k, 3, 3)
    rel = points[:, None, :] - P[:, :, 0]             # (n, k, 3)
    lam = np.linalg.solve(np.transpose(E, (0, 1, 3, 2)), rel[..., None])[..., 0]   # (n, k, 3)
    bary = np.concatenate([1.0 - lam.sum(axis=-1, keepdims=True), lam], axis=-1)    # (n, k, 4)
    score = bary.min(axis=-1)
    best = np.argmax(score, axis=1)
    idx = np.arange(points.shape[0])
    inside = score[idx, best] >= -1e-12
    b = np.clip(bary[idx, best], 0.0, None)
    b /= b.sum(axis=1, keepdims=True)
    return cand[idx, best].astype(np.int64), b, inside


def point_source_vector(n_nodes, tets, tet, bary, power):
    """Load vector (n_nodes,) of point sources of ``power`` (k,) W in tetrahedra ``tet`` (k,) at ``bary`` (k, 4):
    node i of the holding tetrahedron gets power lambda_i (eq. (91))."""
    w = (np.asarray(power, dtype=np.float64)[:, None] * bary).reshape(-1)
    return np.bincount(tets[tet].reshape(-1), weights=w, minlength=n_nodes)


def exitance_from_fluence(phi, A):
    """Diffuse exitance M = phi / (2A) W/mm^2 on the boundary (eq. (92))."""
    return np.asarray(phi) / (2.0 * A)
