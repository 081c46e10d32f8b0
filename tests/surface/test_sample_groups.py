"""Far-zone geodesics shared by groups of entry samples (meshshade/surface/sample_groups.py)."""
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from meshshade.geometry.curvature import principal_curvatures
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods
from meshshade.geometry.procedural import icosphere, saddle_patch
from meshshade.surface.sample_groups import (NORMAL_COS, _law_of_cosines, group_samples, expand_far_pairs,
                                          expand_far_pairs_reference)
from meshshade.surface.pair_kernel import source_frames


class _Samples:
    """Vertex entry samples at every vertex (what a directional light makes)."""

    def __init__(self, mesh):
        n = mesh.n_vertices
        self.vertex, self.face = np.arange(n), np.full(n, -1)
        self.bary, self.normals, self.positions = np.zeros((n, 3)), mesh.vertex_normals, mesh.vertices

    def __len__(self):
        return len(self.vertex)


def _setup(mesh):
    frames = source_frames(_Samples(mesh), principal_curvatures(mesh.vertices, mesh.faces), mesh.faces)
    solver = GeodesicNeighbourhoods(mesh.vertices, mesh.faces, mesh.vertex_normals)

    def query(sel, r):
        nb = solver.query(mesh.vertices[sel], np.full(sel.size, -1), np.zeros((sel.size, 3)), sel,
                          frames.normals[sel], r, d1=frames.d1[sel], d2=frames.d2[sel], k1=frames.k1[sel],
                          k2=frames.k2[sel])
        return sel[nb.source_index()], nb.vertex.astype(np.int64), nb.distance, nb.chord, nb.phi
    return frames, query


def test_group_samples_partitions_the_samples(rng):
    V, F = icosphere(20.0, 4)
    mesh = Mesh.from_arrays(V, F)
    order, ptr = group_samples(V, mesh.vertex_normals, 4.0)
    assert np.array_equal(np.sort(order), np.arange(len(V)))  # every sample exactly once
    centre = order[ptr[:-1]]
    rows = np.repeat(np.arange(ptr.size - 1), np.diff(ptr))
    d = np.linalg.norm(V[order] - V[centre[rows]], axis=1)
    assert d.max() <= np.sqrt(3) * 4.0  # within one voxel cell
    assert np.all(np.einsum("ij,ij->i", mesh.vertex_normals[order], mesh.vertex_normals[centre[rows]]) >= NORMAL_COS)
    assert 3 < len(V) / (ptr.size - 1) < 30  # real groups, not singletons
    # opposite sheets of a thin plate never share a group
    P = np.array([[0, 0, 0], [0, 0, 0.1]], float)
    Nrm = np.array([[0, 0, -1], [0, 0, 1.0]])
    o, p = group_samples(P, Nrm, 1.0)
    assert p.size == 3


def test_law_of_cosines_exact_on_plane_sphere_and_pseudosphere_limit():
    rng = np.random.default_rng(3)
    sc, d, g = rng.uniform(5, 20, 50), rng.uniform(0, 3, 50), rng.uniform(0, np.pi, 50)
    plane = _law_of_cosines(sc, d, d * np.cos(g), d, np.zeros(50))
    np.testing.assert_allclose(plane, np.sqrt(sc ** 2 + d ** 2 - 2 * sc * d * np.cos(g)), rtol=1e-14)
    # on a unit-radius-R sphere: points by rotation, compare with great-circle distance (independent route)
    R = 30.0
    sc, d = sc[:20] * 2, d[:20]
    g = g[:20]
    c = np.array([0, 0, R])
    o = R * np.stack([np.sin(sc / R), np.zeros(20), np.cos(sc / R)], axis=1)
    i = R * np.stack([np.sin(d / R) * np.cos(g), np.sin(d / R) * np.sin(g), np.cos(d / R) * np.ones(20)], axis=1)
    want = R * np.arccos(np.clip(np.einsum("ij,ij->i", o, i) / R ** 2, -1, 1))
    got = _law_of_cosines(sc, d, d * np.cos(g), d, np.full(20, 1 / R ** 2))
    np.testing.assert_allclose(got, want, rtol=1e-10)
    # pseudosphere (K = -1/R^2): points on the hyperboloid -t^2 + x^2 + y^2 = -R^2 of Minkowski space, at geodesic
    # distance sc along x and d at angle g (boosts instead of rotations); their distance from the Minkowski product,
    # cosh(s/R) = (t1 t2 - x1 x2 - y1 y2)/R^2
    o = R * np.stack([np.cosh(sc / R), np.sinh(sc / R), np.zeros(20)], axis=1)
    i = R * np.stack([np.cosh(d / R), np.sinh(d / R) * np.cos(g), np.sinh(d / R) * np.sin(g)], axis=1)
    want_h = R * np.arccosh((o[:, 0] * i[:, 0] - o[:, 1] * i[:, 1] - o[:, 2] * i[:, 2]) / R ** 2)
    got_h = _law_of_cosines(sc, d, d * np.cos(g), d, np.full(20, -1 / R ** 2))
    np.testing.assert_allclose(got_h, want_h, rtol=1e-10)
    # comparison theorem: the third side is longer than the planar one at K < 0, shorter at K > 0, and both tend
    # to it like K s^2 (at R = 1e4 mm: within 1e-5 relative)
    flat = np.sqrt(sc ** 2 + d ** 2 - 2 * sc * d * np.cos(g))
    assert np.all(got_h >= flat * (1 - 1e-12)) and np.all(got <= flat * (1 + 1e-12))
    assert np.any(got_h > flat * (1 + 1e-4)) and np.any(got < flat * (1 - 1e-4))
    for K in (1e-8, -1e-8):
        np.testing.assert_allclose(_law_of_cosines(sc, d, d * np.cos(g), d, np.full(20, K)), flat, rtol=1e-5)


