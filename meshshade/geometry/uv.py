"""Texture coordinates: per-corner UV maps, their checks, an automatic atlas, and rasterisation into texels.

A UV map here is ``uv`` (m, 3, 2) float64: the (u, v) of each face's three corners (so seams, where one vertex has
several UVs, need no split vertices). The texture's row 0 is its top (v = 1), as image files store it; texel
(row, col) has its centre at u = (col + 1/2) / width, v = 1 - (row + 1/2) / height.

* :func:`check_uv`: finite, within the unit square (tiles such as UDIMs are refused: one texture, one tile),
  counts of faces whose UV triangle has no area (they get no texel) and of mirrored ones (negative UV area: used
  as they are).
* :func:`automatic_atlas`: charts and packing by xatlas (MIT) for a mesh without UVs, packed for the texture's size
  with a gutter between charts.
* :func:`rasterise_uv`: each covered texel as (face, barycentrics): a texel belongs to the face whose UV triangle
  holds its centre; on an edge shared by two faces, to exactly one of them (a fill rule on the edge's
  direction); where UV islands overlap, **the first face in the file's order wins** and the texels claimed twice
  are counted.
* :func:`dilate`: padding, so that filtering and mipmaps read the border texels' values instead of the background.

Pure arrays (the rasteriser compiled); no I/O.
"""
from __future__ import annotations

import numba
import numpy as np

from meshshade.errors import MeshValidationError

__all__ = ["UV_TOLERANCE", "check_uv", "automatic_atlas", "rasterise_uv", "dilate", "texel_uv"]

#: UVs this far outside [0, 1] are taken as on its border (exporters write -1e-7 or 1.0000001)
UV_TOLERANCE = 1e-6


def check_uv(uv, n_faces: int, what: str = "UV map") -> dict:
    """Validate per-corner UVs (m, 3, 2) for ``n_faces`` faces; returns counts ``{"uv_degenerate_faces",
    "uv_mirrored_faces"}``. One-line :class:`MeshValidationError` when they cannot be used."""
    uv = np.asarray(uv)
    if uv.shape != (n_faces, 3, 2):
        raise MeshValidationError(f"{what}: expected ({n_faces}, 3, 2) corner UVs, got shape {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise MeshValidationError(f"{what}: {int((~np.isfinite(uv)).any(axis=(1, 2)).sum())} faces have non-finite "
                                  "texture coordinates")
    out = (uv < -UV_TOLERANCE) | (uv > 1.0 + UV_TOLERANCE)
    if out.any():
        bad = int(out.any(axis=(1, 2)).sum())
        raise MeshValidationError(f"{what}: {bad} of {n_faces} faces have texture coordinates outside [0, 1] "
                                  f"(u {uv[..., 0].min():.4g}..{uv[..., 0].max():.4g}, v {uv[..., 1].min():.4g}.."
                                  f"{uv[..., 1].max():.4g}); tiled or UDIM maps are not supported: one texture "
                                  "covers the unit square")
    area = _uv_area(uv)
    return {"uv_degenerate_faces": int(np.sum(area == 0.0)), "uv_mirrored_faces": int(np.sum(area < 0.0))}


def _uv_area(uv) -> np.ndarray:
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


def automatic_atlas(vertices, faces, *, size: int = 1024, padding: int = 4) -> tuple[np.ndarray, dict]:
    """(uv (m, 3, 2), stats) of an automatic atlas by xatlas for a ``size`` x ``size`` texture, charts ``padding``
    texels apart. Faces keep their order (xatlas keeps it; checked)."""
    import xatlas

    atlas = xatlas.Atlas()
    atlas.add_mesh(np.ascontiguousarray(vertices, dtype=np.float32), np.ascontiguousarray(faces, dtype=np.uint32))
    pack = xatlas.PackOptions()
    pack.resolution = int(size)
    pack.padding = int(padding)
    pack.bilinear = True
    atlas.generate(pack_options=pack)
    vmapping, indices, uvs = atlas[0]
    if indices.shape != np.shape(faces) or not np.array_equal(vmapping[indices], np.asarray(faces)):
        raise MeshValidationError("the automatic UV atlas changed the faces; the mesh cannot be given UVs")
    uv = np.clip(np.asarray(uvs, dtype=np.float64)[indices], 0.0, 1.0)
    return uv, {"uv_source": "xatlas", "uv_charts": int(atlas.chart_count),
                "uv_utilisation": round(float(atlas.utilization), 4)}


