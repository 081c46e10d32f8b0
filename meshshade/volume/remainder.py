"""The volume's correction: what the lattice does not carry, summed in the local half-space (docs/physics.md
§15.4, eqs. (102)-(103)).

Per entry of power P whose light travels inside at theta_t, the exitance at a receiver at chord distance s (same
side: normals not opposed) gains P f(s; theta_t) with

    f(s; theta_t) = W(theta_t) R_near(s) - M_long(s; theta_t),                                        (102)

the near-field model (eq. (76), with the incidence gain W of eq. (86)) less the Robin half-space's response to
exactly what the lattice was given: the line sources of eq. (97) at depths t_j cos theta_t, each spread
sideways and weighted as eq. (100) (:func:`meshshade.kernels.robin_halfspace.robin_smoothed_exitance`). On a flat
surface the lattice's solution is M_long, so the bake returns the near-field model; elsewhere the lattice keeps
the curvature, the thin parts and the folds, and f, confined to a few millimetres, is planar.

*The sum over entries* of a surface lit with irradiance E (W/mm^2) per light is the convolution of E with f over
the surface. Its integrand is singular at the receiver (R_near holds single scattering), so the sum subtracts the
receiver's own irradiance and adds back its exact integral (singularity subtraction):

    M_f(x) = sum_j (P_j - E_l(x) A_j) fbar_j(s_xj) + sum_l E_l(x) T(theta_t,l(x)),                      (103)

A_j the area an entry stands for (0 for a beam's point entry), l the entry's light, T the total of f. For
uniform light the pairs cancel and the receiver gets exactly E T; where it varies only its differences are
summed, which the pair quadrature handles. fbar is f averaged over the entry's disc (radius sqrt(A_j / pi)) for
pairs within PATCH_RADII disc radii, f itself beyond; pairs beyond the radius where |f| holds TAIL_TOL of the
near-field total are left out, their signed energy kept at the entry.

Tables per channel over ln s (1025 nodes) and 9 values of cos theta_t; the pair values are a compiled loop run on
blocks of pairs by the pacing threads. No I/O.
"""
from __future__ import annotations

import math
import warnings

import numba
import numpy as np
from numba.core import types
from numba.core.errors import NumbaIRAssumptionWarning
from numba.extending import overload

from meshshade.kernels.robin_halfspace import robin_smoothed_exitances
from meshshade.pacing import run_in_blocks
from meshshade.volume.long_range import line_rule
from meshshade.volume.triangle_tree import morton_order, prefix_tree

__all__ = ["RemainderTables", "TAIL_TOL", "PATCH_RADII", "remainder_exitance", "longest_edges"]

#: the correction's radius: where the magnitude of f beyond it holds this fraction of R_near's total
TAIL_TOL = 1e-3
#: the tables' reach in optical units
TABLE_REACH = 30.0
#: pairs closer than this many disc radii take f averaged over the entry's disc
PATCH_RADII = 4.0
_LOG_R = np.linspace(math.log(1e-5), math.log(200.0), 1025)     # optical distances of the tables
_N_COS = 9
_TH_NODES, _TH_WEIGHTS = np.polynomial.legendre.leggauss(24)


class RemainderTables:
    """f of eq. (102) for each channel of ``material`` with the lattice's sideways ``spread_mm``: ``f`` (3, 9, n_r)
    1/mm^2 per W, its disc integral ``cum`` (3, 9, n_r), ``rest`` (3, 9) the signed energy beyond ``radius_mm``,
    ``total`` (3, 9) the whole integral, on ``cos_t`` (3, 9) and ln-distance offsets ``log_r0`` (3,)."""

    def __init__(self, material, spread_mm: float):
        self.sigma_t_prime = np.asarray(material.sigma_t_prime, dtype=np.float64)
        r_all = np.exp(_LOG_R)
        built = {}
        rows = []
        for c in range(3):
            a, st = float(material.albedo_prime[c]), float(self.sigma_t_prime[c])
            key = (a, round(spread_mm * st, 12))
            if key not in built:
                built[key] = _channel(material.medium.near_field(c), spread_mm * st, r_all)
            rows.append(built[key])
        n_r = max(r[4] for r in rows)
        self.f = np.zeros((3, _N_COS, n_r))
        self.cum = np.zeros((3, _N_COS, n_r))
        self.rest = np.zeros((3, _N_COS))
        self.total = np.zeros((3, _N_COS))
        self.cos_t = np.zeros((3, _N_COS))
        self.n_r = np.zeros(3, dtype=np.int64)
        self.radius_mm = np.zeros(3)
        self.log_r0 = np.array([_LOG_R[0] - math.log(s) for s in self.sigma_t_prime])
        self.long_fraction = np.zeros(3)
        for c, (cos_t, f, cum, total, nr, long_total, near_total) in enumerate(rows):
            s = self.sigma_t_prime[c]
            self.f[c, :, :nr] = f[:, :nr] * s * s
            self.cum[c, :, :nr] = cum[:, :nr]
            self.rest[c] = total - cum[:, nr - 1]
            self.total[c] = total
            self.cos_t[c] = cos_t
            self.n_r[c] = nr
            self.radius_mm[c] = r_all[nr - 1] / s
            self.long_fraction[c] = long_total / near_total
        self.dlog = float(_LOG_R[1] - _LOG_R[0])
        # f averaged over an entry's disc, for every disc radius of the grid and distance up to PATCH_RADII radii
        # (rows computed for the disc radii a bake meets: :meth:`ensure_discs`)
        self.disc = np.zeros((3, _N_COS, DISC_A[2], DISC_STEPS + 1))
        self._disc_rows = np.zeros(DISC_A[2], dtype=bool)

    def ensure_discs(self, radii) -> None:
        """Tabulate the disc averages (``disc``) for the disc radii ``radii`` (mm; their range, and the grid rows
        either side that the interpolation reads)."""
        r = np.asarray(radii, dtype=np.float64)
        r = r[r > 0.0]
        if r.size == 0:
            return
        log_a0 = math.log(DISC_A[0])
        dlog_a = math.log(DISC_A[1] / DISC_A[0]) / (DISC_A[2] - 1)
        lo = int(np.clip(math.floor((math.log(r.min()) - log_a0) / dlog_a), 0, DISC_A[2] - 1))
        hi = int(np.clip(math.floor((math.log(r.max()) - log_a0) / dlog_a) + 1, 0, DISC_A[2] - 1))
        rows = np.flatnonzero(~self._disc_rows[lo:hi + 1]) + lo
        if rows.size:
            _disc_table(self.f, self.cum, self.rest, self.n_r, self.log_r0, self.dlog, _TH_NODES, _TH_WEIGHTS,
                        PATCH_RADII, DISC_STEPS, log_a0, dlog_a, rows.astype(np.int64), self.disc)
            self._disc_rows[rows] = True

    def totals(self, cos_t):
        """(p, 3): T(theta_t) of each channel at ``cos_t`` (p,) (linear in cos theta_t, clamped to the table)."""
        c = np.asarray(cos_t, dtype=np.float64)
        return np.stack([np.interp(np.clip(c, self.cos_t[k, 0], self.cos_t[k, -1]), self.cos_t[k], self.total[k])
                         for k in range(3)], axis=-1)


