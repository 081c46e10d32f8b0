"""validate_mesh and the Mesh container: fatal errors, reported defects, repairs that keep the vertex order."""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from meshshade.errors import MeshValidationError
from meshshade.geometry import procedural
from meshshade.geometry.mesh import Mesh, MeshDefectWarning, face_normals, validate_mesh
from meshshade.transport import BakeOptions


def _quiet_validate(V, F):
    return validate_mesh(V, F, emit_warnings=False)


def _cyclic(F):
    """Faces rotated to start at their smallest index (same winding compares equal)."""
    F = np.asarray(F)
    k = np.argmin(F, axis=1)
    return np.stack([F[np.arange(len(F)), (k + i) % 3] for i in range(3)], axis=1)


@pytest.fixture(scope="module")
def sphere():
    return procedural.icosphere(10.0, 2)


# ------------------------------------------------------------------------------------------- fatal errors

@pytest.mark.parametrize("vertices, faces, match", [
    (np.zeros((0, 3)), np.zeros((0, 3), int), "no vertices"),
    (np.zeros((3, 3)) + np.eye(3), np.zeros((0, 3), int), "no faces"),
    (np.zeros((3, 2)), [[0, 1, 2]], r"\(n, 3\)"),
    (np.eye(3), [[0, 1, 3]], "face index 3 out of range for 3 vertices"),
    (np.eye(3), [[0, -1, 2]], "negative face index -1"),
    (np.eye(4)[:, :3], [[0, 1, 2, 3]], "triangles"),
    (np.eye(4)[:, :3], [[0, 1, 2], [0, 1, 2, 3]], "not all triangles"),
    (np.eye(3), [[0.0, 1.5, 2.0]], "integers"),
    (np.eye(3), [[0, 0, 1], [1, 2, 2]], "all 2 faces are degenerate"),
    (np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float), [[0, 1, 2]], "all 1 faces are degenerate"),
])
def test_validate_mesh_fatal_errors(vertices, faces, match):
    with pytest.raises(MeshValidationError, match=match) as info:
        validate_mesh(vertices, faces)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_validate_mesh_rejects_non_finite(sphere, bad):
    V, F = sphere
    V = V.copy()
    V[7, 1] = bad
    with pytest.raises(MeshValidationError, match=r"1 vertices have NaN or Inf coordinates \(first: vertex 7\)"):
        validate_mesh(V, F)


# ----------------------------------------------------------------------------------------- clean meshes

@pytest.mark.parametrize("name", ["icosphere", "uv_sphere", "capped_cylinder", "torus", "box", "pebble"])
def test_validate_mesh_procedural_shapes_are_clean(name):
    V, F = getattr(procedural, name)()
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshDefectWarning)
        report = validate_mesh(V, F)
    assert report.is_clean and report.is_closed
    assert report.n_components == 1
    np.testing.assert_array_equal(report.faces, F)


# ------------------------------------------------------------------------------------- reported defects

def test_validate_mesh_open_boundary(sphere):
    V, F = sphere
    with pytest.warns(MeshDefectWarning, match="open boundary: 3 edges"):
        report = validate_mesh(V, F[1:])
    assert report.n_boundary_edges == 3 and not report.is_closed


def test_validate_mesh_nonmanifold_edge(sphere):
    V, F = sphere
    a, b, _ = F[0]
    V2 = np.vstack([V, [[0.0, 0.0, 0.0]]])  # a fin from the sphere's centre to one of its edges
    report = _quiet_validate(V2, np.vstack([F, [[a, b, len(V)]]]))
    assert report.warnings == ("open boundary: 2 edges are used by one face only (mesh is not closed)",
                               "non-manifold: 1 edges are shared by more than two faces")
    assert report.n_nonmanifold_edges == 1
    assert report.n_components_flipped == 0  # the closed sphere is still recognised as outward


def test_validate_mesh_components_and_unreferenced_vertices(sphere):
    V, F = sphere
    V2 = np.vstack([V, V + 30.0, [[100.0, 0.0, 0.0]]])
    F2 = np.vstack([F, F + len(V)])
    with pytest.warns(MeshDefectWarning) as record:
        report = validate_mesh(V2, F2)
    text = " | ".join(str(w.message) for w in record)
    assert "2 connected components" in text and "1 unreferenced vertices kept" in text
    assert report.n_components == 2 and report.n_unreferenced_vertices == 1
    assert len(report.warnings) == 2 and not report.fixed


