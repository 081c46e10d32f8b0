"""Far-zone geodesics shared by clusters of nearby entry samples (the bake's ``exact_near_cluster_far`` zone).

A directional or point light makes an entry sample at every lit vertex, and each needs geodesic distances to
every vertex within the cutoff (exact polyhedral geodesics cost ~2 us per pair). Far from a source the distance
field of one sample predicts its neighbours' to second order, so the bake runs one exact geodesic query per
*cluster* of samples for the far zone and derives each member's distances from it:

    s_i = third side of the geodesic triangle (centre c, member i, receiver o) with sides s_c and d = |x_i - x_c|
          meeting at c at the angle gamma between t_c and the tangential part of x_i - x_c,

by the law of cosines of the constant Gaussian curvature K = k1 k2 of the centre (spherical for K > 0, planar,
hyperbolic for K < 0; planar: s_i^2 = s_c^2 - 2 s_c d cos gamma + d^2). s_c is the cluster centre's geodesic
distance to the receiver and t_c the unit initial direction of that geodesic at the centre (from the pair's
azimuth phi_c: t_c = cos phi_c d1 + sin phi_c d2). Exact on planes and spheres; otherwise the error comes from
the variation of K across the triangle and from t_c (tests: ~1e-3 mm mean on spheres, 2-5 mm clusters).
Near pairs (within NEAR_MARGIN r_near) are found exactly per sample; a far pair is used only if the sample's own
near query did not find it, so every (sample, vertex) pair is counted once. Chords and azimuths are the member's
own (chord = |x_o - x_i|; phi from the projection of the chord on the member's tangent plane with the leading
geodesic correction, exactly as the geodesic solvers compute it).

Pure array functions; no mesh objects, no I/O.
"""
from __future__ import annotations

import numpy as np

from .geometry.neighbourhood import tangent_azimuth

#: members whose normal deviates more than this (cosine) from the centre's form their own cluster
NORMAL_COS = 0.9


def cluster_sources(positions, normals, size_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Group entry samples into clusters of diameter <= sqrt(3) ``size_mm`` (voxel cells of that size).

    Within a cell the centre is the member nearest to the cell's mean; members whose normal is more than
    acos(NORMAL_COS) from the centre's (another sheet of a thin part, a sharp crease) become their own cluster.

    Returns ``(order, indptr)``: sample indices grouped by cluster (CSR, the centre first in each row).
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
    # each lone sample is a cluster of its own: give it a fresh label
    label = label.copy()
    label[lone] = n_cells + np.arange(int(lone.sum()))
    centre = centre.copy()
    centre[lone] = np.flatnonzero(lone)
    is_centre = centre == np.arange(k)
    order = np.lexsort((~is_centre, label))  # by cluster, the centre first
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


def expand_far_pairs(centre_pairs, member_of_row, positions, vertices, frames, *, exclude_keys=None,
                     max_distance: float = np.inf):
    """Member pairs from their cluster centre's geodesic pairs (module docstring).

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