def _channel(model, spread_opt, r_all):
    """(cos_t (9,), f (9, n), cum (9, n), total (9,), n_r, long total at cos 1, near total) in optical units, of
    one medium channel's :class:`~meshshade.kernels.near_field.NearFieldModel` ``model``."""
    eta, v = model.eta, model.dipole
    A = v.z_b / (2.0 * v.D)
    c_min = math.sqrt(max(0.0, 1.0 - 1.0 / (eta * eta))) if eta > 1.0 else 0.05
    cos_t = np.linspace(max(c_min, 0.05), 1.0, _N_COS)
    # the tables reach TABLE_REACH optical units (the radius where the tail holds TAIL_TOL lies within 14 for every
    # preset; a medium whose tail reaches further gets the whole table, and the rest beyond it at the entry)
    n_use = int(np.searchsorted(r_all, TABLE_REACH))
    r = r_all[:n_use]
    near = model.profile(r)
    near_cum = np.pi * r * r * model.ring(0.0 * r, r)
    near_total = model.total()
    x, wq = line_rule(model.albedo_prime)
    f = np.empty((_N_COS, r.size))
    cum = np.empty((_N_COS, r.size))
    total = np.empty(_N_COS)
    Ms, Cs, Ts = robin_smoothed_exitances(r, np.outer(cos_t, x), np.broadcast_to(wq, (cos_t.size, wq.size)),
                                          D=v.D, mu=v.mu, A=A, spread=spread_opt)
    for i, ct in enumerate(cos_t):
        gain = model.incidence_gain(float(ct))
        f[i] = gain * near - Ms[i]
        cum[i] = gain * near_cum - Cs[i]
        total[i] = gain * near_total - Ts[i]
    long_total = float(Ts[-1])
    ring = 2.0 * np.pi * r * np.abs(f).max(axis=0)
    tail = np.concatenate([np.cumsum((0.5 * (ring[1:] + ring[:-1]) * np.diff(r))[::-1])[::-1], [0.0]])
    below = tail < TAIL_TOL * near_total
    n_r = int(np.argmax(below)) + 1 if below.any() else r.size
    return cos_t, f, cum, total, n_r, long_total, near_total


@numba.njit(cache=True, inline="always")
def _lookup(tab, c, k, frac, x, log_r0, dlog, n_r, beyond_zero):
    """Linear interpolation in ln r of tab[c, k] and tab[c, k + 1] (cos weight ``frac``) at x > 0 (mm); beyond the
    table 0 (``beyond_zero``, the kernel) or its last value (the disc integral)."""
    u = (math.log(x) - log_r0) / dlog
    if u <= 0.0:
        j, w = 0, 0.0
    elif u >= n_r - 1:
        if beyond_zero:
            return 0.0
        j, w = n_r - 2, 1.0
    else:
        j = int(u)
        w = u - j
    lo = (1.0 - w) * tab[c, k, j] + w * tab[c, k, j + 1]
    hi = (1.0 - w) * tab[c, k + 1, j] + w * tab[c, k + 1, j + 1]
    return (1.0 - frac) * lo + frac * hi


