"""File input and output: the only module that touches the file system (but for the caches: numba's folders,
which ``meshshade.compiled_cache`` places before numba is imported, and the assets' derived data,
``meshshade.asset_cache``).

Reading meshes
--------------
``load_mesh(path, units="mm")`` reads OBJ, PLY, OFF, STL, GLB and glTF. Nothing is merged, reordered or guessed:

* **OBJ** is read by a small parser here, not by trimesh: trimesh splits an OBJ by material or object into
  several geometries (each with a copy of the vertex list, faces regrouped), which breaks the file's face order.
  Only ``v`` and ``f`` records are used (texture coordinates, normals, groups and materials are ignored);
  indices may be negative (relative); polygons with more than three corners are fan-triangulated
  ``(0, i, i+1)``, with a warning, because that changes the face count.
* **PLY** (ASCII, binary little- and big-endian) and **OFF** (also COFF/NOFF/STOFF; extra columns ignored) are
  read by readers here, in file order. Their counts are checked against the data: a header (PLY) or count line
  (OFF) that declares more or fewer rows than the file holds (ASCII), or more or fewer bytes (binary PLY: a
  truncated or over-long file), is an error naming both, never read with face rows taken for vertices. Polygons
  are fan-triangulated ``(0, i, i+1)`` in place (each polygon's triangles where the polygon was), with the same
  warning as OBJ. (trimesh, used before, triangulates silently and out of order: triangles first, then every
  quad's ``(0, 1, 2)``, then every quad's ``(2, 3, 0)``, then larger polygons; and it cannot read binary PLY whose
  polygons have different sizes, which Blender writes.) Other PLY elements and properties are skipped.
* **Text encodings** (OBJ, ASCII PLY, OFF): UTF-8 or ASCII, with or without a byte-order mark (a UTF-8 BOM before
  the first record is dropped, not read as part of it); UTF-16 with its byte-order mark is decoded too.
* **GLB / glTF** scenes are concatenated in the file's mesh order (instances of one mesh by node name), each
  instance moved by its node transform (faces are re-wound under a mirroring transform). glTF positions are metres by
  specification; a warning says so when ``units`` is not ``"m"`` (the unit is still the caller's choice).
* **STL** stores three independent corners per facet, so it has no shared vertices and no vertex order to keep.
  Corners with bitwise-equal positions are merged, numbered in order of first appearance (deterministic, exact:
  no tolerance). This is the only format where vertices are merged.

Coordinates are converted to mm once, by ``mm_per_unit(units)``. Every reading problem raises
``MeshValidationError`` with one line naming the file.

Writing
-------
Every output is written atomically (``atomic_write``: a temporary file in the target directory, then
``os.replace``; the temporary file is removed on any exception, KeyboardInterrupt included), so a failed or
interrupted run never leaves a partial file. Inside ``output_transaction()`` (the CLI runs every command in one)
the renames wait for the end of the block, so several outputs appear together or not at all, and folders made by
``output_dir`` are removed again on failure. ``check_output_path`` refuses an output that is one of the inputs,
a folder, a device, pipe or socket (which a rename would replace by a regular file), or a name whose extension is
not the format written. Writers refuse values a file cannot hold (NaN, infinities, beyond float32), and a full
disk is reported as such.
Writers: ``write_ply`` / ``write_mesh_ply`` (binary PLY with per-vertex float properties and colours),
``write_npz``, ``write_text`` (CSV tables) and ``write_figure`` (matplotlib, format from the extension).
``write_mesh_ply`` writes positions in the **source file's units** (so the result overlays the input in Blender or
MeshLab) and records the factor as a ``comment meshshade mm_per_unit <f>`` header line.
"""
from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import errno
import json
import os
import re
import secrets
import signal
import stat
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from meshshade import memo
from meshshade.errors import MeshshadeError, MeshValidationError, OutputError
from meshshade.geometry.mesh import Mesh, MeshDefectWarning
from meshshade.units import mm_per_unit

__all__ = ["SUPPORTED_MESH_FORMATS", "load_mesh", "read_mesh_arrays", "read_baked_ply", "BAKED_RADIANCE",
           "atomic_write", "output_transaction",
           "check_output_path", "output_dir", "discard_stdout",
           "write_ply", "write_mesh_ply", "write_npz", "write_text", "write_json", "write_figure", "PLY_RESERVED_NAMES",
           "write_exr", "write_png", "read_exr", "read_toml", "read_json", "read_json_lines", "write_json_lines",
           "file_sha256", "folder_files", "job_folder", "remove_stale_parts", "detached", "write_bytes", "write_usd"]

#: file extension -> format name
SUPPORTED_MESH_FORMATS = {".obj": "obj", ".ply": "ply", ".off": "off", ".stl": "stl", ".glb": "glb",
                          ".gltf": "gltf"}

#: vertex property names that write_ply uses itself (or that viewers interpret) and so refuses as custom props
PLY_RESERVED_NAMES = frozenset({"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "s", "t",
                                "u", "v", "vertex_indices"})

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


# ----------------------------------------------------------------------------------------------- reading

def _one_line(exc: BaseException, limit: int = 160) -> str:
    text = str(exc).strip().splitlines()
    text = text[0] if text else ""
    text = text if len(text) <= limit else text[: limit - 3] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _check_input_file(path: Path) -> str:
    if not path.exists():
        raise MeshValidationError(f"mesh file not found: {path}")
    if path.is_dir():
        raise MeshValidationError(f"{path} is a directory, not a mesh file")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_MESH_FORMATS:
        raise MeshValidationError(f"unsupported mesh format {suffix or '(no extension)'!r} for {path}; "
                                  f"supported: {', '.join(SUPPORTED_MESH_FORMATS)}")
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise MeshValidationError(f"cannot read {path}: {_one_line(exc)}") from exc
    if size == 0:
        raise MeshValidationError(f"mesh file is empty: {path}")
    return SUPPORTED_MESH_FORMATS[suffix]


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


_OBJ_V = re.compile(r"^[ \t]*v[ \t]+([^\n]*)", re.M)
_OBJ_F = re.compile(r"^[ \t]*f[ \t]+([^\n]*)", re.M)