def test_validate_mesh_degenerate_faces_kept_but_excluded(sphere):
    V, F = sphere
    a, b, c = F[0]
    V2 = np.vstack([V, 0.5 * (V[a] + V[b])])  # split face 0 with a collinear sliver (a, m, b)
    m = len(V)
    F2 = np.vstack([[a, m, c], [m, b, c], [a, b, m], F[1:], [[a, a, b]]])
    with pytest.warns(MeshDefectWarning, match="2 degenerate"):
        mesh = Mesh(V2, F2)
    assert mesh.defects.n_degenerate_faces == 2
    assert mesh.n_faces == F2.shape[0]  # kept in the face list
    assert mesh.degenerate_face_mask.tolist()[:3] == [False, False, True] and mesh.degenerate_face_mask[-1]
    assert mesh.nondegenerate_faces.shape[0] == F2.shape[0] - 2
    assert mesh.face_areas[2] == 0.0 and np.all(mesh.face_normals[2] == 0.0)
    # the sliver keeps its edges, so the surface is still closed except at the repeated-index face
    assert mesh.defects.n_boundary_edges == 0


def test_validate_mesh_degenerate_test_is_scale_free(sphere):
    V, F = sphere
    for s in (1e-6, 1.0, 1e6):
        report = validate_mesh(V * s, F)
        assert report.n_degenerate_faces == 0


# ------------------------------------------------------------------------------------------- repairs

def test_validate_mesh_flips_inward_mesh_keeping_vertex_order(sphere):
    V, F = sphere
    with pytest.warns(MeshDefectWarning, match="inward orientation fixed"):
        mesh = Mesh(V, F[:, ::-1])
    assert mesh.defects.n_components_flipped == 1
    np.testing.assert_array_equal(mesh.vertices, V)  # vertices untouched
    np.testing.assert_array_equal(_cyclic(mesh.faces), _cyclic(F))  # original outward winding restored
    np.testing.assert_array_equal(mesh.faces[:, 0], F[:, 2])  # first corner kept: (c, b, a) -> (c, a, b)
    assert np.all(np.einsum("ij,ij->i", mesh.vertex_normals, V) > 0)


