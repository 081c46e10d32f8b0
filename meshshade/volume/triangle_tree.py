"""A hierarchy of a mesh's triangles for the volume's inside: the generalised winding number and the distance to
the surface at many points, on every core (docs/physics.md §15.2).

The triangles are ordered along a Morton (Z-order) curve of their centroids and split top-down where their codes'
highest differing bit changes (a linear BVH, Lauterbach et al. 2009: each node a cell of the Morton octree), down
to leaves of at most LEAF triangles. Each node keeps its bounding box, the moments of its triangles' area-weighted
normals about its area-weighted centroid ``p`` (:func:`_node_data`) and the radius of a ball about ``p`` holding
its triangles.

*Winding number* (Jacobson, Kavan and Sorkine-Hornung 2013; Barill, Dickson, Schmidt, Levin and Jacobson 2018,
"Fast winding numbers for soups and clouds"): w(q) = sum_t Omega_t(q) / (4 pi), Omega_t the signed solid angle of
triangle t seen from q (van Oosterom and Strackee's formula). A node farther than ``beta`` times its radius takes
the expansion of its triangles' solid angle about p (each triangle a sheet of dipoles, ``f(r) = r / |r|^3``
expanded to second order in the triangles' offsets from p: :func:`_far_solid_angle`, Barill et al.'s order 2),
nearer ones are opened, and leaves near q are summed exactly. This is libigl's ``fast_winding_number`` (expansion
order 2, the same accuracy at the same beta) as a compiled loop that releases the interpreter, so blocks of points
run on worker threads.

*Distance*: the unsigned distance from q to the nearest triangle within a bound (Ericson's closest point on a
triangle), nodes whose box lies farther than the best distance so far skipped. *Closest point*: the same search
returning the nearest triangle (its input index) and the barycentrics of its nearest point
(:meth:`TriangleTree.closest`; :func:`closest_on` for one point inside compiled code, as the Monte Carlo's painted
medium reads it).

Pure array work (numba); no I/O.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from meshshade.pacing import run_in_blocks

__all__ = ["TriangleTree", "LEAF", "morton_order", "prefix_tree", "winding_at", "closest_on"]

#: triangles per leaf
LEAF = 8
_INV_4PI = 1.0 / (4.0 * math.pi)


def morton_order(centroids):
    """(order, sorted codes): the points ``centroids`` (t, 3) sorted along the Z-order curve of their box (21 bits
    per axis)."""
    lo = centroids.min(axis=0)
    ext = float(np.max(centroids.max(axis=0) - lo))
    q = np.zeros(centroids.shape, dtype=np.uint64) if ext <= 0 else \
        np.minimum((centroids - lo) * ((2 ** 21 - 1) / ext), 2 ** 21 - 1).astype(np.uint64)
    code = np.zeros(centroids.shape[0], dtype=np.uint64)
    for d in range(3):
        x = q[:, d]
        x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
        x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
        x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
        x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
        x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
        code |= x << np.uint64(d)
    order = np.argsort(code, kind="stable")
    return order, code[order]


@numba.njit(cache=True, nogil=True)
def prefix_tree(codes, leaf):
    """(lo, hi, child) of the binary tree over the sorted Morton ``codes``: a node's triangles lo..hi are split
    where their highest differing bit changes (each node a cell of the Morton octree: Lauterbach et al.'s linear
    BVH), at the middle where their codes are equal; a node of at most ``leaf`` triangles is a leaf (child -1).
    Children are numbered after their parent, the second right after the first."""
    n = codes.size
    cap = max(1, 2 * n)
    lo = np.zeros(cap, np.int64)
    hi = np.zeros(cap, np.int64)
    child = np.full(cap, -1, np.int64)
    stack = np.zeros(256, np.int64)
    lo[0], hi[0] = 0, n
    n_nodes = 1
    top = 1
    stack[0] = 0
    while top > 0:
        top -= 1
        nd = stack[top]
        a, b = lo[nd], hi[nd]
        if b - a <= leaf:
            continue
        x = codes[a] ^ codes[b - 1]
        if x == 0:
            m = (a + b) // 2
        else:
            bit = 63
            while (x >> np.uint64(bit)) & np.uint64(1) == 0:
                bit -= 1
            # the first code in a..b with that bit set (the codes share every higher bit)
            u, v = a, b - 1
            while u < v:
                w = (u + v) // 2
                if (codes[w] >> np.uint64(bit)) & np.uint64(1):
                    v = w
                else:
                    u = w + 1
            m = u
        c = n_nodes
        n_nodes += 2
        child[nd] = c
        lo[c], hi[c] = a, m
        lo[c + 1], hi[c + 1] = m, b
        stack[top] = c
        stack[top + 1] = c + 1
        top += 2
    return lo[:n_nodes], hi[:n_nodes], child[:n_nodes]


#: the symmetric pairs (j, k) of the third-order moment S[i, jk]
_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


@numba.njit(cache=True, nogil=True)
def _node_data(A, B, C, lo, hi, child, box, N, M, S, p, rad, area):
    """Each node's box, moments N, M, S about its area-weighted centroid p, radius and area; children before
    parents (reverse numbering). With a_t n_t a triangle's area-weighted normal, c_t its centroid and d = c_t - p:
    N_i = sum a n_i, M_ij = sum a n_i d_j, S_ijk = sum a n_i (d_j d_k + C_jk), C the triangle's own second area
    moment about its centroid per unit area, (1/12) sum over its corners of (v - c_t)(v - c_t)^T."""
    for i in range(lo.size - 1, -1, -1):
        for d in range(3):
            box[i, d] = np.inf
            box[i, 3 + d] = -np.inf
        tot = 0.0
        px = py = pz = 0.0
        c0 = child[i]
        if c0 < 0:
            for t in range(lo[i], hi[i]):
                ux, uy, uz = B[t, 0] - A[t, 0], B[t, 1] - A[t, 1], B[t, 2] - A[t, 2]
                vx, vy, vz = C[t, 0] - A[t, 0], C[t, 1] - A[t, 1], C[t, 2] - A[t, 2]
                nx, ny, nz = 0.5 * (uy * vz - uz * vy), 0.5 * (uz * vx - ux * vz), 0.5 * (ux * vy - uy * vx)
                at = math.sqrt(nx * nx + ny * ny + nz * nz)
                N[i, 0] += nx
                N[i, 1] += ny
                N[i, 2] += nz
                tot += at
                px += at * (A[t, 0] + B[t, 0] + C[t, 0]) / 3.0
                py += at * (A[t, 1] + B[t, 1] + C[t, 1]) / 3.0
                pz += at * (A[t, 2] + B[t, 2] + C[t, 2]) / 3.0
                for d in range(3):
                    box[i, d] = min(box[i, d], A[t, d], B[t, d], C[t, d])
                    box[i, 3 + d] = max(box[i, 3 + d], A[t, d], B[t, d], C[t, d])
        else:
            for j in (c0, c0 + 1):
                tot += area[j]
                px += area[j] * p[j, 0]
                py += area[j] * p[j, 1]
                pz += area[j] * p[j, 2]
                for d in range(3):
                    box[i, d] = min(box[i, d], box[j, d])
                    box[i, 3 + d] = max(box[i, 3 + d], box[j, 3 + d])
                    N[i, d] += N[j, d]
        if tot > 0.0:
            px, py, pz = px / tot, py / tot, pz / tot
        else:
            px = 0.5 * (box[i, 0] + box[i, 3])
            py = 0.5 * (box[i, 1] + box[i, 4])
            pz = 0.5 * (box[i, 2] + box[i, 5])
        p[i, 0], p[i, 1], p[i, 2] = px, py, pz
        area[i] = tot
        r = 0.0
        e = np.empty(3)
        cov = np.empty(6)
        n = np.empty(3)
        if c0 < 0:
            for t in range(lo[i], hi[i]):
                ux, uy, uz = B[t, 0] - A[t, 0], B[t, 1] - A[t, 1], B[t, 2] - A[t, 2]
                vx, vy, vz = C[t, 0] - A[t, 0], C[t, 1] - A[t, 1], C[t, 2] - A[t, 2]
                n[0], n[1], n[2] = 0.5 * (uy * vz - uz * vy), 0.5 * (uz * vx - ux * vz), 0.5 * (ux * vy - uy * vx)
                for d in range(3):
                    e[d] = (A[t, d] + B[t, d] + C[t, d]) / 3.0
                for q in range(6):
                    j, k = _PAIRS[q]
                    cov[q] = ((A[t, j] - e[j]) * (A[t, k] - e[k]) + (B[t, j] - e[j]) * (B[t, k] - e[k])
                              + (C[t, j] - e[j]) * (C[t, k] - e[k])) / 12.0
                e[0] -= px
                e[1] -= py
                e[2] -= pz
                for a in range(3):
                    for b in range(3):
                        M[i, 3 * a + b] += n[a] * e[b]
                    for q in range(6):
                        j, k = _PAIRS[q]
                        S[i, 6 * a + q] += n[a] * (e[j] * e[k] + cov[q])
                for X in (A, B, C):
                    dx, dy, dz = X[t, 0] - px, X[t, 1] - py, X[t, 2] - pz
                    r = max(r, math.sqrt(dx * dx + dy * dy + dz * dz))
        else:
            for j0 in (c0, c0 + 1):
                e[0], e[1], e[2] = p[j0, 0] - px, p[j0, 1] - py, p[j0, 2] - pz
                # moving a child's expansion centre from p_j to p: d -> d + e
                for a in range(3):
                    for b in range(3):
                        M[i, 3 * a + b] += M[j0, 3 * a + b] + N[j0, a] * e[b]
                    for q in range(6):
                        j, k = _PAIRS[q]
                        S[i, 6 * a + q] += (S[j0, 6 * a + q] + M[j0, 3 * a + j] * e[k] + M[j0, 3 * a + k] * e[j]
                                            + N[j0, a] * e[j] * e[k])
                r = max(r, math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) + rad[j0])
            # or the farthest corner of the node's box, if nearer
            bx = max(px - box[i, 0], box[i, 3] - px)
            by = max(py - box[i, 1], box[i, 4] - py)
            bz = max(pz - box[i, 2], box[i, 5] - pz)
            r = min(r, math.sqrt(bx * bx + by * by + bz * bz))
        rad[i] = r


@numba.njit(cache=True, inline="always")
def _far_solid_angle(N, M, S, nd, rx, ry, rz):
    """The solid angle of node ``nd``'s triangles seen from a point at -r of its centre (r = p - q), by the
    expansion of f(r) = r / |r|^3 to second order in the offsets: N . f + M : grad f + S : grad grad f / 2."""
    r2 = rx * rx + ry * ry + rz * rz
    r = math.sqrt(r2)
    i3 = 1.0 / (r2 * r)
    i5 = i3 / r2
    i7 = i5 / r2
    out = (N[nd, 0] * rx + N[nd, 1] * ry + N[nd, 2] * rz) * i3
    # grad f_ij = delta_ij / r^3 - 3 r_i r_j / r^5
    tr = M[nd, 0] + M[nd, 4] + M[nd, 8]
    rmr = rx * (M[nd, 0] * rx + M[nd, 1] * ry + M[nd, 2] * rz) + \
        ry * (M[nd, 3] * rx + M[nd, 4] * ry + M[nd, 5] * rz) + \
        rz * (M[nd, 6] * rx + M[nd, 7] * ry + M[nd, 8] * rz)
    out += tr * i3 - 3.0 * rmr * i5
    # grad grad f_ijk = -3 (delta_ij r_k + delta_ik r_j + delta_jk r_i) / r^5 + 15 r_i r_j r_k / r^7, with S
    # symmetric in jk: S : that = -3 (2 sum_ik r_k S_iik + sum_i r_i sum_j S_ijj) / r^5 + 15 r.S[r, r] / r^7
    rr = (rx, ry, rz)
    lin = 0.0
    cub = 0.0
    for a in range(3):
        s00, s01, s02 = S[nd, 6 * a], S[nd, 6 * a + 1], S[nd, 6 * a + 2]
        s11, s12, s22 = S[nd, 6 * a + 3], S[nd, 6 * a + 4], S[nd, 6 * a + 5]
        # sum_k r_k S_a a k  (row a of the symmetric matrix S_a.. dotted with r)
        if a == 0:
            lin += 2.0 * (rx * s00 + ry * s01 + rz * s02)
        elif a == 1:
            lin += 2.0 * (rx * s01 + ry * s11 + rz * s12)
        else:
            lin += 2.0 * (rx * s02 + ry * s12 + rz * s22)
        lin += rr[a] * (s00 + s11 + s22)
        cub += rr[a] * (rx * rx * s00 + ry * ry * s11 + rz * rz * s22
                        + 2.0 * (rx * ry * s01 + rx * rz * s02 + ry * rz * s12))
    out += 0.5 * (-3.0 * lin * i5 + 15.0 * cub * i7)
    return out


@numba.njit(cache=True, inline="always")
def _solid_angle(ax, ay, az, bx, by, bz, cx, cy, cz):
    """Signed solid angle of the triangle (a, b, c) (corners relative to the viewpoint): van Oosterom and
    Strackee's formula."""
    la = math.sqrt(ax * ax + ay * ay + az * az)
    lb = math.sqrt(bx * bx + by * by + bz * bz)
    lc = math.sqrt(cx * cx + cy * cy + cz * cz)
    det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
    den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (ax * cx + ay * cy + az * cz) * lb + \
        (bx * cx + by * cy + bz * cz) * la
    return 2.0 * math.atan2(det, den)


