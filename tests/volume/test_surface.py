"""The surface the volume transport samples (meshshade/volume/surface.py, docs/physics.md §15.5, eq. (104)).

Checked against the geometry itself, not the code's own bookkeeping: after splitting, no edge is longer than the
spacing, the input's vertices come first and unchanged, every split face lies on its input face (its corners are
the recorded barycentric combinations of the input face's corners) and the split is conforming (a closed input
stays closed: every edge in exactly two faces) with the same area; ``locate`` puts any point of an input face back
at the same 3D point on a split face of that face; a vertex reads the field where a texel or a pixel at its point
reads it (issue 47: one field); eq. (104), the Monte Carlo's patch average, keeps constants and the integral of a
P1 function (sum_v A_v M_v, A_v a third of the input's faces at v, equals the exact integral over the split
triangles) and equals a quadrature of its definition written here.
"""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.volume.surface import SamplingSurface, split_long_edges


@pytest.fixture(scope="module")
def coarse():
    """An icosahedron of radius 10 mm (edges 10.5 mm) sampled at 1 mm: a few hundred split faces per face."""
    mesh = Mesh.from_arrays(*icosphere(10.0, 0))
    return mesh, SamplingSurface(mesh, 1.0)


def _edges(F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def test_split_is_conforming_on_the_input_facets(coarse):
    mesh, ss = coarse
    V, F, origin, bary, complete = split_long_edges(mesh.vertices, mesh.faces, 1.0)
    assert complete and ss.split
    np.testing.assert_array_equal(V[:mesh.n_vertices], mesh.vertices)
    edges, count = _edges(F)
    assert np.all(count == 2)                                          # closed in, closed out: no hanging vertex
    assert np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1).max() <= 1.0
    want = np.einsum("qkm,qmd->qkd", bary, mesh.vertices[mesh.faces[origin]])
    np.testing.assert_allclose(V[F], want, rtol=0, atol=1e-12)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    assert area.sum() == pytest.approx(mesh.total_area, rel=1e-12)


def test_patch_average_keeps_constants_and_the_integral(coarse, rng):
    mesh, ss = coarse
    S = ss.samples
    np.testing.assert_allclose(ss.patch_average(np.full((S.n_vertices, 3), 2.5)), 2.5, rtol=1e-13)
    values = rng.random((S.n_vertices, 3))
    tri = values[S.faces]                                              # (faces, corners, 3)
    area = 0.5 * np.linalg.norm(np.cross(S.vertices[S.faces[:, 1]] - S.vertices[S.faces[:, 0]],
                                         S.vertices[S.faces[:, 2]] - S.vertices[S.faces[:, 0]]), axis=1)
    exact = np.einsum("f,fc->c", area / 3.0, tri.sum(axis=1))
    A_v = np.zeros(mesh.n_vertices)
    np.add.at(A_v, mesh.faces.ravel(), np.repeat(mesh.face_areas / 3.0, 3))
    np.testing.assert_allclose(A_v @ ss.patch_average(values), exact, rtol=1e-12)


def test_patch_average_is_its_definition(rng):
    """Eq. (104) against its definition by quadrature: on an icosahedron of radius 10 mm sampled at 2.5 mm, a P1
    field of random values on the split surface, int w_v M dA / int w_v dA with w_v the input's hat of vertex v
    (its barycentric in each input face) and M at the same point from the split face holding it, by a 6-point
    Gauss rule (Dunavant, exact for degree 4) on every split face; and on the input itself (nothing split), where
    the average of a P1 field is not its vertex value."""
    for mesh, spacing in ((Mesh.from_arrays(*icosphere(10.0, 0)), 2.5), (Mesh.from_arrays(*icosphere(10.0, 1)), 100.0)):
        ss = SamplingSurface(mesh, spacing)
        S = ss.samples
        values = rng.random((S.n_vertices, 2))
        V, F, origin, bary, _ = split_long_edges(mesh.vertices, mesh.faces, spacing)
        a, b = 0.445948490915965, 0.091576213509771                  # Dunavant's 6-point rule
        wa, wb = 0.223381589678011, 0.109951743655322
        pts = np.array([[a, a, 1 - 2 * a], [a, 1 - 2 * a, a], [1 - 2 * a, a, a],
                        [b, b, 1 - 2 * b], [b, 1 - 2 * b, b], [1 - 2 * b, b, b]])
        wts = np.array([wa] * 3 + [wb] * 3)
        area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
        num = np.zeros((mesh.n_vertices, 2))
        den = np.zeros(mesh.n_vertices)
        for lam, w in zip(pts, wts):
            M = np.einsum("k,qkc->qc", lam, values[F])                  # the field at the point
            hat = np.einsum("k,qkm->qm", lam, bary)                    # the input's barycentrics there
            for m in range(3):
                np.add.at(num, mesh.faces[origin, m], (w * area * hat[:, m])[:, None] * M)
                np.add.at(den, mesh.faces[origin, m], w * area * hat[:, m])
        np.testing.assert_allclose(ss.patch_average(values), num / den[:, None], rtol=1e-10)
        assert np.abs(ss.patch_average(values) - ss.to_vertices(values)).max() > 1e-2


