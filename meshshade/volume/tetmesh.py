"""Tetrahedral meshes for the volume transport: of a closed surface mesh (:func:`surface_tetrahedra`, its vertices
kept as nodes), and by construction, graded boxes and balls for the checks against exact solutions.

A box is cut into hexahedral cells along given node coordinates per axis and every cell into six tetrahedra
around its main diagonal (Kuhn's subdivision: neighbouring cells share their face diagonals, so the mesh is
conforming). :func:`graded_box` spaces the nodes geometrically away from a point, fine where the fluence varies
fast (near sources and the lit surface) and coarse where it does not.
"""
from __future__ import annotations

from typing import NamedTuple

import igl
import numpy as np
from scipy.spatial import Delaunay

from meshshade.errors import MeshshadeError
from meshshade.volume.fem import boundary_faces

__all__ = ["SurfaceTetrahedra", "surface_tetrahedra", "box_tetrahedra", "ball_tetrahedra", "graded_axis",
           "graded_box"]

# Kuhn's six tetrahedra of the unit cube: vertex (i, j, k) has index i + 2 j + 4 k; each path 0 -> 7 along the
# axes in one order is a tetrahedron
_KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])


def _oriented(nodes, tets):
    """``tets`` with nodes 1 and 2 swapped where the tetrahedron is negatively oriented (in place; returned)."""
    P = nodes[tets]
    flip = np.linalg.det(P[:, 1:] - P[:, :1]) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return tets


def box_tetrahedra(xs, ys, zs):
    """(nodes (N, 3), tets (6 (nx-1)(ny-1)(nz-1), 4), positively oriented) of the box with node coordinates
    ``xs``, ``ys``, ``zs`` (each strictly increasing, mm)."""
    axes = [np.asarray(a, dtype=np.float64) for a in (xs, ys, zs)]
    if any(a.ndim != 1 or a.size < 2 or np.any(np.diff(a) <= 0) for a in axes):
        raise MeshshadeError("box node coordinates must be strictly increasing, at least two per axis")
    nx, ny, nz = (a.size for a in axes)
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    nodes = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    corner = [idx[i:nx - 1 + i, j:ny - 1 + j, k:nz - 1 + k].ravel() for k in (0, 1) for j in (0, 1) for i in (0, 1)]
    corners = np.stack(corner, axis=1)               # (cells, 8), local index i + 2 j + 4 k
    tets = corners[:, _KUHN].reshape(-1, 4)
    return nodes, _oriented(nodes, tets)


def graded_axis(lo, hi, focus, h_min, ratio, h_max=np.inf):
    """Node coordinates from ``lo`` to ``hi`` (mm): spacing ``h_min`` at ``focus``, growing by ``ratio`` per cell
    away from it, at most ``h_max``; the end cells are stretched to land on ``lo`` and ``hi``."""
    if not (lo < hi and h_min > 0 and ratio >= 1.0):
        raise MeshshadeError("graded_axis needs lo < hi, h_min > 0 and ratio >= 1")
    focus = min(max(focus, lo), hi)

    def side(length):
        out, x, h = [], 0.0, h_min
        while x + h < length - 0.5 * h:
            x += h
            out.append(x)
            h = min(h * ratio, h_max)
        return np.array(out + [length]) if length > 0 else np.zeros(0)

    right = focus + side(hi - focus)
    left = focus - side(focus - lo)
    return np.concatenate([left[::-1], [focus], right]) if focus < hi else np.concatenate([left[::-1], [focus]])


def graded_box(lo, hi, focus, h_min, ratio=1.15, h_max=np.inf):
    """(nodes, tets) of the box ``lo``..``hi`` (3,) mm graded around ``focus`` (3,) by :func:`graded_axis`."""
    axes = [graded_axis(lo[a], hi[a], focus[a], h_min, ratio, h_max) for a in range(3)]
    return box_tetrahedra(*axes)


