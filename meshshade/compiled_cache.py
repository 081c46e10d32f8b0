"""Where numba keeps meshshade's compiled code: a folder named after a hash of the package's sources.

Why: numba's on-disk cache (``cache=True``) checks only the source file of the function it caches (its
modification time and size). A compiled function keeps the machine code of every helper it calls or inlines
(``inline="always"``) from other files, so after an edit to a helper in another file numba loads the old code
and says nothing. meshshade has about 90 cached functions and 50 inlined helpers across a dozen files.

So importing meshshade points numba's cache (``NUMBA_CACHE_DIR``) at ``<user cache>/meshshade/numba/<key>``,
before any meshshade module imports numba. The key is :func:`source_hash` (sha256 over the relative path and
bytes of every ``.py`` file of the package and of its data tables, ``.csv``) followed by the Python, numba and
numpy versions. Any change to any source file or table gives a new, empty folder, and every kernel is compiled
again on its first use. The user cache is
``$XDG_CACHE_HOME``, else ``%LOCALAPPDATA%`` (Windows), ``~/Library/Caches`` (macOS) or ``~/.cache``. When it
cannot be written, a private folder under the system temporary directory is used instead.

Setting ``NUMBA_CACHE_DIR`` in the environment overrides all of this: meshshade leaves it alone, and whoever set
it must then empty it after changing the sources. A value that meshshade itself set in a parent process
(marked by ``MESHSHADE_SET_NUMBA_CACHE_DIR``) is replaced by this checkout's own folder.

Import cost: about 5 ms in all, 3 ms of it hashing the package's 1.2 MB of sources (2 cores, under load);
importing numba takes about 400 ms. Neither numba nor numpy is imported here: their versions are read from
their version files (``meshshade --help`` imports neither).

Old folders are pruned at import: only the :data:`KEEP` most recently used ones are kept. A folder is removed
only after :data:`MIN_IDLE_S` without use and, on POSIX, only when no running process holds its ``in-use``
lock (each process holds a shared lock on its own folder for its lifetime). Without the lock a running process
could crash: numba raises if its cache folder is deleted before it saves a new compilation. Pruning never
raises; a file-system error only leaves a folder in place.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; pruning relies on the idle time alone
    fcntl = None

#: the package whose sources key the cache (the folder that holds this file)
PACKAGE_DIR = Path(__file__).resolve().parent
#: environment variable holding the NUMBA_CACHE_DIR that meshshade itself set (inherited by child processes)
MARKER = "MESHSHADE_SET_NUMBA_CACHE_DIR"
#: number of most recently used key folders that are never pruned
KEEP = 4
#: seconds since a key folder was last used before it may be pruned
MIN_IDLE_S = 3600.0
#: the lock file in each key folder (held shared by every process that uses the folder)
LOCK_NAME = "in-use"

_in_use_fd: int | None = None  # this process's lock on its folder, held until exit


def source_hash(package_dir: str | os.PathLike = PACKAGE_DIR) -> str:
    """sha256 over the sorted relative paths and bytes of every ``*.py`` and ``*.csv`` file under ``package_dir``
    (the sources and the runtime tables of ``kernels/data``: a table is read at import, and a compiled function
    that took one of its arrays as a global would keep the old numbers).

    The first 16 hex digits. Modification times do not count; ``__pycache__`` folders are skipped.
    """
    root = os.fspath(package_dir)
    files = []  # (relative path with "/", path)
    for folder, subfolders, names in os.walk(root):
        subfolders[:] = [d for d in subfolders if d != "__pycache__"]
        rel = os.path.relpath(folder, root).replace(os.sep, "/")
        files += [(n if rel == "." else f"{rel}/{n}", os.path.join(folder, n)) for n in names
                  if n.endswith((".py", ".csv"))]
    digest = hashlib.sha256()
    for rel, path in sorted(files):
        with open(path, "rb") as fh:
            data = fh.read()
        name = rel.encode()
        digest.update(len(name).to_bytes(8, "little") + name + len(data).to_bytes(8, "little"))
        digest.update(data)
    return digest.hexdigest()[:16]


def _numba_version() -> str:
    """numba's version without importing numba (which reads NUMBA_CACHE_DIR when imported): from the version
    file of its source tree, else from its installed metadata (a few ms more: it scans the installed packages)."""
    if "numba" in sys.modules:
        return sys.modules["numba"].__version__
    try:
        text = Path(importlib.util.find_spec("numba").origin).with_name("_version.py").read_text()
        return re.search(r'"version": "([^"]+)"', text).group(1)
    except (AttributeError, TypeError, ValueError, OSError):  # no spec, origin, file or version line
        pass
    from importlib import metadata  # only here: slow to import (numba imports it anyway, later)

    try:
        return metadata.version("numba")
    except metadata.PackageNotFoundError:
        return "none"


def _numpy_version() -> str:
    """numpy's version without importing numpy (a fifth of a second; ``meshshade --help`` needs none of it): from
    its ``version.py``, else from its installed metadata."""
    if "numpy" in sys.modules:
        return sys.modules["numpy"].__version__
    try:
        folder = importlib.util.find_spec("numpy").submodule_search_locations[0]
        text = Path(folder, "version.py").read_text()
        return re.search(r'^(?:__)?version(?:__)? = "([^"]+)"', text, re.MULTILINE).group(1)
    except (AttributeError, TypeError, ValueError, IndexError, OSError):  # no spec, folder, file or version line
        pass
    from importlib import metadata

    try:
        return metadata.version("numpy")
    except metadata.PackageNotFoundError:
        return "none"


def cache_key(package_dir: str | os.PathLike = PACKAGE_DIR) -> str:
    """The key folder's name: ``<source_hash>-py<X><Y>-numba<version>-numpy<version>``."""
    return (f"{source_hash(package_dir)}-py{sys.version_info[0]}{sys.version_info[1]}"
            f"-numba{_numba_version()}-numpy{_numpy_version()}")


