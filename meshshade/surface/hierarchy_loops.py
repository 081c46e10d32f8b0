"""Compiled loops of the hierarchical transport (meshshade/surface/hierarchical.py): cluster geometry per light and
the far-field traversal with every model's kernel.

Everything is float64 on plain arrays, lengths in mm. A source cluster (a node of the k-d tree over vertex
sources, farfield_loops.node_ranges / kd_permutation) stands for its sources by four *sigma points*: with P the
node's power, c its power-weighted centroid and lambda_1 >= lambda_2 the two largest eigenvalues (axes e_1, e_2)
of its power-weighted covariance, the points ``c +- sqrt(2 lambda_k) e_k`` with power P/4 each reproduce the
cluster's zeroth, first and second moments exactly (docs/physics.md §9.1, eq. (72)), so the sum over the cluster is
replaced by four kernel values with an error of third order in the cluster's size over its distance (odd terms
cancel by symmetry: fourth order for symmetric clusters), whatever the kernel. The third eigenvalue (the sagitta
of a curved cluster) is dropped: (k a^2/2)^2 against a^2.

Every pair's kernel is :func:`meshshade.surface.kernel_evaluation.kernel_value` (``kind`` a
:class:`~meshshade.surface.models.Kernel`), the one evaluation the near zone and the direct sum use too; the
fitted model's pairs take the normal-section curvature between their two points (:func:`fitted_geometry`). The
surface distance of a far pair is the arc of docs/physics.md eq. (59) from the chord and the two normals.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from meshshade.surface.farfield_loops import log_grid_interp, near_factor
from meshshade.surface.kernel_evaluation import FITTED, kernel_value, per_kernel

STACK_SIZE = 256


class TreeSources(NamedTuple):
    """One k-d tree of vertex sources in tree order (rows of the node ranges): positions ``pos`` (k, 3) mm, unit
    normals ``nrm`` (k, 3), shape operators ``shape`` (k, 6) 1/mm, powers ``power`` (k,) W, near radii ``near``
    (k,) mm and exact-sphere rows ``sph`` (k,) int64; the nodes' source ranges ``lo``, ``hi`` and the first leaf."""

    pos: np.ndarray
    nrm: np.ndarray
    shape: np.ndarray
    power: np.ndarray
    near: np.ndarray
    sph: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    first_leaf: int


class Clusters(NamedTuple):
    """Per node of a :class:`TreeSources` (:func:`cluster_geometry`): power P, sigma points ``sig`` (4, 3), their
    normals ``nsig`` and shape operators ``ssig`` (4, 6), mean normal, normal-cone cosine, mean shape operator,
    bounding radius ``rad``, largest near radius ``rn`` and representative sphere row ``srow``."""

    P: np.ndarray
    sig: np.ndarray
    nsig: np.ndarray
    ssig: np.ndarray
    nmean: np.ndarray
    cone: np.ndarray
    Smean: np.ndarray
    rad: np.ndarray
    rn: np.ndarray
    srow: np.ndarray


class Opening(NamedTuple):
    """When the traversal uses a node whole: ``cutoff`` (3,) mm per channel, the opening angle ``theta`` (a node
    of radius a is used at distance d >= a / theta) and the cosine ``cone_min`` of the widest normal cone."""

    cutoff: np.ndarray
    theta: float
    cone_min: float


class FarFactors(NamedTuple):
    """The near-field model's factors on far pairs (docs/physics.md eqs. (80), (88)): ``drift`` (k, 3) mm per
    source and ``node_drift`` (nodes, 3) its power-weighted mean per node, the drift slope table ``slope`` (empty:
    no drift) on the grid ``log0 + i log_step`` of ln(r sigma_t'), ``sigma_t`` the drifting channel's sigma_t',
    and ``log_ratio`` (3, m) the near field's ln N(s) on the same grid (m = 0: none)."""

    drift: np.ndarray
    node_drift: np.ndarray
    slope: np.ndarray
    log0: float
    log_step: float
    sigma_t: float
    log_ratio: np.ndarray


# ---------------------------------------------------------------------------------------------------- geometry
@njit(cache=True, inline="always")
def arc_length(chord, k_chord):
    """Surface distance of a pair from its chord (mm) and the normal-section curvature estimate
    ``k_chord = k c / 2`` (eq. (59)): ``c asin(u)/u`` with ``u = min(|k c/2|, 1)``. Unlike the arc geodesics'
    ``geometry.geodesics.arc._arc``, which marks |k c/2| >= 1 invalid for its Dijkstra fallback, the far field
    needs a value for every pair: a half circle, pi c / 2. :func:`meshshade.surface.hierarchical.arc_distances`
    is the array twin the distance checks use."""
    u = min(abs(k_chord), 1.0)
    if u < 1e-4:
        return chord * (1.0 + u * u / 6.0)
    return chord * math.asin(u) / u


