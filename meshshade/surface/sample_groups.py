"""Far-zone geodesics shared by groups of nearby entry samples (the bake's ``exact_near_shared_far`` zone).

A directional or point light makes an entry sample at every lit vertex, and each needs geodesic distances to
every vertex within the cutoff (exact polyhedral geodesics cost ~2 us per pair). Far from a source the distance
field of one sample predicts its neighbours' to second order, so the bake runs one exact geodesic query per
*group* of samples (a *sample group*) for the far zone and derives each member's distances from it:

    s_i = third side of the geodesic triangle (centre c, member i, receiver o) with sides s_c and d = |x_i - x_c|
          meeting at c at the angle gamma between t_c and the tangential part of x_i - x_c,

by the law of cosines of the constant Gaussian curvature K = k1 k2 of the centre (spherical for K > 0, planar,
hyperbolic for K < 0; planar: s_i^2 = s_c^2 - 2 s_c d cos gamma + d^2). s_c is the group centre's geodesic
distance to the receiver and t_c the unit initial direction of that geodesic at the centre (from the pair's
azimuth phi_c: t_c = cos phi_c d1 + sin phi_c d2). Exact on planes and spheres; otherwise the error comes from
the variation of K across the triangle and from t_c (tests: ~1e-3 mm mean on spheres, 2-5 mm groups).
Near pairs (within NEAR_MARGIN r_near) are found exactly per sample; a far pair is used only if the sample's own
near query did not find it, so every (sample, vertex) pair is counted once. Chords and azimuths are the member's
own (chord = |x_o - x_i|; phi from the projection of the chord on the member's tangent plane with the leading
geodesic correction, exactly as the geodesic solvers compute it).

Pure array functions; no mesh objects, no I/O.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from meshshade.geometry.geodesics.neighbourhoods import tangent_azimuth
from meshshade.pacing import run_in_blocks

#: members whose normal deviates more than this (cosine) from the centre's form their own group
NORMAL_COS = 0.9


def group_samples(positions, normals, size_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Group entry samples into sample groups of diameter <= sqrt(3) ``size_mm`` (voxel cells of that size).

    Within a cell the centre is the member nearest to the cell's mean; members whose normal is more than
    acos(NORMAL_COS) from the centre's (another sheet of a thin part, a sharp crease) become their own group.

    Returns ``(order, indptr)``: sample indices grouped by group (CSR, the centre first in each row).
    """
    P = np.asarray(positions, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    k = len(P)
    if k == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64)
    if not size_mm > 0:
        return np.arange(k, dtype=np.int64), np.arange(k + 1, dtype=np.int64)
    cell = np.floor((P - P.min(axis=0)) / size_mm).astype(np.int64)
    _, label = np.unique(cell, axis=0, return_inverse=True)
    label = label.ravel()
    n_cells = int(label.max()) + 1
    cnt = np.bincount(label, minlength=n_cells).astype(np.float64)
    mean = np.stack([np.bincount(label, weights=P[:, j], minlength=n_cells) for j in range(3)], axis=1) / cnt[:, None]
    d2 = np.einsum("ij,ij->i", P - mean[label], P - mean[label])
    order = np.lexsort((d2, label))  # by cell, nearest to the mean first
    first = np.r_[True, label[order][1:] != label[order][:-1]]
    centre_of_cell = order[first]  # cell ids are 0..n_cells-1 in sorted order
    centre = centre_of_cell[label]
    lone = np.einsum("ij,ij->i", N, N[centre]) < NORMAL_COS
    # each lone sample is a group of its own: give it a fresh label
    label = label.copy()
    label[lone] = n_cells + np.arange(int(lone.sum()))
    centre = centre.copy()
    centre[lone] = np.flatnonzero(lone)
    is_centre = centre == np.arange(k)
    order = np.lexsort((~is_centre, label))  # by group, the centre first
    counts = np.bincount(label)
    counts = counts[counts > 0]
    return order.astype(np.int64), np.r_[0, np.cumsum(counts)].astype(np.int64)