def user_cache_root(environ=os.environ) -> Path:
    """``<user cache>/meshshade/numba``, where the key folders live (see the module docstring)."""
    if environ.get("XDG_CACHE_HOME"):
        base = Path(environ["XDG_CACHE_HOME"])
    elif sys.platform == "win32" and environ.get("LOCALAPPDATA"):
        base = Path(environ["LOCALAPPDATA"])
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path.home() / ".cache"
    return base / "meshshade" / "numba"


def temp_cache_root() -> Path:
    """``<temporary directory>/meshshade-<uid>/numba``: the fallback when the user cache cannot be written."""
    user = os.getuid() if hasattr(os, "getuid") else os.environ.get("USERNAME", "user")
    return Path(tempfile.gettempdir()) / f"meshshade-{user}" / "numba"


def _usable(folder: Path, *, shared_parent: Path | None = None) -> bool:
    """Create ``folder``; True when it is a writable folder. Below a shared folder (the temporary directory),
    the first folder below it must be ours and closed to others' writes: numba loads pickles from its cache."""
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        if shared_parent is not None and hasattr(os, "getuid"):
            top = folder.relative_to(shared_parent).parts[0]
            st = (shared_parent / top).stat(follow_symlinks=False)
            if st.st_uid != os.getuid() or st.st_mode & 0o022:
                return False
        return folder.is_dir() and os.access(folder, os.W_OK | os.X_OK)
    except OSError:
        return False


def cache_dir_for(package_dir: str | os.PathLike = PACKAGE_DIR, environ=os.environ) -> Path | None:
    """The key folder for ``package_dir``'s sources, created: under :func:`user_cache_root`, else under
    :func:`temp_cache_root`; None when neither can be written."""
    key = cache_key(package_dir)
    try:
        folder = user_cache_root(environ) / key
    except RuntimeError:  # Path.home(): no home directory
        folder = None
    if folder is not None and _usable(folder):
        return folder
    folder = temp_cache_root() / key
    return folder if _usable(folder, shared_parent=Path(tempfile.gettempdir())) else None


