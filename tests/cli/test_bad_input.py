"""Bad-input corpus through the CLI (`bake` and `check`): one line, exit code 2, nothing lost.

Every case is generated into ``tmp_path`` by the test itself. For each: exit code 2 (or 0 plus warning lines
for the warning-only cases, whose behaviour is documented in geometry/mesh.py and materials.py), exactly one
error line on stderr (``meshshade: warning: ...`` lines may precede it), the offending file or value named,
no "Traceback", no output file and no temporary file (``.*.tmp*``) left, and the input's bytes unchanged.
The SIGINT test runs the CLI as a subprocess and interrupts it mid-bake.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry.procedural import icosphere
from meshshade.io import write_ply

ROOT = Path(__file__).resolve().parents[2]
BEAM = ["--light", "beam:0,0,40:0,0,-1"]
SKIN = ["--material", "skin1"]


# --------------------------------------------------------------------------------------------- corpus writers
def _obj_text(V, F) -> str:
    lines = ["v " + " ".join(repr(float(x)) for x in v) for v in np.asarray(V, float)]
    lines += ["f " + " ".join(str(int(i) + 1) for i in f) for f in np.asarray(F)]
    return "\n".join(lines) + "\n"


def _ply_ascii(V, F) -> str:
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(V)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = "".join(" ".join(repr(float(x)) for x in v) + "\n" for v in np.asarray(V, float))
    body += "".join("3 " + " ".join(str(int(i)) for i in f) + "\n" for f in np.asarray(F))
    return head + body


def _sphere():
    return icosphere(10.0, 2)


def _write(tmp: Path, name: str, content) -> Path:
    p = tmp / name
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_text(content)
    return p


def _good_binary_ply_bytes(tmp: Path) -> bytes:
    V, F = _sphere()
    p = tmp / "scratch_good.ply"
    write_ply(p, V, F)
    data = p.read_bytes()
    p.unlink()
    return data


def make_corpus_file(kind: str, tmp: Path) -> Path:
    """Write one bad mesh of ``kind`` into ``tmp``; return its path (may not exist: 'missing')."""
    V, F = _sphere()
    if kind == "missing":
        return tmp / "nope.ply"
    if kind == "directory":
        (tmp / "adir.obj").mkdir()
        return tmp / "adir.obj"
    if kind == "empty":
        return _write(tmp, "empty.obj", "")
    if kind == "truncated_ply":
        data = _good_binary_ply_bytes(tmp)
        return _write(tmp, "trunc.ply", data[: len(data) // 2])
    if kind == "truncated_ascii_ply":
        text = _ply_ascii(V, F)
        return _write(tmp, "trunc_ascii.ply", text[: 2 * len(text) // 3])
    if kind == "header_only_ply":
        data = _good_binary_ply_bytes(tmp)
        return _write(tmp, "header.ply", data[: data.index(b"end_header\n") + 11])
    if kind == "garbage_ply":
        return _write(tmp, "garbage.ply", np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    if kind == "truncated_obj":
        text = _obj_text(V, F)
        return _write(tmp, "trunc.obj", text[: len(text) // 2 + 7])  # cut inside a vertex line
    if kind == "garbage_obj":
        return _write(tmp, "garbage.obj", np.random.default_rng(2).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    if kind == "nan_vertex":
        V = V.copy()
        V[3, 1] = np.nan
        return _write(tmp, "nan.obj", _obj_text(V, F))
    if kind == "inf_vertex_ply":
        V = V.copy()
        V[7, 0] = np.inf
        return _write(tmp, "inf.ply", _ply_ascii(V, F))
    if kind == "overflow_vertex":
        return _write(tmp, "overflow.obj", "v 1e400 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    if kind == "face_out_of_range":
        F = F.copy()
        F[5, 1] = 9999
        return _write(tmp, "oor.obj", _obj_text(V, F))
    if kind == "face_out_of_range_ply":
        F = F.copy()
        F[2, 2] = len(V)
        return _write(tmp, "oor.ply", _ply_ascii(V, F))
    if kind == "face_negative_ply":
        F = F.copy()
        F[2, 2] = -7
        return _write(tmp, "neg.ply", _ply_ascii(V, F))
    if kind == "face_index_beyond_int64":
        return _write(tmp, "huge.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n")
    if kind == "face_index_zero":
        return _write(tmp, "zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    if kind == "zero_faces":
        return _write(tmp, "nofaces.obj", _obj_text(V, F[:0]))
    if kind == "zero_faces_ply":
        return _write(tmp, "nofaces.ply", _ply_ascii(V, F[:0]))
    if kind == "only_degenerate":
        return _write(tmp, "degenerate.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\nf 1 1 2\n")
    if kind == "unsupported_extension":
        return _write(tmp, "mesh.xyz", _obj_text(V, F))
    raise AssertionError(kind)


FATAL_MESHES = {  # kind -> a word the error line must contain (besides the file name)
    "missing": "not found", "directory": "directory", "empty": "empty", "truncated_ply": "ply",
    "truncated_ascii_ply": "ply", "header_only_ply": "ply", "garbage_ply": "ply", "truncated_obj": "malformed",
    "garbage_obj": "obj", "nan_vertex": "nan", "inf_vertex_ply": "inf", "overflow_vertex": "inf",
    "face_out_of_range": "out of range", "face_out_of_range_ply": "out of range", "face_negative_ply": "negative",
    "face_index_beyond_int64": "out of range", "face_index_zero": "index 0", "zero_faces": "no faces",
    "zero_faces_ply": "no triangles", "only_degenerate": "degenerate", "unsupported_extension": "unsupported",
}


# --------------------------------------------------------------------------------------------- assertions
def _bake_argv(mesh, out, *extra):
    return ["bake", str(mesh), *SKIN, *BEAM, "--out", str(out), "-q", *extra]


# --------------------------------------------------------------------------------------------- fatal meshes
@pytest.mark.parametrize("kind", sorted(FATAL_MESHES))
@pytest.mark.parametrize("command", ["bake", "check"])
def test_bad_mesh_one_line_exit_2(tmp_path, cli, kind, command):
    mesh = make_corpus_file(kind, tmp_path)
    before = cli.snapshot(tmp_path)
    out = tmp_path / "out.ply"
    argv = _bake_argv(mesh, out) if command == "bake" else ["check", str(mesh), *SKIN, "--json",
                                                            str(tmp_path / "out.json")]
    rc, _, err = cli.run(argv)
    cli.assert_clean_failure(rc, err, before, tmp_path, mesh.name, FATAL_MESHES[kind])


# --------------------------------------------------------------------------------------------- warning-only meshes
def _warning_mesh(kind: str, tmp: Path) -> Path:
    V, F = _sphere()
    if kind == "open":
        return _write(tmp, "open.obj", _obj_text(V, F[5:]))
    if kind == "non_manifold":
        V2 = np.vstack([V, [[0.0, 0.0, 30.0]]])
        F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])
        return _write(tmp, "nonmanifold.obj", _obj_text(V2, F2))
    if kind == "inward":
        return _write(tmp, "inward.obj", _obj_text(V, F[:, ::-1]))
    if kind == "some_degenerate":
        V2 = np.vstack([V, V[F[0, 0]] + 0.0])  # a duplicate corner: a zero-area sliver
        F2 = np.vstack([F, [[F[0, 0], len(V), F[0, 1]]]])
        return _write(tmp, "somedegen.obj", _obj_text(V2, F2))
    raise AssertionError(kind)


WARNING_MESHES = {"open": "open boundary", "non_manifold": "non-manifold", "inward": "inward orientation fixed",
                  "some_degenerate": "degenerate"}


@pytest.mark.parametrize("kind", sorted(WARNING_MESHES))
def test_warning_only_mesh_bakes_with_warning(tmp_path, cli, kind):
    mesh = _warning_mesh(kind, tmp_path)
    before = mesh.read_bytes()
    out = tmp_path / "out.ply"
    rc, _, err = cli.run(_bake_argv(mesh, out))
    assert rc == 0, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines and all(line.startswith("meshshade: warning:") for line in lines)
    assert any(WARNING_MESHES[kind] in line for line in lines)
    assert out.exists() and mesh.read_bytes() == before
    assert not list(tmp_path.glob(".*.tmp*"))
    import trimesh

    raw = trimesh.load(out, process=False).metadata["_ply_raw"]["vertex"]["data"]
    for c in "rgb":
        r = raw[f"radiance_{c}"]
        assert np.all(np.isfinite(r)) and np.all(r >= 0)


@pytest.mark.parametrize("kind", sorted(WARNING_MESHES))
def test_check_reports_warning_only_defects(tmp_path, cli, kind):
    mesh = _warning_mesh(kind, tmp_path)
    before = mesh.read_bytes()
    rc, out, err = cli.run(["check", str(mesh)])
    assert rc == 0 and "Traceback" not in err
    assert WARNING_MESHES[kind] in out  # listed in the report instead of as warning lines
    assert mesh.read_bytes() == before


# --------------------------------------------------------------------------------------------- materials, lights
@pytest.fixture
def good_mesh(tmp_path):
    V, F = _sphere()
    p = tmp_path / "good.ply"
    write_ply(p, V, F)
    return p


BAD_OPTIONS = {
    "unknown_material": (["--material", "skn1"], "did you mean 'skin1'"),
    "unknown_material_far": (["--material", "granite"], "unknown material"),
    "negative_sigma_a": (["--sigma-s-prime", "1", "--sigma-a", "-0.1"], "sigma_a"),
    "nan_sigma_a": (["--sigma-s-prime", "1", "--sigma-a", "nan"], "--sigma-a"),
    "nan_sigma_s_prime_rgb": (["--sigma-s-prime", "nan,1,1", "--sigma-a", "0.1"], "--sigma-s-prime"),
    "inf_sigma_s_prime": (["--sigma-s-prime", "inf", "--sigma-a", "0.1"], "--sigma-s-prime"),
    "zero_sigma_s_prime": (["--sigma-s-prime", "0", "--sigma-a", "0.1"], "sigma_s_prime"),
    "negative_sigma_s_prime": (["--sigma-s-prime", "-2", "--sigma-a", "0.1"], "sigma_s_prime"),
    "two_values": (["--sigma-s-prime", "1,2", "--sigma-a", "0.1"], "--sigma-s-prime"),
    "text_value": (["--sigma-s-prime", "one", "--sigma-a", "0.1"], "--sigma-s-prime"),
    "negative_eta": (["--sigma-s-prime", "1", "--sigma-a", "0.1", "--eta", "-1"], "eta"),
    "nan_eta": (["--sigma-s-prime", "1", "--sigma-a", "0.1", "--eta", "nan"], "eta"),
    "only_sigma_a": (["--sigma-a", "0.1"], "sigma-s-prime"),
    "preset_and_numbers": (["--material", "skin1", "--sigma-a", "0.1"], "not both"),
}


@pytest.mark.parametrize("case", sorted(BAD_OPTIONS))
@pytest.mark.parametrize("command", ["bake", "check"])
def test_bad_material_one_line_exit_2(good_mesh, cli, case, command):
    opts, needle = BAD_OPTIONS[case]
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    if command == "bake":
        argv = ["bake", str(good_mesh), *opts, *BEAM, "--out", str(tmp / "o.ply"), "-q"]
    else:
        argv = ["check", str(good_mesh), *opts, "--json", str(tmp / "o.json")]
    rc, _, err = cli.run(argv)
    cli.assert_clean_failure(rc, err, before, tmp, needle)


BAD_LIGHTS = {
    "too_few_fields": ("beam:0,0,40", "beam:ox,oy,oz"),
    "text_origin": ("beam:a,b,c:0,0,-1", "beam origin"),
    "two_components": ("beam:0,0,40:0,0", "beam direction"),
    "zero_direction": ("beam:0,0,40:0,0,0", "non-zero"),
    "nan_power": ("beam:0,0,40:0,0,-1:nan", "power"),
    "inf_power": ("beam:0,0,40:0,0,-1:inf", "power"),
    "negative_power": ("beam:0,0,40:0,0,-1:-1", "power"),
    "negative_irradiance": ("directional:0,0,-1:-1", "irradiance"),
    "nan_point": ("point:0,0,nan", "finite"),
    "unknown_type": ("laser:0,0,1", "unknown light type"),
    "empty": ("", "empty light"),
    "misses_beside": ("beam:100,0,40:0,0,-1", "misses"),
    "misses_away": ("beam:0,0,40:0,0,1", "misses"),
    "starts_inside": ("beam:0,0,0:0,0,-1", "inside"),
    "point_inside": ("point:0,0,0", "inside"),
}


@pytest.mark.parametrize("case", sorted(BAD_LIGHTS))
def test_bad_light_one_line_exit_2(good_mesh, cli, case):
    spec, needle = BAD_LIGHTS[case]
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(["bake", str(good_mesh), *SKIN, "--light", spec, "--out", str(tmp / "o.ply"),
                               "--npz", str(tmp / "o.npz"), "-q"])
    cli.assert_clean_failure(rc, err, before, tmp, needle)


@pytest.mark.parametrize("opts,needle", [
    (["--curvature-radius", "-1"], "curvature radius"),
    (["--curvature-radius", "nan"], "--curvature-radius"),
    (["--cutoff-tol", "nan"], "--cutoff-tol"),
    (["--cutoff-tol", "2"], "cutoff"),
    (["--units", "furlong"], "furlong"),
])
def test_bad_numeric_options_one_line_exit_2(good_mesh, cli, opts, needle):
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, tmp / "o.ply", *opts))
    cli.assert_clean_failure(rc, err, before, tmp, needle)


def test_check_bad_curvature_radius(good_mesh, cli):
    before = cli.snapshot(good_mesh.parent)
    rc, _, err = cli.run(["check", str(good_mesh), "--curvature-radius", "0"])
    cli.assert_clean_failure(rc, err, before, good_mesh.parent, "curvature-radius")


def test_low_albedo_is_a_warning_not_an_error(good_mesh, cli):
    """sigma_a >> sigma_s': diffusion is invalid, documented as a warning; the result is written and finite."""
    out = good_mesh.parent / "o.npz"
    rc, _, err = cli.run(["bake", str(good_mesh), "--sigma-s-prime", "1", "--sigma-a", "50", *BEAM,
                               "--out", str(good_mesh.parent / "o.ply"), "--npz", str(out), "-q"])
    assert rc == 0 and "Traceback" not in err
    assert "meshshade: warning:" in err and "albedo" in err
    M = np.load(out)["radiance"]
    assert np.all(np.isfinite(M)) and np.all(M >= 0) and M.max() > 0


