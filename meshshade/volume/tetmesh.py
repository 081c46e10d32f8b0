"""Tetrahedral meshes built by construction: graded boxes (slabs, blocks), for the volume transport's checks.

A box is cut into hexahedral cells along given node coordinates per axis and every cell into six tetrahedra
around its main diagonal (Kuhn's subdivision: neighbouring cells share their face diagonals, so the mesh is
conforming). :func:`graded_box` spaces the nodes geometrically away from a point, fine where the fluence varies
fast (near sources and the lit surface) and coarse where it does not.
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import MeshshadeError

__all__ = ["box_tetrahedra", "ball_tetrahedra", "graded_axis", "graded_box"]

# Kuhn's six tetrahedra of the unit cube: vertex (i, j, k) has index i + 2 j + 4 k; each path 0 -> 7 along the
# axes in one order is a tetrahedron
_KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])


def box_tetrahedra(xs, ys, zs):
    """(nodes (N, 3), tets (6 (nx-1)(ny-1)(nz-1), 4), positively oriented) of the box with node coordinates
    ``xs``, ``ys``, ``zs`` (each strictly increasing, mm)."""
    axes = [np.asarray(a, dtype=np.float64) for a in (xs, ys, zs)]
    if any(a.ndim != 1 or a.size < 2 or np.any(np.diff(a) <= 0) for a in axes):
        raise MeshshadeError("box node coordinates must be strictly increasing, at least two per axis")
    nx, ny, nz = (a.size for a in axes)
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    nodes = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    corner = [idx[i:nx - 1 + i, j:ny - 1 + j, k:nz - 1 + k].ravel() for k in (0, 1) for j in (0, 1) for i in (0, 1)]
    corners = np.stack(corner, axis=1)               # (cells, 8), local index i + 2 j + 4 k
    tets = corners[:, _KUHN].reshape(-1, 4)
    P = nodes[tets]
    det = np.linalg.det(P[:, 1:] - P[:, :1])
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return nodes, tets


def graded_axis(lo, hi, focus, h_min, ratio, h_max=np.inf):
    """Node coordinates from ``lo`` to ``hi`` (mm): spacing ``h_min`` at ``focus``, growing by ``ratio`` per cell
    away from it, at most ``h_max``; the end cells are stretched to land on ``lo`` and ``hi``."""
    if not (lo < hi and h_min > 0 and ratio >= 1.0):
        raise MeshshadeError("graded_axis needs lo < hi, h_min > 0 and ratio >= 1")
    focus = min(max(focus, lo), hi)

    def side(length):
        out, x, h = [], 0.0, h_min
        while x + h < length - 0.5 * h:
            x += h
            out.append(x)
            h = min(h * ratio, h_max)
        return np.array(out + [length]) if length > 0 else np.zeros(0)

    right = focus + side(hi - focus)
    left = focus - side(focus - lo)
    return np.concatenate([left[::-1], [focus], right]) if focus < hi else np.concatenate([left[::-1], [focus]])


def graded_box(lo, hi, focus, h_min, ratio=1.15, h_max=np.inf):
    """(nodes, tets) of the box ``lo``..``hi`` (3,) mm graded around ``focus`` (3,) by :func:`graded_axis`."""
    axes = [graded_axis(lo[a], hi[a], focus[a], h_min, ratio, h_max) for a in range(3)]
    return box_tetrahedra(*axes)


def ball_tetrahedra(radius, n):
    """(nodes, tets) of a ball of ``radius`` mm: the cube [-1, 1]^3 in n x n x n cells (Kuhn tetrahedra) mapped
    onto the ball radially, x -> radius x |x|_inf / |x|_2, so the cube's boundary nodes land exactly on the
    sphere (the discrete boundary is inscribed in it, an O(h^2) error in the geometry, as P1's own)."""
    if not (radius > 0 and int(n) >= 2):
        raise MeshshadeError("ball_tetrahedra needs radius > 0 and n >= 2 cells per axis")
    axis = np.linspace(-1.0, 1.0, int(n) + 1)
    nodes, tets = box_tetrahedra(axis, axis, axis)
    r2 = np.linalg.norm(nodes, axis=1)
    rinf = np.abs(nodes).max(axis=1)
    scale = np.divide(rinf, r2, out=np.ones_like(r2), where=r2 > 0)
    nodes = radius * nodes * scale[:, None]
    P = nodes[tets]
    det = np.linalg.det(P[:, 1:] - P[:, :1])
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return nodes, tets
