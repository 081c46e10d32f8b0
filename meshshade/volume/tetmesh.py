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
from meshshade.volume.locate import face_keys

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
#: the most lattice candidates :func:`surface_tetrahedra` generates (in the blocks near enough to the surface)
MAX_LATTICE_POINTS = 4e7
#: the largest fraction of the surface's vertices that may end up in no tetrahedron (a spike's tip whose every
#: tetrahedron was outside or flat: the volume transport reads them by interpolation); more is an error
MAX_ORPHANS = 1e-3
#: jitter of the interior points (fraction of their spacing): no five cospherical points, so no flat tetrahedra
JITTER = 0.05
#: a lattice of spacing s fills depths below the surface from where the finer one stops to BAND_HI s (the finest
#: starts at FINE_START x the surface spacing, or below the layers; the coarsest has no upper bound)
BAND_HI, FINE_START = 3.0, 1.2


def _surface_samples(V, F, gap):
    """Points of the surface (V, F) such that every point of it is within ``gap`` of one: the vertices, and a
    barycentric grid on each triangle longer than ``gap``."""
    P = V[F]                                                            # (F, 3, 3)
    longest = np.max(np.linalg.norm(P - np.roll(P, 1, axis=1), axis=2), axis=1)
    out = [V]
    m = np.ceil(longest / gap).astype(np.int64)
    for k in np.unique(m[m > 1]):
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        b = np.stack([i[keep], j[keep], k - i[keep] - j[keep]], axis=1) / k    # (g, 3) barycentrics
        out.append(np.einsum("gk,fkd->fgd", b, P[m == k]).reshape(-1, 3))
    return np.concatenate(out)


def _near_blocks(V, lo, hi, s, distance):
    """The blocks of a lattice of spacing ``s`` (cubes of q x q x q cells, q s >= ``distance``) that may hold a
    point within ``distance`` of a point of ``V``: (block indices (m, 3), q), or (None, 1) for the whole box."""
    if not np.isfinite(distance):
        return None, 1
    q = max(1, int(np.ceil(distance / s)))
    near = _block_marks(V, lo, hi, q * s)
    return (None, 1) if near is None else (np.argwhere(near), q)


def _block_marks(V, lo, hi, size):
    """(blocks,) bool over the box [lo, hi] in cubes of ``size``: True for the blocks within one block of a point
    of ``V`` (every point within ``size`` of one lies in such a block; every other point is farther); None if the
    box has over 1e8 blocks."""
    shape = (np.floor((hi - lo) / size).astype(np.int64) + 1)
    if np.prod(shape.astype(np.float64)) > 1e8:
        return None
    own = np.floor((V - lo) / size).astype(np.int64)
    own = np.unique(np.clip(own, 0, shape - 1) @ np.array([shape[1] * shape[2], shape[2], 1]))
    mark = np.zeros(shape, dtype=bool)
    mark.reshape(-1)[own] = True
    near = mark.copy()                      # dilated by one block along each axis in turn: the 27 neighbours
    for axis in range(3):
        for shift in (-1, 1):
            near |= np.roll(mark, shift, axis=axis) & _not_wrapped(shape, axis, shift)
        mark = near.copy()
    return near


def _farther_than(samples, lo, hi, distance, points):
    """(k,) bool: ``points`` certainly farther than ``distance`` from every one of ``samples`` (by blocks)."""
    near = _block_marks(samples, lo, hi, distance) if np.isfinite(distance) else None
    if near is None:
        return np.zeros(points.shape[0], dtype=bool)
    b = np.clip(np.floor((points - lo) / distance).astype(np.int64), 0, np.array(near.shape) - 1)
    return ~near[b[:, 0], b[:, 1], b[:, 2]]


def _not_wrapped(shape, axis, shift):
    """Mask of the blocks that ``np.roll(..., shift, axis)`` did not wrap around."""
    keep = np.ones(shape, dtype=bool)
    index = [slice(None)] * 3
    index[axis] = 0 if shift > 0 else -1
    keep[tuple(index)] = False
    return keep


