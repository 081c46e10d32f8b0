"""Geodesic neighbourhoods (meshshade.geometry.geodesics.neighbourhoods) against closed forms and exact geodesics.

References: great circles on icospheres (R = 10 mm), helices sqrt((R dtheta)^2 + dz^2) on a cylinder, straight
lines and corner paths on flat domains, and ``igl.exact_geodesic`` (libigl's exact polyhedral MMP geodesics) on a
torus and on a shared mesh.  Accuracy figures for the README come from ``tools/benchmarks/bench_neighbourhood.py``.
"""
from __future__ import annotations

import igl
import numpy as np
import pytest
import trimesh
from scipy.spatial import Delaunay

from meshshade.geometry.geodesics.neighbourhoods import (GeodesicNeighbourhoods, Neighbourhoods,
                                                          geodesic_distances_from, geodesic_neighbourhoods,
                                                          tangent_azimuth)
from meshshade.geometry.procedural import capped_cylinder, icosphere, torus


# ---------------------------------------------------------------------------------------------------- helpers
def _grid(nx, ny, x0, x1, y0, y1, keep=None):
    """Flat triangulated rectangle in z = 0 (alternating diagonals); ``keep(cx, cy)`` filters cells."""
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    V = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
    alt = (i + j) % 2 == 0
    f1 = np.where(alt[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    f2 = np.where(alt[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    cell = np.ones(i.size, bool) if keep is None else keep(0.5 * (xs[i] + xs[i + 1]), 0.5 * (ys[j] + ys[j + 1]))
    return V, np.concatenate([f1[cell], f2[cell]]).astype(np.int64)


def _exact(V, F, source, targets):
    """igl exact polyhedral geodesic distance from vertex ``source`` to ``targets``."""
    e = np.array([], np.int64)
    return igl.exact_geodesic(V, F.astype(np.int64), np.array([source], np.int64), e,
                              np.asarray(targets, np.int64), e)


def _rel_err(d, ref):
    return (d - ref) / ref


def _great_circle(V, R, s, idx):
    u = V / np.linalg.norm(V, axis=1, keepdims=True)
    return R * np.arccos(np.clip(u[idx] @ u[s], -1.0, 1.0))


# ------------------------------------------------------------------------------------------------ accuracy
def test_geodesic_neighbourhoods_sphere_great_circle_converges_order_2():
    """Error against great circles <= 0.5 % beyond 2 edge lengths; converges at order ~2 (polyhedral bias)."""
    R, cut, hs, errs = 10.0, 8.0, [], []
    for sub in (3, 4, 5):
        V, F = icosphere(R, sub)
        solver = GeodesicNeighbourhoods(V, F)
        h = solver.mean_edge_length
        worst = 0.0
        for s in (0, 17, 301):
            v, d = solver.query(None, None, None, [s], None, cut).row(0)
            ref = _great_circle(V, R, s, v)
            far = ref > 2 * h
            e = np.abs(_rel_err(d[far], ref[far]))
            assert e.max() <= 5e-3, (sub, e.max())
            worst = max(worst, e.max())
        hs.append(h)
        errs.append(worst)
    order = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert order >= 1.7, (order, errs)


def test_geodesic_neighbourhoods_window_matches_exact_on_torus_fmm_and_dijkstra_worse():
    """Window propagation = igl exact geodesics; FMM within 2 %; plain Dijkstra off by > 5 % (measured)."""
    V, F = torus(20.0, 6.0, 120, 40)
    cut = 15.0
    worst = {}
    for method in ("window", "fmm", "dijkstra"):
        solver = GeodesicNeighbourhoods(V, F, method=method)
        e_all = []
        for s in (0, 20, 1210):
            v, d = solver.query(None, None, None, [s], None, cut).row(0)
            ref = _exact(V, F, s, v)
            far = ref > 2 * solver.mean_edge_length
            e_all.append(_rel_err(d[far], ref[far]))
        e = np.concatenate(e_all)
        worst[method] = np.abs(e).max()
        if method == "window":
            assert e.min() > -1e-9  # never shorter than the exact polyhedral distance
    assert worst["window"] < 1e-9
    assert worst["fmm"] < 2e-2
    assert worst["dijkstra"] > 5e-2
    assert worst["dijkstra"] > 10 * worst["fmm"] > 10 * worst["window"]


def test_geodesic_neighbourhoods_cylinder_helix():
    R, L = 5.0, 40.0
    V, F = capped_cylinder(R, L, segments=96, rings=64)
    solver = GeodesicNeighbourhoods(V, F)
    side = np.flatnonzero(np.abs(np.hypot(V[:, 0], V[:, 1]) - R) < 1e-9)
    theta, z = np.arctan2(V[:, 1], V[:, 0]), V[:, 2]
    mid = side[np.abs(z[side]) < 0.5]
    h = solver.mean_edge_length
    for s in mid[:: max(1, mid.size // 3)][:3]:
        v, d = solver.query(None, None, None, [s], None, 12.0).row(0)
        assert np.all(np.isin(v, side))  # the caps are > 12 mm away along the surface
        dth = np.angle(np.exp(1j * (theta[v] - theta[s])))
        ref = np.hypot(R * dth, z[v] - z[s])
        far = ref > 2 * h
        assert np.abs(_rel_err(d[far], ref[far])).max() <= 5e-3


def test_geodesic_neighbourhoods_shared_mesh_matches_exact(shared_meshes):
    m = trimesh.load(shared_meshes / "spot.obj", process=False)
    V, F = np.asarray(m.vertices) * 50.0, np.asarray(m.faces, dtype=np.int64)  # ~90 mm cow
    solver = GeodesicNeighbourhoods(V, F)
    cut = 10.0
    for s in (3111, 5894, 9807):
        v, d = solver.query(None, None, None, [s], None, cut).row(0)
        cand = np.flatnonzero(np.linalg.norm(V - V[s], axis=1) <= cut)  # chord <= geodesic: a superset
        ref = _exact(V, F, s, cand)
        inside = cand[ref <= cut * (1 - 1e-9)]
        assert np.setdiff1d(inside, v).size == 0  # every vertex within the cutoff is found
        lookup = dict(zip(cand, ref))
        r = np.array([lookup[x] for x in v])
        far = r > 0
        assert np.abs(_rel_err(d[far], r[far])).max() < 1e-9


def test_geodesic_neighbourhoods_flat_random_delaunay_exact():
    """Random Delaunay plate (obtuse and sliver triangles): window propagation = straight lines, vertex and
    in-face sources; FMM stays within 1 %; every vertex within the cutoff is found."""
    rng = np.random.default_rng(3)
    P = rng.uniform(-20, 20, (8000, 2))
    F = Delaunay(P).simplices.astype(np.int64)
    V = np.column_stack([P, np.zeros(len(P))])
    cut = 5.0
    src = np.flatnonzero(np.all(np.abs(P) < 12, axis=1))[::97]
    for method, tol in (("window", 1e-12), ("fmm", 1e-2)):
        solver = GeodesicNeighbourhoods(V, F, method=method)
        nb = solver.query(None, None, None, src, None, cut)
        ref = np.linalg.norm(V[nb.vertex] - V[src][nb.source_index()], axis=1)
        assert np.all(np.abs(nb.distance - ref) <= tol * np.maximum(ref, 1.0))
        assert nb.n_pairs == sum(int(np.sum(np.linalg.norm(V - V[s], axis=1) <= cut * (1 - tol))) for s in src) \
            or method == "fmm"
        f = int(np.argmin(np.linalg.norm(V[F].mean(1), axis=1)))
        bary = np.array([0.2, 0.3, 0.5])
        p = bary @ V[F[f]]
        nb = solver.query(None, [f], [bary], None, None, cut)
        ref = np.linalg.norm(V[nb.vertex] - p, axis=1)
        assert np.all(np.abs(nb.distance - ref) <= tol * np.maximum(ref, 1.0))
        inside = np.flatnonzero(np.linalg.norm(V - p, axis=1) <= cut * (1 - 1e-9))
        assert np.setdiff1d(inside, nb.vertex).size <= (0 if method == "window" else 3)


def test_geodesic_neighbourhoods_concave_boundary_corner_path():
    """L-shaped plate: targets hidden behind the reflex corner are reached through it (boundary pseudo-source)."""
    V, F = _grid(41, 41, -10, 10, -10, 10, keep=lambda x, y: ~((x > 0) & (y > 0)))
    s = int(np.argmin(np.linalg.norm(V - [6.0, -2.0, 0.0], axis=1)))
    solver = GeodesicNeighbourhoods(V, F)
    used = np.unique(F)
    d = solver.distances_from(vertex=s)
    t = np.linspace(0, 1, 2001)[:, None]
    for o in used[:: 7]:
        seg = V[s, :2] + t * (V[o, :2] - V[s, :2])
        blocked = np.any((seg[:, 0] > 1e-9) & (seg[:, 1] > 1e-9))
        ref = (np.linalg.norm(V[s]) + np.linalg.norm(V[o])) if blocked else np.linalg.norm(V[o] - V[s])
        assert d[o] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_geodesic_neighbourhoods_inconsistent_winding_same_result():
    V, F = _grid(21, 21, 0, 10, 0, 10)
    F2 = F.copy()
    F2[::3] = F2[::3, ::-1]  # flip every third face
    s = 220
    a = GeodesicNeighbourhoods(V, F).distances_from(vertex=s, cutoff_mm=6.0)
    b = GeodesicNeighbourhoods(V, F2).distances_from(vertex=s, cutoff_mm=6.0)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    fin = np.isfinite(a)
    np.testing.assert_allclose(a[fin], np.linalg.norm(V[fin] - V[s], axis=1), rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------------------- sets and topology
def test_geodesic_neighbourhoods_no_leak_across_gap_u_shape():
    """A folded strip: the other arm is 1 mm away in space but > 20 mm away along the surface."""
    r, arm, width = 0.5, 30.0, 4.0
    n_s, n_w = 260, 9
    total = 2 * arm + np.pi * r
    s_par = np.linspace(0, total, n_s)
    x = np.where(s_par < arm, arm - s_par,
                 np.where(s_par < arm + np.pi * r, -r * np.sin((s_par - arm) / r), s_par - arm - np.pi * r))
    y = np.where(s_par < arm, -r, np.where(s_par < arm + np.pi * r, -r * np.cos((s_par - arm) / r), r))
    Vg, F = _grid(n_s, n_w, 0, 1, 0, width)
    i = np.repeat(np.arange(n_s), n_w)
    V = np.column_stack([x[i], y[i], Vg[:, 1]])
    src = int(np.argmin(np.linalg.norm(V - [arm / 2, -r, width / 2], axis=1)))
    cut = 10.0
    other_arm = np.flatnonzero(V[:, 1] > 0.99 * r)
    assert np.min(np.linalg.norm(V[other_arm] - V[src], axis=1)) < 1.5  # close in space
    for method in ("window", "fmm", "dijkstra"):
        nb = GeodesicNeighbourhoods(V, F, method=method).query(None, None, None, [src], None, cut)
        assert np.intersect1d(nb.vertex, other_arm).size == 0
        flat = nb.distance > 0
        if method != "dijkstra":
            ref = np.linalg.norm(V[nb.vertex] - V[src], axis=1)  # same arm: flat, geodesic = chord
            assert np.abs(nb.distance[flat] - ref[flat]).max() < 1e-9


def test_geodesic_neighbourhoods_no_leak_between_touching_spheres():
    Va, Fa = icosphere(5.0, 3)
    Vb = Va + [10.0 + 1e-6, 0.0, 0.0]
    V, F = np.concatenate([Va, Vb]), np.concatenate([Fa, Fa + len(Va)])
    s = int(np.argmax(Va[:, 0]))
    nb = GeodesicNeighbourhoods(V, F).query(None, None, None, [s], None, 4.0)
    assert nb.vertex.max() < len(Va) and nb.n_pairs > 10


def test_geodesic_neighbourhoods_cutoff_respected_and_complete_on_sphere():
    """Found set = {v : exact polyhedral distance <= cutoff}; per-source cutoffs; distances within them."""
    V, F = icosphere(10.0, 4)
    solver = GeodesicNeighbourhoods(V, F)
    src = np.array([0, 100, 2000])
    cuts = np.array([3.0, 6.0, 0.0])
    nb = solver.query(None, None, None, src, None, cuts)
    assert nb.counts[2] == 1 and nb.row(2)[0][0] == 2000 and nb.row(2)[1][0] == 0.0
    for i in range(2):
        v, d = nb.row(i)
        assert np.all(d <= cuts[i]) and np.all(d >= 0)
        ex = _exact(V, F, src[i], np.arange(len(V)))
        inside = np.flatnonzero(ex <= cuts[i] * (1 - 1e-12))
        outside = np.flatnonzero(ex > cuts[i] * (1 + 1e-12))
        assert np.setdiff1d(inside, v).size == 0 and np.intersect1d(outside, v).size == 0
        # great circle >= polyhedral: everything within the smooth cutoff is found too
        gc = _great_circle(V, 10.0, src[i], np.arange(len(V)))
        assert np.setdiff1d(np.flatnonzero(gc <= cuts[i]), v).size == 0


# ----------------------------------------------------------------------------------------------- azimuth
def test_tangent_azimuth_sphere_matches_great_circle_bearing():
    """phi (d1 = north, d2 = east) equals the initial great-circle bearing from spherical trigonometry."""
    R = 10.0
    V, F = icosphere(R, 4)
    N = V / R
    solver = GeodesicNeighbourhoods(V, F, N)
    lat, lon = np.arcsin(N[:, 2]), np.arctan2(N[:, 1], N[:, 0])
    for s in (5, 700, 1800):
        north = np.array([-np.sin(lat[s]) * np.cos(lon[s]), -np.sin(lat[s]) * np.sin(lon[s]), np.cos(lat[s])])
        east = np.array([-np.sin(lon[s]), np.cos(lon[s]), 0.0])
        nb = solver.query(None, None, None, [s], N[[s]], 9.0, d1=north[None], d2=east[None])
        v = nb.vertex
        dl = lon[v] - lon[s]
        bearing = np.arctan2(np.sin(dl) * np.cos(lat[v]),
                             np.cos(lat[s]) * np.sin(lat[v]) - np.sin(lat[s]) * np.cos(lat[v]) * np.cos(dl))
        ok = nb.distance > 0
        diff = np.angle(np.exp(1j * (nb.phi[ok] - bearing[ok])))
        assert np.abs(diff).max() < 1e-9


def test_tangent_azimuth_cylinder_correction_reduces_error():
    """Chord projection deviates by ~(rho^2/6R^2) cos^3 sin; the k1/k2 correction removes the leading term."""
    R = 5.0
    rho = np.linspace(0.2, 3.0, 15)[:, None]
    ang = np.linspace(-np.pi, np.pi, 49)[None, :]
    rho, ang = np.broadcast_arrays(rho, ang)
    dth, dz = rho * np.cos(ang) / R, rho * np.sin(ang)
    # source at theta = 0 on the cylinder x^2 + y^2 = R^2: n = x, d1 = y (around, k1 = 1/R), d2 = z (k2 = 0)
    diff = np.stack([R * np.cos(dth) - R, R * np.sin(dth), dz], -1).reshape(-1, 3)
    t = diff - diff[:, :1] * np.array([1.0, 0, 0])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    d1 = np.tile([0.0, 1, 0], (len(t), 1))
    d2 = np.tile([0.0, 0, 1], (len(t), 1))
    true = ang.ravel()
    raw = np.angle(np.exp(1j * (tangent_azimuth(t, d1, d2) - true)))
    k1, k2 = np.full(len(t), 1 / R), np.zeros(len(t))
    cor = np.angle(np.exp(1j * (tangent_azimuth(t, d1, d2, rho.ravel(), k1, k2) - true)))
    pred = (rho.ravel() ** 2 / (6 * R * R)) * np.cos(true) ** 3 * np.sin(true)
    small = rho.ravel() <= 1.0
    np.testing.assert_allclose(raw[small], pred[small], atol=0.05 * np.abs(pred).max())
    assert np.abs(cor).max() < 0.25 * np.abs(raw).max()
    assert np.abs(cor[small]).max() < 0.05 * np.abs(raw[small]).max()


# ------------------------------------------------------------------------------------------------------ API
def test_geodesic_neighbourhoods_api_outputs_and_threads():
    V, F = icosphere(10.0, 3)
    a = GeodesicNeighbourhoods(V, F, n_threads=1)
    b = GeodesicNeighbourhoods(V, F, n_threads=2)
    src = np.arange(0, len(V), 7)
    na = a.query(None, None, None, src, None, 5.0, tangent=True, block_size=5)
    nb = b.query(None, None, None, src, None, 5.0, tangent=True, block_size=5)
    for name in ("indptr", "vertex", "distance", "chord", "tangent"):
        np.testing.assert_array_equal(getattr(na, name), getattr(nb, name))
    assert isinstance(na, Neighbourhoods) and na.vertex.dtype == np.int32
    assert np.all(na.chord <= na.distance + 1e-12)
    np.testing.assert_allclose(np.linalg.norm(na.tangent[na.distance > 0], axis=1), 1.0)
    assert na.source_index().shape == na.distance.shape
    assert "sources" in repr(na) and "GeodesicNeighbourhoods" in repr(a)
    calls = []
    a.query(None, None, None, src, None, 5.0, progress=lambda done, total: calls.append((done, total)),
            block_size=10)
    assert calls[-1] == (len(src), len(src))
    one = geodesic_neighbourhoods(V, F, None, None, None, src[:3], None, 5.0)
    np.testing.assert_array_equal(one.distance, na.distance[:one.n_pairs])
    d = geodesic_distances_from(V, F, vertex=int(src[1]), cutoff_mm=5.0)
    v, dd = na.row(1)
    np.testing.assert_array_equal(d[v], dd)
    assert np.isinf(d[np.setdiff1d(np.arange(len(V)), v)]).all()


def test_geodesic_neighbourhoods_face_source_points_and_validation():
    V, F = icosphere(10.0, 3)
    solver = GeodesicNeighbourhoods(V, F)
    bary = np.array([[0.6, 0.3, 0.1]])
    p = bary[0] @ V[F[10]]
    nb = solver.query(p[None], [10], bary, [-1], None, 4.0)
    np.testing.assert_allclose(nb.chord, np.linalg.norm(V[nb.vertex] - p, axis=1))
    assert set(F[10]) <= set(nb.vertex.tolist())
    with pytest.raises(ValueError, match="disagree"):
        solver.query(p[None] + 1.0, [10], bary, [-1], None, 4.0)
    with pytest.raises(ValueError):
        solver.query(None, [10], [[0.5, 0.6, 0.1]], [-1], None, 4.0)  # weights do not sum to 1
    with pytest.raises(ValueError):
        solver.query(None, None, None, [len(V)], None, 4.0)
    with pytest.raises(ValueError):
        solver.query(None, None, None, [0], None, -1.0)
    with pytest.raises(ValueError):
        GeodesicNeighbourhoods(V, F, method="heat")
    with pytest.raises(ValueError):
        GeodesicNeighbourhoods(V[:, :2], F)
    with pytest.raises(ValueError):
        GeodesicNeighbourhoods(V, F + len(V))


@pytest.mark.slow
def test_geodesic_neighbourhoods_exact_on_irregular_shared_meshes(shared_meshes):
    """Scanned / sliver-rich meshes (saddles, obtuse triangles): still igl-exact, never below it."""
    for name, scale in (("bunny.ply", 50.0), ("lee_perry_smith_head.obj", 10.0), ("hand.obj", 100.0)):
        m = trimesh.load(shared_meshes / name, process=False)
        V, F = np.asarray(m.vertices) * scale, np.asarray(m.faces, dtype=np.int64)
        solver = GeodesicNeighbourhoods(V, F)
        rng = np.random.default_rng(0)
        for s in rng.choice(len(V), 3, replace=False):
            v, d = solver.query(None, None, None, [s], None, 10.0).row(0)
            ref = _exact(V, F, s, v)
            far = ref > 0
            assert np.abs(_rel_err(d[far], ref[far])).max() < 1e-9, name
