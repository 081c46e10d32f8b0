"""meshshade.io: loading every format without reordering, unit conversion, one-line errors, atomic outputs, PLY."""
from __future__ import annotations

import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from meshshade.errors import MeshValidationError, OutputError, UnitsError
from meshshade.geometry import procedural
from meshshade.geometry.mesh import MeshDefectWarning
from meshshade.io import (atomic_write, check_output_path, load_mesh, read_mesh_arrays, write_figure, write_mesh_ply,
                          write_npz, write_ply, write_text)


@pytest.fixture(scope="module")
def shape():
    """A torus: vertex order matters (no format may re-sort it), not symmetric under the usual sorts."""
    V, F = procedural.torus(3.0, 1.0, 16, 8)
    return V + [0.25, -0.5, 1.0], F


def _export(tmp_path, shape, ext):
    V, F = shape
    path = tmp_path / f"shape.{ext}"
    trimesh.Trimesh(V, F, process=False).export(path)
    return path


def _one_line_error(path, match, **kwargs):
    with pytest.raises(MeshValidationError, match=match) as info:
        load_mesh(path, **kwargs)
    message = str(info.value)
    assert "\n" not in message and "Traceback" not in message
    return message


# ------------------------------------------------------------------------------------------- round trips

@pytest.mark.parametrize("ext, atol", [("obj", 1e-7), ("ply", 1e-6), ("off", 1e-7), ("glb", 1e-6)])
def test_load_mesh_round_trip_keeps_vertex_and_face_order(tmp_path, shape, ext, atol):
    V, F = shape
    path = _export(tmp_path, shape, ext)
    units = "m" if ext == "glb" else "mm"
    mesh = load_mesh(path, units=units)
    scale = 1000.0 if ext == "glb" else 1.0
    np.testing.assert_allclose(mesh.vertices / scale, V, atol=atol)
    np.testing.assert_array_equal(mesh.faces, F)
    assert mesh.defects.is_clean and mesh.source == str(path)


def test_load_mesh_stl_merges_exact_duplicates_in_first_appearance_order(tmp_path, shape):
    V, F = shape
    path = _export(tmp_path, shape, "stl")
    mesh = load_mesh(path)
    assert mesh.n_vertices == len(V) and mesh.n_faces == len(F)
    assert mesh.defects.is_clean  # closed, one component after merging
    corners = V[F].reshape(-1, 3).astype(np.float32).astype(np.float64)  # STL stores float32 corners
    _, first = np.unique(corners, axis=0, return_index=True)
    np.testing.assert_array_equal(mesh.vertices, corners[np.sort(first)])
    np.testing.assert_array_equal(mesh.vertices[mesh.faces].reshape(-1, 3), corners)


@pytest.mark.parametrize("units, factor", [("mm", 1.0), ("cm", 10.0), ("m", 1000.0), ("in", 25.4), (" CM ", 10.0)])
def test_load_mesh_converts_units_once(tmp_path, shape, units, factor):
    path = _export(tmp_path, shape, "obj")
    mesh = load_mesh(path, units=units)
    np.testing.assert_allclose(mesh.vertices, shape[0] * factor, rtol=1e-7)
    assert mesh.mm_per_unit == factor
    np.testing.assert_allclose(mesh.bbox_size_mm, np.ptp(shape[0], axis=0) * factor, rtol=1e-7)


def test_load_mesh_unknown_unit(tmp_path, shape):
    with pytest.raises(UnitsError, match="furlong"):
        load_mesh(_export(tmp_path, shape, "obj"), units="furlong")


def test_load_mesh_glb_warns_when_units_are_not_metres(tmp_path, shape):
    path = _export(tmp_path, shape, "glb")
    with pytest.warns(UserWarning, match="metres by specification"):
        mesh = load_mesh(path)  # the caller's unit is still used, not guessed
    np.testing.assert_allclose(mesh.vertices, shape[0], atol=1e-6)