def ball_tetrahedra(radius, n):
    """(nodes, tets) of a ball of ``radius`` mm: the cube [-1, 1]^3 in n x n x n cells (Kuhn tetrahedra) mapped
    onto the ball radially, x -> radius x |x|_inf / |x|_2, so the cube's boundary nodes land exactly on the
    sphere (the discrete boundary is inscribed in it, an O(h^2) error in the geometry, as P1's own)."""
    if not (radius > 0 and int(n) >= 2):
        raise MeshshadeError("ball_tetrahedra needs radius > 0 and n >= 2 cells per axis")
    axis = np.linspace(-1.0, 1.0, int(n) + 1)
    nodes, tets = box_tetrahedra(axis, axis, axis)
    r2 = np.linalg.norm(nodes, axis=1)
    rinf = np.abs(nodes).max(axis=1)
    scale = np.divide(rinf, r2, out=np.ones_like(r2), where=r2 > 0)
    nodes = radius * nodes * scale[:, None]
    return nodes, _oriented(nodes, tets)


#: the inner layer's depth below each surface vertex, in units of the vertex's mean edge length
LAYER_DEPTH = 0.6
#: the most lattice candidates :func:`surface_tetrahedra` generates (over the bounding box, before the bands)
MAX_LATTICE_POINTS = 4e7
#: jitter of the interior points (fraction of their spacing): no five cospherical points, so no flat tetrahedra
JITTER = 0.05
#: a lattice of spacing s fills the band [BAND_LO s, BAND_HI s) of depths below the surface (the finest starts
#: at FINE_START x the surface spacing, the coarsest has no upper bound)
BAND_LO, BAND_HI, FINE_START = 1.5, 3.0, 1.2


class SurfaceTetrahedra(NamedTuple):
    """A tetrahedral mesh of a closed surface whose first ``n_surface`` nodes are the surface's own vertices.

    nodes (N, 3) mm; tets (T, 4); n_surface: the surface vertices (read the solution there, no interpolation);
    surface_spacing: median edge length of the surface (mm); faces_recovered: the fraction of the input triangles
    that are boundary faces of the tetrahedral mesh. The rest are retriangulated between the same surface
    vertices: a planar quad whose corners lie on a circle may take its other diagonal (about half of a torus's
    grid), a flat tetrahedron between four coplanar surface vertices was dropped, or the surface is undersampled
    against its thickness there.
    """

    nodes: np.ndarray
    tets: np.ndarray
    n_surface: int
    surface_spacing: float
    faces_recovered: float


