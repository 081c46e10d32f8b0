"""The Monte Carlo walk on many threads (issue 30): the compiled emission against the numpy emitter, the result's
independence of the thread count (bitwise with a photon count, within the standard errors face by face with a
time budget) on 16 threads oversubscribing this machine, and a time budget that a slow first round (numba
compiling) cannot starve.

The oversubscribed checks run in a subprocess started with NUMBA_NUM_THREADS=16 (numba reads it once, at import),
over 20 seeds, on a small sphere lit by a point light (a boundary test for a large share of the events).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, torus
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.light import AreaLight, BeamLight, DirectionalLight, EnvironmentLight, PointLight
from meshshade.light.sources import Spot
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, engine, simulate
from meshshade.montecarlo.emission import EmitterKernel, emission_base, fresnel_in, spot_falloff
from meshshade.montecarlo.emitter import Emitter
from meshshade.raycast import make_scene
from meshshade.raycast.embree_direct import DirectEmbreeScene


# ------------------------------------------------------------------------------------------------ scalar twins
@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(1.0, 2.5))
def test_fresnel_in_matches_array_fresnel(cos_i, eta):
    assert fresnel_in(cos_i, eta) == pytest.approx(float(fresnel_reflectance(cos_i, 1.0, eta)), rel=1e-12,
                                                   abs=1e-15)


@settings(max_examples=300, deadline=None)
@given(st.floats(-1.0, 1.0), st.floats(1e-3, math.pi), st.floats(0.0, 1.0))
def test_spot_falloff_matches_spot(cos_theta, angle, blend):
    spot = Spot((0.0, 0.0, 1.0), angle, blend)
    c = math.cos(0.5 * angle)
    assert spot_falloff(cos_theta, c, (1.0 - c) * blend) == pytest.approx(float(spot.falloff(cos_theta)),
                                                                          rel=1e-12, abs=1e-15)


# ------------------------------------------------------------------------------------------------ emission
def _torus():
    V, F = torus(10.0, 4.0, 48, 24)
    return Mesh.from_arrays(V, F)


EMISSION_CASES = {
    # a tilted sun on a torus: part of the inner ring is shadowed by the other side
    "sun_torus": (_torus, [DirectionalLight((0.5, 0.2, -0.84), 2.0)]),
    "point_torus": (_torus, [PointLight((3.0, -2.0, 12.0), 50.0)]),
    # a point light close to a coarse sphere: the irradiance varies strongly across each face (importance weights)
    "point_close_coarse": (lambda: Mesh.from_arrays(*icosphere(5.0, 1)), [PointLight((0.5, 0.3, 6.0), 10.0)]),
    "spot_and_sun": (_torus, [PointLight((14.0, 0.0, 8.0), 80.0, Spot((-0.7, 0.0, -0.7), 1.0, 0.4)),
                              DirectionalLight((0.0, 0.0, -1.0), 0.5)]),
    "disc_beam_sphere": (lambda: Mesh.from_arrays(*icosphere(5.0, 3)), [BeamLight((0.3, 0.2, 20.0), (0, 0, -1), 2.0,
                                                                                  radius=6.0)]),
    "pencil_and_point": (lambda: Mesh.from_arrays(*icosphere(5.0, 3)),
                         [BeamLight((0.3, 0.2, 20.0), (0, 0, -1)), PointLight((8.0, 0.0, 0.0), 10.0)]),
    # environment and area lights (issue 43): a map with a bright spot over a dim sky, rotated; a rectangle and a
    # disc emitter beside a uniform sky, on the torus (it shadows itself)
    "env_torus": (_torus, [EnvironmentLight(np.add.outer(np.linspace(0.2, 1.0, 16), np.zeros(32))
                                            + 80.0 * (np.add.outer(np.arange(16), np.arange(32)) == 12),
                                            rotation_deg=40)]),
    "area_torus": (_torus, [AreaLight((3.0, 2.0, 15.0), (0.0, -0.2, -1.0), "rect", (8.0, 4.0), 5.0)]),
    "disc_and_sky": (_torus, [AreaLight((3.0, 2.0, 15.0), (0.0, -0.2, -1.0), "disc", (3.0, 5.0), 5.0),
                              EnvironmentLight.uniform(0.1)]),
}


def _compiled_entries(mesh, lights, n, seed, direct):
    """(inc, spec, w_in, pos, dir) per photon from the compiled emission (through the pool's slots)."""
    scene = make_scene(mesh.vertices, mesh.faces)
    em = Emitter(mesh.vertices, mesh.faces, mesh.face_normals, mesh.face_areas, lights, scene, 1.4)
    ds = DirectEmbreeScene(mesh.vertices, mesh.faces, scene.center) if direct else None
    ek = EmitterKernel(em, ds)
    st = engine._PoolState(n)
    tot = np.zeros((4, 7))
    slots = np.arange(n)
    ek.emit_into(st, slots, 0, emission_base(seed, 0), np.uint64(1), n, 4, tot, engine.OFFSET_REL,
                 engine.OFFSET_ABS)
    b = ek._buf
    alive = st.status == 1
    pos = np.where(alive[:, None], st.pos, np.nan)
    return b["inc"][:n].copy(), b["spec"][:n].copy(), b["w_in"][:n].copy(), pos, st.d.copy(), tot, em


def _numpy_entries(em, n, seed):
    rng = np.random.default_rng(seed)
    _light, _face, pos, dirs, w_in, spec, inc = em.emit(n, n, rng)
    return inc, spec, w_in, np.where((w_in > 0)[:, None], pos, np.nan), dirs


def _summaries(inc, spec, w_in, pos, d, n):
    """Per-photon quantities whose means both emitters must share: powers, entering power by octant of the
    entry point, and the entering-power-weighted direction."""
    cols = [inc, spec, w_in]
    ok = w_in > 0
    octant = np.where(ok, (np.nan_to_num(pos[:, 0]) > 0) * 4 + (np.nan_to_num(pos[:, 1]) > 0) * 2
                      + (np.nan_to_num(pos[:, 2]) > 0), -1)
    cols += [np.where(octant == k, w_in, 0.0) for k in range(8)]
    cols += [np.where(ok, w_in * d[:, a], 0.0) for a in range(3)]
    X = np.stack(cols, axis=1) * n          # per-photon contribution to the total
    return X.mean(axis=0), X.std(axis=0, ddof=1) / math.sqrt(n)


@pytest.mark.parametrize("direct", [True, False], ids=["direct", "embreex"])
@pytest.mark.parametrize("case", sorted(EMISSION_CASES))
def test_compiled_emission_matches_numpy_emitter(case, direct):
    """Same distribution as the numpy twin (Emitter.emit, which the baseline wavefront uses): every mean within
    4.5 standard errors (14 quantities x 13 cases: a false alarm has probability ~1e-3), and the booked totals
    equal the photons' sums."""
    build, lights = EMISSION_CASES[case]
    mesh = build()
    n = 60_000
    inc, spec, w_in, pos, d, tot, em = _compiled_entries(mesh, lights, n, 11, direct)
    a_mean, a_se = _summaries(inc, spec, w_in, pos, d, n)
    b_mean, b_se = _summaries(*_numpy_entries(em, n, 12), n)
    z = (a_mean - b_mean) / np.sqrt(a_se ** 2 + b_se ** 2 + 1e-300)
    both_zero = (a_se == 0) & (b_se == 0)
    np.testing.assert_allclose(a_mean[both_zero], b_mean[both_zero], rtol=1e-12)
    assert np.all(np.abs(z[~both_zero]) < 4.5), (case, z)
    np.testing.assert_allclose(tot[:, 5].sum(), inc.sum(), rtol=1e-12)
    np.testing.assert_allclose(tot[:, 0].sum(), spec.sum(), rtol=1e-12)
    np.testing.assert_allclose(tot[:, 6].sum(), w_in.sum(), rtol=1e-12)
    # entering photons start just inside the surface, heading inwards
    ok = w_in > 0
    assert ok.sum() > 0.3 * n
    np.testing.assert_allclose(np.linalg.norm(d[ok], axis=1), 1.0, rtol=1e-12)


def test_shadowed_entries_are_booked_but_walk_nothing():
    """A sun on a torus from the side: shadowed entries carry incident power 0 (as the numpy emitter), their slots
    stay free."""
    mesh = _torus()
    inc, _spec, w_in, pos, _d, _tot, _em = _compiled_entries(mesh, [DirectionalLight((1.0, 0.0, -0.05))], 20_000, 3,
                                                             True)
    shadowed = inc == 0
    assert 0.05 < shadowed.mean() < 0.6
    assert np.all(np.isnan(pos[shadowed])) and np.all(w_in[shadowed] == 0)


# ------------------------------------------------------------------------------------------------ time budget
def _long_lived():
    # albedo 0.99999 in a sphere of 30 mean free paths: ~1e3 events per photon, none finishes in the first round
    return Mesh.from_arrays(*icosphere(3.0, 2)), Material(10.0, 1e-4, eta=1.4), [DirectionalLight((0, 0, -1.0))]


def test_budget_is_not_starved_by_a_slow_first_round(monkeypatch, mc_work_clock):
    """The first round carries one-off costs (numba compiling or loading its cache, threads starting); and here no
    photon finishes within it. The budget must still fill most of its time with photons: before the fix, the
    throughput was estimated from that round and emission stopped after the first BUDGET_START_LIVE photons
    (the red channel of a 16-thread run that returned a handful of photons, issue 30)."""
    mesh, mat, lights = _long_lived()
    simulate(mesh, mat, lights, MCOptions(photons=200, beam_distances=False))   # compile / load the kernels
    clock = mc_work_clock()
    real = engine.PoolWalk._round
    calls = {"n": 0}
    budget = 3.0

    def slow_first(self, st, steps):
        calls["n"] += 1
        if calls["n"] == 1:
            clock.t += 0.25 * budget   # a compile inside the first round
        return real(self, st, steps)

    monkeypatch.setattr(engine.PoolWalk, "_round", slow_first)
    r = simulate(mesh, mat, lights, MCOptions(photons=None, time_budget=budget, beam_distances=False))
    # at ~1e3 steps per photon and 1e7 steps/s of work clock the budget holds ~3e4 photons; 0.75 of it is left
    assert r.photons > 4 * engine.BUDGET_START_LIVE, r.photons
    assert np.all(r.lost == 0.0)
    assert clock.t <= budget * (1 + engine.HARD_OVERSHOOT) + clock.longest_round


def test_a_group_that_overran_leaves_the_next_ones_photons(monkeypatch, mc_work_clock):
    """The first channel group's first round eats twice the whole budget (16 threads on 2 busy cores once did
    this to a 0.5 s run, which then returned 0 photons in green and blue): every group still walks photons, on
    at least MIN_GROUP_SHARE of its equal share."""
    mesh = Mesh.from_arrays(*icosphere(3.0, 2))
    mat = Material((10.0, 3.0, 1.0), (1e-4, 0.05, 0.5), eta=1.4)
    beam = BeamLight((0.01, 0.02, 10.0), (0, 0, -1))
    simulate(mesh, mat, [beam], MCOptions(photons=200, beam_distances=False))
    clock = mc_work_clock()
    real = engine.PoolWalk._round
    budget = 0.5
    seen = set()

    def first_round_of_group_0_overruns(self, st, steps):
        if self.group == 0 and 0 not in seen:
            seen.add(0)
            clock.t += 2.0 * budget
        return real(self, st, steps)

    monkeypatch.setattr(engine.PoolWalk, "_round", first_round_of_group_0_overruns)
    r = simulate(mesh, mat, [beam], MCOptions(photons=None, time_budget=budget, beam_distances=False))
    assert np.all(r.photons_per_channel > 1000), r.photons_per_channel


def test_each_channel_is_normalised_by_its_own_photons(mc_work_clock):
    """Three channel groups of very different walk lengths under one budget: each reports its own photon count,
    and each channel's incident power (a pencil beam: exact per photon) equals the beam's power, whatever its
    count."""
    mesh = Mesh.from_arrays(*icosphere(3.0, 2))
    mat = Material((10.0, 3.0, 1.0), (1e-4, 0.05, 0.5), eta=1.4)
    beam = BeamLight((0.01, 0.02, 10.0), (0, 0, -1), power=2.0)
    simulate(mesh, mat, [beam], MCOptions(photons=200, beam_distances=False))
    mc_work_clock()
    r = simulate(mesh, mat, [beam], MCOptions(photons=None, time_budget=1.0, beam_distances=False))
    per = r.photons_per_channel
    assert per.shape == (3,) and np.all(per > 0) and len(set(per.tolist())) == 3
    assert r.photons == per.min()
    np.testing.assert_allclose(r.incident_power, 2.0, rtol=1e-9)


# ------------------------------------------------------------------------------------------------ many threads
_SCRIPT = textwrap.dedent("""
    import json, sys, warnings
    import numba, numpy as np
    warnings.simplefilter("ignore")
    from meshshade.geometry.mesh import Mesh
    from meshshade.geometry.procedural import icosphere
    from meshshade.light import PointLight
    from meshshade.materials import material_from_options
    from meshshade.montecarlo import simulate
    mesh = Mesh.from_arrays(*icosphere(6.0, 3))
    mat = material_from_options("skin1")
    lights = [PointLight((4.0, 3.0, 12.0), 100.0)]
    seeds, threads, budget = json.loads(sys.argv[1])
    kw = dict(beam_distances=False, keep_beam_exits=False)
    out = {"max_threads": numba.config.NUMBA_NUM_THREADS, "fixed": [], "budget": []}
    numba.set_num_threads(threads[-1])
    reference = simulate(mesh, mat, lights, photons=150_000, seed=10**6, **kw)   # independent of every seed below
    for seed in seeds:
        ref = None
        for t in threads:
            numba.set_num_threads(t)
            r = simulate(mesh, mat, lights, photons=12_000, seed=seed, **kw)
            cur = (r.face_power, r.vertex_power, np.stack([r.totals[k] for k in sorted(r.totals)]))
            if ref is None:
                ref = cur
            out["fixed"].append(all(np.array_equal(a, b) for a, b in zip(cur, ref)))
        # the same seed on two thread counts shares its first photons: each run is compared with the reference
        t = threads[seed % 2 * (len(threads) - 1)]
        numba.set_num_threads(t)
        a = simulate(mesh, mat, lights, photons=None, time_budget=budget, seed=seed, **kw)
        se2 = a.face_power_stderr ** 2 + reference.face_power_stderr ** 2
        ok = (a.face_power_stderr > 0) & (a.face_power_stderr < 0.3 * a.face_power)
        z2 = (a.face_power - reference.face_power) ** 2 / np.where(ok, se2, 1.0)
        out["budget"].append({"threads": t, "z2_sum": float(z2[ok].sum()), "n": int(ok.sum()),
                              "photons": a.photons_per_channel.tolist(), "lost": float(a.lost.max())})
    print(json.dumps(out))
""")


def _oversubscribed(seeds, threads, budget):
    env = {**os.environ, "NUMBA_NUM_THREADS": str(max(threads))}
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, json.dumps([seeds, threads, budget])], env=env,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("n_seeds", [6, pytest.param(20, marks=pytest.mark.slow)])
def test_many_threads_same_result_and_budget_runs_agree_face_by_face(n_seeds):
    """16 numba threads on this 2-core machine (oversubscribed, as issue 30 says makes thread bugs show), 20 seeds
    (slow) or 6 (the default suite: 3 s of budget runs instead of 10, about a third of the time):

    * a photon count gives bitwise the same faces, vertices and totals on 1, 2, 7 and 16 threads;
    * with a time budget, on 1 thread (even seeds) and 16 threads (odd seeds), every run agrees face by face with
      an independent 150k-photon reference within the standard errors: z^2 = (a - ref)^2 / (se_a^2 + se_ref^2)
      over every face with a relative error below 0.3. (Two thread counts on one seed share their first photons,
      so they are compared through the reference, not with each other.) With batch-means errors (16 batches, 15
      degrees of freedom) E[z^2] is about 1.1 (1 for known variances, 15/13 for one estimated variance); the
      mean over the faces and channels (about 1800 a seed, measured: 11k for 6 seeds) must lie in [0.85, 1.35] and
      no seed's mean above 1.8 (a wrong tally such as issue 30's 0.42-correlated red channel gives z^2 >> 1 on its
      faces). The bands hold for 6 seeds: z^2 of one face is about F(1, 15) (variance 3.4), so the mean over 11k
      has a standard error of 0.018 (0.85 and 1.35 are 17 and 11 of them from 1.15), one seed's 0.043 (1.8 is 15
      away); measured with 6 seeds: 1.09, seeds 1.06-1.14.
    """
    out = _oversubscribed(list(range(n_seeds)), [1, 2, 7, 16], 0.5)
    assert out["max_threads"] == 16
    assert all(out["fixed"]), out["fixed"]
    z2 = sum(b["z2_sum"] for b in out["budget"])
    n = sum(b["n"] for b in out["budget"])
    per_seed = [b["z2_sum"] / max(b["n"], 1) for b in out["budget"]]
    assert n > 250 * n_seeds, out["budget"]
    assert 0.85 <= z2 / n <= 1.35, (z2 / n, per_seed)
    assert max(per_seed) < 1.8, per_seed
    assert all(min(b["photons"]) > 2000 for b in out["budget"]), [b["photons"] for b in out["budget"]]
    assert {b["threads"] for b in out["budget"]} == {1, 16}
