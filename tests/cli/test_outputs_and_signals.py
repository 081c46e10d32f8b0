"""Outputs, signals, standard output and arguments: the CLI-wide families of the second fault corpus (issue 17).

* a command's outputs succeed or fail together (``meshshade.io.output_transaction``), on a really full disk
  (a small tmpfs) and with a failing rename; output folders made by a failed run are removed;
* outputs that are devices, pipes or folders, or whose extension is not what is written, are refused up front;
* SIGTERM and SIGHUP act like Ctrl-C (exit 128 + signal, one line, no temporary file), in a child process
  synchronised on its own output and CPU clock, and in-process at the worst moment (inside a writer);
* standard output on a full device is one error line; a closed pipe is a quiet exit 141;
* argparse: negative number lists, counts in exponent notation, one-line errors.
"""
from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import meshshade.io as mio
import meshshade.io.images as io_images
import meshshade.io.ply as io_ply
import meshshade.io.transactions as io_transactions
from meshshade.errors import OutputError
from meshshade.geometry.procedural import icosphere
from meshshade.io import output_transaction, write_npz, write_ply, write_text

SKIN = ["--material", "skin1"]
SUN = ["--light", "directional:0,0,-1"]


@pytest.fixture
def sphere(tmp_path) -> Path:
    V, F = icosphere(10.0, 2)
    p = tmp_path / "s.ply"
    write_ply(p, V, F)
    return p


def _bake(mesh, out, *extra):
    return ["bake", mesh, *SKIN, *SUN, "--model", "dipole", "--out", out, "-q", *extra]


# --------------------------------------------------------------------------------------------- together or none
def test_second_output_on_a_full_disk_leaves_neither(sphere, cli, tiny_disk):
    """--npz onto a really full file system: the PLY, written first, does not appear either."""
    disk = tiny_disk(0)
    tmp = sphere.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake(sphere, tmp / "o.ply", "--npz", disk / "o.npz"))
    line = cli.assert_clean_failure(rc, err, before, tmp)
    assert "no space left on device" in line and str(disk / "o.npz") in line and ".tmp" not in line


def test_full_disk_during_an_exr_write_says_so(sphere, cli, tiny_disk):
    """OpenImageIO's own message names the temporary file and "Failed OpenEXR write": the user reads the cause."""
    disk = tiny_disk(2048)
    before = cli.snapshot(sphere.parent)
    rc, _, err = cli.run(["render", sphere, *SKIN, *SUN, "--model", "dipole", "--width", 64, "--height", 64,
                          "--spp", 1, "--out", disk / "r", "-q"])
    line = cli.assert_clean_failure(rc, err, before, sphere.parent)
    assert "no space left on device" in line and ".tmp" not in line, line


def test_transaction_publishes_all_or_nothing(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.npz"
    a.write_text("previous")
    with pytest.raises(OutputError, match="does not exist"):
        with output_transaction():
            write_text(a, "new")
            assert a.read_text() == "previous"  # nothing is published before the end
            write_npz(tmp_path / "no" / "b.npz", x=np.zeros(3))
    assert a.read_text() == "previous" and sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]
    with output_transaction():
        write_text(a, "new")
        write_npz(b, x=np.arange(3))
    assert a.read_text() == "new" and np.load(b)["x"].tolist() == [0, 1, 2]


def test_failed_rename_restores_the_outputs_already_replaced(tmp_path, monkeypatch):
    """The commit's second rename fails: the first output gets its previous content back; no stray files."""
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("old a")
    b.write_text("old b")
    real_replace, calls = os.replace, []

    def second_fails(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(io_transactions.os, "replace", second_fails)
    with pytest.raises(OutputError, match="b.csv"):
        with output_transaction():
            write_text(a, "new a")
            write_text(b, "new b")
    monkeypatch.setattr(io_transactions.os, "replace", real_replace)
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv"]


@pytest.mark.parametrize("command", ["compare", "demo"])
def test_failed_run_removes_the_folder_it_created(sphere, cli, command):
    """A compare whose light misses, and a demo interrupted in its first write: no empty or half-filled folder."""
    tmp = sphere.parent
    out = tmp / "new" / "folder"
    before = cli.snapshot(tmp)
    if command == "compare":
        rc, _, err = cli.run(["compare", sphere, *SKIN, "--light", "beam:30,30,40:0,0,-1", "--width", 16,
                              "--height", 16, "--models", "dipole,curved", "--out", out, "-q"])
        cli.assert_clean_failure(rc, err, before, tmp, "misses")
    else:
        calls = []

        def interrupt_second_write(*args, **kwargs):  # the demo writes figure1_potato.exr, then .png: stop there
            calls.append(args)
            if len(calls) == 2:
                os.kill(os.getpid(), signal.SIGTERM)
            return real(*args, **kwargs)

        real = io_images._write_image
        io_images._write_image = interrupt_second_write
        try:
            rc, _, err = cli.run(["demo", "--small", "--out", out])
        finally:
            io_images._write_image = real
        cli.assert_clean_failure(rc, err, before, tmp, "SIGTERM", code=143)
    assert not (tmp / "new").exists()


# --------------------------------------------------------------------------------------------- what --out names
def test_device_and_pipe_outputs_are_refused(sphere, cli):
    tmp = sphere.parent
    fifo = tmp / "pipe.ply"
    os.mkfifo(fifo)
    before = cli.snapshot(tmp) | {}
    for out in (fifo, "/dev/null"):  # the pipe first: a planted bug must not get to replace /dev/null
        rc, _, err = cli.run(_bake(sphere, out))
        cli.assert_clean_failure(rc, err, before, tmp, str(out), "not a regular file")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode) and stat.S_ISFIFO(os.stat(fifo).st_mode)