def _read_obj(path: Path):
    """Positions and faces of an OBJ file, in file order (see the module docstring).

    Fast path: whole-text regular expressions and one numpy conversion. Anything unusual (malformed numbers,
    index 0, relative indices) goes to the line-by-line reader, which also reports the line number of an error.
    """
    text = _decode_text(path.read_bytes(), path)
    original = text
    if "\\" in text:
        text = re.sub(r"\\[ \t]*\r?\n", " ", text)
    if "#" in text:
        text = re.sub(r"#[^\n]*", "", text)
    try:
        verts = np.array([row.split()[:3] for row in _OBJ_V.findall(text)], dtype=np.float64).reshape(-1, 3)
        rows = [row.split() for row in re.sub(r"/\S*", "", "\n".join(_OBJ_F.findall(text))).split("\n")]
        rows = [r for r in rows if r]
        lengths = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
        if rows and lengths.min() >= 3 and lengths.max() == 3:
            faces = np.array(rows, dtype=np.int64).reshape(-1, 3)
            if faces.min() >= 1:
                return verts, faces - 1
    except (ValueError, OverflowError):  # OverflowError: an index beyond int64 (reported line by line)
        pass
    return _read_obj_lines(path, original)


def _read_obj_lines(path: Path, text: str | None = None):
    """Line-by-line OBJ reader: general (polygons, relative indices) and precise about errors.

    ``text``: the file's decoded text when the caller has read it already (see ``_decode_text``)."""
    if text is None:
        text = _decode_text(path.read_bytes(), path)
    verts: list = []
    faces: list = []
    n_polygons = 0
    pending = ""
    for lineno, raw in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"), start=1):
        line = pending + raw.split("#", 1)[0].rstrip()
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            try:
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except (IndexError, ValueError):
                raise MeshValidationError(f"{path}:{lineno}: malformed vertex line {line.strip()[:60]!r}") \
                    from None
        elif parts[0] == "f":
            n = len(verts)
            try:
                idx = [int(p.split("/", 1)[0]) for p in parts[1:]]
            except ValueError:
                raise MeshValidationError(f"{path}:{lineno}: malformed face line {line.strip()[:60]!r}") \
                    from None
            if len(idx) < 3:
                raise MeshValidationError(f"{path}:{lineno}: face with {len(idx)} corners (need at least 3)")
            if max(map(abs, idx)) >= 2**62:
                raise MeshValidationError(f"{path}:{lineno}: face index out of range in {line.strip()[:60]!r}")
            if 0 in idx:
                raise MeshValidationError(f"{path}:{lineno}: face index 0 (OBJ indices start at 1)")
            idx = [i - 1 if i > 0 else n + i for i in idx]
            if min(idx) < 0:
                raise MeshValidationError(f"{path}:{lineno}: relative face index before the first vertex")
            if len(idx) > 3:
                n_polygons += 1
            faces.extend((idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1))
    if not verts and not faces:
        raise MeshValidationError(f"no OBJ vertex or face records in {path}")
    if n_polygons:
        _warn_polygons(path, n_polygons)
    return np.array(verts, dtype=np.float64).reshape(-1, 3), np.array(faces, dtype=np.int64).reshape(-1, 3)


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


# --- PLY -----------------------------------------------------------------------------------------------------
#: PLY property types -> numpy type codes (both the names of the 1.0 specification and the sized aliases)
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
#: names of the face list in the wild (the specification's and the one many exporters use)
_PLY_FACE_LISTS = ("vertex_indices", "vertex_index")


def _parse_ply_header(data: bytes, path: Path):
    """(format, elements, offset of the data, comments): elements as (name, count, props), props as (name, type
    code, count type code or None for a scalar); comments: the text of the ``comment`` lines. The header may start
    with a UTF-8 byte-order mark."""
    pos = 3 if data.startswith(b"\xef\xbb\xbf") else 0
    lines = []
    while True:
        nl = data.find(b"\n", pos)
        line = data[pos:] if nl < 0 else data[pos:nl]
        lines.append(line.decode("ascii", errors="replace").strip())
        pos = len(data) if nl < 0 else nl + 1
        if lines[-1] == "end_header":
            break
        if nl < 0 or len(lines) > 100_000 or (len(lines) == 1 and lines[0] != "ply"):
            what = "does not start with 'ply'" if lines[0] != "ply" else "has no end_header line"
            raise MeshValidationError(f"{path}: not a PLY file: its header {what}")
    fmt, elements, comments = None, [], []
    for lineno, line in enumerate(lines[1:-1], start=2):
        parts = line.split()
        if parts[:1] == ["comment"]:
            comments.append(line.split(None, 1)[1] if len(parts) > 1 else "")
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format":
            if len(parts) != 3 or parts[1] not in _PLY_FORMATS:
                raise MeshValidationError(f"{path}: header line {lineno}: unsupported PLY format {line!r} "
                                          f"(supported: {', '.join(_PLY_FORMATS)})")
            fmt = parts[1]
        elif parts[0] == "element":
            if len(parts) != 3 or not parts[2].isdigit():
                raise MeshValidationError(f"{path}: header line {lineno}: malformed element line {line!r} "
                                          "(expected 'element NAME COUNT')")
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property":
            if not elements:
                raise MeshValidationError(f"{path}: header line {lineno}: property before any element")
            if len(parts) == 3 and parts[1] in _PLY_TYPES:
                elements[-1][2].append((parts[2], _PLY_TYPES[parts[1]], None))
            elif len(parts) == 5 and parts[1] == "list" and parts[2] in _PLY_TYPES and parts[3] in _PLY_TYPES:
                elements[-1][2].append((parts[4], _PLY_TYPES[parts[3]], _PLY_TYPES[parts[2]]))
            else:
                raise MeshValidationError(f"{path}: header line {lineno}: malformed property line {line!r}")
    if fmt is None:
        raise MeshValidationError(f"{path}: PLY header has no format line")
    for name, _count, props in elements:
        names = [p[0] for p in props]
        if len(set(names)) != len(names):
            raise MeshValidationError(f"{path}: PLY element {name!r} declares a property twice")
    return fmt, elements, pos, comments


