"""The triangle hierarchy's winding number and distance (meshshade/volume/triangle_tree.py) against independent
routes: the closed sphere's exact 0/1, the exact sum of solid angles (every triangle, numpy), libigl's fast winding
number and a brute-force point-triangle distance."""
from __future__ import annotations

import igl
import numpy as np
import pytest

from meshshade.geometry.procedural import icosphere
from meshshade.volume.triangle_tree import TriangleTree


def _solid_angles(P, V, F):
    """(p,) winding number at P by the exact sum over every triangle (van Oosterom and Strackee), numpy."""
    a = V[F[:, 0]][None] - P[:, None]
    b = V[F[:, 1]][None] - P[:, None]
    c = V[F[:, 2]][None] - P[:, None]
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", a, c) * lb \
        + np.einsum("pfi,pfi->pf", b, c) * la
    return (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)


def _brute_distance(P, V, F):
    """(p,) distance from P to the triangles over every pair (numpy): the plane's distance where the projection
    falls inside the triangle, else the nearest of its three edges (clamped projection on each segment)."""
    A, B, C = V[F[:, 0]][None], V[F[:, 1]][None], V[F[:, 2]][None]
    X = P[:, None]
    n = np.cross(B - A, C - A)
    n = n / np.linalg.norm(n, axis=2, keepdims=True)
    h = np.einsum("pfi,pfi->pf", X - A, n)
    q = X - h[..., None] * n
    inside = np.ones(h.shape, dtype=bool)
    for U, W in ((A, B), (B, C), (C, A)):       # the projection on the inner side of every edge
        inside &= np.einsum("pfi,pfi->pf", np.cross(W - U, q - U), n) >= 0
    best = np.where(inside, np.abs(h), np.inf)
    for U, W in ((A, B), (B, C), (C, A)):
        e = W - U
        t = np.clip(np.einsum("pfi,pfi->pf", X - U, e) / np.einsum("pfi,pfi->pf", e, e), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(X - (U + t[..., None] * e), axis=2))
    return best.min(axis=1)


@pytest.fixture(scope="module")
def sphere():
    V, F = icosphere(10.0, 4)
    return V, F, TriangleTree(V, F, n_threads=2)


def test_winding_of_a_closed_sphere_is_its_indicator(sphere):
    V, F, tree = sphere
    P = np.random.default_rng(3).uniform(-15.0, 15.0, (4000, 3))
    r = np.linalg.norm(P, axis=1)
    ok = np.abs(r - 10.0) > 0.3            # the polyhedron departs from the sphere by < 0.03 mm
    w = tree.winding(P[ok], beta=2.0)
    assert np.abs(w - (r[ok] < 10.0)).max() < 0.01


def test_winding_converges_to_the_exact_solid_angle_sum(sphere):
    """The expansion's error falls fast with beta (third-order expansion: below 1e-3 at beta 2 on the points
    near the surface, 1e-5 at beta 6), and beta -> large is the exact sum of every triangle's solid angle."""
    V, F, tree = sphere
    rng = np.random.default_rng(5)
    P = V[rng.integers(0, V.shape[0], 300)] + rng.normal(0.0, 1.0, (300, 3))
    exact = _solid_angles(P, V, F)
    errors = [np.abs(tree.winding(P, beta=b) - exact).max() for b in (1.0, 2.0, 6.0)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[1] < 1e-2 and errors[2] < 1e-4
    assert np.abs(tree.winding(P, beta=1e6) - exact).max() < 1e-12


def test_winding_of_an_open_overlapping_soup_matches_libigl():
    """Two overlapping spheres with a cap cut off one of them (open, overlapping: the union and a hole): libigl's
    fast winding number (its own tree and expansion) agrees within both expansions' error."""
    V1, F1 = icosphere(10.0, 3)
    V2, F2 = icosphere(8.0, 3)
    V2 = V2 + np.array([9.0, 0.0, 0.0])
    keep = V1[F1].mean(axis=1)[:, 2] < 7.0            # a hole at the top of the first sphere
    V = np.concatenate([V1, V2])
    F = np.concatenate([F1[keep], F2 + V1.shape[0]]).astype(np.int64)
    P = np.random.default_rng(11).uniform(-14.0, 20.0, (3000, 3))
    ours = TriangleTree(V, F, n_threads=2).winding(P, beta=2.0)
    bvh = igl.FastWindingNumberBVH()
    bvh.init(V, F, 2)
    ref = bvh.winding_number(P, 2.0)
    assert np.abs(ours - ref).max() < 0.02
    assert np.abs(ours - _solid_angles(P, V, F)).max() < 0.01


def test_distance_matches_brute_force_and_libigl(sphere):
    V, F, tree = sphere
    rng = np.random.default_rng(7)
    P = rng.uniform(-13.0, 13.0, (300, 3))
    assert np.allclose(tree.distance(P), _brute_distance(P, V, F), rtol=0, atol=1e-10)
    P2 = rng.uniform(-13.0, 13.0, (3000, 3))
    ref = igl.signed_distance(P2, V, F.astype(np.int64), sign_type=igl.SIGNED_DISTANCE_TYPE_UNSIGNED)[0]
    assert np.allclose(tree.distance(P2), ref, rtol=0, atol=1e-10)
    bounded = tree.distance(P2, bound=1.5)
    assert np.array_equal(bounded, np.minimum(ref, 1.5)) or np.allclose(bounded, np.minimum(ref, 1.5), atol=1e-12)


def test_blocks_and_threads_do_not_change_the_result(sphere):
    V, F, _ = sphere
    P = np.random.default_rng(9).uniform(-12.0, 12.0, (5000, 3))
    one, two = TriangleTree(V, F, n_threads=1), TriangleTree(V, F, n_threads=2)
    assert np.array_equal(one.winding(P), two.winding(P))
    assert np.array_equal(one.distance(P, 3.0), two.distance(P, 3.0))


def test_empty_and_degenerate_inputs():
    tree = TriangleTree(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    assert np.array_equal(tree.winding(np.ones((3, 3))), np.zeros(3))
    assert np.array_equal(tree.distance(np.ones((2, 3)), 4.0), np.full(2, 4.0))
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])          # a zero-area triangle
    t = TriangleTree(V, np.array([[0, 1, 2]]))
    assert t.winding(np.array([[0.5, 1.0, 0.0]]))[0] == 0.0
    assert np.isclose(t.distance(np.array([[0.5, 1.0, 0.0]]))[0], 1.0)


def test_distance_to_a_soup_of_separate_triangles_matches_brute_force():
    """Triangles sharing no corner, so that each Voronoi region of every triangle (its faces, edges, corners) is
    the nearest for some points."""
    rng = np.random.default_rng(13)
    V = rng.uniform(-5.0, 5.0, (60, 3))
    F = np.arange(60).reshape(20, 3)
    P = rng.uniform(-8.0, 8.0, (2000, 3))
    tree = TriangleTree(V, F, n_threads=2)
    assert np.allclose(tree.distance(P), _brute_distance(P, V, F), rtol=0, atol=1e-10)