@pytest.mark.parametrize("argv,needles", [
    (["bake", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/x.obj"], ["x.obj", ".ply"]),
    (["bake", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/x.ply", "--npz", "{tmp}/x.dat"], ["--npz", ".npz"]),
    (["mc", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/m.ply", "--summary", "{tmp}/m.txt"], ["--summary", ".json"]),
    (["check", "{mesh}", "--json", "{tmp}/c.txt"], ["--json", ".json"]),
    (["render", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/r.jpg"], ["r.jpg", ".exr"]),
    (["render", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/renders/"], ["folder", "base name"]),
    (["render", "{mesh}", *SKIN, *SUN, "--out", "{tmp}"], ["folder"]),
])
def test_output_names_that_do_not_say_what_is_written(sphere, cli, argv, needles):
    tmp = sphere.parent
    (tmp / "renders").mkdir()
    before = cli.snapshot(tmp)
    rc, _, err = cli.run([a.format(mesh=sphere, tmp=tmp) for a in argv])
    cli.assert_clean_failure(rc, err, before, tmp, *needles)


def test_writers_refuse_values_a_file_cannot_hold(tmp_path):
    """Beyond float32 (the PLY's and EXR's storage), infinite or NaN: an error naming the file, nothing written."""
    V, F = icosphere(1.0, 0)
    with pytest.raises(OutputError, match=r"o\.ply: vertex property radiance_r has 1 value"):
        write_ply(tmp_path / "o.ply", V, F, {"radiance_r": np.r_[1e39, np.zeros(len(V) - 1)]})
    image = np.zeros((4, 4, 4), np.float32)
    image[1, 2, 0] = np.nan
    with pytest.raises(OutputError, match=r"o\.exr: the image has 1 value"):
        mio.write_exr(tmp_path / "o.exr", image)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------- signals
def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_act_like_ctrl_c(tmp_path, cli, sig):
    """The signal 1 s of the child's CPU time after it announced the bake (its "mesh:" line): exit 128 + signal,
    one line naming it, nothing left. Level 5 with marble under a directional light by the curved surface model
    (exact geodesic neighbourhoods) takes tens of seconds, so the bake is always mid-way (the default volume model
    bakes it in about a second, which would leave the signal to the writer: tested below); both points are events
    of the child, not wall-clock delays."""
    V, F = icosphere(30.0, 5)
    mesh = tmp_path / "big.ply"
    write_ply(mesh, V, F)
    before = cli.snapshot(tmp_path)
    proc = cli.popen(["bake", mesh, "--material", "marble", "--light", "directional:0.3,-0.5,-1", "--model",
                      "curved", "--out", tmp_path / "o.ply", "--npz", tmp_path / "o.npz"], cwd=tmp_path)
    try:
        first = proc.stdout.readline().decode()
        start = _cpu_seconds(proc.pid)
        guard = time.monotonic() + 600  # only against a hung child
        while proc.poll() is None and _cpu_seconds(proc.pid) - start < 1.0 and time.monotonic() < guard:
            time.sleep(0.02)
        running = proc.poll() is None
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
            proc.wait()
    assert first.startswith("mesh:") and running
    cli.assert_clean_failure(proc.returncode, err.decode(), before, tmp_path, signal.Signals(sig).name,
                             code=128 + sig)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_signal_inside_a_writer_leaves_no_temporary_file(sphere, cli, monkeypatch, sig):
    """A real signal delivered while the PLY's bytes are being written (the moment the hidden temporary file
    exists): the file is removed, the previous output kept, exit 128 + signal. In-process: the CLI's handlers
    are installed by main()."""
    tmp = sphere.parent
    (tmp / "o.ply").write_bytes(b"previous result")

    def open_then_signal(file, *args, **kwargs):  # io.ply.write_ply opens the temporary file to fill it
        assert Path(file).name.startswith(".o.ply.") and Path(file).exists(), file
        os.kill(os.getpid(), sig)
        return open(file, *args, **kwargs)

    monkeypatch.setattr(io_ply, "open", open_then_signal, raising=False)
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake(sphere, tmp / "o.ply"))
    cli.assert_clean_failure(rc, err, before, tmp, "interrupted", code=128 + sig)
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL  # main() put the previous handlers back


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_inside_a_numba_cache_load_is_still_an_interrupt(sphere, cli, monkeypatch, sig):
    """A signal whose handler runs while numba unpickles a cached kernel (a C call back into Python) leaves that
    call as a SystemError caused by the interrupt (seen when SIGTERM landed 1 s into a bake): still one line and
    exit 128 + signal, nothing written. In-process, the bake raising what numba raised there."""
    import meshshade.cli.bake as cli_bake
    from meshshade.cli.main import Interrupted

    def numba_load_interrupted(*args, **kwargs):
        try:
            if sig == signal.SIGINT:
                raise KeyboardInterrupt
            raise Interrupted(sig)
        except BaseException as exc:
            raise SystemError("<function _numba_unpickle> returned a result with an exception set") from exc

    monkeypatch.setattr(cli_bake, "bake", numba_load_interrupted)
    tmp = sphere.parent
    before = cli.snapshot(tmp)
    rc, _, err = cli.run(_bake(sphere, tmp / "o.ply"))
    cli.assert_clean_failure(rc, err, before, tmp, "interrupted", code=128 + sig)


def test_a_system_error_without_a_signal_is_not_an_interrupt(sphere, cli, monkeypatch):
    import meshshade.cli.bake as cli_bake

    def broken(*args, **kwargs):
        raise SystemError("a real bug")

    monkeypatch.setattr(cli_bake, "bake", broken)
    with pytest.raises(SystemError, match="a real bug"):
        cli.run(_bake(sphere, sphere.parent / "o.ply"))


# --------------------------------------------------------------------------------------------- standard output
def test_stdout_on_a_full_device_is_one_line(tmp_path, cli):
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "meshshade.cli", "profile", *SKIN, "--distances", "1,2"],
                              stdout=full, stderr=subprocess.PIPE, env=cli.env(), cwd=tmp_path, timeout=120)
    err = proc.stderr.decode()
    assert proc.returncode == 2 and "Traceback" not in err, err
    assert err.strip().splitlines() == ["meshshade: error: cannot write to standard output: No space left on device"]


def test_closed_pipe_is_a_quiet_exit_141(tmp_path, cli):
    """``meshshade profile ... | head -c 100``: 20 000 rows do not fit a pipe's buffer; the reader leaves."""
    proc = cli.popen(["profile", *SKIN, "--models", "dipole", "--samples", "20000"], cwd=tmp_path)
    proc.stdout.read(100)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141 and err == "", err


# --------------------------------------------------------------------------------------------- arguments
def test_negative_number_lists_are_values(cli):
    rc, out, err = cli.run(["profile", *SKIN, "--models", "dipole", "--azimuth", "-90,0,90", "--distances",
                            "1"])
    assert rc == 0, err
    assert "phi=-90" in out and "phi=90" in out


def test_counts_in_exponent_notation(sphere, cli):
    tmp = sphere.parent
    rc, _, err = cli.run(["mc", sphere, *SKIN, *SUN, "--photons", "2e3", "--out", tmp / "m.ply", "--summary",
                          tmp / "m.json", "-q"])
    assert rc == 0, err
    assert '"photons": 2000' in (tmp / "m.json").read_text().replace("_per_channel", "")


@pytest.mark.parametrize("argv,needle", [
    (["bake", "{mesh}", *SKIN, "--out", "{tmp}/o.ply"], "--light"),
    (["bake", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/o.ply", "--model", "bogus"], "invalid choice"),
    (["bake", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/o.ply", "--frobnicate"], "--frobnicate"),
    (["bake", *SKIN, *SUN], "required"),
    (["mc", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/m.ply", "--photons", "1.5"], "whole number"),
    (["mc", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/m.ply", "--photons", "8"], ">= 16"),
    (["mc", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/m.ply", "--time-budget", "nan"], "finite"),
    (["render", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/r", "--width", "0"], "--width"),
    (["render", "{mesh}", *SKIN, *SUN, "--out", "{tmp}/r", "--bias", "inf"], "--bias"),
    (["profile", *SKIN, "--azimuth", "nan"], "--azimuth"),
    (["profile", *SKIN, "--distances", "1,inf"], "--distances"),
    (["frobnicate"], "invalid choice"),
])
def test_argument_errors_are_one_line(sphere, cli, argv, needle):
    tmp = sphere.parent
    before = cli.snapshot(tmp)
    rc, out, err = cli.run([a.format(mesh=sphere, tmp=tmp) for a in argv])
    line = cli.assert_clean_failure(rc, err, before, tmp, needle)
    assert len(err.strip().splitlines()) == 1 and out == "" and "usage:" not in err, err
    assert line.startswith("meshshade: error:")


@pytest.mark.slow  # ~8 s: imports, a bake and 6 million camera rays before memory runs out
def test_out_of_memory_is_one_line(sphere, cli):
    """A real allocation failure: the child may address 1.5 GiB (RLIMIT_AS, as a batch system's memory limit),
    a 2500 x 2500 render needs more. One line naming the allocation, no traceback, no output."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))

    tmp = sphere.parent
    before = cli.snapshot(tmp)
    proc = cli.popen(["render", sphere, *SKIN, *SUN, "--model", "dipole", "--width", 2500, "--height", 2500,
                      "--spp", 1, "--out", tmp / "big", "-q"], cwd=tmp, preexec_fn=limit)
    _, err = proc.communicate(timeout=300)
    cli.assert_clean_failure(proc.returncode, err.decode(), before, tmp, "out of memory", "allocate")


@pytest.mark.parametrize("command", ["compare", "demo"])
def test_output_folder_that_cannot_be_made(sphere, cli, command):
    """Under /proc (no new entries there) and under a file: one line naming the folder."""
    tmp = sphere.parent
    (tmp / "file").write_text("x")
    for out in ("/proc/meshshade-test/out", tmp / "file" / "out"):
        before = cli.snapshot(tmp)
        argv = (["demo", "--small"] if command == "demo" else
                ["compare", sphere, *SKIN, *SUN, "--width", 16, "--height", 16, "-q"]) + ["--out", out]
        rc, _, err = cli.run(argv)
        cli.assert_clean_failure(rc, err, before, tmp, str(out))


def test_quiet_prints_only_what_the_command_exists_to_print(sphere, tmp_path, capsys):
    """--quiet: no notes and no "wrote ..." lines; profile's table, check's report and compare's statistics stay."""
    from meshshade.cli.main import main

    runs = [
        (["bake", str(sphere), "--material", "marble", "--light", "directional:0,0,-1", "--model", "dipole",
          "--out", str(tmp_path / "b.ply")], None),
        (["render", str(sphere), "--material", "marble", "--light", "directional:0,0,-1", "--model", "dipole",
          "--width", "24", "--height", "24", "--out", str(tmp_path / "r")], None),
        (["profile", "--material", "marble", "--distances", "1,2", "--csv", str(tmp_path / "p.csv")], None),
        (["compare", str(sphere), "--material", "marble", "--light", "directional:0,0,-1", "--models",
          "dipole,curved", "--width", "24", "--height", "24", "--out", str(tmp_path / "c")], "max_rel_diff"),
        (["profile", "--material", "marble", "--distances", "1,2"], "distance_mm"),
    ]
    for argv, kept in runs:
        assert main([argv[0], "--quiet", *argv[1:]]) == 0, argv
        out = capsys.readouterr().out
        if kept is None:
            assert out == "", (argv[0], out)
        else:
            assert kept in out and "wrote" not in out, (argv[0], out)


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_signal_after_the_outputs_are_written_says_so(sig):
    """Issue 32: a stop signal while the finished process winds down (its outputs committed) is not silent."""
    code = ("import os, signal, sys, time\n"
            "from meshshade.cli.main import main\n"
            "sys.argv = ['meshshade', 'materials']\n"
            "rc = main()\n"
            f"os.kill(os.getpid(), signal.{sig})\n"
            "time.sleep(5)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2])))
    number = int(getattr(signal, sig))
    assert out.returncode == 128 + number, (out.returncode, out.stderr)
    assert out.stderr.strip().splitlines()[-1] == f"meshshade: {sig} after the outputs were written (they are complete)"
    assert "Traceback" not in out.stderr and "skin1" in out.stdout


def test_main_with_explicit_arguments_leaves_the_signal_handlers_alone(cli):
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT)}
    rc, _, _ = cli.run(["materials"])
    assert rc == 0
    assert {s: signal.getsignal(s) for s in before} == before
