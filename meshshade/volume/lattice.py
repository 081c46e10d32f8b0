"""The volume's lattice: a graded octree of cubes anchored in world coordinates (docs/physics.md §15.2).

The object's volume is discretised on cubes of side h_l = h0 2^l whose corners lie on the world lattice h_l Z^3
(anchored at the origin, not at the mesh): where the mesh changes, only the cubes near the change move. Level 0
(the finest) covers the surface and a band below it; deeper, each level may be used from the depth ``bands[l]``
on, and nothing is kept deeper than ``depth_max`` (the light has died out there; the cut is a no-flux boundary).
The inside is given by a depth function (positive inside, :mod:`meshshade.volume.inside`), so any surface whose
winding number encloses a volume can be meshed, watertight or not.

Every cube is split into Kuhn's six tetrahedra around its main diagonal, so the P1 functions on neighbouring
cubes agree on shared faces; where a cube of level l meets cubes of level l - 1, the finer cubes' corners on the
coarser cube's edges and faces ("hanging" nodes) are tied to the coarser cube's P1 trace: an edge midpoint to the
mean of the edge's ends, a face centre to the mean of the face's lowest and highest corners (every Kuhn face
diagonal runs between them), which keeps the space conforming. A 2:1 grading (no cube next to one two levels
finer) is guaranteed by the bands (:func:`check_bands`).

Sets of lattice points (the corners of many cubes, shared between neighbours) are numbered on a dense grid of
the finest spacing over the lattice's box (:class:`NodeGrid`): each cube marks its corners, the marks are numbered
slab by slab in the order of their coordinates, and every look-up is an index, in compiled loops run in blocks on
the worker threads (:func:`meshshade.pacing.run_in_blocks`). Nothing is sorted.

Pure array work (numpy and compiled loops); the depth function is the only call-out.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from meshshade.errors import MeshshadeError, NoVolumeError
from meshshade.geometry.sorting import sorted_unique
from meshshade.pacing import default_threads, run_in_blocks

__all__ = ["Grading", "Lattice", "NodeGrid", "KUHN", "CORNERS", "build_lattice", "coarser_lattice", "check_bands",
           "locate_points", "MAX_INDEX_CELLS"]

#: Kuhn's six tetrahedra of the unit cube: corner (i, j, k) has index i + 2 j + 4 k; each path 0 -> 7 along the
#: axes in one order is a tetrahedron
KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]], dtype=np.int64)
#: the cube's corners, index i + 2 j + 4 k
CORNERS = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=np.int64)
#: the cube's 12 edges (corner pairs) and 6 faces (lowest and highest corner: Kuhn's diagonal of the face)
EDGES = np.array([(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)])
FACE_DIAGONALS = np.array([(0, 3), (4, 7), (0, 5), (2, 7), (0, 6), (1, 7)])
#: the largest dense index (level-0 cells of the bounding box) the point location builds; above it, an error
#: names the resolution (8 bytes per cell would be 2 GB)
MAX_INDEX_CELLS = 2 ** 28
_BITS = 20
_OFF = 1 << (_BITS - 1)
#: a point this close (in units of h0) to a lattice plane lies on it (rounding of k h0 / h0)
_EPS = 1e-9


class Grading(NamedTuple):
    """The lattice's resolution: ``h0`` mm, level l >= 1 allowed from depth ``bands[l]`` mm (``bands[0] = 0``),
    nothing deeper than ``depth_max`` mm."""

    h0: float
    bands: tuple
    depth_max: float

    @property
    def levels(self) -> int:
        return len(self.bands)


def check_bands(grading: Grading) -> None:
    """Raise unless the bands guarantee a 2:1 grading: bands[l + 1] - bands[l] >= sqrt(3) h_l for l >= 1 (a cube
    of level l + 2 then lies more than its neighbours' reach below any cube of level l; the depth function is
    1-Lipschitz)."""
    b, h0 = grading.bands, grading.h0
    if b[0] != 0.0 or any(b[k + 1] < b[k] for k in range(len(b) - 1)):
        raise MeshshadeError(f"lattice bands must start at 0 and increase, got {b}")
    for l in range(1, len(b) - 1):
        if b[l + 1] - b[l] < math.sqrt(3.0) * h0 * 2 ** l * (1 - 1e-12):
            raise MeshshadeError(f"lattice bands too close for a 2:1 grading at level {l}: {b}")


def _pack(ijk):
    """int64 key of integer coordinates (|coordinate| < 2^19)."""
    ijk = np.asarray(ijk, dtype=np.int64) + _OFF
    return (ijk[..., 0] << (2 * _BITS)) | (ijk[..., 1] << _BITS) | ijk[..., 2]


def _unpack(key):
    m = (1 << _BITS) - 1
    return np.stack([(key >> (2 * _BITS)) & m, (key >> _BITS) & m, key & m], axis=-1) - _OFF


@numba.njit(cache=True, nogil=True, inline="always")
def _corner(glo, ijk, scale, stride, c, k):
    """The grid index of corner k of item c (as :func:`_mark_corners` describes the items)."""
    s = scale[c]
    return ((ijk[c, 0] + stride * (k & 1)) * s - glo[0], (ijk[c, 1] + stride * ((k >> 1) & 1)) * s - glo[1],
            (ijk[c, 2] + stride * ((k >> 2) & 1)) * s - glo[2])


@numba.njit(cache=True, nogil=True)
def _mark_corners(grid, glo, ijk, scale, stride, c0, c1):
    """grid[corner - glo] = 0 at the 8 corners of items c0..c1: item c's cube has side ``scale[c]`` (in grid
    units) and ijk[c] in units of it; its corners lie ``stride`` sides apart (1: the cube's own corners)."""
    for c in range(c0, c1):
        for k in range(8):
            x, y, z = _corner(glo, ijk, scale, stride, c, k)
            grid[x, y, z] = 0


@numba.njit(cache=True, nogil=True)
def _count_slabs(grid, counts, i0, i1):
    """counts[i] = the marked points of slab i, for slabs i0..i1."""
    for i in range(i0, i1):
        n = 0
        for j in range(grid.shape[1]):
            for k in range(grid.shape[2]):
                if grid[i, j, k] >= 0:
                    n += 1
        counts[i] = n


@numba.njit(cache=True, nogil=True)
def _number_slabs(grid, start, glo, coords, i0, i1):
    """Number the marked points of slabs i0..i1 in the order (i, j, k) from start[i]; coords[id] = the point."""
    for i in range(i0, i1):
        q = start[i]
        for j in range(grid.shape[1]):
            for k in range(grid.shape[2]):
                if grid[i, j, k] >= 0:
                    grid[i, j, k] = q
                    coords[q, 0] = i + glo[0]
                    coords[q, 1] = j + glo[1]
                    coords[q, 2] = k + glo[2]
                    q += 1


@numba.njit(cache=True, nogil=True)
def _corner_ids(grid, glo, ijk, scale, stride, out, c0, c1):
    """out[c, k] = the number of corner k of item c (as :func:`_mark_corners`)."""
    for c in range(c0, c1):
        for k in range(8):
            x, y, z = _corner(glo, ijk, scale, stride, c, k)
            out[c, k] = grid[x, y, z]


@numba.njit(cache=True, nogil=True)
def _point_ids(grid, glo, pts, out, p0, p1):
    """out[p] = the number of the grid point pts[p] (grid units), -1 where it is not numbered or off the grid."""
    nx, ny, nz = grid.shape
    for p in range(p0, p1):
        x, y, z = pts[p, 0] - glo[0], pts[p, 1] - glo[1], pts[p, 2] - glo[2]
        if 0 <= x < nx and 0 <= y < ny and 0 <= z < nz:
            out[p] = grid[x, y, z]
        else:
            out[p] = -1


class NodeGrid:
    """A dense grid of lattice points over the box ``lo``..``hi`` (inclusive; integer coordinates in units of h0,
    multiples of ``unit``): :meth:`mark` cubes' corners, :meth:`number` them in the order of their coordinates (x,
    then y, then z: the order of a sort of packed keys), then :meth:`corners` and :meth:`ids` look numbers up.
    ``coords`` (n, 3) are the numbered points (units of h0)."""

    def __init__(self, lo, hi, unit: int = 1):
        self.unit = int(unit)
        self.lo = np.asarray(lo, dtype=np.int64) // self.unit
        shape = tuple(int(x) for x in np.asarray(hi, dtype=np.int64) // self.unit - self.lo + 1)
        if math.prod(shape) > MAX_INDEX_CELLS:
            raise MeshshadeError(f"the volume's lattice would need {math.prod(shape):.3g} grid points to number; "
                                 "use a coarser volume resolution")
        self.grid = np.full(shape, -1, dtype=np.int32)
        self.coords = None

    def _cubes(self, ijk, scale):
        ijk = np.ascontiguousarray(ijk, dtype=np.int64).reshape(-1, 3)
        # C-contiguous and writeable always (a read-only one made numba compile the loops twice)
        scale = np.require(np.broadcast_to(np.asarray(scale, dtype=np.int64) // self.unit, ijk.shape[:1]),
                           requirements=("C", "W"))
        return ijk, scale

    def mark(self, ijk, scale, stride: int = 1) -> None:
        """Mark the corners of the cubes ``ijk`` (c, 3) of side ``scale`` (c,) h0 (``stride``: see
        :func:`_mark_corners`)."""
        ijk, scale = self._cubes(ijk, scale)
        run_in_blocks(lambda a, b: _mark_corners(self.grid, self.lo, ijk, scale, int(stride), a, b), ijk.shape[0],
                      min_block=4096)

    def number(self) -> int:
        """Number the marked points; returns how many."""
        nx = self.grid.shape[0]
        counts = np.zeros(nx, dtype=np.int64)
        per = max(1, -(-nx // (4 * default_threads())))
        run_in_blocks(lambda a, b: _count_slabs(self.grid, counts, a, b), nx, block=per)
        start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        n = int(counts.sum())
        if n >= 2 ** 31 - 1:
            raise MeshshadeError("the volume's lattice has too many nodes; use a coarser volume resolution")
        coords = np.empty((n, 3), dtype=np.int64)
        run_in_blocks(lambda a, b: _number_slabs(self.grid, start, self.lo, coords, a, b), nx, block=per)
        self.coords = coords * self.unit
        return n

    def corners(self, ijk, scale, stride: int = 1) -> np.ndarray:
        """(c, 8) numbers of the corners of the cubes (as :meth:`mark`)."""
        ijk, scale = self._cubes(ijk, scale)
        out = np.empty((ijk.shape[0], 8), dtype=np.int64)
        run_in_blocks(lambda a, b: _corner_ids(self.grid, self.lo, ijk, scale, int(stride), out, a, b),
                      ijk.shape[0], min_block=4096)
        return out

    def ids(self, pts) -> np.ndarray:
        """(p,) numbers of the points ``pts`` (p, 3) (units of h0); -1 where not numbered."""
        pts = np.ascontiguousarray(pts, dtype=np.int64).reshape(-1, 3)
        on = np.all(pts % self.unit == 0, axis=1)
        q = np.ascontiguousarray(np.where(on[:, None], pts // self.unit, self.lo - 1))
        out = np.empty(q.shape[0], dtype=np.int64)
        run_in_blocks(lambda a, b: _point_ids(self.grid, self.lo, q, out, a, b), q.shape[0], min_block=4096)
        return out


class Lattice:
    """The cubes and nodes of a graded lattice (module docstring). Build with :func:`build_lattice`.

    Attributes: ``grading``; ``level`` (C,) and ``ijk`` (C, 3) of the cubes (coordinates in units of the cube's
    own side); ``nodes`` (N, 3) mm and ``depth`` (N,) mm of their corners (positive inside; beyond a few cells from
    the surface only its sign is meaningful); ``cell_nodes`` (C, 8) corner indices; ``hanging`` (H,) the hanging
    nodes and ``parents`` (H, 2) the nodes whose mean each equals (possibly hanging themselves);
    ``stats`` counts per level and seconds."""

    def __init__(self, grading, level, ijk, nodes, depth, cell_nodes, hanging, parents, index, index_lo, stats,
                 node_grid):
        self.grading = grading
        self.node_grid = node_grid     # the nodes' numbers on a dense grid (NodeGrid), for the coarser levels
        self.level, self.ijk = level, ijk
        self.nodes, self.depth = nodes, depth
        self.cell_nodes = cell_nodes
        self.hanging, self.parents = hanging, parents
        self._index, self._index_lo = index, index_lo
        self.stats = stats

    @property
    def node_keys(self) -> np.ndarray:
        """(N,) int64: each node's integer coordinates (units of h0) packed in one key, ascending."""
        return _pack(self.node_grid.coords)

    @property
    def n_nodes(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def n_cells(self) -> int:
        return int(self.level.shape[0])

    @property
    def cell_size(self) -> np.ndarray:
        """(C,) side of each cube, mm."""
        return self.grading.h0 * np.exp2(self.level.astype(np.float64))

    def locate(self, points):
        """(cell (p,) int64, -1 outside every cube; bary (p, 4) Kuhn barycentrics; nodes (p, 4)) of ``points``
        (p, 3) mm: the tetrahedron of the lattice holding each point and its P1 weights."""
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        cell = np.empty(P.shape[0], dtype=np.int64)
        bary = np.empty((P.shape[0], 4))
        nodes = np.empty((P.shape[0], 4), dtype=np.int64)
        run_in_blocks(lambda a, b: locate_points(P, self.grading.h0, self._index, self._index_lo, self.level,
                                                 self.ijk, self.cell_nodes, cell, bary, nodes, a, b),
                      P.shape[0], min_block=16384)
        return cell, bary, nodes


@numba.njit(cache=True, nogil=True, inline="always")
def kuhn_weights(x, y, z):
    """(corner v1, corner v2, w0, w1, w2, w3): the Kuhn tetrahedron of the point at local cube coordinates
    (x, y, z) (clamped to [0, 1]) and its P1 weights on the cube's corners 0, v1, v2 and 7 (corner i + 2j + 4k):
    the path from corner 0 to 7 through the coordinates in decreasing order."""
    u = (min(1.0, max(0.0, x)), min(1.0, max(0.0, y)), min(1.0, max(0.0, z)))
    a, b, e = 0, 1, 2
    if u[a] < u[b]:
        a, b = b, a
    if u[b] < u[e]:
        b, e = e, b
    if u[a] < u[b]:
        a, b = b, a
    v1 = 1 << a
    v2 = v1 | (1 << b)
    return v1, v2, 1.0 - u[a], u[a] - u[b], u[b] - u[e], u[e]


@numba.njit(cache=True, nogil=True)
def locate_points(P, h0, index, lo, level, ijk, cell_nodes, cell, bary, nodes, p0, p1):
    """For each point p0..p1: the cube holding it (dense index of level-0 cells), the Kuhn tetrahedron by the
    order of its coordinates in the cube, the barycentrics and the corner nodes; cell -1 (weights 0) outside the
    lattice."""
    nx, ny, nz = index.shape
    for p in range(p0, p1):
        # lattice coordinates, nudged up by a rounding's worth: a node at k h0 computed as k - 1e-15 stays on k
        fx, fy, fz = P[p, 0] / h0 + _EPS, P[p, 1] / h0 + _EPS, P[p, 2] / h0 + _EPS
        i0 = int(math.floor(fx)) - lo[0]
        j0 = int(math.floor(fy)) - lo[1]
        k0 = int(math.floor(fz)) - lo[2]
        c = -1
        # a point on a lattice plane belongs to the cubes on both sides: try the lower ones if the upper is absent
        for t in range(8):
            di, dj, dk = t & 1, (t >> 1) & 1, (t >> 2) & 1
            if (di and fx - math.floor(fx) > 2 * _EPS) or (dj and fy - math.floor(fy) > 2 * _EPS) or \
                    (dk and fz - math.floor(fz) > 2 * _EPS):
                continue
            i, j, k = i0 - di, j0 - dj, k0 - dk
            if 0 <= i < nx and 0 <= j < ny and 0 <= k < nz and index[i, j, k] >= 0:
                c = index[i, j, k]
                break
        cell[p] = c
        if c < 0:
            for q in range(4):
                bary[p, q] = 0.0
                nodes[p, q] = 0
            continue
        h = h0 * (2.0 ** level[c])
        v1, v2, bary[p, 0], bary[p, 1], bary[p, 2], bary[p, 3] = kuhn_weights(
            P[p, 0] / h - ijk[c, 0], P[p, 1] / h - ijk[c, 1], P[p, 2] / h - ijk[c, 2])
        nodes[p, 0] = cell_nodes[c, 0]
        nodes[p, 1] = cell_nodes[c, v1]
        nodes[p, 2] = cell_nodes[c, v2]
        nodes[p, 3] = cell_nodes[c, 7]


@numba.njit(cache=True, nogil=True)
def _fill_index(index, lo, level, ijk, c0, c1):
    """index[level-0 cell] = the cube covering it, for cubes c0..c1 (cubes cover disjoint cells)."""
    for c in range(c0, c1):
        s = 1 << level[c]
        i0, j0, k0 = ijk[c, 0] * s - lo[0], ijk[c, 1] * s - lo[1], ijk[c, 2] * s - lo[2]
        for i in range(i0, i0 + s):
            for j in range(j0, j0 + s):
                for k in range(k0, k0 + s):
                    index[i, j, k] = c


#: corners closer to the surface than this fraction of the finest spacing are taken as just outside it
#: (:func:`snap_corner_depths`)
CORNER_SNAP = 1e-4


def snap_corner_depths(depth, h0: float, points=None, side=None):
    """``depth`` with the corners nearer the surface than ``CORNER_SNAP * h0`` put that far outside it; with the
    corners' ``points`` and ``side`` (points -> (p,) bool, inside), a corner on a face with the medium on both
    sides (a seam between parts) is put a hair inside instead: the eight points CORNER_SNAP h0 away along the
    diagonals all fall inside there, where a face that bounds the medium has both sides (the
    split sphere's two hemispheres meeting on the plane x = 0, on the lattice's planes, had been cut apart by
    a void: 281 mm^2 of cut surface inside it and 5.3 % of its red light lost).

    Faces on the lattice's planes (a box at round coordinates) put corners on the surface, where the distance and
    the winding number's side are rounding: a hair outside, every cube on the inside has those corners on its cut
    (the cut surface, a hair inside the face, carries the face's boundary term), and a cube on the outside has no
    corner inside and is dropped, whatever the rounding. Put a hair inside, the inside cube was uncut and the outside
    one dropped, and the face lost its boundary (a box of apple 100 x 100 x 20 mm at the origin read +43 % in the
    middle of its lit face, its cut surface 12,800 of 28,000 mm^2). The surface moves by at most 1e-4 h0."""
    tiny = CORNER_SNAP * float(h0)
    near = np.abs(depth) < tiny
    out = np.where(near, -tiny, depth)
    if side is not None and near.any():
        idx = np.flatnonzero(near)
        # the eight diagonal directions: none lies in a lattice plane through the corner, where a face on that plane
        # would hold the probe itself
        offsets = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], dtype=np.float64) * tiny
        probe = np.asarray(side((np.asarray(points)[idx][:, None, :] + offsets[None, :, :]).reshape(-1, 3)),
                           dtype=bool).reshape(idx.size, 8)
        out[idx[probe.all(axis=1)]] = tiny            # inside on every side: a seam inside the medium
    return out


def build_lattice(depth, lo, hi, grading: Grading, *, refine=None, stats: dict | None = None) -> Lattice:
    """The graded lattice of the volume ``depth(points, bound) > 0`` inside the box ``lo``..``hi`` (mm).

    ``depth(points (p, 3), bound, sign=, exact=)`` returns the signed distance to the surface (positive inside),
    clipped to +-``bound``; ``sign`` (p,) int8 gives the side where known (0: unknown), ``exact=False`` may
    return a lower bound of the magnitude and ``exact=None`` only the side (any magnitude). Top-down: a cube of level l is dropped when its centre lies more than its half-diagonal r_l
    outside, or deeper than ``depth_max + r_l``; it is split when part of it may lie shallower than
    ``bands[l]`` and its level is above the surface's level there; else kept. The surface's level is 0, or, with
    ``refine`` (a callable: cube centres (p, 3) -> bool (p,)), 0 where ``refine`` says so and 1 elsewhere (the
    lattice finer only where the light calls for it). The corners of every cube that may be cut are evaluated
    once (clipped beyond two cells); a cube whose corners all lie outside is dropped (a sliver thinner than the
    lattice between its corners is below its resolution)."""
    import time

    check_bands(grading)
    t0 = time.perf_counter()
    h0, bands, L = float(grading.h0), grading.bands, grading.levels - 1
    hL = h0 * 2 ** L
    a = np.floor(np.asarray(lo, dtype=np.float64) / hL).astype(np.int64) - 1
    b = np.floor(np.asarray(hi, dtype=np.float64) / hL).astype(np.int64) + 2
    if np.any(np.abs(a) * 2 ** L >= _OFF) or np.any(np.abs(b) * 2 ** L >= _OFF):
        raise MeshshadeError("the mesh is too large for the volume's lattice at this resolution "
                             f"({np.max(hi) - np.min(lo):.4g} mm at {h0:.4g} mm)")
    g = np.meshgrid(*[np.arange(a[i], b[i]) for i in range(3)], indexing="ij")
    cand = np.stack([x.ravel() for x in g], axis=1)
    cand_sign = np.zeros(cand.shape[0], dtype=np.int8)     # known side of each candidate (0: unknown)
    centre_sign = cand_sign                                  # known side of each candidate's centre
    parent_d = np.zeros(cand.shape[0])                       # its parent's depth bound at the parent's centre
    kept, counts, evaluated = [None] * (L + 1), [0] * (L + 1), 0
    surface = None              # which cubes kept at level 1 may be cut (they are evaluated with level 0)
    for l in range(L, 0, -1):
        h = h0 * 2 ** l
        r = 0.5 * math.sqrt(3.0) * h
        bound = max(bands[l] + 4 * r, grading.depth_max + 2 * r) if l == L else bands[l] + 4 * r
        centres = (cand + 0.5) * h
        d = depth(centres, bound, sign=centre_sign, exact=False)
        evaluated += cand.shape[0]
        out = d < -r
        shallow = d - r < bands[l]
        if l == 1 and refine is not None:
            # the surface's level is 1 except where ``refine`` asks for 0
            split = shallow & ~out
            split[split] = refine(centres[split])
            keep = ~(out | split) & (d - r <= grading.depth_max)
            surface = (d < r)[keep]
        else:
            split = shallow
            keep = ~(out | split) & (d - r <= grading.depth_max)
        kept[l] = cand[keep]
        counts[l] = int(keep.sum())
        sub = ~out & split
        # a parent wholly on one side (|d| > r) gives its children its side, and a parent whose centre lies
        # farther than r / 2 from the surface (|d| is a lower bound) its children's centres: only the rest need the
        # winding number
        ds = d[sub]
        side = np.where(np.abs(ds) > r, np.sign(ds), 0).astype(np.int8)
        cand = (2 * cand[sub][:, None, :] + CORNERS[None, :, :]).reshape(-1, 3)
        cand_sign = np.repeat(side, 8)
        centre_sign = np.repeat(np.where(np.abs(ds) > 0.5 * r, np.sign(ds), 0).astype(np.int8), 8)
        parent_d = np.repeat(ds, 8)
    # the corners of the finest candidates and of the coarser cubes that may be cut are numbered and evaluated once
    t_mid = time.perf_counter()
    coarse = kept[1][surface] if surface is not None and surface.any() else np.zeros((0, 3), dtype=np.int64)
    boxes = [x for x in (cand, cand + 1, 2 * coarse, 2 * coarse + 2) if x.size]
    if not boxes:        # no cube the surface may cut: nothing inside
        raise NoVolumeError("the mesh encloses no volume the lattice can resolve (winding number below 1/2 "
                            f"everywhere at {h0:.3g} mm)")
    grid = NodeGrid(np.min([x.min(axis=0) for x in boxes], axis=0), np.max([x.max(axis=0) for x in boxes], axis=0))
    grid.mark(cand, 1)
    grid.mark(coarse, 2)
    n_corners = grid.number()
    fine_ids = grid.corners(cand, 1)                                   # (C0, 8)
    coarse_ids = grid.corners(coarse, 2)                               # (C1, 8)
    # a corner of a level-0 candidate nearer its parent's centre than the parent's depth bound is on its side
    known = np.zeros(n_corners, dtype=np.int8)
    run_in_blocks(lambda a, b: _spread_sign(fine_ids, parent_d, h0, known, a, b), cand.shape[0], min_block=4096)
    # first each corner's side; the distance only at the corners of cubes the surface cuts (mixed sides): the
    # others' magnitude is never read (a cube with its corners on one side is whole or dropped)
    pts = grid.coords.astype(np.float64) * h0
    bnd = 2.0 * math.sqrt(3.0) * h0        # the depths are clipped there (:func:`_finish`, h_cut = h0)
    cd = np.asarray(depth(pts, bnd, sign=known, exact=None), dtype=np.float64)
    inside = cd > 0.0
    need = np.zeros(n_corners, dtype=bool)
    for ids in (fine_ids, coarse_ids):
        if ids.size:
            s8 = inside[ids]
            need[ids[s8.any(axis=1) & ~s8.all(axis=1)].ravel()] = True
    if need.any():
        cd[need] = depth(pts[need], bnd, sign=np.where(inside[need], 1, -1).astype(np.int8))
    cd = snap_corner_depths(cd, h0, pts, lambda q: depth(q, bnd, exact=None) > 0.0)   # before the cubes are kept
    # or dropped by their corners' sides
    evaluated += n_corners
    keep0 = cd[fine_ids].max(axis=1) > 0.0 if fine_ids.size else np.zeros(0, dtype=bool)
    kept[0] = cand[keep0]
    counts[0] = int(keep0.sum())
    if coarse.size:
        # a coarse surface cube whose corners are all outside holds no inside at the lattice's resolution
        empty = cd[coarse_ids].max(axis=1) <= 0.0
        if empty.any():
            drop = np.flatnonzero(surface)[empty]
            kept[1] = np.delete(kept[1], drop, axis=0)
            counts[1] = int(kept[1].shape[0])
    level = np.concatenate([np.full(k.shape[0], l, dtype=np.int64) for l, k in enumerate(kept)])
    ijk = np.concatenate(kept)
    if level.size == 0:
        raise NoVolumeError("the mesh encloses no volume the lattice can resolve (winding number below 1/2 "
                             f"everywhere at {h0:.3g} mm)")
    t1 = time.perf_counter()
    # every corner of a cube that may be cut was evaluated above; the others are inside
    out = _finish(grading, level, ijk, None, grid, cd, h0)
    out.stats["volume_cells_per_level"] = counts
    out.stats["volume_depth_queries"] += int(evaluated)
    out.stats["timings"] = {"lattice coarse cells": t_mid - t0, "lattice fine cells": t1 - t_mid,
                            **out.stats["timings"]}
    if stats is not None:
        stats.update(out.stats)
    return out


@numba.njit(cache=True, nogil=True)
def _spread_sign(ids, parent_d, h, known, c0, c1):
    """known[corner] = the side of the parent's centre at the 8 corners of items c0..c1 that lie nearer that
    centre than the parent's depth bound |parent_d| (item c is child c % 8 of its parent, a cube of side 2h; its
    corner k lies at offsets in {-1, 0, 1} h from the parent's centre). Corners on known sides never disagree."""
    for c in range(c0, c1):
        pd = parent_d[c]
        if pd == 0.0:
            continue
        o = c % 8
        s = 1 if pd > 0.0 else -1
        for k in range(8):
            ox = (o & 1) + (k & 1) - 1
            oy = ((o >> 1) & 1) + ((k >> 1) & 1) - 1
            oz = ((o >> 2) & 1) + ((k >> 2) & 1) - 1
            if abs(pd) > h * math.sqrt(ox * ox + oy * oy + oz * oz):
                known[ids[c, k]] = s


def _finish(grading, level, ijk, depth, known_grid, known_depth, h_cut):
    """The :class:`Lattice` of the cubes ``level``, ``ijk``: corners numbered on a :class:`NodeGrid`, their depths
    (read from ``known_grid`` -> ``known_depth`` where it has them; the corners of cubes of side ``h_cut`` or finer
    that may be cut evaluated, clipped beyond two cells), hanging nodes and the point index."""
    import time

    t1 = time.perf_counter()
    h0 = float(grading.h0)
    scale = np.left_shift(1, level)
    lo = np.min(ijk * scale[:, None], axis=0)
    hi = np.max((ijk + 1) * scale[:, None], axis=0)
    grid = NodeGrid(lo, hi, unit=int(scale.min()))
    grid.mark(ijk, scale)
    n = grid.number()
    cell_nodes = grid.corners(ijk, scale)
    nodes = grid.coords.astype(np.float64) * h0
    bound = 2.0 * math.sqrt(3.0) * h_cut
    dep = np.full(n, np.nan)
    if known_grid is not None:
        kid = known_grid.ids(grid.coords)
        hit = kid >= 0
        dep[hit] = np.clip(known_depth[kid[hit]], -bound, bound)
    # corners still unknown: those of the finest cubes (the only ones the surface may cut) are evaluated; the
    # rest lie deeper than band 1 and are inside
    finest = level == level.min()
    ask = np.zeros(n, dtype=bool)
    ask[cell_nodes[finest].ravel()] = True
    ask &= np.isnan(dep)
    queries = int(ask.sum())
    if queries and depth is not None:
        dep[ask] = depth(nodes[ask], bound)
    dep[np.isnan(dep)] = bound
    # a corner on the surface (faces on the lattice's planes: boxes at round coordinates) is put a hair outside,
    # so that rounding (of the distance, the winding number, a float32 file's coordinates) does not decide its side
    if depth is not None:
        dep = snap_corner_depths(dep, h0, nodes, lambda q: depth(q, bound, exact=None) > 0.0)
    else:
        dep = snap_corner_depths(dep, h0)
    t2 = time.perf_counter()
    hanging, parents = _hanging_nodes(grid, level, ijk)
    shape = tuple(int(x) for x in hi - lo)
    if math.prod(shape) > MAX_INDEX_CELLS:
        raise MeshshadeError(f"the volume's lattice would need {math.prod(shape):.3g} cells of {h0:.3g} mm to "
                             "index; use a coarser volume resolution")
    index = np.full(shape, -1, dtype=np.int32)
    run_in_blocks(lambda a, b: _fill_index(index, lo, level, ijk, a, b), level.size, min_block=4096)
    t3 = time.perf_counter()
    counts = np.bincount(level, minlength=grading.levels).tolist()
    info = {"volume_cells_per_level": counts, "volume_nodes": int(n), "volume_hanging_nodes": int(hanging.size),
            "volume_depth_queries": queries, "timings": {"lattice corners": t2 - t1, "lattice index": t3 - t2}}
    return Lattice(grading, level, ijk, nodes, dep, cell_nodes, hanging, parents, index, lo, info, grid)


def coarser_lattice(lattice: Lattice, depth) -> Lattice:
    """The lattice with its finest cubes merged into their parents (a multigrid level: the union of the same
    cubes, one level coarser where it was finest; corners' depths reused where they were nodes, else evaluated
    by ``depth``, or left at the cut-free value without it). Its grading gains a level if the finest cubes were
    already of the coarsest level."""
    lmin = int(lattice.level.min())
    fine = lattice.level == lmin
    parents = sorted_unique(_pack(np.floor_divide(lattice.ijk[fine], 2)))
    level = np.concatenate([lattice.level[~fine], np.full(parents.size, lmin + 1, dtype=np.int64)])
    ijk = np.concatenate([lattice.ijk[~fine], _unpack(parents)])
    g = lattice.grading
    grading = g if lmin + 1 < g.levels else Grading(g.h0, tuple(g.bands) + (g.bands[-1] + g.h0 * 2 ** (lmin + 1),),
                                                    g.depth_max)
    return _finish(grading, level, ijk, depth, lattice.node_grid, lattice.depth, g.h0 * 2 ** (lmin + 1))


@numba.njit(cache=True, inline="always")
def _grid_id(grid, glo, unit, x, y, z):
    """The number of the lattice point (x, y, z) (units of h0) on the grid, -1 where it has none."""
    if x % unit or y % unit or z % unit:
        return -1
    i, j, k = x // unit - glo[0], y // unit - glo[1], z // unit - glo[2]
    if 0 <= i < grid.shape[0] and 0 <= j < grid.shape[1] and 0 <= k < grid.shape[2]:
        return grid[i, j, k]
    return -1


@numba.njit(cache=True, nogil=True)
def _hanging_scan(grid, glo, unit, level, ijk, order, pairs, found, parents):
    """found[n], parents[n] for every node n at the midpoint of corners ``pairs`` (k, 2) (edges, then face
    diagonals) of a coarser cube, in the order: levels up, the pairs, cubes in ``order`` (the first met kept)."""
    lmax = 0
    for c in range(level.size):
        lmax = max(lmax, level[c])
    for l in range(1, lmax + 1):
        s = 1 << l
        half = s >> 1
        for e in range(pairs.shape[0]):
            p, q = pairs[e, 0], pairs[e, 1]
            for t in range(order.size):
                c = order[t]
                if level[c] != l:
                    continue
                bx, by, bz = ijk[c, 0] * s, ijk[c, 1] * s, ijk[c, 2] * s
                mid = _grid_id(grid, glo, unit, bx + ((p & 1) + (q & 1)) * half,
                               by + (((p >> 1) & 1) + ((q >> 1) & 1)) * half,
                               bz + (((p >> 2) & 1) + ((q >> 2) & 1)) * half)
                if mid < 0 or found[mid]:
                    continue
                found[mid] = True
                parents[mid, 0] = _grid_id(grid, glo, unit, bx + (p & 1) * s, by + ((p >> 1) & 1) * s,
                                           bz + ((p >> 2) & 1) * s)
                parents[mid, 1] = _grid_id(grid, glo, unit, bx + (q & 1) * s, by + ((q >> 1) & 1) * s,
                                           bz + ((q >> 2) & 1) * s)


def _hanging_nodes(grid: NodeGrid, level, ijk):
    """(hanging (H,), parents (H, 2)) node numbers: corners of finer cubes that lie on an edge midpoint or a face
    centre of a coarser cube, and the two nodes whose mean each must equal."""
    n = grid.coords.shape[0]
    found = np.zeros(n, dtype=bool)
    parents = np.zeros((n, 2), dtype=np.int64)
    order = np.argsort(level, kind="stable")
    _hanging_scan(grid.grid, grid.lo, grid.unit, level, ijk, order,
                  np.concatenate([EDGES, FACE_DIAGONALS]).astype(np.int64), found, parents)
    h = np.flatnonzero(found)
    return h, parents[h]
