"""Shared writer of the reference CSVs in tests/data (used by every tools/references/precompute_*.py script).

Every file starts with ``# key: value`` header lines (a value spanning several lines continues on lines that
start with ``#   ``), then the CSV column line and the data rows::

    # title: <what the file holds>
    # <key>: <value>            one line per entry of ``params``, in order (function, method, parameters, ...)
    # dps: <working precision>  (required in ``params``)
    # generator: tools/<script>.py
    # sha256: <sha256 of the generator's bytes>
    # dependencies: tools/<other>.py sha256 <hex>; ...   (scripts whose code the generator imports, or "none")
    # mpmath: <version> (backend <backend>)
    # python: <version>
    # date: <UTC, ISO 8601>

tests/conftest.py (``load_reference``) reads this header, recomputes the sha256 of the generator and of each
dependency and fails with "rerun tools/<script>" when one differs. This module only formats: it computes no
reference value, so it is not itself hashed.
"""
from __future__ import annotations

import csv
import datetime
import hashlib
import io
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import mpmath

ROOT = Path(__file__).resolve().parents[2]


def short_commit() -> str:
    """The repository's HEAD as ``git rev-parse --short`` gives it, or "unknown" (no git, not a checkout)."""
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def file_sha256(path: Path) -> str:
    """sha256 (hex) of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _repo_path(path: Path) -> str:
    return Path(path).resolve().relative_to(ROOT).as_posix()


def _header_line(key: str, value: str) -> str:
    first, *more = str(value).split("\n")
    return "\n".join([f"# {key}: {first}", *(f"#   {line}" for line in more)])


def write_reference_csv(path: Path, columns: Sequence[str], rows: Sequence, *, script: Path, title: str,
                        params: Mapping[str, str], depends: Sequence[Path] = ()) -> None:
    """Write ``rows`` under ``columns`` to ``path`` with the provenance header of the module docstring.

    Parameters
    ----------
    path : output CSV (its folder is created).
    columns : column names, in order.
    rows : each a mapping with exactly the keys ``columns`` or a sequence in column order; values are written
        as given (the generators format their numbers as strings).
    script : the generator (pass ``__file__``); recorded relative to the repository root with its sha256.
    title : first header line, what the file holds.
    params : further header entries, in order; must contain ``"dps"`` (the working precision).
    depends : other tools/ scripts whose code the generator imports; their sha256 are recorded too.
    """
    if "dps" not in params:
        raise ValueError("params must record the working precision ('dps')")
    reserved = {"title", "generator", "sha256", "dependencies", "mpmath", "python", "date"}
    if reserved & set(params):
        raise ValueError(f"params may not set {sorted(reserved & set(params))}")
    deps = "; ".join(f"{_repo_path(d)} sha256 {file_sha256(d)}" for d in depends) or "none"
    header = [_header_line("title", title), *(_header_line(k, v) for k, v in params.items()),
              _header_line("generator", _repo_path(script)), _header_line("sha256", file_sha256(script)),
              _header_line("dependencies", deps),
              _header_line("mpmath", f"{mpmath.__version__} (backend {mpmath.libmp.BACKEND})"),
              _header_line("python", sys.version.split()[0]),
              _header_line("date", datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"))]
    buf = io.StringIO()
    buf.write("\n".join(header) + "\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        if isinstance(row, Mapping):
            if set(row) != set(columns):
                raise ValueError(f"row keys {sorted(row)} differ from the columns {list(columns)}")
            row = [row[c] for c in columns]
        elif len(row) != len(columns):
            raise ValueError(f"row of {len(row)} values for {len(columns)} columns")
        writer.writerow(row)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(buf.getvalue())
