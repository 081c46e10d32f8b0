"""Regular refinement of a triangle mesh on its own facets: each triangle split into n^2 similar triangles.

The refined surface is the same polyhedron (new vertices lie on the original edges and faces, nothing is moved
or smoothed); its vertex normals are the original vertex normals interpolated linearly and normalised, so light
enters and leaves it as smoothly as it does the original's shading normals. A texture bake solves the transport
on it when the mesh's edges are longer than the material resolves (:mod:`meshshade.output.texture`).

Numbering: the original vertices keep their indices (first), then n - 1 vertices per unique edge (from its lower
to its higher vertex index), then (n - 1)(n - 2)/2 per face. Face f's sub-triangles are rows f n^2 .. f n^2 + n^2 - 1
(:func:`refined_location` finds the one holding a point given by its barycentrics in the original face).

:func:`refine_faces` and :func:`refined_location` are pure arrays; :func:`refined_mesh` makes the
:class:`~meshshade.geometry.mesh.Mesh`. No I/O.
"""
from __future__ import annotations

import numpy as np

from meshshade.geometry.mesh import Mesh, _readonly

__all__ = ["refine_faces", "refined_location", "refined_mesh"]


def _lattice(n: int):
    """Per face, the lattice points (i, j), 0 <= i + j <= n (i along corner 0 -> 1, j along 0 -> 2) and the
    sub-triangles as triples of lattice indices: "up" (i, j), (i+1, j), (i, j+1) and "down" (i+1, j), (i+1, j+1),
    (i, j+1); ``local[i, j, k]`` is the sub-triangle number of up (k=0) / down (k=1) at (i, j), -1 if none."""
    pts = [(i, j) for i in range(n + 1) for j in range(n + 1 - i)]
    index = {p: k for k, p in enumerate(pts)}
    tris, local = [], -np.ones((n, n, 2), dtype=np.int64)
    for i in range(n):
        for j in range(n - i):
            local[i, j, 0] = len(tris)
            tris.append((index[i, j], index[i + 1, j], index[i, j + 1]))
            if i + j <= n - 2:
                local[i, j, 1] = len(tris)
                tris.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    return np.array(pts, dtype=np.int64), np.array(tris, dtype=np.int64), local


def refine_faces(vertices, faces, normals, n: int):
    """Split every face into n^2 (module docstring).

    vertices (V, 3), faces (F, 3) int, normals (V, 3) unit vertex normals (interpolated onto the new vertices),
    n >= 1 segments per edge. Returns (vertices (V', 3), faces (F n^2, 3), normals (V', 3)); n = 1 returns copies.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    N = np.asarray(normals, dtype=np.float64)
    n = int(n)
    if n < 1:
        raise ValueError(f"refinement must be at least 1 segment per edge, got {n}")
    if n == 1:
        return V.copy(), F.copy(), N.copy()
    nv, nf = V.shape[0], F.shape[0]
    pts, tris, _ = _lattice(n)
    i, j = pts[:, 0], pts[:, 1]
    # global id of each face's lattice point: corners, edge points, interior points
    ids = np.empty((nf, pts.shape[0]), dtype=np.int64)
    corner = {(0, 0): 0, (n, 0): 1, (0, n): 2}
    for k, (a, b) in enumerate(pts):
        if (a, b) in corner:
            ids[:, k] = F[:, corner[a, b]]
    e = np.concatenate([F[:, [0, 1]], F[:, [0, 2]], F[:, [1, 2]]])          # edges 0-1, 0-2, 1-2 of every face
    lo, hi = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
    keys, inverse = np.unique(lo * np.int64(nv) + hi, return_inverse=True)
    ne = keys.size
    edge_id = inverse.reshape(3, nf)                                          # (edge slot, face) -> unique edge
    flip = (e[:, 0] > e[:, 1]).reshape(3, nf)                                 # slot runs from its higher vertex
    for k, (a, b) in enumerate(pts):
        if (a, b) in corner:
            continue
        if b == 0 or a == 0 or a + b == n:
            slot, t = (0, a) if b == 0 else ((1, b) if a == 0 else (2, b))    # parameter along the slot's edge
            step = np.where(flip[slot], n - t, t)
            ids[:, k] = nv + edge_id[slot] * (n - 1) + (step - 1)
    inner = (i > 0) & (j > 0) & (i + j < n)
    n_in = int(inner.sum())
    if n_in:
        ids[:, inner] = nv + ne * (n - 1) + np.arange(nf)[:, None] * n_in + np.arange(n_in)[None, :]
    total = nv + ne * (n - 1) + nf * n_in
    bary = np.stack([n - i - j, i, j], axis=1) / n                            # (P, 3) of each lattice point
    Vn = np.empty((total, 3))
    Nn = np.empty((total, 3))
    Vn[ids] = np.einsum("pk,fkd->fpd", bary, V[F])
    Nn[ids] = np.einsum("pk,fkd->fpd", bary, N[F])
    norm = np.linalg.norm(Nn, axis=1)
    Nn = np.divide(Nn, norm[:, None], out=np.zeros_like(Nn), where=norm[:, None] > 0)
    Vn[:nv], Nn[:nv] = V, N                                                   # exact, and vertices of no face
    Fn = ids[:, tris].reshape(-1, 3)
    return Vn, Fn, Nn


def refined_location(face, bary, n: int):
    """(sub-face (k,), barycentrics (k, 3) in it) of points given by ``face`` (k,) and barycentrics ``bary``
    (k, 3) in the original faces, for :func:`refine_faces` with the same ``n``."""
    face = np.asarray(face, dtype=np.int64)
    bary = np.asarray(bary, dtype=np.float64)
    n = int(n)
    if n == 1:
        return face.copy(), bary.copy()
    _, _, local = _lattice(n)
    x, y = np.clip(bary[:, 1], 0.0, 1.0) * n, np.clip(bary[:, 2], 0.0, 1.0) * n
    i = np.clip(np.floor(x).astype(np.int64), 0, n - 1)
    j = np.clip(np.floor(y).astype(np.int64), 0, n - 1)
    over = i + j > n - 1                                  # on the far edge by rounding: step back into the face
    j = np.where(over, np.maximum(n - 1 - i, 0), j)
    fx, fy = x - i, y - j
    down = (fx + fy > 1.0) & (i + j <= n - 2)
    up_b = np.stack([1.0 - fx - fy, fx, fy], axis=1)
    down_b = np.stack([1.0 - fy, fx + fy - 1.0, 1.0 - fx], axis=1)
    b = np.where(down[:, None], down_b, up_b)
    b = np.clip(b, 0.0, None)
    b /= b.sum(axis=1, keepdims=True)
    return face * (n * n) + local[i, j, down.astype(np.int64)], b


def refined_mesh(mesh, n: int) -> Mesh:
    """``mesh`` split n x n on its own facets (:func:`refine_faces`), its vertex normals the original's interpolated
    (a shading surface as smooth as the original's, not the facets' normals); its first vertices are the mesh's,
    in order. n = 1 returns ``mesh`` itself."""
    if int(n) == 1:
        return mesh
    V, F, N = refine_faces(mesh.vertices, mesh.faces, mesh.vertex_normals, n)
    out = Mesh(V, F, mm_per_unit=mesh.mm_per_unit, source=mesh.source)
    out.__dict__["vertex_normals"] = _readonly(N)   # seeds the cached property (Mesh's docstring)
    return out
