"""Input files and geometry the pipeline could not handle, through every subcommand that reads a mesh (issue 17:
input parsing, crashes, quads, Monte Carlo on open meshes, render of a baked PLY).

Every case is written into ``tmp_path`` by the test. Bad files: exit 2, one ``meshshade: error:`` line naming the
file and the problem, nothing left behind, input untouched (``cli.assert_clean_failure``). Files that are fine but
were read wrongly (a UTF-8 byte-order mark, polygons) must give the same result as the clean file. Geometry that
crashed libigl runs in a child process, so a crash is a failure of the test, not of pytest.
"""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.names import DEFAULT_MODEL
from meshshade.geometry.procedural import icosphere
from meshshade.io import read_baked_ply, read_exr, write_ply

SKIN = ["--material", "skin1"]
BEAM = ["--light", "beam:0,0,40:0,0,-1"]
SMALL_IMAGE = ["--width", "24", "--height", "24", "--spp", "1"]


def _sphere():
    return icosphere(10.0, 2)


def _obj(V, F) -> str:
    return "".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in V) + \
        "".join("f " + " ".join(str(int(i) + 1) for i in f) + "\n" for f in F)


def _ply_ascii(V, F, nv=None, nf=None) -> str:
    return (f"ply\nformat ascii 1.0\nelement vertex {len(V) if nv is None else nv}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(F) if nf is None else nf}\n"
            "property list uchar int vertex_indices\nend_header\n"
            + "".join(" ".join(repr(float(x)) for x in v) + "\n" for v in np.asarray(V, np.float32))
            + "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in F))


def _off(V, F, nv=None, nf=None) -> str:
    return (f"OFF\n{len(V) if nv is None else nv} {len(F) if nf is None else nf} 0\n"
            + "".join(" ".join(repr(float(x)) for x in v) + "\n" for v in V)
            + "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in F))


def _binary_ply_mixed(V, polys) -> bytes:
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(V)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(polys)}\nproperty list uchar int vertex_indices\nend_header\n")
    return head.encode() + np.asarray(V, "<f4").tobytes() + b"".join(
        np.uint8(len(p)).tobytes() + np.asarray(p, "<i4").tobytes() for p in polys)


def _argv(command, mesh, tmp, *extra):
    """The shortest command line of ``command`` that reads ``mesh`` (tiny images, few photons)."""
    if command == "check":
        return ["check", mesh, *SKIN, "--json", tmp / "report.json", *extra]
    if command == "bake":
        return ["bake", mesh, *SKIN, *BEAM, "--geodesic", "arc", "--out", tmp / "out.ply", "-q", *extra]
    if command == "render":
        return ["render", mesh, *SKIN, *BEAM, "--geodesic", "arc", *SMALL_IMAGE, "--out", tmp / "img", "-q", *extra]
    if command == "compare":
        return ["compare", mesh, *SKIN, *BEAM, "--geodesic", "arc", *SMALL_IMAGE, "--out", tmp / "cmp", "-q",
                *extra]
    if command == "mc":
        return ["mc", mesh, *SKIN, *BEAM, "--photons", "2000", "--out", tmp / "mc.ply", "-q", *extra]
    raise AssertionError(command)


COMMANDS = ["check", "bake", "render", "compare", "mc"]


# ------------------------------------------------------------------------------------- declared counts

def _bad_counts_file(kind: str, tmp):
    V, F = _sphere()
    n, m = len(V), len(F)
    if kind == "ply_more_vertices":  # was read with face rows as vertices, exit 0
        return tmp / "more.ply", _ply_ascii(V, F, nv=n + 20), f"declares {n + 20} vertices"
    if kind == "ply_more_faces":
        return tmp / "faces.ply", _ply_ascii(V, F, nf=m + 5), f"declares {n} vertices and {m + 5} faces"
    if kind == "ply_shifted":  # counts add up, but face rows would be read as vertices
        return tmp / "shifted.ply", _ply_ascii(V, F, nv=n + 20, nf=m - 20), "has 4 values"
    if kind == "off_more_vertices":
        return tmp / "more.off", _off(V, F, nv=n + 20), f"declares {n + 20} vertices"
    if kind == "off_fewer_faces":
        return tmp / "fewer.off", _off(V, F, nf=m - 20), f"declares {n} vertices and {m - 20} faces"
    if kind == "off_shifted":
        return tmp / "shifted.off", _off(V, F, nv=n + 20, nf=m - 20), "vertex rows differ in length"
    if kind == "binary_ply_truncated_mixed":
        polys = [list(f) for f in F]
        polys[0] = [*F[0], F[1][2]]
        return tmp / "cut.ply", _binary_ply_mixed(V, polys)[:-5], f"ends inside face {m - 1} of {m}"
    if kind == "binary_ply_too_long":
        return tmp / "long.ply", _binary_ply_mixed(V, [list(f) for f in F]) + b"\n\n", "2 too many"
    raise AssertionError(kind)


BAD_COUNTS = ["ply_more_vertices", "ply_more_faces", "ply_shifted", "off_more_vertices", "off_fewer_faces",
              "off_shifted", "binary_ply_truncated_mixed", "binary_ply_too_long"]


@pytest.mark.parametrize("kind", BAD_COUNTS)
@pytest.mark.parametrize("command", COMMANDS)
def test_counts_that_do_not_match_the_data_fail_cleanly(tmp_path, cli, kind, command):
    path, content, needle = _bad_counts_file(kind, tmp_path)
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(_argv(command, path, tmp_path))
    cli.assert_clean_failure(rc, err, before, tmp_path, path.name, needle)


# ----------------------------------------------------------------------------------------- encodings

@pytest.mark.parametrize("unused_last_vertex", [False, True])
def test_obj_with_a_utf8_bom_bakes_like_the_clean_file(tmp_path, cli, unused_last_vertex):
    """The BOM hid the first vertex: 'face index out of range', or (last vertex unused) exit 0 with every face on
    the wrong vertices."""
    V, F = _sphere()
    if unused_last_vertex:
        V = np.vstack([V, [[30.0, 0.0, 0.0]]])
    text = _obj(V, F)
    (tmp_path / "plain.obj").write_text(text)
    (tmp_path / "bom.obj").write_bytes(b"\xef\xbb\xbf" + text.encode())
    results = {}
    for name in ("plain", "bom"):
        rc, _, err = cli.run(["bake", tmp_path / f"{name}.obj", *SKIN, *BEAM, "--geodesic", "arc",
                              "--out", tmp_path / f"{name}_out.ply", "-q"])
        assert rc == 0, err
        mesh, radiance, _ = read_baked_ply(tmp_path / f"{name}_out.ply")
        results[name] = (mesh.faces, radiance)
    np.testing.assert_array_equal(results["bom"][0], F)
    np.testing.assert_array_equal(results["bom"][0], results["plain"][0])
    np.testing.assert_array_equal(results["bom"][1], results["plain"][1])


@pytest.mark.parametrize("ext", ["ply", "off"])
def test_text_formats_with_a_bom_are_read(tmp_path, cli, ext):
    V, F = _sphere()
    path = tmp_path / f"bom.{ext}"
    path.write_bytes(b"\xef\xbb\xbf" + (_ply_ascii(V, F) if ext == "ply" else _off(V, F)).encode())
    rc, out, err = cli.run(["check", path])
    assert rc == 0 and "Traceback" not in err, err
    assert f"{len(V)} vertices, {len(F)} faces" in out


# ------------------------------------------------------------------------------------------- polygons

@pytest.mark.parametrize("ext", ["ply", "off", "obj"])
def test_quads_warn_in_every_format(tmp_path, cli, ext):
    V = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [0, 0, 10], [10, 0, 10], [10, 10, 10], [0, 10, 10]],
                 float)
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]  # a closed cube
    path = tmp_path / f"cube.{ext}"
    path.write_text({"ply": _ply_ascii, "off": _off, "obj": _obj}[ext](V, quads))
    rc, out, err = cli.run(["bake", path, *SKIN, "--light", "directional:0,0,-1", "--geodesic", "arc",
                            "--out", tmp_path / "out.ply", "-q"])
    assert rc == 0, err
    assert "6 polygons with more than 3 corners were fan-triangulated" in err
    assert all(line.startswith("meshshade: warning:") for line in err.strip().splitlines())
    mesh, radiance, _ = read_baked_ply(tmp_path / "out.ply")
    assert mesh.n_faces == 12 and mesh.defects.is_closed and np.all(np.isfinite(radiance))
    rc, out, err = cli.run(["check", path])  # check lists it in its report
    assert rc == 0 and "fan-triangulated" in out