@njit(cache=True, inline="always")
def pair_geometry(x0, x1, x2, nx0, nx1, nx2, y0, y1, y2, ny0, ny1, ny2, S, srow):
    """(chord, surface distance, kn, kn_perp) of the pair receiver x (normal nx) <- source y (normal ny, shape
    operator S[srow] as (xx, yy, zz, xy, xz, yz)): kn is the normal curvature at y towards x, kn_perp across."""
    v0, v1, v2 = x0 - y0, x1 - y1, x2 - y2
    c2 = v0 * v0 + v1 * v1 + v2 * v2
    c = math.sqrt(c2)
    if c <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    kc = ((nx0 - ny0) * v0 + (nx1 - ny1) * v1 + (nx2 - ny2) * v2) / c2 * c * 0.5
    s = arc_length(c, kc)
    # tangent direction at y towards x
    vn = v0 * ny0 + v1 * ny1 + v2 * ny2
    t0, t1, t2 = v0 - vn * ny0, v1 - vn * ny1, v2 - vn * ny2
    tt = t0 * t0 + t1 * t1 + t2 * t2
    sxx, syy, szz, sxy, sxz, syz = S[srow, 0], S[srow, 1], S[srow, 2], S[srow, 3], S[srow, 4], S[srow, 5]
    tr = sxx + syy + szz
    nsn = (sxx * ny0 * ny0 + syy * ny1 * ny1 + szz * ny2 * ny2
           + 2.0 * (sxy * ny0 * ny1 + sxz * ny0 * ny2 + syz * ny1 * ny2))
    if tt <= 1e-30 * c2:
        kn = 0.5 * (tr - nsn)
    else:
        kn = (sxx * t0 * t0 + syy * t1 * t1 + szz * t2 * t2
              + 2.0 * (sxy * t0 * t1 + sxz * t0 * t2 + syz * t1 * t2)) / tt
    return c, s, kn, tr - nsn - kn


@njit(cache=True, inline="always")
def fitted_geometry(kind, kn, knp, S, srow, x0, x1, x2, nx0, nx1, nx2, y0, y1, y2, ny0, ny1, ny2):
    """(k_along, tau^2) of a pair receiver x (normal nx) <- source y (normal ny, shape operator S[srow]) for the
    kernel: for the fitted model (kind 4) the normal-section curvature between the two points,
    ``(n_x - n_y).(x - y)/|x - y|^2`` (docs/physics.md eq. (85); the source's ``kn`` for coincident points), and
    the source's squared twist from tr(S^2) = kn^2 + knp^2 + 2 tau^2 (S tangent; clamped at 0 against rounding);
    ``(kn, 0)`` for every other kernel."""
    if kind != FITTED:
        return kn, 0.0
    sxx, syy, szz, sxy, sxz, syz = S[srow, 0], S[srow, 1], S[srow, 2], S[srow, 3], S[srow, 4], S[srow, 5]
    tr2 = sxx * sxx + syy * syy + szz * szz + 2.0 * (sxy * sxy + sxz * sxz + syz * syz)
    t2 = max(0.5 * (tr2 - kn * kn - knp * knp), 0.0)
    v0, v1, v2 = x0 - y0, x1 - y1, x2 - y2
    c2 = v0 * v0 + v1 * v1 + v2 * v2
    if c2 <= 0.0:
        return kn, t2
    return ((nx0 - ny0) * v0 + (nx1 - ny1) * v1 + (nx2 - ny2) * v2) / c2, t2


