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

import numba
import numpy as np
from scipy.spatial import cKDTree

from meshshade.kernels.robin_halfspace import robin_smoothed_exitances
from meshshade.pacing import run_in_blocks
from meshshade.volume.long_range import line_rule

__all__ = ["RemainderTables", "TAIL_TOL", "PATCH_RADII", "remainder_exitance"]

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
        self.disc = np.zeros((3, _N_COS, DISC_A[2], DISC_STEPS + 1))
        _disc_table(self.f, self.cum, self.rest, self.n_r, self.log_r0, self.dlog, _TH_NODES, _TH_WEIGHTS,
                    PATCH_RADII, DISC_STEPS, math.log(DISC_A[0]), math.log(DISC_A[1] / DISC_A[0]) / (DISC_A[2] - 1),
                    self.disc)

    def near_and_beyond(self, cos_t, near_mm: float):
        """(p, 3): int_0^near f plus the energy beyond the radius, per channel, at ``cos_t`` (p,): what a receiver
        of irradiance 1 gets from its own neighbourhood and the far tail in eq. (103)."""
        c = np.asarray(cos_t, dtype=np.float64)
        out = np.empty((c.size, 3))
        for k in range(3):
            u = (math.log(near_mm) - self.log_r0[k]) / self.dlog
            j = int(min(max(u, 0.0), self.n_r[k] - 1.0001))
            w = min(max(u - j, 0.0), 1.0)
            at = (1 - w) * self.cum[k, :, j] + w * self.cum[k, :, min(j + 1, self.n_r[k] - 1)]
            val = at + self.rest[k]
            out[:, k] = np.interp(np.clip(c, self.cos_t[k, 0], self.cos_t[k, -1]), self.cos_t[k], val)
        return out

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