def test_load_mesh_glb_scene_concatenates_nodes_in_order(tmp_path):
    Va, Fa = procedural.icosphere(1.0, 1)
    Vb, Fb = procedural.box(1.0, 2)
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.Trimesh(Va, Fa, process=False), node_name="a", geom_name="a")
    shift = np.eye(4)
    shift[:3, 3] = [5.0, 0.0, 0.0]
    scene.add_geometry(trimesh.Trimesh(Vb, Fb, process=False), node_name="b", geom_name="b", transform=shift)
    path = tmp_path / "scene.glb"
    scene.export(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)  # two components
        mesh = load_mesh(path, units="m")
    np.testing.assert_allclose(mesh.vertices / 1000.0, np.vstack([Va, Vb + [5.0, 0.0, 0.0]]), atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, np.vstack([Fa, Fb + len(Va)]))
    assert mesh.defects.n_components == 2


def test_load_mesh_obj_features(tmp_path):
    path = tmp_path / "features.obj"
    path.write_text(
        "# comment line\nmtllib none.mtl\no first\n"
        "v 0 0 0\nv 1 0 0   # trailing comment\nv 1 1 0\nv 0 1 0\nv 9 9 9 1.0\n"
        "vt 0 0\nvn 0 0 1\nusemtl red\n"
        "f 1/1/1 2/1/1 3/1/1\n"
        "o second\nv 0 0 1\nusemtl blue\n"
        "f -6//1 -3//1 -2//1\n"  # relative indices: 1, 4, 5 counted from the 6 vertices read so far
        "f 1 2 3 4\n"  # a quad: fan-triangulated
        "f 1 \\\n 3 6\n"  # line continuation
    )
    with pytest.warns(MeshDefectWarning, match="1 polygons with more than 3 corners"):
        V, F = read_mesh_arrays(path)
    np.testing.assert_array_equal(V, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [9, 9, 9], [0, 0, 1]])
    np.testing.assert_array_equal(F, [[0, 1, 2], [0, 3, 4], [0, 1, 2], [0, 2, 3], [0, 2, 5]])


def test_load_mesh_obj_fast_and_line_readers_agree(tmp_path, shape):
    from meshshade.io.meshes import _read_obj, _read_obj_lines

    path = _export(tmp_path, shape, "obj")
    for a, b in zip(_read_obj(path), _read_obj_lines(path)):
        np.testing.assert_array_equal(a, b)


def test_load_mesh_shared_meshes_keep_file_order(shared_meshes):
    for name in ("spot.obj", "bunny.ply"):
        path = shared_meshes / name
        raw = trimesh.load(path, process=False, maintain_order=True)
        mesh = load_mesh(path)
        np.testing.assert_array_equal(mesh.vertices, raw.vertices)
        np.testing.assert_array_equal(mesh.faces, raw.faces)
        assert mesh.defects.is_clean


# ------------------------------------------------------------------------------------------------ errors

def test_load_mesh_missing_file(tmp_path):
    _one_line_error(tmp_path / "nope.obj", "mesh file not found: .*nope.obj")


def test_load_mesh_directory(tmp_path):
    _one_line_error(tmp_path, "is a directory, not a mesh file")


@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "glb"])
def test_load_mesh_empty_file(tmp_path, ext):
    path = tmp_path / f"empty.{ext}"
    path.touch()
    _one_line_error(path, f"mesh file is empty: .*empty.{ext}")


@pytest.mark.parametrize("name", ["mesh.xyz", "mesh", "mesh.3ds"])
def test_load_mesh_unsupported_extension(tmp_path, name):
    path = tmp_path / name
    path.write_text("v 0 0 0\n")
    _one_line_error(path, "unsupported mesh format .* supported: .obj, .ply")


@pytest.mark.parametrize("ext", ["ply", "stl", "glb", "off"])
def test_load_mesh_garbage(tmp_path, ext, rng):
    path = tmp_path / f"garbage.{ext}"
    path.write_bytes(rng.integers(0, 256, 700, dtype=np.uint8).tobytes())
    message = _one_line_error(path, "garbage")
    assert str(path) in message