def _ply_declared(elements) -> str:
    """'642 vertices and 1280 faces' (other elements by name)."""
    words = {"vertex": "vertices", "face": "faces"}
    parts = [f"{count} {words.get(name, name + ' elements')}" for name, count, _ in elements]
    return " and ".join([", ".join(parts[:-1]), parts[-1]]) if len(parts) > 1 else (parts[0] if parts else "nothing")


def _ply_ascii(body: bytes, elements, path: Path) -> dict:
    """Every element of an ASCII PLY body: {name: {property: (count,) float64 | [(rows, values (g, k))]}}.

    One element per line (blank lines are skipped); the number of lines must be what the header declares."""
    rows = [r for r in _decode_text(body, path).split("\n") if r.strip()]
    declared = sum(count for _, count, _ in elements)
    if len(rows) != declared:
        raise MeshValidationError(f"{path}: header declares {_ply_declared(elements)} ({declared} data rows), the "
                                  f"file holds {len(rows)} rows")
    out, first = {}, 0
    for name, count, props in elements:
        block = rows[first:first + count]
        first += count
        if name in ("vertex", "face"):
            out[name] = _ply_ascii_element(block, props, name, path)
    return out


def _ply_ascii_element(block, props, name: str, path: Path) -> dict:
    toks = [r.split() for r in block]
    lengths = np.fromiter(map(len, toks), dtype=np.int64, count=len(toks))
    out = {p: (np.empty(len(toks)) if c is None else []) for p, _, c in props}
    for length in np.flatnonzero(np.bincount(lengths)) if len(toks) else ():
        rows = np.flatnonzero(lengths == length)
        try:
            T = np.array([toks[i] for i in rows], dtype=np.float64)
        except ValueError:
            raise MeshValidationError(f"{path}: malformed number in the {name} rows") from None
        col, short = 0, False
        for prop, ptype, ctype in props:
            if col >= length:
                short = True
                break
            if ctype is None:  # rounded to the declared type, as a binary file would store it
                out[prop][rows] = T[:, col].astype(ptype) if ptype[0] == "f" else T[:, col]
                col += 1
                continue
            k = T[:, col]
            if not (np.all(k == k[0]) and k[0] >= 0 and k[0] == int(k[0])):
                raise MeshValidationError(f"{path}: {name} rows with {length} values disagree on the length of "
                                          f"list {prop!r} (unsupported layout, or a malformed row)")
            k = int(k[0])
            out[prop].append((rows, T[:, col + 1:col + 1 + k]))
            col += 1 + k
        if short or col != length:
            i = int(rows[0])
            need = "more" if short else str(col)
            raise MeshValidationError(f"{path}: {name} {i} has {length} values, the header's properties "
                                      f"({', '.join(p[0] for p in props)}) need {need} (wrong counts in the "
                                      "header?)")
    return out


def _ply_scan_rows(buf, pos, count, kinds, sizes, csizes, csigned, big):
    """Start of every row of a binary PLY element with list properties (sizes vary per row): numba kernel.

    kinds[p]: 0 scalar of sizes[p] bytes, 1 list (count of csizes[p] bytes, signed if csigned[p], then items of
    sizes[p] bytes). Returns (starts (count + 1,), list lengths (count, lists), rows read, status): status 0 ok,
    1 the data ends inside row ``rows read``, 2 a negative list length there.
    """
    n = buf.size
    n_lists = 0
    for p in range(kinds.size):
        n_lists += kinds[p]
    starts = np.zeros(count + 1, np.int64)
    lens = np.zeros((count, max(n_lists, 1)), np.int64)
    for r in range(count):
        starts[r] = pos
        li = 0
        for p in range(kinds.size):
            if kinds[p] == 0:
                pos += sizes[p]
                continue
            cs = csizes[p]
            if pos + cs > n:
                return starts, lens, r, 1
            k = 0
            for b in range(cs):
                k = k * 256 + np.int64(buf[pos + (b if big else cs - 1 - b)])
            if csigned[p] and k >= (np.int64(1) << (8 * cs - 1)):
                k -= np.int64(1) << (8 * cs)
            if k < 0:
                return starts, lens, r, 2
            lens[r, li] = k
            li += 1
            pos += cs + k * sizes[p]
        if pos > n:
            return starts, lens, r, 1
    starts[count] = pos
    return starts, lens, count, 0


_PLY_SCAN = []  # the compiled _ply_scan_rows, made on first use


def _ply_binary(body: bytes, elements, fmt: str, path: Path) -> dict:
    """Every element of a binary PLY body (same layout as ``_ply_ascii``); its size must be what the header
    declares, to the byte."""
    e = "<" if fmt == "binary_little_endian" else ">"
    buf = np.frombuffer(body, np.uint8)
    out, pos = {}, 0
    for name, count, props in elements:
        if all(c is None for _, _, c in props):
            dtype = np.dtype([(p, e + t) for p, t, _ in props])
            end = pos + count * dtype.itemsize
            if end > buf.size:
                raise MeshValidationError(f"{path}: header declares {_ply_declared(elements)}, but the binary data "
                                          f"ends inside the {name} elements (truncated file, or wrong counts)")
            rec = np.frombuffer(body, dtype, count, pos)
            cols = {p: rec[p].astype(np.float64 if t[0] == "f" else np.int64) for p, t, _ in props}
        else:
            cols, end = _ply_binary_lists(buf, pos, count, props, e, name, elements, path)
        if name in ("vertex", "face"):
            out[name] = cols
        pos = end
    if pos != buf.size:
        raise MeshValidationError(f"{path}: header declares {_ply_declared(elements)} ({pos} bytes of binary data), "
                                  f"the file holds {buf.size} bytes after the header ({buf.size - pos} too many: "
                                  "wrong counts in the header?)")
    return out


