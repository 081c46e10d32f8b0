"""Reading meshes: OBJ, PLY, OFF, STL, GLB and glTF in the file's order, converted to mm (``load_mesh``), and a
bake's PLY read back (``read_baked_ply``).

``load_mesh(path, units="mm")`` reads OBJ, PLY, OFF, STL, GLB and glTF. Nothing is merged, reordered or guessed:

* **OBJ** is read by a small parser here, not by trimesh: trimesh splits an OBJ by material or object into
  several geometries (each with a copy of the vertex list, faces regrouped), which breaks the file's face order.
  Only ``v`` and ``f`` records are used (texture coordinates, normals, groups and materials are ignored);
  indices may be negative (relative); polygons with more than three corners are fan-triangulated
  ``(0, i, i+1)``, with a warning, because that changes the face count.
* **PLY** (ASCII, binary little- and big-endian; read by :mod:`meshshade.io.ply`) and **OFF** (also
  COFF/NOFF/STOFF; extra columns ignored) are read by readers of this package, in file order. Their counts are
  checked against the data: a header (PLY) or count line (OFF) that declares more or fewer rows than the file holds
  (ASCII), or more or fewer bytes (binary PLY: a truncated or over-long file), is an error naming both, never read
  with face rows taken for vertices. Polygons are fan-triangulated ``(0, i, i+1)`` in place (each polygon's
  triangles where the polygon was), with the same warning as OBJ. (trimesh, used before, triangulates silently and
  out of order: triangles first, then every quad's ``(0, 1, 2)``, then every quad's ``(2, 3, 0)``, then larger
  polygons; and it cannot read binary PLY whose polygons have different sizes, which Blender writes.) Other PLY
  elements and properties are skipped.
* **Text encodings** (OBJ, ASCII PLY, OFF): UTF-8 or ASCII, with or without a byte-order mark (a UTF-8 BOM before
  the first record is dropped, not read as part of it); UTF-16 with its byte-order mark is decoded too
  (:mod:`meshshade.io._reading`).
* **GLB / glTF** scenes are concatenated in the file's mesh order (instances of one mesh by node name), each
  instance moved by its node transform (faces are re-wound under a mirroring transform). glTF positions are metres by
  specification; a warning says so when ``units`` is not ``"m"`` (the unit is still the caller's choice).
* **STL** stores three independent corners per facet, so it has no shared vertices and no vertex order to keep.
  Corners with bitwise-equal positions are merged, numbered in order of first appearance (deterministic, exact:
  no tolerance). This is the only format where vertices are merged.

Coordinates are converted to mm once, by ``mm_per_unit(units)``. Every reading problem raises
``MeshValidationError`` with one line naming the file.
"""
from __future__ import annotations

import dataclasses
import re
import warnings
from pathlib import Path

import numpy as np

from meshshade import memo
from meshshade.errors import MeshValidationError
from meshshade.geometry.mesh import Mesh, MeshDefectWarning
from meshshade.io._messages import _one_line
from meshshade.io._reading import _decode_text, _fan_triangulate, _obj_statements, _warn_polygons
from meshshade.io.ply import _parse_ply_header, _ply_data, _read_ply
from meshshade.units import mm_per_unit

__all__ = ["SUPPORTED_MESH_FORMATS", "load_mesh", "read_mesh_arrays", "read_baked_ply", "BAKED_RADIANCE"]

#: file extension -> format name
SUPPORTED_MESH_FORMATS = {".obj": "obj", ".ply": "ply", ".off": "off", ".stl": "stl", ".glb": "glb",
                          ".gltf": "gltf"}


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


# --- OBJ -----------------------------------------------------------------------------------------------------
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


def _read_obj_lines(path: Path, text: str | None = None, *, uv: bool = False):
    """Line-by-line OBJ reader: general (polygons, relative indices) and precise about errors.

    ``text``: the file's decoded text when the caller has read it already (see ``_decode_text``). With ``uv``,
    also the texture coordinates: returns (V, F, corner UV (m, 3, 2) or None when the file has no ``vt``), the
    corners' ``f v/vt`` indices fan-triangulated as the faces are; a file with ``vt`` where some faces have none is
    refused with the count."""
    if text is None:
        text = _decode_text(path.read_bytes(), path)
    verts: list = []
    faces: list = []
    vt: list = []
    corners: list = []
    untextured = 0
    n_polygons = 0
    for lineno, line, parts in _obj_statements(text):
        if parts[0] == "v":
            try:
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except (IndexError, ValueError):
                raise MeshValidationError(f"{path}:{lineno}: malformed vertex line {line.strip()[:60]!r}") \
                    from None
        elif parts[0] == "vt" and uv:
            try:
                vt.append((float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0))
            except (IndexError, ValueError):
                raise MeshValidationError(f"{path}:{lineno}: malformed texture coordinate line "
                                          f"{line.strip()[:60]!r}") from None
        elif parts[0] == "f":
            n = len(verts)
            fields = [p.split("/") for p in parts[1:]]
            try:
                idx = [int(f[0]) for f in fields]
                tex = [int(f[1]) for f in fields] if uv and all(len(f) > 1 and f[1] for f in fields) else None
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
            if uv:
                if tex is None:
                    untextured += len(idx) - 2
                    tex = [0] * len(idx)
                tex = [t - 1 if t > 0 else len(vt) + t for t in tex]
                corners.extend((tex[0], tex[k], tex[k + 1]) for k in range(1, len(tex) - 1))
    if not verts and not faces:
        raise MeshValidationError(f"no OBJ vertex or face records in {path}")
    if n_polygons:
        _warn_polygons(path, n_polygons)
    V, F = np.array(verts, dtype=np.float64).reshape(-1, 3), np.array(faces, dtype=np.int64).reshape(-1, 3)
    if not uv:
        return V, F
    if not vt:
        return V, F, None
    if untextured:
        raise MeshValidationError(f"{path}: {untextured} of {F.shape[0]} triangles have no texture coordinates "
                                  "(f v/vt): a texture needs every face mapped")
    C = np.array(corners, dtype=np.int64).reshape(-1, 3)
    T = np.array(vt, dtype=np.float64)
    if C.size and (C.min() < 0 or C.max() >= T.shape[0]):
        raise MeshValidationError(f"{path}: a face refers to texture coordinate {int(C.max()) + 1} of {T.shape[0]}")
    return V, F, T[C]


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


# --- STL, GLB, glTF (through trimesh) and every format ------------------------------------------------------
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


# --- a bake read back ----------------------------------------------------------------------------------------
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
