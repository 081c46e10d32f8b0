"""The volume's share of the entering light: sources along the refracted rays, spread sideways (docs/physics.md
§15.3, eqs. (100)-(101)).

Light entering with power P along the refracted unit direction w is first scattered at distance t along it with
density alpha' sigma_t' P exp(-sigma_t' t); an n-point Gauss-Laguerre rule replaces the line (eq. (97)). Split as
particle-mesh Ewald methods split a charge (the screened, Yukawa, form): each point source q delta(x - x_j) of
channel c is written

    q delta = q exp(-kappa^2 s^2 / 2) (g_s * delta)  +  [the rest],                              (100)

g_s a Gaussian of standard deviation s in the tangent plane and kappa = sqrt(sigma_a / D). The first part is
smooth on the scale s and carries, far from the source, exactly the point's field (the Gaussian's sideways
spread multiplies the diffusion tail exp(-kappa rho) by exp(kappa^2 s^2 / 2), which the weight undoes); it is
what the lattice solves. The rest is short-ranged and summed analytically in the local half-space
(:mod:`meshshade.volume.remainder`). With s of half a lattice spacing the lattice carries 82-99 % of skin's light
and almost all of marble's.

:func:`lattice_loads` puts each smoothed point source on the lattice's nodes (its P1 weights: the Galerkin load of
a point) at the nodes of a 2 x 2 Gauss-Hermite rule in the tangent plane (exact for the Gaussian's moments up to
degree 3), and gathers them onto the unknowns. Compiled loop over fixed ranges of entries on the worker threads;
no I/O.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.polynomial.hermite_e import hermegauss
from numpy.polynomial.laguerre import laggauss

from meshshade.errors import MeshshadeError
from meshshade.pacing import parallel_for
from meshshade.volume.lattice import kuhn_weights

__all__ = ["SOURCE_POINTS", "line_rule", "ewald_weight", "lattice_loads", "SIDEWAYS_POINTS"]

#: points of the Gauss-Laguerre rule along each refracted ray (exact for the moments of t up to degree 11)
SOURCE_POINTS = 6
#: points per axis of the Gauss-Hermite rule of the sideways Gaussian. The rule must resolve the Gaussian on the
#: finest cubes (their side equals the spread, resolution.SPREAD_OVER_H0): with 2 points (+-spread) the cubes around
#: edges of light saw four lumps per entry, and the surface read at the entries (which sit among them) came out low:
#: a marble block's face at the finest level -23 / -30 / -36 % against adding-doubling (-0.5 / -0.7 / -0.8 % at the
#: next level); 3 or 5 points put one on the entry itself (+27 % high); 4 points -10 %; 6 points within 2 % (issue 47;
#: docs/limitations.md). Cost: the 141k head's sources 0.2 -> 0.9 s of a 9-10 s bake.
SIDEWAYS_POINTS = 6
#: the entries are loaded in this many fixed ranges, each into its own array (on the worker threads)
LOAD_BLOCKS = 8


def line_rule(albedo_prime: float, n: int = SOURCE_POINTS):
    """(distances (n,) optical units, strengths (n,)): alpha' exp(-t) as its n-point Gauss-Laguerre rule."""
    x, w = laggauss(int(n))
    return x, float(albedo_prime) * w


def ewald_weight(kappa, spread):
    """exp(-kappa^2 s^2 / 2): the weight of the smoothed part of eq. (100) (kappa 1/mm, spread s mm)."""
    return np.exp(-0.5 * (np.asarray(kappa, dtype=np.float64) * float(spread)) ** 2)


