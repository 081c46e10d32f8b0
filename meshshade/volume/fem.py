"""P1 finite elements for diffusion in a volume with the extrapolated boundary (docs/physics.md §15, eqs. (89)-(92)).

Pure array functions on a tetrahedral mesh: ``nodes`` (N, 3) float64 mm, ``tets`` (T, 4) int64 (any orientation).
The weak form (eq. (90)): for every P1 test function v,

    integral_Omega D grad(phi) . grad(v) + sigma_a phi v dV + integral_dOmega phi v / (2 A) dS = integral Q v dV,

so the matrix is K = D S + sigma_a M + B / (2A) with S the stiffness, M the volume mass and B the boundary mass
matrix: symmetric positive definite (sigma_a > 0 or a boundary), depending on mesh and material only. A point
source of power P at x (eq. (91)) contributes P lambda_i(x) to the nodes i of the tetrahedron holding x (its
barycentric coordinates lambda). The exitance on the boundary is M = phi / (2A) (eq. (92)).

No Python loop over elements or nodes: every step is a vectorised numpy expression or a sparse-matrix build.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError
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


def boundary_faces(tets, nodes=None):
    """(F, 3) int64 faces that belong to one tetrahedron only; with ``nodes``, oriented outward."""
    faces = tets[:, FACE_NODES].reshape(-1, 3)        # outward for a positively oriented tetrahedron
    opposite = tets.reshape(-1)                      # face f of tetrahedron t (row 4t + f) lies opposite node f
    key = np.sort(faces, axis=1).astype(np.int64)
    n = int(key.max()) + 1 if key.size else 1
    if n ** 3 < 2 ** 62:    # one integer per face: a sort of int64 instead of np.unique(axis=0)'s rows
        code = (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
        _, inverse, counts = np.unique(code, return_inverse=True, return_counts=True)
    else:
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse.reshape(-1)] == 1
    out = faces[once]
    if nodes is not None:   # orient against the opposite node of the owning tetrahedron
        opp = nodes[opposite[once]]
        a, b, c = nodes[out[:, 0]], nodes[out[:, 1]], nodes[out[:, 2]]
        n = np.cross(b - a, c - a)
        flip = np.einsum("ij,ij->i", n, opp - a) > 0.0
        out[flip] = out[flip][:, [0, 2, 1]]
    return out


def _triangle_areas(nodes, faces):
    a, b, c = nodes[faces[:, 0]], nodes[faces[:, 1]], nodes[faces[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def assemble_diffusion(nodes, tets, faces, *, D, sigma_a, A, geometry=None, lumped=False):
    """K = D S + sigma_a M + B/(2A) (eq. (90)) as a CSR matrix (N, N), float64.

    nodes : (N, 3) mm; tets : (T, 4); faces : (F, 3) boundary faces (:func:`boundary_faces`); D : diffusion
    constant in mm; sigma_a : 1/mm; A : boundary mismatch (docs/physics.md §2) of the material;
    geometry : :func:`tet_geometry`'s result, if already computed. ``lumped``: the mass matrices M and B diagonal
    (each element's mass shared equally by its nodes): the same second order at the nodes, and no negative
    fluence from the mass terms' coupling where the solution falls steeply (a sun's terminator in the blue).
    """
    indptr, indices, data = assemble_channels(nodes, tets, faces, D=[D], sigma_a=[sigma_a], A=[A],
                                              geometry=geometry, lumped=lumped)
    N = nodes.shape[0]
    return sp.csr_matrix((data[:, 0], indices, indptr), shape=(N, N))


def assemble_channels(nodes, tets, faces, *, D, sigma_a, A, geometry=None, lumped=False):
    """Eq. (90)'s matrices of k channels (``D``, ``sigma_a``, ``A`` sequences of k) on one CSR structure:
    (indptr (N+1,), indices (nnz,), data (nnz, k)), rows sorted, duplicates summed (see
    :func:`assemble_diffusion`)."""
    D, sigma_a, A = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (D, sigma_a, A))
    if not (np.all(D > 0.0) and np.all(sigma_a >= 0.0) and np.all(A >= 1.0)):
        raise MeshshadeError(f"diffusion needs D > 0, sigma_a >= 0 and A >= 1, got D={D}, sigma_a={sigma_a}, A={A}")
    N = nodes.shape[0]
    vol, grad = geometry if geometry is not None else tet_geometry(nodes, tets)
    # element matrices (T, 4, 4): stiffness vol grad_i . grad_j, mass vol (1 + delta_ij) / 20 (lumped: vol/4)
    Se = (vol[:, None, None] * np.einsum("tik,tjk->tij", grad, grad)).reshape(-1)
    Me = (vol / 20.0)[:, None, None] * (5.0 * np.eye(4) if lumped else np.ones((4, 4)) + np.eye(4))
    area = _triangle_areas(nodes, faces)
    Be = (area / 12.0)[:, None, None] * (4.0 * np.eye(3) if lumped else np.ones((3, 3)) + np.eye(3))
    rows = np.concatenate([np.repeat(tets, 4, axis=1).reshape(-1), np.repeat(faces, 3, axis=1).reshape(-1)])
    cols = np.concatenate([np.tile(tets, (1, 4)).reshape(-1), np.tile(faces, (1, 3)).reshape(-1)])
    key = rows.astype(np.int64) * N + cols
    uniq, inv = np.unique(key, return_inverse=True)
    nt = Se.size
    s_sum = np.bincount(inv[:nt], weights=Se, minlength=uniq.size)
    m_sum = np.bincount(inv[:nt], weights=Me.reshape(-1), minlength=uniq.size)
    b_sum = np.bincount(inv[nt:], weights=Be.reshape(-1), minlength=uniq.size)
    data = s_sum[:, None] * D[None, :] + m_sum[:, None] * sigma_a[None, :] + b_sum[:, None] / (2.0 * A[None, :])
    indptr = np.concatenate([[0], np.cumsum(np.bincount(uniq // N, minlength=N))]).astype(np.int64)
    return indptr, (uniq % N).astype(np.int64), data


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
