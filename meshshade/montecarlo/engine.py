"""Pooled Monte Carlo engine: numba walks on a regenerating photon pool, boundary hits from Embree.

A pool of ``pool`` photon slots is advanced in rounds; every step that touches photons runs on all cores:

1. refill: the free slots among the first ``max_live`` take the next photons in photon-index order; their entries
   are drawn, cast and refracted by the compiled emitter (:mod:`meshshade.montecarlo.emission`, ``prange`` over
   photons, each from its own stream), and written straight into the slots;
2. the walk (numba, threads over the live slots, in dynamic chunks sized to the number of live photons): a photon
   scatters without any ray while its sampled free path is certified by the
   :class:`~meshshade.montecarlo.interior.SafeDistanceGrid` (shorter than the conservative distance to the surface,
   or both ends inside a half-space certificate); otherwise Embree selects the first face hit within the free path
   (float32), the distance is recomputed in float64 on that face, and the photon scatters before the surface, is
   Fresnel-reflected or leaves (:func:`~meshshade.montecarlo.loops.surface_s`). At most ``MAX_STEPS`` events per
   photon and round.

   * ``fused`` (default): every thread calls Embree's ``rtcIntersect1`` itself, inside the walk
     (:mod:`meshshade.montecarlo.fused_walk` through :mod:`meshshade.raycast.embree_direct`), so the boundary
     tests run on all cores;
   * ``batched``: the interior loop stops every photon at its first uncertified free path, ONE embreex call
     traces all of them (embreex holds the GIL: one core), a second loop resolves them.
3. ``reduce_round`` adds the round's absorbed/lost/exit weights to the per-batch tallies, in parallel over
   batches (slot order within a batch).

Every random number of photon ``i`` (its entry and its walk) comes from its own counter-based stream keyed by
(seed, group, i) (:mod:`meshshade.montecarlo.loops`), and every sum runs in a fixed order: the result is bitwise
identical for any number of numba threads, and photon ``i``'s path is the same for any pool size and either Embree
mode (the tallies then differ only by the floating-point summation order).

Time budget (:class:`BudgetClock`): emission stops once ``elapsed + predicted drain >= budget``. The drain of the
photons in flight is predicted from the throughput measured *after the first round* (which carries the one-off
costs: numba compiling or loading its cache, the thread pool starting, first touches of memory), and only once at
least ``BUDGET_MIN_DONE`` photons have finished in that window; before that, emission goes on (a warm-up can no
longer make the walk stop after a handful of photons). With a budget the number of live photons starts at
``BUDGET_START_LIVE`` and doubles only while its predicted drain stays below ``BUDGET_DRAIN_FRACTION`` of the
budget and the last round took less than half of ``ROUND_FRACTION`` of it. Hard bound: at
``budget * (1 + HARD_OVERSHOOT)`` the photons still in flight are cut off and their weight is booked as ``lost``
(the energy balance stays exact and the truncation is visible in the result). Every run reports the photons it
emitted, and its tallies are normalised by that count (:func:`meshshade.montecarlo.simulation.simulate`).
"""
from __future__ import annotations

import time

import numba
import numpy as np

from meshshade.light import BeamLight
from meshshade.montecarlo import loops as K
from meshshade.montecarlo.fused_walk import walk_parallel
from meshshade.montecarlo.emission import EmitterKernel, emission_base
from meshshade.montecarlo.sampling import ROULETTE_BOOST as K_BOOST, ROULETTE_THRESHOLD as K_THRESH, GroupMedium
from meshshade.raycast.embree_direct import TFAR_MARGIN_REL
from meshshade.raycast.scene import OFFSET_ABS, OFFSET_REL

#: photons per entry chunk: the unit in which a run is split across Dask workers (``chunks=``)
ENTRY_CHUNK = 1 << 14
MAX_STEPS = 64
MAX_STEPS_GROWTH = 1024
BUDGET_START_LIVE = 4096
BUDGET_DRAIN_FRACTION = 0.2
DRAIN_SAFETY = 1.5
ROUND_FRACTION = 0.05
HARD_OVERSHOOT = 0.25
DEFAULT_POOL = 1 << 18
SAFE_STEPS_PER_VOXEL = 4
#: most photons per dynamically scheduled chunk of the parallel walk
CHUNK = 1024
#: chunks per thread at least, while the pool drains (smaller chunks, so no thread is left with the tail)
CHUNKS_PER_THREAD = 8
#: photons that must finish after the first round before the budget trusts the measured throughput
BUDGET_MIN_DONE = 512
#: refills per round (the slots of shadowed entries are refilled at once)
REFILL_PASSES = 4