@numba.njit(cache=True, nogil=True)
def _loads(pos, refracted, normal, power, scale, t, w, gx, gw, spread, h0, index, lo, level, ijk, cell_nodes, out,
           dropped, p_lo, p_hi):
    """Nodal loads (N, k) of the sources of entries p_lo:p_hi: per channel c, depth points t[c] (mm) times the
    entry's ``scale[p, c]`` with strengths w[c] (times the entry's power), each spread over the Gauss-Hermite nodes
    gx (weights gw) in the plane normal to ``normal``; ``power`` (p, k): each entry's power per channel;
    ``dropped[c]`` collects power that fell outside the lattice."""
    k_ch, n_t = t.shape
    n_g = gx.size
    for p in range(p_lo, p_hi):
        nx, ny, nz = normal[p, 0], normal[p, 1], normal[p, 2]
        # a tangent basis of the normal
        if abs(nx) < 0.9:
            ax, ay, az = 1.0, 0.0, 0.0
        else:
            ax, ay, az = 0.0, 1.0, 0.0
        e1x, e1y, e1z = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax
        l1 = math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
        e1x, e1y, e1z = e1x / l1, e1y / l1, e1z / l1
        e2x, e2y, e2z = ny * e1z - nz * e1y, nz * e1x - nx * e1z, nx * e1y - ny * e1x
        for c in range(k_ch):
            for j in range(n_t):
                tj = t[c, j] * scale[p, c]
                cx = pos[p, 0] + tj * refracted[p, 0]
                cy = pos[p, 1] + tj * refracted[p, 1]
                cz = pos[p, 2] + tj * refracted[p, 2]
                for a in range(n_g):
                    for b in range(n_g):
                        q = power[p, c] * w[c, j] * gw[a] * gw[b]
                        if q == 0.0:
                            continue
                        px = cx + spread * (gx[a] * e1x + gx[b] * e2x)
                        py = cy + spread * (gx[a] * e1y + gx[b] * e2y)
                        pz = cz + spread * (gx[a] * e1z + gx[b] * e2z)
                        cell = _find(px, py, pz, h0, index, lo)
                        if cell < 0:
                            dropped[c] += q
                            continue
                        h = h0 * (2.0 ** level[cell])
                        v1, v2, w0, w1, w2, w3 = kuhn_weights(px / h - ijk[cell, 0], py / h - ijk[cell, 1],
                                                              pz / h - ijk[cell, 2])
                        out[cell_nodes[cell, 0], c] += q * w0
                        out[cell_nodes[cell, v1], c] += q * w1
                        out[cell_nodes[cell, v2], c] += q * w2
                        out[cell_nodes[cell, 7], c] += q * w3


@numba.njit(cache=True, inline="always")
def _find(px, py, pz, h0, index, lo):
    i = int(math.floor(px / h0 + 1e-9)) - lo[0]
    j = int(math.floor(py / h0 + 1e-9)) - lo[1]
    k = int(math.floor(pz / h0 + 1e-9)) - lo[2]
    if 0 <= i < index.shape[0] and 0 <= j < index.shape[1] and 0 <= k < index.shape[2]:
        return index[i, j, k]
    return -1


def lattice_loads(lattice, positions, refracted, normals, power, depths_mm, strengths, spread_mm, depth_scale=None):
    """(N, k) nodal loads W and (k,) power dropped outside the lattice, for entries at ``positions`` (p, 3) mm
    entering along ``refracted`` (p, 3) with ``power`` (p,) W, or (p, k) per channel (a medium that varies from
    entry to entry): per channel, points at ``depths_mm`` (k, n) along the ray (times each entry's ``depth_scale``
    (p, k) where given: a mean free path that varies from entry to entry) with ``strengths`` (k, n) (the rule's
    weights times each channel's Ewald weight), spread sideways by a Gaussian of ``spread_mm`` in the plane normal
    to ``normals``."""
    depths_mm = np.ascontiguousarray(np.atleast_2d(depths_mm), dtype=np.float64)
    strengths = np.ascontiguousarray(np.atleast_2d(strengths), dtype=np.float64)
    if depths_mm.shape != strengths.shape:
        raise MeshshadeError("source depths and strengths must have one shape")
    k = depths_mm.shape[0]
    out = np.zeros((lattice.n_nodes, k))
    if spread_mm > 0:
        gx, gw = hermegauss(SIDEWAYS_POINTS)
        gw = gw / gw.sum()
    else:
        gx, gw = np.zeros(1), np.ones(1)
    args = [np.ascontiguousarray(a, dtype=np.float64) for a in (positions, refracted, normals)]
    n = args[0].shape[0]
    power = np.asarray(power, dtype=np.float64)
    if power.ndim == 1:
        power = power[:, None]
    if power.shape[0] != n or power.shape[1] not in (1, k):
        raise MeshshadeError("the entries' power must be (entries,) or (entries, channels)")
    args.append(np.ascontiguousarray(np.broadcast_to(power, (n, k))))
    scale = np.ones((n, k)) if depth_scale is None else np.asarray(depth_scale, dtype=np.float64)
    if scale.shape != (n, k):
        raise MeshshadeError("the entries' depth scale must be (entries, channels)")
    args.append(np.ascontiguousarray(scale))
    # LOAD_BLOCKS fixed ranges of entries, each into its own nodal array, summed in order: the same loads for any
    # number of threads
    blocks = min(LOAD_BLOCKS, max(1, n // 4096))
    edges = [round(i * n / blocks) for i in range(blocks + 1)]
    outs = [out] + [np.zeros_like(out) for _ in range(blocks - 1)]
    drops = np.zeros((blocks, k))

    def run(a, b):
        for i in range(a, b):
            _loads(*args, depths_mm, strengths, gx, gw, float(spread_mm), float(lattice.grading.h0), lattice._index,
                   lattice._index_lo, lattice.level, lattice.ijk, lattice.cell_nodes, outs[i], drops[i], edges[i],
                   edges[i + 1])

    parallel_for(run, blocks, min_block=1)
    for extra in outs[1:]:
        out += extra
    dropped = drops.sum(axis=0)
    return out, dropped
