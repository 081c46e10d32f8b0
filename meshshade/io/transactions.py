"""Output transactions: every output is written atomically, and the outputs of one command appear together or not
at all.

Every output is written atomically (``atomic_write``: a temporary file in the target directory, then
``os.replace``; the temporary file is removed on any exception, KeyboardInterrupt included), so a failed or
interrupted run never leaves a partial file. Inside ``output_transaction()`` (the CLI runs every command in one)
the renames wait for the end of the block, so several outputs appear together or not at all, and folders made by
``output_dir`` are removed again on failure. ``check_output_path`` refuses an output that is one of the inputs,
a folder, a device, pipe or socket (which a rename would replace by a regular file), or a name whose extension is
not the format written. A full disk is reported as such. Renames and removals run with SIGINT, SIGTERM and SIGHUP
held; ``detached()`` runs a block outside any transaction (what it writes lands at once).
"""
from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import secrets
import signal
import stat
import sys
from pathlib import Path

from meshshade.errors import OutputError
from meshshade.io._messages import _one_line

__all__ = ["atomic_write", "output_transaction", "check_output_path", "output_dir", "discard_stdout", "detached"]


def check_output_path(out, inputs=(), *, suffixes=None, option: str = "--out") -> Path:
    """Check that ``out`` can be written and is none of ``inputs``; return it as a Path.

    ``suffixes``: the file extensions the caller writes (e.g. ``(".ply",)``; compared case-insensitively); an
    output named otherwise is refused, naming ``option``, rather than written in a format its name does not say.

    Raises
    ------
    OutputError
        The output is an existing directory or another non-regular file (a device such as ``/dev/null``, a pipe, a
        socket: atomic replacement would put a regular file in its place), its directory is missing or not
        writable, or it resolves to the same file as one of ``inputs`` (symbolic and hard links included).
    """
    out = Path(out)
    if out.is_dir() or str(out).endswith(("/", os.sep)):
        raise OutputError(f"output {out} is a directory; give a file name")
    try:
        mode = out.stat().st_mode
    except OSError:
        mode = None  # does not exist yet (or cannot be inspected: the directory checks below report that)
    if mode is not None and not stat.S_ISREG(mode):
        raise OutputError(f"output {out} exists and is not a regular file (a device, pipe or socket); "
                          "give a file name")
    directory = out.parent if str(out.parent) else Path(".")
    if not directory.is_dir():
        raise OutputError(f"output directory does not exist: {directory}")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise OutputError(f"output directory is not writable: {directory}")
    target = out.resolve()
    for inp in inputs:
        inp = Path(inp)
        same = target == inp.resolve()
        if not same and out.exists() and inp.exists():
            with contextlib.suppress(OSError):
                same = os.path.samefile(out, inp)
        if same:
            raise OutputError(f"output {out} is the same file as input {inp}; refusing to overwrite an input")
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise OutputError(f"{option} {out}: this output is written as {' or '.join(suffixes)}; give a name ending "
                          f"in {' or '.join(suffixes)}")
    return out


def output_dir(path, option: str = "--out") -> Path:
    """Create the output directory ``path`` (parents too; an existing directory is used as it is); return it.

    ``option`` names the command-line option the path came from, for the error message. Inside
    :func:`output_transaction` the folders created here are removed again if the transaction fails (they then
    hold nothing: every file written into them was still a temporary file).

    Raises
    ------
    OutputError
        ``path`` exists and is not a directory, or it cannot be created (one line).
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{option} {out} exists and is not a directory")
    missing = []
    parent = out
    while not parent.exists() and parent != parent.parent:
        missing.append(parent)
        parent = parent.parent
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output folder {out}: {exc.strerror or _one_line(exc)}") from None
    txn = _TRANSACTION.get()
    if txn is not None:
        txn.created_dirs.extend(missing)  # deepest first: the order rmdir needs
    return out


def discard_stdout() -> None:
    """Point file descriptor 1 at the null device, so that the interpreter's last flush of a standard output that
    failed (a full device, a closed pipe) cannot fail again at exit."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


# ----------------------------------------------------------------------------------------------- transactions
_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextlib.contextmanager
def _signals_deferred():
    """Hold SIGINT, SIGTERM and SIGHUP while files are renamed or removed, so an interrupt never lands between
    two renames of one commit or rollback; a signal that arrives meanwhile is delivered right after."""
    block = getattr(signal, "pthread_sigmask", None)
    if block is None:  # pragma: no cover - not POSIX
        yield
        return
    old = block(signal.SIG_BLOCK, _SIGNALS)
    try:
        yield
    finally:
        block(signal.SIG_SETMASK, old)