def _lattice_points(lo, hi, s, blocks, q):
    """The cubic lattice lo + (i + 1/2) s inside the box [lo, hi] (its first sublattice), all of it
    (``blocks`` None) or in the given blocks of q x q x q cells only."""
    if blocks is None:
        axes = [np.arange(lo[a] + 0.5 * s, hi[a], s) for a in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    local = np.stack(np.meshgrid(*[np.arange(q)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = (blocks[:, None, :] * q + local[None]).reshape(-1, 3)
    G = lo + (idx + 0.5) * s
    return G[np.all(G < hi, axis=1)]


def _inside(V, F, P, T, depth):
    """(T,) bool: the centroid of tetrahedron ``T`` lies inside the surface (V, F). ``depth`` (N,): each node's
    distance below the surface (0 for the surface's own). A centroid closer to one of its nodes than that node's
    depth lies in a ball inside the body; only the rest are asked of the winding number (in practice the
    tetrahedra touching the surface)."""
    inside = np.zeros(T.shape[0], dtype=bool)
    for lo in range(0, T.shape[0], 1 << 20):      # in chunks: (chunk, 4, 3) at a time
        t = T[lo:lo + (1 << 20)]
        Q = P[t]
        c = Q.mean(axis=1)
        inside[lo:lo + t.shape[0]] = np.any(np.einsum("tkj,tkj->tk", Q - c[:, None], Q - c[:, None])
                                            < depth[t] ** 2, axis=1)
    ask = np.flatnonzero(~inside)
    if ask.size:
        inside[ask] = igl.fast_winding_number(V, F, P[T[ask]].mean(axis=1)) > 0.5
    return inside


def _faces_recovered(F, boundary, n):
    """The fraction of the surface triangles ``F`` among the ``boundary`` faces (nodes below ``n`` only)."""
    boundary = boundary[np.all(boundary < n, axis=1)]
    return float(np.isin(face_keys(F, n), face_keys(boundary, n)).sum()) / max(F.shape[0], 1)


class SurfaceTetrahedra(NamedTuple):
    """A tetrahedral mesh of a closed surface whose first ``n_surface`` nodes are the surface's own vertices.

    nodes (N, 3) mm; tets (T, 4); n_surface: the surface vertices (read the solution there, no interpolation,
    except at the few, at most ``MAX_ORPHANS``, that may be in no tetrahedron: nodes of no element);
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
                       interior_spacing=None, interior_reach=0.0, column_spacing=None):
    """Tetrahedralise the inside of a closed, outward-oriented triangle mesh, keeping its vertices as nodes.

    The points: the surface vertices (exactly), layers every ``normal_spacing`` (default ``LAYER_DEPTH`` x the
    local edge length) below each vertex down to ``layered_depth`` (at least one; along the vertex normal;
    dropped where the body is thinner than half its depth), and body-centred cubic lattices whose spacing
    doubles from 2x the surface's median edge length up to ``h_max`` (default: the largest extent / 12), taking
    ``interior_spacing`` itself on the way, each in a band of depth below the surface (up to ``BAND_HI`` x its
    spacing; the lattice no coarser than ``interior_spacing`` fills everything to ``interior_reach``; inside by
    igl's fast winding number, depth by its point-to-mesh distance). Their Delaunay tetrahedralisation (scipy,
    Qhull) is kept where the centroid is inside (a ball around a node, or the winding number above 1/2), and
    zero-volume tetrahedra spanned by four coplanar surface vertices are dropped (the boundary then takes the
    quad's other diagonal: same plane, same area).
    Interior points are jittered by ``JITTER`` of their spacing (deterministic, ``seed``) so that no other flat
    tetrahedron forms.

    ``column_spacing`` (mm; the material's tangential need, :func:`meshshade.volume.transport.grading`): on a
    surface finer than that, the layers stand under one vertex per cube of that size only (every vertex whose own
    edges are longer keeps its column), and no lattice is finer than twice it. So
    the node count follows the material's lengths and the surface's own vertices, not the surface's resolution
    times the layers: subdividing a mesh adds its vertices and little else.

    Permissive (scipy's Qhull, libigl): the default install needs no mesher of its own. Raises MeshshadeError if
    a flat tetrahedron remains off the surface or more than ``MAX_ORPHANS`` of the surface vertices are left
    outside every tetrahedron.
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
    column = np.ones(n, dtype=bool)
    if column_spacing is not None:      # one column per cube of column_spacing among the finer vertices
        rho = float(column_spacing)
        fine = np.flatnonzero(vlen < rho)
        cell = np.floor((V[fine] - lo) / rho).astype(np.int64)
        size = np.floor((hi - lo) / rho).astype(np.int64) + 1
        code = (cell[:, 0] * size[1] + cell[:, 1]) * size[2] + cell[:, 2]
        column[fine] = False
        column[fine[np.unique(code, return_index=True)[1]]] = True
    # layers every normal_spacing where given (no thinner on a fine surface: the material does not ask for it),
    # else LAYER_DEPTH x the local edge length
    step = LAYER_DEPTH * vlen if normal_spacing is None else np.full(n, float(normal_spacing))
    n_layers = max(1, int(np.ceil(float(layered_depth) / float(step[column].min())))) if layered_depth > 0 else 1
    k = np.arange(1, n_layers + 1)
    layer_depth = k[:, None] * step[None, :]                            # (layers, n)
    live = ((k[:, None] == 1) | (layer_depth <= max(float(layered_depth), 0.0))) & column[None, :]
    layer = (V[None] - normals[None] * layer_depth[..., None])[live]
    layer += rng.uniform(-JITTER, JITTER, layer.shape) * np.broadcast_to(step[None, :], live.shape)[live][:, None]
    layer_depth = layer_depth[live]
    # no interior lattice finer than the surface's own resolution: a material whose diffusion length is far below
    # the edge length (sigma_a >> sigma_s') gains nothing from it
    cap = np.inf if interior_spacing is None else max(float(interior_spacing), 2.0 * h_s)
    spacings = [2.0 * max(h_s, float(column_spacing or 0.0))]
    while spacings[-1] < h_max:         # doubling, with the cap itself where a doubling would step over it
        spacings.append(cap if 1.2 * spacings[-1] < cap < 2.0 * spacings[-1] else 2.0 * spacings[-1])
    bands, band_hi = [], max(FINE_START * h_s, float(layered_depth))
    for k, s in enumerate(spacings):        # the depths each lattice fills: from where the finer one stops
        band_lo, band_hi = band_hi, (BAND_HI * s if k < len(spacings) - 1 else np.inf)
        if s <= cap and (k == len(spacings) - 1 or spacings[k + 1] > cap):
            band_hi = max(band_hi, float(interior_reach))     # no coarser than the cap within the reach
        bands.append((band_lo, max(band_hi, band_lo)))
    # surface samples (the vertices, and points on the longer triangles) such that every point of the surface is
    # within `gap` of one: a point within d of the surface is within d + gap of a sample
    gap = 2.0 * h_s
    samples = _surface_samples(V, F, gap)
    blocks = [_near_blocks(samples, lo, hi, s, b[1] + gap) for s, b in zip(spacings, bands)]
    count = sum(2.0 * (np.prod(np.floor((hi - lo) / s) + 1.0) if m is None else m.shape[0] * q ** 3)
                for s, (m, q) in zip(spacings, blocks))
    if count > MAX_LATTICE_POINTS:
        raise MeshshadeError(f"the tetrahedral mesh would need {count:.3g} lattice candidates (surface spacing "
                             f"{h_s:.3g} mm over a {np.max(hi - lo):.4g} mm box); at most {MAX_LATTICE_POINTS:.3g}")
    lattices = []
    for s, (m, q) in zip(spacings, blocks):
        G = _lattice_points(lo, hi, s, m, q)
        G = np.concatenate([G, G + 0.5 * s])
        lattices.append(G + rng.uniform(-JITTER * s, JITTER * s, G.shape))
    candidates = np.concatenate(lattices + [layer])
    depth = np.full(candidates.shape[0], -1.0)       # depth below the surface; -1 outside
    inside = np.flatnonzero(igl.fast_winding_number(V, F, candidates) > 0.5)
    # the exact depth (distance to the surface) wherever a band boundary may fall; a point farther than the
    # coarsest lattice's start (plus the gap) from every sample goes to that lattice and keeps that start as a
    # lower bound of its depth (the point-to-mesh distance is slowest far from the surface)
    deep = bands[-1][0]
    far = _farther_than(samples, lo, hi, deep + gap, candidates[inside])
    depth[inside[far]] = deep
    depth[inside[~far]] = np.sqrt(igl.point_mesh_squared_distance(candidates[inside[~far]], V, F)[0])
    points, depths, start = [V], [np.zeros(n)], 0
    for G, (band_lo, band_hi) in zip(lattices, bands):
        d = depth[start:start + G.shape[0]]
        start += G.shape[0]
        band = (d >= band_lo) & (d < band_hi)
        points.append(G[band])
        depths.append(d[band])
    keep_layer = depth[start:] > 0.5 * layer_depth
    points.insert(1, layer[keep_layer])
    depths.insert(1, depth[start:][keep_layer])
    P = np.concatenate(points)
    T = Delaunay(P).simplices.astype(np.int64)
    T = T[_inside(V, F, P, T, np.concatenate(depths))]
    Q = P[T]
    det = np.linalg.det(Q[:, 1:] - Q[:, :1])
    del Q
    flat = np.abs(det) <= 6e-9 * h_s ** 3
    if np.any(T[flat] >= n):
        raise MeshshadeError(f"{int(np.sum(np.any(T[flat] >= n, axis=1)))} flat tetrahedra off the surface")
    T, det = T[~flat], det[~flat]
    neg = det < 0
    T[neg] = T[neg][:, [0, 2, 1, 3]]
    used = np.zeros(P.shape[0], dtype=bool)
    used[T.ravel()] = True
    if np.sum(~used[:n]) > MAX_ORPHANS * n:
        raise MeshshadeError(f"{int(np.sum(~used[:n]))} surface vertices are in no tetrahedron (is the surface "
                             "closed, and sampled finely against its thinnest part?)")
    # a face of three surface vertices belongs only to tetrahedra with three or four of them
    return SurfaceTetrahedra(P, T, n, h_s, _faces_recovered(F, boundary_faces(T[(T < n).sum(axis=1) >= 3]), n))