def surface_tetrahedra(vertices, faces, *, h_max=None, seed=0, normal_spacing=None, layered_depth=0.0,
                       interior_spacing=None, interior_reach=0.0):
    """Tetrahedralise the inside of a closed, outward-oriented triangle mesh, keeping its vertices as nodes.

    The points: the surface vertices (exactly), an inner layer ``LAYER_DEPTH`` x the local edge length below
    each vertex (along the vertex normal; dropped where the body is thinner than that), and body-centred cubic
    lattices whose spacing doubles from 2x the surface's median edge length up to ``h_max`` (default: the largest
    extent / 12), each in a band of depth below the surface (``BAND_LO``, ``BAND_HI``; inside by igl's fast
    winding number, depth by its point-to-mesh distance). Their Delaunay tetrahedralisation (scipy, Qhull) is
    kept where the centroid's winding number is above 1/2, and zero-volume tetrahedra spanned by four coplanar
    surface vertices are dropped (the boundary then takes the quad's other diagonal: same plane, same area).
    Interior points are jittered by ``JITTER`` of their spacing (deterministic, ``seed``) so that no other flat
    tetrahedron forms.

    Permissive (scipy's Qhull, libigl): the default install needs no mesher of its own. Raises MeshshadeError if
    a flat tetrahedron remains off the surface or a surface vertex is left outside every tetrahedron.
    """
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    n = V.shape[0]
    edges = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    length = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    h_s = float(np.median(length))
    lo, hi = V.min(axis=0), V.max(axis=0)
    h_max = float(h_max) if h_max is not None else float(np.max(hi - lo)) / 12.0
    count = np.maximum(np.bincount(edges.ravel(), minlength=n), 1)
    vlen = np.bincount(edges.ravel(), weights=np.repeat(length, 2), minlength=n) / count
    rng = np.random.default_rng(seed)
    normals = igl.per_vertex_normals(V, F)
    if not np.all(vlen > 0):
        raise MeshshadeError(f"{int(np.sum(vlen <= 0))} surface vertices are used by no edge of positive length "
                             "(unreferenced or collapsed): tetrahedralise the vertices the faces use")
    step = LAYER_DEPTH * vlen if normal_spacing is None else np.minimum(LAYER_DEPTH * vlen, float(normal_spacing))
    n_layers = max(1, int(np.ceil(float(layered_depth) / float(step.min())))) if layered_depth > 0 else 1
    k = np.arange(1, n_layers + 1)
    layer_depth = k[:, None] * step[None, :]                            # (layers, n)
    live = (k[:, None] == 1) | (layer_depth <= max(float(layered_depth), 0.0))
    layer = (V[None] - normals[None] * layer_depth[..., None])[live]
    layer += rng.uniform(-JITTER, JITTER, layer.shape) * np.broadcast_to(step[None, :], live.shape)[live][:, None]
    layer_depth = layer_depth[live]
    # no interior lattice finer than the surface's own resolution: a material whose diffusion length is far below
    # the edge length (sigma_a >> sigma_s') gains nothing from it
    cap = np.inf if interior_spacing is None else max(float(interior_spacing), 2.0 * h_s)
    spacings = [2.0 * h_s]
    while spacings[-1] < h_max:
        spacings.append(2.0 * spacings[-1])
    count = sum(2.0 * float(np.prod(np.floor((hi - lo) / s) + 1.0)) for s in spacings)
    if count > MAX_LATTICE_POINTS:
        raise MeshshadeError(f"the tetrahedral mesh would need {count:.3g} lattice candidates (surface spacing "
                             f"{h_s:.3g} mm over a {np.max(hi - lo):.4g} mm box); at most {MAX_LATTICE_POINTS:.3g}")
    lattices = []
    for s in spacings:
        axes = [np.arange(lo[a] + 0.5 * s, hi[a], s) for a in range(3)]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        G = np.concatenate([G, G + 0.5 * s])
        lattices.append(G + rng.uniform(-JITTER * s, JITTER * s, G.shape))
    candidates = np.concatenate(lattices + [layer])
    depth = np.full(candidates.shape[0], -1.0)       # depth below the surface; -1 outside
    inside = igl.fast_winding_number(V, F, candidates) > 0.5
    depth[inside] = np.sqrt(igl.point_mesh_squared_distance(candidates[inside], V, F)[0])
    points, start = [V], 0
    for k, (G, s) in enumerate(zip(lattices, spacings)):
        d = depth[start:start + G.shape[0]]
        start += G.shape[0]
        band_lo = BAND_LO * s if k else max(FINE_START * h_s, float(layered_depth))
        band_hi = BAND_HI * s if k < len(spacings) - 1 else np.inf
        if s <= cap and (k == len(spacings) - 1 or spacings[k + 1] > cap):
            band_hi = max(band_hi, float(interior_reach))     # no coarser than the cap within the reach
        elif s > cap:
            band_lo = max(band_lo, float(interior_reach))
        points.append(G[(d >= band_lo) & (d < band_hi)])
    points.insert(1, layer[depth[start:] > 0.5 * layer_depth])
    P = np.concatenate(points)
    T = Delaunay(P).simplices.astype(np.int64)
    T = T[igl.fast_winding_number(V, F, P[T].mean(axis=1)) > 0.5]
    Q = P[T]
    det = np.linalg.det(Q[:, 1:] - Q[:, :1])
    flat = np.abs(det) <= 6e-9 * h_s ** 3
    if np.any(T[flat] >= n):
        raise MeshshadeError(f"{int(np.sum(np.any(T[flat] >= n, axis=1)))} flat tetrahedra off the surface")
    T = _oriented(P, T[~flat])
    used = np.zeros(P.shape[0], dtype=bool)
    used[T.ravel()] = True
    if not used[:n].all():
        raise MeshshadeError(f"{int(np.sum(~used[:n]))} surface vertices are in no tetrahedron (is the surface "
                             "closed, and sampled finely against its thinnest part?)")
    surface = {tuple(f) for f in np.sort(F, axis=1).tolist()}
    bound = {tuple(f) for f in np.sort(boundary_faces(T), axis=1).tolist()}
    return SurfaceTetrahedra(P, T, n, h_s, len(surface & bound) / max(len(surface), 1))

