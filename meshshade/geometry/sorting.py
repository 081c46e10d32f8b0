"""Sorting and grouping of integer arrays in linear time, for the topology of large meshes (pure array functions).

A mesh of 2M vertices has 13.5M half-edges; a comparison sort of their keys (numpy's ``argsort`` or ``unique``)
takes seconds, and numpy's plain ``unique`` of int64 keys is slower still (its hash path: 21 s for 13.5M random
keys, against 1 s for a sort). Keys that are small integers (edge ids, vertex indices) sort in linear time:

* :func:`counting_order`: the stable order of keys in ``0 .. n_keys - 1`` (a counting sort);
* :func:`pair_table`: the distinct unordered pairs ``(lo, hi)`` (``lo < hi``, both below ``n``) in lexicographic
  order, each pair's multiplicity and every input pair's index among them: half-edges grouped by their lower
  vertex, each group (a few edges) sorted by the higher one;
* :func:`sorted_unique`: ``np.unique(a)`` of a 1-D array by a sort (no hash).

The results are those of the comparison sorts (same order, same ties), so callers need not change.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["counting_order", "pair_table", "sorted_unique"]


@numba.njit(cache=True, nogil=True)
def _counting_order(keys, n_keys):
    count = np.zeros(n_keys + 1, np.int64)
    for i in range(keys.size):
        count[keys[i] + 1] += 1
    for k in range(n_keys):
        count[k + 1] += count[k]
    out = np.empty(keys.size, np.int64)
    for i in range(keys.size):
        k = keys[i]
        out[count[k]] = i
        count[k] += 1
    return out


def counting_order(keys, n_keys: int) -> np.ndarray:
    """(k,) int64: the stable ascending order of ``keys`` (k,) of integers in ``0 .. n_keys - 1`` (what
    ``np.argsort(keys, kind="stable")`` returns), in O(k + n_keys)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    if keys.size == 0:
        return np.zeros(0, dtype=np.int64)
    return _counting_order(keys, int(n_keys))


@numba.njit(cache=True, nogil=True)
def _pair_table(lo, hi, n):
    order = _counting_order(lo, n)                       # pairs grouped by lo, stable
    start = np.zeros(n + 1, np.int64)
    for i in range(lo.size):
        start[lo[i] + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    # each group sorted by hi (stable insertion sort: groups hold a few pairs)
    for v in range(n):
        for t in range(start[v] + 1, start[v + 1]):
            x = order[t]
            u = t - 1
            while u >= start[v] and hi[order[u]] > hi[x]:
                order[u + 1] = order[u]
                u -= 1
            order[u + 1] = x
    inverse = np.empty(lo.size, np.int64)
    n_pairs = 0
    for t in range(order.size):
        i = order[t]
        if t == 0 or lo[i] != lo[order[t - 1]] or hi[i] != hi[order[t - 1]]:
            n_pairs += 1
        inverse[i] = n_pairs - 1
    pairs = np.empty((n_pairs, 2), np.int64)
    counts = np.zeros(n_pairs, np.int64)
    for i in range(lo.size):
        e = inverse[i]
        pairs[e, 0] = lo[i]
        pairs[e, 1] = hi[i]
        counts[e] += 1
    return pairs, inverse, counts


def pair_table(lo, hi, n: int):
    """(pairs (e, 2), inverse (k,), counts (e,)): the distinct pairs of ``lo`` (k,) and ``hi`` (k,) (integers in
    ``0 .. n - 1``) sorted by ``lo`` then ``hi``, the index of each input pair among them, and their
    multiplicities: ``np.unique(lo * n + hi, return_inverse=True, return_counts=True)`` in O(k + n)."""
    lo = np.ascontiguousarray(lo, dtype=np.int64)
    hi = np.ascontiguousarray(hi, dtype=np.int64)
    if lo.size == 0:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return _pair_table(lo, hi, int(n))


def sorted_unique(a) -> np.ndarray:
    """The sorted distinct values of the 1-D array ``a`` (``np.unique(a)``), by a sort."""
    s = np.sort(np.asarray(a).reshape(-1))
    if s.size == 0:
        return s
    keep = np.empty(s.size, dtype=bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]
