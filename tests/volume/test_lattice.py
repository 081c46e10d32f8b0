"""The volume's lattice (meshshade/volume/lattice.py, docs/physics.md §15.2): world anchoring, the 2:1 grading,
point location and the conforming P1 space over hanging nodes, checked against twins written here
(tests/volume/_volume_reference.py: the Kuhn tetrahedron of a point from the definition, a dense map of level-0
cells to cubes, the 26-neighbourhood of cubes).

* Anchoring: cubes lie on the world lattice h_l Z^3, so a mesh and the same mesh with a bump 30 mm away share
  every cube farther than a few cells from the bump (measured: none differs beyond 2.6 cube sides).
* 2:1 grading: no cube touches (face, edge or corner) a cube two levels finer, with the bands at the limit
  check_bands allows, with and without ``refine``; check_bands refuses bands closer than sqrt(3) h_l.
* locate: the barycentrics reproduce linear functions to rounding in cubes of every level, are >= 0 and sum
  to 1; points on lattice planes, edges and nodes are found, in a cube whose closed box holds them.
* Hanging nodes: a P1 field given by arbitrary values at the free nodes (hanging nodes the mean of their
  parents, resolved here) takes the same value on both sides of every face, edge and corner shared by cubes of
  different levels; with linear nodal values it is that linear function everywhere.
* coarser_lattice: its cubes do not overlap, cover every cube of the lattice (each fine cube lies in a coarser
  one or is kept) and only add the parents' missing children.
"""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from meshshade.errors import MeshshadeError
from meshshade.geometry.procedural import box, icosphere
from meshshade.volume.inside import SurfaceVolume
from meshshade.volume.lattice import Grading, build_lattice, check_bands, coarser_lattice

_spec = importlib.util.spec_from_file_location("_volume_reference", Path(__file__).with_name("_volume_reference.py"))
ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ref)


def tight_bands(h0, levels, first):
    """Bands at the limit of check_bands: bands[1] = first, then bands[l + 1] = bands[l] + sqrt(3) h0 2^l."""
    b = [0.0, first]
    for l in range(1, levels - 1):
        b.append(b[-1] + math.sqrt(3.0) * h0 * 2 ** l)
    return tuple(b)


def assert_two_to_one(lattice):
    """No two touching cubes differ by more than one level (the twin's 26-neighbourhood)."""
    grid, _ = ref.cell_grid(lattice.level, lattice.ijk)
    pairs = ref.neighbour_pairs(grid)
    jump = np.abs(lattice.level[pairs[:, 0]] - lattice.level[pairs[:, 1]])
    assert pairs.shape[0] > 0
    assert jump.max() <= 1, f"{int((jump > 1).sum())} touching pairs differ by {int(jump.max())} levels"
    return pairs, jump


@pytest.fixture(scope="module")
def ball_lattice():
    """A ball of radius 6.3 mm off the lattice's origin, h0 = 0.5 mm, four levels with tight bands."""
    g = Grading(0.5, tight_bands(0.5, 4, 1.0), 50.0)
    c = np.array([0.21, -0.37, 0.13])
    return build_lattice(ref.ball_depth(c, 6.3), c - 6.3, c + 6.3, g), c


@pytest.fixture(scope="module")
def refined_lattice():
    """A box 12 x 10 x 9 mm with the surface's level 0 only where ``refine`` says (a half-space x > 0.7 and a
    random tenth of the rest), level 1 elsewhere: level transitions along the surface, not only with depth."""
    lo, hi = np.array([-6.1, -5.2, -4.3]), np.array([5.9, 4.8, 4.7])
    g = Grading(0.4, tight_bands(0.4, 4, 0.9), 50.0)
    rng = np.random.default_rng(5)

    def refine(centres):
        return (centres[:, 0] > 0.7) | (rng.random(centres.shape[0]) < 0.1)
    return build_lattice(ref.box_depth(lo, hi), lo, hi, g, refine=refine)