def test_validate_mesh_fixes_inconsistent_winding(sphere, rng):
    V, F = sphere
    F2 = F.copy()
    idx = rng.choice(len(F), size=len(F) // 3, replace=False)
    F2[idx] = F2[idx][:, [1, 0, 2]]
    with pytest.warns(MeshDefectWarning, match=f"flipped {len(idx)} of {len(F)} faces"):
        report = validate_mesh(V, F2)
    assert report.n_faces_rewound == len(idx) and report.n_winding_conflicts == 0
    np.testing.assert_array_equal(_cyclic(report.faces), _cyclic(F))


def test_validate_mesh_fixes_winding_then_orientation(sphere, rng):
    V, F = sphere
    F2 = F[:, ::-1].copy()
    idx = rng.choice(len(F), size=10, replace=False)
    F2[idx] = F2[idx][:, [0, 2, 1]]  # a few faces point out, most in
    report = _quiet_validate(V, F2)
    assert report.n_faces_rewound == 10 and report.n_components_flipped == 1
    np.testing.assert_array_equal(_cyclic(report.faces), _cyclic(F))


def test_validate_mesh_open_patch_keeps_majority_orientation():
    V, F = procedural.saddle_patch(0.1, 1.0, 9)
    F2 = F.copy()
    F2[:5] = F2[:5][:, [0, 2, 1]]
    report = _quiet_validate(V, F2)
    np.testing.assert_array_equal(report.faces, F)  # the 5 odd faces flipped back, not the other 123
    assert report.n_faces_rewound == 5 and report.n_components_flipped == 0


def test_validate_mesh_cavity_points_into_the_hole():
    Vo, Fo = procedural.icosphere(10.0, 2)
    Vi, Fi = procedural.icosphere(5.0, 2)
    V = np.vstack([Vo, Vi])
    # hollow ball: the inner wall must face the cavity (negative signed volume); give it outward winding
    report = _quiet_validate(V, np.vstack([Fo, Fi + len(Vo)]))
    assert report.n_components_flipped == 1
    np.testing.assert_array_equal(report.faces[: len(Fo)], Fo)
    np.testing.assert_array_equal(_cyclic(report.faces[len(Fo):]), _cyclic(Fi[:, ::-1] + len(Vo)))
    # already correct: nothing to do
    report = _quiet_validate(V, np.vstack([Fo, Fi[:, ::-1] + len(Vo)]))
    assert report.n_components_flipped == 0


def test_validate_mesh_separate_components_oriented_independently():
    Va, Fa = procedural.icosphere(10.0, 2)
    Vb, Fb = procedural.torus(8.0, 2.0, 24, 12)
    V = np.vstack([Va, Vb + [40.0, 0.0, 0.0]])
    report = _quiet_validate(V, np.vstack([Fa, Fb[:, ::-1] + len(Va)]))
    assert report.n_components_flipped == 1
    np.testing.assert_array_equal(_cyclic(report.faces), _cyclic(np.vstack([Fa, Fb + len(Va)])))


def test_validate_mesh_reports_non_orientable_surface():
    n = 24
    u = 2 * np.pi * np.arange(n) / n
    radial = np.stack([np.cos(u), np.sin(u), 0 * u], 1)
    offset = np.cos(u / 2)[:, None] * radial + np.sin(u / 2)[:, None] * [0, 0, 1]
    V = np.vstack([5 * radial - offset, 5 * radial + offset])  # rails a_i = i, b_i = n + i
    quads = [(i, i + 1, n + i + 1, n + i) for i in range(n - 1)] + [(n - 1, n, 0, 2 * n - 1)]
    F = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    report = _quiet_validate(V, F)
    assert report.n_winding_conflicts > 0
    assert any(w.startswith("non-orientable surface") for w in report.warnings)


# ------------------------------------------------------------------------------------------ Mesh arrays

def test_mesh_derived_arrays_on_sphere():
    V, F = procedural.icosphere(10.0, 4)
    mesh = Mesh(V, F)
    assert mesh.total_area == pytest.approx(4 * np.pi * 100, rel=0.01)
    assert mesh.vertex_areas.sum() == pytest.approx(mesh.total_area, rel=1e-12)
    np.testing.assert_allclose(np.linalg.norm(mesh.face_normals, axis=1), 1.0)
    np.testing.assert_allclose(mesh.vertex_normals, V / 10.0, atol=1e-2)
    np.testing.assert_allclose(mesh.bbox_size_mm, 20.0)
    assert mesh.scale == pytest.approx(20.0 * np.sqrt(3))
    edges = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    assert mesh.mean_edge_length == pytest.approx(np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1).mean())


def test_mesh_is_frozen_and_read_only(sphere):
    mesh = Mesh(*sphere)
    with pytest.raises(dataclasses.FrozenInstanceError):
        mesh.vertices = np.zeros((3, 3))
    for arr in (mesh.vertices, mesh.faces, mesh.face_normals, mesh.vertex_normals, mesh.vertex_areas):
        assert not arr.flags.writeable
    assert mesh.face_areas is mesh.face_areas  # cached
    assert "162 vertices" in repr(mesh) and "mm" in repr(mesh)


def test_mesh_from_arrays_converts_units_once(sphere):
    V, F = sphere
    mesh = Mesh.from_arrays(V, F, units="cm", source="gen")
    np.testing.assert_array_equal(mesh.vertices, V * 10.0)
    assert mesh.mm_per_unit == 10.0 and mesh.source == "gen"
    np.testing.assert_allclose(mesh.bbox_size_mm, 200.0)
    np.testing.assert_allclose(mesh.vertices_in_source_units(), V)


def test_mesh_rejects_bad_mm_per_unit(sphere):
    with pytest.raises(MeshValidationError, match="mm_per_unit"):
        Mesh(*sphere, mm_per_unit=0.0)


def test_mesh_unreferenced_vertex_has_zero_normal_and_area(sphere):
    V, F = sphere
    with pytest.warns(MeshDefectWarning):
        mesh = Mesh(np.vstack([V, [[1e3, 0, 0]]]), F)
    assert mesh.vertex_areas[-1] == 0.0 and np.all(mesh.vertex_normals[-1] == 0.0)
    assert not mesh.referenced_vertex_mask[-1]
    np.testing.assert_allclose(mesh.bbox_size_mm, 20.0)  # the stray vertex does not inflate the scale


# ------------------------------------------------------------------------------------------- face_normals

