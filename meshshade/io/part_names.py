"""The names a mesh file gives its faces, for materials of parts (docs/physics.md §17 "Parts"): an OBJ's ``usemtl``
and ``g`` names, a glTF's (GLB's) materials.

:func:`read_face_names` returns, per name, which of the mesh's faces carry it, in the face order the mesh readers
(:mod:`meshshade.io.meshes`) give: an OBJ's faces in file order, each polygon fan-triangulated into its
``n - 2`` triangles in place (a face before any ``usemtl`` or ``g`` carries no name of that kind); a glTF's
primitives in the order :func:`meshshade.io.meshes.read_mesh_arrays` concatenates them, each the name of its
material. Other formats (PLY, OFF, STL) name nothing.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from meshshade.errors import MeshValidationError
from meshshade.io._reading import _decode_text, _obj_statements

__all__ = ["read_face_names"]


def read_face_names(path, n_faces: int) -> dict[str, np.ndarray]:
    """name -> (n_faces,) bool: the faces of the mesh file ``path`` that carry ``name`` (an OBJ ``usemtl`` or
    ``g`` name, a glTF material name), in the names' order of first appearance; ``n_faces`` is the mesh's face
    count (a MeshValidationError if the file's faces are not as many)."""
    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt == "obj":
        labels = _obj_labels(path)
    elif fmt in ("glb", "gltf"):
        labels = _gltf_labels(path)
    else:
        return {}
    out = {}
    for kind_names, kind_index in labels:
        for i, name in enumerate(kind_names):
            if name is None:
                continue
            mask = kind_index == i
            if mask.shape[0] != n_faces:
                raise MeshValidationError(f"{path}: its names cover {mask.shape[0]} faces, the mesh has {n_faces}")
            out[name] = out[name] | mask if name in out else mask
    return out


def _obj_labels(path: Path):
    """[(usemtl names, each face's index into them), (g names, each face's)]: the names current at each ``f``
    record, repeated for its triangles (index -1: none yet)."""
    text = _decode_text(path.read_bytes(), path)
    kinds = {"usemtl": ([], {}), "g": ([], {})}
    current = {"usemtl": -1, "g": -1}
    per_face = {"usemtl": [], "g": []}
    for _, _, parts in _obj_statements(text):
        key = parts[0]
        if key in kinds:
            name = " ".join(parts[1:]) if len(parts) > 1 else None
            names, index = kinds[key]
            if name is None:
                current[key] = -1
            else:
                if name not in index:
                    index[name] = len(names)
                    names.append(name)
                current[key] = index[name]
        elif key == "f":
            k = max(0, len(parts) - 3)              # a polygon's fan: n - 2 triangles
            for kind in per_face:
                per_face[kind].append((current[kind], k))
    out = []
    for kind in ("usemtl", "g"):
        names, _ = kinds[kind]
        rows = per_face[kind]
        idx = np.repeat(np.array([r[0] for r in rows], dtype=np.int64), [r[1] for r in rows]) if rows else \
            np.zeros(0, dtype=np.int64)
        out.append((names, idx))
    return out


def _gltf_labels(path: Path):
    """[(material names, each face's index)] of a glTF or GLB, its primitives in the mesh reader's order."""
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, maintain_order=True)
    except Exception as exc:  # noqa: BLE001 - the reader has said it already; here: no names
        raise MeshValidationError(f"could not read {path}: {str(exc).splitlines()[0] if str(exc) else exc}") \
            from exc
    geoms = [loaded] if isinstance(loaded, trimesh.Trimesh) else None
    if geoms is None:
        rank = {name: i for i, name in enumerate(loaded.geometry)}
        nodes = sorted(loaded.graph.nodes_geometry, key=lambda node: (rank[loaded.graph[node][1]], str(node)))
        geoms = [loaded.geometry[loaded.graph[node][1]] for node in nodes]
        geoms = [g for g in geoms if isinstance(g, trimesh.Trimesh)]
    names, index, idx = [], {}, []
    for g in geoms:
        mat = getattr(getattr(g, "visual", None), "material", None)
        name = getattr(mat, "name", None)
        if name is None:
            idx.append(np.full(len(g.faces), -1, dtype=np.int64))
            continue
        name = str(name)
        if name not in index:
            index[name] = len(names)
            names.append(name)
        idx.append(np.full(len(g.faces), index[name], dtype=np.int64))
    return [(names, np.concatenate(idx) if idx else np.zeros(0, dtype=np.int64))]
