"""Pooled Monte Carlo engine: numba walks on a regenerating photon pool, boundary hits from Embree.

A pool of ``pool`` photon slots is advanced in rounds:

1. ``refill`` (serial): free slots take the next photons of the emitter's pre-sampled entry list, in photon-index
   order (entries are drawn in fixed chunks of ``ENTRY_CHUNK`` photons, chunk ``c`` from
   ``numpy.random.default_rng([seed, group, c])``, so photon ``i``'s entry does not depend on the pool);
2. the walk (numba, threads over photons): a photon scatters without any ray while its sampled free path is
   certified by the :class:`~meshshade.montecarlo.interior.SafeDistanceGrid` (shorter than the conservative
   distance to the surface, or both ends inside a half-space certificate); otherwise Embree selects the first
   face hit within the free path (float32), the distance is recomputed in float64 on that face, and the photon
   scatters before the surface, is Fresnel-reflected or leaves (:func:`~meshshade.montecarlo.kernels.surface_s`).
   At most ``MAX_STEPS`` events per photon and round.

   * ``direct`` (default): every thread calls Embree's ``rtcIntersect1`` itself
     (:mod:`meshshade.montecarlo.direct_walk` through :mod:`meshshade.raycast.embree_direct`), so the boundary
     tests run on all cores;
   * ``batched``: the interior kernel stops every photon at its first uncertified free path, ONE embreex call
     traces all of them (embreex holds the GIL: one core), a second kernel resolves them.
3. ``reduce_round`` (serial, slot order) adds the round's absorbed/lost/exit weights to the per-batch tallies.

Every random number of photon ``i`` comes from its own counter-based stream keyed by (seed, group, i)
(:mod:`meshshade.montecarlo.kernels`): the result is bitwise identical for any number of numba threads, and
photon ``i``'s path is the same for any pool size and either Embree mode (the tallies then differ only by the
floating-point summation order).

Time budget: emission stops once ``elapsed + predicted drain >= budget``, where the drain of the photons in flight
is predicted from the measured seconds per completed photon (x ``DRAIN_SAFETY``); with a budget the number of
live photons starts at ``BUDGET_START_LIVE`` and doubles only while its predicted drain stays below
``BUDGET_DRAIN_FRACTION`` of the budget and the last round took less than half of ``ROUND_FRACTION`` of it (a
round costs at most ``MAX_STEPS`` events per live photon, so rounds stay near ``ROUND_FRACTION * budget``).
Hard bound: at ``budget * (1 + HARD_OVERSHOOT)`` the photons still in flight are cut off and their weight is
booked as ``lost`` (the energy balance stays exact and the truncation is visible in the result). The overshoot is
therefore at most ``HARD_OVERSHOOT * budget`` plus one round (~``ROUND_FRACTION * budget``) plus the result
assembly; normally the drain prediction ends the walk before the budget and nothing is lost.
"""
from __future__ import annotations

import time

import numba
import numpy as np

