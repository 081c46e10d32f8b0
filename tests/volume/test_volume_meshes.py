"""The volume transport on meshes of several parts (issue 41): vertices buried inside another part report 0 and
are counted, the exposed surface is baked as the union's, the bake and ``meshshade check`` say so in one line.

The geometric truth is written here: a vertex of the small ball is buried when it lies inside the big ball
(|x - c| < R), which the winding-number rule must reproduce away from the intersection curve.
"""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.check import check_mesh, format_check
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport.baking import bake, mesh_note

SKIN = Material.preset("skin1")
SUN = [DirectionalLight((0.3, -0.4, -0.866), 1.0)]
R = 12.0


def two_balls(centre, r, level=2):
    V1, F1 = icosphere(R, 3)
    V2, F2 = icosphere(r, level)
    V = np.vstack([V1, V2 + np.asarray(centre)])
    F = np.vstack([F1, F2 + V1.shape[0]])
    return Mesh.from_arrays(V, F), V1.shape[0]


@pytest.fixture(scope="module")
def lone():
    mesh = Mesh.from_arrays(*icosphere(R, 3))
    return mesh, bake(mesh, SKIN, SUN)


def test_a_closed_part_nested_inside_another_is_a_cavity(lone):
    """A ball wholly inside a ball is oriented inward by the mesh's validation (hollow objects: a closed part
    nested inside another is a cavity, meshshade.geometry.mesh), so the winding number is 0 inside it: its
    vertices are not buried, they read the light that reaches the cavity's wall."""
    mesh, n_big = two_balls((1.0, -2.0, 0.5), 4.0)
    assert mesh.defects.n_components_flipped == 1
    res = bake(mesh, SKIN, SUN)
    assert res.model == "volume" and res.stats["volume_buried_vertices"] == 0
    assert np.all(np.isfinite(res.radiance)) and np.all(res.radiance[n_big:, 0] > 0.0)
    assert mesh_note(lone[1]) is None


def test_a_ball_overlapping_the_surface_is_buried_where_it_is_inside():
    centre = np.array([0.0, 0.0, R])
    mesh, n_big = two_balls(centre, 4.0, level=3)
    res = bake(mesh, SKIN, SUN)
    small = mesh.vertices[n_big:]
    inside = np.linalg.norm(small, axis=1) < R
    clear = np.abs(np.linalg.norm(small, axis=1) - R) > 0.3        # away from the intersection curve
    buried = res.radiance[n_big:, 0] == 0.0
    assert np.array_equal(buried[clear], inside[clear])
    assert res.stats["volume_buried_vertices"] == int((res.radiance[:, 0] == 0.0).sum())
    note = mesh_note(res)
    assert note.startswith("volume transport on a closed mesh: 2 parts baked as their union")
    assert f"{res.stats['volume_buried_vertices']} vertices buried" in note
    # not buried: lit (red, the channel ``buried`` reads; a vertex is the field at its point, whose blue is
    # clamped to 0 at three vertices 0.33 mm from the intersection curve: issue 47)
    assert np.all(res.radiance[n_big:][~inside & clear, 0] > 0.0)
    # the big ball's vertices inside the small one are buried too (the union's inside)
    big = mesh.vertices[:n_big]
    big_inside = np.linalg.norm(big - centre, axis=1) < 4.0 - 0.3
    assert np.all(res.radiance[:n_big][big_inside] == 0.0)


def test_check_reports_what_the_bake_will_do():
    mesh, n_big = two_balls((0.0, 0.0, R), 4.0, level=3)
    report = check_mesh(mesh, SKIN)
    v = report["volume"]
    res = bake(mesh, SKIN, SUN)
    assert (v["transport"], v["closed"], v["parts"], v["buried_vertices"]) == (
        "volume", True, 2, res.stats["volume_buried_vertices"])
    assert v["sampling_vertices"] >= mesh.n_vertices
    text = format_check(report)
    assert "default bake: volume transport, closed, 2 parts baked as their union" in text
    flat = Mesh.from_arrays(np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0], [10, 10, 0]]),
                            np.array([[0, 1, 2], [1, 3, 2]]))
    assert check_mesh(flat)["volume"]["transport"].startswith("surface")
    res = bake(flat, SKIN, [DirectionalLight((0.0, 0.0, -1.0), 1.0)])
    assert res.model != "volume" or res.stats.get("transport") != "volume"
    assert mesh_note(res).startswith("surface transport: the volume transport cannot be built (the mesh is flat")


def test_a_curved_double_sided_sheet_falls_back_when_its_lattice_is_empty():
    """A spherical cap with every face duplicated with the opposite winding encloses nothing (winding number 0
    everywhere), which only the lattice finds: the bake falls back to the surface transport and says why, as for
    a flat sheet (before: a one-line error)."""
    V, F = icosphere(20.0, 3)
    cap = F[V[F].mean(axis=1)[:, 2] > 10.0]
    with pytest.warns(Warning):
        mesh = Mesh.from_arrays(V, np.vstack([cap, cap[:, ::-1]]))
    res = bake(mesh, SKIN, [DirectionalLight((0.0, 0.0, -1.0), 1.0)])
    assert res.model == "auto"
    assert "winding number below 1/2 everywhere" in mesh_note(res)