# --------------------------------------------------------------------------------------------- outputs
def test_output_equal_to_input(good_mesh, cli):
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, good_mesh))
    cli.assert_clean_failure(rc, err, before, tmp, "same file", good_mesh.name)


def test_output_equal_to_input_via_symlink(good_mesh, cli):
    tmp = good_mesh.parent
    (tmp / "link.ply").symlink_to(good_mesh)
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, tmp / "link.ply"))
    cli.assert_clean_failure(rc, err, before, tmp, "same file")


def test_npz_equal_to_input(good_mesh, cli):
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, tmp / "o.ply", "--npz", str(good_mesh)))
    cli.assert_clean_failure(rc, err, before, tmp, "same file")


def test_check_json_equal_to_input(good_mesh, cli):
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(["check", str(good_mesh), "--json", str(good_mesh)])
    cli.assert_clean_failure(rc, err, before, tmp, "same file")


def test_output_directory_missing(good_mesh, cli):
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, tmp / "no" / "such" / "o.ply"))
    cli.assert_clean_failure(rc, err, before, tmp, "does not exist")


def test_output_is_a_directory(good_mesh, cli):
    tmp = good_mesh.parent
    (tmp / "sub").mkdir()
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, tmp / "sub"))
    cli.assert_clean_failure(rc, err, before, tmp, "directory")


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root can write to a 0o555 directory")
def test_output_directory_not_writable(good_mesh, cli):
    tmp = good_mesh.parent
    ro = tmp / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        before = cli.snapshot(tmp)
        rc, _, err = cli.run(_bake_argv(good_mesh, ro / "o.ply"))
        cli.assert_clean_failure(rc, err, before, tmp, "not writable")
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc (Linux)")
def test_output_directory_refuses_files(good_mesh, cli):
    """A directory that passes os.access but refuses new files (/proc, also as root): the atomic writer's
    failure is one line, exit 2, and nothing is left anywhere."""
    tmp = good_mesh.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, "/proc/meshshade_test_out.ply"))
    cli.assert_clean_failure(rc, err, before, tmp, "/proc")
    assert not Path("/proc/meshshade_test_out.ply").exists()


