"""Regular refinement on the facets: same surface, closed, original vertices first, points located exactly."""
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, torus
from meshshade.geometry.refine import refine_faces, refined_location, refined_mesh


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_refinement_is_the_same_closed_surface(n):
    V, F = torus(10.0, 3.0, 24, 12)
    mesh = Mesh.from_arrays(V, F)
    Vn, Fn, Nn = refine_faces(mesh.vertices, mesh.faces, mesh.vertex_normals, n)
    fine = Mesh.from_arrays(Vn, Fn)
    assert fine.defects.is_closed and Fn.shape[0] == F.shape[0] * n * n
    assert Vn.shape[0] - 3 * Fn.shape[0] // 2 + Fn.shape[0] == 0               # Euler characteristic of a torus
    np.testing.assert_array_equal(Vn[:V.shape[0]], mesh.vertices)
    assert fine.total_area == pytest.approx(mesh.total_area, rel=1e-12)
    parent = np.repeat(np.arange(F.shape[0]), n * n)
    assert np.all(np.einsum("ij,ij->i", fine.face_normals, mesh.face_normals[parent]) > 1 - 1e-9)
    np.testing.assert_allclose(np.linalg.norm(Nn, axis=1), 1.0, atol=1e-12)


def test_points_are_located_in_their_sub_triangle():
    V, F = icosphere(1.0, 1)
    rng = np.random.default_rng(0)
    face = rng.integers(0, F.shape[0], 2000)
    bary = rng.dirichlet([1, 1, 1], 2000)
    bary[:6] = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.5, 0], [0, 0.5, 0.5], [1 / 3, 1 / 3, 1 / 3]]
    p = np.einsum("ij,ijk->ik", bary, V[F[face]])
    N = Mesh.from_arrays(V, F).vertex_normals
    for n in (1, 2, 4, 7):
        Vn, Fn, _ = refine_faces(V, F, N, n)
        sf, sb = refined_location(face, bary, n)
        assert np.all(sf // (n * n) == face) and np.all(sb >= 0)
        np.testing.assert_allclose(np.einsum("ij,ijk->ik", sb, Vn[Fn[sf]]), p, atol=1e-13)


def test_refined_mesh_interpolates_the_shading_normals():
    V, F = icosphere(5.0, 1)
    mesh = Mesh.from_arrays(V, F)
    fine = refined_mesh(mesh, 3)
    assert refined_mesh(mesh, 1) is mesh
    np.testing.assert_array_equal(fine.vertex_normals[:mesh.n_vertices], mesh.vertex_normals)
    # the exact sphere's normal is closer to the interpolated normal than to the facet's (mid-face vertices)
    exact = fine.vertices / np.linalg.norm(fine.vertices, axis=1, keepdims=True)
    facet = Mesh.from_arrays(fine.vertices, fine.faces).vertex_normals
    err_interp = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", fine.vertex_normals, exact), -1, 1)))
    err_facet = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", facet, exact), -1, 1)))
    assert err_interp.mean() < 0.5 * err_facet.mean()