def _build_tree(pos, power, normal, cos_t, leaf, area=None):
    """A tree over the entries (the Morton order of their positions split where the codes' highest differing bit
    changes: :func:`meshshade.volume.triangle_tree.prefix_tree`): ``perm``, per node its range ``lo``/``hi`` in
    perm, ``child`` (first child, -1 for a leaf; the second is child + 1), bounding ``box`` (n, 6), and the
    aggregates ``agg`` (n, 14): total power, power-weighted centroid (3) and cos theta_t, unit mean normal (3), the
    cosine of the widest angle between a member's normal and the mean (members with power or area), total area
    (``area``, mm^2, zeros when None), area-weighted centroid (3) and cos theta_t."""
    if pos.shape[0] == 0:
        return (np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64), np.full(1, -1, np.int64),
                np.zeros((1, 6)), np.zeros((1, 14)))
    perm, codes = morton_order(pos)
    lo, hi, child = prefix_tree(codes, leaf)
    box = np.zeros((lo.size, 6))
    agg = np.zeros((lo.size, 14))
    area = np.zeros(pos.shape[0]) if area is None else np.ascontiguousarray(area, dtype=np.float64)
    _aggregates(pos, power, normal, cos_t, area, perm.astype(np.int64), lo, hi, box, agg)
    return perm.astype(np.int64), lo, hi, child, box, agg


@numba.njit(cache=True, nogil=True, inline="always")
def _weighted_moments(weight, pos, cos_t, perm, a, b, agg, nd, col):
    """agg[nd, col] = the total of ``weight`` over members perm[a:b], agg[nd, col + 1: col + 5] their weighted
    centroid (3) and cos theta_t (left 0 where the total is 0)."""
    tot = cx = cy = cz = cc = 0.0
    for t in range(a, b):
        j = perm[t]
        w = weight[j]
        tot += w
        cx += w * pos[j, 0]
        cy += w * pos[j, 1]
        cz += w * pos[j, 2]
        cc += w * cos_t[j]
    agg[nd, col] = tot
    if tot > 0.0:
        agg[nd, col + 1], agg[nd, col + 2], agg[nd, col + 3], agg[nd, col + 4] = cx / tot, cy / tot, cz / tot, cc / tot


@numba.njit(cache=True, nogil=True)
def _aggregates(pos, power, normal, cos_t, area, perm, lo, hi, box, agg):
    """Each node's box and aggregates (:func:`_build_tree`) over its members perm[lo:hi]."""
    n_nodes = lo.size
    for nd in range(n_nodes):
        for d in range(3):
            box[nd, d] = np.inf
            box[nd, 3 + d] = -np.inf
        for t in range(lo[nd], hi[nd]):
            j = perm[t]
            for d in range(3):
                box[nd, d] = min(box[nd, d], pos[j, d])
                box[nd, 3 + d] = max(box[nd, 3 + d], pos[j, d])
    for nd in range(n_nodes):
        _weighted_moments(power, pos, cos_t, perm, lo[nd], hi[nd], agg, nd, 0)     # power: columns 0-4
        _weighted_moments(area, pos, cos_t, perm, lo[nd], hi[nd], agg, nd, 9)      # area: columns 9-13
        nx = ny = nz = 0.0
        for t in range(lo[nd], hi[nd]):
            j = perm[t]
            w = power[j] + area[j]
            nx += w * normal[j, 0]
            ny += w * normal[j, 1]
            nz += w * normal[j, 2]
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            agg[nd, 5], agg[nd, 6], agg[nd, 7] = nx / ln, ny / ln, nz / ln
        worst = 1.0
        for t in range(lo[nd], hi[nd]):
            j = perm[t]
            if power[j] > 0.0 or area[j] > 0.0:
                worst = min(worst, normal[j, 0] * agg[nd, 5] + normal[j, 1] * agg[nd, 6] + normal[j, 2] * agg[nd, 7])
        agg[nd, 8] = worst


#: the disc averages are tabulated for d / a from 0 to PATCH_RADII in DISC_STEPS steps, and for disc radii from
#: DISC_A[0] to DISC_A[1] mm at DISC_A[2] log-spaced values (a disc outside the range takes its end's value)
DISC_STEPS = 40
DISC_A = (1e-3, 30.0, 96)


@numba.njit(cache=True)
def _disc_average(f, cum, rest, c, k, frac, d, a, log_r0, dlog, nr, th_x, th_w):
    """f of channel c (cos bin k, weight frac) averaged over the disc of radius a centred at distance d: full
    circles up to a - d from the disc integral (with the energy beyond the radius when d < a), arcs from |d - a| to
    d + a by Gauss-Legendre in theta."""
    acc = 0.0
    if d < a:
        acc = _lookup(cum, c, k, frac, a - d, log_r0, dlog, nr, False)
        acc += (1.0 - frac) * rest[c, k] + frac * rest[c, k + 1]
    lo, hi = abs(d - a), d + a
    if d > 0.0:
        for q in range(th_x.size):
            th = 0.5 * math.pi * (th_x[q] + 1.0)
            rho = lo + 0.5 * (hi - lo) * (1.0 - math.cos(th))
            if rho <= 0.0:
                continue
            cang = (rho * rho + d * d - a * a) / (2.0 * rho * d)
            cang = min(1.0, max(-1.0, cang))
            wgt = 2.0 * rho * math.acos(cang) * 0.5 * (hi - lo) * math.sin(th) * 0.5 * math.pi * th_w[q]
            acc += wgt * _lookup(f, c, k, 0.0 if frac == 0.0 else frac, rho, log_r0, dlog, nr, True)
    return acc / (math.pi * a * a)