# ---------------------------------------------------------------------------------------------------- clusters
@njit(cache=True, inline="always")
def rotated_shape(S, row, a0, a1, a2, b0, b1, b2, out, orow, w):
    """out[orow] += w R S[row] R^T with R the smallest rotation taking unit normal a to unit normal b (Rodrigues):
    a shape operator tangent to a, carried to b's tangent plane. (xx, yy, zz, xy, xz, yz) storage."""
    v0, v1, v2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    c = a0 * b0 + a1 * b1 + a2 * b2
    f = 1.0 / (1.0 + c) if c > -0.999999 else 0.0
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - f * (v1 * v1 + v2 * v2)
    R[1, 1] = 1.0 - f * (v0 * v0 + v2 * v2)
    R[2, 2] = 1.0 - f * (v0 * v0 + v1 * v1)
    R[0, 1], R[1, 0] = -v2 + f * v0 * v1, v2 + f * v0 * v1
    R[0, 2], R[2, 0] = v1 + f * v0 * v2, -v1 + f * v0 * v2
    R[1, 2], R[2, 1] = -v0 + f * v1 * v2, v0 + f * v1 * v2
    A = np.empty((3, 3))
    A[0, 0], A[1, 1], A[2, 2] = S[row, 0], S[row, 1], S[row, 2]
    A[0, 1] = A[1, 0] = S[row, 3]
    A[0, 2] = A[2, 0] = S[row, 4]
    A[1, 2] = A[2, 1] = S[row, 5]
    B = R @ A @ R.T
    out[orow, 0] += w * B[0, 0]
    out[orow, 1] += w * B[1, 1]
    out[orow, 2] += w * B[2, 2]
    out[orow, 3] += w * B[0, 1]
    out[orow, 4] += w * B[0, 2]
    out[orow, 5] += w * B[1, 2]


@njit(cache=True)
def cluster_geometry(pos, nrm, shape, power, patch, near, sph, logr, lo, hi):
    """Per node of the tree (rows in tree order): total power P, sigma points (4, 3), their normals (4, 3: the mean
    normal turned by the mean shape operator, dn = S dx, so a sigma point is a point of the smooth surface) and
    shape operators (4, 6: the mean carried to each sigma point's normal), mean unit normal, the cosine
    of its normal cone (min over members of n_j . n_mean), power-weighted mean shape operator (6), bounding
    radius about the centroid (including the members' patch radii), the largest near radius of its members and a
    representative sphere-table row (``sph``, the member whose log local radius ``logr`` is nearest the
    power-weighted mean; -1 without sphere rows). Nodes without power get P = 0 and are skipped by the traversal."""
    n_nodes = lo.shape[0]
    P = np.zeros(n_nodes)
    sig = np.zeros((n_nodes, 4, 3))
    nsig = np.zeros((n_nodes, 4, 3))
    ssig = np.zeros((n_nodes, 4, 6))
    nmean = np.zeros((n_nodes, 3))
    cone = np.zeros(n_nodes)
    Smean = np.zeros((n_nodes, 6))
    rad = np.zeros(n_nodes)
    rn = np.zeros(n_nodes)
    srow = np.full(n_nodes, -1, np.int64)
    # serial: parallel=True measured no faster on 2 cores (2.5k-164k sources: 14-1600 ms either way) and doubled
    # its compile time (tools/benchmarks/bench_first_run.py)
    for i in range(n_nodes):
        a, b = lo[i], hi[i]
        w = 0.0
        cx = cy = cz = 0.0
        for j in range(a, b):
            p = power[j]
            w += p
            cx += p * pos[j, 0]
            cy += p * pos[j, 1]
            cz += p * pos[j, 2]
        if not w > 0.0:
            continue
        cx, cy, cz = cx / w, cy / w, cz / w
        Q = np.zeros((3, 3))
        m0 = m1 = m2 = 0.0
        s6 = np.zeros(6)
        r_max = 0.0
        rn_max = 0.0
        for j in range(a, b):
            p = power[j]
            dx, dy, dz = pos[j, 0] - cx, pos[j, 1] - cy, pos[j, 2] - cz
            Q[0, 0] += p * dx * dx
            Q[1, 1] += p * dy * dy
            Q[2, 2] += p * dz * dz
            Q[0, 1] += p * dx * dy
            Q[0, 2] += p * dx * dz
            Q[1, 2] += p * dy * dz
            m0 += p * nrm[j, 0]
            m1 += p * nrm[j, 1]
            m2 += p * nrm[j, 2]
            for q in range(6):
                s6[q] += p * shape[j, q]
            if p > 0.0:
                r = math.sqrt(dx * dx + dy * dy + dz * dz) + patch[j]
                if r > r_max:
                    r_max = r
                if near[j] > rn_max:
                    rn_max = near[j]
        Q[1, 0], Q[2, 0], Q[2, 1] = Q[0, 1], Q[0, 2], Q[1, 2]
        lam, vec = np.linalg.eigh(Q / w)
        for k in range(2):  # the two largest axes (eigh sorts ascending)
            ax = 2 - k
            h = math.sqrt(2.0 * max(lam[ax], 0.0))
            for q in range(3):
                sig[i, 2 * k, q] = (cx, cy, cz)[q] + h * vec[q, ax]
                sig[i, 2 * k + 1, q] = (cx, cy, cz)[q] - h * vec[q, ax]
        nn = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        if nn > 0.0:
            m0, m1, m2 = m0 / nn, m1 / nn, m2 / nn
        cmin = 1.0
        lmean = 0.0
        for j in range(a, b):
            if power[j] > 0.0:
                cj = nrm[j, 0] * m0 + nrm[j, 1] * m1 + nrm[j, 2] * m2
                if cj < cmin:
                    cmin = cj
                lmean += power[j] * logr[j]
        # the normal at each sigma point: the mean normal turned by the mean shape operator (dn = S dx)
        for q in range(4):
            e0, e1, e2 = sig[i, q, 0] - cx, sig[i, q, 1] - cy, sig[i, q, 2] - cz
            g0 = m0 + s6[0] / w * e0 + s6[3] / w * e1 + s6[4] / w * e2
            g1 = m1 + s6[3] / w * e0 + s6[1] / w * e1 + s6[5] / w * e2
            g2 = m2 + s6[4] / w * e0 + s6[5] / w * e1 + s6[2] / w * e2
            gn = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
            if gn > 0.0:
                nsig[i, q, 0], nsig[i, q, 1], nsig[i, q, 2] = g0 / gn, g1 / gn, g2 / gn
        # the mean shape operator in the mean normal's tangent plane (each member's carried there first), then
        # carried on to each sigma point's normal
        sm = np.zeros((1, 6))
        for j in range(a, b):
            if power[j] > 0.0:
                rotated_shape(shape, j, nrm[j, 0], nrm[j, 1], nrm[j, 2], m0, m1, m2, sm, 0, power[j] / w)
        for q in range(4):
            rotated_shape(sm, 0, m0, m1, m2, nsig[i, q, 0], nsig[i, q, 1], nsig[i, q, 2], ssig[i], q, 1.0)
        P[i] = w
        nmean[i, 0], nmean[i, 1], nmean[i, 2] = m0, m1, m2
        cone[i] = cmin if nn > 0.0 else -1.0
        for q in range(6):
            Smean[i, q] = s6[q] / w
        rad[i] = r_max
        rn[i] = rn_max
        lmean = lmean / w
        best = math.inf
        for j in range(a, b):
            if power[j] > 0.0 and sph[j] >= 0:
                dd = abs(logr[j] - lmean)
                if dd < best:
                    best = dd
                    srow[i] = sph[j]
    return P, sig, nsig, ssig, nmean, cone, Smean, rad, rn, srow