def test_a_vertex_reads_the_field_where_a_texel_does(coarse, rng):
    """The field P1 on the split surface, read through ``locate`` at an input vertex (as a texel or a pixel on that
    point is), is what ``to_vertices`` gives the vertex: the point value, not the patch average (issue 47)."""
    mesh, ss = coarse
    S = ss.samples
    values = rng.random((S.n_vertices, 3))
    F = mesh.faces
    face = np.repeat(np.arange(F.shape[0]), 3)
    bary = np.tile(np.eye(3), (F.shape[0], 1))                          # every corner of every input face
    sub, lam = ss.locate(face, bary)
    at_point = np.einsum("km,kmc->kc", lam, values[S.faces[sub]])
    np.testing.assert_allclose(at_point, ss.to_vertices(values)[F.ravel()], rtol=1e-12)
    assert ss.to_vertices(values).shape == (mesh.n_vertices, 3)


def test_nothing_split_is_the_identity():
    mesh = Mesh.from_arrays(*icosphere(10.0, 2))
    ss = SamplingSurface(mesh, 100.0)
    assert not ss.split and ss.samples is mesh
    x = np.arange(3.0 * mesh.n_vertices).reshape(-1, 3)
    np.testing.assert_array_equal(ss.to_vertices(x), x)
    face, bary = np.array([0, 5]), np.array([[0.2, 0.3, 0.5], [1.0, 0.0, 0.0]])
    f2, b2 = ss.locate(face, bary)
    np.testing.assert_array_equal(f2, face)
    np.testing.assert_array_equal(b2, bary)


def test_locate_finds_every_point_again(coarse, rng):
    mesh, ss = coarse
    S = ss.samples
    k = 5000
    face = rng.integers(0, mesh.n_faces, k)
    bary = rng.dirichlet([1.0, 1.0, 1.0], k)
    bary[:10] = np.eye(3)[rng.integers(0, 3, 10)]                      # input corners
    bary[10:20] = [0.5, 0.5, 0.0]                                       # edge midpoints (shared by split faces)
    sub, lam = ss.locate(face, bary)
    point = np.einsum("km,kmd->kd", bary, mesh.vertices[mesh.faces[face]])
    again = np.einsum("km,kmd->kd", lam, S.vertices[S.faces[sub]])
    np.testing.assert_allclose(again, point, rtol=0, atol=1e-10)
    assert np.all(lam >= 0.0) and np.allclose(lam.sum(axis=1), 1.0)
    # the split face lies on the input face (not a neighbour's that touches the point)
    Fi = mesh.vertices[mesh.faces[face]]
    n_in = np.cross(Fi[:, 1] - Fi[:, 0], Fi[:, 2] - Fi[:, 0])
    Fs = S.vertices[S.faces[sub]]
    n_sub = np.cross(Fs[:, 1] - Fs[:, 0], Fs[:, 2] - Fs[:, 0])
    cos = np.einsum("ij,ij->i", n_in, n_sub) / (np.linalg.norm(n_in, axis=1) * np.linalg.norm(n_sub, axis=1))
    np.testing.assert_allclose(cos, 1.0, atol=1e-9)