@numba.njit(cache=True)
def _disc_table(f, cum, rest, n_r, log_r0, dlog, th_x, th_w, patch_radii, steps, log_a0, dlog_a, rows, out):
    """out[c, k, i, j] for the radius rows i in ``rows``: f (channel c, cos node k) averaged over a disc of radius
    a_i = exp(log_a0 + i dlog_a) mm at distance j / steps * patch_radii * a_i."""
    for c in range(out.shape[0]):
        for k in range(out.shape[1]):
            kk = min(k, out.shape[1] - 2)
            fr = 0.0 if k < out.shape[1] - 1 else 1.0
            for i in rows:
                a = math.exp(log_a0 + i * dlog_a)
                for j in range(steps + 1):
                    d = j * patch_radii * a / steps
                    out[c, k, i, j] = _disc_average(f, cum, rest, c, kk, fr, d, a, log_r0[c], dlog, n_r[c],
                                                    th_x, th_w)


@numba.njit(cache=True, inline="always")
def _pair_cell(d, a, patch_radii, log_a0, dlog_a, na, steps):
    """Where a pair at distance d from an entry of disc radius a reads the tables: (disc, i, wi, j, wj, ld), the
    disc table's cell in ln a (i, wi of ``na`` radii) and d / a (j, wj of ``steps``) when d < patch_radii a, else
    ln d (``ld``)."""
    i, wi, j, wj, ld = 0, 0.0, 0, 0.0, 0.0
    disc = a > 0.0 and d < patch_radii * a
    if disc:
        u = (math.log(a) - log_a0) / dlog_a
        if u >= na - 1:
            i, wi = na - 2, 1.0
        elif u > 0.0:
            i = int(u)
            wi = u - i
        v = d / (patch_radii * a) * steps
        j = min(int(v), steps - 1)
        wj = v - j
    else:
        ld = math.log(max(d, 1e-300))
    return disc, i, wi, j, wj, ld


@numba.njit(cache=True, inline="always")
def _kernel3(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, rec_node, rec_blend,
             r):
    """f of the three channels at distance d for an entry of cos theta_t, averaged over a disc of radius a when
    d < PATCH_RADII a (interpolated in the disc table: ln a, d / a and cos theta_t); the logarithms and the disc
    table's cell are shared by the channels. One table (``rec_node``, ``rec_blend`` and ``r`` are not read:
    :func:`_pair_kernel`)."""
    k0 = k1 = k2 = 0.0
    if d <= 0.0 and a <= 0.0:
        return k0, k1, k2
    disc, i, wi, j, wj, ld = _pair_cell(d, a, patch_radii, log_a0, dlog_a, dtab.shape[2], dtab.shape[3] - 1)
    for c in range(3):
        if d > radius[c]:
            continue
        g = cosg[c]
        ct = min(max(cos_t, g[0]), g[g.size - 1])
        k = min(int((ct - g[0]) / (g[1] - g[0])), g.size - 2)
        frac = (ct - g[k]) / (g[k + 1] - g[k])
        val = 0.0
        if disc:
            for kk, wk in ((k, 1.0 - frac), (k + 1, frac)):
                lo = (1.0 - wj) * dtab[c, kk, i, j] + wj * dtab[c, kk, i, j + 1]
                hi = (1.0 - wj) * dtab[c, kk, i + 1, j] + wj * dtab[c, kk, i + 1, j + 1]
                val += wk * ((1.0 - wi) * lo + wi * hi)
        else:
            u = (ld - log_r0[c]) / dlog
            if u >= n_r[c] - 1:
                continue
            jj, w = 0, 0.0
            if u > 0.0:
                jj = int(u)
                w = u - jj
            lo = (1.0 - w) * f[c, k, jj] + w * f[c, k, jj + 1]
            hi = (1.0 - w) * f[c, k + 1, jj] + w * f[c, k + 1, jj + 1]
            val = (1.0 - frac) * lo + frac * hi
        if c == 0:
            k0 = val
        elif c == 1:
            k1 = val
        else:
            k2 = val
    return k0, k1, k2


@numba.njit(cache=True, inline="always")
def _kernel3_blend(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, rec_node,
                   rec_blend, r):
    """:func:`_kernel3` over several tables (their arrays with a leading table axis): channel c of receiver r
    reads the tables rec_node[r, c, q] with the weights rec_blend[r, c, q] (a painted receiver's albedo, and mean
    free path, between tabulated ones, eqs. (108), (133)); the logarithms and the disc table's cell are shared by
    the channels and the tables."""
    k0 = k1 = k2 = 0.0
    if d <= 0.0 and a <= 0.0:
        return k0, k1, k2
    disc, i, wi, j, wj, ld = _pair_cell(d, a, patch_radii, log_a0, dlog_a, dtab.shape[3], dtab.shape[4] - 1)
    for c in range(3):
        val = 0.0
        for q in range(rec_node.shape[2]):
            t = rec_node[r, c, q]
            wq = rec_blend[r, c, q]
            if wq == 0.0 or d > radius[t, c]:
                continue
            g = cosg[t, c]
            ct = min(max(cos_t, g[0]), g[g.size - 1])
            k = min(int((ct - g[0]) / (g[1] - g[0])), g.size - 2)
            frac = (ct - g[k]) / (g[k + 1] - g[k])
            if disc:
                for kk, wk in ((k, 1.0 - frac), (k + 1, frac)):
                    lo = (1.0 - wj) * dtab[t, c, kk, i, j] + wj * dtab[t, c, kk, i, j + 1]
                    hi = (1.0 - wj) * dtab[t, c, kk, i + 1, j] + wj * dtab[t, c, kk, i + 1, j + 1]
                    val += wq * wk * ((1.0 - wi) * lo + wi * hi)
            else:
                u = (ld - log_r0[t, c]) / dlog
                if u >= n_r[t, c] - 1:
                    continue
                jj, w = 0, 0.0
                if u > 0.0:
                    jj = int(u)
                    w = u - jj
                lo = (1.0 - w) * f[t, c, k, jj] + w * f[t, c, k, jj + 1]
                hi = (1.0 - w) * f[t, c, k + 1, jj] + w * f[t, c, k + 1, jj + 1]
                val += wq * ((1.0 - frac) * lo + frac * hi)
        if c == 0:
            k0 = val
        elif c == 1:
            k1 = val
        else:
            k2 = val
    return k0, k1, k2


