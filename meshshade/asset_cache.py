"""Derived data of assets kept between runs (automatic UV atlases, benchmark references).

``<user cache>/meshshade/<kind>/<key>.npz`` (beside numba's folder, :func:`meshshade.compiled_cache.user_cache_root`);
``MESHSHADE_ASSET_CACHE`` names another root, or turns the cache off when set to ``off``. A cache: every failure to
read is a miss and every failure to write is skipped, never an error. Files are written under a temporary name and
renamed (``os.replace``), so a reader never sees a partial entry; the :data:`KEEP` most recently used entries of
each kind are kept. The pipeline's stages do no I/O themselves: they are handed an :class:`AssetCache`.
"""
from __future__ import annotations

import contextlib
import os
import secrets
import zipfile
from pathlib import Path

import numpy as np

from meshshade.compiled_cache import user_cache_root

__all__ = ["AssetCache", "KEEP", "cache_dir"]

#: entries kept per kind (least recently used beyond it are removed)
KEEP = 16


def _off() -> bool:
    return os.environ.get("MESHSHADE_ASSET_CACHE", "").lower() == "off"


def cache_dir(kind: str) -> Path:
    """The folder of ``kind``'s entries."""
    root = os.environ.get("MESHSHADE_ASSET_CACHE")
    return (Path(root) if root else user_cache_root().parent) / kind


class AssetCache:
    """The entries of one ``kind``: ``read(key)`` -> dict of arrays or None, ``write(key, **arrays)`` -> bool."""

    def __init__(self, kind: str):
        self.kind = kind

    def read(self, key: str) -> dict | None:
        if _off():
            return None
        path = cache_dir(self.kind) / f"{key}.npz"
        try:
            with np.load(path, allow_pickle=False) as data:
                out = {k: data[k] for k in data.files}
            os.utime(path)   # recently used
            return out
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None

    def write(self, key: str, **arrays) -> bool:
        if _off():
            return False
        folder = cache_dir(self.kind)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            tmp = folder / f".{key}.{secrets.token_hex(4)}.tmp.npz"
            try:
                with open(tmp, "wb") as fh:
                    np.savez(fh, **arrays)
                os.replace(tmp, folder / f"{key}.npz")
            finally:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            entries = sorted(folder.glob("*.npz"), key=lambda p: p.stat().st_mtime, reverse=True)
            for old in entries[KEEP:]:
                with contextlib.suppress(OSError):
                    old.unlink()
            return True
        except OSError:
            return False
