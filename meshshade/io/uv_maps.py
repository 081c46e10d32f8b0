"""Texture coordinates read from mesh files, as per-corner UV maps matched to a loaded mesh's faces.

* **OBJ**: ``vt`` records and the texture index of each face corner (``f v/vt``, ``f v/vt/vn``; negative indices
  relative, as for positions); polygons fan-triangulated ``(0, i, i+1)`` as the geometry is. A file with ``vt``
  where some faces have no texture index is refused with the count (a texture of part of a mesh is not guessed).
* **glTF / GLB**: ``TEXCOORD_0`` of each primitive (read by trimesh, v already flipped to the OpenGL origin used
  here), in the same mesh and instance order as the geometry.
* **PLY**: per-vertex ``s, t``, ``u, v`` or ``texture_u, texture_v`` properties.
* OFF and STL carry no texture coordinates.

The loaded mesh's faces may differ from the file's rows (validation repairs the winding): corners are matched by
vertex, face by face, so each corner keeps its own UV (a repaired face's UVs are permuted with it).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from meshshade.errors import MeshValidationError
from meshshade.io._messages import _one_line
from meshshade.io.meshes import _check_input_file, _read_obj_lines
from meshshade.io.ply import _ply_data

__all__ = ["read_uv_map", "read_corner_uv"]

_PLY_UV = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"))


def read_corner_uv(path):
    """(the file's faces (m, 3) as :func:`meshshade.io.read_mesh_arrays` reads them, their corner UVs (m, 3, 2)), or
    None when the file has no texture coordinates; the file is read once."""
    path = Path(path)
    fmt = _check_input_file(path)
    try:
        if fmt == "obj":
            _, F, uv = _read_obj_lines(path, uv=True)
            return None if uv is None else (F, uv)
        if fmt == "ply":
            return _ply_uv(path)
        if fmt in ("glb", "gltf"):
            return _gltf_uv(path, fmt)
    except OSError as exc:
        raise MeshValidationError(f"cannot read {path}: {_one_line(exc)}") from exc
    return None


def read_uv_map(path, mesh) -> np.ndarray | None:
    """Per-corner UVs (m, 3, 2) of the file at ``path`` for the faces of ``mesh`` (loaded from it), or None when
    the file has none (module docstring)."""
    got = read_corner_uv(path)
    return None if got is None else match_corners(got[0], got[1], mesh.faces, path)


def match_corners(F_file, uv_file, F_mesh, path="mesh") -> np.ndarray:
    """UVs of the faces ``F_mesh`` from those of ``F_file`` (the same triangles, corners possibly permuted)."""
    F_file = np.asarray(F_file, dtype=np.int64)
    F_mesh = np.asarray(F_mesh, dtype=np.int64)
    if F_file.shape == F_mesh.shape and np.array_equal(F_file, F_mesh):
        return np.asarray(uv_file, dtype=np.float64)
    n = int(max(F_file.max(initial=0), F_mesh.max(initial=0))) + 1
    key = lambda F: np.sort(F, axis=1) @ np.array([n * n, n, 1], dtype=np.int64)   # noqa: E731
    kf, km = key(F_file), key(F_mesh)
    order = np.argsort(kf, kind="stable")
    pos = np.searchsorted(kf[order], km)
    ok = (pos < kf.size) & (kf[order[np.minimum(pos, kf.size - 1)]] == km)
    if not ok.all():
        raise MeshValidationError(f"{path}: {int((~ok).sum())} faces of the mesh are not in the file; its texture "
                                  "coordinates cannot be matched")
    src = order[pos]
    out = np.empty((F_mesh.shape[0], 3, 2))
    for c in range(3):
        corner = np.argmax(F_file[src] == F_mesh[:, c:c + 1], axis=1)
        out[:, c] = uv_file[src, corner]
    return out


def _ply_uv(path: Path):
    _, F, columns, _ = _ply_data(path, path.read_bytes())
    for su, sv in _PLY_UV:
        if su in columns and sv in columns:
            uv = np.stack([np.asarray(columns[su], np.float64), np.asarray(columns[sv], np.float64)], axis=1)
            return F, uv[F]
    return None


def _gltf_uv(path: Path, fmt: str):
    import trimesh  # lazy, as the geometry reader

    try:
        loaded = trimesh.load(str(path), file_type=fmt, process=False, maintain_order=True)
    except Exception as exc:  # noqa: BLE001 - the geometry reader reports the same file's problem first
        raise MeshValidationError(f"could not read {fmt.upper()} file {path}: {_one_line(exc)}") from exc
    scene = loaded if isinstance(loaded, trimesh.Scene) else trimesh.Scene(loaded)
    # the geometry reader's order and winding (meshes._scene_arrays): file's mesh order, mirrored instances flipped
    rank = {name: i for i, name in enumerate(scene.geometry)}
    nodes = sorted(scene.graph.nodes_geometry, key=lambda node: (rank[scene.graph[node][1]], str(node)))
    faces, corners, offset, missing = [], [], 0, 0
    for node in nodes:
        transform, name = scene.graph[node]
        geom = scene.geometry[name]
        if not isinstance(geom, trimesh.Trimesh):
            continue
        F = np.asarray(geom.faces, dtype=np.int64)
        uv = getattr(geom.visual, "uv", None)
        if uv is None or len(uv) != len(geom.vertices):
            missing += 1
            uv = np.zeros((len(geom.vertices), 2))
        if np.linalg.det(np.asarray(transform, dtype=np.float64)[:3, :3]) < 0:
            F = F[:, [0, 2, 1]]
        corners.append(np.asarray(uv, dtype=np.float64)[:, :2][F])
        faces.append(F + offset)
        offset += len(geom.vertices)
    if not corners or missing == len(corners):
        return None
    if missing:
        raise MeshValidationError(f"{path}: {missing} of {len(corners)} mesh instances have no TEXCOORD_0: a texture "
                                  "needs every face mapped")
    return np.concatenate(faces), np.concatenate(corners)
