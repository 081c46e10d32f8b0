"""A baked mesh as glTF 2.0: binary GLB or JSON ``.gltf`` with its buffer embedded (pure: bytes in memory).

What the file holds (glTF 2.0 specification, Khronos 2017/2021):

* one mesh, one primitive of triangles, **vertices in the order of the baked mesh** (no merging, no re-ordering;
  indices ``UNSIGNED_INT``);
* ``POSITION`` (float32 VEC3) in **metres**, as glTF requires (the mesh's mm times 1e-3), with its min/max;
* ``COLOR_0`` (float32 VEC3): the tone-mapped display colour, stored **linear** as glTF defines vertex colours
  (viewers multiply it into the base colour and encode the result to sRGB, so it shows the colours of the PLY's
  ``red/green/blue``);
* ``_RADIANCE`` (float32 VEC3): the linear radiant exitance in W/mm^2 per unit light power (an application-specific
  attribute: the leading underscore is the specification's rule for those);
* a material with ``KHR_materials_unlit`` (white base colour), so viewers show the baked colours without shading
  them again;
* ``asset.extras``: generator, model, material and units of ``_RADIANCE``.

With a texture bake (``texture=``, :func:`textured_vertices`): vertices are split where a vertex has several UVs
(a seam): the mesh's vertices come first, in order, each with the UV of its first corner, and the other
(vertex, UV) pairs follow in the order of their first corner, the primitive's ``extras.seam_vertex_source``
listing the mesh's vertex of each of those (not a second custom vertex attribute: Blender 5.0's importer
mixes custom attributes of different widths and fails about one import in two); ``TEXCOORD_0`` holds the UVs
(v flipped: glTF's origin is the image's top left); the material is emissive with the tone-mapped texture
(PNG, embedded; an 8-bit image needs no ``KHR_materials_emissive_strength``) on a black, non-metallic base, so
any viewer shows the bake as it was computed; the linear texture (OpenEXR, which glTF cannot embed as an image) is
named in the material's ``extras.linear_texture`` with its units.
"""
from __future__ import annotations

import base64
import json
import struct

import numpy as np

from meshshade import __version__
from meshshade.errors import OutputError

__all__ = ["gltf_document", "glb_bytes", "gltf_text", "textured_vertices", "RADIANCE_ATTRIBUTE"]

RADIANCE_ATTRIBUTE = "_RADIANCE"
_FLOAT, _UINT = 5126, 5125            # componentType
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_F32_MAX = float(np.finfo(np.float32).max)


def _f32(name: str, a) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > _F32_MAX):
        raise OutputError(f"glTF {name}: values must be finite float32 numbers")
    return np.ascontiguousarray(a, dtype="<f4")


def textured_vertices(n_vertices: int, faces, uv):
    """(source vertex (n',) of each glTF vertex, faces (m, 3) into them, UV (n', 2)) for per-corner ``uv``
    (m, 3, 2): the mesh's vertices first, in order, then each further (vertex, UV) pair (module docstring)."""
    F = np.asarray(faces, dtype=np.int64)
    corner_uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    v = F.reshape(-1)
    keys = np.concatenate([v[:, None].astype(np.float64), corner_uv], axis=1)
    uniq, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(first, kind="stable")                 # pairs in the order of their first corner
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    pair_vertex = uniq[order, 0].astype(np.int64)
    is_first = np.zeros(order.size, dtype=bool)              # each vertex's first pair keeps the vertex's index
    _, first_pair = np.unique(pair_vertex, return_index=True)
    is_first[first_pair] = True
    index = np.empty(order.size, dtype=np.int64)
    index[is_first] = pair_vertex[is_first]
    index[~is_first] = n_vertices + np.arange(int((~is_first).sum()))
    source = np.concatenate([np.arange(n_vertices), pair_vertex[~is_first]])
    uv_out = np.zeros((source.size, 2))
    uv_out[index] = uniq[order, 1:]
    return source, index[rank[inverse]].reshape(F.shape), uv_out


