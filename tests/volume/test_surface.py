"""The surface the volume transport samples (meshshade/volume/surface.py, docs/physics.md §15.5, eq. (104)).

Checked against the geometry itself, not the code's own bookkeeping: after splitting, no edge is longer than the
spacing, the input's vertices come first and unchanged, every split face lies on its input face (its corners are
the recorded barycentric combinations of the input face's corners) and the split is conforming (a closed input
stays closed: every edge in exactly two faces) with the same area; eq. (104) keeps constants and the integral of
a P1 function (sum_v A_v M_v, A_v a third of the input's faces at v, equals the exact integral over the split
triangles); and ``locate`` puts any point of an input face back at the same 3D point on a split face of that face.
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
    np.testing.assert_allclose(ss.to_vertices(np.full((S.n_vertices, 3), 2.5)), 2.5, rtol=1e-13)
    values = rng.random((S.n_vertices, 3))
    tri = values[S.faces]                                              # (faces, corners, 3)
    area = 0.5 * np.linalg.norm(np.cross(S.vertices[S.faces[:, 1]] - S.vertices[S.faces[:, 0]],
                                         S.vertices[S.faces[:, 2]] - S.vertices[S.faces[:, 0]]), axis=1)
    exact = np.einsum("f,fc->c", area / 3.0, tri.sum(axis=1))
    A_v = np.zeros(mesh.n_vertices)
    np.add.at(A_v, mesh.faces.ravel(), np.repeat(mesh.face_areas / 3.0, 3))
    np.testing.assert_allclose(A_v @ ss.to_vertices(values), exact, rtol=1e-12)


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
