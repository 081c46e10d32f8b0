"""PLY: the reader (ASCII, binary little- and big-endian) and the writers (binary little-endian, with per-vertex
float properties and colours).

Reading (for :func:`meshshade.io.meshes.read_mesh_arrays` and :func:`meshshade.io.meshes.read_baked_ply`): in file
order; a header that declares more or fewer rows than the file holds (ASCII), or more or fewer bytes (binary: a
truncated or over-long file), is an error naming both. Polygons are fan-triangulated ``(0, i, i+1)`` in place, with
a warning; binary face lists whose lengths vary from row to row (which Blender writes) are read through a compiled
scan of the rows (numba, compiled on first use). Other elements and properties are skipped.

Writing: ``write_ply`` / ``write_mesh_ply`` write atomically (:mod:`meshshade.io.transactions`) and refuse values a
float32 cannot hold. ``write_mesh_ply`` writes positions in the **source file's units** (so the result overlays the
input in Blender or MeshLab) and records the factor as a ``comment meshshade mm_per_unit <f>`` header line.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from meshshade.errors import MeshValidationError
from meshshade.geometry.mesh import Mesh
from meshshade.io._reading import _as_indices, _decode_text, _fan_triangulate, _warn_polygons
from meshshade.io.transactions import atomic_write, check_output_path
from meshshade.io.writers import _check_float32

__all__ = ["write_ply", "write_mesh_ply", "PLY_RESERVED_NAMES"]

#: vertex property names that write_ply uses itself (or that viewers interpret) and so refuses as custom props
PLY_RESERVED_NAMES = frozenset({"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "s", "t",
                                "u", "v", "vertex_indices"})

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


# --- reading -------------------------------------------------------------------------------------------------
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
    """Start of every row of a binary PLY element with list properties (sizes vary per row): compiled loop.

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


# --- writing -------------------------------------------------------------------------------------------------
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