def test_expanded_pairs_of_the_centre_reproduce_the_solver():
    mesh = Mesh.from_arrays(*icosphere(20.0, 3))
    frames, query = _setup(mesh)
    cen = np.array([0, 17, 101])
    pc = query(cen, 25.0)
    out = expand_far_pairs(pc, (cen, cen), mesh.vertices, mesh.vertices, frames)
    o1 = np.lexsort((pc[1], pc[0]))
    o2 = np.lexsort((out[1], out[0]))
    for a, b in zip(pc, out):
        np.testing.assert_allclose(b[o2], a[o1], rtol=1e-12, atol=1e-12)


@pytest.mark.filterwarnings("ignore:open boundary")
@pytest.mark.parametrize("shape", ["plane", "sphere"])
def test_member_distances_match_their_own_exact_geodesics(shape):
    """Far pairs from the centre's geodesics by the law of cosines vs each member's own exact query: exact on the
    plane (to rounding); on a 20 mm sphere (1.2 mm edges, 2 mm groups) the polyhedral geodesics differ from the
    constant-curvature triangle by the facets' O(h^2) (measured max 0.013 mm, mean 5e-4 mm at s > 10 mm)."""
    if shape == "plane":
        mesh = Mesh.from_arrays(*saddle_patch(0.0, 30.0, 41))  # an open flat patch (warns: open boundary)
    else:
        mesh = Mesh.from_arrays(*icosphere(20.0, 4))
    frames, query = _setup(mesh)
    V = mesh.vertices
    order, ptr = group_samples(V, frames.normals, 2.0 if shape == "sphere" else 3.0)
    rows = np.repeat(np.arange(ptr.size - 1), np.diff(ptr))
    centre_of = order[ptr[:-1]][rows]
    pick = np.flatnonzero(np.linalg.norm(V[order], axis=1) < 8) if shape == "plane" else np.arange(300)
    mem, cen_of = order[pick], centre_of[pick]
    pc = query(np.unique(cen_of), 30.0)
    pf = expand_far_pairs(pc, (mem, cen_of), V, V, frames, max_distance=20.0)
    pe = query(mem, 20.0)
    n = len(V)
    _, ie, i_f = np.intersect1d(pe[0] * n + pe[1], pf[0] * n + pf[1], return_indices=True)
    far = pe[2][ie] > 10.0
    err = np.abs(pf[2][i_f] - pe[2][ie])[far]
    assert far.sum() > 1000
    if shape == "plane":
        assert err.max() < 1e-9
    else:
        assert err.max() < 0.03 and err.mean() < 2e-3, (err.max(), err.mean())
    np.testing.assert_allclose(pf[3][i_f], pe[3][ie], atol=1e-9)  # chords are the member's own


@given(sc=st.floats(0.0, 200.0), d=st.floats(0.0, 20.0), cosg=st.floats(-1.0, 1.0),
       K=st.one_of(st.just(0.0), st.floats(-1.0, 1.0)))
def test_law_of_cosines_finite_and_within_the_triangle_inequality(sc, d, cosg, K):
    """For every side pair, angle and Gaussian curvature in range (radii down to 1 mm): finite, >= 0, and
    |sc - d| <= s <= sc + d (a geodesic triangle's third side; spherical/hyperbolic laws keep it)."""
    s = _law_of_cosines(np.array([sc]), np.array([d]), np.array([d * cosg]), np.array([d]), np.array([K]))[0]
    assert np.isfinite(s) and s >= 0.0
    assert abs(sc - d) - 1e-9 * (sc + d + 1) <= s <= sc + d + 1e-9 * (sc + d + 1)


def test_numba_expansion_equals_the_numpy_reference():
    """Same pairs in the same order, values to rounding, with exclusions and a distance limit."""
    mesh = Mesh.from_arrays(*icosphere(20.0, 3))
    frames, query = _setup(mesh)
    V, n = mesh.vertices, mesh.n_vertices
    order, ptr = group_samples(V, frames.normals, 4.0)
    rows = np.repeat(np.arange(ptr.size - 1), np.diff(ptr))
    centre_of = order[ptr[:-1]][rows]
    mem, cen_of = order[:200], centre_of[:200]
    pc = query(np.unique(cen_of), 30.0)
    pn = query(mem, 6.0)
    keys = np.sort(pn[0] * n + pn[1])
    a = expand_far_pairs(pc, (mem, cen_of), V, V, frames, exclude_keys=keys, max_distance=25.0)
    b = expand_far_pairs_reference(pc, (mem, cen_of), V, V, frames, exclude_keys=keys, max_distance=25.0)
    assert a[0].size == b[0].size > 1000
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    for x, y in zip(a[2:4], b[2:4]):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12)
    # azimuths as angles: -pi and +pi are the same direction (the two wrap differently by rounding)
    assert np.max(np.abs(np.angle(np.exp(1j * (a[4] - b[4]))))) < 1e-12
