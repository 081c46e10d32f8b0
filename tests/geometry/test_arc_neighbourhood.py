"""The "arc" geodesic neighbourhoods (meshshade.geometry.geodesics.arc) against the exact window solver.

References: exact polyhedral geodesics (``GeodesicNeighbourhoods(..., rel_tol=0)``) and great circles on
icospheres; a torus; a folded strip and two touching spheres for leaks across gaps.
"""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.geometry.geodesics.arc import ArcGeodesicNeighbourhoods
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods, Neighbourhoods
from meshshade.geometry.procedural import icosphere, torus


def _normals(V, F):
    return np.asarray(Mesh(V, F).vertex_normals, dtype=np.float64)


def _pairs(nb):
    """dict (source, vertex) -> distance."""
    return dict(zip(zip(nb.source_index().tolist(), nb.vertex.tolist()), nb.distance.tolist()))


def _compare(V, F, N, sources, cut, tol=5e-3, **kw):
    """Arc vs exact: relative error beyond 2 mean edges and vertex sets (up to the 0.5 % cutoff band)."""
    exact = GeodesicNeighbourhoods(V, F, N).query(None, None, None, sources, None, cut, **kw)
    arc_s = ArcGeodesicNeighbourhoods(V, F, N)
    arc = arc_s.query(None, None, None, sources, None, cut, **kw)
    h = arc_s.mean_edge_length
    pe, pf = _pairs(exact), _pairs(arc)
    common = pe.keys() & pf.keys()
    de = np.array([pe[p] for p in common])
    df = np.array([pf[p] for p in common])
    far = de > 2 * h
    rel = np.abs(df[far] - de[far]) / de[far]
    assert rel.max() <= tol, rel.max()
    only_e = np.array([pe[p] for p in pe.keys() - pf.keys()])
    only_f = np.array([pf[p] for p in pf.keys() - pe.keys()])
    assert np.all(only_e >= (1 - tol) * cut), only_e.min(initial=np.inf)
    assert np.all(only_f >= (1 - tol) * cut), only_f.min(initial=np.inf)
    return exact, arc, rel


def test_arc_icosphere_matches_exact_and_great_circle():
    R = 10.0
    V, F = icosphere(R, 4)
    N = V / np.linalg.norm(V, axis=1, keepdims=True)
    src = np.arange(0, len(V), 37)
    exact, arc, rel = _compare(V, F, N, src, 5.0)
    x, y = V[src[arc.source_index()]], V[arc.vertex]
    gc = R * np.arctan2(np.linalg.norm(np.cross(x, y), axis=1), np.einsum("ij,ij->i", x, y))
    assert np.abs(arc.distance - gc).max() < 1e-9  # exact normals: the arc is the great circle
    assert arc.method == "arc" and isinstance(arc, Neighbourhoods)


def test_arc_icosphere_mesh_normals_within_half_percent():
    V, F = icosphere(60.0, 5)
    _compare(V, F, _normals(V, F), np.arange(0, len(V), 211), 28.0)


def test_arc_torus_matches_exact():
    V, F = torus(40.0, 15.0, 160, 64)
    _, _, rel = _compare(V, F, _normals(V, F), np.arange(0, len(V), 97), 14.0)
    assert rel.mean() < 1e-3