@numba.njit(cache=True, inline="always")
def winding_at(x, y, z, root, A, B, C, lo, hi, child, N, M, S, p, rad, beta, stack):
    """The winding number at (x, y, z) of the tree whose root is node ``root`` (module docstring; ``stack`` an
    int64 work array of 256; trees packed one after another keep their own roots)."""
    w = 0.0
    top = 1
    stack[0] = root
    while top > 0:
        top -= 1
        nd = stack[top]
        rx, ry, rz = p[nd, 0] - x, p[nd, 1] - y, p[nd, 2] - z
        r2 = rx * rx + ry * ry + rz * rz
        if r2 > (beta * rad[nd]) ** 2:
            w += _far_solid_angle(N, M, S, nd, rx, ry, rz)
            continue
        c0 = child[nd]
        if c0 < 0:
            for t in range(lo[nd], hi[nd]):
                w += _solid_angle(A[t, 0] - x, A[t, 1] - y, A[t, 2] - z, B[t, 0] - x, B[t, 1] - y, B[t, 2] - z,
                                  C[t, 0] - x, C[t, 1] - y, C[t, 2] - z)
            continue
        stack[top] = c0
        stack[top + 1] = c0 + 1
        top += 2
    return w * _INV_4PI


@numba.njit(cache=True, nogil=True)
def _winding(P, A, B, C, lo, hi, child, N, M, S, p, rad, beta, out, q0, q1):
    """out[q] = the winding number at P[q] for q in q0..q1 (module docstring); node 0 is the root."""
    stack = np.empty(256, np.int64)
    for q in range(q0, q1):
        out[q] = winding_at(P[q, 0], P[q, 1], P[q, 2], 0, A, B, C, lo, hi, child, N, M, S, p, rad, beta, stack)


