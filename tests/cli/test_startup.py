"""Start-up (issue 32): ``meshshade --help``, each ``meshshade <cmd> --help`` and argument errors import nothing
heavy, and a stop signal while a command's heavy modules are imported is an interrupt like any other.

* What is imported is checked in a fresh child's ``sys.modules`` (deterministic, unlike a timing;
  ``tools/benchmarks/bench_startup.py`` measures the times): only the light half of the CLI
  (:mod:`meshshade.cli.arguments`, :mod:`meshshade.names`, ...), no numpy, numba, scipy or trimesh.
* The signal is sent while the child is inside those imports, synchronised on the child itself: either a finder put
  first on the child's ``sys.meta_path`` announces the first heavy import on stderr and holds it (the signal lands
  inside that import), or, with nothing added to the child, when the compiled extension of numpy, numba or scipy
  (the first is numpy's) appears in the child's memory map (``/proc/<pid>/maps``). Either way: exit 128 + the
  signal, one ``meshshade: interrupted`` line, no traceback, nothing written.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from meshshade.geometry.procedural import icosphere
from meshshade.io import write_ply

#: top-level packages that ``--help`` and argument errors must not import
HEAVY = ("numpy", "numba", "llvmlite", "scipy", "trimesh", "matplotlib", "dask", "distributed", "embreex",
         "OpenImageIO", "igl")
#: the meshshade modules they may import: the light half of the CLI and the names it is built from
LIGHT = ("meshshade", "meshshade.compiled_cache", "meshshade.errors", "meshshade.units", "meshshade.names",
         "meshshade.material_presets", "meshshade.cli", "meshshade.cli.main", "meshshade.cli.arguments")
#: only against a child that hangs; every wait is on an event of the child
GUARD = 300.0

SKIN_SUN = ["--material", "skin1", "--light", "directional:0,0,-1", "--model", "dipole"]


def _child(code: str, cwd, **kwargs) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1",
               PYTHONPATH=str(Path(__file__).resolve().parents[2]) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], env=env, cwd=str(cwd),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


def test_help_and_argument_errors_import_nothing_heavy(tmp_path):
    """``meshshade --help``, ``meshshade <cmd> --help`` for every command, argument errors (an unknown option, a
    bad choice, a bad number, a missing argument) and no command at all, in one fresh interpreter: their exit
    codes, and no heavy module imported by any of them."""
    code = f"""
        import contextlib, io, json, sys
        from meshshade.cli.main import COMMANDS, main
        runs = [["--help"], ["--version"], []] + [[c, "--help"] for c in COMMANDS] + [
            ["bake", "m.obj", "--bogus"], ["bake", "m.obj", "--model", "nope"], ["profile", "--samples", "x"],
            ["mc"], ["render", "m.obj", "--tonemap", "nope", "--out", "r"]]
        codes = []
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            for argv in runs:
                codes.append(main(argv))
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in {HEAVY!r} or m.startswith("meshshade"))
        print(json.dumps({{"codes": codes, "loaded": loaded, "commands": len(COMMANDS)}}))
    """
    proc = _child(code, tmp_path)
    out, err = proc.communicate(timeout=GUARD)
    assert proc.returncode == 0, err.decode()
    got = json.loads(out.decode().strip().splitlines()[-1])
    assert got["codes"] == [0, 0, 2] + [0] * got["commands"] + [2] * 5
    heavy = [m for m in got["loaded"] if m.split(".")[0] in HEAVY]
    assert heavy == [], f"--help or an argument error imported {heavy[:10]}"
    meshshade = [m for m in got["loaded"] if m.startswith("meshshade")]
    assert [m for m in meshshade if m not in LIGHT and not m.startswith("meshshade.cli.arguments.")] == []


def test_argument_errors_are_one_line_without_importing(tmp_path):
    """The one-line error and exit 2 of a bad choice, which the light half checks (the names come from
    :mod:`meshshade.names`, the list the bake itself uses)."""
    proc = _child("""
        import sys
        from meshshade.cli.main import main
        code = main(["bake", "m.obj", "--model", "nope", "--material", "skin1"])
        sys.stderr.write("heavy: " + str("numba" in sys.modules) + "\\n")
        sys.exit(code)
    """, tmp_path)
    _, err = proc.communicate(timeout=GUARD)
    lines = err.decode().strip().splitlines()
    assert proc.returncode == 2 and lines[-1] == "heavy: False", lines
    assert lines[0].startswith("meshshade: error: bake: argument --model: invalid choice: 'nope'") and len(lines) == 2


@pytest.fixture
def sphere(tmp_path) -> Path:
    V, F = icosphere(10.0, 2)
    write_ply(tmp_path / "s.ply", V, F)
    return tmp_path / "s.ply"


def _snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def _assert_interrupted(proc, err: str, sig, before: dict, folder: Path):
    assert proc.returncode == 128 + sig, (proc.returncode, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1].startswith("meshshade: interrupted"), err
    assert _snapshot(folder) == before  # no output, no temporary file


#: the child: a finder first on sys.meta_path says when the first heavy module starts to execute (is imported, not
#: merely looked up as compiled_cache looks up numba's version) and holds it there (a minute) until the signal; then
#: the program, as the console script runs it (main() with sys.argv)
HELD_IMPORT = """
    import importlib.abc, importlib.machinery, sys, time

    class HoldHeavyImport(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] not in {heavy!r}:
                return None
            spec = importlib.machinery.PathFinder.find_spec(name, path)
            if spec is not None and spec.loader is not None:
                execute = spec.loader.exec_module

                def held(module):
                    if self in sys.meta_path:
                        sys.meta_path.remove(self)
                        sys.stderr.write("test: importing " + name + "\\n")
                        time.sleep(60)
                    execute(module)

                spec.loader.exec_module = held
            return spec

    sys.meta_path.insert(0, HoldHeavyImport())
    sys.argv = ["meshshade"] + {argv!r}
    from meshshade.cli.main import main
    sys.exit(main())
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_the_heavy_imports_is_an_interrupt(sphere, sig):
    """Issue 32: Ctrl-C in the first second and a half (numba, scipy being imported) printed a KeyboardInterrupt
    traceback. The signal lands inside the first heavy import of ``meshshade bake``."""
    folder = sphere.parent
    before = _snapshot(folder)
    argv = ["bake", str(sphere), *SKIN_SUN, "--out", str(folder / "o.ply")]
    proc = _child(HELD_IMPORT.format(heavy=HEAVY, argv=argv), folder)
    try:
        first = proc.stderr.readline().decode()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=GUARD)
    finally:
        if proc.poll() is None:  # pragma: no cover - only when the child hangs
            proc.kill()
            proc.wait()
    assert first.startswith("test: importing "), first + err.decode()
    _assert_interrupted(proc, err.decode(), sig, before, folder)


#: a heavy library's compiled extension in a memory map
HEAVY_MAPPED = re.compile(r"/(numpy|numba|scipy)/\S*\.so")


def _maps(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return ""


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc/<pid>/maps (Linux)")
def test_ctrl_c_while_the_libraries_are_imported_is_an_interrupt(sphere, cli):
    """The same with nothing added to the child (``python -m meshshade.cli bake``): SIGINT as soon as the first
    heavy library's compiled extension is mapped into the child, i.e. while numpy (and then numba, scipy, trimesh,
    the kernels) is being imported, a second before any work."""
    folder = sphere.parent
    before = _snapshot(folder)
    proc = cli.popen(["bake", sphere, *SKIN_SUN, "--out", folder / "o.ply", "-q"], cwd=folder)
    try:
        guard = time.monotonic() + GUARD
        while proc.poll() is None and not HEAVY_MAPPED.search(_maps(proc.pid)) and time.monotonic() < guard:
            time.sleep(0.002)
        running = proc.poll() is None
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=GUARD)
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
            proc.wait()
    assert running, err.decode()
    _assert_interrupted(proc, err.decode(), signal.SIGINT, before, folder)
