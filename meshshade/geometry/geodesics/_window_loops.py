"""Compiled loops of the exact ("window") method of :mod:`meshshade.geometry.geodesics.neighbourhoods` (private).

Exact polyhedral geodesics by continuous-Dijkstra *window* propagation (Mitchell-Mount-Papadimitriou 1987 windows,
processed in the order and with the pruning of Xin & Wang 2009, "Improving Chen and Han's algorithm on the
discrete geodesic problem", ACM TOG 28(4):104): a window is an interval of a half-edge lit by straight rays from a
pseudo-source unfolded into the plane of the face it enters.  Pruning: the interval is trimmed where a path
through one of its edge's end vertices is shorter (exact), a window whose whole interval is beaten through the
opposite vertex is dropped (exact, the set where a point beats a pseudo-source along a line is an interval), and
"one angle one split" trims the rays of a window that would cross a shorter ray to the same vertex (exact).
Pseudo-sources are emitted at boundary and non-manifold vertices (all around) and at saddles (cone angle
theta > 2 pi) only into the sector [alpha + pi, alpha + theta - pi] opposite the arrival direction alpha, where a
path through the vertex can be shortest (MMP's rule; it halves the window count on scanned meshes).  Every
distance is the length of an actual path on the mesh, so results never fall below the exact polyhedral distance
(up to rounding).  Block structure, stamps and bucket queue: :mod:`._queue_loops`.

``_window_block`` (the driver) runs one source after the other:

1. initial distances and windows from the source: ``_seed_vertex_source`` / ``_seed_face_source``;
2. pending windows are pruned (``_trim_by_end_vertices``, ``_window_min`` against the cutoff,
   ``_beaten_through_opposite``), offer paths to the corners of their face (``_path_to_window_vertex``) and are
   queued (``_queue_window``);
3. a popped window lights the face behind its half-edge: "one angle one split", then it is carried across each
   exit edge (``_exit_edge``, ``_unfold_across_edge``, ``_cone_on_line``) as a pending window;
4. a popped saddle/boundary vertex is a pseudo-source: paths to the other corners of its faces and pending
   windows on their far edges, a saddle's only inside its sector (``_arrival_angle``, ``_sector_on_edge`` in
   :mod:`._saddle_loops`);
5. the vertices within the cutoff are collected (``_append_results``).

Numba note: the per-event helpers are inlined (``inline="always"``), and those that take arrays are straight-line
code (no branch between their arguments and their last use: ``_first_visit``, ``_record_arrival``,
``_push_child``, ``_queue_window``); every branching step over the shared state stays in the driver and calls
scalar helpers.  An inlined helper that uses an array argument only inside branches keeps a reference-count
increment and decrement per array and call (numba cannot pair them up), and helpers of that kind made this kernel
2.7-3x slower.  Helpers that branch over arrays run once per source (``_seed_face_source``) or once per
pseudo-source (``_arrival_angle``).

Half-edge convention (built in ``neighbourhoods._build_topology``): half-edge ``h = 3 f + k`` runs from
``F[f, k]`` (tail) to ``F[f, (k+1) % 3]`` (head); its opposite corner is ``F[f, (k+2) % 3]``.  Its local frame
puts the tail at (0, 0), the head at (L, 0) and the opposite corner at (ox, oy) with oy > 0.  A point (x, y)
of frame(h) is (tox + tsx x, -y) in the frame of the twin half-edge (the same edge seen from the other face,
unfolded flat): tox = L, tsx = -1 for a consistently wound neighbour, tox = 0, tsx = +1 otherwise.  Lengths are
in mm, angles in radians.

Work arrays of the driver (one set per block, reset by stamps):

* per vertex (n,): ``dist`` best distance, ``vstamp`` source stamp of ``dist``, ``vdone`` stamp of the source
  that emitted from it, ``touched`` the vertices reached (first ``nt``), and how the best path arrived:
  ``arr_role`` (0 opposite corner / 1 tail / 2 head of half-edge ``arr_h``, -1 the source itself) with its last
  straight piece coming from (``arr_x``, ``arr_y``) in frame(``arr_h``);
* per half-edge (3m,): ``astamp``, ``abest``, ``abx``: the shortest ray to the opposite vertex so far and where it
  crosses the half-edge (one angle, one split);
* window pool (``npool`` queued windows): ``p_h`` half-edge, pseudo-source (``p_sx``, ``p_sy``) in its frame
  (y < 0), lit interval [``p_lo``, ``p_hi``] of the edge, ``p_sg`` distance of the pseudo-source;
* pending windows (``nc``, at most ``_MAX_CHILDREN``): ``c_t``, ``c_sx``, ``c_sy``, ``c_lo``, ``c_hi``, ``c_sg``,
  the same fields, not yet pruned or queued.

Queue items: ``w >= 0`` is window ``w`` of the pool, ``-u - 1`` is a pseudo-source event at vertex ``u``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from meshshade.geometry.geodesics._queue_loops import (_IMPROVE, _append_results, _bq_pop, _bq_push, _grow_f,
                                                         _reserve_events)
from meshshade.geometry.geodesics._saddle_loops import _arrival_angle, _sector_on_edge

#: pending windows at once (one per face around a pseudo-source vertex; further faces get no window)
_MAX_CHILDREN = 64


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


# ---------------------------------------------------------------------------------------------------------------
# bookkeeping (straight-line array helpers; see the module docstring)
# ---------------------------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _first_visit(u, stamp, vstamp, dist, vdone, touched, nt):
    """Vertex ``u`` is reached for the first time by the current source: distance inf, listed in ``touched``.
    Returns nt."""
    vstamp[u] = stamp
    dist[u] = np.inf
    vdone[u] = 0
    touched[nt] = u
    return nt + 1


@njit(cache=True, nogil=True, inline="always")
def _record_arrival(u, dd, role, h, ax, ay, dist, arr_role, arr_h, arr_x, arr_y):
    """Vertex ``u`` gets distance ``dd`` along a path whose last straight piece comes from (ax, ay) of frame(h),
    ``u`` being corner ``role`` of h (0 opposite, 1 tail, 2 head)."""
    dist[u] = dd
    arr_role[u] = role
    arr_h[u] = h
    arr_x[u] = ax
    arr_y[u] = ay


@njit(cache=True, nogil=True, inline="always")
def _push_child(c_t, c_sx, c_sy, c_lo, c_hi, c_sg, nc, t, sx, sy, lo, hi, sg):
    """Add a pending window: interval [lo, hi] of half-edge t lit from (sx, sy) of frame(t) at distance sg.
    Returns nc."""
    c_t[nc] = t
    c_sx[nc] = sx
    c_sy[nc] = sy
    c_lo[nc] = lo
    c_hi[nc] = hi
    c_sg[nc] = sg
    return nc + 1


@njit(cache=True, nogil=True, inline="always")
def _queue_window(p_h, p_sx, p_sy, p_lo, p_hi, p_sg, npool, t, sx, sy, lo, hi, sg, key, bhead, ek, ei, en, nev,
                  inv_delta, cur, nb):
    """Store a window as entry ``npool`` of the pool and queue it with priority ``key``.  Returns nev."""
    p_h[npool] = t
    p_sx[npool] = sx
    p_sy[npool] = sy
    p_lo[npool] = lo
    p_hi[npool] = hi
    p_sg[npool] = sg
    return _bq_push(bhead, ek, ei, en, nev, key, npool, inv_delta, cur, nb)


# ---------------------------------------------------------------------------------------------------------------
# geometry of one window (scalar helpers)
# ---------------------------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _trim_by_end_vertices(sx, sy, lo, hi, sg, Lt, reached_a, d_a, reached_b, d_b):
    """Trim the interval [lo, hi] of an edge of length Lt (tail A at x = 0, head B at x = Lt) to where the window
    from (sx, sy) at distance sg is shorter than the best path through A (left part) or B (right part).

    ``d_a`` (``d_b``) is A's (B's) best distance, used only when ``reached_a`` (``reached_b``).  Returns (lo, hi).
    """
    if reached_a:
        dA = d_a - sg
        den = 2.0 * (sx + dA)
        if den > 0.0:
            xA = (sx * sx + sy * sy - dA * dA) / den
            if xA + dA >= 0.0 and xA > lo:
                lo = xA
    if reached_b:
        dB = d_b - sg
        sxm = Lt - sx
        den = 2.0 * (sxm + dB)
        if den > 0.0:
            xB = (sxm * sxm + sy * sy - dB * dB) / den
            if xB + dB >= 0.0 and Lt - xB < hi:
                hi = Lt - xB
    return lo, hi


@njit(cache=True, nogil=True, inline="always")
def _beaten_through_opposite(sx, sy, lo, hi, sg, vx, vy, d_o):
    """Whether the path through the opposite vertex at (vx, vy), best distance ``d_o``, beats the window at both
    interval ends (then it does over the whole interval, and the window is useless)."""
    return (d_o + np.sqrt((vx - lo) ** 2 + vy * vy) < sg + np.sqrt((lo - sx) ** 2 + sy * sy) and
            d_o + np.sqrt((vx - hi) ** 2 + vy * vy) < sg + np.sqrt((hi - sx) ** 2 + sy * sy))


@njit(cache=True, nogil=True, inline="always")
def _path_to_window_vertex(e, sx, sy, lo, hi, sg, Lt, vx, vy):
    """Path from a window to corner ``e`` of its face (0 tail, 1 head, 2 opposite vertex at (vx, vy)).

    Returns (lit, dd, ax, ay): whether the path exists (the tail and head only when the interval reaches them),
    its length, and the start (ax, ay) of its last straight piece.  A ray to the opposite vertex that misses the
    interval is replaced by the bent path through the interval's nearer end (a valid upper bound).
    """
    if e == 0:
        if lo > 1e-12 * Lt:
            return False, 0.0, sx, sy
        return True, sg + np.sqrt(sx * sx + sy * sy), sx, sy
    if e == 1:
        if hi < Lt * (1.0 - 1e-12):
            return False, 0.0, sx, sy
        return True, sg + np.sqrt((Lt - sx) ** 2 + sy * sy), sx, sy
    xc = sx + (vx - sx) * (-sy) / (vy - sy)
    if xc < lo:
        return True, sg + np.sqrt((lo - sx) ** 2 + sy * sy) + np.sqrt((vx - lo) ** 2 + vy * vy), lo, 0.0
    if xc > hi:
        return True, sg + np.sqrt((hi - sx) ** 2 + sy * sy) + np.sqrt((vx - hi) ** 2 + vy * vy), hi, 0.0
    return True, sg + np.sqrt((vx - sx) ** 2 + (vy - sy) ** 2), sx, sy


@njit(cache=True, nogil=True, inline="always")
def _exit_edge(e, h, Lh, vx, vy):
    """Exit edge ``e`` of the face of half-edge h (frame(h): tail (0, 0), head (Lh, 0), opposite (vx, vy)).

    e = 0: head -> opposite (fed by the rays right of the opposite vertex); e = 1: opposite -> tail (left of it).
    Returns (he, px, py, qx, qy): its half-edge and its end points p -> q in frame(h).
    """
    base = 3 * (h // 3)
    if e == 0:
        return base + (h - base + 1) % 3, Lh, 0.0, vx, vy
    return base + (h - base + 2) % 3, vx, vy, 0.0, 0.0


@njit(cache=True, nogil=True, inline="always")
def _unfold_across_edge(sx, sy, c0, c1, px, py, qx, qy, Le, tox, tsx):
    """Carry a window's rays through [c0, c1] of its half-edge (y = 0 of its frame) across the face's exit edge
    p -> q (length Le), unfolding the pseudo-source (sx, sy) into the frame of that edge's twin.

    Returns (lit, s1x, s1y, lo, hi): the pseudo-source and the lit interval in the twin's frame; ``lit`` is False
    when the source is not behind the edge or the interval is empty.
    """
    ux = (qx - px) / Le
    uy = (qy - py) / Le
    # frame(h) -> frame(he): ((P - p).u, (P - p).n) with n = (-uy, ux); then -> frame(t)
    s1x = tox + tsx * ((sx - px) * ux + (sy - py) * uy)
    s1y = -((sx - px) * (-uy) + (sy - py) * ux)
    if s1y >= 0.0:
        return False, s1x, s1y, 0.0, 0.0
    q0x = tox + tsx * ((c0 - px) * ux - py * uy)
    q0y = -((c0 - px) * (-uy) - py * ux)
    q1x = tox + tsx * ((c1 - px) * ux - py * uy)
    q1y = -((c1 - px) * (-uy) - py * ux)
    lo, hi = _cone_on_line(s1x, s1y, q0x, q0y, q1x, q1y)
    if lo < 0.0:
        lo = 0.0
    if hi > Le:
        hi = Le
    return not (hi - lo <= 1e-12 * Le), s1x, s1y, lo, hi


# ---------------------------------------------------------------------------------------------------------------
# sources (once per source)
# ---------------------------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, inline="always")
def _seed_vertex_source(sv, stamp, vstamp, dist, vdone, touched, arr_role, bhead, ek, ei, en, inv_delta, nb):
    """Start a source at vertex ``sv``: distance 0 and a pseudo-source event there.  Returns (nt, nev, qn)."""
    vstamp[sv] = stamp
    dist[sv] = 0.0
    vdone[sv] = 0
    arr_role[sv] = -1
    touched[0] = sv
    return 1, _bq_push(bhead, ek, ei, en, 0, 0.0, -sv - 1, inv_delta, 0, nb), 1


@njit(cache=True, nogil=True)
def _seed_face_source(f, bary, stamp, cut, he_tail, he_twin, he_tox, he_tsx, he_len, he_ox, he_oy, vstamp, dist,
                      vdone, touched, arr_role, arr_h, arr_x, arr_y, emitter, pending, bhead, ek, ei, en, inv_delta,
                      nb):
    """Start a source inside face ``f`` at barycentric weights ``bary`` (3,): straight paths to the three corners,
    a pending window on each neighbouring face's edge (into ``pending``, the six pending-window arrays) and
    pseudo-source events at the corners that emit or that the source sits on.  Returns (nt, nev, qn, nc)."""
    c_t, c_sx, c_sy, c_lo, c_hi, c_sg = pending
    nt = 0
    nev = 0
    qn = 0
    nc = 0
    for kk in range(3):
        h = 3 * f + kk
        Lh = he_len[h]
        px = bary[(kk + 1) % 3] * Lh + bary[(kk + 2) % 3] * he_ox[h]
        py = bary[(kk + 2) % 3] * he_oy[h]
        u = he_tail[h]
        vstamp[u] = stamp
        vdone[u] = 0
        _record_arrival(u, np.sqrt(px * px + py * py), 1, h, px, py, dist, arr_role, arr_h, arr_x, arr_y)
        touched[nt] = u
        nt += 1
        t = he_twin[h]
        if t >= 0:
            nc = _push_child(c_t, c_sx, c_sy, c_lo, c_hi, c_sg, nc, t, he_tox[h] + he_tsx[h] * px, -py, 0.0, Lh,
                             0.0)
    for kk in range(3):
        u = he_tail[3 * f + kk]
        if (emitter[u] or dist[u] == 0.0) and dist[u] <= cut:
            nev = _bq_push(bhead, ek, ei, en, nev, dist[u], -u - 1, inv_delta, 0, nb)
            qn += 1
    return nt, nev, qn, nc


# ---------------------------------------------------------------------------------------------------------------
# driver
# ---------------------------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def _window_block(src_vertex, src_face, src_bary, cutoff, n_vertices, he_tail, he_head, he_opp, he_twin,
                  he_tox, he_tsx, he_len, he_ox, he_oy, v_ptr, v_he, emitter, inv_delta, nb,
                  fan_start, fan_ok, he_corner, v_theta, stop):
    """Window propagation for a block of k sources (``src_vertex`` (k,) vertex or -1, else face ``src_face`` (k,)
    at barycentric ``src_bary`` (k, 3)), each up to its ``cutoff`` (k,) mm.

    Returns (counts (k,) int64, vertex (nnz,) int32, distance (nnz,) float64 mm), rows in source order.
    ``stop`` (1,) int64: when another thread sets it non-zero (an interrupted query), the call returns at its
    next event with an unfinished result, which the caller drops (one source can take a second).
    """
    k = src_vertex.shape[0]
    m3 = he_tail.shape[0]
    dist = np.empty(n_vertices)
    vstamp = np.zeros(n_vertices, np.int32)
    vdone = np.zeros(n_vertices, np.int32)
    touched = np.empty(n_vertices, np.int64)
    arr_role = np.zeros(n_vertices, np.int8)
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
    ek = np.empty(4096)
    ei = np.empty(4096, np.int64)
    en = np.empty(4096, np.int64)
    c_t = np.empty(_MAX_CHILDREN, np.int64)
    c_sx = np.empty(_MAX_CHILDREN)
    c_sy = np.empty(_MAX_CHILDREN)
    c_lo = np.empty(_MAX_CHILDREN)
    c_hi = np.empty(_MAX_CHILDREN)
    c_sg = np.empty(_MAX_CHILDREN)
    counts = np.zeros(k, np.int64)
    out_v = np.empty(max(1024, 64 * k), np.int32)
    out_d = np.empty(out_v.shape[0])
    nout = np.int64(0)   # not the literal 0: numba would compile _append_results for Literal[int](0) too
    for i in range(k):
        stamp = i + 1
        cut = cutoff[i]
        cur = 0
        bhead[:] = -1
        npool = 0
        nc = 0
        if src_vertex[i] >= 0:
            nt, nev, qn = _seed_vertex_source(src_vertex[i], stamp, vstamp, dist, vdone, touched, arr_role, bhead,
                                              ek, ei, en, inv_delta, nb)
        else:
            nt, nev, qn, nc = _seed_face_source(src_face[i], src_bary[i], stamp, cut, he_tail, he_twin, he_tox,
                                                he_tsx, he_len, he_ox, he_oy, vstamp, dist, vdone, touched,
                                                arr_role, arr_h, arr_x, arr_y, emitter,
                                                (c_t, c_sx, c_sy, c_lo, c_hi, c_sg), bhead, ek, ei, en, inv_delta,
                                                nb)
        while True:
            # ---- pending windows: prune, offer paths to the three corners of the face, queue -----------------
            ek, ei, en = _reserve_events(ek, ei, en, nev + 4 * nc + 8)   # a window and up to three vertices each
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
                sg = c_sg[c]
                Lt = he_len[t]
                A = he_tail[t]
                B = he_head[t]
                O = he_opp[t]
                lo, hi = _trim_by_end_vertices(sx, sy, c_lo[c], c_hi[c], sg, Lt, vstamp[A] == stamp, dist[A],
                                               vstamp[B] == stamp, dist[B])
                if hi - lo <= 1e-12 * Lt:
                    continue
                key = _window_min(sx, sy, lo, hi, sg)
                if key > cut:
                    continue
                vx = he_ox[t]
                vy = he_oy[t]
                if vstamp[O] == stamp and _beaten_through_opposite(sx, sy, lo, hi, sg, vx, vy, dist[O]):
                    continue
                for e in range(3):
                    lit, dd, ax, ay = _path_to_window_vertex(e, sx, sy, lo, hi, sg, Lt, vx, vy)
                    if not lit:
                        continue
                    u = A if e == 0 else (B if e == 1 else O)
                    if vstamp[u] != stamp:
                        nt = _first_visit(u, stamp, vstamp, dist, vdone, touched, nt)
                    if dd < dist[u] * _IMPROVE:
                        # arrival role: tail 1, head 2, opposite 0
                        _record_arrival(u, dd, (e + 1) % 3, t, ax, ay, dist, arr_role, arr_h, arr_x, arr_y)
                        if emitter[u] and dd <= cut:
                            vdone[u] = 0
                            nev = _bq_push(bhead, ek, ei, en, nev, dd, -u - 1, inv_delta, cur, nb)
                            qn += 1
                nev = _queue_window(p_h, p_sx, p_sy, p_lo, p_hi, p_sg, npool, t, sx, sy, lo, hi, sg, key, bhead,
                                    ek, ei, en, nev, inv_delta, cur, nb)
                qn += 1
                npool += 1
            nc = 0
            # ---- next event ------------------------------------------------------------------------------
            if qn == 0 or stop[0] != 0:
                break
            key, item, cur = _bq_pop(bhead, ek, ei, en, cur, nb)
            qn -= 1
            if key > cut:
                continue
            if item >= 0:
                # ---- window: light the face behind its half-edge, continue across the two other edges ----------
                h = p_h[item]
                sx = p_sx[item]
                sy = p_sy[item]
                b0 = p_lo[item]
                b1 = p_hi[item]
                sg = p_sg[item]
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
                    he, px, py, qx, qy = _exit_edge(e, h, he_len[h], vx, vy)
                    c0 = r0 if e == 0 else l0
                    c1 = r1 if e == 0 else l1
                    t = he_twin[he]
                    if t < 0 or c1 <= c0:
                        continue
                    lit, s1x, s1y, lo, hi = _unfold_across_edge(sx, sy, c0, c1, px, py, qx, qy, he_len[he],
                                                                he_tox[he], he_tsx[he])
                    if lit:
                        nc = _push_child(c_t, c_sx, c_sy, c_lo, c_hi, c_sg, nc, t, s1x, s1y, lo, hi, sg)
                continue
            # ---- vertex: a pseudo-source lighting the faces around it -------------------------------------------
            v = -item - 1
            if vdone[v] == stamp or key > dist[v]:
                continue
            vdone[v] = stamp
            ek, ei, en = _reserve_events(ek, ei, en, nev + 2 * (v_ptr[v + 1] - v_ptr[v]) + 8)   # two per face
            # MMP: a shortest path through a saddle turns by >= pi on both sides, so the pseudo-source only lights
            # the sector [alpha + pi, alpha + theta - pi] opposite the arrival direction alpha
            sector = fan_ok[v] and arr_role[v] >= 0
            alpha = 0.0
            if sector:
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
                        nt = _first_visit(u, stamp, vstamp, dist, vdone, touched, nt)
                    if dd < dist[u] * _IMPROVE:
                        _record_arrival(u, dd, e + 1, h, vx, vy, dist, arr_role, arr_h, arr_x, arr_y)
                        if emitter[u] and dd <= cut:
                            vdone[u] = 0
                            nev = _bq_push(bhead, ek, ei, en, nev, dd, -u - 1, inv_delta, cur, nb)
                            qn += 1
                t = he_twin[h]
                if t < 0 or nc >= _MAX_CHILDREN:
                    continue
                x0 = 0.0
                x1 = Lh
                if sector:
                    lit, x0, x1 = _sector_on_edge(alpha, v_theta[v], fan_start[h], he_corner[h], vx, vy, Lh)
                    if not lit:
                        continue
                # interval [x0, x1] of frame(h) -> frame(t)
                q0 = he_tox[h] + he_tsx[h] * x0
                q1 = he_tox[h] + he_tsx[h] * x1
                nc = _push_child(c_t, c_sx, c_sy, c_lo, c_hi, c_sg, nc, t, he_tox[h] + he_tsx[h] * vx, -vy,
                                 min(q0, q1), max(q0, q1), key)
        before = nout
        out_v, out_d, nout = _append_results(out_v, out_d, nout, touched, nt, dist, cut)
        counts[i] = nout - before
    return counts, out_v[:nout], out_d[:nout]
