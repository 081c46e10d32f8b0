"""One Monte Carlo run split across the workers of a Dask client (``simulate(..., client=client)``).

The photons of every channel group are cut into tasks of whole entry chunks (:data:`ENTRY_CHUNK` photons each):
at most :data:`TASKS_PER_GROUP` tasks per group, so the split depends only on the photon count, never on the
number of workers. Each task walks its chunks with :func:`meshshade.montecarlo.walks.walk_group`: photon ``i``
gets the random streams and the entry of the whole run, so the task tallies exactly what the whole run would
tally for those photons. The tallies are added on the workers by a binary tree of fixed shape (task 0 + task 1,
task 2 + task 3, ..., then the sums pairwise), so the result is bitwise the same for 1, 2 or 100 workers; against
the same run in one process only the order of the sums differs (~1e-15 relative).

What travels: the mesh and its walk surface (:mod:`meshshade.montecarlo.boundary`) once per worker
(``client.scatter(..., broadcast=True)``); per task, the material, lights
and a chunk range (bytes), and back the per-batch tallies ``B x (faces + vertices + 7)`` floats, added on the
workers, so only one tally per channel group reaches the client. Each worker process builds the walk's set-up
(Embree scene, safe-distance grid, emitter) once per mesh, lights and material (:func:`_setup`, a small per-process
cache keyed by a content hash) and reuses it for every later task.
"""
from __future__ import annotations

import hashlib
import threading
import warnings
from collections import OrderedDict
from typing import NamedTuple

import numpy as np

from meshshade.batch.dask_cluster import task_threads
from meshshade.geometry.mesh import MeshDefectWarning
from meshshade.montecarlo.engine import ENTRY_CHUNK
from meshshade.montecarlo.walks import GroupTally, channel_groups, prepare_walks, walk_group

__all__ = ["TASKS_PER_GROUP", "split_chunks", "walk_on_client"]

#: most tasks per channel group (each at least one entry chunk of ENTRY_CHUNK photons)
TASKS_PER_GROUP = 64
#: walk set-ups kept per worker process
SETUPS_KEPT = 2

_SETUPS: OrderedDict = OrderedDict()
_LOCK = threading.Lock()


def split_chunks(n_photons: int) -> list[tuple[int, int]]:
    """The entry-chunk ranges ``(c0, c1)`` of the tasks of one channel group of ``n_photons`` photons."""
    n_chunks = -(-int(n_photons) // ENTRY_CHUNK)
    per = -(-n_chunks // TASKS_PER_GROUP)
    return [(c, min(c + per, n_chunks)) for c in range(0, n_chunks, per)]


def _photons_in(chunks, n_photons: int) -> int:
    return min(chunks[1] * ENTRY_CHUNK, n_photons) - chunks[0] * ENTRY_CHUNK


def setup_key(mesh, material, lights, engine, surface=None) -> str:
    """Content hash of what a walk's set-up depends on (mesh arrays, the walk surface's, material, lights,
    engine)."""
    h = hashlib.sha256()
    extra = () if surface is None else (surface.vertices, surface.faces, surface.face_of)
    for a in (mesh.vertices, mesh.faces, *extra):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    h.update(repr((material.sigma_s_prime.tolist(), material.sigma_a.tolist(), float(material.eta),
                   float(material.g), repr(lights), engine)).encode())
    return h.hexdigest()


def _setup(key, mesh, material, lights, engine, surface=None):
    with _LOCK:
        if key in _SETUPS:
            _SETUPS.move_to_end(key)
            return _SETUPS[key]
    with warnings.catch_warnings():   # the client has said it (one line per run, not one per worker)
        warnings.simplefilter("ignore", MeshDefectWarning)
        setup = prepare_walks(mesh, material, lights, engine=engine, surface=surface)
    with _LOCK:
        _SETUPS[key] = setup
        while len(_SETUPS) > SETUPS_KEPT:
            _SETUPS.popitem(last=False)
    return setup


class _Run(NamedTuple):
    """What every task of one run shares (beside the mesh, the material and the lights)."""

    n_photons: int
    seed: int
    n_batches: int
    pool: object
    keep_beam: bool


def _walk_task(mesh, key, material, lights, engine, gi, run: _Run, chunks, surface=None):
    """One task: channel group ``gi``, entry chunks ``chunks`` (runs on a worker)."""
    task_threads()
    setup = _setup(key, mesh, material, lights, engine, surface)
    return walk_group(setup, gi, run.n_photons, seed=run.seed, n_batches=run.n_batches, pool=run.pool,
                      keep_beam=run.keep_beam, chunks=chunks)


def _add(a: GroupTally, b: GroupTally) -> GroupTally:
    return a + b


def walk_on_client(client, mesh, material, lights, n_photons: int, *, seed: int, n_batches: int, pool,
                   keep_beam: bool, engine: str = "auto", progress=None, surface=None) -> list[GroupTally]:
    """The :class:`GroupTally` of every channel group of a run of ``n_photons`` photons per group, walked on the
    client's workers (module docstring). ``progress``: a :class:`meshshade.progress.Progress` advanced by the
    photons of each finished task; ``surface``: the walk surface (default: each worker computes the mesh's)."""
    from distributed import as_completed

    key = setup_key(mesh, material, lights, engine, surface)
    [mesh_future, surface_future] = client.scatter([mesh, surface], broadcast=True, hash=False)
    ranges = split_chunks(n_photons)
    run = _Run(n_photons, seed, n_batches, pool, keep_beam)
    leaves, roots = {}, []
    try:
        for gi in range(len(channel_groups(material))):
            level = []
            for i, chunks in enumerate(ranges):
                f = client.submit(_walk_task, mesh_future, key, material, lights, engine, gi, run, chunks,
                                  surface_future,
                                  key=f"meshshade-mc-{key[:16]}-{seed}-{gi}-{i}", pure=False)
                leaves[f] = _photons_in(chunks, n_photons)
                level.append(f)
            while len(level) > 1:   # a tree of fixed shape: the same sums in the same order for any workers
                level = [client.submit(_add, level[j], level[j + 1], pure=False) if j + 1 < len(level)
                         else level[j] for j in range(0, len(level), 2)]
            roots.append(level[0])
        for f in as_completed(list(leaves)):
            f.result()   # a task's error (or a worker lost too often) is raised here
            if progress is not None:
                progress.update(leaves[f])
        return client.gather(roots)
    except BaseException:
        client.cancel(list(leaves) + roots)
        raise