def _ply_binary_lists(buf, pos, count, props, e, name, elements, path):
    """Columns of a binary element with list properties, and the offset after it. Fast path: every row has the
    lengths of the first (one numpy view); otherwise the rows are scanned one by one (numba)."""
    scalar_min = sum(np.dtype(t).itemsize if c is None else np.dtype(c).itemsize for _, t, c in props)
    if count * scalar_min > buf.size - pos:
        raise MeshValidationError(f"{path}: header declares {_ply_declared(elements)}, but the binary data ends "
                                  f"inside the {name} elements (truncated file, or wrong counts)")
    if count == 0:
        return {p: (np.empty(0) if c is None else []) for p, _, c in props}, pos
    fields, at = [], pos
    for p, t, c in props:  # the first row's layout
        if c is None:
            fields.append((p, e + t))
            at += np.dtype(t).itemsize
            continue
        if at + np.dtype(c).itemsize > buf.size:
            break
        k = int(np.frombuffer(buf, e + c, 1, at)[0])
        if k < 0:
            break
        fields += [("__n_" + p, e + c), (p, e + t, (k,))]
        at += np.dtype(c).itemsize + k * np.dtype(t).itemsize
    else:
        dtype = np.dtype(fields)
        if pos + count * dtype.itemsize <= buf.size:
            rec = np.frombuffer(buf, dtype, count, pos)
            if all(np.all(rec["__n_" + p] == rec[p].shape[1]) for p, _, c in props if c is not None):
                cols = {p: (rec[p].astype(np.float64 if t[0] == "f" else np.int64) if c is None
                            else [(np.arange(count), rec[p])]) for p, t, c in props}
                return cols, pos + count * dtype.itemsize
    if not _PLY_SCAN:
        from numba import njit  # lazy: only binary PLY lists of varying length (mixed polygons) need the scan

        _PLY_SCAN.append(njit(cache=True)(_ply_scan_rows))
    kinds = np.array([0 if c is None else 1 for _, _, c in props], np.int64)
    sizes = np.array([np.dtype(t).itemsize for _, t, _ in props], np.int64)
    csizes = np.array([0 if c is None else np.dtype(c).itemsize for _, _, c in props], np.int64)
    csigned = np.array([c is not None and c[0] == "i" for _, _, c in props], np.bool_)
    starts, lens, done, status = _PLY_SCAN[0](buf, pos, count, kinds, sizes, csizes, csigned, e == ">")
    if status == 2:
        raise MeshValidationError(f"{path}: {name} {done} has a negative list length (corrupt binary data)")
    if status == 1:
        raise MeshValidationError(f"{path}: header declares {_ply_declared(elements)}, but the binary data ends "
                                  f"inside {name} {done} of {count} (truncated file, or wrong counts)")
    off = starts[:-1].copy()
    cols, li = {}, 0
    for p, t, c in props:
        size = np.dtype(t).itemsize
        if c is None:
            raw = buf[off[:, None] + np.arange(size)]
            cols[p] = raw.view(e + t).reshape(-1).astype(np.float64 if t[0] == "f" else np.int64)
            off += size
            continue
        k = lens[:, li]
        li += 1
        groups = []
        for length in np.flatnonzero(np.bincount(k)):
            rows = np.flatnonzero(k == length)
            raw = buf[(off[rows] + np.dtype(c).itemsize)[:, None] + np.arange(length * size)]
            groups.append((rows, raw.view(e + t).reshape(rows.size, length)))
        cols[p] = groups
        off += np.dtype(c).itemsize + k * size
    return cols, int(starts[-1])


def _read_ply(path: Path):
    """Positions and faces of an ASCII or binary PLY, in file order; polygons fan-triangulated in place."""
    V, F, _, _ = _ply_data(path, path.read_bytes())
    return V, F


def _ply_data(path: Path, data: bytes, header=None):
    """(V (n, 3) float64, F (m, 3) int64, vertex columns {name: (n,) array}, header comments) of a PLY's bytes
    (``header``: its ``_parse_ply_header`` if already parsed)."""
    fmt, elements, offset, comments = header or _parse_ply_header(data, path)
    names = [name for name, _, _ in elements]
    if "vertex" not in names:
        raise MeshValidationError(f"{path}: PLY header declares no vertex element")
    vprops = [p for p, _, _ in elements[names.index("vertex")][2]]
    if not {"x", "y", "z"} <= set(vprops):
        raise MeshValidationError(f"{path}: PLY vertex element has no x, y, z properties (it has: "
                                  f"{', '.join(vprops) or 'none'})")
    face_list = None
    if "face" in names:
        lists = [p for p, _, c in elements[names.index("face")][2] if c is not None]
        face_list = next((p for p in _PLY_FACE_LISTS if p in lists), None)
        if face_list is None:
            raise MeshValidationError(f"{path}: PLY face element has no vertex_indices list")
    body = memoryview(data)[offset:]
    cols = _ply_ascii(bytes(body), elements, path) if fmt == "ascii" else _ply_binary(bytes(body), elements, fmt,
                                                                                        path)
    vert = cols["vertex"]
    V = np.stack([np.asarray(vert[a], np.float64) for a in "xyz"], axis=1)
    n_faces = elements[names.index("face")][1] if face_list else 0
    if n_faces == 0:
        raise MeshValidationError(f"no triangles found in {path} (a PLY without faces: a point cloud?)")
    groups = [(rows, _as_indices(values, path, "PLY face indices")) for rows, values in cols["face"][face_list]]
    F, n_polygons = _fan_triangulate(groups, n_faces, path)
    if n_polygons:
        _warn_polygons(path, n_polygons)
    return V, F, vert, comments


# --- OFF -----------------------------------------------------------------------------------------------------
_OFF_KEYWORD = re.compile(r"^(ST)?C?N?(4)?(n)?OFF$")