@numba.njit(cache=True)
def _build_tree(pos, power, normal, cos_t, leaf):
    """A k-d tree over the entries (median splits on the widest axis): ``perm``, per node its range ``lo``/``hi``
    in perm, ``child`` (first child, -1 for a leaf; the second is child + 1), bounding ``box`` (n, 6), and the
    power-weighted aggregates ``agg`` (n, 9): total power, centroid (3), cos theta_t, unit mean normal (3), the
    cosine of the widest angle between a member's normal and the mean."""
    k = pos.shape[0]
    cap = 2 * (k // max(1, leaf) + 1) * 2 + 1
    perm = np.arange(k)
    lo = np.zeros(cap, np.int64)
    hi = np.zeros(cap, np.int64)
    child = np.full(cap, -1, np.int64)
    box = np.zeros((cap, 6))
    agg = np.zeros((cap, 9))
    n_nodes = 1
    lo[0], hi[0] = 0, k
    stack = np.zeros(128, np.int64)
    top = 1
    stack[0] = 0
    while top > 0:
        top -= 1
        nd = stack[top]
        a, b = lo[nd], hi[nd]
        for d in range(3):
            box[nd, d] = np.inf
            box[nd, 3 + d] = -np.inf
        for t in range(a, b):
            j = perm[t]
            for d in range(3):
                box[nd, d] = min(box[nd, d], pos[j, d])
                box[nd, 3 + d] = max(box[nd, 3 + d], pos[j, d])
        if b - a <= leaf:
            continue
        ext = np.array([box[nd, 3] - box[nd, 0], box[nd, 4] - box[nd, 1], box[nd, 5] - box[nd, 2]])
        ax = int(np.argmax(ext))
        seg = perm[a:b].copy()
        order = np.argsort(pos[seg, ax])
        perm[a:b] = seg[order]
        mid = (a + b) // 2
        c0 = n_nodes
        n_nodes += 2
        child[nd] = c0
        lo[c0], hi[c0] = a, mid
        lo[c0 + 1], hi[c0 + 1] = mid, b
        stack[top] = c0
        stack[top + 1] = c0 + 1
        top += 2
    for nd in range(n_nodes):
        tot = 0.0
        cx = cy = cz = cc = nx = ny = nz = 0.0
        for t in range(lo[nd], hi[nd]):
            j = perm[t]
            w = power[j]
            tot += w
            cx += w * pos[j, 0]
            cy += w * pos[j, 1]
            cz += w * pos[j, 2]
            cc += w * cos_t[j]
            nx += w * normal[j, 0]
            ny += w * normal[j, 1]
            nz += w * normal[j, 2]
        agg[nd, 0] = tot
        if tot > 0.0:
            agg[nd, 1], agg[nd, 2], agg[nd, 3], agg[nd, 4] = cx / tot, cy / tot, cz / tot, cc / tot
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            agg[nd, 5], agg[nd, 6], agg[nd, 7] = nx / ln, ny / ln, nz / ln
        worst = 1.0
        for t in range(lo[nd], hi[nd]):
            j = perm[t]
            if power[j] > 0.0:
                worst = min(worst, normal[j, 0] * agg[nd, 5] + normal[j, 1] * agg[nd, 6] + normal[j, 2] * agg[nd, 7])
        agg[nd, 8] = worst
    return perm, lo[:n_nodes], hi[:n_nodes], child[:n_nodes], box[:n_nodes], agg[:n_nodes]


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
def _disc_table(f, cum, rest, n_r, log_r0, dlog, th_x, th_w, patch_radii, steps, log_a0, dlog_a, out):
    """out[c, k, i, j]: f (channel c, cos node k) averaged over a disc of radius a_i = exp(log_a0 + i dlog_a) mm
    at distance j / steps * patch_radii * a_i."""
    for c in range(out.shape[0]):
        for k in range(out.shape[1]):
            kk = min(k, out.shape[1] - 2)
            fr = 0.0 if k < out.shape[1] - 1 else 1.0
            for i in range(out.shape[2]):
                a = math.exp(log_a0 + i * dlog_a)
                for j in range(steps + 1):
                    d = j * patch_radii * a / steps
                    out[c, k, i, j] = _disc_average(f, cum, rest, c, kk, fr, d, a, log_r0[c], dlog, n_r[c],
                                                    th_x, th_w)


@numba.njit(cache=True, inline="always")
def _kernel3(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a, cos_t, d, a):
    """f of the three channels at distance d for an entry of cos theta_t, averaged over a disc of radius a when
    d < PATCH_RADII a (interpolated in the disc table: ln a, d / a and cos theta_t); the logarithms and the disc
    table's cell are shared by the channels."""
    k0 = k1 = k2 = 0.0
    if d <= 0.0 and a <= 0.0:
        return k0, k1, k2
    disc = a > 0.0 and d < patch_radii * a
    i, wi, j, wj, ld = 0, 0.0, 0, 0.0, 0.0
    if disc:
        u = (math.log(a) - log_a0) / dlog_a
        na = dtab.shape[2]
        if u >= na - 1:
            i, wi = na - 2, 1.0
        elif u > 0.0:
            i = int(u)
            wi = u - i
        steps = dtab.shape[3] - 1
        v = d / (patch_radii * a) * steps
        j = min(int(v), steps - 1)
        wj = v - j
    else:
        ld = math.log(max(d, 1e-300))
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _traverse(rec_pos, rec_n, rec_a, rec_E, perm, lo, hi, child, box, agg, src_pos, src_n, src_p, src_area, src_a,
              src_cos, src_light, f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a,
              near, theta, mode, out, counts, r_lo, r_hi):
    """Receivers r_lo:r_hi: eq. (103)'s pair sum (``mode`` 0: the entries within ``near`` only, 1: those beyond
    only, 2: all). Entries within ``near`` of the receiver one by one, their weight
    P_j - E_l(x) A_j; beyond, nodes whose extent over distance is below ``theta`` (and whose normals agree) as
    one entry of their total power at their centroid; the rest one by one without the subtraction."""
    rmax = 0.0
    for c in range(3):
        rmax = max(rmax, radius[c])
    stack = np.zeros(256, np.int64)
    for r in range(r_lo, r_hi):
        x0, x1, x2 = rec_pos[r, 0], rec_pos[r, 1], rec_pos[r, 2]
        a0 = a1 = a2 = 0.0
        n_pairs = 0
        top = 1
        stack[0] = 0
        while top > 0:
            top -= 1
            nd = stack[top]
            if agg[nd, 0] <= 0.0 and True:
                # no power below this node: only its subtraction terms could matter, and they are near ones
                pass
            # distance from the receiver to the node's box
            dx = max(box[nd, 0] - x0, 0.0, x0 - box[nd, 3])
            dy = max(box[nd, 1] - x1, 0.0, x1 - box[nd, 4])
            dz = max(box[nd, 2] - x2, 0.0, x2 - box[nd, 5])
            dmin = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dmin > rmax or (mode == 0 and dmin >= near):
                continue
            if mode == 1:
                # far only: a node wholly within ``near`` holds nothing for this pass
                fx = max(abs(box[nd, 0] - x0), abs(box[nd, 3] - x0))
                fy = max(abs(box[nd, 1] - x1), abs(box[nd, 4] - x1))
                fz = max(abs(box[nd, 2] - x2), abs(box[nd, 5] - x2))
                if fx * fx + fy * fy + fz * fz < near * near:
                    continue
            if mode != 0 and child[nd] >= 0 and dmin >= near and agg[nd, 0] > 0.0 and agg[nd, 8] > 0.9:
                ex = max(box[nd, 3] - box[nd, 0], box[nd, 4] - box[nd, 1], box[nd, 5] - box[nd, 2])
                cx, cy, cz = agg[nd, 1] - x0, agg[nd, 2] - x1, agg[nd, 3] - x2
                dc = math.sqrt(cx * cx + cy * cy + cz * cz)
                if ex < theta * dc:
                    if agg[nd, 5] * rec_n[r, 0] + agg[nd, 6] * rec_n[r, 1] + agg[nd, 7] * rec_n[r, 2] > 0.0:
                        v0, v1, v2 = _kernel3(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0,
                                              dlog_a, agg[nd, 4], dc, 0.0)
                        a0 += agg[nd, 0] * v0
                        a1 += agg[nd, 0] * v1
                        a2 += agg[nd, 0] * v2
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
                if d > rmax or (mode == 0 and d >= near) or (mode == 1 and d < near):
                    continue
                w = src_p[j]
                if d < near:
                    w -= rec_E[r, src_light[j]] * src_area[j]
                if w == 0.0:
                    continue
                a = src_a[j] if src_a[j] > 0.0 else rec_a[r]
                v0, v1, v2 = _kernel3(f, dtab, cosg, n_r, log_r0, dlog, radius, patch_radii, log_a0, dlog_a,
                                      src_cos[j], d, a)
                a0 += w * v0
                a1 += w * v1
                a2 += w * v2
                n_pairs += 1
        out[r, 0] += a0
        out[r, 1] += a1
        out[r, 2] += a2
        counts[r] = n_pairs


#: entries within this many mm of a receiver are summed one by one with the subtraction of eq. (103)
NEAR_MM = 2.5
#: beyond it, a node of the entries' tree whose extent is below THETA times its distance counts as one entry
THETA = 0.35
#: entries per leaf of the tree
LEAF = 16


def remainder_exitance(tables: RemainderTables, src, rec, *, near_mm: float = NEAR_MM, theta: float = THETA,
                       coarse_far: bool = True):
    """Eq. (103) at the receivers: ((n, 3) W/mm^2, pair evaluations).

    ``src``: dict of entry arrays ``pos`` (k, 3) mm, ``normal`` (k, 3), ``power`` (k,) W, ``area`` (k,) mm^2
    (0 for point entries), ``cos_t`` (k,), ``light`` (k,) int. ``rec``: ``pos`` (n, 3), ``normal`` (n, 3),
    ``radius`` (n,) mm (the receiver's patch, for point entries), ``E`` (n, L) W/mm^2 and ``cos_t`` (n, L): the
    irradiance of each light at the receiver and the cosine its light travels inside at there.

    Entries within ``near_mm`` are summed one by one with the subtraction, and the receiver gets
    E_l(x) [int_0^near f + the energy beyond the radius] analytically; beyond, the entries' k-d tree is opened
    until a node's extent is below ``theta`` times its distance (Barnes-Hut), so the cost per receiver grows with
    the log of the radius over the spacing, not with its square. With ``coarse_far`` the part beyond ``near_mm``
    (smooth on that scale) is summed at one receiver per cube of side ``near_mm`` and interpolated."""
    n = rec["pos"].shape[0]
    out = np.zeros((n, 3))
    E, rc = np.ascontiguousarray(rec["E"], dtype=np.float64), np.asarray(rec["cos_t"], dtype=np.float64)
    for l in range(E.shape[1]):
        lit = E[:, l] > 0
        if lit.any():
            out[lit] += E[lit, l, None] * tables.near_and_beyond(rc[lit, l], near_mm)
    k = src["pos"].shape[0]
    if k == 0:
        return out, 0
    pos = np.ascontiguousarray(src["pos"], dtype=np.float64)
    nrm = np.ascontiguousarray(src["normal"], dtype=np.float64)
    pw = np.ascontiguousarray(src["power"], dtype=np.float64)
    cos_s = np.ascontiguousarray(src["cos_t"], dtype=np.float64)
    perm, lo, hi, child, box, agg = _build_tree(pos, pw, nrm, cos_s, LEAF)
    area = np.ascontiguousarray(src["area"], dtype=np.float64)
    disc = np.sqrt(np.maximum(area, 0.0) / math.pi)
    light = np.ascontiguousarray(src["light"], dtype=np.int64)
    tabs = (tables.f, tables.disc, tables.cos_t, tables.n_r, tables.log_r0, tables.dlog, tables.radius_mm,
            PATCH_RADII, math.log(DISC_A[0]), math.log(DISC_A[1] / DISC_A[0]) / (DISC_A[2] - 1))
    rp = np.ascontiguousarray(rec["pos"], dtype=np.float64)
    rn = np.ascontiguousarray(rec["normal"], dtype=np.float64)
    ra = np.ascontiguousarray(rec["radius"], dtype=np.float64)
    counts = np.zeros(n, dtype=np.int64)

    def run(pos_, nrm_, rad_, E_, mode, dest, cnt):
        run_in_blocks(lambda a, b: _traverse(pos_, nrm_, rad_, E_, perm, lo, hi, child, box, agg, pos, nrm, pw, area,
                                             disc, cos_s, light, *tabs, float(near_mm), float(theta), mode, dest,
                                             cnt, a, b), pos_.shape[0])

    if not coarse_far:
        run(rp, rn, ra, E, 2, out, counts)
        return out, int(counts.sum())
    run(rp, rn, ra, E, 0, out, counts)
    # beyond ``near`` the sum is smooth on the scale of ``near``: it is evaluated at one receiver per cube of that
    # side (and facing) and interpolated to the others from their nearest such receivers facing their way
    octant = (rn > 0).astype(np.int64) @ np.array([1, 2, 4])
    cell = np.floor(rp / near_mm).astype(np.int64)
    key = np.concatenate([cell, octant[:, None]], axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    cp, cn = rp[first], rn[first]
    far = np.zeros((first.size, 3))
    cnt = np.zeros(first.size, dtype=np.int64)
    run(np.ascontiguousarray(cp), np.ascontiguousarray(cn), ra[first], E[first], 1, far, cnt)
    out += _interpolate(cp, cn, far, rp, rn, near_mm)
    counts[first] += cnt
    return out, int(counts.sum())


def _interpolate(cp, cn, cv, rp, rn, scale, k: int = 6):
    """Values ``cv`` (m, 3) at points ``cp`` (normals ``cn``) interpolated to ``rp`` (normals ``rn``): inverse
    distance weights of the ``k`` nearest whose normal is within 60 degrees of the receiver's (the nearest of
    them if none is)."""
    tree = cKDTree(cp)
    k = min(k, cp.shape[0])
    d, idx = tree.query(rp, k=k)
    d, idx = d.reshape(rp.shape[0], k), idx.reshape(rp.shape[0], k)
    agree = np.einsum("pkd,pd->pk", cn[idx], rn) > 0.5
    w = np.where(agree, 1.0 / (d + 1e-3 * scale), 0.0)
    none = w.sum(axis=1) == 0
    w[none, 0] = 1.0
    w /= w.sum(axis=1, keepdims=True)
    return np.einsum("pk,pkc->pc", w, cv[idx])
