"""Procedural generators: closed, outward, deterministic, exact where stated."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry import procedural
from meshshade.geometry.mesh import validate_mesh
from meshshade.geometry.topology import signed_volumes
from meshshade.io import load_mesh

CLOSED = {
    "icosphere": (lambda: procedural.icosphere(2.0, 3), 4 / 3 * np.pi * 8),
    "uv_sphere": (lambda: procedural.uv_sphere(2.0, 24, 48), 4 / 3 * np.pi * 8),
    "capped_cylinder": (lambda: procedural.capped_cylinder(1.0, 5.0, 64, 10), np.pi * 5.0),
    "torus": (lambda: procedural.torus(3.0, 1.0, 96, 48), 2 * np.pi**2 * 3.0),
    "box": (lambda: procedural.box((1.0, 2.0, 3.0), 3), 6.0),
    "pebble": (lambda: procedural.pebble(subdivisions=3), None),
    "apple": (lambda: procedural.apple(subdivisions=3), None),
}


@pytest.mark.parametrize("name", CLOSED)
def test_procedural_closed_outward_clean_deterministic(name):
    make, volume = CLOSED[name]
    V, F = make()
    assert V.dtype == np.float64 and F.dtype == np.int64
    report = validate_mesh(V, F)
    assert report.is_clean and report.is_closed and report.n_components == 1
    vol = signed_volumes(V, F, np.zeros(len(F), np.int64), 1)[0]
    assert vol > 0
    if volume is not None:
        assert vol == pytest.approx(volume, rel=0.02)
    V2, F2 = make()
    assert np.array_equal(V, V2) and np.array_equal(F, F2)


@pytest.mark.parametrize("s", range(5))
def test_icosphere_counts_and_exact_radius(s):
    V, F = procedural.icosphere(7.5, s)
    assert V.shape == (10 * 4**s + 2, 3) and F.shape == (20 * 4**s, 3)
    np.testing.assert_allclose(np.linalg.norm(V, axis=1), 7.5, rtol=1e-15)


def test_box_shares_vertices_across_sides():
    V, F = procedural.box(2.0, 4)
    assert V.shape[0] == 6 * 16 + 2
    assert np.unique(V, axis=0).shape[0] == V.shape[0]
    np.testing.assert_allclose(np.abs(V).max(axis=0), 1.0)


def test_saddle_patch_height_and_upward_normals():
    V, F = procedural.saddle_patch(0.2, 1.5, 11)
    np.testing.assert_allclose(V[:, 2], 0.1 * (V[:, 0] ** 2 - V[:, 1] ** 2))
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert np.all(n[:, 2] > 0)
    assert validate_mesh(V, F, emit_warnings=False).n_boundary_edges == 4 * 10


@pytest.mark.parametrize("call", [
    lambda: procedural.icosphere(-1.0, 2),
    lambda: procedural.icosphere(1.0, 1.5),
    lambda: procedural.torus(1.0, 2.0),
    lambda: procedural.box(0.0),
    lambda: procedural.capped_cylinder(1.0, 1.0, 2),
    lambda: procedural.saddle_patch(np.nan),
])
def test_procedural_rejects_bad_parameters(call):
    with pytest.raises(ValueError):
        call()


def test_assets_match_their_generators():
    """assets/*.ply are what tools/tables/make_assets.py says (float32 positions in mm, same faces), and clean."""
    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("make_assets", root / "tools" / "tables" / "make_assets.py")
    make_assets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_assets)
    for name in make_assets.ASSETS:
        path = root / "assets" / name
        assert path.stat().st_size < 2 * 1024**2
        mesh = load_mesh(path)
        V, F = make_assets.build(name)
        assert mesh.defects.is_clean and mesh.mm_per_unit == 1.0
        np.testing.assert_array_equal(mesh.faces, F)
        np.testing.assert_array_equal(mesh.vertices, V.astype(np.float32).astype(np.float64))
        assert name in (root / "assets" / "README.md").read_text()