def _read_off(path: Path):
    """Positions and faces of an ASCII OFF (also COFF, NOFF, STOFF: extra columns ignored), in file order;
    polygons fan-triangulated in place. The counts line must match the rows that follow."""
    lines = [line.split("#", 1)[0].split() for line in _decode_text(path.read_bytes(), path).splitlines()]
    lines = [parts for parts in lines if parts]
    if not lines or not _OFF_KEYWORD.match(lines[0][0]):
        raise MeshValidationError(f"{path}: not an OFF file (it does not start with OFF)")
    match = _OFF_KEYWORD.match(lines[0][0])
    if match.group(2) or match.group(3):
        raise MeshValidationError(f"{path}: {lines[0][0]} (4-D or n-D) OFF is not supported; use 3-D OFF")
    head, rows = lines[0][1:], lines[1:]
    if head[:1] == ["BINARY"]:
        raise MeshValidationError(f"{path}: binary OFF is not supported; save it as ASCII OFF, PLY or OBJ")
    if not head:
        if not rows:
            raise MeshValidationError(f"{path}: OFF file has no vertex/face count line")
        head, rows = rows[0], rows[1:]
    try:
        nv, nf = int(head[0]), int(head[1])
        if nv < 0 or nf < 0:
            raise ValueError
    except (IndexError, ValueError):
        raise MeshValidationError(f"{path}: malformed OFF count line {' '.join(head)!r} (expected 'VERTICES "
                                  "FACES EDGES')") from None
    if len(rows) != nv + nf:
        raise MeshValidationError(f"{path}: header declares {nv} vertices and {nf} faces ({nv + nf} rows), the file "
                                  f"holds {len(rows)} rows")
    widths = np.fromiter(map(len, rows[:nv]), dtype=np.int64, count=nv)
    if nv and widths.min() != widths.max():  # e.g. face rows read as vertices: the counts line is wrong
        i = int(np.flatnonzero(widths != widths[0])[0])
        raise MeshValidationError(f"{path}: OFF vertex rows differ in length ({int(widths[0])} values in vertex 0, "
                                  f"{int(widths[i])} in vertex {i}): does the counts line ({nv} vertices, {nf} faces) "
                                  "match the data?")
    try:
        V = np.array([r[:3] for r in rows[:nv]], dtype=np.float64).reshape(nv, 3)
    except ValueError:
        raise MeshValidationError(f"{path}: malformed OFF vertex rows (each needs x y z)") from None
    face_rows = rows[nv:]
    try:
        corners = np.fromiter((int(r[0]) for r in face_rows), dtype=np.int64, count=nf)
    except ValueError:
        raise MeshValidationError(f"{path}: malformed OFF face row (it must start with its corner count)") from None
    lengths = np.fromiter(map(len, face_rows), dtype=np.int64, count=nf)
    short = np.flatnonzero(lengths < corners + 1)
    if short.size:
        i = int(short[0])
        raise MeshValidationError(f"{path}: OFF face {i} declares {int(corners[i])} corners but lists "
                                  f"{int(lengths[i]) - 1} values")
    if nf and corners.min() < 0:
        raise MeshValidationError(f"{path}: OFF face {int(np.argmin(corners))} has a negative corner count")
    groups = []
    for k in np.flatnonzero(np.bincount(corners)) if nf else ():
        rows_k = np.flatnonzero(corners == k)
        try:
            groups.append((rows_k, np.array([face_rows[i][1:1 + k] for i in rows_k], dtype=np.int64)
                           .reshape(rows_k.size, k)))
        except ValueError:
            raise MeshValidationError(f"{path}: malformed OFF face row (indices must be integers)") from None
    F, n_polygons = _fan_triangulate(groups, nf, path)
    if n_polygons:
        _warn_polygons(path, n_polygons)
    return V, F


