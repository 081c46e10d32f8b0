"""The tetrahedral mesh of a closed surface (meshshade.volume.tetmesh.surface_tetrahedra): the surface's vertices
are its first nodes, the volume is the surface's, the triangles come back as boundary faces, and the diffusion
solve on it converges to the ball's exact series (docs/physics.md eq. (94))."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import trimesh

from meshshade.io import load_mesh
from meshshade.geometry.procedural import icosphere, torus
from meshshade.volume import DiffusionOperator, boundary_faces, locate_points, point_source_vector, tet_geometry
from meshshade.volume.tetmesh import surface_tetrahedra

_spec = importlib.util.spec_from_file_location("volume_fem_tests", Path(__file__).with_name("test_volume_fem.py"))
fem_tests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fem_tests)


def _check(V, F, tm, min_recovered, rtol):
    """The surface vertices are the first nodes, exactly; the boundary is a triangulation of surface vertices only,
    of the surface's area and enclosing its volume (to ``rtol``); ``min_recovered`` of its triangles are the
    input's own."""
    assert tm.n_surface == V.shape[0]
    np.testing.assert_array_equal(tm.nodes[:tm.n_surface], V)          # the surface's own vertices, exactly
    vol, _ = tet_geometry(tm.nodes, tm.tets)
    surface = trimesh.Trimesh(V, F, process=False)
    np.testing.assert_allclose(vol.sum(), surface.volume, rtol=rtol)
    bf = boundary_faces(tm.tets, tm.nodes)
    assert bf.max() < tm.n_surface                                       # no interior node on the boundary
    np.testing.assert_allclose(trimesh.Trimesh(tm.nodes, bf, process=False).area, surface.area, rtol=10 * rtol)
    assert tm.faces_recovered >= min_recovered, tm.faces_recovered
    P = tm.nodes[tm.tets]
    assert np.all(np.linalg.det(P[:, 1:] - P[:, :1]) > 0)               # positively oriented


@pytest.mark.parametrize("level", [3, 4])
def test_ball_mesh_keeps_the_surface(level):
    V, F = icosphere(5.0, level)
    _check(V, F, surface_tetrahedra(V, F), 1.0, 1e-9)


def test_torus_mesh_keeps_the_surface():
    """The torus's grid quads are planar isosceles trapezoids, whose corners lie on a circle: the Delaunay
    tetrahedralisation may take either diagonal and takes the other one on about half of them, which triangulates
    the same plane (volume and area equal to rounding)."""
    V, F = torus(8.0, 3.0, 48, 24)
    _check(V, F, surface_tetrahedra(V, F), 0.4, 1e-9)


def test_scanned_mesh(shared_meshes):
    mesh = load_mesh(shared_meshes / "spot.obj")
    V = (mesh.vertices - mesh.vertices.mean(axis=0)) * (50.0 / np.ptp(mesh.vertices, axis=0).max())
    _check(V, mesh.faces, surface_tetrahedra(V, mesh.faces), 0.995, 1e-5)


def test_solve_on_surface_mesh_converges_to_the_ball_series():
    """Icospheres of 642 and 2562 vertices (the surface spacing halves), a source 1 mm below the top of a 5 mm
    ball: the exitance at the surface vertices (nodes, read without interpolation) from 0.2 to 1.6 rad converges
    to eq. (94) at second order (measured 6.9 % -> 1.8 %)."""
    radius, depth = 5.0, 1.0
    errors = []
    for level in (3, 4):
        V, F = icosphere(radius, level)
        tm = surface_tetrahedra(V, F)
        op = DiffusionOperator(tm.nodes, tm.tets, D=fem_tests.D, sigma_a=fem_tests.SIGMA_A, A=fem_tests.A)
        tet, bary = locate_points(tm.nodes, tm.tets, [[0.0, 0.0, radius - depth]])
        M = op.solve(point_source_vector(tm.nodes.shape[0], tm.tets, tet, bary, [1.0]))[:tm.n_surface]
        M = M / (2.0 * fem_tests.A)
        gamma = np.arccos(np.clip(V[:, 2] / radius, -1.0, 1.0))
        keep = (gamma > 0.2) & (gamma < 1.6)
        ref = fem_tests.robin_ball_exitance(gamma[keep], radius, radius - depth)
        errors.append(np.mean(np.abs(M[keep] / ref - 1.0)))
    assert errors[1] < 0.025 and errors[0] / errors[1] > 3.0, errors


def test_a_finer_surface_adds_its_vertices_and_little_else():
    """With the material's grading (meshshade.volume.transport.grading), subdividing the surface below the
    material's lengths adds the new surface vertices, not layers under each of them or finer lattices: the
    interior nodes stay within 25 % (before, they grew about fourfold per subdivision with the surface)."""
    from meshshade.materials import Material
    from meshshade.volume.transport import grading

    mat = Material([0.5, 0.5, 0.5], [0.01, 0.01, 0.01])      # 1/sigma_t' = 1.96 mm: layers 0.88 mm, columns 1.3 mm
    g = grading(mat)
    interior = []
    for level in (4, 5):
        V, F = icosphere(10.0, level)
        tm = surface_tetrahedra(V, F, normal_spacing=g[0], layered_depth=g[1], interior_spacing=g[2],
                                interior_reach=g[3], column_spacing=g[4])
        interior.append(tm.nodes.shape[0] - tm.n_surface)
    _check(V, F, tm, 0.4, 2e-3)
    assert interior[1] < 1.25 * interior[0], interior