# ------------------------------------------------------------------------------ geometry that crashed libigl

def _bowtie():
    T = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 10.0
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return np.vstack([T, -T[1:]]), np.vstack([Ft, np.array([0, 4, 5, 6])[Ft][:, [0, 2, 1]]])


def _double_sided_sheet():
    x, y = np.meshgrid(np.arange(6.0), np.arange(6.0), indexing="ij")
    q = (np.arange(5)[:, None] * 6 + np.arange(5)[None, :]).reshape(-1)
    F = np.vstack([np.c_[q, q + 6, q + 1], np.c_[q + 1, q + 6, q + 7]])
    return np.c_[x.ravel(), y.ravel(), np.zeros(36)] * 4.0, np.vstack([F, F[:, ::-1]])


@pytest.mark.parametrize("shape", ["bowtie", "double_sided_sheet"])
@pytest.mark.parametrize("command", ["check", "bake"])
def test_normals_that_cancel_do_not_crash(tmp_path, cli, shape, command):
    """Two tetrahedra mirrored through a shared vertex (exit 139 before, no message), a sheet whose faces are
    all duplicated with the opposite winding: the vertices without a tangent plane take the fallback curvature,
    and the run says so (the bake with a curvature model: the default volume model computes no curvature)."""
    V, F = {"bowtie": _bowtie, "double_sided_sheet": _double_sided_sheet}[shape]()
    mesh = write_ply(tmp_path / f"{shape}.ply", V, F)
    light = ["--light", "directional:0.3,0.2,-1"]
    argv = (["check", mesh, *SKIN] if command == "check" else
            ["bake", mesh, *SKIN, *light, "--model", "curved", "--geodesic", "arc", "--out", tmp_path / "out.ply",
             "-q"])
    proc = cli.popen(argv, tmp_path)
    out, err = proc.communicate(timeout=300)
    out, err = out.decode(), err.decode()
    assert proc.returncode in (0, 2), (proc.returncode, err[-600:])  # never a signal (-11) or a traceback
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert all(line.startswith("meshshade: ") for line in lines), err
    if proc.returncode == 0:
        said = out if command == "check" else err
        assert "tangent plane" in said, said


