"""Convexity certificate of a closed triangle mesh in O(faces), without a convex hull (pure array function)."""
from __future__ import annotations

import numpy as np

from meshshade.geometry.mesh import face_normals
from meshshade.geometry.sorting import counting_order, pair_table
from meshshade.geometry.topology import vertex_components

__all__ = ["is_convex"]


def is_convex(vertices, faces) -> bool:
    """Whether a triangle mesh bounds a convex body, certified in O(faces) without a convex hull.

    Checks: (1) closed and consistently oriented (every directed edge once, its reverse once); (2) connected;
    (3) Euler characteristic V - E + F = 2 (a sphere); (4) every edge locally convex (the neighbour's opposite
    vertex at most 1e-9 x bbox diagonal in front of the face's plane); (5) every vertex's face-angle sum at most
    2 pi (+1e-9; flat is allowed); (6) positive signed volume (outward faces). (4) and (5) make the surface locally
    convex everywhere unless a vertex star wraps around its vertex more than once, which only a self-intersecting
    mesh can do; a closed, connected, locally convex surface bounds a convex body (Tietze-Nakajima theorem;
    van Heijenoort 1952 for immersed surfaces). A self-intersecting mesh is outside meshshade's domain anyway.

    Parameters
    ----------
    vertices : (n, 3) array_like of float, mm (any unit: the tolerances are relative to the bbox diagonal)
    faces : (m, 3) array_like of int, the winding to test (outward = counter-clockwise seen from outside)

    Returns
    -------
    bool
        True only if all six checks pass (coplanar neighbouring faces count as convex); False for an open,
        inward-wound, disconnected, non-spherical or locally concave mesh, or one with a zero-area face.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    m, n = F.shape[0], np.int64(V.shape[0])
    if m < 4 or (3 * m) % 2:
        return False
    if F.min() < 0 or F.max() >= n:
        return False
    # a quick necessary test first: a convex body lies behind every face's plane; the planes of a few faces
    # (fixed choice) already show most meshes are not convex, without the O(faces) work below
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    for f in np.linspace(0, m - 1, min(m, 16)).astype(np.int64):
        nrm = np.cross(V[F[f, 1]] - V[F[f, 0]], V[F[f, 2]] - V[F[f, 0]])
        ln = float(np.linalg.norm(nrm))
        if ln > 0.0 and float(np.max((V - V[F[f, 0]]) @ (nrm / ln))) > 1e-9 * scale:
            return False
    a = F.reshape(-1)
    b = np.roll(F, -1, axis=1).reshape(-1)
    # (1) each undirected edge used exactly twice, once each way
    _, edge, count = pair_table(np.minimum(a, b), np.maximum(a, b), int(n))
    if np.any(count != 2):
        return False
    order = counting_order(edge, count.size)
    first, second = order[0::2], order[1::2]
    if not (np.all(a[first] == b[second]) and np.all(b[first] == a[second])):
        return False
    twin = np.empty_like(order)
    twin[first], twin[second] = second, first                                  # index of the reverse edge
    # (4) first: the cheapest test that a non-convex mesh fails
    tri = V[F]
    cross = face_normals(V, F, unit=False)
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    if np.any(length == 0.0):
        return False
    unit = cross / length
    opposite = F[twin // 3, (twin % 3 + 2) % 3]
    height = np.einsum("ij,ij->i", np.repeat(unit, 3, axis=0), V[opposite] - V[a])
    if np.any(height > 1e-9 * scale):                                          # (4)
        return False
    used_mask = np.bincount(a, minlength=V.shape[0]) > 0
    n_components, _ = vertex_components(V.shape[0], F)
    if n_components != 1:                                                      # (2)
        return False
    if int(used_mask.sum()) - (3 * m) // 2 + m != 2:                           # (3)
        return False
    angle_sum = np.zeros(V.shape[0])
    for k in range(3):
        e1 = tri[:, (k + 1) % 3] - tri[:, k]
        e2 = tri[:, (k + 2) % 3] - tri[:, k]
        ang = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1), np.einsum("ij,ij->i", e1, e2))
        angle_sum += np.bincount(F[:, k], weights=ang, minlength=V.shape[0])
    if np.any(angle_sum[used_mask] > 2.0 * np.pi + 1e-9):                      # (5)
        return False
    return float(np.einsum("ij,ij->i", tri[:, 0], cross).sum()) > 0.0          # (6)
