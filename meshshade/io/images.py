"""Images through OpenImageIO: EXR (32-bit float, with ``meshshade:*`` attributes) and PNG written atomically, an
image and its attributes read back.

OpenImageIO is imported on first use (about 0.3 s). The EXR writer refuses values a float32 cannot hold; a failed
write names the output, not the temporary file, and says so when the disk is full.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from meshshade.errors import MeshValidationError, OutputError
from meshshade.io._messages import _one_line
from meshshade.io.transactions import _no_space_hint, atomic_write, check_output_path
from meshshade.io.writers import _check_float32

__all__ = ["write_exr", "write_png", "read_exr", "read_pixels", "UnreadableImage"]


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
    directory = path.parent if str(path.parent) else Path(".")
    with atomic_write(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        ok = out is not None and out.open(str(tmp), spec)
        if ok:
            ok = out.write_image(np.ascontiguousarray(pixels))
            err = out.geterror()
            ok = out.close() and ok
            err = err or out.geterror()
        else:
            err = oiio.geterror() or (out.geterror() if out else "")
        if not ok:  # OpenImageIO's messages name the temporary file and not the cause ("Failed OpenEXR write")
            err = " ".join(str(err).replace(str(tmp), str(path)).split()) or "OpenImageIO error"
            raise OutputError(f"could not write {path}: {_no_space_hint(directory, err)}")
    return path


def write_exr(path, rgba_float, metadata: dict | None = None) -> Path:
    """Write an (H, W, 4) or (H, W, 3) linear float image as OpenEXR (half=no: 32-bit float) atomically.

    ``metadata`` entries become string attributes ``meshshade:<key>`` (model, material, lights, camera, units).
    """
    arr = np.asarray(rgba_float, dtype=np.float32)
    if arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"image must be (H, W, 3|4), got {arr.shape}")
    check_output_path(path, suffixes=(".exr",), option="EXR output")
    _check_float32(path, "the image", rgba_float)
    return _write_image(path, arr, "float", metadata)


def write_png(path, rgba_uint8) -> Path:
    """Write an (H, W, 4|3) uint8 image (sRGB-encoded, straight alpha) as PNG atomically."""
    arr = np.asarray(rgba_uint8)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] not in (3, 4):
        raise ValueError(f"PNG image must be (H, W, 3|4) uint8, got {arr.shape} {arr.dtype}")
    check_output_path(path, suffixes=(".png",), option="PNG output")
    return _write_image(path, arr, "uint8")


class UnreadableImage(Exception):
    """An image OpenImageIO cannot open or read; the message is OpenImageIO's (each reader words its user's
    error)."""


def read_pixels(path):
    """((H, W, C) float32 pixels, OpenImageIO's spec) of the image at ``path``; :class:`UnreadableImage` where it
    cannot be opened or read."""
    oiio = _oiio()
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise UnreadableImage(oiio.geterror() or "unknown format")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        err = inp.geterror()
    finally:
        inp.close()
    if pixels is None:
        raise UnreadableImage(err or "no pixels")
    return np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels), spec


def read_exr(path) -> tuple[np.ndarray, dict]:
    """Read an image through OpenImageIO: ((H, W, C) float32 pixels, {key: value} of ``meshshade:*`` attributes)."""
    path = Path(path)
    try:
        pixels, spec = read_pixels(path)
    except UnreadableImage as exc:
        raise MeshValidationError(f"{path}: cannot read image: {exc}") from None
    meta = {a.name.split(":", 1)[1]: a.value for a in spec.extra_attribs if a.name.startswith("meshshade:")}
    return pixels, meta
