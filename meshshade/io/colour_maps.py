"""Painted colours read from files (docs/physics.md §17): a colour map image, the OBJ's MTL ``map_Kd``, or a PLY's
vertex colours, all returned linear; and a data map (a radius map, eq. (132)) read without any transfer function.

* an image through OpenImageIO: OpenEXR and Radiance HDR are read as linear; 8- and 16-bit images (PNG, JPEG,
  TIFF, TGA...) are sRGB-encoded colours and are decoded with the sRGB transfer function (IEC 61966-2-1);
* ``mtl``: the ``map_Kd`` of the material library an OBJ names (``mtllib``), relative to the library's folder;
  an OBJ whose materials name several different maps is refused (per-part materials are not supported yet);
* ``vertex``: a PLY's ``red, green, blue`` vertex properties (uchar: sRGB; float: linear), matched to the loaded
  mesh's vertices by position (the loader may merge duplicates).

Every failure is a one-line MeshValidationError naming the file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from meshshade.errors import MeshValidationError
from meshshade.io._messages import _one_line
from meshshade.io.images import UnreadableImage, read_pixels
from meshshade.io.ply import _parse_ply_header, _ply_data

__all__ = ["read_colour_map", "read_data_map", "mtl_colour_map", "read_vertex_colours", "srgb_to_linear",
           "LINEAR_FORMATS"]

#: image formats whose values are linear (the rest are sRGB-encoded)
LINEAR_FORMATS = (".exr", ".hdr")


def srgb_to_linear(v):
    """The sRGB transfer function's inverse (IEC 61966-2-1) of encoded values in [0, 1]."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def read_colour_map(path) -> np.ndarray:
    """(H, W, 3) linear float64 colours of the image at ``path`` (module docstring; a grey image is repeated into
    three channels, alpha dropped)."""
    path = Path(path)
    px = _read_three_channels(path, "colour map")
    return px if path.suffix.lower() in LINEAR_FORMATS else srgb_to_linear(px)


def read_data_map(path, what: str = "radius map") -> np.ndarray:
    """(H, W, 3) float64 values of the image at ``path`` read as data, not colour (Blender's Non-Color): no sRGB
    decoding, an 8-bit value v read as v / 255; a grey image repeated into three channels, alpha dropped."""
    return _read_three_channels(Path(path), what)


def _read_three_channels(path: Path, what: str) -> np.ndarray:
    if not path.is_file():
        raise MeshValidationError(f"{path}: {what} not found")
    try:
        px, spec = read_pixels(path)
    except UnreadableImage as exc:
        raise MeshValidationError(f"{path}: cannot read the {what}: {_one_line(str(exc))}") from None
    px = px.astype(np.float64)
    if spec.nchannels < 3:
        px = np.repeat(px[:, :, :1], 3, axis=2)
    px = px[:, :, :3]
    if not np.all(np.isfinite(px)):
        raise MeshValidationError(f"{path}: the {what} holds values that are not finite")
    return px


def mtl_colour_map(obj_path) -> Path:
    """The ``map_Kd`` file of the material library that the OBJ at ``obj_path`` names (module docstring)."""
    obj_path = Path(obj_path)
    if obj_path.suffix.lower() != ".obj":
        raise MeshValidationError(f"{obj_path}: --albedo-map mtl needs an OBJ with a material library (mtllib)")
    libs = []
    with open(obj_path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("mtllib"):
                libs += [obj_path.parent / name for name in line.split()[1:]]
    if not libs:
        raise MeshValidationError(f"{obj_path}: names no material library (mtllib), so no map_Kd")
    maps = []
    for lib in libs:
        if not lib.is_file():
            raise MeshValidationError(f"{obj_path}: its material library {lib.name} is not found")
        for line in lib.read_text(encoding="utf-8", errors="replace").splitlines():
            parts = line.split()
            if parts and parts[0] == "map_Kd" and len(parts) > 1:
                maps.append(lib.parent / parts[-1])
    if not maps:
        raise MeshValidationError(f"{obj_path}: its material library has no map_Kd")
    if len(set(maps)) > 1:
        raise MeshValidationError(f"{obj_path}: its materials name {len(set(maps))} different map_Kd (a map per "
                                  "part is not supported yet)")
    return maps[0]


def read_vertex_colours(path, mesh) -> np.ndarray:
    """(n_vertices, 3) linear colours of ``mesh`` (loaded from the PLY at ``path``) from the file's ``red, green,
    blue`` vertex properties (module docstring)."""
    path = Path(path)
    if path.suffix.lower() != ".ply":
        raise MeshValidationError(f"{path}: --albedo-map vertex needs a PLY with red, green, blue vertex colours")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshValidationError(f"cannot read {path}: {_one_line(exc)}") from None
    header = _parse_ply_header(data, path)
    V, _, columns, _ = _ply_data(path, data, header)
    names = ("red", "green", "blue")
    if not all(n in columns for n in names):
        raise MeshValidationError(f"{path}: has no red, green, blue vertex colours")
    declared = {p[0]: np.dtype(p[1]) for name, _, props in header[1] if name == "vertex" for p in props}
    kind = declared["red"]
    rgb = np.stack([np.asarray(columns[n], dtype=np.float64) for n in names], axis=1)
    if np.issubdtype(kind, np.integer):           # encoded sRGB: 8 bits (uchar) or 16 (ushort)
        rgb = srgb_to_linear(rgb / float(np.iinfo(kind).max))
    d, i = cKDTree(np.asarray(V, dtype=np.float64) * mesh.mm_per_unit).query(mesh.vertices)
    if np.any(d > 1e-6 * max(1.0, float(np.abs(mesh.vertices).max()))):
        raise MeshValidationError(f"{path}: its vertex colours cannot be matched to the loaded mesh's vertices")
    return rgb[i]
