"""The defect generators of tools/benchmarks/mesh_defects.py (issue 41): each makes the defect it says (checked by
independent counts and by meshshade's own mesh validation), keeps the input's vertices first and in order, and is
deterministic. Fast: icospheres of 642 vertices."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import csgraph

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere

import mesh_defects  # tools/benchmarks/, on sys.path by tests/conftest.py
import real_models  # tools/benchmarks/, on sys.path by tests/conftest.py





md = mesh_defects
counts = real_models.topology_counts


@pytest.fixture(scope="module")
def sphere():
    V, F = icosphere(20.0, 3)     # 642 vertices, 1280 faces, mean edge about 2.7 mm
    V.setflags(write=False)
    F.setflags(write=False)
    return V, F


def _validated(V, F):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Mesh.from_arrays(V, F).defects


def _boundary_loops(n, F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    b = u[c == 1]
    if b.size == 0:
        return 0
    g = sparse.coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n, n))
    _, labels = csgraph.connected_components(g, directed=False)
    return np.unique(labels[np.unique(b)]).size


def _two_ring_by_brute_force(F, c):
    """Faces with a corner in {c} or among c's neighbours (a loop over the faces)."""
    ring1 = {c}
    for f in F.tolist():
        if c in f:
            ring1.update(f)
    return sorted(i for i, f in enumerate(F.tolist()) if ring1 & set(f))


def test_ring_faces_two_ring_counts_on_a_regular_triangulation(sphere):
    V, F = sphere
    valence = np.bincount(F.reshape(-1), minlength=V.shape[0])
    six, five = int(np.flatnonzero(valence == 6)[0]), int(np.flatnonzero(valence == 5)[0])
    assert md.ring_faces(V.shape[0], F, six).size == 6 + 18
    assert md.ring_faces(V.shape[0], F, five).size == 5 + 15
    assert md.ring_faces(V.shape[0], F, six, rings=1).size == 6
    for c in (six, five, 100, 400):
        assert md.ring_faces(V.shape[0], F, c).tolist() == _two_ring_by_brute_force(F, c)


def test_punch_holes_removes_the_two_ring_faces_and_keeps_vertices(sphere):
    V, F = sphere
    out = md.punch_holes(V, F, 6, seed=3)
    centres = out.details["centres"]
    expected = sorted(set().union(*(_two_ring_by_brute_force(F, c) for c in centres)))
    assert len(centres) == 6
    assert out.details["removed_faces"] == expected
    assert out.faces.shape[0] == F.shape[0] - len(expected)
    keep = np.ones(F.shape[0], bool)
    keep[expected] = False
    np.testing.assert_array_equal(out.faces, F[keep])                  # kept faces in their order
    np.testing.assert_array_equal(out.vertices, V)                     # no vertex removed or moved
    np.testing.assert_array_equal(out.points, V[centres])
    assert _boundary_loops(V.shape[0], out.faces) == 6                  # six separate holes
    report = _validated(out.vertices, out.faces)
    assert not report.is_closed and report.n_components == 1
    one_ring = set(centres).union(*(set(f) for f in F.tolist() if set(f) & set(centres)))
    assert out.details["unreferenced"] == sorted(one_ring)               # the centres and their neighbours
    assert report.n_unreferenced_vertices == len(one_ring)


def test_punch_holes_centres_apart_and_deterministic(sphere):
    V, F = sphere
    a = md.punch_holes(V, F, 6, seed=3, min_separation=12.0)
    b = md.punch_holes(V, F, 6, seed=3, min_separation=12.0)
    c = md.punch_holes(V, F, 6, seed=4, min_separation=12.0)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert a.details == b.details
    assert a.details["centres"] != c.details["centres"]
    P = a.points
    d = np.linalg.norm(P[:, None] - P[None], axis=2)
    assert d[np.triu_indices(6, 1)].min() >= 12.0


