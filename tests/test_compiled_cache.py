"""meshshade.compiled_cache: numba's on-disk cache lives in a folder named after a hash of all of meshshade's
sources, so an edit to a helper in one file recompiles its callers in other files. numba alone keys each cache
on the caller's own file and keeps running the old code (the control below shows it).

The end-to-end tests run subprocesses on a copy of the package with two probe modules added: ``_probe_a`` holds
an ``inline="always"`` helper and a plain compiled helper, ``_probe_b`` a cached function that calls both.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from meshshade import compiled_cache
from meshshade.compiled_cache import MARKER, PACKAGE_DIR, cache_dir_for, cache_key, prune, source_hash

PROBE_A = '''import numba


@numba.njit(cache=True, inline="always")
def inlined():
    return {value}


@numba.njit(cache=True)
def called():
    return {value}
'''
PROBE_B = '''import numba

from meshshade._probe_a import called, inlined


@numba.njit(cache=True)
def probe():
    return inlined() + 10 * called()
'''
#: run in a subprocess: what the import configured and what the compiled probe returns
SCRIPT = '''import json, os, sys
if "numba-first" in sys.argv:
    import numba
import meshshade
import numba
from meshshade.kernels.dipole import dipole_diffuse_reflectance
out = dict(file=meshshade.__file__, env=os.environ.get("NUMBA_CACHE_DIR"), config=numba.config.CACHE_DIR,
           kernel_cache=dipole_diffuse_reflectance._cache._cache_path)
if "probe" in sys.argv:
    from meshshade._probe_b import probe
    out.update(probe=probe(), probe_cache=probe._cache._cache_path)
print(json.dumps(out))
'''


def _env(tmp_path: Path, pythonpath: Path, **extra) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", MARKER)}
    # no bytecode: an edit within the same second and of the same size would otherwise import the stale .pyc
    env.update(PYTHONPATH=str(pythonpath), XDG_CACHE_HOME=str(tmp_path / "xdg"), PYTHONDONTWRITEBYTECODE="1", **extra)
    return env


def _run(env: dict[str, str], cwd: Path, *args: str) -> dict:
    # cwd: "python -c" puts the working directory first on sys.path, where a checkout's meshshade/ would win
    proc = subprocess.run([sys.executable, "-c", SCRIPT, *args], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture
def package_copy(tmp_path) -> Path:
    """``tmp_path/src/meshshade``: the package's sources with the probe modules; returns ``tmp_path/src``."""
    src = tmp_path / "src"
    shutil.copytree(PACKAGE_DIR, src / "meshshade", ignore=shutil.ignore_patterns("__pycache__"))
    (src / "meshshade" / "_probe_a.py").write_text(PROBE_A.format(value=1))
    (src / "meshshade" / "_probe_b.py").write_text(PROBE_B)
    return src


def test_configure_recompiles_callers_after_an_edit_in_another_file(tmp_path, package_copy):
    env = _env(tmp_path, package_copy)
    before = _run(env, tmp_path, "probe")
    assert Path(before["file"]).is_relative_to(package_copy)  # the copy, not the installed package
    assert before["probe"] == 11
    assert Path(before["env"]).name.startswith(source_hash(package_copy / "meshshade"))
    assert before["config"] == before["env"] and Path(before["probe_cache"]).is_relative_to(before["env"])

    (package_copy / "meshshade" / "_probe_a.py").write_text(PROBE_A.format(value=2))  # _probe_b.py untouched
    after = _run(env, tmp_path, "probe")
    assert after["probe"] == 22, "the caller kept the old helper's code"
    assert Path(after["env"]).name.startswith(source_hash(package_copy / "meshshade"))
    assert after["env"] != before["env"]