from meshshade.light import BeamLight
from meshshade.montecarlo import kernels as K
from meshshade.montecarlo.direct_walk import walk_parallel
from meshshade.montecarlo.sampling import ROULETTE_BOOST as K_BOOST, ROULETTE_THRESHOLD as K_THRESH
from meshshade.raycast.embree_direct import TFAR_MARGIN_REL
from meshshade.raycast.scene import OFFSET_ABS, OFFSET_REL

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
#: photons per dynamically scheduled chunk of the parallel walk
CHUNK = 1024


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
    :class:`~meshshade.montecarlo.interior.SafeDistanceGrid`; sigma_s, sigma_a : 1/mm; direct :
    :class:`~meshshade.raycast.embree_direct.DirectEmbreeScene` or None (batched mode). After :meth:`run`:
    ``face`` (B, m) and ``face_vert`` (B, n) exit power W per batch, ``tot`` (B, 7) W, ``events``, ``boundary``,
    ``rays`` counts, ``exits`` of the beam's photons.
    """

    def __init__(self, V, F, normals, emitter, scene, grid, *, sigma_s, sigma_a, g, eta, n_batches, keep_beam,
                 seed, group, direct=None):
        self.V, self.F, self.N, self.em, self.scene, self.grid = V, F, normals, emitter, scene, grid
        self.sigma_t = sigma_s + sigma_a
        self.albedo = sigma_s / self.sigma_t if self.sigma_t > 0 else 0.0
        self.g, self.eta, self.B, self.keep_beam = g, eta, n_batches, keep_beam
        self.seed, self.group = int(seed), int(group)
        self.face = np.zeros((n_batches, F.shape[0]))
        self.face_vert = np.zeros((n_batches, V.shape[0]))
        self.tot = np.zeros((n_batches, 7))  # specular, diffuse, transmitted, absorbed, lost, incident, entering
        self.events = 0
        self.boundary = 0
        self.rays = 0
        self.beam_light = next((i for i, lt in enumerate(emitter.lights) if isinstance(lt, BeamLight)), None)
        self.exits = {"face": [], "bary": [], "weight": [], "batch": []}
        tri = V[F]
        # one 96-byte record per face (v0, e1, e2, normal): a boundary test touches 1-2 cache lines, not 4
        packed = np.ascontiguousarray(np.concatenate([tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0],
                                                      np.asarray(normals, dtype=np.float64)], axis=1))
        self._v0, self._e1, self._e2, self._N = (packed[:, 3 * j:3 * j + 3] for j in range(4))
        self._F = np.ascontiguousarray(F, dtype=np.int64)
        self._facing = np.ascontiguousarray(emitter.facing)
        self._base = np.uint64(K.stream_base(np.uint64(self.seed & 0xFFFFFFFFFFFFFFFF), self.group))
        self._center = np.ascontiguousarray(scene.center, dtype=np.float64)
        self._margin = TFAR_MARGIN_REL * scene.scale
        self.direct = direct
        # the bound as uint8 in units of h/4, rounded down (conservative): 1/8 of the float64 grid's cache footprint
        unit = grid.h / SAFE_STEPS_PER_VOXEL
        self._safe = np.minimum(np.floor(grid.safe / unit), 255).astype(np.uint8)
        self._geo = np.array([*grid.origin, 1.0 / grid.h, unit, grid.h, grid.plane_radius ** 2])


    # --- entries ----------------------------------------------------------------------------------------------
    def _entries(self, chunk, n_photons):
        """Pre-sampled entries of photons chunk * ENTRY_CHUNK ... (clipped at n_photons)."""
        start = chunk * ENTRY_CHUNK
        k = int(min(ENTRY_CHUNK, n_photons - start))
        rng = np.random.default_rng([self.seed, self.group, chunk])
        light, _, pos, dirs, w_in, spec, inc = self.em.emit(k, n_photons, rng)
        return [np.ascontiguousarray(pos), np.ascontiguousarray(dirs), w_in, spec, inc, light.astype(np.int64),
                start + np.arange(k, dtype=np.int64)]

    def run(self, n_photons, *, pool=None, time_budget=None, progress=None, chunks=None):
        """Walk ``n_photons`` photons (fewer if ``time_budget`` seconds run out); returns the number emitted.

        ``chunks=(c0, c1)``: walk only the photons of entry chunks c0 <= c < c1 (photons ``c0 * ENTRY_CHUNK`` up to
        ``min(c1 * ENTRY_CHUNK, n_photons)``) of the run of ``n_photons``: the same paths and weights as in the
        whole run, so the tallies of a partition of the chunks add up to the whole run's (a run split across
        workers, :mod:`meshshade.montecarlo.distributed`).
        """
        t0 = time.perf_counter()
        c0, n_chunks = (0, -(-n_photons // ENTRY_CHUNK)) if chunks is None else (int(chunks[0]), int(chunks[1]))
        in_range = max(0, min(n_chunks * ENTRY_CHUNK, n_photons) - c0 * ENTRY_CHUNK)
        P = int(max(1, min(pool or DEFAULT_POOL, in_range)))
        st = _PoolState(P)
        queue, e, chunk = None, 0, c0   # the current chunk of pre-sampled entries and its next entry
        emitted = 0
        stop = False
        max_live = P if time_budget is None else min(P, BUDGET_START_LIVE)
        live = 0
        last_round = 0.0
        while True:
            now = time.perf_counter() - t0
            if time_budget is not None:
                if now >= time_budget * (1.0 + HARD_OVERSHOOT):
                    K.cut_off(st.status, st.w, st.batch, self.tot)
                    break
                done = emitted - live
                per_photon = now / done if done > 0 else np.inf
                if not stop and emitted and now + DRAIN_SAFETY * live * per_photon >= time_budget:
                    stop = True
                if (not stop and last_round < 0.5 * ROUND_FRACTION * time_budget
                        and DRAIN_SAFETY * 2 * max_live * per_photon < BUDGET_DRAIN_FRACTION * time_budget):
                    max_live = min(P, 2 * max_live)
            if not stop:
                slot = 0
                while live < max_live:
                    if queue is None or e >= queue[0].shape[0]:
                        if chunk >= n_chunks:
                            stop = True
                            break
                        queue, e = self._entries(chunk, n_photons), 0
                        chunk += 1
                    e_old = e
                    e, live, slot = K.refill(st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key, st.ctr,
                                             st.batch, st.light, st.pid, *queue, e, queue[0].shape[0], max_live,
                                             live, slot, self._base, self.B, self.tot)
                    emitted += e - e_old
                    if progress is not None:
                        progress.update(e - e_old)
                if e >= queue[0].shape[0] and chunk >= n_chunks:
                    stop = True
            if live == 0:
                if stop:
                    break
                continue
            t_round = time.perf_counter()
            # every live slot lies below max_live (refill fills the lowest free slots first); while photons die
            # out, more steps per round keep the work per round (and the number of thread launches) bounded
            steps = MAX_STEPS * min(max_live // live, MAX_STEPS_GROWTH)
            self._round(st.view(max_live), live, steps)
            last_round = time.perf_counter() - t_round
            live = int(np.count_nonzero(st.status[:max_live]))
        return emitted

    def _round(self, st, live, steps):
        grid = self.grid
        common = (self._v0, self._e1, self._e2, self._N, self._center, self.scene.scale, OFFSET_REL, OFFSET_ABS)
        if self.direct is not None:
            # dynamic chunks: a thread preempted by another process does not hold up the round
            with numba.parallel_chunksize(CHUNK):
                ev, bd, nr = walk_parallel(
                    st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key, st.ctr, st.absorbed, st.lost, st.exit_face,
                    st.exit_bary, st.exit_w, self._safe, self._geo, grid.planes, grid.plane_index,
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
        beam = -1 if self.beam_light is None or not self.keep_beam else self.beam_light
        nb = K.reduce_round(st.batch, st.light, st.absorbed, st.lost, st.exit_face, st.exit_bary, st.exit_w,
                            self._F, self._facing, self.tot, self.face, self.face_vert, beam, st.beam_face,
                            st.beam_bary, st.beam_w, st.beam_batch)
        if nb:
            for k, arr in (("face", st.beam_face), ("bary", st.beam_bary), ("weight", st.beam_w),
                           ("batch", st.beam_batch)):
                self.exits[k].append(arr[:nb].copy())


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
        self.beam_face, self.beam_batch = np.zeros(P, dtype=np.int64), np.zeros(P, dtype=np.int64)
        self.beam_bary, self.beam_w = np.zeros((P, 3)), np.zeros(P)
