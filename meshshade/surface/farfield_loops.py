"""Compiled loops of the clustered far-field sum (meshshade/surface/farfield.py): k-d tree build, node moments,
traversal.

Everything here is float64 on plain arrays. Distances are in mm; the dipole is evaluated in optical units per
channel (``r_opt = r_mm * sigma_t'``, z_r = 1) and rescaled by ``sigma_t'**2`` to 1/mm^2, exactly as
:func:`meshshade.kernels.dipole.dipole_profile` does (docs/physics.md eq. (15)).

Cluster approximation and its error bound (optical units). Write the dipole as a function of t = r^2/2,
R(r) = G(t), with ``d_z = sqrt(r^2 + z^2)`` for z in {z_r = 1, z_v} and x = mu d:

    G     =  alpha'/(4 pi) sum_z z g(d_z),    g(d) = (x + 1) e^{-x} / d^3
    G'    = -alpha'/(4 pi) sum_z z p(d_z),    p(d) = (x^2 + 3x + 3) e^{-x} / d^5
    G''   =  alpha'/(4 pi) sum_z z q(d_z),    q(d) = (x^3 + 6x^2 + 15x + 15) e^{-x} / d^7
    G'''  = -alpha'/(4 pi) sum_z z w(d_z),    w(d) = (x^4 + 10x^3 + 45x^2 + 105x + 105) e^{-x} / d^9

(dd/dt = 1/d, so dg/dt = -p, dp/dt = -q, dq/dt = -w). For f(y) = R(|y - x|) and v = y - x:
grad f = G' v, Hess f = G'' v v^T + G' I, D^3 f[u, u, u] = G''' (v.u)^3 + 3 G'' (v.u) |u|^2.

A cluster of sources y_j with powers P_j (total P), power-weighted centroid c, second-moment tensor
Q = sum_j P_j (y_j - c)(y_j - c)^T, radius a about c and mean cubed radius m3 = sum_j P_j |y_j - c|^3 / P, seen
from x at distance d = |c - x|, is replaced by its Taylor expansion about c to second order (the first-order
term vanishes at the power-weighted centroid):

    sum_j P_j R(|x - y_j|) ~ P G + 1/2 [G'' (c - x)^T Q (c - x) + G' tr Q]        (G, G', G'' at d)

The Lagrange remainder is at most ``P m3/6 * T(d - a)``: |D^3 f[u,u,u]| <= |u|^3 (|G'''| r^3 + 3 |G''| r) and
r <= d_z give ``T(r) = alpha'/(4 pi) sum_z z tau(d_z(r))`` with ``tau(d) = w d^3 + 3 q d =
(x^4 + 13x^3 + 63x^2 + 150x + 150) e^{-x} / d^6``. tau decreases with d (d log tau/dd =
-mu (x^4 + 9x^3 + 24x^2 + 24x)/poly - 6/d < 0), so T(d - a) holds over the whole ball of radius a about c.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from meshshade.kernels.dipole import dipole_diffuse_reflectance

FOUR_PI = 4.0 * np.pi
#: relative margin on the near/cutoff radii for whole-cluster decisions (pairs at the boundary go to the leaves)
EDGE_RTOL = 1e-12
STACK_SIZE = 256


# --------------------------------------------------------------------------------------------------------------
# dipole in optical units (one channel: alpha' = al, mu = sigma_tr/sigma_t', z_r = 1, z_v = zv)
@njit(cache=True, inline="always")
def dipole_opt(r, al, mu, zv):
    """R_d / sigma_t'^2 at optical distance r: the kernels' closed form (dipole_diffuse_reflectance), z_r = 1."""
    return dipole_diffuse_reflectance(r, al, mu, 1.0, zv)


@njit(cache=True)
def dipole_taylor_opt(r, al, mu, zv):
    """(G, G', G''): the dipole at optical distance r and its first two derivatives in t = r^2/2."""
    dr = np.sqrt(r * r + 1.0)
    dv = np.sqrt(r * r + zv * zv)
    er = np.exp(-mu * dr)
    ev = zv * np.exp(-mu * dv)
    xr, xv = mu * dr, mu * dv
    k = al / FOUR_PI
    G = k * ((xr + 1.0) * er / dr**3 + (xv + 1.0) * ev / dv**3)
    G1 = -k * (((xr + 3.0) * xr + 3.0) * er / dr**5 + ((xv + 3.0) * xv + 3.0) * ev / dv**5)
    G2 = k * ((((xr + 6.0) * xr + 15.0) * xr + 15.0) * er / dr**7
              + (((xv + 6.0) * xv + 15.0) * xv + 15.0) * ev / dv**7)
    return G, G1, G2


@njit(cache=True, inline="always")
def _tau_poly(d, mu):
    x = mu * d
    return ((((x + 13.0) * x + 63.0) * x + 150.0) * x + 150.0) / d**6


@njit(cache=True, inline="always")
def _g_poly(d, mu):
    return (mu * d + 1.0) / d**3


@njit(cache=True)
def third_derivative_bound_opt(r_lo, al, mu, zv):
    """T(r_lo) >= |D^3 f[u,u,u]|/|u|^3 for f(y) = R(|x - y|) wherever |x - y| >= r_lo (optical units)."""
    dr = np.sqrt(r_lo * r_lo + 1.0)
    dv = np.sqrt(r_lo * r_lo + zv * zv)
    return al / FOUR_PI * (_tau_poly(dr, mu) * np.exp(-mu * dr) + zv * _tau_poly(dv, mu) * np.exp(-mu * dv))


@njit(cache=True, inline="always")
def cluster_bound(m3_6, r_lo, r_hi, al, mu, zv, tau):
    """The cluster's error bound m3/6 T(r_lo) (optical units, per unit power) if it is at most tau R(r_hi),
    else -1 (open the cluster). The test is a ratio scaled by exp(mu d_r(r_hi)), so nothing under- or overflows
    to a wrong decision (an overflow to inf rejects)."""
    lr = np.sqrt(r_lo * r_lo + 1.0)
    hr = np.sqrt(r_hi * r_hi + 1.0)
    hv = np.sqrt(r_hi * r_hi + zv * zv)
    t_r = _tau_poly(lr, mu)
    g_r, g_v = _g_poly(hr, mu), zv * _g_poly(hv, mu)
    if m3_6 * t_r > tau * (g_r + g_v):  # exp-free lower bound of the ratio (exp(mu(hr - lr)) >= 1): reject
        return -1.0
    lv = np.sqrt(r_lo * r_lo + zv * zv)
    num = t_r * np.exp(mu * (hr - lr)) + zv * _tau_poly(lv, mu) * np.exp(mu * (hr - lv))
    den = g_r + g_v * np.exp(-mu * (hv - hr))
    if not m3_6 * num <= tau * den:
        return -1.0
    return al / FOUR_PI * m3_6 * num * np.exp(-mu * hr)  # = m3/6 T(r_lo)


# --------------------------------------------------------------------------------------------------------------
# k-d tree (implicit complete binary tree: node i has children 2i+1, 2i+2; each node is a contiguous range)
@njit(cache=True)
def tree_depth(k, leaf_size):
    depth = 0
    while (k + (1 << depth) - 1) >> depth > leaf_size:
        depth += 1
    return depth


@njit(cache=True)
def node_ranges(k, depth):
    n_nodes = (1 << (depth + 1)) - 1
    lo = np.empty(n_nodes, np.int64)
    hi = np.empty(n_nodes, np.int64)
    lo[0], hi[0] = 0, k
    for i in range((1 << depth) - 1):
        mid = (lo[i] + hi[i]) // 2
        lo[2 * i + 1], hi[2 * i + 1] = lo[i], mid
        lo[2 * i + 2], hi[2 * i + 2] = mid, hi[i]
    return lo, hi


@njit(cache=True)
def kd_permutation(pos, depth, lo, hi):
    """Order of the points such that every node's range is split at its median along its widest axis.

    Serial: with parallel=True (a prange over each level's nodes) it measured slower on 2 cores (2.5k points:
    100 ms against 1-4 ms; 164k: 460-570 ms against 330-360 ms) and took longer to compile."""
    perm = np.arange(pos.shape[0])
    for level in range(depth):
        first = (1 << level) - 1
        for t in range(1 << level):
            i = first + t
            a, b = lo[i], hi[i]
            if b - a < 2:
                continue
            sub = perm[a:b].copy()
            best, axis = -1.0, 0
            for ax in range(3):
                v = pos[sub, ax]
                ext = v.max() - v.min()
                if ext > best:
                    best, axis = ext, ax
            order = np.argsort(pos[sub, axis], kind="mergesort")
            perm[a:b] = sub[order]
    return perm


@njit(cache=True, nogil=True)
def node_moments(pos, power, lo, hi):
    """Per node and channel: total power P, power-weighted centroid C, bounding radius A about C (exact max
    distance to the node's points), second-moment tensor Q = sum_j P_j (y_j - C)(y_j - C)^T as
    (xx, yy, zz, xy, xz, yz) [W mm^2] and mean cubed distance M3 = sum_j P_j |y_j - C|^3 / P [mm^3].

    A channel without power gets the plain mean as its centre (it is skipped in the traversal anyway).
    Cost O(k log k): every point belongs to one node per level.
    """
    n_nodes = lo.shape[0]
    nc = power.shape[1]
    P = np.zeros((n_nodes, nc))
    C = np.zeros((n_nodes, nc, 3))
    A = np.zeros((n_nodes, nc))
    Q = np.zeros((n_nodes, nc, 6))
    M3 = np.zeros((n_nodes, nc))
    for i in range(n_nodes):
        a, b = lo[i], hi[i]
        if b <= a:
            continue
        for c in range(nc):
            w = 0.0
            s0 = s1 = s2 = 0.0
            for j in range(a, b):
                w += power[j, c]
                s0 += power[j, c] * pos[j, 0]
                s1 += power[j, c] * pos[j, 1]
                s2 += power[j, c] * pos[j, 2]
            if w > 0.0:
                cx, cy, cz = s0 / w, s1 / w, s2 / w
            else:
                cx = cy = cz = 0.0
                for j in range(a, b):
                    cx += pos[j, 0]
                    cy += pos[j, 1]
                    cz += pos[j, 2]
                cx, cy, cz = cx / (b - a), cy / (b - a), cz / (b - a)
            rmax, m3 = 0.0, 0.0
            qxx = qyy = qzz = qxy = qxz = qyz = 0.0
            for j in range(a, b):
                dx, dy, dz = pos[j, 0] - cx, pos[j, 1] - cy, pos[j, 2] - cz
                r2 = dx * dx + dy * dy + dz * dz
                if r2 > rmax:
                    rmax = r2
                pj = power[j, c]
                m3 += pj * r2 * np.sqrt(r2)
                qxx += pj * dx * dx
                qyy += pj * dy * dy
                qzz += pj * dz * dz
                qxy += pj * dx * dy
                qxz += pj * dx * dz
                qyz += pj * dy * dz
            P[i, c] = w
            C[i, c, 0], C[i, c, 1], C[i, c, 2] = cx, cy, cz
            A[i, c] = np.sqrt(rmax)
            Q[i, c, 0], Q[i, c, 1], Q[i, c, 2] = qxx, qyy, qzz
            Q[i, c, 3], Q[i, c, 4], Q[i, c, 5] = qxy, qxz, qyz
            M3[i, c] = m3 / w if w > 0.0 else 0.0
    return P, C, A, Q, M3


# --------------------------------------------------------------------------------------------------------------
@njit(cache=True, nogil=True)
def traverse(recv, order, pos, power, lo, hi, first_leaf, P, C, A, Q, M3, r_near, cutoff, st, al, mu, zv, tau,
             budget_share, nlog, nl0, nstep):
    """Clustered far-field sum for the receivers ``recv[order]`` (a block of them, in an order with locality; the
    caller runs blocks on the pacing threads, :func:`meshshade.pacing.run_in_blocks`).

    A cluster wholly inside the annulus r_near < r <= cutoff is accepted when its Taylor remainder bound E is at
    most ``(1 - budget_share) tau`` times its own lower bound P R(d + a), or, failing that, at most its share of
    a global budget ``budget_share tau L P / P_total`` where L = (sum so far) - (bounds so far) <= M_exact is a
    running lower bound (the traversal goes nearest child first so that L grows fast). A cluster that lies past
    r_near but straddles the cutoff may use the budget too, with E + P R(cutoff) (the most the sources beyond the
    cutoff can add) in place of E. Summed: error <= (1 - share) tau M_exact + share tau M_exact = tau M_exact.

    With ``nlog`` (nc, m) non-empty (the near field "beam", docs/physics.md eq. (80)), each channel's dipole is
    multiplied by the near-field factor N(r) = exp(nlog[c]) interpolated at ln(r sigma_t') on the grid
    nl0 + i nstep: per pair at leaves, at the centroid distance for an accepted cluster (its bound, that of the
    dipole, scaled alike).

    Returns, per receiver of ``order`` (n = len(order)): M (n, 3) W/mm^2, the summed error bounds of the accepted
    clusters (n, 3) W/mm^2, and counts (n, 4): exact pair evaluations at leaves, clusters accepted
    (channel-wise), nodes visited, clusters accepted from the budget.
    """
    n = order.shape[0]
    nc = power.shape[1]
    M = np.zeros((n, nc))
    E = np.zeros((n, nc))
    counts = np.zeros((n, 4), np.int64)
    rn_in = np.empty(nc)  # a cluster wholly inside this is skipped
    rn_out = np.empty(nc)  # a cluster wholly beyond this is past the near radius
    cut_in = np.empty(nc)
    cut_out = np.empty(nc)
    r_cut = np.empty(nc)  # R(cutoff), optical units
    per_power = np.empty(nc)  # budget_share tau / (P_total sigma_t'^2)
    for c in range(nc):
        slack = EDGE_RTOL * cutoff[c]
        rn_in[c] = r_near[c] - EDGE_RTOL * r_near[c] - slack
        rn_out[c] = r_near[c] + EDGE_RTOL * r_near[c] + slack
        cut_in[c] = cutoff[c] - slack
        cut_out[c] = cutoff[c] + slack
        r_cut[c] = dipole_opt(cutoff[c] * st[c], al[c], mu[c], zv[c])
        per_power[c] = budget_share * tau / (P[0, c] * st[c] * st[c]) if P[0, c] > 0.0 else 0.0
    tau_own = (1.0 - budget_share) * tau
    full = (1 << nc) - 1
    use_n = nlog.shape[1] > 0
    for t in range(n):
        o = order[t]
        x0, x1, x2 = recv[o, 0], recv[o, 1], recv[o, 2]
        stack_node = np.empty(STACK_SIZE, np.int64)
        stack_mask = np.empty(STACK_SIZE, np.int64)
        stack_node[0], stack_mask[0] = 0, full
        top = 1
        n_pairs = n_clusters = n_visits = n_budget = 0
        m_acc = np.zeros(nc)
        e_acc = np.zeros(nc)
        while top > 0:
            top -= 1
            node, mask = stack_node[top], stack_mask[top]
            n_visits += 1
            leaf = node >= first_leaf
            open_mask = 0
            for c in range(nc):
                if not (mask >> c) & 1 or P[node, c] <= 0.0:
                    continue
                dx, dy, dz = x0 - C[node, c, 0], x1 - C[node, c, 1], x2 - C[node, c, 2]
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                a = A[node, c]
                if d + a < rn_in[c] or d - a > cut_out[c]:
                    continue  # wholly inside the near zone or wholly beyond the cutoff
                if d - a > rn_out[c]:
                    s = st[c]
                    m3_6 = M3[node, c] * s * s * s / 6.0
                    r_lo, r_hi = (d - a) * s, (d + a) * s
                    inside = d + a < cut_in[c]
                    bound = cluster_bound(m3_6, r_lo, r_hi, al[c], mu[c], zv[c], tau_own) if inside else -1.0
                    if bound < 0.0:
                        budget = (m_acc[c] - e_acc[c]) * per_power[c]  # optical units, per unit power
                        if budget > 0.0:
                            extra = 0.0 if inside else r_cut[c]
                            if extra < budget:
                                e = m3_6 * third_derivative_bound_opt(r_lo, al[c], mu[c], zv[c]) + extra
                                if e <= budget:
                                    bound = e
                                    n_budget += 1
                    if bound >= 0.0:
                        G, G1, G2 = dipole_taylor_opt(d * s, al[c], mu[c], zv[c])
                        q = Q[node, c]
                        vqv = (q[0] * dx * dx + q[1] * dy * dy + q[2] * dz * dz
                               + 2.0 * (q[3] * dx * dy + q[4] * dx * dz + q[5] * dy * dz))
                        # optical units: Q s^2 and v s, so vQv s^4 and tr Q s^2; the sum is rescaled by s^2
                        quad = 0.5 * (G2 * vqv * s**4 + G1 * (q[0] + q[1] + q[2]) * s * s)
                        nf = near_factor(nlog, c, d * s, nl0, nstep) if use_n else 1.0
                        m_acc[c] += (P[node, c] * G + quad) * s * s * nf
                        e_acc[c] += P[node, c] * bound * s * s * nf
                        n_clusters += 1
                        continue
                open_mask |= 1 << c
            if open_mask == 0:
                continue
            if leaf:
                for j in range(lo[node], hi[node]):
                    dx, dy, dz = x0 - pos[j, 0], x1 - pos[j, 1], x2 - pos[j, 2]
                    r = np.sqrt(dx * dx + dy * dy + dz * dz)
                    for c in range(nc):
                        if (open_mask >> c) & 1 and power[j, c] > 0.0 and r_near[c] < r <= cutoff[c]:
                            s = st[c]
                            nf = near_factor(nlog, c, r * s, nl0, nstep) if use_n else 1.0
                            m_acc[c] += power[j, c] * dipole_opt(r * s, al[c], mu[c], zv[c]) * s * s * nf
                            n_pairs += 1
            else:  # nearer child on top of the stack (by the first open channel's centroids)
                c0 = 0
                while not (open_mask >> c0) & 1:
                    c0 += 1
                near, far = 2 * node + 1, 2 * node + 2
                d_near = (x0 - C[near, c0, 0]) ** 2 + (x1 - C[near, c0, 1]) ** 2 + (x2 - C[near, c0, 2]) ** 2
                d_far = (x0 - C[far, c0, 0]) ** 2 + (x1 - C[far, c0, 1]) ** 2 + (x2 - C[far, c0, 2]) ** 2
                if d_far < d_near:
                    near, far = far, near
                stack_node[top], stack_mask[top] = far, open_mask
                stack_node[top + 1], stack_mask[top + 1] = near, open_mask
                top += 2
        for c in range(nc):
            M[t, c] = m_acc[c]
            E[t, c] = e_acc[c]
        counts[t, 0], counts[t, 1], counts[t, 2], counts[t, 3] = n_pairs, n_clusters, n_visits, n_budget
    return M, E, counts


@njit(cache=True, inline="always")
def log_grid_interp(row, r_opt, l0, step):
    """``row`` (m,) tabulated on the grid l0 + i step of ln r, interpolated linearly at ln ``r_opt`` (end values
    beyond, the first at r <= 0)."""
    m = row.shape[0]
    x = (np.log(r_opt) - l0) / step if r_opt > 0.0 else 0.0
    if x <= 0.0:
        return row[0]
    if x >= m - 1:
        return row[m - 1]
    i = int(x)
    f = x - i
    return row[i] * (1.0 - f) + row[i + 1] * f


@njit(cache=True, inline="always")
def near_factor(nlog, c, r_opt, l0, step):
    """The near field's N(r) = exp(nlog[c]) with ln N interpolated on the grid of :func:`log_grid_interp`."""
    return np.exp(log_grid_interp(nlog[c], r_opt, l0, step))


@njit(cache=True)
def accumulate_pairs(M, recv, pos, power, ii, jj, r_near, cutoff, st, al, mu, zv, nlog, nl0, nstep):
    """Direct sum over candidate pairs (receiver ii, source jj) with the exact masks r_near < r <= cutoff (times
    the near-field factor, as :func:`traverse`).

    Returns the number of (pair, channel) kernel evaluations."""
    nc = power.shape[1]
    count = 0
    use_n = nlog.shape[1] > 0
    for p in range(ii.shape[0]):
        i, j = ii[p], jj[p]
        dx, dy, dz = recv[i, 0] - pos[j, 0], recv[i, 1] - pos[j, 1], recv[i, 2] - pos[j, 2]
        r = np.sqrt(dx * dx + dy * dy + dz * dz)
        for c in range(nc):
            if power[j, c] > 0.0 and r_near[c] < r <= cutoff[c]:
                s = st[c]
                nf = near_factor(nlog, c, r * s, nl0, nstep) if use_n else 1.0
                M[i, c] += power[j, c] * dipole_opt(r * s, al[c], mu[c], zv[c]) * s * s * nf
                count += 1
    return count