def first_hit_faces32(scene, o32, d32, tfar):
    """(k,) int32 face of the first hit within ``tfar`` (-1: none) of float32 rays relative to ``scene.center``.

    One batched embreex call (``EmbreeScene.first_hit_faces_local``: no float64 round trip; ``tfar`` is
    overwritten); the numpy backend goes through ``first_hit``.
    """
    if hasattr(scene, "first_hit_faces_local"):
        return scene.first_hit_faces_local(o32, d32, tfar)
    hits = scene.first_hit(o32.astype(np.float64) + scene.center, d32.astype(np.float64))
    return np.where(hits.t <= tfar, hits.face, -1).astype(np.int32)


class PoolWalk:
    """One channel group's walk on a regenerating pool of photon slots (same tallies as WavefrontWalk).

    V : (n, 3) float64 mm; F : (m, 3) int64; normals : (m, 3) unit outward face normals; emitter :
    :class:`~meshshade.montecarlo.emitter.Emitter`; scene : EmbreeScene or NumpyScene; grid :
    :class:`~meshshade.montecarlo.interior.SafeDistanceGrid`; medium :
    :class:`~meshshade.montecarlo.sampling.GroupMedium`; direct :
    :class:`~meshshade.raycast.embree_direct.DirectEmbreeScene` or None (batched mode). After :meth:`run`:
    ``face`` (B, m) and ``face_vert`` (B, n) exit power W per batch, ``tot`` (B, 7) W, ``events``, ``boundary``,
    ``rays`` counts, ``exits`` of the beam's photons.
    """

    def __init__(self, V, F, normals, emitter, scene, grid, medium: GroupMedium, *, n_batches, keep_beam, seed, group,
                 direct=None):
        self.V, self.F, self.N, self.em, self.scene, self.grid = V, F, normals, emitter, scene, grid
        self.sigma_t, self.albedo = medium.sigma_t, medium.albedo
        self.g, self.eta, self.B, self.keep_beam = medium.g, medium.eta, n_batches, keep_beam
        self.seed, self.group = int(seed), int(group)
        self.face = np.zeros((n_batches, F.shape[0]))
        self.face_vert = np.zeros((n_batches, V.shape[0]))
        self.tot = np.zeros((n_batches, 7))  # specular, diffuse, transmitted, absorbed, lost, incident, entering
        self.events = 0
        self.boundary = 0
        self.rays = 0
        self.beam_light = next((i for i, lt in enumerate(emitter.lights) if isinstance(lt, BeamLight)), None)
        self.exits = {"face": [], "bary": [], "weight": [], "batch": []}
        self._v0, self._e1, self._e2, self._N = K.face_records(V, F, normals)
        self._F = np.ascontiguousarray(F, dtype=np.int64)
        self._facing = np.ascontiguousarray(emitter.facing)
        self._base = np.uint64(K.stream_base(np.uint64(self.seed & 0xFFFFFFFFFFFFFFFF), self.group))
        self._ebase = emission_base(self.seed, self.group)
        self.emitter = EmitterKernel(emitter, direct)
        self.emitted = 0
        self._center = np.ascontiguousarray(scene.center, dtype=np.float64)
        self._margin = TFAR_MARGIN_REL * scene.scale
        self.direct = direct
        # the bound as uint8 in units of h/4, rounded down (conservative): 1/8 of the float64 grid's cache footprint
        unit = grid.h / SAFE_STEPS_PER_VOXEL
        self._safe = np.minimum(np.floor(grid.safe / unit), 255).astype(np.uint8)
        self._geo = np.array([*grid.origin, 1.0 / grid.h, unit, grid.h, grid.plane_radius ** 2])


    def run(self, n_photons, *, pool=None, time_budget=None, progress=None, chunks=None):
        """Walk ``n_photons`` photons (fewer if ``time_budget`` seconds run out); returns the number emitted.

        ``chunks=(c0, c1)``: walk only the photons of entry chunks c0 <= c < c1 (photons ``c0 * ENTRY_CHUNK`` up to
        ``min(c1 * ENTRY_CHUNK, n_photons)``) of the run of ``n_photons``: the same paths and weights as in the
        whole run, so the tallies of a partition of the chunks add up to the whole run's (a run split across
        workers, :mod:`meshshade.montecarlo.distributed`).
        """
        c0, n_chunks = (0, -(-n_photons // ENTRY_CHUNK)) if chunks is None else (int(chunks[0]), int(chunks[1]))
        first = c0 * ENTRY_CHUNK
        last = max(first, min(n_chunks * ENTRY_CHUNK, n_photons))
        P = int(max(1, min(pool or DEFAULT_POOL, last - first)))
        st = _PoolState(P)
        clock = BudgetClock(time_budget)
        next_pid = first
        max_live = P if time_budget is None else min(P, BUDGET_START_LIVE)
        live = entered = 0   # photons in flight; photons that entered with power (shadowed ones finish at once)
        while True:
            if clock.cut_off():
                K.cut_off(st.status, st.w, st.batch, self.tot)
                break
            if not clock.stopped:
                clock.decide(next_pid - first, live, max_live)
                if clock.may_grow(max_live, P):
                    max_live = min(P, 2 * max_live)
            # a few passes: slots of shadowed entries (no power) stay free and are refilled at once
            for _ in range(REFILL_PASSES):
                if clock.stopped or next_pid >= last or live >= max_live:
                    break
                free = np.flatnonzero(st.status[:max_live] == K.FREE)[:max(0, min(max_live - live, last - next_pid))]
                if free.size == 0:
                    break
                k = self.emitter.emit_into(st, free, next_pid, self._ebase, self._base, n_photons, self.B, self.tot,
                                           OFFSET_REL, OFFSET_ABS)
                live += k
                entered += k
                next_pid += free.size
                if progress is not None:
                    progress.update(int(free.size))
            if next_pid >= last:
                clock.stopped = True
            if live == 0:
                if clock.stopped:
                    break
                continue
            # while photons die out, more steps per round keep the work per round (and thread launches) bounded
            steps = MAX_STEPS * min(max_live // live, MAX_STEPS_GROWTH)
            t_round = time.perf_counter()
            self._round(st.view(max_live), steps)
            live = int(np.count_nonzero(st.status[:max_live]))
            clock.end_round(time.perf_counter() - t_round, entered - live)
        self.emitted = next_pid - first
        return self.emitted

    def _round(self, st, steps):
        grid = self.grid
        common = (self._v0, self._e1, self._e2, self._N, self._center, self.scene.scale, OFFSET_REL, OFFSET_ABS)
        if self.direct is not None:
            idx = np.flatnonzero(st.status)
            # dynamic chunks of live photons, small enough that every thread gets several while the pool drains
            chunk = int(min(CHUNK, max(1, idx.size // (CHUNKS_PER_THREAD * numba.get_num_threads()))))
            with numba.parallel_chunksize(chunk):
                ev, bd, nr = walk_parallel(
                    idx, st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key, st.ctr, st.absorbed, st.lost,
                    st.exit_face, st.exit_bary, st.exit_w, self._safe, self._geo, grid.planes, grid.plane_index,
                    *common, self._margin, self.sigma_t, self.albedo, self.g, self.eta, K_THRESH, K_BOOST, steps,
                    self.direct.intersect, self.direct.handle)
        else:
            ev = K.advance_parallel(st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key, st.ctr, st.absorbed,
                                    st.need, self._safe, self._geo, grid.planes, grid.plane_index,
                                    self.sigma_t, self.albedo, self.g, K_THRESH, K_BOOST, steps)
            idx, o32, d32, tfar = K.gather_rays(st.need, st.pos, st.d, st.pend, self._center, self._margin)
            nr = bd = 0
            if idx.shape[0]:
                prim = first_hit_faces32(self.scene, o32, d32, tfar)
                ev2, bd = K.resolve_parallel(idx, prim, st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key,
                                             st.ctr, st.absorbed, st.lost, st.exit_face, st.exit_bary, st.exit_w,
                                             *common, self.eta, self.albedo, self.g, K_THRESH, K_BOOST)
                ev += ev2
                nr = idx.shape[0]
        self.events += int(ev)
        self.boundary += int(bd)
        self.rays += int(nr)
        if self.beam_light is not None and self.keep_beam:   # the first beam's exits, in slot order
            sel = np.flatnonzero((st.exit_face >= 0) & (st.light == self.beam_light))
            if sel.size:
                for k, arr in (("face", st.exit_face), ("bary", st.exit_bary), ("weight", st.exit_w),
                               ("batch", st.batch)):
                    self.exits[k].append(arr[sel].copy())
        K.reduce_round(st.batch, st.light, st.absorbed, st.lost, st.exit_face, st.exit_bary, st.exit_w, self._F,
                       self._facing, self.tot, self.face, self.face_vert)


class BudgetClock:
    """When a time-budget walk stops emitting, and when it cuts off (module docstring); no budget: never.

    ``decide(emitted, live, max_live)`` before each refill, ``end_round(seconds, done)`` after each round (done:
    walked photons finished so far, shadowed entries not counted: they cost no walk); ``stopped`` once emission has
    ended, ``cut_off()`` true past the hard bound.
    """

    def __init__(self, budget):
        self.budget = budget
        self.t0 = time.perf_counter()
        self.stopped = False
        self.rounds = 0
        self.last_round = 0.0
        self._ref = None          # (time, done) at the end of the first round
        self._rate = None         # photons finished per second since then (None: not measured yet)

    def elapsed(self):
        return time.perf_counter() - self.t0

    def cut_off(self):
        """Past the hard bound, once the first round is done (so that a walk started late, or whose first round
        carried a compile, still returns photons rather than none)."""
        return self.budget is not None and self.rounds > 0 and self.elapsed() >= self.budget * (1.0 + HARD_OVERSHOOT)

    def end_round(self, seconds, done):
        self.rounds += 1
        self.last_round = seconds
        now = self.elapsed()
        if self._ref is None:
            self._ref = (now, done)
        elif done - self._ref[1] >= BUDGET_MIN_DONE and now > self._ref[0]:
            self._rate = (done - self._ref[1]) / (now - self._ref[0])

    def drain(self, live):
        """Predicted seconds to finish ``live`` photons (inf while the rate is unmeasured)."""
        return DRAIN_SAFETY * live / self._rate if self._rate else np.inf

    def decide(self, emitted, live, max_live):
        if self.budget is None or self.stopped:
            return
        if emitted and self._rate is not None and self.elapsed() + self.drain(live) >= self.budget:
            self.stopped = True

    def may_grow(self, max_live, pool):
        return (self.budget is not None and not self.stopped and max_live < pool and self._rate is not None
                and self.last_round < 0.5 * ROUND_FRACTION * self.budget
                and self.drain(2 * max_live) < BUDGET_DRAIN_FRACTION * self.budget)


class _PoolState:
    """Arrays of the photon slots."""

    def view(self, n):
        """The first ``n`` slots (numpy views)."""
        out = _PoolState.__new__(_PoolState)
        out.__dict__.update({k: v[:n] for k, v in self.__dict__.items()})
        return out

    def __init__(self, P):
        self.status = np.zeros(P, dtype=np.int8)
        self.pos, self.d = np.zeros((P, 3)), np.zeros((P, 3))
        self.w, self.w0, self.pend = np.zeros(P), np.zeros(P), np.full(P, -1.0)
        self.key, self.ctr = np.zeros(P, dtype=np.uint64), np.zeros(P, dtype=np.uint64)
        self.batch, self.light, self.pid = (np.zeros(P, dtype=np.int64) for _ in range(3))
        self.absorbed, self.lost, self.need = np.zeros(P), np.zeros(P), np.zeros(P, dtype=np.bool_)
        self.exit_face, self.exit_bary, self.exit_w = np.full(P, -1, dtype=np.int64), np.zeros((P, 3)), np.zeros(P)
