"""Reuse of derived geometry across the jobs of one process (a Dask worker running a batch).

A sweep runs many bakes on one mesh: over lights, over materials, over models. What depends only on the mesh (the
loaded mesh, its principal curvatures, the Embree scene) or on the mesh, material and model (the hierarchical
transport's near-field matrix and far-field trees, :class:`~meshshade.surface.hierarchical.SurfaceTransport`)
is the same from one job to the next. Inside :func:`reuse` (the batch runner wraps every job in it),
:func:`cached` keeps such values in a small process-wide least-recently-used store; outside it, :func:`cached`
just builds the value, so a single command or API call behaves exactly as without this module.

Keys hold plain values (paths with size and modification time, option values, ``Material.describe()``) and the
``id`` of objects such as a :class:`~meshshade.geometry.mesh.Mesh`; an entry keeps those objects alive (``pins``)
so an ``id`` cannot be reused by another object while its entry exists.
"""
from __future__ import annotations

import contextlib
import contextvars
import threading
from collections import Counter, OrderedDict

__all__ = ["MAX_ENTRIES", "cached", "reuse", "reusing", "stats", "clear"]

#: entries kept (a mesh, its curvature and scene, and a few transports of two or three meshes)
MAX_ENTRIES = 24

_ON: contextvars.ContextVar[bool] = contextvars.ContextVar("meshshade_reuse", default=False)
_STORE: OrderedDict = OrderedDict()
_STATS: Counter = Counter()
_LOCK = threading.RLock()


@contextlib.contextmanager
def reuse():
    """Turn reuse on for the block (in this thread or task's context)."""
    token = _ON.set(True)
    try:
        yield
    finally:
        _ON.reset(token)


def reusing() -> bool:
    return _ON.get()


def cached(kind: str, key: tuple, build, pins: tuple = ()):
    """``build()``, or inside :func:`reuse` the value stored for ``(kind, key)`` (built and stored on a miss).

    ``pins``: the objects whose ``id`` appears in ``key`` (kept alive with the entry). Counts hits and builds per
    ``kind`` (:func:`stats`).
    """
    if not _ON.get():
        return build()
    k = (kind, key)
    with _LOCK:
        if k in _STORE:
            _STORE.move_to_end(k)
            _STATS[f"{kind} reused"] += 1
            return _STORE[k][0]
    value = build()
    with _LOCK:
        _STORE[k] = (value, tuple(pins))
        _STATS[f"{kind} built"] += 1
        while len(_STORE) > MAX_ENTRIES:
            _STORE.popitem(last=False)
    return value


def stats() -> dict:
    """Counts so far in this process: ``{"<kind> built": n, "<kind> reused": n}``."""
    with _LOCK:
        return dict(_STATS)


def clear() -> None:
    """Drop every entry and count."""
    with _LOCK:
        _STORE.clear()
        _STATS.clear()