def test_control_numba_alone_keeps_stale_code_and_a_user_cache_dir_is_left_alone(tmp_path, package_copy):
    """With NUMBA_CACHE_DIR set by the user, meshshade leaves it alone, and numba's own per-file keying then runs
    the old helper after the edit. If numba ever notices on its own, the last assert fails: good news, and this
    control can go."""
    fixed = tmp_path / "fixed"
    env = _env(tmp_path, package_copy, NUMBA_CACHE_DIR=str(fixed))
    before = _run(env, tmp_path, "probe")
    assert before["env"] == before["config"] == str(fixed)
    assert Path(before["probe_cache"]).is_relative_to(fixed)
    assert before["probe"] == 11

    (package_copy / "meshshade" / "_probe_a.py").write_text(PROBE_A.format(value=2))
    after = _run(env, tmp_path, "probe")
    assert after["env"] == str(fixed)
    assert after["probe"] == 11, "numba now recompiles callers of an edited helper in another file by itself"


@pytest.mark.parametrize("order", ["meshshade-first", "numba-first"])
def test_import_points_numba_at_the_hash_of_the_current_sources(tmp_path, order):
    """Whether numba is imported after meshshade (it reads NUMBA_CACHE_DIR) or before (numba.config is set)."""
    keys = {cache_key(PACKAGE_DIR)}
    out = _run(_env(tmp_path, PACKAGE_DIR.parent), tmp_path, order)
    keys.add(cache_key(PACKAGE_DIR))  # before and after: other work may edit the sources meanwhile
    assert Path(out["file"]).parent == PACKAGE_DIR
    root = tmp_path / "xdg" / "meshshade" / "numba"
    assert out["env"] in {str(root / k) for k in keys}
    assert out["config"] == out["env"]
    assert Path(out["kernel_cache"]).is_relative_to(out["env"])  # numba's locator uses it
    assert (Path(out["env"]) / compiled_cache.LOCK_NAME).is_file()


def test_a_cache_dir_inherited_from_meshshade_is_replaced(tmp_path, package_copy):
    """A child process of a meshshade process inherits NUMBA_CACHE_DIR; when it runs other sources (another
    checkout) it must use its own folder, not take the parent's for the user's choice."""
    parent = str(tmp_path / "parent-key")
    out = _run(_env(tmp_path, package_copy, NUMBA_CACHE_DIR=parent, **{MARKER: parent}), tmp_path)
    assert out["env"] != parent
    assert Path(out["env"]).name.startswith(source_hash(package_copy / "meshshade"))


def _tiny_package(folder: Path) -> Path:
    (folder / "sub" / "__pycache__").mkdir(parents=True)
    (folder / "__init__.py").write_text('"""Tiny."""\n')
    (folder / "sub" / "__init__.py").write_text("")
    (folder / "sub" / "helper.py").write_text("def helper():\n    return 1\n")
    return folder


def test_source_hash_changes_with_any_source_change_only(tmp_path):
    pkg = _tiny_package(tmp_path / "pkg")
    h0 = source_hash(pkg)
    assert len(h0) == 16 and source_hash(_tiny_package(tmp_path / "elsewhere" / "pkg")) == h0  # location-free

    helper = pkg / "sub" / "helper.py"
    helper.write_text("def helper():\n    return 2\n")  # same size, new bytes
    assert source_hash(pkg) != h0
    helper.write_text("def helper():\n    return 1\n")  # back: contents count, modification times do not
    assert source_hash(pkg) == h0

    (pkg / "sub" / "__pycache__" / "helper.cpython-311.pyc").write_bytes(b"x")  # not sources
    (pkg / "sub" / "helper.nbi").write_bytes(b"x")
    (pkg / "notes.txt").write_text("x")
    assert source_hash(pkg) == h0

    (pkg / "new.py").write_text("")  # a new file, even empty
    assert source_hash(pkg) != h0
    (pkg / "new.py").unlink()
    (pkg / "sub" / "table.csv").write_text("x\n1.0\n")  # a runtime table (kernels/data/*.csv)
    h_table = source_hash(pkg)
    assert h_table != h0
    (pkg / "sub" / "table.csv").write_text("x\n1.5\n")
    assert source_hash(pkg) != h_table
    (pkg / "sub" / "table.csv").unlink()
    assert source_hash(pkg) == h0
    helper.rename(pkg / "sub" / "helper2.py")  # a rename
    assert source_hash(pkg) != h0