# ------------------------------------------------------------------------------------- Monte Carlo, open

def test_mc_on_an_open_mesh_says_what_the_walk_does(tmp_path, cli):
    V, F = _sphere()
    top = V[F].mean(axis=1)[:, 2] > 8.0
    mesh = write_ply(tmp_path / "open.ply", V, F[~top])
    rc, _, err = cli.run(["mc", mesh, *SKIN, "--light", "beam:-40,0,0:1,0,0", "--photons", "2000",
                          "--out", tmp_path / "mc.ply", "-q"])
    assert rc == 0, err
    said = [line for line in err.splitlines() if "Monte Carlo" in line]
    assert len(said) == 1, err
    for needle in ("boundary edges", "w > 1/2", "closed by lids", "Fresnel"):
        assert needle in said[0], said[0]


def test_mc_on_a_closed_mesh_has_no_such_warning(tmp_path, cli):
    mesh = write_ply(tmp_path / "closed.ply", *_sphere())
    rc, _, err = cli.run(["mc", mesh, *SKIN, *BEAM, "--photons", "2000", "--out", tmp_path / "mc.ply", "-q"])
    assert rc == 0 and "Monte Carlo" not in err, err


# ------------------------------------------------------------------------------------- render a baked PLY

@pytest.fixture
def baked(tmp_path, cli):
    """A tiny sphere (float32 positions, as the bake writes them back) baked through the CLI."""
    src = write_ply(tmp_path / "sphere.ply", *_sphere())
    out = tmp_path / "baked.ply"
    rc, _, err = cli.run(["bake", src, *SKIN, "--light", "directional:0.2,-0.3,-1", "--geodesic", "arc",
                          "--out", out, "-q"])
    assert rc == 0, err
    return src, out


def test_render_of_a_baked_ply_equals_the_render_of_the_same_bake(tmp_path, cli, baked):
    src, out = baked
    rc, _, err = cli.run(["render", out, *SMALL_IMAGE, "--out", tmp_path / "from_bake", "-q"])  # no material/light
    assert rc == 0 and err == "", err
    rc, _, err = cli.run(["render", src, *SKIN, "--light", "directional:0.2,-0.3,-1", "--geodesic", "arc",
                          *SMALL_IMAGE, "--out", tmp_path / "direct", "-q"])
    assert rc == 0, err
    a, meta = read_exr(tmp_path / "from_bake.exr")
    b, _ = read_exr(tmp_path / "direct.exr")
    assert a[..., 3].any()
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6 * np.abs(b[..., :3]).max())  # radiance stored as float32
    assert meta["model"].startswith(DEFAULT_MODEL) and "skin1" in meta["material"]


def test_render_of_a_baked_ply_says_which_options_it_ignores(tmp_path, cli, baked):
    _, out = baked
    rc, _, err = cli.run(["render", out, *SKIN, *BEAM, "--model", "dipole", *SMALL_IMAGE, "--out", tmp_path / "r",
                          "-q"])
    assert rc == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("meshshade: warning:")
    for needle in ("is a bake", "--material", "--light", "--model", "ignored"):
        assert needle in lines[0]


def test_render_of_a_baked_ply_refuses_per_pixel(tmp_path, cli, baked):
    _, out = baked
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run(["render", out, *SMALL_IMAGE, "--per-pixel", "--out", tmp_path / "r"])
    cli.assert_clean_failure(rc, err, before, tmp_path, "--per-pixel", out.name)


def test_render_help_says_a_baked_ply_is_rendered_as_it_is(cli):
    try:
        rc, out, _ = cli.run(["render", "--help"])
    except SystemExit as exc:  # argparse's own exit, if main lets it through
        rc, out = exc.code, cli._capsys.readouterr().out
    text = " ".join(out.split())
    assert rc == 0 and "meshshade bake" in text and "rendered as it is" in text

