"""The fused walk loop of the pooled engine's ``fused`` mode: Embree's ``rtcIntersect1`` from numba threads.

One ``prange`` kernel over the live slots walks every live photon for up to ``max_steps`` events: free paths
certified by the safe-distance grid (:mod:`meshshade.montecarlo.interior`) need no ray, the others are traced from
the photon's own thread through :func:`meshshade.raycast.embree_direct.trace` (no GIL) and resolved in float64 by
:func:`meshshade.montecarlo.loops.surface_s`. Physics and random streams are those of
:mod:`meshshade.montecarlo.loops`, so a photon walks the same path as in the ``batched`` mode.
"""
from __future__ import annotations

import math

from numba import njit, prange

from meshshade.montecarlo import loops as K
from meshshade.raycast.embree_direct import rayhit_buffer, trace

__all__ = ["walk_parallel"]


def _walk(idx, status, pos, d, w, w0, pend, key, ctr, absorbed, lost, exit_face, exit_bary, exit_w, safe, geo,
          planes, pidx, v0, e1, e2, normals, center, scale, off_rel, off_abs, margin, sigma_t, albedo, g, eta, thresh,
          boost, max_steps, intersect, scene):
    """Every live photon (the slots ``idx``) walks up to ``max_steps`` events (scattering or surface) or until it
    dies.

    Free paths certified by the safe-distance grid (distance bound or half-space certificate) need no ray; the
    others are traced by Embree from this thread. The photon's state stays in local variables for the whole
    round. Returns (scattering events, boundary events, rays).
    """
    events = 0
    boundary = 0
    rays = 0
    for j in prange(idx.shape[0]):
        i = idx[j]
        if status[i] != K.ALIVE:
            continue
        rh, rhi = rayhit_buffer()
        x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        wi, s, k, c = w[i], pend[i], key[i], ctr[i]
        thr = thresh * w0[i]
        ab_sum = 0.0
        alive = True
        ev = 0
        bd = 0
        nr = 0
        steps = 0
        while steps < max_steps:
            steps += 1
            if s < 0.0:
                u, c = K._uniform(k, c)
                s = -math.log(1.0 - u) / sigma_t
            kind = K.SCATTER
            if not K.certified(safe, geo, planes, pidx, x, y, z, dx, dy, dz, s):
                f = trace(intersect, scene, rh, rhi, x - center[0], y - center[1], z - center[2], dx, dy, dz,
                           min(s + margin, 1e37))
                nr += 1
                kind, x, y, z, dx, dy, dz, c, u, v = K.surface_s(f, x, y, z, dx, dy, dz, s, k, c, v0, e1, e2,
                                                                 normals, center, scale, off_rel, off_abs, eta)
            if kind == K.SCATTER:
                x, y, z, dx, dy, dz, wi, c, ab, alive = K.scatter_s(x, y, z, dx, dy, dz, wi, s, k, c, thr, albedo,
                                                                    g, boost)
                ab_sum += ab
                ev += 1
            elif kind == K.LEAK:
                lost[i] += wi
                wi = 0.0
                alive = False
            elif kind == K.EXIT:
                exit_face[i] = f
                exit_bary[i, 0], exit_bary[i, 1], exit_bary[i, 2] = 1.0 - u - v, u, v
                exit_w[i] = wi
                wi = 0.0
                alive = False
                bd += 1
            else:
                bd += 1
            s = -1.0
            if not alive:
                status[i] = K.FREE
                break
        pos[i, 0], pos[i, 1], pos[i, 2] = x, y, z
        d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
        w[i], pend[i], ctr[i] = wi, s, c
        absorbed[i] += ab_sum
        events += ev
        boundary += bd
        rays += nr
    return events, boundary, rays


walk_parallel = njit(parallel=True, nogil=True, **K._OPTS)(_walk)