def gltf_document(vertices_mm, faces, display_linear, radiance, *, extras: dict | None = None,
                  texture: dict | None = None) -> tuple[dict, bytes]:
    """(glTF JSON as a dict, its binary buffer) of a baked mesh.

    vertices_mm : (n, 3) mm; faces : (m, 3) indices; display_linear : (n, 3) in [0, 1] (tone-mapped, linear);
    radiance : (n, 3) W/mm^2; extras : JSON-ready dict recorded in ``asset.extras``; texture : None or
    ``{"uv": (m, 3, 2), "png": bytes, "linear_uri": str}`` (module docstring).
    """
    source, n_seam = None, 0
    if texture is not None:
        n_mesh = np.shape(vertices_mm)[0]
        source, faces, uv = textured_vertices(n_mesh, faces, texture["uv"])
        n_seam = source.size - n_mesh
        vertices_mm = np.asarray(vertices_mm, dtype=np.float64)[source]
        display_linear = np.asarray(display_linear, dtype=np.float64)[source]
        radiance = np.asarray(radiance, dtype=np.float64)[source]
    V = _f32("POSITION", np.asarray(vertices_mm, dtype=np.float64) * 1e-3)
    C = _f32("COLOR_0", np.clip(display_linear, 0.0, 1.0))
    R = _f32(RADIANCE_ATTRIBUTE, radiance)
    F = np.asarray(faces)
    n = V.shape[0]
    if F.ndim != 2 or F.shape[1] != 3 or F.size == 0 or F.min() < 0 or F.max() >= n:
        raise OutputError("glTF: faces must be (m, 3) indices of the vertices")
    idx = np.ascontiguousarray(F, dtype="<u4").ravel()
    blobs, views, accessors = [], [], []
    offset = 0

    def add(data: bytes, target: int, accessor: dict) -> int:
        nonlocal offset
        pad = (-offset) % 4
        if pad:
            blobs.append(b"\0" * pad)
            offset += pad
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data), "target": target})
        blobs.append(data)
        offset += len(data)
        accessors.append({"bufferView": len(views) - 1, **accessor})
        return len(accessors) - 1

    pos = add(V.tobytes(), _ARRAY_BUFFER, {"componentType": _FLOAT, "count": n, "type": "VEC3",
                                           "min": V.min(axis=0).tolist(), "max": V.max(axis=0).tolist()})
    col = None if texture is not None else add(C.tobytes(), _ARRAY_BUFFER, {"componentType": _FLOAT, "count": n,
                                                                             "type": "VEC3"})
    rad = add(R.tobytes(), _ARRAY_BUFFER, {"componentType": _FLOAT, "count": n, "type": "VEC3"})
    ind = add(idx.tobytes(), _ELEMENT_ARRAY_BUFFER, {"componentType": _UINT, "count": int(idx.size),
                                                     "type": "SCALAR"})
    attributes = {"POSITION": pos, "COLOR_0": col, RADIANCE_ATTRIBUTE: rad}
    material = {"name": "meshshade_baked_radiance",
                "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                                         "roughnessFactor": 1.0},
                "extensions": {"KHR_materials_unlit": {}}}
    textures, seam = {}, {}
    if texture is not None:
        seam = {"extras": {"seam_vertex_source": source[source.size - n_seam:].tolist()}}
        T = _f32("TEXCOORD_0", np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1))
        attributes = {"POSITION": pos, "TEXCOORD_0": add(T.tobytes(), _ARRAY_BUFFER, {
            "componentType": _FLOAT, "count": int(T.shape[0]), "type": "VEC2"}), RADIANCE_ATTRIBUTE: rad}
        png = bytes(texture["png"])
        blobs.append(b"\0" * ((-offset) % 4))
        offset += (-offset) % 4
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(png)})
        blobs.append(png)
        offset += len(png)
        material = {"name": "meshshade_baked_texture",
                    "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0.0,
                                             "roughnessFactor": 1.0},
                    "emissiveTexture": {"index": 0, "texCoord": 0}, "emissiveFactor": [1.0, 1.0, 1.0],
                    "extras": {"linear_texture": texture.get("linear_uri"),
                               "linear_texture_units": "W/mm^2 per unit light power (linear radiant exitance)",
                               "emissive_texture": "tone-mapped display image (sRGB PNG)"}}
        textures = {"images": [{"bufferView": len(views) - 1, "mimeType": "image/png", "name": "meshshade_bake"}],
                    "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}],
                    "textures": [{"source": 0, "sampler": 0}]}
    data = b"".join(blobs)
    data += b"\0" * ((-len(data)) % 4)
    doc = {
        "asset": {"version": "2.0", "generator": f"meshshade {__version__}",
                  "extras": {"radiance_attribute": RADIANCE_ATTRIBUTE,
                             "radiance_units": "W/mm^2 per unit light power (linear radiant exitance)",
                             "color_0": "tone-mapped display colour, linear", **(extras or {})}},
        **({} if texture is not None else {"extensionsUsed": ["KHR_materials_unlit"]}),
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "meshshade_bake"}],
        "meshes": [{"name": "meshshade_bake", "primitives": [{
            "attributes": attributes, "indices": ind, "material": 0, "mode": 4, **seam}]}],
        "materials": [material],
        **textures,
        "buffers": [{"byteLength": len(data)}],
        "bufferViews": views,
        "accessors": accessors,
    }
    return doc, data


def glb_bytes(doc: dict, data: bytes) -> bytes:
    """The binary container (GLB): header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * ((-len(js)) % 4)
    total = 12 + 8 + len(js) + 8 + len(data)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(data), b"BIN\0") + data)


def gltf_text(doc: dict, data: bytes) -> str:
    """A self-contained ``.gltf``: the JSON with the buffer embedded as a base64 data URI."""
    doc = json.loads(json.dumps(doc))
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
    return json.dumps(doc, indent=1)
