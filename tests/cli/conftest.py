"""Fixtures of the command-line corpus: run the CLI in-process or as a child, snapshot a folder, and the one
assertion every bad-input case makes (``cli.assert_clean_failure``).

A clean failure is: exit code 2 (or ``rc`` given), no "Traceback", exactly one ``meshshade: error:`` line last
on stderr (``meshshade: warning:`` lines may precede it) that names the problem (``needles``), and the folder
byte-identical to its snapshot: no output, no temporary file (``.*.tmp*``), inputs untouched.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from meshshade.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def snapshot(directory: Path) -> dict:
    """Every entry under ``directory`` (recursively, hidden ones too) -> its bytes (None for folders)."""
    directory = Path(directory)
    return {str(p.relative_to(directory)): (p.read_bytes() if p.is_file() else None)
            for p in sorted(directory.rglob("*"))}


class CLI:
    """The CLI as a test sees it (``cli`` fixture)."""

    snapshot = staticmethod(snapshot)

    def __init__(self, capsys):
        self._capsys = capsys

    def run(self, argv) -> tuple[int, str, str]:
        """``main(argv)`` in this process: (exit code, stdout, stderr)."""
        self._capsys.readouterr()
        rc = main([str(a) for a in argv])
        cap = self._capsys.readouterr()
        return rc, cap.out, cap.err

    @staticmethod
    def env() -> dict:
        """Environment of a child ``python -m meshshade.cli``: unbuffered, this checkout first on the path."""
        return dict(os.environ, PYTHONUNBUFFERED="1",
                    PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))

    def popen(self, argv, cwd, **kwargs) -> subprocess.Popen:
        """``python -m meshshade.cli ARGV`` as a child with pipes for stdout and stderr."""
        kwargs.setdefault("stdout", subprocess.PIPE)
        kwargs.setdefault("stderr", subprocess.PIPE)
        return subprocess.Popen([sys.executable, "-m", "meshshade.cli", *map(str, argv)], env=self.env(),
                                cwd=str(cwd), **kwargs)

    @staticmethod
    def assert_clean_failure(rc, err, before: dict, directory: Path, *needles, code: int = 2) -> str:
        """The clean-failure contract (module docstring); returns the error line."""
        assert rc == code, err
        assert "Traceback" not in err, err
        lines = err.strip().splitlines()
        assert lines, "no error line"
        assert all(line.startswith("meshshade: warning:") for line in lines[:-1]), err
        assert lines[-1].startswith("meshshade: error:") or (code > 128 and "interrupted" in lines[-1]), err
        for needle in needles:
            assert needle.lower() in lines[-1].lower(), (needle, lines[-1])
        after = snapshot(directory)
        assert after == before, sorted(set(after) ^ set(before)) or "an existing file changed"
        return lines[-1]


@pytest.fixture
def cli(capsys) -> CLI:
    return CLI(capsys)


@pytest.fixture
def tiny_disk(tmp_path):
    """A real, nearly full file system: a tmpfs of a few kB mounted at ``tmp_path / "disk"`` (needs root, as in
    CI and the developers' machines; skipped with the reason elsewhere). Call it with the free bytes wanted."""
    mounts = []

    def make(free_bytes: int = 0) -> Path:
        point = tmp_path / f"disk{len(mounts)}"
        point.mkdir()
        size_kb = max(4, -(-free_bytes // 4096) * 4 + 4)
        proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(point)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            pytest.skip(f"cannot mount a small tmpfs here ({proc.stderr.strip() or 'not root'})")
        mounts.append(point)
        st = os.statvfs(point)
        filler = st.f_bavail * st.f_frsize - free_bytes
        if filler > 0:
            with open(point / "filler", "wb") as fh:
                fh.write(b"\0" * filler)
        return point

    yield make
    for point in mounts:
        subprocess.run(["umount", "-l", str(point)], capture_output=True)