def test_failed_write_keeps_previous_output(good_mesh, cli, monkeypatch):
    """An exception while the PLY is being written leaves the previous output byte-identical, no temp file."""
    import meshshade.io.transactions as mio  # where the outputs are renamed (os.replace)

    tmp = good_mesh.parent
    out = tmp / "o.ply"
    out.write_bytes(b"previous result")

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(mio.os, "replace", boom)
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, out))
    cli.assert_clean_failure(rc, err, before, tmp, "o.ply", "disk full")


# --------------------------------------------------------------------------------------------- SIGINT
def _sphere_ply(tmp: Path, level: int) -> Path:
    V, F = icosphere(30.0, level)
    p = tmp / "big.ply"
    write_ply(p, V, F)
    return p


def _cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of a live process, all its threads (Linux: /proc/<pid>/stat fields 14 and 15)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.parametrize("level", [5, pytest.param(6, marks=pytest.mark.slow)])
def test_sigint_leaves_no_partial_output(tmp_path, cli, level):
    """SIGINT 1 s of the child's own CPU time into the work (counted from the mesh line it prints when the bake
    starts): exit 130 (or 2), one line, nothing left.

    Level 5 (10 242 vertices) with marble, a directional light and the direct sum (``--transport direct``; the
    hierarchical transport bakes this sphere in about 2 s) takes minutes of CPU, so the run is always
    interrupted mid-bake; the slow variant uses 40 962 vertices and interrupts after 3 s of CPU. Both points are
    events of the child's progress, not wall-clock delays, so a loaded machine only makes the test slower."""
    mesh = _sphere_ply(tmp_path, level)
    before = cli.snapshot(tmp_path)
    out, npz = tmp_path / "out.ply", tmp_path / "out.npz"
    env = dict(os.environ, PYTHONUNBUFFERED="1",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "meshshade.cli", "bake", str(mesh), "--material", "marble",
                             "--light", "directional:0.3,-0.5,-1", "--model", "curved", "--transport", "direct",
                             "--out", str(out), "--npz", str(npz)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=env, cwd=str(tmp_path))
    try:
        first = proc.stdout.readline().decode()  # "mesh: ... transport mean free paths ...": the job started
        start, work = _cpu_seconds(proc.pid), (1.0 if level == 5 else 3.0)
        guard = time.monotonic() + 600  # only against a hung child: the wait itself is on the child's CPU clock
        while proc.poll() is None and _cpu_seconds(proc.pid) - start < work and time.monotonic() < guard:
            time.sleep(0.02)
        still_running = proc.poll() is None
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
            proc.wait()
    err = err.decode()
    assert first.startswith("mesh:"), (first, err)
    assert still_running, "the bake finished before SIGINT: make the mesh bigger"
    assert proc.returncode in (130, 2), err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 or all(line.startswith("meshshade: warning:") for line in lines[:-1]), err
    assert lines[-1].startswith("meshshade:") and "interrupted" in lines[-1]
    assert cli.snapshot(tmp_path) == before
    assert not list(tmp_path.glob(".*.tmp*"))


