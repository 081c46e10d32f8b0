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
"""
from __future__ import annotations

import base64
import json
import struct

import numpy as np

from meshshade import __version__
from meshshade.errors import OutputError

__all__ = ["gltf_document", "glb_bytes", "gltf_text", "RADIANCE_ATTRIBUTE"]

RADIANCE_ATTRIBUTE = "_RADIANCE"
_FLOAT, _UINT = 5126, 5125            # componentType
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_F32_MAX = float(np.finfo(np.float32).max)


def _f32(name: str, a) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > _F32_MAX):
        raise OutputError(f"glTF {name}: values must be finite float32 numbers")
    return np.ascontiguousarray(a, dtype="<f4")


def gltf_document(vertices_mm, faces, display_linear, radiance, *, extras: dict | None = None) -> tuple[dict, bytes]:
    """(glTF JSON as a dict, its binary buffer) of a baked mesh.

    vertices_mm : (n, 3) mm; faces : (m, 3) indices; display_linear : (n, 3) in [0, 1] (tone-mapped, linear);
    radiance : (n, 3) W/mm^2; extras : JSON-ready dict recorded in ``asset.extras``.
    """
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
    col = add(C.tobytes(), _ARRAY_BUFFER, {"componentType": _FLOAT, "count": n, "type": "VEC3"})
    rad = add(R.tobytes(), _ARRAY_BUFFER, {"componentType": _FLOAT, "count": n, "type": "VEC3"})
    ind = add(idx.tobytes(), _ELEMENT_ARRAY_BUFFER, {"componentType": _UINT, "count": int(idx.size),
                                                     "type": "SCALAR"})
    data = b"".join(blobs)
    data += b"\0" * ((-len(data)) % 4)
    doc = {
        "asset": {"version": "2.0", "generator": f"meshshade {__version__}",
                  "extras": {"radiance_attribute": RADIANCE_ATTRIBUTE,
                             "radiance_units": "W/mm^2 per unit light power (linear radiant exitance)",
                             "color_0": "tone-mapped display colour, linear", **(extras or {})}},
        "extensionsUsed": ["KHR_materials_unlit"],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "meshshade_bake"}],
        "meshes": [{"name": "meshshade_bake", "primitives": [{
            "attributes": {"POSITION": pos, "COLOR_0": col, RADIANCE_ATTRIBUTE: rad},
            "indices": ind, "material": 0, "mode": 4}]}],
        "materials": [{"name": "meshshade_baked_radiance",
                       "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0,
                                                "roughnessFactor": 1.0},
                       "extensions": {"KHR_materials_unlit": {}}}],
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