def test_arc_csr_layout_and_phi_match_exact():
    V, F = icosphere(10.0, 3)
    N = V / np.linalg.norm(V, axis=1, keepdims=True)
    src = np.arange(0, len(V), 7)
    a = np.where(np.abs(N[src, 0:1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    d1 = np.cross(N[src], a)
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    d2 = np.cross(N[src], d1)
    kw = dict(d1=d1, d2=d2, tangent=True)
    exact = GeodesicNeighbourhoods(V, F, N).query(None, None, None, src, None, 4.0, **kw)
    arc = ArcGeodesicNeighbourhoods(V, F, N).query(None, None, None, src, None, 4.0, **kw)
    for name in ("indptr", "vertex", "distance", "chord", "tangent", "phi", "cutoff"):
        e, f = getattr(exact, name), getattr(arc, name)
        assert e.dtype == f.dtype and e.ndim == f.ndim, name
    assert arc.indptr.shape == (src.size + 1,) and arc.indptr[0] == 0
    assert np.all(np.diff(arc.indptr) >= 1)
    ke = {p: i for i, p in enumerate(zip(exact.source_index().tolist(), exact.vertex.tolist()))}
    kf = {p: i for i, p in enumerate(zip(arc.source_index().tolist(), arc.vertex.tolist()))}
    common = sorted(ke.keys() & kf.keys())
    ie, jf = np.array([ke[p] for p in common]), np.array([kf[p] for p in common])
    assert np.allclose(exact.phi[ie], arc.phi[jf], atol=1e-12)
    assert np.allclose(exact.chord[ie], arc.chord[jf], atol=1e-12)
    # each row: the source itself at distance 0, chord <= distance <= cutoff
    assert np.all(arc.chord <= arc.distance + 1e-12) and np.all(arc.distance <= 4.0)
    with pytest.raises(ValueError):
        ArcGeodesicNeighbourhoods(V, F, N).query(None, None, None, [len(V)], None, 4.0)


def test_arc_face_sources_match_exact():
    V, F = icosphere(10.0, 4)
    N = V / np.linalg.norm(V, axis=1, keepdims=True)
    rng = np.random.default_rng(3)
    faces = rng.choice(len(F), 20, replace=False)
    bary = rng.dirichlet([2, 2, 2], 20)
    kw = dict(source_faces=faces, source_bary=bary, source_vertex=None)
    exact = GeodesicNeighbourhoods(V, F, N).query(None, faces, bary, None, None, 5.0)
    arc = ArcGeodesicNeighbourhoods(V, F, N).query(None, faces, bary, None, None, 5.0)
    pe, pf = _pairs(exact), _pairs(arc)
    common = pe.keys() & pf.keys()
    de, df = np.array([pe[p] for p in common]), np.array([pf[p] for p in common])
    far = de > 1.0
    assert np.abs(df[far] / de[far] - 1).max() < 5e-3
    assert all(pe[p] > 0.995 * 5.0 for p in pe.keys() - pf.keys())
    del kw


def _u_strip(r=0.5, arm=30.0, width=4.0, n_s=260, n_w=9):
    total = 2 * arm + np.pi * r
    s_par = np.linspace(0, total, n_s)
    x = np.where(s_par < arm, arm - s_par,
                 np.where(s_par < arm + np.pi * r, -r * np.sin((s_par - arm) / r), s_par - arm - np.pi * r))
    y = np.where(s_par < arm, -r, np.where(s_par < arm + np.pi * r, -r * np.cos((s_par - arm) / r), r))
    xs, ys = np.arange(n_s), np.linspace(0, width, n_w)
    i, j = np.meshgrid(np.arange(n_s - 1), np.arange(n_w - 1), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a, b, c, d = i * n_w + j, (i + 1) * n_w + j, (i + 1) * n_w + j + 1, i * n_w + j + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    ii = np.repeat(xs, n_w)
    V = np.column_stack([x[ii], y[ii], np.tile(ys, n_s)])
    return V, F


def test_arc_no_leak_u_strip_far_from_fold():
    """The other arm is 1 mm away in space but > 20 mm along the surface."""
    V, F = _u_strip()
    r, arm, width = 0.5, 30.0, 4.0
    src = int(np.argmin(np.linalg.norm(V - [arm / 2, -r, width / 2], axis=1)))
    other = np.flatnonzero(V[:, 1] > 0.99 * r)
    arc = ArcGeodesicNeighbourhoods(V, F, _normals(V, F)).query(None, None, None, [src], None, 10.0)
    assert np.intersect1d(arc.vertex, other).size == 0 and arc.n_pairs > 100


@pytest.mark.xfail(strict=True, reason="known limitation: within ~6 mm of a 0.5 mm-radius fold the arc/graph "
                   "ratio test (r_max=1.6) accepts the chord across the fold, so distances on the other arm "
                   "undershoot (up to 37 %) and extra vertices are included")
def test_arc_u_strip_around_the_fold_matches_exact():
    """Source 3 mm before the fold: the other arm is reached only around the bend (fallback path)."""
    V, F = _u_strip()
    N = _normals(V, F)
    srcs = [int(np.argmin(np.linalg.norm(V - [x, -0.5, 2.0], axis=1))) for x in (1.0, 3.0, 6.0)]
    exact, arc, rel = _compare(V, F, N, srcs, 10.0, tol=1e-2)
    other = np.flatnonzero(V[:, 1] > 0.49)
    assert np.intersect1d(arc.vertex, other).size > 0


def test_arc_no_leak_between_touching_spheres():
    Va, Fa = icosphere(5.0, 3)
    Vb = Va + [10.0 + 1e-6, 0.0, 0.0]
    V, F = np.concatenate([Va, Vb]), np.concatenate([Fa, Fa + len(Va)])
    s = int(np.argmax(Va[:, 0]))
    nb = ArcGeodesicNeighbourhoods(V, F, _normals(V, F)).query(None, None, None, [s], None, 4.0)
    assert nb.vertex.max() < len(Va) and nb.n_pairs > 10


def test_arc_overflow_rerun_and_blocks_consistent():
    V, F = icosphere(10.0, 4)
    N = V / np.linalg.norm(V, axis=1, keepdims=True)
    src = np.arange(0, len(V), 5)
    cut = np.where(np.arange(src.size) % 3 == 0, 8.0, 2.0)
    s = ArcGeodesicNeighbourhoods(V, F, N)
    a = s.query(None, None, None, src, None, cut, block_size=50)
    s._cap = 16  # force the capacity re-run path
    b = s.query(None, None, None, src, None, cut)
    assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.vertex, b.vertex)
    assert np.array_equal(a.distance, b.distance)
    assert s.stats["pairs"] == b.n_pairs


def test_arc_results_do_not_depend_on_threads_or_blocks():
    """The arc loop is serial over a block of sources, the blocks on the pacing threads: one thread in blocks of 3
    sources and two threads in paced blocks give the same neighbourhoods, bit for bit."""
    V, F = icosphere(10.0, 3)
    N = _normals(V, F)
    src = np.arange(0, len(V), 5)
    one = ArcGeodesicNeighbourhoods(V, F, N, n_threads=1).query(None, None, None, src, None, 6.0, block_size=3)
    two = ArcGeodesicNeighbourhoods(V, F, N, n_threads=2).query(None, None, None, src, None, 6.0)
    assert one.vertex.size > 10 * src.size
    for name in ("indptr", "vertex", "distance", "chord"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))