def _pair_kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, rec_node,
                 rec_blend, r):
    """f of the three channels for one pair: :func:`_kernel3` when ``rec_node`` is None (one table), else
    :func:`_kernel3_blend`. In compiled code the choice is made by the argument's type (the overload below), so
    :func:`_traverse` compiles as two specialisations, each with only its own kernel inlined (one loop holding both
    ran the one-table sum 30 % slower)."""
    kernel = _kernel3 if rec_node is None else _kernel3_blend
    return kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, rec_node,
                  rec_blend, r)


@overload(_pair_kernel, inline="always")
def _pair_kernel_typed(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, rec_node,
                       rec_blend, r):
    return (_kernel3 if isinstance(rec_node, types.NoneType) else _kernel3_blend).py_func


def _entry_kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, src_node,
                  src_blend, j, v0, v1, v2):
    """f of the pair in the entry's medium (:func:`_kernel3_blend` with the entry's tables ``src_node[j]`` and
    weights ``src_blend[j]``), or the receiver's values (v0, v1, v2) when ``src_node`` is None (one medium, or the
    receiver's kernel for the whole pair): chosen by type in compiled code (the overload below)."""
    if src_node is None:
        return v0, v1, v2
    return _kernel3_blend(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a,
                          src_node, src_blend, j)


@numba.njit(cache=True, inline="always")
def _receiver_values(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, src_node,
                     src_blend, j, v0, v1, v2):
    """:func:`_entry_kernel` without the entries' media: the receiver's values."""
    return v0, v1, v2


@overload(_entry_kernel, inline="always")
def _entry_kernel_typed(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a, src_node,
                        src_blend, j, v0, v1, v2):
    return _receiver_values.py_func if isinstance(src_node, types.NoneType) else _entry_kernel


def _same_medium(src_node, src_blend, j, rec_node, rec_blend, r):
    """Whether entry j reads the same tables with the same weights as receiver r in every channel (then the pair's
    two kernels are one); True without the entries' media (``src_node`` None): chosen by type (the overload)."""
    if src_node is None:
        return True
    return _same_corners(src_node, src_blend, j, rec_node, rec_blend, r)


@numba.njit(cache=True, inline="always")
def _same_corners(src_node, src_blend, j, rec_node, rec_blend, r):
    """:func:`_same_medium` for the entries' arrays."""
    if src_node.shape[2] != rec_node.shape[2]:
        return False
    for c in range(3):
        for q in range(src_node.shape[2]):
            if src_node[j, c, q] != rec_node[r, c, q] or src_blend[j, c, q] != rec_blend[r, c, q]:
                return False
    return True


@numba.njit(cache=True, inline="always")
def _always_same(src_node, src_blend, j, rec_node, rec_blend, r):
    """:func:`_same_medium` without the entries' media."""
    return True