def _merge_exact_duplicates(V: np.ndarray, F: np.ndarray):
    """Merge bitwise-equal positions, numbering them in order of first appearance (STL only)."""
    _, first, inverse = np.unique(V, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return V[np.sort(first)], rank[inverse.reshape(-1)][F]


def _scene_arrays(scene, path: Path):
    import trimesh  # lazy: ~1 s to import; only non-OBJ meshes are read through it

    verts, faces, offset, skipped = [], [], 0, 0
    # trimesh's graph traversal order is not the file's; the geometry dict is in the file's mesh order
    rank = {name: i for i, name in enumerate(scene.geometry)}
    nodes = sorted(scene.graph.nodes_geometry, key=lambda node: (rank[scene.graph[node][1]], str(node)))
    for node in nodes:
        transform, name = scene.graph[node]
        geom = scene.geometry[name]
        if not isinstance(geom, trimesh.Trimesh):
            skipped += 1
            continue
        V = np.asarray(geom.vertices, dtype=np.float64)
        F = np.asarray(geom.faces, dtype=np.int64)
        T = np.asarray(transform, dtype=np.float64)
        V = V @ T[:3, :3].T + T[:3, 3]
        if np.linalg.det(T[:3, :3]) < 0:  # a mirroring instance turns the winding inside out
            F = F[:, [0, 2, 1]]
        verts.append(V)
        faces.append(F + offset)
        offset += V.shape[0]
    if skipped:
        warnings.warn(f"{path}: skipped {skipped} scene nodes that are not triangle meshes", MeshDefectWarning,
                      stacklevel=4)
    if not verts:
        raise MeshValidationError(f"no triangles found in {path}")
    return np.concatenate(verts), np.concatenate(faces)


def read_mesh_arrays(path) -> tuple[np.ndarray, np.ndarray]:
    """Read raw ``(vertices, faces)`` in the file's own units, without validation.

    Returns
    -------
    vertices : (n, 3) float64, in file order (STL: merged corners, see the module docstring)
    faces : (m, 3) int64

    Raises
    ------
    MeshValidationError
        Missing file, directory, empty file, unsupported extension, unreadable or malformed content.
    """
    path = Path(path)
    fmt = _check_input_file(path)
    own = {"obj": _read_obj, "ply": _read_ply, "off": _read_off}.get(fmt)
    if own is not None:
        try:
            return own(path)
        except OSError as exc:
            raise MeshValidationError(f"cannot read {path}: {_one_line(exc)}") from exc
    import trimesh  # lazy: ~1 s to import; only non-OBJ meshes are read through it

    try:
        loaded = trimesh.load(str(path), file_type=fmt, process=False, maintain_order=True)
    except MeshValidationError:
        raise
    except Exception as exc:  # noqa: BLE001 - any parser failure (ValueError, struct.error, KeyError, ...)
        raise MeshValidationError(f"could not read {fmt.upper()} file {path}: {_one_line(exc)}") from exc
    if isinstance(loaded, trimesh.Scene):
        if len(loaded.geometry) == 0:
            raise MeshValidationError(f"no triangles found in {path} (unreadable or empty {fmt.upper()} file)")
        V, F = _scene_arrays(loaded, path)
    elif isinstance(loaded, trimesh.Trimesh):
        V = np.asarray(loaded.vertices, dtype=np.float64)
        F = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
    else:
        raise MeshValidationError(f"no triangles found in {path} (it holds a {type(loaded).__name__})")
    if fmt == "stl":
        V, F = _merge_exact_duplicates(V, F)
    return V, F


def load_mesh(path, units: str = "mm") -> Mesh:
    """Load, validate and convert a mesh to mm.

    Parameters
    ----------
    path : str or Path, an .obj, .ply, .off, .stl, .glb or .gltf file
    units : str, the unit of the file's coordinates (``meshshade.units.MM_PER_UNIT``); never guessed

    Returns
    -------
    Mesh with vertices in mm, ``mm_per_unit`` of the file, ``source=str(path)`` and the validation report.
    Defects are reported as ``MeshDefectWarning`` (see ``meshshade.geometry.mesh``); those of the reading itself
    (polygons fan-triangulated, scene nodes skipped) are also added to ``mesh.defects.warnings``, so a report of
    the mesh (``meshshade check``) lists them with the others.

    Raises
    ------
    UnitsError for an unknown unit; MeshValidationError (one line naming the file) for anything else.
    """
    mm_per_unit(units)  # an unknown unit fails before the file is read
    path = Path(path)
    try:  # inside memo.reuse() (a batch worker) a file read before, unchanged since, is not read again
        st = path.stat()
        key = (str(path.resolve()), st.st_size, st.st_mtime_ns, str(units))
    except OSError:
        key = None
    if key is None:
        mesh, caught = _load_mesh(path, units)
    else:
        mesh, caught = memo.cached("mesh", key, lambda: _load_mesh(path, units))
    for w in caught:  # shown as they would have been, under the caller's filters
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return mesh


def _load_mesh(path: Path, units: str):
    """(Mesh, warnings caught while reading it) of :func:`load_mesh`."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MeshDefectWarning)
        V, F = read_mesh_arrays(path)
    notes = tuple(str(w.message) for w in caught if issubclass(w.category, MeshDefectWarning))
    with warnings.catch_warnings(record=True) as more:
        warnings.simplefilter("always")
        if path.suffix.lower() in (".glb", ".gltf") and str(units).strip().lower() != "m":
            warnings.warn(f"{path}: glTF positions are metres by specification, but units={units!r} was given",
                          UserWarning, stacklevel=2)
        try:
            mesh = Mesh.from_arrays(V, F, units=units, source=str(path))
        except MeshValidationError as exc:
            raise MeshValidationError(f"{path}: {exc}") from None
    if notes:
        mesh = dataclasses.replace(mesh, defects=dataclasses.replace(mesh.defects,
                                                                     warnings=notes + mesh.defects.warnings))
    return mesh, list(caught) + list(more)


#: vertex properties of a bake's PLY (``meshshade bake``, :func:`meshshade.output.bake_file.write_bake`)
BAKED_RADIANCE = ("radiance_r", "radiance_g", "radiance_b")
_BAKE_RECORD = re.compile(r"^meshshade ([A-Za-z_]+) (.*)$")
_BAKE_ETA = re.compile(r"\beta=([-+0-9.eE]+)")


def read_baked_ply(path, units: str = "mm"):
    """The mesh, radiance and record of a PLY written by ``meshshade bake``; None for any other mesh file.

    A file is a bake when it is a PLY whose vertices carry float ``radiance_r/g/b`` (only its header is read
    otherwise). Positions are converted to mm with the ``comment meshshade mm_per_unit`` the bake recorded
    (``units`` only when that line is missing).

    Returns
    -------
    None, or (mesh, radiance, info):
    mesh : Mesh in mm (faces as written, validated again; ``mm_per_unit`` as recorded)
    radiance : (n, 3) float64, the bake's linear exitance W/mm^2 per vertex (stored as float32)
    info : dict: ``mm_per_unit`` (float), ``model`` and ``material`` (the bake's one-line description; None when
        not recorded), ``eta`` (float from the material line, or None), ``source`` (the mesh that was baked, or
        None), ``comments`` (every header comment line)

    Raises
    ------
    MeshValidationError
        One line naming the file: unreadable or malformed PLY, radiance values that are not finite or negative.
    """
    path = Path(path)
    if _check_input_file(path) != "ply":
        return None
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshValidationError(f"cannot read {path}: {_one_line(exc)}") from exc
    header = _parse_ply_header(data, path)
    vertex_props = next((props for name, _, props in header[1] if name == "vertex"), [])
    if not set(BAKED_RADIANCE) <= {p for p, t, c in vertex_props if c is None and t[0] == "f"}:
        return None
    V, F, columns, comments = _ply_data(path, data, header)
    record: dict = {}
    for line in comments:
        match = _BAKE_RECORD.match(line.strip())
        if match:
            record.setdefault(match.group(1), match.group(2).strip())
    try:
        factor = float(record["mm_per_unit"].split()[0])
    except (KeyError, IndexError, ValueError):
        factor = mm_per_unit(units)
    if not (np.isfinite(factor) and factor > 0):
        raise MeshValidationError(f"{path}: the recorded mm_per_unit {record.get('mm_per_unit')!r} is not a positive "
                                  "number")
    radiance = np.stack([np.asarray(columns[c], np.float64) for c in BAKED_RADIANCE], axis=1)
    bad = ~(np.isfinite(radiance) & (radiance >= 0))
    if bad.any():
        raise MeshValidationError(f"{path}: {int(bad.any(axis=1).sum())} vertices have radiance_r/g/b that are not "
                                  "finite non-negative numbers (a damaged bake?)")
    eta = _BAKE_ETA.search(record.get("material", ""))
    try:
        mesh = Mesh(V * factor, F, mm_per_unit=factor, source=str(path))
    except MeshValidationError as exc:
        raise MeshValidationError(f"{path}: {exc}") from None
    info = {"mm_per_unit": factor, "model": record.get("model"), "material": record.get("material"),
            "eta": float(eta.group(1)) if eta else None, "source": record.get("source"), "comments": list(comments)}
    return mesh, radiance, info


# ----------------------------------------------------------------------------------------------- writing

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


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_float32(path, what: str, values) -> None:
    """Refuse (``OutputError``) to write ``values`` that are NaN, infinite or beyond float32's range (which the
    file would store as infinity): an output file holds finite numbers or is not written."""
    v = np.asarray(values, dtype=np.float64)
    bad = ~(np.abs(v) <= _FLOAT32_MAX)
    if bad.any():
        raise OutputError(f"refusing to write {path}: {what} has {int(bad.sum())} value(s) that are not finite "
                          f"32-bit floats (first: {float(v[bad].flat[0])!r})")


def _ply_header(n: int, m: int, props, colors: bool, comments) -> bytes:
    lines = ["ply", "format binary_little_endian 1.0"]
    for c in comments:
        text = " ".join(str(c).split())  # one header line each
        lines.append(f"comment {text}".rstrip())
    lines += [f"element vertex {n}", "property float x", "property float y", "property float z"]
    lines += [f"property float {name}" for name in props]
    if colors:
        lines += ["property uchar red", "property uchar green", "property uchar blue"]
    lines += [f"element face {m}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(lines) + "\n").encode("ascii", errors="replace")


def write_ply(path, vertices, faces, vertex_float_props=None, vertex_colors=None, *, comments=()) -> Path:
    """Write a binary little-endian PLY (atomically) that MeshLab, Blender and trimesh open.

    Vertex layout: ``float x, y, z``, then one ``float`` per entry of ``vertex_float_props`` (in dict order),
    then ``uchar red, green, blue`` when ``vertex_colors`` is given; faces as ``list uchar int vertex_indices``.

    Parameters
    ----------
    path : str or Path
    vertices : (n, 3) float, written as float32 as given (no unit conversion here; see ``write_mesh_ply``)
    faces : (m, 3) int, 0-based
    vertex_float_props : dict[str, (n,) float], optional; names must be identifiers and not in
        ``PLY_RESERVED_NAMES``; written as float32
    vertex_colors : (n, 3) uint8, optional
    comments : iterable of str, header comment lines (ASCII)

    Returns
    -------
    Path written.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"vertices must be (n, 3), got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu":
        raise ValueError(f"faces must be an (m, 3) integer array, got shape {F.shape} dtype {F.dtype}")
    n, m = V.shape[0], F.shape[0]
    if m and (F.min() < 0 or F.max() >= n):
        raise ValueError("face indices out of range")
    props = dict(vertex_float_props or {})
    for name, values in props.items():
        if not _NAME.match(name) or name in PLY_RESERVED_NAMES:
            raise ValueError(f"invalid PLY property name {name!r} (an identifier, not one of the reserved names)")
        if np.shape(values) != (n,):
            raise ValueError(f"property {name!r} must have shape ({n},), got {np.shape(values)}")
        _check_float32(path, f"vertex property {name}", values)
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")] + [(name, "<f4") for name in props]
    if vertex_colors is not None:
        colors = np.asarray(vertex_colors)
        if colors.shape != (n, 3) or colors.dtype != np.uint8:
            raise ValueError(f"vertex_colors must be an (n, 3) uint8 array, got {colors.shape} {colors.dtype}")
        dtype += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vert = np.empty(n, dtype=np.dtype(dtype))  # packed: numpy structured dtypes have no padding by default
    vert["x"], vert["y"], vert["z"] = V[:, 0], V[:, 1], V[:, 2]
    for name, values in props.items():
        vert[name] = np.asarray(values, dtype=np.float64)
    if vertex_colors is not None:
        vert["red"], vert["green"], vert["blue"] = colors[:, 0], colors[:, 1], colors[:, 2]
    face = np.empty(m, dtype=np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
    face["n"] = 3
    face["i"] = F
    header = _ply_header(n, m, props, vertex_colors is not None, comments)
    path = check_output_path(path, suffixes=(".ply",), option="PLY output")
    with atomic_write(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(header)
            fh.write(vert.tobytes())
            fh.write(face.tobytes())
    return path


def write_mesh_ply(path, mesh: Mesh, vertex_float_props=None, vertex_colors=None, *, comments=()) -> Path:
    """Write ``mesh`` with per-vertex results as PLY, positions in the **source file's units**.

    The PLY then overlays the input in a viewer. The header records ``comment meshshade mm_per_unit <f>``
    (multiply positions by it for mm) and the source path. Faces are the validated (possibly re-wound) faces.
    Refuses (``OutputError``) to overwrite the mesh's own source file.
    """
    if mesh.source and Path(mesh.source).exists():
        check_output_path(path, [mesh.source])
    head = [f"meshshade mm_per_unit {mesh.mm_per_unit!r} (positions in source units; times mm_per_unit = mm)"]
    if mesh.source:
        head.append(f"meshshade source {mesh.source}")
    return write_ply(path, mesh.vertices_in_source_units(), mesh.faces, vertex_float_props, vertex_colors,
                     comments=[*head, *comments])


def write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8, e.g. a CSV table) atomically."""
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_figure(path, figure, *, dpi: int = 150) -> Path:
    """Save a matplotlib ``figure`` atomically, in the format named by the extension (.png, .pdf, .svg, ...),
    then close it."""
    path = Path(path)
    fmt = path.suffix[1:].lower()
    supported = figure.canvas.get_supported_filetypes()
    if fmt not in supported:
        raise OutputError(f"unsupported figure format {path.suffix or '(no extension)'!r} for {path}; "
                          f"use one of {', '.join('.' + k for k in sorted(supported))}")
    try:
        with atomic_write(path) as tmp:
            figure.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight")
    finally:
        import matplotlib.pyplot as plt  # lazy: heavy plotting library; already loaded by whoever made the figure

        plt.close(figure)
    return path


def write_npz(path, **arrays) -> Path:
    """Write arrays to a compressed ``.npz`` atomically (``numpy.savez_compressed`` into a temporary file)."""
    path = check_output_path(path, suffixes=(".npz",), option="NPZ output")
    with atomic_write(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return path


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` (a GLB, say) atomically."""
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_usd(path, stage) -> Path:
    """Write a ``Usd.Stage`` (:mod:`meshshade.output.usd`) atomically: ``.usda`` as text, ``.usd`` and ``.usdc`` as
    binary crate files (the temporary file keeps the extension, from which USD picks the format)."""
    path = Path(path)
    with atomic_write(path) as tmp:
        if not stage.GetRootLayer().Export(str(tmp)):
            raise OutputError(f"could not write {path}: USD refused to export the stage")
    return path


def write_json(path, obj) -> Path:
    """Write ``obj`` as indented JSON (UTF-8) atomically."""
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2) + "\n", encoding="utf-8")
    return path


