"""Numba fast path of the Monte Carlo walk: free flights that cannot reach the surface need no ray cast.

A conservative distance-to-surface grid (``SafeDistanceGrid``) bounds, for every point of a voxel, the distance
to the nearest triangle from below: voxels touched by a triangle's bounding box are marked, the Euclidean
distance transform gives the distance ``e`` from a voxel's centre to the nearest marked centre, and for a point
x in voxel v and a surface point y in marked voxel w, |x - y| >= |c_v - c_w| - |x - c_v| - |y - c_w|
>= e - sqrt(3) h. While a sampled free path is shorter than that bound the photon scatters without Embree (the
numba kernel below); otherwise the free path is kept (``pending``) and handed to the Embree step, so every
free path is drawn exactly once from the exponential law (no bias).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


class SafeDistanceGrid:
    """Lower bound of the distance to the mesh surface on a cubic voxel grid (mm).

    vertices : (n, 3) float64 mm; faces : (m, 3) int; resolution : voxels along the largest extent.
    """

    def __init__(self, vertices, faces, resolution: int = 96):
        from scipy.ndimage import distance_transform_edt  # noqa: PLC0415

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

    def __repr__(self) -> str:
        return f"SafeDistanceGrid(shape={self.safe.shape}, h={self.h:.4g} mm, free={np.mean(self.safe > 0):.2f})"


@njit(cache=True)
def _mark(marked, i0, i1):
    for f in range(i0.shape[0]):
        for a in range(i0[f, 0], i1[f, 0] + 1):
            for b in range(i0[f, 1], i1[f, 1] + 1):
                for c in range(i0[f, 2], i1[f, 2] + 1):
                    marked[a, b, c] = True


@njit(cache=True, inline="always")
def _uniform(state, i):
    """SplitMix64 (Steele, Lea & Flood 2014) on photon i's own counter: [0, 1), independent of threading."""
    z = state[i] + _GOLDEN
    state[i] = z
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _lookup(safe, origin, h, x, y, z):
    a = int(math.floor((x - origin[0]) / h))
    b = int(math.floor((y - origin[1]) / h))
    c = int(math.floor((z - origin[2]) / h))
    if a < 0 or b < 0 or c < 0 or a >= safe.shape[0] or b >= safe.shape[1] or c >= safe.shape[2]:
        return 0.0
    return safe[a, b, c]


def _interior_walk(pos, d, w, w0, pending, safe, origin, h, sigma_t, albedo, g, thresh, boost, max_steps, state):
    """Advance every photon by free flights that stay inside its safe ball; in place.

    Returns (absorbed (n,) weight booked as absorbed incl. roulette net, alive (n,) bool, events int).
    On return ``pending[i]`` holds the free path (mm) the Embree step must use. ``state`` (n,) uint64 holds each
    photon's random counter, so the result does not depend on the number of threads.
    """
    n = w.shape[0]
    absorbed = np.zeros(n)
    alive = np.ones(n, dtype=np.bool_)
    events = 0
    for i in prange(n):
        for _ in range(max_steps):
            s = pending[i]
            if s < 0.0:
                s = -math.log(1.0 - _uniform(state, i)) / sigma_t
                pending[i] = s
            if s >= _lookup(safe, origin, h, pos[i, 0], pos[i, 1], pos[i, 2]):
                break
            pending[i] = -1.0
            pos[i, 0] += s * d[i, 0]
            pos[i, 1] += s * d[i, 1]
            pos[i, 2] += s * d[i, 2]
            absorbed[i] += w[i] * (1.0 - albedo)
            w[i] *= albedo
            events += 1
            # Henyey-Greenstein direction
            u = _uniform(state, i)
            if abs(g) < 1e-6:
                ct = 1.0 - 2.0 * u
            else:
                tmp = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
                ct = min(1.0, max(-1.0, (1.0 + g * g - tmp * tmp) / (2.0 * g)))
            st = math.sqrt(max(0.0, 1.0 - ct * ct))
            phi = 2.0 * math.pi * _uniform(state, i)
            dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
            sign = 1.0 if dz >= 0.0 else -1.0
            a = -1.0 / (sign + dz)
            bb = dx * dy * a
            tx, ty, tz = 1.0 + sign * dx * dx * a, sign * bb, -sign * dx
            bx, by, bz = bb, sign + dy * dy * a, -dy
            cp, sp = st * math.cos(phi), st * math.sin(phi)
            nx = cp * tx + sp * bx + ct * dx
            ny = cp * ty + sp * by + ct * dy
            nz = cp * tz + sp * bz + ct * dz
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            d[i, 0], d[i, 1], d[i, 2] = nx / norm, ny / norm, nz / norm
            # Russian roulette, net change booked as absorbed
            if w[i] < thresh * w0[i]:
                if _uniform(state, i) * boost < 1.0:
                    absorbed[i] -= (boost - 1.0) * w[i]
                    w[i] *= boost
                else:
                    absorbed[i] += w[i]
                    w[i] = 0.0
                    alive[i] = False
                    break
    return absorbed, alive, events


_walk_serial = njit(cache=True)(_interior_walk)
_walk_parallel = njit(cache=True, parallel=True)(_interior_walk)
#: below this many photons the thread launch (~25 ms per call measured with the OpenMP layer) costs more than it saves
PARALLEL_MIN_PHOTONS = 50_000


def interior_walk(pos, d, w, w0, pending, safe, origin, h, sigma_t, albedo, g, thresh, boost, max_steps, state):
    """Dispatch to the serial or the threaded kernel (identical results: per-photon random counters)."""
    kernel = _walk_parallel if w.shape[0] >= PARALLEL_MIN_PHOTONS else _walk_serial
    return kernel(pos, d, w, w0, pending, safe, origin, h, sigma_t, albedo, g, thresh, boost, max_steps, state)