@numba.njit(cache=True, inline="always")
def _point_triangle_d2(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Squared distance from p to the triangle abc (Ericson, Real-Time Collision Detection, 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        qx, qy, qz = apx - v * abx, apy - v * aby, apz - v * abz
        return qx * qx + qy * qy + qz * qz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        qx, qy, qz = apx - w * acx, apy - w * acy, apz - w * acz
        return qx * qx + qy * qy + qz * qz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        qx, qy, qz = bpx - w * (cx - bx), bpy - w * (cy - by), bpz - w * (cz - bz)
        return qx * qx + qy * qy + qz * qz
    den = 1.0 / (va + vb + vc)
    v = vb * den
    w = vc * den
    qx, qy, qz = apx - v * abx - w * acx, apy - v * aby - w * acy, apz - v * abz - w * acz
    return qx * qx + qy * qy + qz * qz


@numba.njit(cache=True, nogil=True)
def _distance(P, A, B, C, lo, hi, child, box, bound, out, q0, q1):
    """out[q] = min(bound, distance from P[q] to the nearest triangle) for q in q0..q1."""
    stack = np.empty(256, np.int64)
    for q in range(q0, q1):
        x, y, z = P[q, 0], P[q, 1], P[q, 2]
        best = bound * bound
        top = 1
        stack[0] = 0
        while top > 0:
            top -= 1
            nd = stack[top]
            dx = max(box[nd, 0] - x, 0.0, x - box[nd, 3])
            dy = max(box[nd, 1] - y, 0.0, y - box[nd, 4])
            dz = max(box[nd, 2] - z, 0.0, z - box[nd, 5])
            if dx * dx + dy * dy + dz * dz >= best:
                continue
            c0 = child[nd]
            if c0 < 0:
                for t in range(lo[nd], hi[nd]):
                    d2 = _point_triangle_d2(x, y, z, A[t, 0], A[t, 1], A[t, 2], B[t, 0], B[t, 1], B[t, 2],
                                            C[t, 0], C[t, 1], C[t, 2])
                    best = min(best, d2)
                continue
            stack[top] = c0 + 1
            stack[top + 1] = c0
            top += 2
        out[q] = math.sqrt(best)


class TriangleTree:
    """The hierarchy of the triangles ``faces`` (F, 3) over ``vertices`` (V, 3) mm (module docstring):
    :meth:`winding` and :meth:`distance` at many points, in blocks on ``n_threads`` worker threads (default:
    :func:`meshshade.pacing.default_threads`)."""

    def __init__(self, vertices, faces, n_threads: int | None = None):
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        self.n_threads = n_threads
        self.n_tri = int(F.shape[0])
        if self.n_tri:
            order, codes = morton_order(V[F].mean(axis=1))
            F = F[order]
        else:
            order, codes = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.uint64)
        #: (t,) the input index of each of the tree's triangles (they are kept in Morton order)
        self.order = np.ascontiguousarray(order, dtype=np.int64)
        self.A, self.B, self.C = (np.ascontiguousarray(V[F[:, k]]) for k in range(3))
        self.lo, self.hi, self.child = prefix_tree(codes, LEAF)
        n = self.lo.size
        self.box = np.zeros((n, 6))
        self.N = np.zeros((n, 3))
        self.M = np.zeros((n, 9))
        self.S = np.zeros((n, 18))
        self.p = np.zeros((n, 3))
        self.rad = np.zeros(n)
        self.area = np.zeros(n)
        _node_data(self.A, self.B, self.C, self.lo, self.hi, self.child, self.box, self.N, self.M, self.S, self.p,
                   self.rad, self.area)

    def winding(self, points, beta: float = 2.0) -> np.ndarray:
        """(p,) generalised winding number at ``points`` (p, 3) mm; nodes farther than ``beta`` times their radius
        take their second-order expansion (libigl's accuracy scale: 2 is its recommended accuracy)."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(P.shape[0])
        if self.n_tri == 0 or P.shape[0] == 0:
            return out
        args = (P, self.A, self.B, self.C, self.lo, self.hi, self.child, self.N, self.M, self.S, self.p,
                self.rad, float(beta), out)
        run_in_blocks(lambda a, b: _winding(*args, a, b), P.shape[0], n_threads=self.n_threads, min_block=512)
        return out

    def distance(self, points, bound: float = np.inf) -> np.ndarray:
        """(p,) unsigned distance (mm) from ``points`` (p, 3) to the nearest triangle, at most ``bound``."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.full(P.shape[0], float(bound))
        if self.n_tri == 0 or P.shape[0] == 0:
            return out
        args = (P, self.A, self.B, self.C, self.lo, self.hi, self.child, self.box, float(bound), out)
        run_in_blocks(lambda a, b: _distance(*args, a, b), P.shape[0], n_threads=self.n_threads, min_block=512)
        return out

    def closest(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The nearest point of the triangles to each of ``points`` (p, 3) mm: ((p,) input triangle index, (p, 3)
        its barycentrics, (p,) distance mm); exact (:func:`closest_on`; ties go to the triangle met first)."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        face = np.full(P.shape[0], -1, dtype=np.int64)
        bary = np.zeros((P.shape[0], 3))
        dist = np.full(P.shape[0], np.inf)
        if self.n_tri == 0 or P.shape[0] == 0:
            return face, bary, dist
        args = (P, self.A, self.B, self.C, self.lo, self.hi, self.child, self.box, self.order, face, bary, dist)
        run_in_blocks(lambda a, b: _closest(*args, a, b), P.shape[0], n_threads=self.n_threads, min_block=512)
        return face, bary, dist


@numba.njit(cache=True, inline="always")
def closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """(squared distance, v, w): the point of the triangle abc nearest to p, a + v (b - a) + w (c - a) (Ericson,
    Real-Time Collision Detection, 5.1.5, with its barycentrics)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    v = w = 0.0
    if d1 <= 0.0 and d2 <= 0.0:
        pass
    else:
        bpx, bpy, bpz = px - bx, py - by, pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = px - cx, py - cy, pz - cz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            v = 1.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v = d1 / (d1 - d3)
        elif d6 >= 0.0 and d5 <= d6:
            w = 1.0
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            w = d2 / (d2 - d6)
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            v = 1.0 - w
        else:
            den = 1.0 / (va + vb + vc)
            v = vb * den
            w = vc * den
    qx = apx - v * abx - w * acx
    qy = apy - v * aby - w * acy
    qz = apz - v * abz - w * acz
    return qx * qx + qy * qy + qz * qz, v, w


@numba.njit(cache=True, inline="always")
def closest_on(x, y, z, A, B, C, lo, hi, child, box, stack):
    """(tree triangle t, v, w, squared distance): the triangle nearest to (x, y, z) and the barycentrics (1 - v - w,
    v, w) of its nearest point; nodes whose box is no nearer than the best so far skipped, the nearer child first
    (``stack``: an int64 work array of 256)."""
    best = np.inf
    bt = -1
    bv = bw = 0.0
    top = 1
    stack[0] = 0
    while top > 0:
        top -= 1
        nd = stack[top]
        dx = max(box[nd, 0] - x, 0.0, x - box[nd, 3])
        dy = max(box[nd, 1] - y, 0.0, y - box[nd, 4])
        dz = max(box[nd, 2] - z, 0.0, z - box[nd, 5])
        if dx * dx + dy * dy + dz * dz >= best:
            continue
        c0 = child[nd]
        if c0 < 0:
            for t in range(lo[nd], hi[nd]):
                d2, v, w = closest_on_triangle(x, y, z, A[t, 0], A[t, 1], A[t, 2], B[t, 0], B[t, 1], B[t, 2],
                                               C[t, 0], C[t, 1], C[t, 2])
                if d2 < best:
                    best, bt, bv, bw = d2, t, v, w
            continue
        # the child whose box is nearer is popped first
        e0 = _box_d2(box, c0, x, y, z)
        e1 = _box_d2(box, c0 + 1, x, y, z)
        if e0 <= e1:
            stack[top] = c0 + 1
            stack[top + 1] = c0
        else:
            stack[top] = c0
            stack[top + 1] = c0 + 1
        top += 2
    return bt, bv, bw, best


@numba.njit(cache=True, inline="always")
def _box_d2(box, nd, x, y, z):
    dx = max(box[nd, 0] - x, 0.0, x - box[nd, 3])
    dy = max(box[nd, 1] - y, 0.0, y - box[nd, 4])
    dz = max(box[nd, 2] - z, 0.0, z - box[nd, 5])
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True, nogil=True)
def _closest(P, A, B, C, lo, hi, child, box, order, face, bary, dist, q0, q1):
    stack = np.empty(256, np.int64)
    for q in range(q0, q1):
        t, v, w, d2 = closest_on(P[q, 0], P[q, 1], P[q, 2], A, B, C, lo, hi, child, box, stack)
        face[q] = order[t]
        bary[q, 0], bary[q, 1], bary[q, 2] = 1.0 - v - w, v, w
        dist[q] = math.sqrt(d2)