# ----------------------------------------------------------------------------------------------- images
def _oiio():
    try:
        import OpenImageIO as oiio  # lazy: ~0.3 s to import; only image outputs need it
    except ImportError as exc:  # pragma: no cover - a required dependency
        raise OutputError(f"OpenImageIO is needed to write images: {_one_line(exc)}") from None
    return oiio


def _write_image(path, pixels, fmt, metadata=None) -> Path:
    oiio = _oiio()
    path = Path(path)
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    if c == 4:
        spec.channelnames = ("R", "G", "B", "A")
        spec.alpha_channel = 3
    for key, value in (metadata or {}).items():
        spec.attribute(f"meshshade:{key}", str(value))
    directory = path.parent if str(path.parent) else Path(".")
    with atomic_write(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        ok = out is not None and out.open(str(tmp), spec)
        if ok:
            ok = out.write_image(np.ascontiguousarray(pixels))
            err = out.geterror()
            ok = out.close() and ok
            err = err or out.geterror()
        else:
            err = oiio.geterror() or (out.geterror() if out else "")
        if not ok:  # OpenImageIO's messages name the temporary file and not the cause ("Failed OpenEXR write")
            err = " ".join(str(err).replace(str(tmp), str(path)).split()) or "OpenImageIO error"
            raise OutputError(f"could not write {path}: {_no_space_hint(directory, err)}")
    return path


def write_exr(path, rgba_float, metadata: dict | None = None) -> Path:
    """Write an (H, W, 4) or (H, W, 3) linear float image as OpenEXR (half=no: 32-bit float) atomically.

    ``metadata`` entries become string attributes ``meshshade:<key>`` (model, material, lights, camera, units).
    """
    arr = np.asarray(rgba_float, dtype=np.float32)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"image must be (H, W, 3|4), got {arr.shape}")
    check_output_path(path, suffixes=(".exr",), option="EXR output")
    _check_float32(path, "the image", rgba_float)
    return _write_image(path, arr, "float", metadata)