def test_punch_holes_at_given_centres_and_too_many(sphere):
    V, F = sphere
    out = md.punch_holes(V, F, 0, centres=[0, 300], rings=1)
    assert out.details["centres"] == [0, 300]
    valence = np.bincount(F.reshape(-1))
    assert out.faces.shape[0] == F.shape[0] - valence[0] - valence[300]   # 1-ring faces only, apart
    with pytest.raises(ValueError, match="hole centres"):
        md.punch_holes(V, F, 50, seed=0, min_separation=15.0)


def test_duplicate_faces_appends_copies(sphere):
    V, F = sphere
    out = md.duplicate_faces(V, F, 5, seed=1)
    dup = out.details["duplicated"]
    assert len(set(dup)) == 5
    np.testing.assert_array_equal(out.faces[:F.shape[0]], F)
    np.testing.assert_array_equal(out.faces[F.shape[0]:], F[dup])
    np.testing.assert_array_equal(out.vertices, V)
    np.testing.assert_allclose(out.points, V[F[dup]].mean(axis=1))
    assert counts(out.vertices, out.faces)["duplicated_faces"] == 5
    rev = md.duplicate_faces(V, F, 5, seed=1, reverse=True)
    np.testing.assert_array_equal(rev.faces[F.shape[0]:], F[dup][:, [0, 2, 1]])
    assert counts(rev.vertices, rev.faces)["duplicated_faces"] == 5
    np.testing.assert_array_equal(md.duplicate_faces(V, F, 5, seed=1).faces, out.faces)


def test_add_ball_appends_a_closed_overlapping_part(sphere):
    V, F = sphere
    centre = V[7]
    out = md.add_ball(V, F, centre, 3.0)
    n = V.shape[0]
    np.testing.assert_array_equal(out.vertices[:n], V)
    np.testing.assert_array_equal(out.faces[:F.shape[0]], F)
    ball = out.vertices[n:]
    assert ball.shape[0] == 162
    np.testing.assert_allclose(np.linalg.norm(ball - centre, axis=1), 3.0)
    assert out.faces[F.shape[0]:].min() == n
    np.testing.assert_array_equal(out.points, centre[None])
    got = counts(out.vertices, out.faces)
    assert got["parts"] == 2 and got["boundary_edges"] == 0 and got["nonmanifold_edges"] == 0
    report = _validated(out.vertices, out.faces)
    assert report.is_closed and report.n_components == 2 and report.n_components_flipped == 0
    with pytest.raises(ValueError):
        md.add_ball(V, F, centre, 0.0)


@pytest.mark.parametrize("n_fins", [1, 3])
def test_add_fin_makes_one_nonmanifold_edge(sphere, n_fins):
    V, F = sphere
    out = md.add_fin(V, F, seed=2, n_fins=n_fins, height=4.0)
    a, b = out.details["edge"]
    n = V.shape[0]
    np.testing.assert_array_equal(out.vertices[:n], V)
    np.testing.assert_array_equal(out.faces[:F.shape[0]], F)
    assert out.vertices.shape[0] == n + n_fins
    mid = 0.5 * (V[a] + V[b])
    np.testing.assert_allclose(out.points, mid[None])
    np.testing.assert_allclose(np.linalg.norm(out.vertices[n:] - mid, axis=1), 4.0)
    uses = sum(1 for f in out.faces.tolist() if a in f and b in f)
    assert uses == 2 + n_fins
    got = counts(out.vertices, out.faces)
    assert got["nonmanifold_edges"] == 1 and got["boundary_edges"] == 2 * n_fins
    if n_fins == 1:   # the fin stands out of the surface, along the outward normal
        assert np.linalg.norm(out.vertices[n]) > np.linalg.norm(mid) + 3.0


def test_add_fin_on_a_given_edge_and_refusals(sphere):
    V, F = sphere
    a, b = int(F[0, 0]), int(F[0, 1])
    out = md.add_fin(V, F, edge=(b, a))
    assert out.details["edge"] == sorted([a, b])
    with pytest.raises(ValueError, match="not an edge"):
        md.add_fin(V, F, edge=(0, 641))
    with pytest.raises(ValueError):
        md.add_fin(V, F, n_fins=0)