def texel_uv(row, col, width: int, height: int) -> np.ndarray:
    """(k, 2) UV of the centres of texels (row, col)."""
    return np.stack([(np.asarray(col) + 0.5) / width, 1.0 - (np.asarray(row) + 0.5) / height], axis=1)


def rasterise_uv(uv, width: int, height: int):
    """The covered texels of a UV map (module docstring).

    Returns (texel (k,) int64 flat index row * width + col in increasing order, face (k,) int64, bary (k, 3)
    barycentrics of the texel centre in that face, stats {"texels_covered", "uv_overlap_texels"})."""
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    owner, overlaps = _rasterise(uv, int(width), int(height))
    texel = np.flatnonzero(owner >= 0)
    face = owner[texel]
    p = texel_uv(texel // width, texel % width, width, height)
    a, b, c = uv[face, 0], uv[face, 1], uv[face, 2]
    d1, d2, dp = b - a, c - a, p - a
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    l1 = (dp[:, 0] * d2[:, 1] - dp[:, 1] * d2[:, 0]) / det
    l2 = (d1[:, 0] * dp[:, 1] - d1[:, 1] * dp[:, 0]) / det
    bary = np.clip(np.stack([1.0 - l1 - l2, l1, l2], axis=1), 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    return texel, face, bary, {"texels_covered": int(texel.size), "uv_overlap_texels": int(overlaps)}


@numba.njit(cache=True)
def _tie(dx, dy):
    """Whether a texel centre exactly on an edge of direction (dx, dy) (counter-clockwise triangle) is inside: one
    of the two triangles sharing the edge (which run along it in opposite directions) takes it."""
    return dy > 0.0 or (dy == 0.0 and dx < 0.0)


@numba.njit(cache=True)
def _rasterise(uv, width, height):
    owner = -np.ones(width * height, dtype=np.int64)
    overlaps = 0
    for f in range(uv.shape[0]):
        ax, ay = uv[f, 0, 0] * width, (1.0 - uv[f, 0, 1]) * height      # texel units, y down (row direction)
        bx, by = uv[f, 1, 0] * width, (1.0 - uv[f, 1, 1]) * height
        cx, cy = uv[f, 2, 0] * width, (1.0 - uv[f, 2, 1]) * height
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0.0:
            continue
        if area < 0.0:                       # make it counter-clockwise in these (x, y) units
            bx, by, cx, cy = cx, cy, bx, by
        c0 = max(int(np.floor(min(ax, bx, cx) - 0.5)), 0)
        c1 = min(int(np.ceil(max(ax, bx, cx) - 0.5)), width - 1)
        r0 = max(int(np.floor(min(ay, by, cy) - 0.5)), 0)
        r1 = min(int(np.ceil(max(ay, by, cy) - 0.5)), height - 1)
        for r in range(r0, r1 + 1):
            py = r + 0.5
            for c in range(c0, c1 + 1):
                px = c + 0.5
                w0 = (cx - bx) * (py - by) - (cy - by) * (px - bx)
                w1 = (ax - cx) * (py - cy) - (ay - cy) * (px - cx)
                w2 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                if (w0 == 0.0 and not _tie(cx - bx, cy - by)) or (w1 == 0.0 and not _tie(ax - cx, ay - cy)) \
                        or (w2 == 0.0 and not _tie(bx - ax, by - ay)):
                    continue
                k = r * width + c
                if owner[k] < 0:
                    owner[k] = f
                elif owner[k] != f:
                    overlaps += 1
    return owner, overlaps


def dilate(image, covered, padding: int):
    """``image`` (H, W, C) with the texels outside ``covered`` (H, W) bool filled up to ``padding`` texels away
    (chessboard distance: square rings, as an 8-neighbour dilation grows) by the value of the nearest covered texel
    (the padding of texture bakers: an island's border extended outwards); returns (image, filled mask)."""
    from scipy.ndimage import distance_transform_cdt

    img = np.array(image, dtype=np.float64, copy=True)
    mask = np.asarray(covered, dtype=bool)
    if int(padding) <= 0 or not mask.any() or mask.all():
        return img, mask.copy()
    dist, (rows, cols) = distance_transform_cdt(~mask, metric="chessboard", return_indices=True)
    grow = (~mask) & (dist <= int(padding))
    img[grow] = img[rows[grow], cols[grow]]
    return img, mask | grow