def configure(package_dir: str | os.PathLike = PACKAGE_DIR, environ=os.environ) -> str:
    """Point numba's cache at the key folder of ``package_dir`` (run by ``import meshshade``).

    Leaves a user-set ``NUMBA_CACHE_DIR`` alone. Sets ``NUMBA_CACHE_DIR`` (read by numba when it is imported,
    and again before each compilation) and, if numba is already imported, ``numba.config.CACHE_DIR``; then
    marks the folder in use and prunes old ones. Returns the cache folder now in force ('' for numba's default).
    """
    current = environ.get("NUMBA_CACHE_DIR")
    if current and current != environ.get(MARKER):
        return current  # the user's choice
    try:
        folder = cache_dir_for(package_dir, environ)
    except OSError as exc:  # a source file could not be read
        folder, why = None, str(exc)
    else:
        why = "no writable folder"
    if folder is None:  # numba's default: __pycache__ next to each source file, keyed on that file alone
        warnings.warn(f"meshshade: numba's cache stays next to the sources ({why}); there an edit to one file "
                      "does not recompile its callers in other files", RuntimeWarning, stacklevel=2)
        environ.pop("NUMBA_CACHE_DIR", None)
        environ.pop(MARKER, None)
    else:
        environ["NUMBA_CACHE_DIR"] = environ[MARKER] = str(folder)
    # numba imported before meshshade: the cache locators read config.CACHE_DIR, and numba re-reads NUMBA_*
    # (all of them) before its next compilation because the environment changed
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = str(folder or "")
    if folder is None:
        return ""
    _hold_in_use_lock(folder)
    prune(folder.parent)
    return str(folder)


def _hold_in_use_lock(folder: Path) -> None:
    """Hold a shared lock on ``folder/in-use`` until the process exits (POSIX; elsewhere a no-op)."""
    global _in_use_fd
    if fcntl is None:
        return
    lock = folder / LOCK_NAME
    for _ in range(3):
        try:
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)  # again if a pruner removed it meanwhile
            os.utime(folder)  # last used: now
            fd = os.open(lock, os.O_RDONLY | os.O_CREAT, 0o600)
        except OSError:
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_SH)  # waits while a pruner holds it and deletes the folder
            held = os.path.samestat(os.fstat(fd), os.stat(lock))  # not a lock file it deleted meanwhile
        except OSError:
            held = False
        if held:
            if _in_use_fd is not None:
                os.close(_in_use_fd)
            _in_use_fd = fd
            return
        os.close(fd)


def prune(root: str | os.PathLike, *, keep: int = KEEP, min_idle_s: float = MIN_IDLE_S,
          now: float | None = None) -> list[str]:
    """Remove the key folders under ``root`` beyond the ``keep`` most recently used that have been idle for at
    least ``min_idle_s`` and that no process holds (POSIX lock). Returns the names removed; never raises."""
    removed = []
    try:
        with os.scandir(root) as it:
            entries = [e for e in it if e.is_dir(follow_symlinks=False)]
        if len(entries) <= keep:
            return removed
        now = time.time() if now is None else now
        entries.sort(key=lambda e: e.stat(follow_symlinks=False).st_mtime, reverse=True)
        for entry in entries[keep:]:
            if now - entry.stat(follow_symlinks=False).st_mtime >= min_idle_s and _remove_unless_held(entry.path):
                removed.append(entry.name)
    except OSError:
        pass
    return removed


def _remove_unless_held(folder: str) -> bool:
    if fcntl is None:
        shutil.rmtree(folder, ignore_errors=True)
        return not os.path.exists(folder)
    try:
        fd = os.open(os.path.join(folder, LOCK_NAME), os.O_RDONLY | os.O_CREAT, 0o600)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:  # a running process uses it
        os.close(fd)
        return False
    try:
        shutil.rmtree(folder, ignore_errors=True)
    finally:
        os.close(fd)
    return not os.path.exists(folder)
