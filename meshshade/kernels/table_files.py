"""Reading the runtime tables that ship as data files in ``meshshade/kernels/data/``.

Each table is a CSV file whose ``# key: value`` header (continued on ``#   `` lines) records its provenance: the
generator in ``tools/tables/`` and the sha256 of its source, the files it read, the command and its parameters
(the grid's nodes among them), the meshshade version, commit and date of the run; then the column line and one
row per grid point. Numbers are written as the shortest text that reads back to the same double, so the arrays
are exactly those the generator computed. tests/kernels/test_runtime_tables.py checks that each header's
generator and inputs still hash to the recorded sha256.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data"


def read_table(name: str, folder: Path = DATA) -> tuple[dict[str, str], dict[str, list[str]]]:
    """``(header, columns)`` of ``data/<name>``: the header entries, and each column's cells as text."""
    lines = (Path(folder) / name).read_text(encoding="utf-8").splitlines()
    header: dict[str, str] = {}
    key = None
    n = 0
    for n, line in enumerate(lines):
        if line.startswith("#   ") and key is not None:
            header[key] += "\n" + line[4:]
        elif line.startswith("# ") and ": " in line:
            key, _, value = line[2:].partition(": ")
            header[key] = value
        else:
            break
    rows = list(csv.reader(lines[n:]))
    return header, {c: [r[i] for r in rows[1:]] for i, c in enumerate(rows[0])}


def floats(cells) -> np.ndarray:
    """Text cells (or a space-separated header value) as a float64 array, each number read exactly."""
    return np.array([float(c) for c in (cells.split() if isinstance(cells, str) else cells)], dtype=np.float64)


def grid_shape(columns: dict[str, list[str]], axes: dict[str, np.ndarray]) -> tuple[int, ...]:
    """The grid's shape, after checking that the rows run over it in C order: the first axis slowest, each axis
    column holding exactly its header's nodes."""
    shape = tuple(len(v) for v in axes.values())
    for column, grid in zip(axes, np.meshgrid(*axes.values(), indexing="ij")):
        if not np.array_equal(floats(columns[column]), grid.ravel()):
            raise ValueError(f"column {column!r} is not the table's grid in row order")
    return shape
