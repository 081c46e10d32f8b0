"""Folders: a batch's job folders, which appear whole or not at all, the files in a folder and their hashes, private
scratch folders, and log files appended to.

``job_folder`` writes a ``.<name>.part-<random>`` folder beside the final one and renames it on success; a process
killed meanwhile leaves only the ``.part`` folder, which ``remove_stale_parts`` removes. Renames and removals run
with SIGINT, SIGTERM and SIGHUP held (as in :mod:`meshshade.io.transactions`).
"""
from __future__ import annotations

import contextlib
import os
import re
import secrets
import tempfile
from pathlib import Path

from meshshade.errors import OutputError
from meshshade.io._messages import _one_line
from meshshade.io.transactions import _no_space_hint, _signals_deferred

__all__ = ["file_sha256", "folder_files", "job_folder", "remove_stale_parts", "scratch_folder", "remove_folder",
           "temp_path", "append_text"]

#: a job folder being written: ``.<name>.part-<random>`` beside the final ``<name>`` (meshshade.batch)
_PART = re.compile(r"^\.(.+)\.part-[0-9a-f]{8}$")


def file_sha256(path) -> str:
    """SHA-256 of a file's bytes (hex)."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def folder_files(folder) -> list[str]:
    """Relative paths (POSIX) of the regular files under ``folder``, sorted."""
    folder = Path(folder)
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def _remove_tree(path: Path) -> None:
    import shutil

    with _signals_deferred():
        shutil.rmtree(path, ignore_errors=True)


@contextlib.contextmanager
def job_folder(final):
    """Write a folder that appears whole or not at all: yields a new empty ``.<name>.part-<random>`` beside
    ``final``; on success it is renamed to ``final`` (an existing ``final``, from an earlier run with other
    parameters, is replaced only then); on any exception, KeyboardInterrupt included, it is removed. A process
    killed meanwhile leaves only the ``.part`` folder, which :func:`remove_stale_parts` removes."""
    final = Path(final)
    for _ in range(100):
        tmp = final.parent / f".{final.name}.part-{secrets.token_hex(4)}"
        try:
            os.mkdir(tmp)
            break
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(f"cannot create a folder in {final.parent}: "
                              f"{_no_space_hint(final.parent, exc)}") from None
    else:  # pragma: no cover
        raise OutputError(f"cannot create a temporary folder in {final.parent}")
    try:
        yield tmp
        with _signals_deferred():
            if final.exists():
                old = final.parent / f".{final.name}.part-{secrets.token_hex(4)}"
                os.replace(final, old)
                os.replace(tmp, final)
                import shutil

                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, final)
    except BaseException:
        _remove_tree(tmp)
        raise


def remove_stale_parts(folder, names=None) -> list[str]:
    """Remove the ``.<name>.part-*`` folders under ``folder`` left by killed jobs (only those of ``names`` when
    given); returns the removed folders' names."""
    folder = Path(folder)
    removed = []
    if not folder.is_dir():
        return removed
    for p in folder.iterdir():
        m = _PART.match(p.name)
        if m and p.is_dir() and (names is None or m.group(1) in names):
            _remove_tree(p)
            removed.append(p.name)
    return removed


# ------------------------------------------------------------------------------------------------ scratch space
# ------------------------------------------------------------------------------------------------ scratch space
def scratch_folder(prefix: str = "meshshade-") -> Path:
    """A new private folder in the system's temporary directory; the caller removes it (:func:`remove_folder`)."""
    try:
        return Path(tempfile.mkdtemp(prefix=prefix))
    except OSError as exc:
        raise OutputError(f"cannot create a temporary folder: {_one_line(exc)}") from None


def remove_folder(path) -> None:
    """Remove ``path`` and everything in it (missing: nothing to do)."""
    _remove_tree(Path(path))


def temp_path(name: str) -> Path:
    """``name`` in the system's temporary directory."""
    return Path(tempfile.gettempdir()) / name


def append_text(path, text: str) -> bool:
    """Append ``text`` to the log file ``path``; False (and nothing raised) when it cannot be written."""
    try:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(text)
        return True
    except OSError:
        return False
