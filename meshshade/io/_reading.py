"""What the mesh readers share (OBJ and OFF in :mod:`meshshade.io.meshes`, PLY in :mod:`meshshade.io.ply`): the
text of a file in the encodings met in the wild, polygons fan-triangulated in place, integer face indices.

* **Text encodings** (OBJ, ASCII PLY, OFF): UTF-8 or ASCII, with or without a byte-order mark (a UTF-8 BOM before
  the first record is dropped, not read as part of it); UTF-16 with its byte-order mark is decoded too.
* **Polygons** with more than three corners are fan-triangulated ``(0, i, i+1)`` in place (each polygon's triangles
  where the polygon was), with a warning, because that changes the face count.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from meshshade.errors import MeshValidationError
from meshshade.geometry.mesh import MeshDefectWarning

#: byte-order marks of the text formats (OBJ, ASCII PLY, OFF); UTF-8 text may carry one, UTF-16 text always does
_BOMS = ((b"\xef\xbb\xbf", "utf-8"), (b"\xff\xfe", "utf-16-le"), (b"\xfe\xff", "utf-16-be"))


def _decode_text(data: bytes, path: Path) -> str:
    """Text of a mesh file: UTF-8 with or without a byte-order mark (dropped; undecodable bytes are replaced), or
    UTF-16 with its byte-order mark (what Windows editors write as "Unicode")."""
    for bom, encoding in _BOMS:
        if data.startswith(bom):
            try:
                return data[len(bom):].decode(encoding, errors="replace" if encoding == "utf-8" else "strict")
            except UnicodeDecodeError:
                raise MeshValidationError(f"{path}: starts with a {encoding.upper()} byte-order mark but is not "
                                          f"{encoding.upper()} text") from None
    return data.decode("utf-8", errors="replace")


def _obj_statements(text: str):
    """(line number, line, its words) of each non-empty statement of an OBJ's decoded ``text``: any line ending
    (\\n, \\r\\n, \\r), comments dropped, a trailing backslash joining the next line (numbered by the last)."""
    pending = ""
    for lineno, raw in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"), start=1):
        line = pending + raw.split("#", 1)[0].rstrip()
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        parts = line.split()
        if parts:
            yield lineno, line, parts


def _warn_polygons(path: Path, n_polygons: int) -> None:
    warnings.warn(f"{path}: {n_polygons} polygons with more than 3 corners were fan-triangulated (0, i, i+1)",
                  MeshDefectWarning, stacklevel=4)


def _fan_triangulate(groups, count: int, path: Path):
    """Faces ((m, 3) int64, file order) of ``count`` polygons given as groups ``(rows, corners (g, k))`` of equal
    corner count ``k``: polygon ``(c0, ..., c_k-1)`` becomes ``(c0, ci, ci+1)``, i = 1 .. k-2, in place.
    Returns (faces, number of polygons with more than 3 corners)."""
    corners = np.zeros(count, np.int64)
    for rows, values in groups:
        corners[rows] = values.shape[1]
    if count and corners.min() < 3:
        i = int(np.argmin(corners))
        raise MeshValidationError(f"{path}: face {i} has {int(corners[i])} corners (need at least 3)")
    n_tri = corners - 2
    start = np.cumsum(n_tri) - n_tri
    faces = np.empty((int(n_tri.sum()), 3), np.int64)
    for rows, values in groups:
        g, k = values.shape
        t = np.arange(k - 2)
        tri = np.stack([np.broadcast_to(values[:, :1], (g, k - 2)), values[:, 1 + t], values[:, 2 + t]], axis=2)
        faces[(start[rows][:, None] + t).reshape(-1)] = tri.reshape(-1, 3)
    return faces, int(np.count_nonzero(corners > 3))


def _as_indices(values: np.ndarray, path: Path, what: str) -> np.ndarray:
    """Integer face indices from numbers read as floats (ASCII) or any PLY type; non-integers are an error."""
    if values.dtype.kind in "iu":
        return values.astype(np.int64)
    if values.size and not (np.all(np.isfinite(values)) and np.all(values == np.round(values))
                            and np.abs(values).max() < 2**53):
        raise MeshValidationError(f"{path}: {what} are not all integers")
    return values.astype(np.int64)