@njit(cache=True)
def bessel_i0e(x):
    """exp(-x) I0(x) for x >= 0 (Abramowitz & Stegun 9.8.1-9.8.2, relative error < 2e-7; checked against
    scipy.special.i0e in tests/surface/test_drift.py)."""
    if x < 3.75:
        t = (x / 3.75) ** 2
        return math.exp(-x) * (1.0 + t * (3.5156229 + t * (3.0899424 + t * (1.2067492 + t * (0.2659732 + t * (
            0.0360768 + t * 0.0045813))))))
    t = 3.75 / x
    return (0.39894228 + t * (0.01328592 + t * (0.00225319 + t * (-0.00157565 + t * (0.00916281 + t * (
        -0.02057706 + t * (0.02635537 + t * (-0.01647633 + t * 0.00392377)))))))) / math.sqrt(x)


@njit(cache=True)
def drift_factor(u0, u1, u2, n0, n1, n2, d0, d1, d2, s, dslope, dlog0, dlogstep, dst):
    """The drift factor exp(A (cos psi - 1)) / i0e(A) of eq. (88) for one far pair: chord u = receiver - source,
    source normal n, the source's drift D (mm, tangent), surface distance s (mm); A = |D| lambda(s~) s / s~ with
    s~ = sqrt(s^2 + |D|^2), and cos psi the angle between D and the chord's tangential part."""
    un = u0 * n0 + u1 * n1 + u2 * n2
    t0, t1, t2 = u0 - un * n0, u1 - un * n1, u2 - un * n2
    tl = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    dl = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if tl <= 0.0 or dl <= 0.0 or s <= 0.0:
        return 1.0
    sm = math.sqrt(s * s + dl * dl)   # the kernel smoothed over the drift, as NearFieldFactors.drift_factor
    A = dl * log_grid_interp(dslope, sm * dst, dlog0, dlogstep) * s / (sm * sm)
    cos_psi = (d0 * t0 + d1 * t1 + d2 * t2) / (dl * tl)
    return math.exp(A * (cos_psi - 1.0)) / bessel_i0e(A)


