"""File input and output: the only module that touches the file system.

Reading meshes
--------------
``load_mesh(path, units="mm")`` reads OBJ, PLY, OFF, STL, GLB and glTF. Nothing is merged, reordered or guessed:

* **OBJ** is read by a small parser here, not by trimesh: trimesh splits an OBJ by material or object into
  several geometries (each with a copy of the vertex list, faces regrouped), which breaks the file's face order.
  Only ``v`` and ``f`` records are used (texture coordinates, normals, groups and materials are ignored);
  indices may be negative (relative); polygons with more than three corners are fan-triangulated
  ``(0, i, i+1)``, with a warning, because that changes the face count.
* **PLY, OFF** are read by trimesh with ``process=False, maintain_order=True``: the file's vertex and face order
  are kept.
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
interrupted run never leaves a partial file. ``check_output_path`` refuses an output that is one of the inputs.
Writers: ``write_ply`` / ``write_mesh_ply`` (binary PLY with per-vertex float properties and colours),
``write_npz``, ``write_text`` (CSV tables) and ``write_figure`` (matplotlib, format from the extension).
``write_mesh_ply`` writes positions in the **source file's units** (so the result overlays the input in Blender or
MeshLab) and records the factor as a ``comment meshshade mm_per_unit <f>`` header line.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import warnings
from pathlib import Path

import numpy as np

from meshshade.errors import MeshValidationError, OutputError
from meshshade.geometry.mesh import Mesh, MeshDefectWarning
from meshshade.units import mm_per_unit

__all__ = ["SUPPORTED_MESH_FORMATS", "load_mesh", "read_mesh_arrays", "atomic_write", "check_output_path",
           "write_ply", "write_mesh_ply", "write_npz", "write_text", "write_json", "write_figure", "PLY_RESERVED_NAMES",
           "write_exr", "write_png", "read_exr"]

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


_OBJ_V = re.compile(r"^[ \t]*v[ \t]+([^\n]*)", re.M)
_OBJ_F = re.compile(r"^[ \t]*f[ \t]+([^\n]*)", re.M)


def _read_obj(path: Path):
    """Positions and faces of an OBJ file, in file order (see the module docstring).

    Fast path: whole-text regular expressions and one numpy conversion. Anything unusual (malformed numbers,
    index 0, relative indices) goes to the line-by-line reader, which also reports the line number of an error.
    """
    text = path.read_text(encoding="utf-8", errors="replace")
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
    return _read_obj_lines(path)


def _read_obj_lines(path: Path):
    """Line-by-line OBJ reader: general (polygons, relative indices) and precise about errors."""
    verts: list = []
    faces: list = []
    n_polygons = 0
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        pending = ""
        for lineno, raw in enumerate(fh, start=1):
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
        warnings.warn(f"{path}: {n_polygons} polygons with more than 3 corners were fan-triangulated",
                      MeshDefectWarning, stacklevel=3)
    return np.array(verts, dtype=np.float64).reshape(-1, 3), np.array(faces, dtype=np.int64).reshape(-1, 3)


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
    if fmt == "obj":
        try:
            return _read_obj(path)
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
    Defects are reported as ``MeshDefectWarning`` (see ``meshshade.geometry.mesh``).

    Raises
    ------
    UnitsError for an unknown unit; MeshValidationError (one line naming the file) for anything else.
    """
    mm_per_unit(units)  # an unknown unit fails before the file is read
    path = Path(path)
    V, F = read_mesh_arrays(path)
    if path.suffix.lower() in (".glb", ".gltf") and str(units).strip().lower() != "m":
        warnings.warn(f"{path}: glTF positions are metres by specification, but units={units!r} was given",
                      UserWarning, stacklevel=2)
    try:
        return Mesh.from_arrays(V, F, units=units, source=str(path))
    except MeshValidationError as exc:
        raise MeshValidationError(f"{path}: {exc}") from None


# ----------------------------------------------------------------------------------------------- writing

def check_output_path(out, inputs=()) -> Path:
    """Check that ``out`` can be written and is none of ``inputs``; return it as a Path.

    Raises
    ------
    OutputError
        The output is an existing directory, its directory is missing or not writable, or it resolves to the
        same file as one of ``inputs`` (symbolic and hard links included).
    """
    out = Path(out)
    if out.is_dir():
        raise OutputError(f"output {out} is a directory; give a file name")
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
    return out


def output_dir(path, option: str = "--out") -> Path:
    """Create the output directory ``path`` (parents too; an existing directory is used as it is); return it.

    ``option`` names the command-line option the path came from, for the error message.

    Raises
    ------
    OutputError
        ``path`` exists and is not a directory, or it cannot be created (one line).
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{option} {out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output folder {out}: {exc.strerror}") from None
    return out


@contextlib.contextmanager
def atomic_write(path):
    """Context manager yielding a temporary path next to ``path``; on success it replaces ``path``.

    The temporary file (``.<name>.<random>.tmp<suffix>``, same directory, so the final ``os.replace`` is atomic
    and writers that choose a format by extension still work) is created empty with the usual permissions
    (0o666 minus the umask). On any exception, KeyboardInterrupt included, it is removed and ``path`` is left
    untouched. ``OSError`` while writing becomes ``OutputError`` with one line.

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
            raise OutputError(f"cannot create a file in {directory}: {_one_line(exc)}") from exc
    else:  # pragma: no cover - 100 collisions of a 32-bit random name
        raise OutputError(f"cannot create a temporary file in {directory}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):
            raise OutputError(f"could not write {path}: {_one_line(exc)}") from exc
        raise


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
    path = Path(path)
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
    path = Path(path)
    with atomic_write(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
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
    with atomic_write(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise OutputError(f"could not write {path}: {oiio.geterror() or (out.geterror() if out else '')}")
        ok = out.write_image(np.ascontiguousarray(pixels))
        err = out.geterror()
        out.close()
        if not ok:
            raise OutputError(f"could not write {path}: {err}")
    return path


def write_exr(path, rgba_float, metadata: dict | None = None) -> Path:
    """Write an (H, W, 4) or (H, W, 3) linear float image as OpenEXR (half=no: 32-bit float) atomically.

    ``metadata`` entries become string attributes ``meshshade:<key>`` (model, material, lights, camera, units).
    """
    arr = np.asarray(rgba_float, dtype=np.float32)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"image must be (H, W, 3|4), got {arr.shape}")
    return _write_image(path, arr, "float", metadata)


def write_png(path, rgba_uint8) -> Path:
    """Write an (H, W, 4|3) uint8 image (sRGB-encoded, straight alpha) as PNG atomically."""
    arr = np.asarray(rgba_uint8)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"PNG image must be (H, W, 3|4) uint8, got {arr.shape} {arr.dtype}")
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