def _law_of_cosines(sc, d, t_dot_dx, dx_len, K):
    """Third side of a geodesic triangle with sides ``sc`` and ``d`` meeting at angle gamma (cos gamma =
    t.dx/|dx|) on a surface of constant Gaussian curvature ``K`` (spherical / planar / hyperbolic law of
    cosines; the planar law where |K| (sc + d)^2 < 1e-6 or on the far side of a sphere, k (sc + d) > 2.5)."""
    cosg = np.divide(t_dot_dx, dx_len, out=np.zeros_like(sc), where=dx_len > 0)
    out = np.sqrt(np.maximum(sc * sc - 2.0 * sc * d * cosg + d * d, 0.0))
    k = np.sqrt(np.abs(K))
    x, y = k * sc, k * d
    sph = (K > 0) & (K * (sc + d) ** 2 >= 1e-6) & (x + y <= 2.5)
    if np.any(sph):
        c = np.cos(x[sph]) * np.cos(y[sph]) + np.sin(x[sph]) * np.sin(y[sph]) * cosg[sph]
        out[sph] = np.arccos(np.clip(c, -1.0, 1.0)) / k[sph]
    hyp = (K < 0) & (-K * (sc + d) ** 2 >= 1e-6) & (x + y <= 30.0)
    if np.any(hyp):
        c = np.cosh(x[hyp]) * np.cosh(y[hyp]) - np.sinh(x[hyp]) * np.sinh(y[hyp]) * cosg[hyp]
        out[hyp] = np.arccosh(np.maximum(c, 1.0)) / k[hyp]
    return out


def expand_far_pairs_reference(centre_pairs, member_of_row, positions, vertices, frames, *, exclude_keys=None,
                               max_distance: float = np.inf):
    """Member pairs from their group centre's geodesic pairs (module docstring), in numpy: the test oracle of
    :func:`expand_far_pairs` (same pairs, same order; the bake uses the numba version only).

    centre_pairs : (src_c, vertex, s_c, chord_c, phi_c) arrays of the centres' far query (src_c are sample ids
        of the centres); member_of_row : (members, centre) index arrays listing every member with its centre;
    positions : (k, 3) sample positions; vertices : (n, 3); frames : SourceFrames of the samples;
    exclude_keys : sorted int64 array of ``sample * n + vertex`` keys already found (the members' near pairs);
    max_distance : pairs with s_i beyond it are dropped.
    Returns ``(src, vertex, s, chord, phi)`` of the members (centres included: their own pairs come out unchanged
    up to rounding).
    """
    src_c, vtx, s_c, _, phi_c = centre_pairs
    members, centres = member_of_row
    n = np.int64(len(vertices))
    if src_c.size == 0 or members.size == 0:
        e = np.zeros(0)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), e, e, e
    # rows of the centre pairs, grouped by centre (a stable sort keeps the solver's order within a row)
    by_c = np.argsort(src_c, kind="stable")
    cs = src_c[by_c]
    uc, start = np.unique(cs, return_index=True)
    stop = np.r_[start[1:], cs.size]
    pos_of = np.full(int(max(uc.max(), centres.max())) + 1, -1, dtype=np.int64)
    pos_of[uc] = np.arange(uc.size)
    j = pos_of[centres]
    ok = j >= 0
    members, centres, j = members[ok], centres[ok], j[ok]
    lens = stop[j] - start[j]
    m_rep = np.repeat(members, lens)
    c_rep = np.repeat(centres, lens)
    offs = np.arange(int(lens.sum())) - np.repeat(np.cumsum(lens) - lens, lens)
    rows = by_c[np.repeat(start[j], lens) + offs]
    f = frames
    t = np.cos(phi_c[rows])[:, None] * f.d1[c_rep] + np.sin(phi_c[rows])[:, None] * f.d2[c_rep]
    dx = positions[m_rep] - positions[c_rep]
    dx -= np.einsum("ij,ij->i", dx, f.normals[c_rep])[:, None] * f.normals[c_rep]
    s = _law_of_cosines(s_c[rows], np.linalg.norm(positions[m_rep] - positions[c_rep], axis=1),
                        np.einsum("ij,ij->i", t, dx), np.linalg.norm(dx, axis=1), f.k1[c_rep] * f.k2[c_rep])
    o = vtx[rows].astype(np.int64)
    keep = s <= max_distance
    if exclude_keys is not None and exclude_keys.size:
        keep &= ~np.isin(m_rep * n + o, exclude_keys, assume_unique=False)
    m_rep, o, s = m_rep[keep], o[keep], s[keep]
    v = np.asarray(vertices)[o] - positions[m_rep]
    chord = np.linalg.norm(v, axis=1)
    nm = f.normals[m_rep]
    tan = v - np.einsum("ij,ij->i", v, nm)[:, None] * nm
    ln = np.linalg.norm(tan, axis=1, keepdims=True)
    tan = np.divide(tan, ln, out=np.zeros_like(tan), where=ln > 0)
    phi = tangent_azimuth(tan, f.d1[m_rep], f.d2[m_rep], rho=s, k1=f.k1[m_rep], k2=f.k2[m_rep])
    return m_rep, o, s, chord, phi