# ------------------------------------------------------------------------------------------------ bands
def test_check_bands_refuses_bands_too_close():
    h0 = 0.5
    ok = tight_bands(h0, 5, 0.3)
    check_bands(Grading(h0, ok, 10.0))
    for l in range(1, 4):
        # bands[l + 1] - bands[l] one percent short of sqrt(3) h_l, the other gaps unchanged
        short = 0.01 * math.sqrt(3.0) * h0 * 2 ** l
        bad = tuple(x - short if k > l else x for k, x in enumerate(ok))
        with pytest.raises(MeshshadeError, match="2:1"):
            check_bands(Grading(h0, bad, 10.0))
    for bad in ((0.1, 1.0, 3.0), (0.0, 2.0, 1.0)):
        with pytest.raises(MeshshadeError, match="start at 0 and increase"):
            check_bands(Grading(h0, bad, 10.0))
    with pytest.raises(MeshshadeError, match="2:1"):
        build_lattice(ref.ball_depth([0, 0, 0], 3.0), [-3] * 3, [3] * 3, Grading(h0, (0.0, 1.0, 1.5, 9.0), 10.0))


# ------------------------------------------------------------------------------------------------ grading
def test_two_to_one_grading_with_depth(ball_lattice):
    lat, _ = ball_lattice
    counts = np.bincount(lat.level, minlength=4)
    assert np.all(counts[:3] > 0), counts          # three levels present, so two transitions are tested
    pairs, jump = assert_two_to_one(lat)
    assert np.any(jump == 1)


def test_two_to_one_grading_with_refine(refined_lattice):
    lat = refined_lattice
    counts = np.bincount(lat.level, minlength=4)
    assert np.all(counts[:3] > 0), counts
    pairs, jump = assert_two_to_one(lat)
    # level 0 meets level 1 along the surface (both touch the surface there), not only with depth
    d = lat.depth[lat.cell_nodes].min(axis=1)
    cut = d <= 0.0
    lv = lat.level[pairs]
    both_cut = cut[pairs[:, 0]] & cut[pairs[:, 1]]
    assert np.any(both_cut & (lv.min(axis=1) == 0) & (lv.max(axis=1) == 1))


def test_two_to_one_grading_of_a_mesh_with_sharp_edges():
    """The transport's inside (SurfaceVolume with its quick distance bound from the split surface's points) on a
    box mesh with sharp edges and corners, bands at the limit and ``refine`` on a slanted half-space."""
    V, F = box((12.0, 10.0, 8.0), 12)
    inside = SurfaceVolume(V, F, V, 1.0)
    g = Grading(0.3, tight_bands(0.3, 4, 0.5), 50.0)
    lat = build_lattice(inside.depth, V.min(axis=0), V.max(axis=0), g,
                        refine=lambda c: c[:, 0] + 0.5 * c[:, 1] > 0.3)
    assert np.all(np.bincount(lat.level, minlength=4)[:3] > 0)
    assert_two_to_one(lat)


# ------------------------------------------------------------------------------------------------ anchoring
def _bumped_box(bump, offset):
    """A 44 x 12 x 12 mm box (x from -22 to 22, shifted by ``offset``) with a smooth bump of height ``bump`` mm on
    its +x end, centred at (22, 0.3, -0.2) + offset, radius 2 mm; the vertices are the same, only moved."""
    V, F = box((44.0, 12.0, 12.0), 44)
    V = V.copy()
    r = np.hypot(V[:, 1] - 0.3, V[:, 2] + 0.2)
    on = np.isclose(V[:, 0], 22.0) & (r < 2.0)
    V[on, 0] += bump * (1.0 - (r[on] / 2.0) ** 2) ** 2
    return V + offset, F


GRADING = Grading(0.6, tight_bands(0.6, 4, 1.2), 50.0)
#: the reach of a change: a cube's level is decided by the depth at its parent's centre (within sqrt(3) h_1 / 2 of
#: it) against bands[1] + sqrt(3) h_1 / 2, and the depth there is bounded from below by the distance to the
#: surface's points less spacing / sqrt(3) (SurfaceVolume's quick bound, spacing 1 mm here): a change of the surface
#: moves no cube farther than bands[1] + sqrt(3) h_1 + 1 / sqrt(3) mm from it
REACH = GRADING.bands[1] + math.sqrt(3.0) * 1.2 + 1.0 / math.sqrt(3.0)


def _anchoring(offset):
    """(largest distance (mm) from the bump of a cube in only one lattice; the two lattices)."""
    g = GRADING
    lats = []
    for bump in (0.0, 0.8):
        V, F = _bumped_box(bump, offset)
        inside = SurfaceVolume(V, F, V, 1.0)
        lats.append(build_lattice(inside.depth, V.min(axis=0), V.max(axis=0), g))
    keys = [set(zip(l.level.tolist(), map(tuple, l.ijk.tolist()))) for l in lats]
    differ = keys[0] ^ keys[1]
    assert differ, "the bump changed no cube"
    bump_lo, bump_hi = np.array([21.9, -1.7, -2.2]) + offset, np.array([22.9, 2.3, 1.8]) + offset
    far = 0.0
    for lev, ijk in differ:
        h = 0.6 * 2 ** lev
        lo, hi = np.array(ijk) * h, (np.array(ijk) + 1) * h
        gap = np.linalg.norm(np.maximum(0.0, np.maximum(bump_lo - hi, lo - bump_hi)))
        far = max(far, gap)
    return far, lats