@overload(_same_medium, inline="always")
def _same_medium_typed(src_node, src_blend, j, rec_node, rec_blend, r):
    return (_always_same if isinstance(src_node, types.NoneType) else _same_corners).py_func


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _traverse(rec_pos, rec_n, rec_a, rec_E, perm, lo, hi, child, box, agg, src_pos, src_n, src_p, src_area, src_a,
              src_cos, src_light, f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a,
              rec_near, rec_node, rec_blend, src_node, src_blend, theta, out, counts, r_lo, r_hi):
    """Receivers r_lo:r_hi: eq. (103)'s pair sum over the entries, every pair with its weight P_j - E_l(x) A_j.
    Entries within ``rec_near[r]`` of receiver r one by one; beyond, nodes whose extent over distance is below
    ``theta`` (and whose normals agree) as one entry of their total power at their power centroid less the
    receiver's irradiance times their area at their area centroid (one light: a receiver of several lights opens
    the nodes), the rest one by one. Receiver r reads the tables rec_node[r] blended by rec_blend[r]
    (:func:`_kernel3_blend`, the tables' arrays with a leading axis); ``rec_node`` None: one table
    (:func:`_kernel3`), chosen by type (:func:`_pair_kernel`). With ``src_node`` / ``src_blend`` (the entries'
    tables and weights, eq. (134)) a pair summed one by one weighs the entry's power by f in the entry's medium and
    the subtraction E A_j by the receiver's (:func:`_entry_kernel`); the tree's far nodes take the receiver's for
    both (their entries' power-weighted tables made spot's dark patches brighter still: physics eq. (134))."""
    rmax = 0.0
    for v in radius.ravel():
        rmax = max(rmax, v)
    stack = np.zeros(256, np.int64)
    for r in range(r_lo, r_hi):
        x0, x1, x2 = rec_pos[r, 0], rec_pos[r, 1], rec_pos[r, 2]
        near = rec_near[r]
        a0 = a1 = a2 = 0.0
        n_pairs = 0
        unlit = True
        for l in range(rec_E.shape[1]):
            if rec_E[r, l] != 0.0:
                unlit = False
        one_light = rec_E.shape[1] == 1
        e0 = rec_E[r, 0]
        top = 1
        stack[0] = 0
        while top > 0:
            top -= 1
            nd = stack[top]
            # nearest and farthest distance from the receiver to the node's box
            dx = max(box[nd, 0] - x0, 0.0, x0 - box[nd, 3])
            dy = max(box[nd, 1] - x1, 0.0, x1 - box[nd, 4])
            dz = max(box[nd, 2] - x2, 0.0, x2 - box[nd, 5])
            dmin = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dmin > rmax:
                continue
            sub_w = 0.0 if unlit else e0 * agg[nd, 9]           # the subtraction's weight (one light)
            if agg[nd, 0] <= 0.0 and sub_w == 0.0 and (unlit or one_light):
                continue                       # no power below, and no subtraction term (weights all 0)
            if (child[nd] >= 0 and dmin >= near and (agg[nd, 0] > 0.0 or sub_w > 0.0) and agg[nd, 8] > 0.9
                    and (unlit or one_light)):
                ex = max(box[nd, 3] - box[nd, 0], box[nd, 4] - box[nd, 1], box[nd, 5] - box[nd, 2])
                dc, da = math.inf, math.inf
                if agg[nd, 0] > 0.0:
                    cx, cy, cz = agg[nd, 1] - x0, agg[nd, 2] - x1, agg[nd, 3] - x2
                    dc = math.sqrt(cx * cx + cy * cy + cz * cz)
                if sub_w > 0.0:
                    cx, cy, cz = agg[nd, 10] - x0, agg[nd, 11] - x1, agg[nd, 12] - x2
                    da = math.sqrt(cx * cx + cy * cy + cz * cz)
                if ex < theta * min(dc, da):
                    if agg[nd, 5] * rec_n[r, 0] + agg[nd, 6] * rec_n[r, 1] + agg[nd, 7] * rec_n[r, 2] > 0.0:
                        if agg[nd, 0] > 0.0:
                            v0, v1, v2 = _pair_kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0,
                                                      dlog_a, agg[nd, 4], dc, 0.0, rec_node, rec_blend, r)
                            a0 += agg[nd, 0] * v0
                            a1 += agg[nd, 0] * v1
                            a2 += agg[nd, 0] * v2
                        if sub_w > 0.0:
                            v0, v1, v2 = _pair_kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0,
                                                      dlog_a, agg[nd, 13], da, 0.0, rec_node, rec_blend, r)
                            a0 -= sub_w * v0
                            a1 -= sub_w * v1
                            a2 -= sub_w * v2
                        n_pairs += 1
                    continue
            if child[nd] >= 0:
                stack[top] = child[nd]
                stack[top + 1] = child[nd] + 1
                top += 2
                continue
            for t in range(lo[nd], hi[nd]):
                j = perm[t]
                if src_n[j, 0] * rec_n[r, 0] + src_n[j, 1] * rec_n[r, 1] + src_n[j, 2] * rec_n[r, 2] <= 0.0:
                    continue
                qx, qy, qz = src_pos[j, 0] - x0, src_pos[j, 1] - x1, src_pos[j, 2] - x2
                d = math.sqrt(qx * qx + qy * qy + qz * qz)
                if d > rmax:
                    continue
                sub = rec_E[r, src_light[j]] * src_area[j]
                w = src_p[j] - sub
                same = _same_medium(src_node, src_blend, j, rec_node, rec_blend, r)
                if w == 0.0 and (same or sub == 0.0):
                    continue
                a = src_a[j] if src_a[j] > 0.0 else rec_a[r]
                v0, v1, v2 = _pair_kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a,
                                          src_cos[j], d, a, rec_node, rec_blend, r)
                if same:
                    a0 += w * v0
                    a1 += w * v1
                    a2 += w * v2
                else:              # the entry's power in its own medium, the subtraction in the receiver's
                    u0, u1, u2 = _entry_kernel(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a,
                                               src_cos[j], d, a, src_node, src_blend, j, v0, v1, v2)
                    a0 += src_p[j] * u0 - sub * v0
                    a1 += src_p[j] * u1 - sub * v1
                    a2 += src_p[j] * u2 - sub * v2
                n_pairs += 1
        out[r, 0] += a0
        out[r, 1] += a1
        out[r, 2] += a2
        counts[r] = n_pairs


#: the zone of pairs summed one by one reaches at most this many mm from each receiver
NEAR_MM = 2.5
#: entries within this many of a receiver's longest edges (at most NEAR_MM) are summed one by one (beyond: the
#: tree's nodes); a fixed radius would hold pairs growing as the square of a fine mesh's density (566k vertices:
#: 310M pairs in 2.5 mm). The sun-lit ball's lit error against its exact series at 10k / 41k / 164k vertices: 1.69 /
#: 1.75 / 1.62 % (2.5 mm everywhere: 1.65 / 1.73 / 1.82 %; measured with the subtraction within this zone only)
NEAR_SPACINGS = 3.0
#: the one-by-one zone reaches at most this many mean sampling spacings
MID_SPACINGS = 6.0
#: beyond the one-by-one zone, a node of the entries' tree whose extent is below THETA times its distance counts as
#: one entry
THETA = 0.3
#: entries per leaf of the tree
LEAF = 4


