"""The analytic near field on top of the volume solution, without counting anything twice (docs/physics.md §15.1).

The volume solve carries diffusion from where the entering light is first scattered: the line source alpha'
exp(-t) along each refracted ray as a 4-point Gauss-Laguerre rule (:func:`meshshade.volume.sources.line_source_rule`,
eq. (97)). What diffusion in the volume cannot give, the near field does analytically: per entry sample, the
half-space's near-field model minus the Robin half-space's response to the very sources the volume was given
(eq. (98)),

    Delta R(s; theta_t) = W(theta_t) R_near(s) - sum_j W_j M_Robin(s; tau_j cos theta_t),

so on a flat surface with a converged volume solution the bake returns the near-field model exactly, and
elsewhere the volume solution's curvature, thin parts and folds are kept. ``R_near`` is eq. (76) with the
incidence gain W of eq. (86); ``M_Robin`` is eq. (96) (:mod:`meshshade.kernels.robin_halfspace`) with d'Eon's
D and A, the same diffusion theory the volume is solved with. Delta R is tabulated per channel over the
distance and cos theta_t; it is summed over the pairs of an entry sample and a receiver within the chord radius
``radius_mm`` (where the magnitude of what lies beyond is TAIL_TOL of the near-field total; that remainder's
signed energy is kept at the entry point) whose normals face the same way (pairs across a thin part are the
volume's alone). A pair within PATCH_RADII patch radii takes Delta R averaged over the source's disc of radius a
(a vertex sample stands for its patch; for a beam's point entry, the receiver's patch).

Pure array work (tables in numpy, the pair values compiled: a serial loop over a range of pairs, run on blocks
of each chunk's pairs by the pacing threads, :func:`meshshade.pacing.run_in_blocks`); no I/O.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from scipy.spatial import cKDTree

from meshshade.kernels.beam_diffusion import dipole_variant
from meshshade.kernels.near_field import incidence_gain, near_field_profile, near_field_ring, near_field_total
from meshshade.kernels.robin_halfspace import (robin_point_source_disc, robin_point_source_exitance,
                                               robin_point_source_total)
from meshshade.pacing import run_in_blocks
from meshshade.volume.sources import line_source_rule

__all__ = ["NearFieldCorrection", "TAIL_TOL", "PATCH_RADII"]
#: the near-field correction's radius: where the magnitude of Delta R beyond holds this fraction of R_near's total
TAIL_TOL = 1e-2
#: pairs closer than this many patch radii take Delta R averaged over the patch's disc
PATCH_RADII = 4.0
#: pairs per block of sources in :meth:`NearFieldCorrection.exitance` (on average; about 100 bytes each)
PAIR_BLOCK = 8_000_000
_LOG_R = np.linspace(math.log(1e-5), math.log(200.0), 1025)     # optical distances of the tables
_N_COS = 9
_TH_NODES, _TH_WEIGHTS = np.polynomial.legendre.leggauss(24)


class _ChannelTable:
    """Delta R of one channel (optical units): ``f`` (n_cos, n_r) per unit entering power, its disc integral ``cum``
    int_0^r Delta R 2 pi r dr, and ``rest`` (n_cos,), the signed energy beyond the radius."""

    def __init__(self, albedo_prime: float, eta: float, g: float):
        a = float(albedo_prime)
        self.tau, self.W = line_source_rule(a)
        v = dipole_variant(a, eta, "better")
        self.D, self.mu, self.A = v.D, v.mu, v.z_b / (2.0 * v.D)
        c_min = math.sqrt(max(0.0, 1.0 - 1.0 / (eta * eta))) if eta > 1.0 else 0.05
        self.cos_t = np.linspace(max(c_min, 0.05), 1.0, _N_COS)
        r = np.exp(_LOG_R)
        kw = {"albedo_prime": a, "eta": eta}
        near = near_field_profile(r, g=g, **kw)
        near_cum = np.pi * r * r * near_field_ring(0.0 * r, r, g=g, **kw)
        near_total = near_field_total(g=g, **kw)
        rob = dict(D=self.D, mu=self.mu, A=self.A)
        self.f = np.empty((_N_COS, r.size))
        self.cum = np.empty((_N_COS, r.size))
        total = np.empty(_N_COS)
        for i, c in enumerate(self.cos_t):
            gain = incidence_gain(g=g, cos_t=float(c), **kw)
            depths = self.tau * c
            self.f[i] = gain * near - sum(W * robin_point_source_exitance(r, d, **rob) for d, W in zip(depths, self.W))
            self.cum[i] = gain * near_cum - sum(W * robin_point_source_disc(r, d, **rob)
                                                for d, W in zip(depths, self.W))
            total[i] = gain * near_total - float(sum(W * robin_point_source_total(d, **rob)
                                                     for d, W in zip(depths, self.W)))
        # the radius: where the magnitude of Delta R beyond it is TAIL_TOL of the near-field total (trapezoid in r)
        ring = 2.0 * np.pi * r * np.abs(self.f).max(axis=0)
        tail = np.concatenate([np.cumsum((0.5 * (ring[1:] + ring[:-1]) * np.diff(r))[::-1])[::-1], [0.0]])
        self.n_r = int(np.argmax(tail < TAIL_TOL * near_total)) + 1
        self.radius = float(r[self.n_r - 1])
        self.f, self.cum = self.f[:, :self.n_r], self.cum[:, :self.n_r]
        self.rest = total - self.cum[:, -1]
        self.total = total


class NearFieldCorrection:
    """The near-field correction of one material (module docstring), per channel; lengths in mm.

    ``radius_mm`` (3,): the pairs' chord radius; :meth:`exitance` sums the correction."""

    def __init__(self, material):
        self.material = material
        eta, g = float(material.eta), float(material.g)
        cache = {}
        self.tables = []
        for c in range(3):
            key = float(material.albedo_prime[c])
            if key not in cache:
                cache[key] = _ChannelTable(key, eta, g)
            self.tables.append(cache[key])
        self.sigma_t_prime = np.asarray(material.sigma_t_prime, dtype=np.float64)
        self.radius_mm = np.array([t.radius / s for t, s in zip(self.tables, self.sigma_t_prime)])
        n_r = max(t.n_r for t in self.tables)
        # packed for the compiled sum, in mm: f [c, cos, r] 1/mm^2, cum and rest dimensionless, log r of mm
        self._f = np.zeros((3, _N_COS, n_r))
        self._cum = np.zeros((3, _N_COS, n_r))
        self._rest = np.zeros((3, _N_COS))
        self._cos = np.zeros((3, _N_COS))
        self._n_r = np.array([t.n_r for t in self.tables], dtype=np.int64)
        self._log_r0 = np.array([_LOG_R[0] - math.log(s) for s in self.sigma_t_prime])
        for c, (t, s) in enumerate(zip(self.tables, self.sigma_t_prime)):
            self._f[c, :, :t.n_r] = t.f * s * s
            self._cum[c, :, :t.n_r] = t.cum
            self._rest[c] = t.rest
            self._cos[c] = t.cos_t

    def exitance(self, src_pos, src_normal, src_power, src_cos_t, src_radius, rec_pos, rec_normal, rec_radius):
        """Sum of Delta R over the pairs: (n, 3) W/mm^2 at the receivers and the number of pairs.

        src_pos (k, 3) mm, src_normal (k, 3) unit outward, src_power (k,) W entering, src_cos_t (k,) cosine of the
        refracted direction with the inward normal, src_radius (k,) mm the patch a source stands for (0 for a
        point entry: the receiver's patch ``rec_radius`` (n,) is used)."""
        n = rec_pos.shape[0]
        out = np.zeros((n, 3))
        if len(src_pos) == 0:
            return out, 0
        tree_r = cKDTree(rec_pos)
        radius = float(self.radius_mm.max())
        # the pairs in blocks of nearby sources (the source tree's order), each block within PAIR_BLOCK pairs on
        # average, so that memory stays bounded on dense meshes
        order = cKDTree(src_pos).indices
        probe = src_pos[order[np.linspace(0, order.size - 1, min(order.size, 256)).astype(np.int64)]]
        per_source = max(float(np.mean(tree_r.query_ball_point(probe, radius, return_length=True))), 1.0)
        blocks = max(1, int(math.ceil(order.size * per_source / PAIR_BLOCK)))
        arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (src_normal, rec_normal, src_power, src_cos_t,
                                                                        src_radius, rec_radius)]
        tables = (self._f, self._cum, self._rest, self._cos, self._n_r, self._log_r0, _LOG_R[1] - _LOG_R[0],
                  self.radius_mm, _TH_NODES, _TH_WEIGHTS, PATCH_RADII)
        total = 0
        for chunk in np.array_split(order, blocks):
            pairs = cKDTree(src_pos[chunk]).sparse_distance_matrix(tree_r, radius, output_type="ndarray")
            i = chunk[pairs["i"]].astype(np.int64)
            o = np.ascontiguousarray(pairs["j"], dtype=np.int64)
            s = np.ascontiguousarray(pairs["v"], dtype=np.float64)
            del pairs
            vals = np.zeros((i.size, 3))
            # each pair's value on its own: blocks of pairs on the pacing threads, written into their rows of vals
            run_in_blocks(lambda a, b: _pair_values(i, o, s, *arrays, *tables, vals, a, b), i.size)
            for c in range(3):
                out[:, c] += np.bincount(o, weights=vals[:, c], minlength=n)
            total += int(i.size)
        return out, total


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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pair_values(i, o, s, src_n, rec_n, power, cos_t, src_a, rec_a, f, cum, rest, cosg, n_r, log_r0, dlog,
                 radius, th_x, th_w, patch_radii, out, p_lo, p_hi):
    """Pairs ``p_lo:p_hi`` of (i, o, s): each pair's Delta R times the source's power written to its row of
    ``out`` (P, 3) (left as it is, zero, for pairs facing away or beyond the radius); serial, without the GIL."""
    for p in range(p_lo, p_hi):
        a_src, b = i[p], o[p]
        if (src_n[a_src, 0] * rec_n[b, 0] + src_n[a_src, 1] * rec_n[b, 1] + src_n[a_src, 2] * rec_n[b, 2]) <= 0.0:
            continue
        a = src_a[a_src] if src_a[a_src] > 0.0 else rec_a[b]
        d = s[p]
        for c in range(3):
            if d > radius[c]:
                continue
            g = cosg[c]
            ct = min(max(cos_t[a_src], g[0]), g[g.size - 1])
            k = min(int((ct - g[0]) / (g[1] - g[0])), g.size - 2)
            frac = (ct - g[k]) / (g[k + 1] - g[k])
            nr = n_r[c]
            if d >= patch_radii * a or a <= 0.0:
                v = _lookup(f, c, k, frac, max(d, 1e-300), log_r0[c], dlog, nr, True)
            else:
                # average over the disc of radius a centred at distance d: full circles up to a - d (the disc
                # integral), then arcs from |d - a| to d + a (Gauss-Legendre in theta, rho = lo + (hi-lo)(1-cos)/2)
                acc = 0.0
                if d < a:
                    acc = _lookup(cum, c, k, frac, a - d, log_r0[c], dlog, nr, False)
                    acc += (1.0 - frac) * rest[c, k] + frac * rest[c, k + 1]   # the energy beyond the radius
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
                        acc += wgt * _lookup(f, c, k, frac, rho, log_r0[c], dlog, nr, True)
                v = acc / (math.pi * a * a)
            out[p, c] = power[a_src] * v