def write_png(path, rgba_uint8) -> Path:
    """Write an (H, W, 4|3) uint8 image (sRGB-encoded, straight alpha) as PNG atomically."""
    arr = np.asarray(rgba_uint8)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"PNG image must be (H, W, 3|4) uint8, got {arr.shape} {arr.dtype}")
    check_output_path(path, suffixes=(".png",), option="PNG output")
    return _write_image(path, arr, "uint8")


def read_exr(path) -> tuple[np.ndarray, dict]:
    """Read an image through OpenImageIO: ((H, W, C) float32 pixels, {key: value} of ``meshshade:*`` attributes)."""
    oiio = _oiio()
    path = Path(path)
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise MeshValidationError(f"{path}: cannot read image: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        meta = {a.name.split(":", 1)[1]: a.value for a in spec.extra_attribs if a.name.startswith("meshshade:")}
    finally:
        inp.close()
    return np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels), meta


# ----------------------------------------------------------------------------------------------- batch folders
#: a job folder being written: ``.<name>.part-<random>`` beside the final ``<name>`` (meshshade.batch)
_PART = re.compile(r"^\.(.+)\.part-[0-9a-f]{8}$")


def read_toml(path) -> dict:
    """A TOML file (a batch's job file) as a dict; MeshshadeError with one line naming the file and the problem."""
    try:
        import tomllib
    except ModuleNotFoundError:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    path = Path(path)
    if not path.is_file():
        raise MeshshadeError(f"job file not found: {path}" if not path.exists() else f"{path} is not a file")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise MeshshadeError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise MeshshadeError(f"cannot read {path}: {exc.strerror or _one_line(exc)}") from None


def read_json_lines(path) -> list[dict]:
    """The records of a JSON-lines file (a batch manifest); [] when it does not exist. A line that is not a JSON
    object (a torn last line) is skipped."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise MeshshadeError(f"cannot read {path}: {exc.strerror or _one_line(exc)}") from None
    out = []
    for line in text.splitlines():
        with contextlib.suppress(ValueError):
            rec = json.loads(line)
            if isinstance(rec, dict):
                out.append(rec)
    return out


def write_json_lines(path, records) -> Path:
    """Write ``records`` (dicts) as JSON lines, atomically."""
    return write_text(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in records))


def read_json(path):
    """A JSON file's content, or None when it is missing or unreadable."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


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


def write_obj(path, vertices, faces, *, comment: str | None = None) -> Path:
    """Write an OBJ (atomically) of ``vertices`` (n, 3), every float64 written exactly (17 significant digits, so
    :func:`load_mesh` reads back the same numbers), and 0-based triangle ``faces`` (m, 3)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"vertices and faces must be (n, 3) and (m, 3), got {V.shape} and {F.shape}")
    path = check_output_path(path, suffixes=(".obj",), option="OBJ output")
    with atomic_write(path) as tmp:
        with open(tmp, "w", encoding="ascii") as fh:
            if comment:
                fh.write("".join(f"# {line}\n" for line in comment.splitlines()))
            np.savetxt(fh, V, fmt="v %.17g %.17g %.17g")
            np.savetxt(fh, F + 1, fmt="f %d %d %d")
    return path
