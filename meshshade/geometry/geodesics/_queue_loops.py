"""Numba machinery shared by the geodesic loops (private): bucket queue, growable arrays, result collection.

The propagations in :mod:`._window_loops` and :mod:`._graph_loops` process a *block* of sources sequentially
with reused, stamp-reset work arrays (no O(n) clearing per source), so that a block costs O(sum of neighbourhood
sizes).  Events are ordered by a bucket queue: ``nb`` circular buckets of width ``1/inv_delta`` (mm) spanning the
largest key jump, each a LIFO linked list threaded through the event arrays ``ek`` (key, mm), ``ei`` (item) and
``en`` (next event in the bucket, -1 at the end); ``bhead`` (nb,) holds each bucket's first event.  Every update is
a min over lengths of valid paths and every event re-checks its key, so processing slightly out of order changes
the work, not the result (label-correcting).
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: relative improvement below which a vertex is not re-queued (rounding noise)
_IMPROVE = 1.0 - 1e-13


@njit(cache=True, nogil=True, inline="always")
def _bq_push(bhead, ek, ei, en, nev, key, item, inv_delta, cur, nb):
    """Queue ``item`` with priority ``key`` in bucket floor(key / delta) (clamped to the live range)."""
    b = int(key * inv_delta)
    if b < cur:
        b = cur
    elif b >= cur + nb:
        b = cur + nb - 1
    slot = b % nb
    ek[nev] = key
    ei[nev] = item
    en[nev] = bhead[slot]
    bhead[slot] = nev
    return nev + 1


@njit(cache=True, nogil=True, inline="always")
def _bq_pop(bhead, ek, ei, en, cur, nb):
    """Remove an event of the lowest non-empty bucket (LIFO inside a bucket); the queue must not be empty."""
    while True:
        slot = cur % nb
        e = bhead[slot]
        if e >= 0:
            bhead[slot] = en[e]
            return ek[e], ei[e], cur
        cur += 1


@njit(cache=True, nogil=True)
def _grow_f(a, cap):
    """(cap,) copy of the 1-D array ``a`` (same dtype) with ``a`` in front; the rest uninitialised."""
    b = np.empty(cap, a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(cache=True, nogil=True, inline="always")
def _reserve_events(ek, ei, en, need):
    """Event arrays with room for ``need`` events (doubled to ``2 need`` when they are not longer than that)."""
    if need >= ek.shape[0]:
        cap = 2 * need
        ek = _grow_f(ek, cap)
        ei = _grow_f(ei, cap)
        en = _grow_f(en, cap)
    return ek, ei, en


@njit(cache=True, nogil=True)
def _append_results(out_v, out_d, nout, touched, nt, dist, cutoff):
    """Append the touched vertices within ``cutoff`` (growing the outputs); returns arrays and new length."""
    need = nout + nt
    if need > out_v.shape[0]:
        cap = max(need, 2 * out_v.shape[0])
        out_v = _grow_f(out_v, cap)
        out_d = _grow_f(out_d, cap)
    for j in range(nt):
        u = touched[j]
        if dist[u] <= cutoff:
            out_v[nout] = u
            out_d[nout] = dist[u]
            nout += 1
    return out_v, out_d, nout
