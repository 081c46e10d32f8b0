"""The bake's glTF/GLB and USD files, read back by other readers: trimesh (glTF), a small independent GLB/JSON
decoder here (COLOR_0, the material), and OpenUSD's own ``pxr`` (USD)."""
from __future__ import annotations

import base64
import json
import struct
import sys

import numpy as np
import pytest
import trimesh

from meshshade import Material
from meshshade.cli.main import main
from meshshade.geometry.procedural import icosphere
from meshshade.io import load_mesh, read_baked_ply, write_ply
from meshshade.light import DirectionalLight
from meshshade.output.bake_file import write_bake
from meshshade.output.tonemap import srgb_encode
from meshshade.transport import BakeOptions, SurfaceOptions, bake

pxr = pytest.importorskip("pxr", reason="usd-core is in the test extra")
from pxr import Usd, UsdGeom  # noqa: E402

LIGHTS = [DirectionalLight((0.3, -0.4, -1.0), 1.0)]


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    d = tmp_path_factory.mktemp("formats")
    V, F = icosphere(2.0, 2)                       # 2 cm radius, written in cm
    rng = np.random.default_rng(4)
    F = F[rng.permutation(len(F))]                 # a face order no reader may "fix"
    write_ply(d / "ball_cm.ply", V, F)
    mesh = load_mesh(d / "ball_cm.ply", units="cm")
    result = bake(mesh, Material.preset("marble"), LIGHTS, BakeOptions(
        model="dipole", surface=SurfaceOptions(transport="direct")))
    return d, mesh, result


def _glb_json_and_bin(data: bytes):
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and total == len(data)
    n_json, kind = struct.unpack_from("<I4s", data, 12)
    assert kind == b"JSON" and n_json % 4 == 0
    doc = json.loads(data[20:20 + n_json])
    n_bin, kind = struct.unpack_from("<I4s", data, 20 + n_json)
    assert kind == b"BIN\0"
    return doc, data[28 + n_json:28 + n_json + n_bin]


def _accessor(doc, blob, index):
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {5126: "<f4", 5125: "<u4"}[acc["componentType"]]
    width = {"VEC3": 3, "SCALAR": 1}[acc["type"]]
    a = np.frombuffer(blob, dtype=dtype, count=acc["count"] * width, offset=view["byteOffset"])
    return a.reshape(acc["count"], width) if width > 1 else a


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_keeps_vertex_order_metres_colour_and_radiance(baked, suffix):
    d, mesh, result = baked
    out = d / f"ball{suffix}"
    write_bake(result, mesh, out, lights=LIGHTS)
    scene = trimesh.load(out, process=False)
    g = next(iter(scene.geometry.values()))
    np.testing.assert_allclose(g.vertices * 1e3, mesh.vertices, rtol=1e-6, atol=1e-5)   # metres, same order
    np.testing.assert_array_equal(g.faces, mesh.faces)
    np.testing.assert_array_equal(g.vertex_attributes["_RADIANCE"], result.radiance.astype(np.float32))
    if suffix == ".glb":
        doc, blob = _glb_json_and_bin(out.read_bytes())
    else:
        doc = json.loads(out.read_text())
        uri = doc["buffers"][0]["uri"]
        assert uri.startswith("data:application/octet-stream;base64,")
        blob = base64.b64decode(uri.split(",", 1)[1])
    prim = doc["meshes"][0]["primitives"][0]
    colour = _accessor(doc, blob, prim["attributes"]["COLOR_0"])
    # COLOR_0 is linear; encoded to sRGB by a viewer it shows the PLY's tone-mapped colours
    write_bake(result, mesh, d / "ball.ply")
    _m, _r, info = read_baked_ply(d / "ball.ply")
    ply_rgb = trimesh.load(d / "ball.ply", process=False).visual.vertex_colors[:, :3]
    np.testing.assert_array_equal(np.round(srgb_encode(colour) * 255), ply_rgb)
    assert doc["materials"][0]["extensions"] == {"KHR_materials_unlit": {}}
    assert "KHR_materials_unlit" in doc["extensionsUsed"]
    extras = doc["asset"]["extras"]
    assert extras["model"] == "dipole" and extras["material"].startswith("marble")
    assert "directional light 0" in extras["lights"]
    acc = doc["accessors"][prim["attributes"]["POSITION"]]
    np.testing.assert_allclose(acc["min"], mesh.vertices.min(axis=0) * 1e-3, rtol=1e-6)


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd"])
def test_usd_mesh_primvars_units_and_metadata(baked, suffix):
    d, mesh, result = baked
    out = d / f"ball{suffix}"
    write_bake(result, mesh, out, lights=LIGHTS)
    if suffix == ".usda":
        assert out.read_text().startswith("#usda 1.0")
    else:
        assert out.read_bytes()[:8] == b"PXR-USDC"
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)     # the file was in cm
    prim = stage.GetDefaultPrim()
    geom = UsdGeom.Mesh(prim)
    np.testing.assert_allclose(np.array(geom.GetPointsAttr().Get()), mesh.vertices / 10.0, rtol=1e-6, atol=1e-6)
    assert set(geom.GetFaceVertexCountsAttr().Get()) == {3}
    np.testing.assert_array_equal(np.array(geom.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3), mesh.faces)
    api = UsdGeom.PrimvarsAPI(prim)
    rad = api.GetPrimvar("meshshade:radiance")
    assert rad.GetInterpolation() == UsdGeom.Tokens.vertex
    np.testing.assert_array_equal(np.array(rad.Get()), result.radiance.astype(np.float32))
    colour = api.GetPrimvar("displayColor")
    assert colour.GetInterpolation() == UsdGeom.Tokens.vertex and len(colour.Get()) == mesh.n_vertices
    data = prim.GetCustomData()["meshshade"]
    assert data["model"] == "dipole" and data["material"].startswith("marble") and "directional" in data["lights"]


def test_bake_command_writes_each_format_and_refuses_others(baked, tmp_path, capsys):
    d, _mesh, _result = baked
    base = ["bake", str(d / "ball_cm.ply"), "--units", "cm", "--material", "marble", "--light",
            "directional:0.3,-0.4,-1", "--model", "dipole", "--quiet"]
    for name in ("a.glb", "a.gltf", "a.usda", "a.usdc"):
        assert main([*base, "--out", str(tmp_path / name)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.glb", "a.gltf", "a.usda", "a.usdc"]
    capsys.readouterr()
    assert main([*base, "--out", str(tmp_path / "a.obj")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ".glb" in err and ".usd" in err


def test_usd_without_usd_core_is_one_line_before_any_work(baked, tmp_path, capsys, monkeypatch):
    d, _mesh, _result = baked
    monkeypatch.setitem(sys.modules, "pxr", None)     # as if usd-core were not installed
    rc = main(["bake", str(d / "ball_cm.ply"), "--units", "cm", "--material", "marble", "--light",
               "directional:0,0,-1", "--out", str(tmp_path / "a.usd")])
    err = capsys.readouterr().err
    assert rc == 2 and err.strip() == ("meshshade: error: USD output needs the usd-core package: pip install "
                                       "usd-core (or pip install 'meshshade[usd]')")
    assert list(tmp_path.iterdir()) == []