def test_add_stray_vertices_unreferenced_and_where_asked(sphere):
    V, F = sphere
    out = md.add_stray_vertices(V, F, 25, seed=5)
    n = V.shape[0]
    np.testing.assert_array_equal(out.vertices[:n], V)
    np.testing.assert_array_equal(out.faces, F)
    np.testing.assert_array_equal(out.vertices[n:], out.points)
    r = np.linalg.norm(out.points, axis=1)
    assert np.all(r <= 20.0 + 1e-9) and np.all(r >= 20.0 * 0.98)      # on the faces: chords of the sphere
    assert counts(out.vertices, out.faces)["unreferenced_vertices"] == 25
    assert _validated(out.vertices, out.faces).n_unreferenced_vertices == 25
    box = md.add_stray_vertices(V, F, 25, seed=5, mode="bbox")
    assert np.all(np.abs(box.points) <= 20.0)
    spread = md.add_stray_vertices(V, F, 200, seed=5, spread=2.0)
    r = np.linalg.norm(spread.points, axis=1)
    assert r.max() <= 22.0 and r.min() >= 20.0 * 0.98 - 2.0 and r.max() - r.min() > 2.0
    np.testing.assert_array_equal(md.add_stray_vertices(V, F, 25, seed=5).vertices, out.vertices)
    with pytest.raises(ValueError):
        md.add_stray_vertices(V, F, 3, mode="cloud")


def test_flip_faces_are_put_back_by_the_validation(sphere):
    V, F = sphere
    out = md.flip_faces(V, F, 10, seed=6)
    flipped = out.details["flipped"]
    assert len(set(flipped)) == 10
    np.testing.assert_array_equal(out.vertices, V)
    np.testing.assert_array_equal(out.faces[flipped], F[flipped][:, [0, 2, 1]])
    others = np.setdiff1d(np.arange(F.shape[0]), flipped)
    np.testing.assert_array_equal(out.faces[others], F[others])
    report = _validated(out.vertices, out.faces)
    assert report.n_faces_rewound == 10
    np.testing.assert_array_equal(report.faces, F)                     # repaired into the clean mesh exactly
    np.testing.assert_array_equal(md.flip_faces(V, F, 10, seed=6).faces, out.faces)


def test_far_from_and_relative_change_by_hand():
    V = np.array([[0.0, 0, 0], [5, 0, 0], [20, 0, 0], [40, 0, 0]])
    assert md.far_from(V, [[0.0, 0, 0]], 10.0).tolist() == [False, False, True, True]
    assert md.far_from(V, np.zeros((0, 3)), 10.0).all() and md.far_from(V, [[0, 0, 0]], 0.0).all()
    clean = np.array([[1.0, 1.0], [2.0, 1e-6], [4.0, 1.0], [1.0, 1.0]])
    defect = np.array([[1.1, 1.0], [2.0, 5.0], [3.0, 1.0], [1.0, 1.0]])
    got = md.relative_change(defect, clean, np.array([True, True, True, False]))
    assert got["count"] == [3, 2]                       # channel 1: vertex 1 below 1e-3 of the peak
    np.testing.assert_allclose(got["mean"], [(0.1 + 0.0 + 0.25) / 3, 0.0])
    np.testing.assert_allclose(got["max"], [0.25, 0.0])
    assert got["finite"]
    none = md.relative_change(defect, clean, np.zeros(4, bool))
    assert none["mean"] == [None, None] and none["count"] == [0, 0]


def test_generators_refuse_bad_input(sphere):
    V, F = sphere
    with pytest.raises(ValueError):
        md.duplicate_faces(V, F, F.shape[0] + 1)
    with pytest.raises(ValueError):
        md.flip_faces(V[:, :2], F, 1)
    with pytest.raises(ValueError):
        md.punch_holes(V, F, 1, rings=0)