def test_cubes_are_anchored_in_world_coordinates():
    """The same box (faces off the lattice's planes) with and without a 0.8 mm bump on its far end: every cube
    farther than REACH (3.9 mm, 6.4 level-0 sides) from the bump's region is in both lattices (same level and
    integer coordinates; measured: the farthest that differs, level-0 cubes 2.5 mm behind the bump that are level 1
    with it), and the nodes 30 mm and more from the bump keep their depths bit for bit."""
    offset = np.array([0.41, -0.05, 0.33])
    far, (a, b) = _anchoring(offset)
    assert 0.0 < far <= REACH, far
    common, ia, ib = np.intersect1d(a.node_keys, b.node_keys, return_indices=True)
    away = a.nodes[ia, 0] < -8.0
    assert away.sum() > 1000
    np.testing.assert_array_equal(a.depth[ia[away]], b.depth[ib[away]])


def test_anchoring_when_faces_lie_on_lattice_planes():
    """Faces on the lattice's planes: the corners on the surface are put a hair outside before cubes are kept or
    dropped (lattice.snap_corner_depths), so the rounding of the distance (1e-16) and of the winding number (about
    1/2 there) no longer decides whether a cube outside is kept. Before (corners snapped inside after the cubes were
    chosen), level-0 cubes 17.6 mm from the bump differed."""
    far, _ = _anchoring(np.zeros(3))
    assert far <= REACH, far


# ------------------------------------------------------------------------------------------------ locate
def _points_in_cubes(lattice, rng, per=1, snap=False):
    """Random points in random cubes of every level (``snap``: rounded to the level-0 lattice h0 / 4, so many lie
    on planes, edges and nodes of the lattice)."""
    out, owner = [], []
    for l in np.unique(lattice.level):
        cubes = np.flatnonzero(lattice.level == l)
        pick = rng.choice(cubes, size=min(400, cubes.size), replace=False)
        h = lattice.grading.h0 * 2.0 ** l
        u = rng.random((pick.size * per, 3))
        p = (np.repeat(lattice.ijk[pick], per, axis=0) + u) * h
        if snap:
            q = lattice.grading.h0 / 4
            p = np.round(p / q) * q
        out.append(p)
        owner.append(np.repeat(pick, per))
    return np.concatenate(out), np.concatenate(owner)


def _closed_box_holds(lattice, cube, points, tol=1e-12):
    h = lattice.grading.h0 * np.exp2(lattice.level[cube].astype(np.float64))
    lo = lattice.ijk[cube] * h[:, None]
    return np.all((points >= lo - tol) & (points <= lo + h[:, None] + tol), axis=1)


@pytest.mark.parametrize("snap", [False, True])
def test_locate_reproduces_linear_functions_on_every_level(ball_lattice, refined_lattice, snap, rng):
    for lat in (ball_lattice[0], refined_lattice):
        P, _ = _points_in_cubes(lat, rng, snap=snap)
        cell, bary, nodes = lat.locate(P)
        assert np.all(cell >= 0)
        assert np.all(_closed_box_holds(lat, cell, P))
        assert np.all(bary >= -1e-15)
        np.testing.assert_allclose(bary.sum(axis=1), 1.0, rtol=0, atol=1e-14)
        # the nodes are corners of the cube found, and x (hence every linear function) is reproduced
        assert np.all(np.any(nodes[:, :, None] == lat.cell_nodes[cell][:, None, :], axis=2))
        for a in (np.array([1.0, 0.0, 0.0]), np.array([0.3, -1.7, 2.2])):
            f = lat.nodes @ a + 0.9
            np.testing.assert_allclose(np.einsum("pk,pk->p", bary, f[nodes]), P @ a + 0.9, rtol=0,
                                       atol=1e-12 * (1 + np.abs(P).max()))
        if not snap:
            # the twin's Kuhn tetrahedron and weights in the cube found (no ties off the lattice's planes)
            h = lat.grading.h0 * np.exp2(lat.level[cell].astype(np.float64))
            corners, w = ref.kuhn_barycentrics(P / h[:, None] - lat.ijk[cell])
            np.testing.assert_array_equal(nodes, np.take_along_axis(lat.cell_nodes[cell], corners, axis=1))
            np.testing.assert_allclose(bary, w, rtol=0, atol=1e-12)


