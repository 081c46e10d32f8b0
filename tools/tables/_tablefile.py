"""Shared writer of the runtime tables in meshshade/kernels/data/ (used by the generators in tools/tables/).

A table is a CSV file with ``# key: value`` header lines (a value spanning several lines continues on lines that
start with ``#   ``), then the column line and one row per grid point::

    # title: <what the table holds>
    # description: <what each column and header entry means>
    # generator: tools/tables/<script>.py
    # sha256: <sha256 of the generator's bytes>
    # inputs: <path> sha256 <hex>; ...      (files the generator read, e.g. a training set, or "none")
    # command: python tools/tables/<script>.py <arguments>
    # <key>: <value>                         one line per parameter (photons, seeds, the grid's nodes, ...)
    # meshshade: <version>
    # commit: <git commit of the run>
    # date: <YYYY-MM-DD of the run>

Every number is written as ``repr(float)``, the shortest text that reads back to the same double, so a table
round-trips bit for bit; a generator rounds its values (to the significant digits its fit supports) before
handing them here. The package reads the files with :mod:`meshshade.kernels.table_files`;
tests/kernels/test_runtime_tables.py recomputes the sha256 of the generator and of each input and fails with
"rerun tools/tables/<script>" when one differs. This module only formats: it is not itself hashed.
"""
from __future__ import annotations

import csv
import datetime
import hashlib
import io
import shlex
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: where the package's tables live
DATA = ROOT / "meshshade" / "kernels" / "data"
RESERVED = ("title", "description", "generator", "sha256", "inputs", "command", "meshshade", "commit", "date")


def short_commit() -> str:
    """The repository's HEAD as ``git rev-parse --short`` gives it, or "unknown" (no git, not a checkout)."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_provenance(script: Path, argv: Sequence[str]) -> dict[str, str]:
    """The ``command``, ``meshshade``, ``commit`` and ``date`` entries of a run of ``script`` now."""
    from meshshade import __version__

    return {"command": shlex.join(["python", repo_path(script), *argv]), "meshshade": __version__,
            "commit": short_commit(), "date": datetime.date.today().isoformat()}


def file_sha256(path: Path) -> str:
    """sha256 (hex) of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def repo_path(path: Path) -> str:
    return Path(path).resolve().relative_to(ROOT).as_posix()


def number(x: float) -> str:
    """A float as the shortest text that reads back to the same double."""
    return repr(float(x))


def nodes(values: Sequence[float]) -> str:
    """A grid axis as a header value: its numbers separated by spaces."""
    return " ".join(number(v) for v in values)


def _header_line(key: str, value: str) -> str:
    first, *more = str(value).split("\n")
    return "\n".join([f"# {key}: {first}", *(f"#   {line}" for line in more)])


def write_table(path: Path, columns: Sequence[str], rows: Sequence[Sequence], *, script: Path, title: str,
                description: str, provenance: Mapping[str, str], params: Mapping[str, str],
                inputs: Sequence[Path] = ()) -> None:
    """Write ``rows`` under ``columns`` to ``path`` with the provenance header of the module docstring.

    Parameters
    ----------
    path : output CSV (its folder must exist).
    columns : column names, in order.
    rows : sequences in column order; floats are written with :func:`number`, anything else with ``str``.
    script : the generator (pass ``__file__``); recorded relative to the repository root with its sha256.
    title, description : what the table holds and what its columns and parameters mean.
    provenance : ``command``, ``meshshade``, ``commit``, ``date`` (:func:`run_provenance`), in that order.
    params : further header entries, in order (run parameters, the grid's nodes).
    inputs : files the generator read (a training set, another table); their sha256 are recorded too.
    """
    clash = set(RESERVED) & set(params)
    if clash:
        raise ValueError(f"params may not set {sorted(clash)}")
    if list(provenance) != ["command", "meshshade", "commit", "date"]:
        raise ValueError("provenance must give command, meshshade, commit and date")
    deps = "; ".join(f"{repo_path(p)} sha256 {file_sha256(p)}" for p in inputs) or "none"
    header = [_header_line("title", title), _header_line("description", description),
              _header_line("generator", repo_path(script)), _header_line("sha256", file_sha256(script)),
              _header_line("inputs", deps), _header_line("command", provenance["command"]),
              *(_header_line(k, v) for k, v in params.items()),
              *(_header_line(k, provenance[k]) for k in ("meshshade", "commit", "date"))]
    buf = io.StringIO()
    buf.write("\n".join(header) + "\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        if len(row) != len(columns):
            raise ValueError(f"row of {len(row)} values for {len(columns)} columns")
        writer.writerow([number(v) if isinstance(v, float) else str(v) for v in row])
    Path(path).write_text(buf.getvalue())
