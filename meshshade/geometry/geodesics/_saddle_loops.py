"""Compiled loops for pseudo-sources at saddle vertices (private; used by :mod:`._window_loops`).

A shortest path through a saddle vertex (cone angle theta > 2 pi) turns by at least pi on both sides (Mitchell,
Mount & Papadimitriou 1987), so a pseudo-source there only lights the sector [alpha + pi, alpha + theta - pi] of
the vertex's fan, opposite the direction alpha the path arrived from.  Angles are measured around the vertex,
counter-clockwise, across its unfolded fan of faces (radians); lengths in mm.  Half-edge frames as in
:mod:`._window_loops`.
"""
from __future__ import annotations

import numpy as np
from numba import njit


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


@njit(cache=True, nogil=True, inline="always")
def _sector_on_edge(alpha, theta, start, cor, vx, vy, Lh):
    """Part of half-edge h (y = 0 of its frame, length Lh) that a saddle pseudo-source at its opposite corner
    (vx, vy) may light: the rays inside the sector [alpha + pi, alpha + theta - pi] of the vertex's fan.

    ``alpha`` is the arrival angle (``_arrival_angle``), ``theta`` the cone angle, ``start`` the fan angle where
    this corner begins (towards the tail of h) and ``cor`` the corner angle.  Returns (lit, x0, x1).
    """
    width = theta - 2.0 * np.pi
    # the sector relative to this corner, which spans [0, corner] from direction v -> tail
    a0 = (alpha + np.pi - start) % theta
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
        return False, 0.0, Lh
    # rays from v at those angles (counter-clockwise from v -> tail) meet the edge y = 0
    ux = -vx
    uy = -vy
    nu = np.sqrt(ux * ux + uy * uy)
    ux /= nu
    uy /= nu
    x0 = 0.0
    x1 = Lh
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
    return True, x0, x1
