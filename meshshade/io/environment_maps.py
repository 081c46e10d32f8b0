"""Environment maps read from disk: an equirectangular HDR image (OpenEXR, Radiance .hdr, or anything else
OpenImageIO reads) as a float64 array, checked so that a bad file is one line naming it.

The reader only reads and checks; what the pixels mean (directions, radiance, sampling) is
:mod:`meshshade.light.environment`'s. A map must be 2:1 (width = 2 x height: 360 degrees by 180), hold one
(grey) or at least three channels (the first three are R, G, B; a fourth, alpha, is ignored), and its values
must be finite and >= 0 (radiance), not all zero.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from meshshade.errors import LightError
from meshshade.io.images import UnreadableImage, read_pixels

__all__ = ["read_environment_map"]


def _first_line(text: str, limit: int = 160) -> str:
    line = " ".join(str(text).split()) or "OpenImageIO error"
    return line if len(line) <= limit else line[: limit - 3] + "..."


def read_environment_map(path) -> np.ndarray:
    """(H, W, 3) float64 linear RGB of the equirectangular image at ``path`` (row 0 the top, the zenith).

    Raises
    ------
    LightError
        One line naming the file: missing, a folder, unreadable by OpenImageIO, not 2:1 (width = 2 x height),
        no or two channels, a value that is NaN, infinite or negative, or every value zero.
    """
    path = Path(path)
    what = f"environment map {str(path)!r}"
    if not path.exists():
        raise LightError(f"{what} does not exist")
    if path.is_dir():
        raise LightError(f"{what} is a folder, not an image")
    try:
        pixels, spec = read_pixels(path)
    except UnreadableImage as exc:
        raise LightError(f"{what} cannot be read as an image: {_first_line(str(exc))}") from None
    h, w, c = spec.height, spec.width, spec.nchannels
    if w != 2 * h:
        raise LightError(f"{what} is {w}x{h} pixels: an equirectangular map is twice as wide as it is high "
                         "(360 by 180 degrees)")
    if c == 2 or c < 1:
        raise LightError(f"{what} has {c} channels: expected 1 (grey) or 3-4 (RGB[A])")
    img = np.asarray(pixels, dtype=np.float64).reshape(h, w, c)
    rgb = np.repeat(img, 3, axis=2) if c == 1 else img[:, :, :3]
    bad = ~np.isfinite(rgb)
    if np.any(bad):
        r, col, _ = np.argwhere(bad)[0]
        raise LightError(f"{what} holds {int(bad.sum())} NaN or infinite values (first at row {r}, column {col}): "
                         "radiance must be finite")
    neg = rgb < 0.0
    if np.any(neg):
        r, col, _ = np.argwhere(neg)[0]
        raise LightError(f"{what} holds {int(neg.sum())} negative values (first {rgb[r, col].min():.6g} at row {r}, "
                         f"column {col}): radiance must be >= 0")
    if not np.any(rgb > 0.0):
        raise LightError(f"{what} is black (every value 0): it lights nothing")
    return np.ascontiguousarray(rgb)