@pytest.mark.parametrize("ext", ["ply", "stl", "glb"])
def test_load_mesh_truncated(tmp_path, shape, ext):
    path = _export(tmp_path, shape, ext)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    _one_line_error(path, str(path.name), units="m")


def test_load_mesh_text_without_mesh_records(tmp_path):
    path = tmp_path / "notes.obj"
    path.write_text("hello\nthis is not a mesh\n")
    _one_line_error(path, "no OBJ vertex or face records in .*notes.obj")


def test_load_mesh_obj_errors_name_the_line(tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n")
    _one_line_error(path, r"bad.obj:3: malformed vertex line")
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    _one_line_error(path, r"bad.obj:4: face index 0")
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n")
    _one_line_error(path, r"bad.obj:4: face with 2 corners")


def test_load_mesh_validation_errors_name_the_file(tmp_path):
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    _one_line_error(path, r"points.obj: mesh has no faces")
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    _one_line_error(path, r"points.obj: face index 6 out of range for 3 vertices")
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n")
    _one_line_error(path, r"points.obj: 1 vertices have NaN or Inf")


# ---------------------------------------------------------------------------------------- atomic output

def test_atomic_write_replaces_on_success(tmp_path):
    out = tmp_path / "out.bin"
    out.write_bytes(b"old")
    with atomic_write(out) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".bin" and tmp.exists()
        tmp.write_bytes(b"new")
        assert out.read_bytes() == b"old"  # nothing visible until the block succeeds
    assert out.read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_atomic_write_leaves_nothing_on_exception(tmp_path, exc):
    out = tmp_path / "out.ply"
    with pytest.raises(exc):
        with atomic_write(out) as tmp:
            tmp.write_bytes(b"partial")
            raise exc()
    assert list(tmp_path.iterdir()) == []


def test_atomic_write_keeps_existing_file_on_exception(tmp_path):
    out = tmp_path / "out.ply"
    out.write_bytes(b"previous result")
    with pytest.raises(ValueError):
        with atomic_write(out):
            raise ValueError("boom")
    assert out.read_bytes() == b"previous result"
    assert [p.name for p in tmp_path.iterdir()] == ["out.ply"]


def test_write_ply_interrupted_leaves_no_file(tmp_path, shape, monkeypatch):
    out = tmp_path / "out.ply"
    real_open = open

    class Interrupting:
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, data):
            self.fh.write(data[:10])
            raise KeyboardInterrupt  # Ctrl-C in the middle of the body

    monkeypatch.setattr("meshshade.io.ply.open", lambda *a, **k: Interrupting(real_open(*a, **k)), raising=False)
    with pytest.raises(KeyboardInterrupt):
        write_ply(out, *shape)
    assert list(tmp_path.iterdir()) == []


