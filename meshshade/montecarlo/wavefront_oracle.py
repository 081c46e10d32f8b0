"""Oracle for tests and benchmarks: the baseline Monte Carlo engine, a numpy wavefront with one Embree query per step.

Not a production path: it is kept only as the simple, independent reference that the pooled engine
(:mod:`meshshade.montecarlo.engine`) is tested and benchmarked against (``simulate(..., fast_interior=False)``,
``tools/benchmarks/bench_mc.py``). All live photons advance together by one free path per iteration; dead photons are
replaced by new ones from the lights as long as photons remain (a regenerating pool of ``pool`` photons, so the
long tail of the walk does not starve the Embree batches). Physics and tallies as in
:mod:`meshshade.montecarlo.simulation`, sampling from :mod:`meshshade.montecarlo.sampling`.
"""
from __future__ import annotations

import time

import numpy as np

from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.light import BeamLight
from meshshade.montecarlo.sampling import ROULETTE_BOOST, ROULETTE_THRESHOLD, GroupMedium, scatter_directions


class WavefrontWalk:
    """One grey walk (one channel group) with a regenerating wavefront."""

    def __init__(self, V, F, normals, emitter, scene, medium: GroupMedium, *, n_batches, keep_beam):
        self.V, self.F, self.N, self.em, self.scene = V, F, normals, emitter, scene
        self.sigma_t, self.albedo = medium.sigma_t, medium.albedo
        self.g, self.eta, self.B, self.keep_beam = medium.g, medium.eta, n_batches, keep_beam
        m, L = F.shape[0], len(emitter.lights)
        self.face = np.zeros((n_batches, m))
        self.face_vert = np.zeros((n_batches, V.shape[0]))
        self.tot = np.zeros((n_batches, 7))  # specular, diffuse, transmitted, absorbed, lost, incident, entering
        self.events = 0
        self.boundary = 0
        self.beam_light = next((i for i, lt in enumerate(emitter.lights) if isinstance(lt, BeamLight)), None)
        self.exits = {"face": [], "bary": [], "weight": [], "batch": []}
        self.L = L

    def run(self, n_photons, rng, *, pool, time_budget=None, progress=None):
        t0 = time.perf_counter()
        self.rays = 0
        emitted = 0
        keys = ("pos", "dir", "w", "w0", "batch", "light")
        live = {k: np.zeros((0, 3) if k in ("pos", "dir") else 0) for k in keys}
        live["batch"] = live["batch"].astype(np.int64)
        live["light"] = live["light"].astype(np.int64)
        stop_emitting = False
        while True:
            if time_budget is not None and time.perf_counter() - t0 > time_budget:
                stop_emitting = True
            k = min(pool - live["w"].size, n_photons - emitted) if not stop_emitting else 0
            if k > 0:
                live = self._add(live, k, emitted, n_photons, rng)
                emitted += k
                if progress is not None:
                    progress.update(k)
            if live["w"].size == 0:
                break
            live = self._step(live, rng)
        return emitted

    def _add(self, live, k, emitted, n_total, rng):
        light, face, pos, dirs, w_in, spec, inc = self.em.emit(k, n_total, rng)
        batch = (emitted + np.arange(k)) % self.B
        np.add.at(self.tot, (batch, 0), spec)
        np.add.at(self.tot, (batch, 5), inc)
        np.add.at(self.tot, (batch, 6), w_in)
        ok = w_in > 0.0
        new = {"pos": pos[ok], "dir": dirs[ok], "w": w_in[ok], "w0": w_in[ok], "batch": batch[ok],
               "light": light[ok]}
        return {key: np.concatenate([live[key], new[key]]) for key in live}

    def _step(self, live, rng):
        pos, d, w, batch = live["pos"], live["dir"], live["w"], live["batch"]
        n = w.size
        hits = self.scene.first_hit(pos, d)
        self.rays += n
        s = -np.log1p(-rng.random(n)) / self.sigma_t if self.sigma_t > 0 else np.full(n, np.inf)
        t_hit = np.where(hits.face >= 0, np.maximum(hits.t, 0.0), np.inf)
        # a ray from inside must hit the back of a face; a miss or a front hit means the photon leaked out
        fn = self.N[np.maximum(hits.face, 0)]
        cos_i = np.einsum("ij,ij->i", d, fn)
        leaked = (hits.face < 0) | (cos_i <= 0.0)
        at_boundary = (t_hit <= s) & ~leaked
        scatter = (s < t_hit) & ~leaked & ~at_boundary
        keep = scatter.copy()
        # --- leaks
        if np.any(leaked):
            np.add.at(self.tot, (batch[leaked], 4), w[leaked])
        # --- interactions: absorb, scatter
        idx = np.flatnonzero(scatter)
        if idx.size:
            pos[idx] += s[idx, None] * d[idx]
            np.add.at(self.tot, (batch[idx], 3), w[idx] * (1.0 - self.albedo))
            w[idx] *= self.albedo
            d[idx] = scatter_directions(d[idx], self.g, rng)
            self.events += idx.size
        # --- boundary: Fresnel reflect or exit
        idx = np.flatnonzero(at_boundary)
        if idx.size:
            self.boundary += idx.size
            ci = np.clip(cos_i[idx], 0.0, 1.0)
            R = fresnel_reflectance(ci, self.eta, 1.0)
            refl = rng.random(idx.size) < R
            r_idx, e_idx = idx[refl], idx[~refl]
            if r_idx.size:
                nr = fn[r_idx]
                d[r_idx] = d[r_idx] - 2.0 * cos_i[r_idx, None] * nr
                pos[r_idx] = self.scene.offset_origins(hits.points[r_idx], nr, sign=-1.0)
                keep[r_idx] = True
            if e_idx.size:
                f = hits.face[e_idx]
                u, v = hits.uv[e_idx, 0], hits.uv[e_idx, 1]
                bary = np.stack([1.0 - u - v, u, v], axis=1)
                we, be = w[e_idx], batch[e_idx]
                np.add.at(self.face, (be, f), we)
                for j in range(3):
                    np.add.at(self.face_vert, (be, self.F[f, j]), we * bary[:, j])
                facing = self.em.facing[live["light"][e_idx], f]
                np.add.at(self.tot, (be[facing], 1), we[facing])
                np.add.at(self.tot, (be[~facing], 2), we[~facing])
                if self.keep_beam and self.beam_light is not None:
                    mine = live["light"][e_idx] == self.beam_light
                    for key, val in (("face", f), ("bary", bary), ("weight", we), ("batch", be)):
                        self.exits[key].append(val[mine])
        # --- Russian roulette (net change booked as absorbed: exact balance, unbiased)
        low = keep & (w < ROULETTE_THRESHOLD * live["w0"])
        idx = np.flatnonzero(low)
        if idx.size:
            survive = rng.random(idx.size) * ROULETTE_BOOST < 1.0
            delta = np.where(survive, -(ROULETTE_BOOST - 1.0) * w[idx], w[idx])
            np.add.at(self.tot, (batch[idx], 3), delta)
            w[idx] = np.where(survive, w[idx] * ROULETTE_BOOST, 0.0)
            keep[idx[~survive]] = False
        live = {key: val[keep] for key, val in live.items()}
        return live