class _OutputSet:
    """The files and folders one :func:`output_transaction` will publish together."""

    def __init__(self):
        self.pending: dict[Path, Path] = {}  # final path -> fully written temporary file beside it
        self.created_dirs: list[Path] = []

    def add(self, tmp: Path, path: Path) -> None:
        older = self.pending.pop(path, None)
        if older is not None:  # the same output written twice: the last one counts
            with contextlib.suppress(OSError):
                os.unlink(older)
        self.pending[path] = tmp

    def rollback(self) -> None:
        with _signals_deferred():
            for tmp in self.pending.values():
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            self.pending.clear()
            for d in self.created_dirs:
                with contextlib.suppress(OSError):  # not empty (someone else's file): leave it
                    os.rmdir(d)

    def commit(self) -> None:
        """Rename every temporary file onto its output. If one rename fails, the outputs already replaced get
        their previous content back (kept as hard links until the end) and the error is raised."""
        with _signals_deferred():
            done: list[tuple[Path, Path | None]] = []
            try:
                for path, tmp in self.pending.items():
                    backup = None
                    if path.exists():
                        backup = path.with_name(f".{path.name}.{secrets.token_hex(4)}.bak")
                        try:
                            os.link(path, backup)
                        except OSError:  # no hard links on this file system: the old content cannot be restored
                            backup = None
                    try:
                        os.replace(tmp, path)
                    except BaseException:
                        if backup is not None:
                            with contextlib.suppress(OSError):
                                os.unlink(backup)
                        raise
                    done.append((path, backup))
            except BaseException as exc:
                for published, backup in reversed(done):
                    with contextlib.suppress(OSError):
                        if backup is not None:
                            os.replace(backup, published)
                        else:
                            os.unlink(published)
                self.rollback()
                if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                    hint = _no_space_hint(path.parent if str(path.parent) else Path("."), exc)
                    raise OutputError(f"could not write {path}: {hint}") from exc
                raise
            for _path, backup in done:
                if backup is not None:
                    with contextlib.suppress(OSError):
                        os.unlink(backup)
            self.pending.clear()


_TRANSACTION: contextvars.ContextVar[_OutputSet | None] = contextvars.ContextVar("meshshade_outputs",
                                                                                  default=None)


@contextlib.contextmanager
def output_transaction():
    """Make every output written inside the block appear together at its end, or none of them.

    Each writer (:func:`atomic_write` and everything built on it) still writes a complete temporary file beside its
    output, but the final renames wait for the end of the block; folders made by :func:`output_dir` inside the
    block are removed again on failure. On any exception (KeyboardInterrupt and the CLI's SIGTERM/SIGHUP
    included) the temporary files and new folders are removed, and no output, old or new, is touched. Renames and
    removals run with SIGINT/SIGTERM/SIGHUP held. Nested blocks join the outermost one. The CLI runs every command
    in one transaction, so a command's outputs succeed or fail together.

    Example
    -------
    >>> with output_transaction():                   # doctest: +SKIP
    ...     write_mesh_ply("out.ply", mesh, props)
    ...     write_npz("out.npz", radiance=rad)       # a full disk here: out.ply is not written either
    """
    if _TRANSACTION.get() is not None:
        yield
        return
    txn = _OutputSet()
    token = _TRANSACTION.set(txn)
    try:
        yield
    except BaseException:
        txn.rollback()
        raise
    finally:
        _TRANSACTION.reset(token)
    txn.commit()


@contextlib.contextmanager
def detached():
    """Run the block outside any :func:`output_transaction`: what it writes lands at once (a batch's manifest and
    job folders, which must survive the batch being stopped half-way)."""
    token = _TRANSACTION.set(None)
    try:
        yield
    finally:
        _TRANSACTION.reset(token)


def _no_space_hint(directory: Path, exc: BaseException | str) -> str:
    """``exc`` as one line; when the file system of ``directory`` is (nearly) full, say so plainly."""
    text = exc if isinstance(exc, str) else _one_line(exc)
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return "no space left on device"
    try:
        st = os.statvfs(directory)
        free = st.f_bavail * st.f_frsize
    except OSError:
        return text
    return f"no space left on device ({free} bytes free)" if free < 1 << 20 else text


@contextlib.contextmanager
def atomic_write(path):
    """Context manager yielding a temporary path next to ``path``; on success it replaces ``path``.

    The temporary file (``.<name>.<random>.tmp<suffix>``, same directory, so the final ``os.replace`` is atomic
    and writers that choose a format by extension still work) is created empty with the usual permissions
    (0o666 minus the umask). On any exception, KeyboardInterrupt included, it is removed and ``path`` is left
    untouched. ``OSError`` while writing becomes ``OutputError`` with one line (a full disk says so). Inside
    :func:`output_transaction` the final rename waits for the end of the transaction.

    Example
    -------
    >>> with atomic_write("out.ply") as tmp:       # doctest: +SKIP
    ...     tmp.write_bytes(data)
    """
    path = Path(path)
    check_output_path(path)
    directory = path.parent if str(path.parent) else Path(".")
    for _ in range(100):
        tmp = directory / f".{path.name}.{secrets.token_hex(4)}.tmp{path.suffix}"
        try:
            os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
            break
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(f"cannot create a file in {directory}: {_no_space_hint(directory, exc)}") from exc
    else:  # pragma: no cover - 100 collisions of a 32-bit random name
        raise OutputError(f"cannot create a temporary file in {directory}")
    txn = _TRANSACTION.get()
    try:
        yield tmp
        if txn is None:
            with _signals_deferred():
                os.replace(tmp, path)
        else:
            txn.add(tmp, path)
    except BaseException as exc:
        with _signals_deferred(), contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OutputError):
            raise OutputError(str(exc).replace(str(tmp), str(path))) from exc.__cause__
        if isinstance(exc, OSError):
            raise OutputError(f"could not write {path}: {_no_space_hint(directory, exc)}") from exc
        raise