def test_face_normals_against_a_per_face_loop():
    V = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 1.5], [1.0, 1.0, 1.0]])
    F = np.array([[0, 1, 2], [0, 3, 1], [1, 2, 4], [0, 0, 4]])  # the last one has a repeated index
    cross = []
    for a, b, c in F:  # independent route: explicit cross product per face
        u, w = V[b] - V[a], V[c] - V[a]
        cross.append([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]])
    cross = np.array(cross)
    np.testing.assert_allclose(face_normals(V, F, unit=False), cross, rtol=1e-15, atol=0)
    np.testing.assert_allclose(face_normals(V, F, unit=False)[:2], [[0, 0, 6.0], [0, 3.0, 0]])
    unit = face_normals(V, F)
    np.testing.assert_allclose(unit[:3], cross[:3] / np.linalg.norm(cross[:3], axis=1, keepdims=True), rtol=1e-15)
    np.testing.assert_array_equal(unit[3], 0.0)  # zero cross product: zero normal, no NaN
    # half the norm of the area-weighted normal is the face area
    np.testing.assert_allclose(0.5 * np.linalg.norm(face_normals(V, F, unit=False)[0]), 3.0)


def test_face_normals_agree_with_the_mesh_container(sphere):
    V, F = sphere
    mesh = Mesh(V, F)
    np.testing.assert_array_equal(face_normals(V, mesh.faces), mesh.face_normals)
    np.testing.assert_array_equal(0.5 * np.linalg.norm(face_normals(V, mesh.faces, unit=False), axis=1),
                                  mesh.face_areas)
    # outward on a sphere centred at the origin
    assert np.all(np.einsum("ij,ij->i", face_normals(V, mesh.faces), V[mesh.faces].mean(axis=1)) > 0)


# ------------------------------------------------------------------------------------- non-manifold vertices

def _mirrored_through_vertex(V, F, k):
    n = len(V)
    others = np.flatnonzero(np.arange(n) != k)
    index = np.full(n, k)
    index[others] = n + np.arange(n - 1)
    return np.vstack([V, 2 * V[k] - V[others]]), np.vstack([F, index[F][:, [0, 2, 1]]])


def test_nonmanifold_vertex_two_solids_touching_at_a_point(sphere):
    from meshshade.geometry.mesh import nonmanifold_vertices

    V, F = _mirrored_through_vertex(*sphere, 5)
    assert np.flatnonzero(nonmanifold_vertices(len(V), F)).tolist() == [5]
    with pytest.warns(MeshDefectWarning, match="1 vertices join fans of faces that meet only at the vertex"):
        report = validate_mesh(V, F)
    assert report.n_nonmanifold_vertices == 1 and report.n_nonmanifold_edges == 0 and report.is_closed


def test_nonmanifold_vertices_not_reported_for_manifold_cases(sphere):
    from meshshade.geometry.mesh import nonmanifold_vertices

    V, F = sphere
    upper = V[F].mean(axis=1)[:, 2] > 0
    fins = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])  # a non-manifold edge is not a bow-tie
    degenerate = np.vstack([F, [[F[0, 0], F[0, 0], F[0, 1]]]])
    for n, faces in ((len(V), F), (len(V), F[upper]), (len(V) + 1, fins), (len(V), degenerate)):
        assert not nonmanifold_vertices(n, faces).any()
    assert _quiet_validate(V, F).n_nonmanifold_vertices == 0


@pytest.mark.parametrize("model", ["dipole", "curved"])
def test_bake_with_an_unreferenced_vertex_raises_no_numpy_warning(sphere, model):
    """An OBJ with one stray vertex: the bake says so once (MeshDefectWarning) and no raw numpy warning
    ("invalid value encountered in divide" reached users from the surface models' source frames) follows; the
    stray vertex gets 0."""
    from meshshade.light import DirectionalLight
    from meshshade.materials import Material
    from meshshade.transport import bake

    V, F = sphere
    with pytest.warns(MeshDefectWarning):
        mesh = Mesh(np.vstack([V, [[1e3, 0, 0]]]), F)
    with warnings.catch_warnings(), np.errstate(invalid="raise", divide="raise"):
        warnings.simplefilter("error", RuntimeWarning)
        res = bake(mesh, Material.preset("skin1"), [DirectionalLight((0.0, 0.0, -1.0))], BakeOptions(model=model))
    assert np.all(np.isfinite(res.radiance)) and np.all(res.radiance[-1] == 0.0)
