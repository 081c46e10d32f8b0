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
from meshshade.io._reading import _decode_text
from meshshade.io.meshes import _check_input_file, read_mesh_arrays
from meshshade.io.ply import _ply_data

__all__ = ["read_uv_map", "read_corner_uv"]

_PLY_UV = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"))


def read_corner_uv(path):
    """(corner UV (m, 3, 2) float64 in the file's face order, or None when the file has no texture coordinates)."""
    path = Path(path)
    fmt = _check_input_file(path)
    try:
        if fmt == "obj":
            return _obj_uv(path)
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
    uv = read_corner_uv(path)
    if uv is None:
        return None
    _, F_file = read_mesh_arrays(path)
    if F_file.shape[0] != uv.shape[0]:
        raise MeshValidationError(f"{path}: {uv.shape[0]} faces have texture coordinates, the mesh has "
                                  f"{F_file.shape[0]}")
    return match_corners(F_file, uv, mesh.faces, path)


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


def _obj_uv(path: Path):
    text = _decode_text(path.read_bytes(), path)
    vt: list = []
    corners: list = []
    missing = 0
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
        if parts[0] == "vt":
            try:
                vt.append((float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0))
            except (IndexError, ValueError):
                raise MeshValidationError(f"{path}:{lineno}: malformed texture coordinate line "
                                          f"{line.strip()[:60]!r}") from None
        elif parts[0] == "f":
            idx = []
            for p in parts[1:]:
                fields = p.split("/")
                if len(fields) < 2 or not fields[1]:
                    idx = None
                    break
                try:
                    i = int(fields[1])
                except ValueError:
                    raise MeshValidationError(f"{path}:{lineno}: malformed face line {line.strip()[:60]!r}") \
                        from None
                idx.append(i - 1 if i > 0 else len(vt) + i)
            if idx is None:
                missing += max(len(parts) - 3, 1)
                corners.extend((-1, -1, -1) for _ in range(max(len(parts) - 3, 1)))
                continue
            corners.extend((idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1))
    if not vt:
        return None
    C = np.array(corners, dtype=np.int64).reshape(-1, 3)
    if missing:
        raise MeshValidationError(f"{path}: {missing} of {C.shape[0]} triangles have no texture coordinates "
                                  "(f v/vt): a texture needs every face mapped")
    T = np.array(vt, dtype=np.float64)
    if C.size and (C.min() < 0 or C.max() >= T.shape[0]):
        raise MeshValidationError(f"{path}: a face refers to texture coordinate {int(C.max()) + 1} of "
                                  f"{T.shape[0]}")
    return T[C]


def _ply_uv(path: Path):
    V, F, columns, _ = _ply_data(path, path.read_bytes())
    for su, sv in _PLY_UV:
        if su in columns and sv in columns:
            uv = np.stack([np.asarray(columns[su], np.float64), np.asarray(columns[sv], np.float64)], axis=1)
            return uv[F]
    return None


def _gltf_uv(path: Path, fmt: str):
    import trimesh  # lazy, as the geometry reader

    try:
        loaded = trimesh.load(str(path), file_type=fmt, process=False, maintain_order=True)
    except Exception as exc:  # noqa: BLE001 - the geometry reader reports the same file's problem first
        raise MeshValidationError(f"could not read {fmt.upper()} file {path}: {_one_line(exc)}") from exc
    scene = loaded if isinstance(loaded, trimesh.Scene) else trimesh.Scene(loaded)
    rank = {name: i for i, name in enumerate(scene.geometry)}
    nodes = sorted(scene.graph.nodes_geometry, key=lambda node: (rank[scene.graph[node][1]], str(node)))
    out, any_uv = [], False
    for node in nodes:
        transform, name = scene.graph[node]
        geom = scene.geometry[name]
        if not isinstance(geom, trimesh.Trimesh):
            continue
        F = np.asarray(geom.faces, dtype=np.int64)
        uv = getattr(geom.visual, "uv", None)
        if uv is None or len(uv) != len(geom.vertices):
            out.append(None)
            continue
        any_uv = True
        corner = np.asarray(uv, dtype=np.float64)[:, :2][F]
        if np.linalg.det(np.asarray(transform, dtype=np.float64)[:3, :3]) < 0:
            corner = corner[:, [0, 2, 1]]
        out.append(corner)
    if not any_uv:
        return None
    missing = sum(1 for u in out if u is None)
    if missing:
        raise MeshValidationError(f"{path}: {missing} of {len(out)} mesh instances have no TEXCOORD_0: a texture "
                                  "needs every face mapped")
    return np.concatenate(out)