def test_check_output_path_refuses_inputs(tmp_path, shape):
    src = _export(tmp_path, shape, "ply")
    for out in (src, tmp_path / "." / "shape.ply", tmp_path / "sub" / ".." / "shape.ply"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(OutputError, match="same file as input"):
            check_output_path(out, [src])
    link = tmp_path / "link.ply"
    link.symlink_to(src)
    with pytest.raises(OutputError, match="same file as input"):
        check_output_path(link, [src])
    hard = tmp_path / "hard.ply"
    os.link(src, hard)
    with pytest.raises(OutputError, match="same file as input"):
        check_output_path(hard, [src])
    assert check_output_path(tmp_path / "result.ply", [src]) == tmp_path / "result.ply"


def test_check_output_path_directory_problems(tmp_path):
    with pytest.raises(OutputError, match="output directory does not exist: .*missing"):
        check_output_path(tmp_path / "missing" / "out.ply")
    with pytest.raises(OutputError, match="is a directory"):
        check_output_path(tmp_path)
    with pytest.raises(OutputError, match="output directory does not exist"):
        write_npz(tmp_path / "missing" / "out.npz", a=np.zeros(3))


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root can write anywhere")
def test_check_output_path_unwritable_directory(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="not writable: .*locked"):
            write_ply(locked / "out.ply", np.eye(3), [[0, 1, 2]])
    finally:
        locked.chmod(0o700)


def test_check_output_path_unwritable_directory_reported(tmp_path, monkeypatch):
    monkeypatch.setattr("meshshade.io.transactions.os.access", lambda path, mode: False)  # also runs as root
    with pytest.raises(OutputError, match="output directory is not writable: "):
        write_ply(tmp_path / "out.ply", np.eye(3), [[0, 1, 2]])


def test_write_npz_round_trip(tmp_path):
    out = write_npz(tmp_path / "arrays.npz", k1=np.arange(5.0), faces=np.ones((2, 3), np.int64))
    with np.load(out) as data:
        np.testing.assert_array_equal(data["k1"], np.arange(5.0))
        assert data["faces"].dtype == np.int64
    assert sorted(p.name for p in tmp_path.iterdir()) == ["arrays.npz"]


def test_write_text_atomic(tmp_path):
    out = write_text(tmp_path / "table.csv", "a,b\n1,2\n")
    assert out.read_text() == "a,b\n1,2\n"
    with pytest.raises(OutputError, match="output directory does not exist"):
        write_text(tmp_path / "no" / "t.csv", "x")


def test_write_figure_by_extension(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    out = write_figure(tmp_path / "plot.png", fig)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)  # closed
    fig, _ = plt.subplots()
    with pytest.raises(OutputError, match="unsupported figure format '.xyz'"):
        write_figure(tmp_path / "plot.xyz", fig)
    plt.close(fig)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plot.png"]


# ------------------------------------------------------------------------------------------------- PLY

def _parse_ply(path: Path):
    """A tiny independent reader for the binary little-endian PLY that write_ply produces."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert header[:2] == ["ply", "format binary_little_endian 1.0"]
    comments = [line[8:] for line in header if line.startswith("comment ")]
    types = {"float": "<f4", "uchar": "u1", "int": "<i4"}
    props, counts, element = {"vertex": [], "face": []}, {}, None
    for line in header:
        words = line.split()
        if words[0] == "element":
            element, counts[words[1]] = words[1], int(words[2])
        elif words[0] == "property" and words[1] != "list":
            props[element].append((words[2], types[words[1]]))
    vdt = np.dtype(props["vertex"])
    vert = np.frombuffer(data, vdt, counts["vertex"], end)
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    face = np.frombuffer(data, fdt, counts["face"], end + vdt.itemsize * counts["vertex"])
    assert np.all(face["n"] == 3) and end + vdt.itemsize * counts["vertex"] + fdt.itemsize * counts["face"] == len(data)
    return vert, face["i"], comments


def test_write_ply_custom_props_and_colors_round_trip(tmp_path, shape, rng):
    V, F = shape
    n = len(V)
    props = {"radiance_r": rng.random(n), "k1": rng.normal(size=n), "fallback": np.zeros(n)}
    colors = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    out = write_ply(tmp_path / "baked.ply", V, F, props, colors, comments=["made by a test"])
    vert, faces, comments = _parse_ply(out)
    assert vert.dtype.names == ("x", "y", "z", "radiance_r", "k1", "fallback", "red", "green", "blue")
    np.testing.assert_allclose(np.stack([vert["x"], vert["y"], vert["z"]], 1), V, rtol=1e-7)
    for name, values in props.items():
        np.testing.assert_array_equal(vert[name], values.astype(np.float32))
    np.testing.assert_array_equal(np.stack([vert["red"], vert["green"], vert["blue"]], 1), colors)
    np.testing.assert_array_equal(faces, F)
    assert comments == ["made by a test"]
    # trimesh (and so Blender/MeshLab-style readers) opens it and sees the custom properties
    loaded = trimesh.load(out, process=False)
    np.testing.assert_array_equal(loaded.faces, F)
    raw = loaded.metadata["_ply_raw"]["vertex"]["data"]
    np.testing.assert_array_equal(raw["k1"], props["k1"].astype(np.float32))
    np.testing.assert_array_equal(loaded.visual.vertex_colors[:, :3], colors)


def test_write_ply_without_extras_is_loadable(tmp_path, shape):
    out = write_ply(tmp_path / "plain.ply", *shape)
    mesh = load_mesh(out)
    np.testing.assert_allclose(mesh.vertices, shape[0], rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, shape[1])


@pytest.mark.parametrize("props, colors, match", [
    ({"red": None}, None, "invalid PLY property name"),
    ({"two words": None}, None, "invalid PLY property name"),
    ({"k": np.zeros(3)}, None, "must have shape"),
    (None, np.zeros((4, 3)), "uint8"),
])
def test_write_ply_rejects_bad_arguments(tmp_path, props, colors, match):
    V, F = np.eye(4)[:, :3], np.array([[0, 1, 2], [0, 2, 3]])
    props = {k: (np.zeros(4) if v is None else v) for k, v in (props or {}).items()}
    with pytest.raises(ValueError, match=match):
        write_ply(tmp_path / "x.ply", V, F, props, colors)
    assert list(tmp_path.iterdir()) == []


def test_write_mesh_ply_writes_source_units(tmp_path, shape):
    src = _export(tmp_path, shape, "obj")
    mesh = load_mesh(src, units="cm")
    out = write_mesh_ply(tmp_path / "baked.ply", mesh, {"value": np.arange(mesh.n_vertices, dtype=float)})
    vert, faces, comments = _parse_ply(out)
    np.testing.assert_allclose(np.stack([vert["x"], vert["y"], vert["z"]], 1), shape[0], rtol=1e-6, atol=1e-6)
    assert any(c.startswith("meshshade mm_per_unit 10.0") for c in comments)
    assert any(str(src) in c for c in comments)
    again = load_mesh(out, units="cm")
    np.testing.assert_allclose(again.vertices, mesh.vertices, rtol=1e-6, atol=1e-5)


def test_write_mesh_ply_refuses_to_overwrite_its_source(tmp_path, shape):
    src = write_ply(tmp_path / "in.ply", *shape)
    before = src.read_bytes()
    mesh = load_mesh(src)
    with pytest.raises(OutputError, match="same file as input"):
        write_mesh_ply(src, mesh, {"value": np.zeros(mesh.n_vertices)})
    assert src.read_bytes() == before


def test_write_ply_header_layout_is_exact(tmp_path):
    out = write_ply(tmp_path / "t.ply", np.eye(3), [[0, 1, 2]], {"q": np.ones(3)}, None)
    data = out.read_bytes()
    header, body = data.split(b"end_header\n")
    assert header.decode().splitlines() == [
        "ply", "format binary_little_endian 1.0", "element vertex 3", "property float x", "property float y",
        "property float z", "property float q", "element face 1", "property list uchar int vertex_indices"]
    assert len(body) == 3 * 16 + 13
    assert struct.unpack("<4f", body[:16]) == (1.0, 0.0, 0.0, 1.0)
    assert struct.unpack("<B3i", body[48:]) == (3, 0, 1, 2)


# ------------------------------------------------------------------ reading: encodings, declared counts, polygons

def _obj(V, F) -> str:
    return "".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in np.asarray(V, float)) + \
        "".join("f " + " ".join(str(int(i) + 1) for i in f) + "\n" for f in F)


def _ply_text(V, polys, nv=None, nf=None, vprops="property float x\nproperty float y\nproperty float z\n") -> str:
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(V) if nv is None else nv}\n{vprops}"
            f"element face {len(polys) if nf is None else nf}\nproperty list uchar int vertex_indices\nend_header\n")
    return head + "".join(" ".join(repr(float(x)) for x in v) + "\n" for v in np.asarray(V, np.float32)) + \
        "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys)


def _off_text(V, polys, nv=None, nf=None) -> str:
    return (f"OFF\n{len(V) if nv is None else nv} {len(polys) if nf is None else nf} 0\n"
            + "".join(" ".join(repr(float(x)) for x in v) + "\n" for v in np.asarray(V, float))
            + "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys))


def _binary_ply(V, polys, fmt="binary_little_endian", extra=b"") -> bytes:
    e = "<" if fmt == "binary_little_endian" else ">"
    head = (f"ply\nformat {fmt} 1.0\nelement vertex {len(V)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(polys)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = np.asarray(V, e + "f4").tobytes()
    body += b"".join(np.uint8(len(p)).tobytes() + np.asarray(p, e + "i4").tobytes() for p in polys)
    return head.encode() + body + extra


@pytest.mark.parametrize("last_vertex_used", [True, False])
def test_obj_utf8_bom_does_not_hide_the_first_vertex(tmp_path, shape, last_vertex_used):
    """The BOM glued to the first ``v`` made the fast reader skip that vertex: every face then pointed one vertex
    off (an out-of-range error when the last vertex is used, silently wrong faces when it is not)."""
    V, F = shape
    if not last_vertex_used:
        V = np.vstack([V, [[9.0, 9.0, 9.0]]])
    text = _obj(V, F)
    plain, bom = tmp_path / "plain.obj", tmp_path / "bom.obj"
    plain.write_text(text, encoding="utf-8")
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    from meshshade.io.meshes import _read_obj, _read_obj_lines

    for reader in (_read_obj, _read_obj_lines, read_mesh_arrays):
        Vb, Fb = reader(bom)
        np.testing.assert_array_equal(Vb, V)
        np.testing.assert_array_equal(Fb, F)


def test_obj_utf16_with_bom_is_decoded(tmp_path, shape):
    V, F = shape
    path = tmp_path / "notepad.obj"
    path.write_bytes(b"\xff\xfe" + _obj(V, F).encode("utf-16-le"))
    Vb, Fb = read_mesh_arrays(path)
    np.testing.assert_array_equal(Vb, V)
    np.testing.assert_array_equal(Fb, F)


@pytest.mark.parametrize("ext", ["ply", "off"])
def test_text_formats_with_a_utf8_bom(tmp_path, shape, ext):
    V, F = shape
    text = _ply_text(V, F) if ext == "ply" else _off_text(V, F)
    path = tmp_path / f"bom.{ext}"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    Vb, Fb = read_mesh_arrays(path)
    np.testing.assert_allclose(Vb, V, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(Fb, F)


# (declared vertices, declared faces): more or fewer rows than the file holds, and counts that add up but put
# face rows among the vertices
COUNT_CASES = {"more_vertices": (20, 0), "fewer_vertices": (-20, 0), "more_faces": (0, 20), "fewer_faces": (0, -20),
               "shifted": (20, -20)}


@pytest.mark.parametrize("case", sorted(COUNT_CASES))
@pytest.mark.parametrize("ext", ["ply", "off"])
def test_declared_counts_must_match_the_rows(tmp_path, shape, case, ext):
    V, F = shape
    dv, df = COUNT_CASES[case]
    nv, nf = len(V) + dv, len(F) + df
    path = tmp_path / f"counts.{ext}"
    path.write_text(_ply_text(V, F, nv, nf) if ext == "ply" else _off_text(V, F, nv, nf))
    if case == "shifted":
        needle = "vertex 128 has 4 values" if ext == "ply" else "vertex rows differ in length .* in vertex 128"
        message = _one_line_error(path, needle)
    else:
        message = _one_line_error(path, f"declares {nv} vertices and {nf} faces .*holds {len(V) + len(F)} rows")
    assert str(path) in message


@pytest.mark.parametrize("cut", ["vertex", "face", "long"])
@pytest.mark.parametrize("mixed", [False, True])
def test_binary_ply_truncated_or_too_long(tmp_path, shape, cut, mixed):
    V, F = shape
    polys = [list(f) for f in F]
    if mixed:  # rows of different sizes: the row-by-row scan
        polys[3] = [0, 1, 2, 3]
    data = _binary_ply(V, polys)
    body = data.index(b"end_header\n") + 11
    data = {"vertex": data[:body + 100], "face": data[:-3], "long": data + b"\0\0"}[cut]
    path = tmp_path / "cut.ply"
    path.write_bytes(data)
    needle = "too many" if cut == "long" else f"ends inside .*{cut}"
    message = _one_line_error(path, needle)
    assert f"declares {len(V)} vertices and {len(F)} faces" in message


@pytest.mark.parametrize("writer", ["ply_ascii", "ply_binary", "ply_big_endian", "off", "obj"])
def test_polygons_fan_triangulated_in_place_with_a_warning(tmp_path, writer):
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 1.5, 0], [2, 0, 0]], float)
    polys = [[0, 1, 2], [0, 1, 2, 3], [1, 5, 2], [0, 1, 2, 4, 3], [1, 5, 2, 4]]
    expected = [[0, 1, 2], [0, 1, 2], [0, 2, 3], [1, 5, 2], [0, 1, 2], [0, 2, 4], [0, 4, 3], [1, 5, 2], [1, 2, 4]]
    path = tmp_path / f"poly.{writer.split('_')[0]}"
    if writer == "ply_ascii":
        path.write_text(_ply_text(V, polys))
    elif writer in ("ply_binary", "ply_big_endian"):
        path.write_bytes(_binary_ply(V, polys, "binary_little_endian" if writer == "ply_binary" else
                                     "binary_big_endian"))
    elif writer == "off":
        path.write_text(_off_text(V, polys))
    else:
        path.write_text(_obj(V, polys))
    with pytest.warns(MeshDefectWarning, match="3 polygons with more than 3 corners were fan-triangulated"):
        Vr, Fr = read_mesh_arrays(path)
    np.testing.assert_array_equal(Fr, expected)
    np.testing.assert_array_equal(Vr, V)


def test_triangle_only_ply_and_off_do_not_warn(tmp_path, shape):
    for ext in ("ply", "off"):
        path = _export(tmp_path, shape, ext)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            read_mesh_arrays(path)


def test_ply_variants_agree_with_trimesh(tmp_path, shape):
    """Big-endian doubles with normals and colours, a 'vertex_index' list of uint, a texcoord list and a scalar
    after the indices, an extra element; ASCII floats rounded to their declared float32 as trimesh does."""
    V, F = shape
    e = ">"
    vert = np.zeros(len(V), [("x", e + "f8"), ("y", e + "f8"), ("z", e + "f8"), ("nx", e + "f4"), ("ny", e + "f4"),
                             ("nz", e + "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    vert["x"], vert["y"], vert["z"] = V.T
    face = np.zeros(len(F), [("n", "u1"), ("i", e + "u4", (3,)), ("m", "u1"), ("t", e + "f4", (6,)),
                             ("flags", e + "i4")])
    face["n"], face["i"], face["m"] = 3, F, 6
    head = ("ply\nformat binary_big_endian 1.0\ncomment variants\nobj_info made by a test\n"
            f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
            "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\n"
            f"property uchar blue\nelement face {len(F)}\nproperty list uchar uint vertex_index\n"
            "property list uchar float texcoord\nproperty int flags\nelement edge 2\nproperty int vertex1\n"
            "property int vertex2\nend_header\n")
    path = tmp_path / "variants.ply"
    path.write_bytes(head.encode() + vert.tobytes() + face.tobytes() + np.zeros(4, ">i4").tobytes())
    Vr, Fr = read_mesh_arrays(path)
    np.testing.assert_array_equal(Vr, V)
    np.testing.assert_array_equal(Fr, F)
    ascii_path = tmp_path / "ascii.ply"
    trimesh.Trimesh(V, F, process=False).export(ascii_path, encoding="ascii")
    Va, Fa = read_mesh_arrays(ascii_path)
    raw = trimesh.load(ascii_path, process=False, maintain_order=True)
    np.testing.assert_array_equal(Va, raw.vertices)
    np.testing.assert_array_equal(Fa, raw.faces)


@pytest.mark.parametrize("text, match", [
    ("ply\nformat ascii 2.0 x\nend_header\n", "unsupported PLY format"),
    ("ply\nformat ascii 1.0\nelement vertex three\nend_header\n", "malformed element line"),
    ("ply\nformat ascii 1.0\nproperty float x\nend_header\n", "property before any element"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n",
     "no x, y, z properties"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n",
     "no end_header"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2.5\n",
     "not all integers"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 one 0\n3 0 1 2\n",
     "malformed number in the vertex rows"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     "end_header\n0 0 0\n1 0 0\n0 1 0\n", "no triangles found"),
    ("OFF BINARY\n", "binary OFF is not supported"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", "declares 4 corners but lists 3"),
])
def test_ply_and_off_malformed_one_line(tmp_path, text, match):
    path = tmp_path / ("bad.off" if text.startswith("OFF") else "bad.ply")
    path.write_text(text)
    assert str(path) in _one_line_error(path, match)


def test_binary_ply_with_mixed_polygons_is_read(tmp_path, shape):
    """Blender writes n-gons as lists of varying length; each polygon's triangles stay where it was."""
    V, F = shape
    polys = [list(F[0]) + [F[1][2]]] + [list(f) for f in F[2:]]
    path = tmp_path / "blender.ply"
    path.write_bytes(_binary_ply(V, polys))
    with pytest.warns(MeshDefectWarning, match="1 polygons"):
        Vr, Fr = read_mesh_arrays(path)
    np.testing.assert_array_equal(Fr[:2], [F[0], [F[0][0], F[0][2], F[1][2]]])
    np.testing.assert_array_equal(Fr[2:], F[2:])
    np.testing.assert_allclose(Vr, V, rtol=1e-6, atol=1e-6)


# ---------------------------------------------------------------------------------------------- baked PLY

def test_read_baked_ply_round_trip(tmp_path, shape, rng):
    from meshshade.io import read_baked_ply

    V, F = shape
    src = tmp_path / "in.obj"
    src.write_text(_obj(V, F))
    mesh = load_mesh(src, units="cm")
    M = rng.random((mesh.n_vertices, 3)) * 1e-3
    out = write_mesh_ply(tmp_path / "baked.ply", mesh, {"radiance_r": M[:, 0], "radiance_g": M[:, 1],
                                                        "radiance_b": M[:, 2]},
                         comments=["meshshade model curved",
                                   "meshshade material skin1: sigma_s'=[0.74,0.88,1.01] sigma_a=[0.032,0.17,0.48] "
                                   "1/mm, eta=1.44, g=0"])
    again, radiance, info = read_baked_ply(out)  # the recorded cm, not the default mm
    np.testing.assert_allclose(again.vertices, mesh.vertices, rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(again.faces, mesh.faces)
    np.testing.assert_array_equal(radiance, M.astype(np.float32))
    assert info["mm_per_unit"] == 10.0 and info["eta"] == 1.44 and info["model"] == "curved"
    assert info["material"].startswith("skin1") and info["source"] == str(src)
    assert read_baked_ply(src) is None and read_baked_ply(write_ply(tmp_path / "plain.ply", V, F)) is None


def test_read_baked_ply_refuses_damaged_radiance(tmp_path, shape):
    from meshshade.io import read_baked_ply

    V, F = shape
    vert = np.zeros(len(V), [(name, "<f4") for name in ("x", "y", "z", "radiance_r", "radiance_g", "radiance_b")])
    vert["x"], vert["y"], vert["z"] = V.T
    vert["radiance_g"][4], vert["radiance_b"][7] = np.nan, -1.0  # write_ply refuses such values: built by hand
    face = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,))])
    face["n"], face["i"] = 3, F
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(V)}\n"
            + "".join(f"property float {name}\n" for name in vert.dtype.names)
            + f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
    path = tmp_path / "damaged.ply"
    path.write_bytes(head.encode() + vert.tobytes() + face.tobytes())
    with pytest.raises(MeshValidationError, match="damaged.ply: 2 vertices have radiance_r/g/b that are not"):
        read_baked_ply(path)