def _arg(a, dtype=np.float64):
    """``a`` as a C-contiguous, writeable array of ``dtype`` (a copy only where it is not one): every call of the
    compiled loops then has one signature (a read-only receiver array, such as the sampling surface's vertices,
    made numba compile :func:`_traverse` a second time on the first run, 3 s; issue 48)."""
    return np.require(a, dtype=dtype, requirements=("C", "W"))


def _corners(blend, n, n_tables):
    """(tables (n, 3, Q) int64, weights (n, 3, Q)) of a blend given as corners or as a node and the next (n, 3), a
    ValueError naming the form for any other shape or a table past the last."""
    node, weight = np.asarray(blend[0], dtype=np.int64), np.asarray(blend[1], dtype=np.float64)
    if node.ndim == 2:
        if node.shape != (n, 3) or weight.shape != (n, 3):
            raise ValueError("blend: node (n, 3) in 0..len(tables) - 2 and weight (n, 3)")
        node, weight = np.stack([node, node + 1], axis=2), np.stack([1.0 - weight, weight], axis=2)
    if node.shape[:2] != (n, 3) or weight.shape != node.shape or node.min(initial=0) < 0 or \
            node.max(initial=0) > n_tables - 1:
        raise ValueError("blend: tables (n, 3, Q) in 0..len(tables) - 1 and weights of the same shape")
    return node, weight


def _stacked(tables):
    """The tables' arrays with a leading axis over ``tables`` (the kernels' reach padded to the longest)."""
    n = max(tb.f.shape[2] for tb in tables)
    f = np.zeros((len(tables), 3, _N_COS, n))
    for k, tb in enumerate(tables):
        f[k, :, :, :tb.f.shape[2]] = tb.f
    return (f, *(np.stack([getattr(tb, a) for tb in tables]) for a in ("disc", "cos_t", "n_r", "log_r0", "radius_mm")))


