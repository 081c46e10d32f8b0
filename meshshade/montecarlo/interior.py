"""Safe-distance grid of the Monte Carlo walk: free flights that cannot reach the surface need no ray cast.

A conservative distance-to-surface grid (``SafeDistanceGrid``) bounds, for every point of a voxel, the distance
to the nearest triangle from below: voxels touched by a triangle's bounding box are marked, the Euclidean
distance transform gives the distance ``e`` from a voxel's centre to the nearest marked centre, and for a point
x in voxel v and a surface point y in marked voxel w, |x - y| >= |c_v - c_w| - |x - c_v| - |y - c_w|
>= e - sqrt(3) h. While a sampled free path is shorter than that bound the photon scatters without Embree
(:func:`meshshade.montecarlo.loops.interior_run`); otherwise the free path is kept (``pending``) and handed to
the boundary test, so every free path is drawn exactly once from the exponential law (no bias).

Half-space certificates (``planes``): near the surface the distance bound fails for most free paths, although
most of them do not reach the surface. For a voxel v near the surface with centre c_v, let B be the ball of radius
R = (PLANE_K + 1/2) h around c_v (it lies inside the (2 PLANE_K + 1)^3 voxels around v), n the area-weighted mean
outward normal of the triangles registered in the 3^3 voxels around v, and c the minimum of n . y over the vertices
of every triangle registered in the (2 PLANE_K + 1)^3 voxels (a triangle meeting B is registered there). Every
surface point y in B lies on a triangle whose vertices all have n . vertex >= c, hence n . y >= c: the convex set
B n {n . y < c} holds no surface point. A free path from x to e = x + s d with both ends in that set therefore
cannot reach the surface and needs no ray (:func:`meshshade.montecarlo.loops.certified`). Embree still finds
every boundary hit; the certificates only prove the absence of one, like the distance bound.

The walk runs in the walk surface of :mod:`meshshade.montecarlo.boundary` (the boundary of the bake's inside
{w > 1/2}: holes closed by lids, faces inside or outside the medium left out), which is closed; the grid is built
on it. Where the walk is the mesh's faces alone (``MCOptions(inside="faces")``, or a mesh enclosing no volume) and
the surface does not bound a volume, :func:`open_surface_warning` says what the walk then does: at a hole
(boundary edges) a photon simply flies through: there is no face to exit by, so it walks on beyond the hole as if
the material continued, until it is absorbed (booked as absorbed), comes back in, or meets a face from the front
(booked as lost, like a numerical leak); nothing is tallied as leaving through the hole. A face inside the material
(at a non-manifold edge) stops photons like the surface: met from behind they reflect or leave through it, met
from the front they are lost.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange
from scipy.ndimage import binary_fill_holes, distance_transform_edt

from meshshade.geometry.mesh import face_normals
from meshshade.geometry.topology import edge_topology

PLANE_K = 2
#: skip the half-space certificates when the triangle-voxel registrations would exceed this (huge triangles)
MAX_REGISTRATIONS = 20_000_000
#: ... and for meshes with more faces: the set-up of a curved mesh (0.2-0.6 s for ~1e5 surface voxels of a 320- or
#: 20480-face sphere, measured) costs more than the rays it saves in runs of ~1e7 events; flat, coarse geometry
#: (the MCML boxes and slabs) is where they pay off (0.37 -> 0.21 boundary tests per event, set-up ~0.05 s)
PLANE_MAX_FACES = 64


def open_surface_warning(faces) -> str | None:
    """One line saying what the walk of the faces alone does on this surface if it does not bound a volume
    (boundary or non-manifold edges; see the module docstring), or None for a closed 2-manifold. ``faces``: (m, 3)
    int."""
    topo = edge_topology(np.asarray(faces, dtype=np.int64))
    n_open, n_fin = topo.n_boundary, topo.n_nonmanifold
    if not (n_open or n_fin):
        return None
    parts = []
    if n_open:
        parts.append(f"the mesh is open ({n_open} boundary edges): photons that reach a hole pass through it and "
                     "walk on outside as if the material continued, until they are absorbed (booked as absorbed), come "
                     "back in, or meet the surface from outside (booked as lost); none is tallied as leaving through "
                     "the hole, so exitance near it is too low")
    if n_fin:
        parts.append(f"{n_fin} non-manifold edges: faces inside the material stop photons as if they were the "
                     "surface (photons leave through them, or are lost when they meet their front)")
    return "Monte Carlo: " + "; ".join(parts) + " (close the mesh for a reference)"


class SafeDistanceGrid:
    """Lower bound of the distance to the mesh surface on a cubic voxel grid (mm).

    vertices : (n, 3) float64 mm; faces : (m, 3) int (the walk surface); resolution : voxels along the largest
    extent.
    """

    def __init__(self, vertices, faces, resolution: int = 96, mean_free_path: float | None = None):
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        lo, hi = V.min(axis=0), V.max(axis=0)
        h = float((hi - lo).max()) / resolution
        pad = 2.0 * h
        self.origin = lo - pad
        self.h = h
        shape = np.maximum(np.ceil((hi - lo + 2 * pad) / h).astype(np.int64), 1)
        marked = np.zeros(tuple(shape), dtype=np.bool_)
        tri = V[F]
        i0 = np.clip(np.floor((tri.min(axis=1) - self.origin) / h).astype(np.int64), 0, shape - 1)
        i1 = np.clip(np.floor((tri.max(axis=1) - self.origin) / h).astype(np.int64), 0, shape - 1)
        _mark(marked, i0, i1)
        edt = distance_transform_edt(~marked) * h
        self.safe = np.ascontiguousarray(np.maximum(edt - math.sqrt(3.0) * h * 1.001, 0.0))
        #: half-space certificates (n, c) and each voxel's index into them (-1: none). They pay off only when most
        #: free paths are shorter than their radius: built only for mean_free_path < plane_radius (and coarse meshes).
        self.plane_radius = (PLANE_K + 0.5) * h
        self.planes = np.zeros((0, 4))
        self.plane_index = np.full(self.safe.shape, -1, dtype=np.int32)
        regs = int(np.prod(i1 - i0 + 1, axis=1).sum())
        if (mean_free_path is not None and mean_free_path < self.plane_radius and regs <= MAX_REGISTRATIONS
                and F.shape[0] <= PLANE_MAX_FACES):
            start, tris = _register(i0, i1, np.array(shape), regs)
            vox = np.argwhere(binary_fill_holes(marked) & (self.safe < self.plane_radius))
            an = 0.5 * face_normals(V, F, unit=False)   # area-weighted outward normals
            pl, ok = _planes(vox, start, tris, np.array(shape), an, np.ascontiguousarray(tri), self.origin, h,
                             PLANE_K, max(1, min(4 * numba.get_num_threads(), vox.shape[0])))
            self.planes = np.ascontiguousarray(pl[ok])
            self.plane_index[tuple(vox[ok].T)] = np.arange(self.planes.shape[0], dtype=np.int32)

    def __repr__(self) -> str:
        return (f"SafeDistanceGrid(shape={self.safe.shape}, h={self.h:.4g} mm, free={np.mean(self.safe > 0):.2f}, "
                f"planes={self.planes.shape[0]})")


@njit(cache=True)
def _mark(marked, i0, i1):
    for f in range(i0.shape[0]):
        for a in range(i0[f, 0], i1[f, 0] + 1):
            for b in range(i0[f, 1], i1[f, 1] + 1):
                for c in range(i0[f, 2], i1[f, 2] + 1):
                    marked[a, b, c] = True


@njit(cache=True)
def _register(i0, i1, shape, total):
    """CSR lists of the triangles whose bounding box touches each voxel: (start (nvox + 1,), triangles)."""
    nyz = shape[1] * shape[2]
    count = np.zeros(shape[0] * nyz + 1, dtype=np.int64)
    for f in range(i0.shape[0]):
        for a in range(i0[f, 0], i1[f, 0] + 1):
            for b in range(i0[f, 1], i1[f, 1] + 1):
                for c in range(i0[f, 2], i1[f, 2] + 1):
                    count[a * nyz + b * shape[2] + c + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    tris = np.empty(total, dtype=np.int64)
    for f in range(i0.shape[0]):
        for a in range(i0[f, 0], i1[f, 0] + 1):
            for b in range(i0[f, 1], i1[f, 1] + 1):
                for c in range(i0[f, 2], i1[f, 2] + 1):
                    v = a * nyz + b * shape[2] + c
                    tris[fill[v]] = f
                    fill[v] += 1
    return start, tris


@njit(cache=True, parallel=True)
def _planes(vox, start, tris, shape, area_normals, tri, origin, h, k, n_chunks):
    """Half-space (n, c) of each voxel of ``vox`` (see the module docstring); ok = a useful certificate exists."""
    nyz = shape[1] * shape[2]
    nv = vox.shape[0]
    out = np.zeros((nv, 4))
    ok = np.zeros(nv, dtype=np.bool_)
    stamp = np.full((n_chunks, tri.shape[0]), -1, dtype=np.int32)
    for ch in prange(n_chunks):
        seen = stamp[ch]   # each triangle once per voxel (it is listed in many voxels)
        for j in range(ch * nv // n_chunks, (ch + 1) * nv // n_chunks):
            a0, b0, c0 = vox[j, 0], vox[j, 1], vox[j, 2]
            nx = ny = nz = 0.0
            for a in range(max(a0 - 1, 0), min(a0 + 2, shape[0])):
                for b in range(max(b0 - 1, 0), min(b0 + 2, shape[1])):
                    for c in range(max(c0 - 1, 0), min(c0 + 2, shape[2])):
                        v = a * nyz + b * shape[2] + c
                        for t in range(start[v], start[v + 1]):
                            f = tris[t]
                            if seen[f] == j:
                                continue
                            seen[f] = j
                            nx += area_normals[f, 0]
                            ny += area_normals[f, 1]
                            nz += area_normals[f, 2]
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            if not norm > 0.0:
                continue
            nx, ny, nz = nx / norm, ny / norm, nz / norm
            cmin = math.inf
            for a in range(max(a0 - k, 0), min(a0 + k + 1, shape[0])):
                for b in range(max(b0 - k, 0), min(b0 + k + 1, shape[1])):
                    for c in range(max(c0 - k, 0), min(c0 + k + 1, shape[2])):
                        v = a * nyz + b * shape[2] + c
                        for t in range(start[v], start[v + 1]):
                            f = tris[t]
                            if seen[f] == -2 - j:
                                continue
                            seen[f] = -2 - j
                            for q in range(3):
                                cmin = min(cmin, nx * tri[f, q, 0] + ny * tri[f, q, 1] + nz * tri[f, q, 2])
            # the certificate is only worth a lookup if the voxel centre is (nearly) inside the half-space
            cx = origin[0] + (a0 + 0.5) * h
            cy = origin[1] + (b0 + 0.5) * h
            cz = origin[2] + (c0 + 0.5) * h
            if cmin - (nx * cx + ny * cy + nz * cz) > -0.5 * h:
                # float64 rounding of the dot products (~1e-16 of the coordinates): a tiny shift inward
                scale = abs(cx) + abs(cy) + abs(cz) + (2 * k + 1) * h
                out[j, 0], out[j, 1], out[j, 2], out[j, 3] = nx, ny, nz, cmin - 1e-12 * scale
                ok[j] = True
    return out, ok