def test_keyboard_interrupt_during_write_removes_temp_file(good_mesh, cli, monkeypatch):
    """KeyboardInterrupt inside the atomic writer (the worst moment): exit 130, no output, no temp file."""
    import meshshade.io.transactions as mio  # where the outputs are renamed (os.replace)

    tmp = good_mesh.parent
    real_replace = mio.os.replace

    def interrupted(src, dst):
        assert Path(src).exists()  # the temporary file was fully written
        raise KeyboardInterrupt

    monkeypatch.setattr(mio.os, "replace", interrupted)
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake_argv(good_mesh, tmp / "o.ply"))
    monkeypatch.setattr(mio.os, "replace", real_replace)
    assert rc == 130 and "Traceback" not in err
    assert cli.snapshot(tmp) == before


@pytest.mark.parametrize("command", ["bake", "mc"])
@pytest.mark.parametrize("spec,needles", [
    ("directional:0,0,1", ("directional light 0", "reaches no vertex", "faces away",
                           "did you mean directional:0,0,-1")),
    ("point:0,0,-5", ("point light 0", "reaches no vertex", "faces away")),
])
def test_light_reaching_no_vertex_is_a_warning(tmp_path, cli, command, spec, needles):
    """A scene whose only light reaches nothing (the open plate faces +z, the light comes from below) would give an
    all-zero result: since issue 17 it is an error in bake and mc alike (one rule, light/samples.py
    check_lights_reach), raised before any transport work: exit 2, one line naming the light and why (with the
    reversed direction for a directional light), no output. A light among several that reaches nothing stays a
    warning (tests/cli/test_bad_values.py)."""
    xs = np.linspace(-5, 5, 11)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    F = [(i * 11 + j, (i + 1) * 11 + j, (i + 1) * 11 + j + 1) for i in range(10) for j in range(10)]
    F += [(i * 11 + j, (i + 1) * 11 + j + 1, i * 11 + j + 1) for i in range(10) for j in range(10)]
    mesh = tmp_path / "plate.ply"
    write_ply(mesh, V, np.array(F))
    before = cli.snapshot(tmp_path)
    rc, _, err = cli.run([command, str(mesh), *SKIN, "--light", spec, "--out", str(tmp_path / "o.ply"),
                          "--npz", str(tmp_path / "o.npz"), "-q"])
    cli.assert_clean_failure(rc, err, before, tmp_path, *needles)