def test_source_hash_of_a_copy_of_meshshade_changes_with_one_edit(tmp_path):
    copy = tmp_path / "meshshade"
    shutil.copytree(PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    h0 = source_hash(copy)
    dipole = copy / "kernels" / "dipole.py"
    dipole.write_text(dipole.read_text().replace("fastmath=False", "fastmath=True", 1))
    assert source_hash(copy) != h0


def test_an_unwritable_user_cache_falls_back_to_a_private_temp_folder(tmp_path, monkeypatch):
    pkg = _tiny_package(tmp_path / "pkg")
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    folder = cache_dir_for(pkg, {"XDG_CACHE_HOME": str(not_a_folder)})
    assert folder == compiled_cache.temp_cache_root() / cache_key(pkg) and folder.is_dir()
    assert folder.is_relative_to(tmp_path / "tmp")
    if hasattr(os, "getuid"):  # a folder in the shared temporary directory that others may write is refused
        top = tmp_path / "tmp" / f"meshshade-{os.getuid()}"
        top.chmod(0o777)
        assert cache_dir_for(pkg, {"XDG_CACHE_HOME": str(not_a_folder)}) is None


def test_configure_without_a_usable_folder_warns_and_keeps_numba_default(tmp_path, monkeypatch):
    monkeypatch.setattr(compiled_cache, "cache_dir_for", lambda package_dir, environ: None)
    monkeypatch.setattr(numba.core.config, "CACHE_DIR", "inherited")  # restored afterwards
    environ = {"NUMBA_CACHE_DIR": "inherited", MARKER: "inherited"}
    with pytest.warns(RuntimeWarning, match="next to the sources"):
        assert compiled_cache.configure(tmp_path, environ) == ""
    assert environ == {} and numba.core.config.CACHE_DIR == ""


def test_prune_keeps_the_recent_the_idle_and_the_held(tmp_path):
    now = 1_000_000.0
    ages = {"k0": 0, "k1": 10, "k2": 20, "k3": 7200, "k4": 7300, "k5": 7400, "held": 7500}
    for name, age in ages.items():
        (tmp_path / name / "sub").mkdir(parents=True)
        os.utime(tmp_path / name, (now - age, now - age))
    (tmp_path / "a-file").write_text("")
    fd = None
    if compiled_cache.fcntl is not None:
        fd = os.open(tmp_path / "held" / compiled_cache.LOCK_NAME, os.O_RDONLY | os.O_CREAT)
        compiled_cache.fcntl.flock(fd, compiled_cache.fcntl.LOCK_SH)  # a running process uses "held"
    try:
        removed = prune(tmp_path, keep=2, min_idle_s=3600, now=now)
    finally:
        if fd is not None:
            os.close(fd)
    expected = {"k3", "k4", "k5"} | (set() if fd is not None else {"held"})
    assert set(removed) == expected  # k2 is beyond keep=2 but was used 20 s ago
    assert {p.name for p in tmp_path.iterdir()} == set(ages) - expected | {"a-file"}
    assert prune(tmp_path / "missing") == []  # never raises


@pytest.mark.skipif(compiled_cache.fcntl is None, reason="the in-use lock needs POSIX advisory locks")
def test_prune_spares_the_folder_of_a_running_process(tmp_path):
    env = _env(tmp_path, PACKAGE_DIR.parent)
    code = "import os, sys, meshshade; print(os.environ['NUMBA_CACHE_DIR'], flush=True); sys.stdin.readline()"
    with subprocess.Popen([sys.executable, "-c", code], env=env, cwd=tmp_path, stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True) as proc:
        try:
            folder = Path(proc.stdout.readline().strip())
            assert folder.is_dir()
            assert prune(folder.parent, keep=0, min_idle_s=0) == []  # held by the running process
            assert folder.is_dir()
        finally:
            proc.communicate("\n", timeout=60)
    assert prune(folder.parent, keep=0, min_idle_s=0) == [folder.name]  # the process has exited
    assert not folder.exists()