def _centre_rows(src_c, centres):
    """Centre pairs grouped by centre: (order of the rows, start, stop per member's centre, member ok mask)."""
    by_c = np.argsort(src_c, kind="stable")
    cs = src_c[by_c]
    uc, start = np.unique(cs, return_index=True)
    stop = np.r_[start[1:], cs.size]
    pos_of = np.full(int(max(uc.max(), centres.max())) + 1, -1, dtype=np.int64)
    pos_of[uc] = np.arange(uc.size)
    j = pos_of[centres]
    ok = j >= 0
    jj = np.where(ok, j, 0)
    return by_c, np.where(ok, start[jj], 0), np.where(ok, stop[jj], 0)


def expand_far_pairs(centre_pairs, member_of_row, positions, vertices, frames, *, exclude_keys=None,
                     max_distance: float = np.inf):
    """Member pairs from their group centre's geodesic pairs (module docstring): the numba version of
    :func:`expand_far_pairs_reference` (same arguments, same pairs in the same order),
    blocks of members on the pacing threads, with no intermediate arrays of all member x centre-pair candidates."""
    src_c, vtx, s_c, _, phi_c = centre_pairs
    members, centres = (np.asarray(a, dtype=np.int64) for a in member_of_row)
    if src_c.size == 0 or members.size == 0:
        e = np.zeros(0)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), e, e, e
    by_c, lo, hi = _centre_rows(np.asarray(src_c, dtype=np.int64), centres)
    keys = np.zeros(0, np.int64) if exclude_keys is None else np.ascontiguousarray(exclude_keys, dtype=np.int64)
    f = frames
    args = (members, centres, lo, hi, by_c, np.asarray(vtx, dtype=np.int64), np.asarray(s_c, dtype=np.float64),
            np.asarray(phi_c, dtype=np.float64), np.ascontiguousarray(positions, dtype=np.float64),
            np.ascontiguousarray(vertices, dtype=np.float64), f.normals, f.d1, f.d2, f.k1, f.k2, keys,
            np.int64(len(vertices)), float(max_distance))
    counts = np.zeros(members.size, dtype=np.int64)
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0))
    # serial loops over blocks of members on the pacing threads (each member writes its own slots)
    run_in_blocks(lambda a, b: _expand(*args, counts, True, counts, *none, a, b), members.size)
    offsets = np.r_[0, np.cumsum(counts)].astype(np.int64)
    m = int(offsets[-1])
    out = (np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m), np.empty(m), np.empty(m))
    run_in_blocks(lambda a, b: _expand(*args, counts, False, offsets, *out, a, b), members.size)
    return out