def remainder_exitance(tables, src, rec, *, near_mm: float = NEAR_MM, theta: float = THETA,
                       spacing_mm: float | None = None, blend=None, src_blend=None):
    """Eq. (103) at the receivers: ((n, 3) W/mm^2, pair evaluations).

    ``tables``: a :class:`RemainderTables`, or a sequence of them with ``blend`` = (node (n, 3) int, weight (n, 3)):
    receiver r's channel c then takes (1 - w) f_node + w f_node+1 (a painted medium's receiver albedo between two
    tabulated ones, eq. (108)), every pair evaluated with both in one pass over the entries (the same sums as one
    pass per table interpolated afterwards, to rounding, at the cost of one pass). Or ``blend`` = (tables (n, 3, Q)
    int, weights (n, 3, Q)): channel c of receiver r takes sum_q w_q f_{t_q} (a bilinear blend over albedo and
    mean free path, eq. (133)). ``src_blend`` = (tables (k, 3, Q), weights (k, 3, Q)) of the entries, with
    ``blend``: each pair summed one by one then weighs the entry's power by f in the entry's medium and only the
    subtraction E A_j by the receiver's (eq. (134)); None: the receiver's for both (eq. (108)).

    ``src``: dict of entry arrays ``pos`` (k, 3) mm, ``normal`` (k, 3), ``power`` (k,) W, ``area`` (k,) mm^2
    (0 for point entries), ``cos_t`` (k,), ``light`` (k,) int. ``rec``: ``pos`` (n, 3), ``normal`` (n, 3),
    ``radius`` (n,) mm (the receiver's patch, for point entries), ``E`` (n, L) W/mm^2 and ``cos_t`` (n, L): the
    irradiance of each light at the receiver and the cosine its light travels inside at there; optionally
    ``spacing`` (n,) mm, the receiver's longest edge.

    Every pair within the table's reach carries the subtraction (weight P_j - E_l(x) A_j) and the receiver gets
    E_l(x) T analytically, so a uniformly lit receiver gets exactly E T whatever the sampling (physics §15.4: the
    subtraction within 2.5 mm only left marble's long f to the sampled sum, 9-14 % low on a flat face). Entries
    within ``near_mm`` (with ``spacing_mm``, the entries' mean spacing: NEAR_SPACINGS times the receiver's own
    spacing where that is less, and never more than MID_SPACINGS mean spacings) are summed one by one; beyond, the
    entries' tree is opened until a node's extent is below ``theta`` times its distance (Barnes-Hut: a node's power
    at its power centroid less E(x) times its area at its area centroid), so the cost per receiver grows with the
    log of the radius over the spacing, not with its square. Every receiver is summed itself: an earlier pass that
    evaluated the part beyond a reach at one receiver per cube and interpolated it split the pairs at the reach
    differently for the receiver and the cube's (up to 22 % off at single samples of the 141k head, and a 5e-8
    change of scale moved a vertex by 13 %); made consistent, it cost what this does."""
    n = rec["pos"].shape[0]
    ra = _arg(rec["radius"])
    if spacing_mm is None:
        sub = np.full(n, float(near_mm))
    else:
        mid_mm = min(float(near_mm), MID_SPACINGS * float(spacing_mm))
        # the receiver's own spacing: its longest edge where given, else that of a regular triangulation whose
        # vertices' patches have its area pi a^2 (edge sqrt(2 pi / sqrt 3) a)
        own = rec["spacing"] if "spacing" in rec else math.sqrt(2.0 * math.pi / math.sqrt(3.0)) * ra
        sub = np.clip(NEAR_SPACINGS * np.asarray(own, dtype=np.float64), 1e-3 * mid_mm, mid_mm)
    tables = [tables] if isinstance(tables, RemainderTables) else list(tables)
    if blend is None:
        if len(tables) != 1:
            raise ValueError("several tables need the receivers' blend (node, weight)")
        node = weight = None
    elif len(tables) == 1:          # one table: every weight on it, the one-table sum (checked all the same)
        t, w = _corners(blend, n, 2 if np.ndim(blend[0]) == 2 else 1)
        if np.any(w[t > 0] != 0.0):
            raise ValueError("blend: with one table every weight is on it (node 0, weight 0)")
        node = weight = None
    else:
        node, weight = (_arg(x, x.dtype) for x in _corners(blend, n, len(tables)))
    src_node = src_weight = None
    if src_blend is not None and node is not None:
        src_node, src_weight = (_arg(x, x.dtype) for x in _corners(src_blend, src["pos"].shape[0], len(tables)))
    out = np.zeros((n, 3))
    E, rc = _arg(rec["E"]), np.asarray(rec["cos_t"], dtype=np.float64)
    for l in range(E.shape[1]):
        lit = E[:, l] > 0
        if lit.any():          # every pair within the table carries the subtraction: the receiver gets E T
            if node is None:
                T = tables[0].totals(rc[lit, l])
            else:
                Tk = np.stack([tb.totals(rc[lit, l]) for tb in tables])            # (K, p, 3)
                nl, wl, rows = node[lit], weight[lit], np.arange(int(lit.sum()))[:, None]
                T = np.stack([np.sum(wl[:, c] * Tk[nl[:, c], rows, c], axis=1) for c in range(3)], axis=1)
            out[lit] += E[lit, l, None] * T
    k = src["pos"].shape[0]
    if k == 0:
        return out, 0
    pos = _arg(src["pos"])
    nrm = _arg(src["normal"])
    pw = _arg(src["power"])
    cos_s = _arg(src["cos_t"])
    area = _arg(src["area"])
    perm, lo, hi, child, box, agg = _build_tree(pos, pw, nrm, cos_s, LEAF, area)
    disc = np.sqrt(np.maximum(area, 0.0) / math.pi)
    for tb in tables:
        tb.ensure_discs(np.concatenate([disc, ra]))
    light = _arg(src["light"], np.int64)
    if node is None:          # one table: its own arrays (the one-table specialisation of _traverse)
        tb = tables[0]
        f, dtab, cosg, n_r, log_r0, radius = tb.f, tb.disc, tb.cos_t, tb.n_r, tb.log_r0, tb.radius_mm
    else:
        f, dtab, cosg, n_r, log_r0, radius = (_arg(x, x.dtype) for x in _stacked(tables))
    tabs = (f, dtab, cosg, n_r, log_r0, tables[0].dlog, radius,
            PATCH_RADII, math.log(DISC_A[0]), math.log(DISC_A[1] / DISC_A[0]) / (DISC_A[2] - 1))
    rp = _arg(rec["pos"])
    rn = _arg(rec["normal"])
    counts = np.zeros(n, dtype=np.int64)
    sub = _arg(sub)
    args = (rp, rn, ra, E, perm, lo, hi, child, box, agg, pos, nrm, pw, area, disc, cos_s, light, *tabs, sub, node,
            weight, src_node, src_weight, float(theta), out, counts)
    with warnings.catch_warnings():
        # compiled (or loaded) here, on this thread, before the workers run it: inlining the overload of
        # _pair_kernel trips numba's pedantic SSA check (NumbaIRAssumptionWarning, "variable ... is not in
        # scope"), a warning about numba's own IR; the code is the plain kernels' (the tests: bit for bit)
        warnings.simplefilter("ignore", NumbaIRAssumptionWarning)
        _traverse(*args, 0, 0)
    run_in_blocks(lambda a, b: _traverse(*args, a, b), n)
    return out, int(counts.sum())


@numba.njit(cache=True, nogil=True)
def _longest_edges(V, F, out):
    """out[v] = the longest edge at vertex v of the triangles F over V (0 for a vertex of no face)."""
    for f in range(F.shape[0]):
        for k in range(3):
            a, b = F[f, k], F[f, (k + 1) % 3]
            d = math.sqrt((V[a, 0] - V[b, 0]) ** 2 + (V[a, 1] - V[b, 1]) ** 2 + (V[a, 2] - V[b, 2]) ** 2)
            out[a] = max(out[a], d)
            out[b] = max(out[b], d)


def longest_edges(vertices, faces) -> np.ndarray:
    """(n,) mm: each vertex's longest edge (the spacing of the entries around a receiver, eq. (103))."""
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    out = np.zeros(V.shape[0])
    _longest_edges(V, np.ascontiguousarray(faces, dtype=np.int64), out)
    return out
