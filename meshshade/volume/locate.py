"""Point location in a tetrahedral mesh: a compiled neighbour walk from the nearest centroid.

Each point starts in the tetrahedron whose centroid is nearest (a ``cKDTree``) and walks across the face opposite
its most negative barycentric coordinate until every coordinate is >= -``INSIDE_TOL`` (found) or the face is on
the boundary (the point is outside). Each point is walked on its own: a serial compiled loop over a range of
points, run on blocks of the points by the pacing threads (:func:`meshshade.pacing.run_in_blocks`). A point
the walk does not settle within ``MAX_STEPS`` (a cycle, possible on degenerate meshes) is handed to the
candidate search of :func:`meshshade.volume.fem.locate_points`, which also serves as this walk's test oracle.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from meshshade.pacing import run_in_blocks

__all__ = ["FACE_NODES", "tet_neighbours", "walk_locate", "INSIDE_TOL", "MAX_STEPS"]

#: a barycentric coordinate above -INSIDE_TOL counts as inside
INSIDE_TOL = 1e-12
#: most tetrahedra a walk visits
MAX_STEPS = 1000
#: the face opposite node f of a tetrahedron, outward for a positively oriented one (row f)
FACE_NODES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def face_keys(faces, n):
    """(F,) one sortable key per triangle ``faces`` (F, 3) of nodes below ``n``, the same for any order of its
    nodes: an int64 code where n^3 fits, else the sorted row as one opaque 24-byte value."""
    key = np.ascontiguousarray(np.sort(np.asarray(faces, dtype=np.int64), axis=1))
    if n ** 3 < 2 ** 62:
        return (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
    return key.view(np.dtype((np.void, 24))).ravel()


def tet_neighbours(tets):
    """(T, 4) int64: the tetrahedron across the face opposite each node (-1 on the boundary)."""
    T = tets.shape[0]
    faces = tets[:, FACE_NODES].reshape(-1, 3)
    code = face_keys(faces, int(faces.max()) + 1 if faces.size else 1)
    order = np.argsort(code, kind="stable")
    sc = code[order]
    same = sc[1:] == sc[:-1]
    a, b = order[:-1][same], order[1:][same]
    nb = np.full(4 * T, -1, dtype=np.int64)
    nb[a], nb[b] = b // 4, a // 4
    return nb.reshape(T, 4)


@njit(inline="always", cache=True)
def _bary(nodes, tets, t, px, py, pz):
    """Barycentric coordinates (l0, l1, l2, l3) of p in tetrahedron t (Cramer's rule)."""
    i0, i1, i2, i3 = tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3]
    ax, ay, az = nodes[i1, 0] - nodes[i0, 0], nodes[i1, 1] - nodes[i0, 1], nodes[i1, 2] - nodes[i0, 2]
    bx, by, bz = nodes[i2, 0] - nodes[i0, 0], nodes[i2, 1] - nodes[i0, 1], nodes[i2, 2] - nodes[i0, 2]
    cx, cy, cz = nodes[i3, 0] - nodes[i0, 0], nodes[i3, 1] - nodes[i0, 1], nodes[i3, 2] - nodes[i0, 2]
    rx, ry, rz = px - nodes[i0, 0], py - nodes[i0, 1], pz - nodes[i0, 2]
    det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
    l1 = (rx * (by * cz - bz * cy) - ry * (bx * cz - bz * cx) + rz * (bx * cy - by * cx)) / det
    l2 = (ax * (ry * cz - rz * cy) - ay * (rx * cz - rz * cx) + az * (rx * cy - ry * cx)) / det
    l3 = (ax * (by * rz - bz * ry) - ay * (bx * rz - bz * rx) + az * (bx * ry - by * rx)) / det
    return 1.0 - l1 - l2 - l3, l1, l2, l3


def walk_locate(nodes, tets, neighbours, points, start, tet_out, bary_out):
    """Walk every point from ``start`` (k,); writes ``tet_out`` (k,) and ``bary_out`` (k, 4) and returns a (k,)
    int8 status: 1 found, 0 outside the mesh (stopped at a boundary face), -1 not settled in MAX_STEPS.

    The points are walked in blocks on the pacing threads (:func:`meshshade.pacing.run_in_blocks`), each point on
    its own, so the result does not depend on the threads or the blocks."""
    status = np.zeros(points.shape[0], dtype=np.int8)
    run_in_blocks(lambda a, b: _walk(nodes, tets, neighbours, points, start, tet_out, bary_out, status, a, b),
                  points.shape[0])
    return status


@njit(nogil=True, cache=True)
def _walk(nodes, tets, neighbours, points, start, tet_out, bary_out, status, lo, hi):
    """:func:`walk_locate` of points ``lo:hi``, writing their rows of ``tet_out``, ``bary_out`` and ``status``;
    serial, without the GIL."""
    for i in range(lo, hi):
        t = start[i]
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        status[i] = -1
        for _ in range(MAX_STEPS):
            l0, l1, l2, l3 = _bary(nodes, tets, t, px, py, pz)
            m, lm = 0, l0
            if l1 < lm:
                m, lm = 1, l1
            if l2 < lm:
                m, lm = 2, l2
            if l3 < lm:
                m, lm = 3, l3
            tet_out[i] = t
            bary_out[i, 0], bary_out[i, 1], bary_out[i, 2], bary_out[i, 3] = l0, l1, l2, l3
            if lm >= -INSIDE_TOL:
                status[i] = 1
                break
            nt = neighbours[t, m]
            if nt < 0:
                status[i] = 0
                break
            t = nt
