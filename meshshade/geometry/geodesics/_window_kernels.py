"""Numba kernels behind :mod:`meshshade.geometry.geodesics.neighbourhoods` (private; no I/O, no Python objects).

Bounded single-source propagations, each processing a *block* of sources sequentially with reused,
stamp-reset work arrays (no O(n) clearing per source), so that a block costs O(sum of neighbourhood sizes).
Events are ordered by a bucket queue (width ``1/inv_delta``, ``nb`` circular buckets spanning the largest key
jump; LIFO inside a bucket).  Every update below is a min over lengths of valid paths and every event re-checks
its key, so processing slightly out of order changes the work, not the result (label-correcting).

``_window_block``
    Exact polyhedral geodesics by continuous-Dijkstra *window* propagation (Mitchell-Mount-Papadimitriou 1987
    windows, processed in the order and with the pruning of Xin & Wang 2009, "Improving Chen and Han's algorithm
    on the discrete geodesic problem", ACM TOG 28(4):104): a window is an interval of a half-edge lit by straight
    rays from a pseudo-source unfolded into the plane of the face it enters.  Pruning: the interval is trimmed
    where a path through one of its edge's end vertices is shorter (exact), a window whose whole interval is
    beaten through the opposite vertex is dropped (exact, the set where a point beats a pseudo-source along a
    line is an interval), and "one angle one split" trims the rays of a window that would cross a shorter ray
    to the same vertex (exact).  Pseudo-sources are emitted at boundary and non-manifold vertices (all
    around) and at saddles (cone angle theta > 2 pi) only into the sector [alpha + pi, alpha + theta - pi]
    opposite the arrival direction alpha, where a path through the vertex can be shortest (MMP's rule; it
    halves the window count on scanned meshes).  Every distance is the length of an actual path on the mesh,
    so results never fall below the exact polyhedral distance (up to rounding).
``_vertex_queue_block(..., use_triangles=True)``
    First-order fast marching (Kimmel & Sethian 1998) with the point-source ("circle intersection") triangle
    update of Novotni & Klein 2002 and re-opening of settled vertices; exact on flat meshes, O(h) on curved ones.
``_vertex_queue_block(..., use_triangles=False)``
    Plain Dijkstra on the edge graph (the baseline: zig-zag paths overestimate by 8-15 % on average).

Half-edge convention (built in ``neighbourhood._build_topology``): half-edge ``h = 3 f + k`` runs from
``F[f, k]`` (tail) to ``F[f, (k+1) % 3]`` (head); its opposite corner is ``F[f, (k+2) % 3]``.  Its local frame
puts the tail at (0, 0), the head at (L, 0) and the opposite corner at (ox, oy) with oy > 0.  A point (x, y)
of frame(h) is (tox + tsx x, -y) in the frame of the twin half-edge (the same edge seen from the other face,
unfolded flat): tox = L, tsx = -1 for a consistently wound neighbour, tox = 0, tsx = +1 otherwise.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# relative improvement below which a vertex is not re-queued (rounding noise)
_IMPROVE = 1.0 - 1e-13


@njit(cache=True, nogil=True, inline="always")
def _bq_push(bhead, ek, ei, en, nev, key, item, inv_delta, cur, nb):
    """Queue ``item`` with priority ``key`` in bucket floor(key / delta) (clamped to the live range)."""
    b = int(key * inv_delta)
    if b < cur:
        b = cur
    elif b >= cur + nb:
        b = cur + nb - 1
    slot = b % nb
    ek[nev] = key
    ei[nev] = item
    en[nev] = bhead[slot]
    bhead[slot] = nev
    return nev + 1


@njit(cache=True, nogil=True, inline="always")
def _bq_pop(bhead, ek, ei, en, cur, nb):
    """Remove an event of the lowest non-empty bucket (LIFO inside a bucket); the queue must not be empty."""
    while True:
        slot = cur % nb
        e = bhead[slot]
        if e >= 0:
            bhead[slot] = en[e]
            return ek[e], ei[e], cur
        cur += 1


@njit(cache=True, nogil=True)
def _grow_f(a, cap):
    b = np.empty(cap, a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(cache=True, nogil=True, inline="always")
def _cone_on_line(sx, sy, q0x, q0y, q1x, q1y):
    """Interval of the line y = 0 hit by the rays from s (sy < 0) between the rays through q0 and q1.

    The cone is the smaller angle between the two rays.  A ray that does not rise towards y = 0 turns its
    end of the interval into -inf or +inf, on the side the cone sweeps past the horizontal (the sign of the
    cross product of the rising ray and the other one); no rising ray gives an empty interval (lo > hi).
    """
    d0x = q0x - sx
    d0y = q0y - sy
    d1x = q1x - sx
    d1y = q1y - sy
    tiny = 1e-14 * (abs(sy) + abs(q0y) + abs(q1y))
    up0 = d0y > tiny
    up1 = d1y > tiny
    if up0 and up1:
        x0 = sx + d0x * (-sy) / d0y
        x1 = sx + d1x * (-sy) / d1y
        return min(x0, x1), max(x0, x1)
    if up0:
        x0 = sx + d0x * (-sy) / d0y
        if d0x * d1y - d0y * d1x > 0.0:   # the cone turns counter-clockwise from the rising ray: leftwards
            return -np.inf, x0
        return x0, np.inf
    if up1:
        x1 = sx + d1x * (-sy) / d1y
        if d1x * d0y - d1y * d0x > 0.0:
            return -np.inf, x1
        return x1, np.inf
    return np.inf, -np.inf


@njit(cache=True, nogil=True, inline="always")
def _window_min(sx, sy, lo, hi, sg):
    """Smallest distance sg + |s - (x, 0)| over x in [lo, hi] (the window's queue key)."""
    if sx < lo:
        return sg + np.sqrt((lo - sx) ** 2 + sy * sy)
    if sx > hi:
        return sg + np.sqrt((hi - sx) ** 2 + sy * sy)
    return sg - sy


@njit(cache=True, nogil=True)
def _append_results(out_v, out_d, nout, touched, nt, dist, cutoff):
    """Append the touched vertices within ``cutoff`` (growing the outputs); returns arrays and new length."""
    need = nout + nt
    if need > out_v.shape[0]:
        cap = max(need, 2 * out_v.shape[0])
        out_v = _grow_f(out_v, cap)
        out_d = _grow_f(out_d, cap)
    for j in range(nt):
        u = touched[j]
        if dist[u] <= cutoff:
            out_v[nout] = u
            out_d[nout] = dist[u]
            nout += 1
    return out_v, out_d, nout


@njit(cache=True, nogil=True)
def _build_fans(n_vertices, he_twin, he_tsx, he_corner, v_ptr, v_he):
    """Angular position of every corner in its vertex's fan (for the pseudo-source shadow rule).

    Walking counter-clockwise around vertex v, the half-edge opposite v in the next face is
    ``next(twin(next(h)))``.  Returns ``fan_start`` (3m,): the angle, around the opposite vertex of half-edge h,
    of the direction towards tail(h) (the corner of h's face spans [fan_start, fan_start + corner]), and
    ``fan_ok`` (n,): the walk closed over all of v's faces (interior manifold vertex, consistent winding).
    """
    fan_start = np.zeros(he_twin.shape[0])
    fan_ok = np.zeros(n_vertices, np.bool_)
    for v in range(n_vertices):
        a, b = v_ptr[v], v_ptr[v + 1]
        deg = b - a
        if deg < 3:
            continue
        h = v_he[a]
        acc = 0.0
        ok = True
        for _ in range(deg):
            fan_start[h] = acc
            acc += he_corner[h]
            nx = 3 * (h // 3) + (h % 3 + 1) % 3
            t = he_twin[nx]
            if t < 0 or he_tsx[nx] > 0.0:  # open edge or inconsistent winding: no fan
                ok = False
                break
            h = 3 * (t // 3) + (t % 3 + 1) % 3
        fan_ok[v] = ok and h == v_he[a]
    return fan_start, fan_ok


@njit(cache=True, nogil=True, inline="always")
def _arrival_angle(role, h, px, py, he_len, he_ox, he_oy, fan_start, he_corner):
    """Fan angle, around the vertex, of the direction back along the path that reached it.

    The path's last straight piece comes from point (px, py) of frame(h); the vertex is the opposite corner
    (role 0), the tail (role 1) or the head (role 2) of h.
    """
    L = he_len[h]
    ox = he_ox[h]
    oy = he_oy[h]
    base = 3 * (h // 3)
    if role == 0:
        ax = -ox
        ay = -oy
        dx = px - ox
        dy = py - oy
        return fan_start[h] + np.arctan2(ax * dy - ay * dx, ax * dx + ay * dy)
    if role == 1:   # from direction tail -> head, counter-clockwise positive
        hA = base + (h - base + 1) % 3
        return fan_start[hA] + np.arctan2(py, px)
    hB = base + (h - base + 2) % 3  # from direction head -> tail
    dx = px - L
    return fan_start[hB] + he_corner[hB] + np.arctan2(-py, -dx)


@njit(cache=True, nogil=True)
def _window_block(src_vertex, src_face, src_bary, cutoff, n_vertices, he_tail, he_head, he_opp, he_twin,
                  he_tox, he_tsx, he_len, he_ox, he_oy, v_ptr, v_he, emitter, inv_delta, nb,
                  fan_start, fan_ok, he_corner, v_theta):
    """Window propagation for a block of sources.  Returns (counts (k,), vertex (nnz,) int32, distance (nnz,))."""
    k = src_vertex.shape[0]
    m3 = he_tail.shape[0]
    dist = np.empty(n_vertices)
    vstamp = np.zeros(n_vertices, np.int32)
    vdone = np.zeros(n_vertices, np.int32)
    touched = np.empty(n_vertices, np.int64)
    arr_role = np.zeros(n_vertices, np.int8)   # how the best path reached the vertex (see _arrival_angle)
    arr_h = np.zeros(n_vertices, np.int64)
    arr_x = np.zeros(n_vertices)
    arr_y = np.zeros(n_vertices)
    abest = np.empty(m3)
    abx = np.empty(m3)
    astamp = np.zeros(m3, np.int32)
    pcap = 4096
    p_h = np.empty(pcap, np.int64)
    p_sx = np.empty(pcap)
    p_sy = np.empty(pcap)
    p_lo = np.empty(pcap)
    p_hi = np.empty(pcap)
    p_sg = np.empty(pcap)
    bhead = np.full(nb, -1, np.int64)
    ecap = 4096
    ek = np.empty(ecap)
    ei = np.empty(ecap, np.int64)
    en = np.empty(ecap, np.int64)
    MAXC = 64
    c_t = np.empty(MAXC, np.int64)
    c_sx = np.empty(MAXC)
    c_sy = np.empty(MAXC)
    c_lo = np.empty(MAXC)
    c_hi = np.empty(MAXC)
    c_sg = np.empty(MAXC)
    counts = np.zeros(k, np.int64)
    out_v = np.empty(max(1024, 64 * k), np.int32)
    out_d = np.empty(out_v.shape[0])
    nout = 0
    for i in range(k):
        stamp = i + 1
        cut = cutoff[i]
        nt = 0
        nev = 0
        qn = 0
        cur = 0
        bhead[:] = -1
        npool = 0
        nc = 0
        sv = src_vertex[i]
        if sv >= 0:
            vstamp[sv] = stamp
            dist[sv] = 0.0
            vdone[sv] = 0
            arr_role[sv] = -1
            touched[nt] = sv
            nt += 1
            nev = _bq_push(bhead, ek, ei, en, nev, 0.0, -sv - 1, inv_delta, cur, nb)
            qn += 1
        else:
            f = src_face[i]
            for kk in range(3):
                h = 3 * f + kk
                Lh = he_len[h]
                px = src_bary[i, (kk + 1) % 3] * Lh + src_bary[i, (kk + 2) % 3] * he_ox[h]
                py = src_bary[i, (kk + 2) % 3] * he_oy[h]
                u = he_tail[h]
                vstamp[u] = stamp
                dist[u] = np.sqrt(px * px + py * py)
                vdone[u] = 0
                arr_role[u] = 1
                arr_h[u] = h
                arr_x[u] = px
                arr_y[u] = py
                touched[nt] = u
                nt += 1
                t = he_twin[h]
                if t >= 0:
                    c_t[nc] = t
                    c_sx[nc] = he_tox[h] + he_tsx[h] * px
                    c_sy[nc] = -py
                    c_lo[nc] = 0.0
                    c_hi[nc] = Lh
                    c_sg[nc] = 0.0
                    nc += 1
            for kk in range(3):
                u = he_tail[3 * f + kk]
                if (emitter[u] or dist[u] == 0.0) and dist[u] <= cut:
                    nev = _bq_push(bhead, ek, ei, en, nev, dist[u], -u - 1, inv_delta, cur, nb)
                    qn += 1
        while True:
            # ---- insert pending children (windows) after pruning -------------------------------------
            if nev + 4 * nc + 8 >= ecap:
                ecap = 2 * (nev + 4 * nc + 8)
                ek = _grow_f(ek, ecap)
                ei = _grow_f(ei, ecap)
                en = _grow_f(en, ecap)
            if npool + nc >= pcap:
                pcap = 2 * (npool + nc)
                p_h = _grow_f(p_h, pcap)
                p_sx = _grow_f(p_sx, pcap)
                p_sy = _grow_f(p_sy, pcap)
                p_lo = _grow_f(p_lo, pcap)
                p_hi = _grow_f(p_hi, pcap)
                p_sg = _grow_f(p_sg, pcap)
            for c in range(nc):
                t = c_t[c]
                sx = c_sx[c]
                sy = c_sy[c]
                lo = c_lo[c]
                hi = c_hi[c]
                sg = c_sg[c]
                Lt = he_len[t]
                A = he_tail[t]
                B = he_head[t]
                O = he_opp[t]
                # trim where the path through A (x < xA) or B is shorter
                if vstamp[A] == stamp:
                    dA = dist[A] - sg
                    den = 2.0 * (sx + dA)
                    if den > 0.0:
                        xA = (sx * sx + sy * sy - dA * dA) / den
                        if xA + dA >= 0.0 and xA > lo:
                            lo = xA
                if vstamp[B] == stamp:
                    dB = dist[B] - sg
                    sxm = Lt - sx
                    den = 2.0 * (sxm + dB)
                    if den > 0.0:
                        xB = (sxm * sxm + sy * sy - dB * dB) / den
                        if xB + dB >= 0.0 and Lt - xB < hi:
                            hi = Lt - xB
                if hi - lo <= 1e-12 * Lt:
                    continue
                key = _window_min(sx, sy, lo, hi, sg)
                if key > cut:
                    continue
                vx = he_ox[t]
                vy = he_oy[t]
                if vstamp[O] == stamp:
                    dO = dist[O]
                    if (dO + np.sqrt((vx - lo) ** 2 + vy * vy) < sg + np.sqrt((lo - sx) ** 2 + sy * sy) and
                            dO + np.sqrt((vx - hi) ** 2 + vy * vy) < sg + np.sqrt((hi - sx) ** 2 + sy * sy)):
                        continue
                # distances to the window's end vertices (when lit) and to the opposite vertex
                for e in range(3):
                    ax_ = sx
                    ay_ = sy
                    if e == 0:
                        if lo > 1e-12 * Lt:
                            continue
                        u = A
                        dd = sg + np.sqrt(sx * sx + sy * sy)
                    elif e == 1:
                        if hi < Lt * (1.0 - 1e-12):
                            continue
                        u = B
                        dd = sg + np.sqrt((Lt - sx) ** 2 + sy * sy)
                    else:
                        u = O
                        xc = sx + (vx - sx) * (-sy) / (vy - sy)
                        if xc < lo:    # bent path through the interval's end point (a valid upper bound)
                            dd = sg + np.sqrt((lo - sx) ** 2 + sy * sy) + np.sqrt((vx - lo) ** 2 + vy * vy)
                            ax_ = lo
                            ay_ = 0.0
                        elif xc > hi:
                            dd = sg + np.sqrt((hi - sx) ** 2 + sy * sy) + np.sqrt((vx - hi) ** 2 + vy * vy)
                            ax_ = hi
                            ay_ = 0.0
                        else:
                            dd = sg + np.sqrt((vx - sx) ** 2 + (vy - sy) ** 2)
                    if vstamp[u] != stamp:
                        vstamp[u] = stamp
                        dist[u] = np.inf
                        vdone[u] = 0
                        touched[nt] = u
                        nt += 1
                    if dd < dist[u] * _IMPROVE:
                        dist[u] = dd
                        arr_role[u] = (e + 1) % 3   # e: 0 = tail (role 1), 1 = head (role 2), 2 = opposite (0)
                        arr_h[u] = t
                        arr_x[u] = ax_
                        arr_y[u] = ay_
                        if emitter[u] and dd <= cut:
                            vdone[u] = 0
                            nev = _bq_push(bhead, ek, ei, en, nev, dd, -u - 1, inv_delta, cur, nb)
                            qn += 1
                p_h[npool] = t
                p_sx[npool] = sx
                p_sy[npool] = sy
                p_lo[npool] = lo
                p_hi[npool] = hi
                p_sg[npool] = sg
                nev = _bq_push(bhead, ek, ei, en, nev, key, npool, inv_delta, cur, nb)
                qn += 1
                npool += 1
            nc = 0
            # ---- next event ------------------------------------------------------------------------
            if qn == 0:
                break
            key, item, cur = _bq_pop(bhead, ek, ei, en, cur, nb)
            qn -= 1
            if key > cut:
                continue
            if item < 0:  # vertex event: emit a pseudo-source into every face around the vertex
                v = -item - 1
                if vdone[v] == stamp or key > dist[v]:
                    continue
                vdone[v] = stamp
                # MMP: a shortest path through a saddle turns by >= pi on both sides, so the pseudo-source
                # only lights the sector [alpha + pi, alpha + theta - pi] opposite the arrival direction alpha
                sector = fan_ok[v] and arr_role[v] >= 0
                if sector:
                    theta = v_theta[v]
                    width = theta - 2.0 * np.pi
                    alpha = _arrival_angle(arr_role[v], arr_h[v], arr_x[v], arr_y[v], he_len, he_ox, he_oy,
                                           fan_start, he_corner)
                for j in range(v_ptr[v], v_ptr[v + 1]):
                    h = v_he[j]
                    vx = he_ox[h]
                    vy = he_oy[h]
                    Lh = he_len[h]
                    for e in range(2):  # the face's other corners directly (needed at open boundaries)
                        if e == 0:
                            u = he_tail[h]
                            dd = key + np.sqrt(vx * vx + vy * vy)
                        else:
                            u = he_head[h]
                            dd = key + np.sqrt((Lh - vx) ** 2 + vy * vy)
                        if vstamp[u] != stamp:
                            vstamp[u] = stamp
                            dist[u] = np.inf
                            vdone[u] = 0
                            touched[nt] = u
                            nt += 1
                        if dd < dist[u] * _IMPROVE:
                            dist[u] = dd
                            arr_role[u] = e + 1
                            arr_h[u] = h
                            arr_x[u] = vx
                            arr_y[u] = vy
                            if emitter[u] and dd <= cut:
                                vdone[u] = 0
                                if nev + 8 >= ecap:
                                    ecap = 2 * (nev + 8)
                                    ek = _grow_f(ek, ecap)
                                    ei = _grow_f(ei, ecap)
                                    en = _grow_f(en, ecap)
                                nev = _bq_push(bhead, ek, ei, en, nev, dd, -u - 1, inv_delta, cur, nb)
                                qn += 1
                    t = he_twin[h]
                    if t < 0 or nc >= MAXC:
                        continue
                    x0 = 0.0
                    x1 = Lh
                    if sector:
                        # the sector relative to this corner, which spans [0, corner] from direction v -> tail
                        cor = he_corner[h]
                        a0 = (alpha + np.pi - fan_start[h]) % theta
                        b0 = -1.0
                        b1 = -2.0
                        for wrap in range(2):
                            lo_a = max(a0 - wrap * theta, 0.0) - 1e-9
                            hi_a = min(a0 - wrap * theta + width, cor) + 1e-9
                            if hi_a >= lo_a:
                                if b1 < b0:
                                    b0 = lo_a
                                    b1 = hi_a
                                else:
                                    b0 = min(b0, lo_a)
                                    b1 = max(b1, hi_a)
                        if b1 < b0:
                            continue
                        # rays from v at those angles (counter-clockwise from v -> tail) meet the edge y = 0
                        ux = -vx
                        uy = -vy
                        nu = np.sqrt(ux * ux + uy * uy)
                        ux /= nu
                        uy /= nu
                        for e in range(2):
                            ang = max(b0, 0.0) if e == 0 else min(b1, cor)
                            ca = np.cos(ang)
                            sa = np.sin(ang)
                            rx = ux * ca - uy * sa
                            ry = ux * sa + uy * ca
                            xe = vx + rx * (-vy) / ry if ry < -1e-15 else (0.0 if e == 0 else Lh)
                            if e == 0:
                                x0 = min(max(xe, 0.0), Lh)
                            else:
                                x1 = min(max(xe, 0.0), Lh)
                        if x1 < x0:
                            x0, x1 = x1, x0
                    # interval [x0, x1] of frame(h) -> frame(t)
                    q0 = he_tox[h] + he_tsx[h] * x0
                    q1 = he_tox[h] + he_tsx[h] * x1
                    c_t[nc] = t
                    c_sx[nc] = he_tox[h] + he_tsx[h] * vx
                    c_sy[nc] = -vy
                    c_lo[nc] = min(q0, q1)
                    c_hi[nc] = max(q0, q1)
                    c_sg[nc] = key
                    nc += 1
                continue
            w = item
            h = p_h[w]
            sx = p_sx[w]
            sy = p_sy[w]
            b0 = p_lo[w]
            b1 = p_hi[w]
            sg = p_sg[w]
            Lh = he_len[h]
            base = 3 * (h // 3)
            kk = h - base
            vx = he_ox[h]
            vy = he_oy[h]
            # one angle, one split: rays crossing a shorter ray to the opposite vertex are useless
            l0 = b0
            l1 = b1
            r0 = b0
            r1 = b1
            xc = sx + (vx - sx) * (-sy) / (vy - sy)
            if b0 <= xc <= b1:
                dO = sg + np.sqrt((vx - sx) ** 2 + (vy - sy) ** 2)
                if astamp[h] != stamp or dO < abest[h]:
                    astamp[h] = stamp
                    abest[h] = dO
                    abx[h] = xc
                elif abx[h] < xc:
                    l1 = min(b1, abx[h])
                else:
                    r0 = max(b0, abx[h])
            for e in range(2):
                if e == 0:  # exit edge head -> opposite, fed by rays right of the opposite vertex
                    he = base + (kk + 1) % 3
                    px = Lh
                    py = 0.0
                    qx = vx
                    qy = vy
                    c0 = r0
                    c1 = r1
                else:       # exit edge opposite -> tail
                    he = base + (kk + 2) % 3
                    px = vx
                    py = vy
                    qx = 0.0
                    qy = 0.0
                    c0 = l0
                    c1 = l1
                t = he_twin[he]
                if t < 0 or c1 <= c0:
                    continue
                Le = he_len[he]
                ux = (qx - px) / Le
                uy = (qy - py) / Le
                tox = he_tox[he]
                tsx = he_tsx[he]
                # frame(h) -> frame(he): ((P - p).u, (P - p).n) with n = (-uy, ux); then -> frame(t)
                s1x = tox + tsx * ((sx - px) * ux + (sy - py) * uy)
                s1y = -((sx - px) * (-uy) + (sy - py) * ux)
                if s1y >= 0.0:
                    continue
                q0x = tox + tsx * ((c0 - px) * ux - py * uy)
                q0y = -((c0 - px) * (-uy) - py * ux)
                q1x = tox + tsx * ((c1 - px) * ux - py * uy)
                q1y = -((c1 - px) * (-uy) - py * ux)
                lo, hi = _cone_on_line(s1x, s1y, q0x, q0y, q1x, q1y)
                if lo < 0.0:
                    lo = 0.0
                if hi > Le:
                    hi = Le
                if hi - lo <= 1e-12 * Le:
                    continue
                c_t[nc] = t
                c_sx[nc] = s1x
                c_sy[nc] = s1y
                c_lo[nc] = lo
                c_hi[nc] = hi
                c_sg[nc] = sg
                nc += 1
        before = nout
        out_v, out_d, nout = _append_results(out_v, out_d, nout, touched, nt, dist, cut)
        counts[i] = nout - before
    return counts, out_v[:nout], out_d[:nout]