@njit(cache=True)
def _law_of_cosines_1(sc, d, t_dot_dx, dx_len, K):
    """Scalar :func:`_law_of_cosines`."""
    cosg = t_dot_dx / dx_len if dx_len > 0.0 else 0.0
    k = math.sqrt(abs(K))
    x, y = k * sc, k * d
    if K > 0.0 and K * (sc + d) ** 2 >= 1e-6 and x + y <= 2.5:
        c = math.cos(x) * math.cos(y) + math.sin(x) * math.sin(y) * cosg
        return math.acos(min(1.0, max(-1.0, c))) / k
    if K < 0.0 and -K * (sc + d) ** 2 >= 1e-6 and x + y <= 30.0:
        c = math.cosh(x) * math.cosh(y) - math.sinh(x) * math.sinh(y) * cosg
        return math.acosh(max(c, 1.0)) / k
    return math.sqrt(max(sc * sc - 2.0 * sc * d * cosg + d * d, 0.0))


@njit(nogil=True, cache=True)
def _expand(members, centres, lo, hi, by_c, vtx, s_c, phi_c, P, V, N, D1, D2, K1, K2, keys, n, max_d, counts,
            count_only, offsets, o_src, o_v, o_s, o_ch, o_phi, a_lo, a_hi):
    """Members ``a_lo:a_hi``: their pair counts (``count_only``) or their pairs written from ``offsets``."""
    for a in range(a_lo, a_hi):
        i, c = members[a], centres[a]
        dx0, dx1, dx2 = P[i, 0] - P[c, 0], P[i, 1] - P[c, 1], P[i, 2] - P[c, 2]
        d = math.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2)
        dn = dx0 * N[c, 0] + dx1 * N[c, 1] + dx2 * N[c, 2]
        t0, t1, t2 = dx0 - dn * N[c, 0], dx1 - dn * N[c, 1], dx2 - dn * N[c, 2]
        dxl = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        K = K1[c] * K2[c]
        w = offsets[a]
        cnt = 0
        for q in range(lo[a], hi[a]):
            r = by_c[q]
            cp, sp = math.cos(phi_c[r]), math.sin(phi_c[r])
            tdx = ((cp * D1[c, 0] + sp * D2[c, 0]) * t0 + (cp * D1[c, 1] + sp * D2[c, 1]) * t1
                   + (cp * D1[c, 2] + sp * D2[c, 2]) * t2)
            s = _law_of_cosines_1(s_c[r], d, tdx, dxl, K)
            if s > max_d:
                continue
            o = vtx[r]
            if keys.size:
                key = i * n + o
                p = np.searchsorted(keys, key)
                if p < keys.size and keys[p] == key:
                    continue
            cnt += 1
            if count_only:
                continue
            v0, v1, v2 = V[o, 0] - P[i, 0], V[o, 1] - P[i, 1], V[o, 2] - P[i, 2]
            vn = v0 * N[i, 0] + v1 * N[i, 1] + v2 * N[i, 2]
            u0, u1, u2 = v0 - vn * N[i, 0], v1 - vn * N[i, 1], v2 - vn * N[i, 2]
            ul = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            if ul > 0.0:
                u0, u1, u2 = u0 / ul, u1 / ul, u2 / ul
            phi = math.atan2(u0 * D2[i, 0] + u1 * D2[i, 1] + u2 * D2[i, 2],
                             u0 * D1[i, 0] + u1 * D1[i, 1] + u2 * D1[i, 2])
            cs, sn = math.cos(phi), math.sin(phi)
            kn = K1[i] * cs * cs + K2[i] * sn * sn
            phi = phi - (s * s / 6.0) * kn * (K1[i] - K2[i]) * sn * cs  # tangent_azimuth's geodesic correction
            phi = math.atan2(math.sin(phi), math.cos(phi))
            o_src[w], o_v[w], o_s[w] = i, o, s
            o_ch[w] = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            o_phi[w] = phi
            w += 1
        if count_only:
            counts[a] = cnt