def test_locate_finds_lattice_nodes_and_refuses_points_outside(ball_lattice):
    lat, c = ball_lattice
    free = np.setdiff1d(np.arange(lat.n_nodes), lat.hanging)
    P = lat.nodes[free[::5]]
    cell, bary, nodes = lat.locate(P)
    assert np.all(cell >= 0)
    # a node that is not hanging is a corner of every cube holding it: weight 1 there
    hit = np.take_along_axis(nodes, np.argmax(bary, axis=1)[:, None], axis=1)[:, 0]
    np.testing.assert_allclose(bary.max(axis=1), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(lat.nodes[hit], P)
    far = np.array([c + [50.0, 0, 0], c - [0, 0, 40.0]])
    cell, bary, _ = lat.locate(far)
    assert np.all(cell == -1) and np.all(bary == 0.0)
    # a hanging node lies on a coarser cube's edge or face: found there, the mean of that cube's corners
    P = lat.nodes[lat.hanging]
    cell, bary, nodes = lat.locate(P)
    assert np.all(cell >= 0)
    np.testing.assert_allclose(np.einsum("pk,pkd->pd", bary, lat.nodes[nodes]), P, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------------------ hanging nodes
def resolve_hanging(lattice, free_values):
    """Nodal values with each hanging node the mean of its two parents (repeated until every chain of hanging
    parents is resolved)."""
    v = np.array(free_values, dtype=np.float64)
    hg, par = lattice.hanging, lattice.parents
    for _ in range(32):
        new = 0.5 * (v[par[:, 0]] + v[par[:, 1]])
        if np.array_equal(new, v[hg]):
            return v
        v[hg] = new
    raise AssertionError("hanging nodes do not resolve")


def _shared_points(lattice, pairs, rng, per=6):
    """Random points on the intersection (a face, an edge or a corner) of the closed boxes of each pair."""
    h = lattice.grading.h0 * np.exp2(lattice.level.astype(np.float64))
    lo = lattice.ijk * h[:, None]
    hi = lo + h[:, None]
    a, b = pairs[:, 0], pairs[:, 1]
    ilo, ihi = np.maximum(lo[a], lo[b]), np.minimum(hi[a], hi[b])
    assert np.all(ihi >= ilo - 1e-12)
    u = rng.random((pairs.shape[0], per, 3))
    P = ilo[:, None, :] + u * (ihi - ilo)[:, None, :]
    return P.reshape(-1, 3), np.repeat(a, per), np.repeat(b, per)


@pytest.mark.parametrize("which", ["ball", "refined"])
def test_p1_space_is_continuous_across_level_transitions(ball_lattice, refined_lattice, which, rng):
    lat = ball_lattice[0] if which == "ball" else refined_lattice
    assert lat.hanging.size > 0
    grid, _ = ref.cell_grid(lat.level, lat.ijk)
    pairs = ref.neighbour_pairs(grid)
    mixed = pairs[lat.level[pairs[:, 0]] != lat.level[pairs[:, 1]]]
    assert mixed.shape[0] > 100
    P, a, b = _shared_points(lat, mixed, rng)
    # arbitrary values at the free nodes
    v = resolve_hanging(lat, rng.standard_normal(lat.n_nodes))
    fa, fb = ref.eval_in_cube(lat, a, v, P), ref.eval_in_cube(lat, b, v, P)
    np.testing.assert_allclose(fa, fb, rtol=0, atol=1e-12 * np.abs(v).max())
    # linear nodal values: the interpolant is the linear function on both sides (the hanging nodes' parents are
    # the right ones, not merely consistent)
    g = np.array([0.7, -1.3, 0.4])
    lin = resolve_hanging(lat, lat.nodes @ g)
    np.testing.assert_allclose(lin, lat.nodes @ g, rtol=0, atol=1e-12 * np.abs(lat.nodes).max())
    np.testing.assert_allclose(ref.eval_in_cube(lat, a, lin, P), P @ g, rtol=0, atol=1e-11)


def test_hanging_nodes_are_exactly_the_nodes_inside_coarser_faces_and_edges(refined_lattice):
    """A node is hanging iff it lies on a coarser touching cube's boundary but is not one of its corners (the
    twin finds them by brute force over the cubes' boxes)."""
    lat = refined_lattice
    h = lat.grading.h0 * np.exp2(lat.level.astype(np.float64))
    lo = lat.ijk * h[:, None]
    from scipy.spatial import cKDTree

    tree = cKDTree(lat.nodes)
    expected = np.zeros(lat.n_nodes, dtype=bool)
    for c in np.flatnonzero(lat.level > lat.level.min()):
        near = tree.query_ball_point(lo[c] + 0.5 * h[c], 0.5 * math.sqrt(3.0) * h[c] + 1e-9)
        near = np.array(near)
        q = (lat.nodes[near] - lo[c]) / h[c]
        on_box = np.all((q > -1e-9) & (q < 1 + 1e-9), axis=1)
        corner = np.all(np.isclose(q, 0.0, atol=1e-9) | np.isclose(q, 1.0, atol=1e-9), axis=1)
        expected[near[on_box & ~corner]] = True
    got = np.zeros(lat.n_nodes, dtype=bool)
    got[lat.hanging] = True
    np.testing.assert_array_equal(got, expected)


# ------------------------------------------------------------------------------------------------ coarsening
@pytest.mark.parametrize("which", ["ball", "refined"])
def test_coarser_lattice_covers_the_lattice(ball_lattice, refined_lattice, which, rng):
    lat = ball_lattice[0] if which == "ball" else refined_lattice
    coarse = coarser_lattice(lat, None)
    lmin = lat.level.min()
    assert coarse.level.min() == lmin + 1
    ref.cell_grid(coarse.level, coarse.ijk)                 # no overlap
    # every fine cube lies inside one coarse cube
    P, owner = _points_in_cubes(lat, rng, per=3)
    cell, _, _ = coarse.locate(P)
    assert np.all(cell >= 0)
    # the coarse cubes are the fine ones that were not finest, and the parents of the finest
    fine = lat.level == lmin
    expect = set(zip(lat.level[~fine].tolist(), map(tuple, lat.ijk[~fine].tolist())))
    expect |= {(int(lmin) + 1, tuple(x)) for x in np.unique(lat.ijk[fine] // 2, axis=0).tolist()}
    assert set(zip(coarse.level.tolist(), map(tuple, coarse.ijk.tolist()))) == expect
    # the nodes it shares with the fine lattice keep their depths
    common, ia, ib = np.intersect1d(lat.node_keys, coarse.node_keys, return_indices=True)
    assert common.size > 0
    np.testing.assert_array_equal(lat.depth[ia], coarse.depth[ib])


# ------------------------------------------------------------------------------------------------ entries' sources
def test_a_depth_scale_per_entry_is_the_same_loads_as_scaled_depths(ball_lattice, rng):
    # eq. (132): an entry whose mean free path is m times the base's puts its line sources m times deeper; per
    # entry and channel, the same loads as a call per entry with its depths scaled
    from meshshade.volume.long_range import lattice_loads, line_rule
    lat, c = ball_lattice
    n = 40
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pos = c + 6.3 * d
    x, q = line_rule(0.9)
    depths = np.stack([x / s for s in (0.8, 1.2, 2.0)])
    strengths = np.stack([q, 0.9 * q, 0.8 * q])
    power = rng.uniform(0.5, 1.5, size=(n, 3))
    scale = rng.uniform(0.5, 2.0, size=(n, 3))
    got, dropped = lattice_loads(lat, pos, -d, d, power, depths, strengths, 0.3, depth_scale=scale)
    expected = np.zeros_like(got)
    for i in range(n):
        expected += lattice_loads(lat, pos[i:i + 1], -d[i:i + 1], d[i:i + 1], power[i:i + 1],
                                  depths * scale[i][:, None], strengths, 0.3)[0]
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
    assert np.count_nonzero(got) > 100
    plain, _ = lattice_loads(lat, pos, -d, d, power, depths, strengths, 0.3)
    np.testing.assert_array_equal(plain, lattice_loads(lat, pos, -d, d, power, depths, strengths, 0.3,
                                                       depth_scale=np.ones((n, 3)))[0])
    with pytest.raises(MeshshadeError, match="depth scale"):
        lattice_loads(lat, pos, -d, d, power, depths, strengths, 0.3, depth_scale=np.ones((n, 2)))