# ---------------------------------------------------------------------------------------------------- traversal
def _traverse_of(kind):
    """:func:`far_traverse` for the sources of kernel ``kind`` (a constant of the closure: only that kernel's
    code is typed and compiled; :func:`~meshshade.surface.kernel_evaluation.per_kernel`)."""

    def far_traverse(recv, rnrm, order, tree, clusters, opening, rep, params, factors):
        """Far-field exitance M (len(order), 3) [W/mm^2] at the receivers ``recv[order]`` (normals ``rnrm``),
        from the sources of one :class:`TreeSources` (``tree``, all of kernel ``kind``) and their
        :class:`Clusters`, with the :class:`Opening` criteria, the kernel's
        :class:`~meshshade.surface.kernel_evaluation.KernelParams` and the near-field model's :class:`FarFactors`.

        A node is skipped when its sources are all beyond the cutoff (chord), used whole (sigma points, mean
        normal, mean shape operator, representative sphere row) when all its pairs are far (d - a > its largest
        near radius + ``margin``), a <= theta d and its normal cone is within acos(cone_min), else opened; at leaves
        each source counts when the chord from its ``home`` position exceeds its near radius and its surface
        distance is within the cutoff. ``rep[c]`` is the channel computed for channel c (equal channels are
        computed once).

        The light's sideways drift (docs/physics.md §13.4, eq. (88)): with ``dslope`` non-empty every pair is
        multiplied by exp(A (cos psi - 1)) / i0e(A), A = |D| lambda(s~) s / s~, from the source's drift D
        (``drift`` (k, 3) mm; a whole node: its power-weighted mean ``ndrift``) and the slope
        lambda(s) = g(ln(s dst)) / s of the near-field model, g tabulated in ``dslope`` on the uniform grid
        ``dlog0 + i dlogstep`` of ln(r sigma_t'), ``dst`` that channel's sigma_t' (one channel per pass: the others'
        columns are not used). The near field's pair factor (docs/physics.md eq. (80), N(s) = R_near(s) / R_d(s)):
        with ``nlog`` (3, m) non-empty, each channel's kernel is multiplied by exp(nlog[c]) interpolated at
        ln(s sigma_t'[c]) on the same grid as ``dslope``. Returns M and per-receiver counts (len(order), 2):
        kernel evaluations at leaves, clusters used. Serial, without the GIL: the caller runs blocks of receivers
        on the pacing threads (:func:`meshshade.pacing.run_paced`); each receiver is computed on its own.
        """
        pos, nrm, shape, power, near, sph, lo, hi, first_leaf = tree
        P, sig, nsig, ssig, nmean, cone, Smean, rad, rn, srow = clusters
        cutoff, theta, cone_min = opening
        drift, ndrift, dslope, dlog0, dlogstep, dst, nlog = factors
        M = np.zeros((order.shape[0], 3))
        counts = np.zeros((order.shape[0], 2), np.int64)
        use_drift = dslope.shape[0] > 0
        use_n = nlog.shape[1] > 0
        full = 0
        for c in range(3):
            if rep[c] == c:
                full |= 1 << c
        for t in range(order.shape[0]):
            o = order[t]
            x0, x1, x2 = recv[o, 0], recv[o, 1], recv[o, 2]
            nx0, nx1, nx2 = rnrm[o, 0], rnrm[o, 1], rnrm[o, 2]
            acc = np.zeros(3)
            stack = np.empty(STACK_SIZE, np.int64)
            smask = np.empty(STACK_SIZE, np.int64)
            stack[0], smask[0] = 0, full
            top = 1
            n_leaf = 0
            n_clu = 0
            while top > 0:
                top -= 1
                node, mask = stack[top], smask[top]
                if not P[node] > 0.0:
                    continue
                # distance from the receiver to the node's power centroid (the mean of its sigma points)
                cx = 0.25 * (sig[node, 0, 0] + sig[node, 1, 0] + sig[node, 2, 0] + sig[node, 3, 0])
                cy = 0.25 * (sig[node, 0, 1] + sig[node, 1, 1] + sig[node, 2, 1] + sig[node, 3, 1])
                cz = 0.25 * (sig[node, 0, 2] + sig[node, 1, 2] + sig[node, 2, 2] + sig[node, 3, 2])
                v0, v1, v2 = x0 - cx, x1 - cy, x2 - cz
                d = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
                a = rad[node]
                whole = d - a > rn[node] and a <= theta * d and cone[node] >= cone_min
                s_hi = 0.0
                if whole:  # the surface distance of the node's farthest pair, by the centroid's arc curvature
                    kc = ((nx0 - nmean[node, 0]) * v0 + (nx1 - nmean[node, 1]) * v1
                          + (nx2 - nmean[node, 2]) * v2) / (d * d)
                    s_hi = arc_length(d + a, 0.5 * kc * (d + a))
                use = 0
                open_mask = 0
                for c in range(3):
                    if not (mask >> c) & 1 or d - a > cutoff[c]:  # chord <= surface distance: all beyond the cutoff
                        continue
                    if whole and s_hi <= cutoff[c]:
                        use |= 1 << c
                    else:
                        open_mask |= 1 << c
                if use:
                    w = 0.25 * P[node]
                    for q in range(4):
                        ch, s, kn, knp = pair_geometry(x0, x1, x2, nx0, nx1, nx2, sig[node, q, 0], sig[node, q, 1],
                                                       sig[node, q, 2], nsig[node, q, 0], nsig[node, q, 1],
                                                       nsig[node, q, 2], ssig[node], q)
                        ka, t2 = fitted_geometry(kind, kn, knp, ssig[node], q, x0, x1, x2, nx0, nx1, nx2,
                                                 sig[node, q, 0], sig[node, q, 1], sig[node, q, 2], nsig[node, q, 0],
                                                 nsig[node, q, 1], nsig[node, q, 2])
                        wq = w
                        if use_drift:
                            wq *= drift_factor(x0 - sig[node, q, 0], x1 - sig[node, q, 1], x2 - sig[node, q, 2],
                                               nsig[node, q, 0], nsig[node, q, 1], nsig[node, q, 2], ndrift[node, 0],
                                               ndrift[node, 1], ndrift[node, 2], s, dslope, dlog0, dlogstep, dst)
                        for c in range(3):
                            if (use >> c) & 1:
                                kv = kernel_value(kind, c, ch, s, ka, knp, t2, srow[node], params)
                                if use_n:
                                    kv *= near_factor(nlog, c, s * params.sigma_t[c], dlog0, dlogstep)
                                acc[c] += wq * kv
                    n_clu += 1
                if open_mask == 0:
                    continue
                if node >= first_leaf:
                    for j in range(lo[node], hi[node]):
                        if power[j] <= 0.0:
                            continue
                        ch, s, kn, knp = pair_geometry(x0, x1, x2, nx0, nx1, nx2, pos[j, 0], pos[j, 1], pos[j, 2],
                                                       nrm[j, 0], nrm[j, 1], nrm[j, 2], shape, j)
                        if ch <= near[j]:
                            continue
                        ka, t2 = fitted_geometry(kind, kn, knp, shape, j, x0, x1, x2, nx0, nx1, nx2, pos[j, 0],
                                                 pos[j, 1], pos[j, 2], nrm[j, 0], nrm[j, 1], nrm[j, 2])
                        pj = power[j]
                        if use_drift:
                            pj *= drift_factor(x0 - pos[j, 0], x1 - pos[j, 1], x2 - pos[j, 2], nrm[j, 0], nrm[j, 1],
                                               nrm[j, 2], drift[j, 0], drift[j, 1], drift[j, 2], s, dslope, dlog0,
                                               dlogstep, dst)
                        for c in range(3):
                            if (open_mask >> c) & 1 and s <= cutoff[c]:
                                kv = kernel_value(kind, c, ch, s, ka, knp, t2, sph[j], params)
                                if use_n:
                                    kv *= near_factor(nlog, c, s * params.sigma_t[c], dlog0, dlogstep)
                                acc[c] += pj * kv
                        n_leaf += 1
                    continue
                stack[top], smask[top] = 2 * node + 1, open_mask
                stack[top + 1], smask[top + 1] = 2 * node + 2, open_mask
                top += 2
            for c in range(3):
                M[t, c] = acc[rep[c]]
            counts[t, 0] = n_leaf
            counts[t, 1] = n_clu
        return M, counts

    return far_traverse


#: the far-field traversal compiled per kernel kind (serial over a block of receivers), each on its first use:
#: ``FAR_TRAVERSE[kind](recv, rnrm, order, tree, clusters, opening, rep, params, factors)``
FAR_TRAVERSE = per_kernel(_traverse_of, nogil=True)
