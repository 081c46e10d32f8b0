"""Pooled Monte Carlo engine: building blocks against independent references, determinism (seed, threads, pool;
Embree mode in a slow test), exact energy balance, bounded time budget, statistical agreement with the baseline.

Statistical test: the pooled engine and the numpy wavefront (fast_interior=False; independent code, different
random streams) simulate the same scene; every compared quantity must agree within Z_MAX combined batch-means
standard errors. With 16 batches per run (Welch ~30 degrees of freedom) and 33 comparisons, Z_MAX = 5 gives a
family-wise false-alarm probability of about 1e-3 (Sidak); a bias of 3.5 % of the diffuse reflectance would fail.
The seeds are fixed, so the test is deterministic.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest

from meshshade.errors import LightError, MeshshadeError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.light import BeamLight, DirectionalLight, PointLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, TOTAL_KEYS, simulate
from meshshade.montecarlo import engine
from meshshade.montecarlo import interior as montecarlo_interior
from meshshade.montecarlo import loops as K
from meshshade.montecarlo.sampling import ROULETTE_BOOST, ROULETTE_THRESHOLD
from meshshade.raycast import embree_direct as montecarlo_embree
from meshshade.raycast import make_scene
from meshshade.raycast.embree_direct import DirectEmbreeScene

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")
Z_MAX = 5.0


def _sphere_scene(level=2):
    mesh = Mesh.from_arrays(*icosphere(5.0, level))
    mat = Material((1.0, 2.0, 0.5), (0.05, 0.1, 0.2), eta=1.4, g=0.5)
    return mesh, mat, [DirectionalLight((0.2, -0.3, -1.0))]


def _assert_same(a, b, exact=True):
    check = np.testing.assert_array_equal if exact else (
        lambda x, y: np.testing.assert_allclose(x, y, rtol=1e-10, atol=1e-15))
    for field in ("face_power", "face_power_stderr", "vertex_power", "radiance", "radiance_stderr", "lost"):
        check(getattr(a, field), getattr(b, field))
    for key in a.totals:
        check(a.totals[key], b.totals[key])


# ------------------------------------------------------------------------------------------------ building blocks
def test_counter_streams_uniform_and_distinct():
    base = K.stream_base(np.uint64(7), 0)
    u = K.uniform_stream(K.photon_key(base, 0), 200_000)
    assert u.min() >= 0.0 and u.max() < 1.0
    # mean 1/2 and variance 1/12 of U(0, 1): 5-sigma bounds
    assert abs(u.mean() - 0.5) < 5 * np.sqrt(1 / 12 / u.size)
    assert abs(u.var() - 1 / 12) < 5 * np.sqrt(1 / 180 / u.size)
    # neighbouring photons and groups: uncorrelated streams
    v = K.uniform_stream(K.photon_key(base, 1), 200_000)
    w = K.uniform_stream(K.photon_key(K.stream_base(np.uint64(7), 1), 0), 200_000)
    for x in (v, w):
        assert abs(np.corrcoef(u, x)[0, 1]) < 5 / np.sqrt(u.size)


def test_fresnel_out_matches_array_kernel():
    cos = np.linspace(0.0, 1.0, 1001)
    for eta in (1.0, 1.33, 1.5, 2.4):
        ref = fresnel_reflectance(cos, eta, 1.0)   # kernels.fresnel: closed form, tested on its own
        got = np.array([K.fresnel_out(c, eta) for c in cos])
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)


def test_direct_embree_matches_embreex_and_float64():
    V, F = icosphere(3.0, 3)
    scene = make_scene(V, F)
    direct = DirectEmbreeScene(V, F, scene.center)
    rng = np.random.default_rng(4)
    o = rng.normal(size=(20_000, 3))
    o *= (2.9 * rng.random((o.shape[0], 1)) ** (1 / 3)) / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.normal(size=o.shape)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    got = direct.first_hit_faces((o - scene.center).astype(np.float32), d.astype(np.float32))
    ref = scene.first_hit(o, d).face                              # embreex, float64 adapter
    exact = make_scene(V, F, backend="numpy").first_hit(o, d).face  # float64 brute force
    assert np.all(got >= 0)
    assert np.mean(got == ref) > 0.999 and np.mean(got == exact) > 0.999


def test_roulette_constants_shared():
    assert (engine.K_THRESH, engine.K_BOOST) == (ROULETTE_THRESHOLD, ROULETTE_BOOST)


def test_emitter_accepts_only_light_objects_outside_the_mesh():
    """The light classes validate their fields; the emitter checks the type and the placement against the mesh."""
    mesh = Mesh.from_arrays(*icosphere(5.0, 1))
    mat = Material(1.0, 0.1, eta=1.4)
    fake_beam = type("FakeBeam", (), {"origin": (0.0, 0.0, 20.0), "direction": (0.0, 0.0, -1.0), "power": 1.0})()
    cases = [([], "at least one light"), ([fake_beam], "light 0 is not a BeamLight"),
             ([DirectionalLight((0, 0, -1)), "beam:0,0,20:0,0,-1"], "light 1 is not a BeamLight"),
             ([BeamLight((0.0, 0.0, 1.0), (0.0, 0.0, -1.0))], "beam light 0 starts inside the mesh"),
             ([DirectionalLight((0, 0, -1)), PointLight((0.5, 0.0, 0.0))], "point light 1 .* is inside the mesh")]
    for lights, message in cases:
        with pytest.raises(LightError, match=message):
            simulate(mesh, mat, lights, MCOptions(photons=16, beam_distances=False))


# ------------------------------------------------------------------------------------------------ determinism
def test_deterministic_for_seed_threads_and_pool():
    mesh, mat, lights = _sphere_scene()
    kw = dict(photons=20_000, seed=3, beam_distances=False)
    a = simulate(mesh, mat, lights, MCOptions(**kw))
    b = simulate(mesh, mat, lights, MCOptions(**kw))
    _assert_same(a, b)
    c = simulate(mesh, mat, lights, MCOptions(**{**kw, "seed": 4}))
    assert not np.array_equal(a.radiance, c.radiance)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = simulate(mesh, mat, lights, MCOptions(**kw))
    finally:
        numba.set_num_threads(threads)
    _assert_same(a, one)                                     # bitwise, whatever the thread count
    # photon i's path does not depend on the pool: same events, same tallies up to the summation order
    other = simulate(mesh, mat, lights, MCOptions(pool=3000, **kw))
    assert (other.events, other.boundary_events, other.boundary_tests) == (a.events, a.boundary_events,
                                                                          a.boundary_tests)
    _assert_same(a, other, exact=False)


@pytest.mark.slow
def test_batched_embreex_mode_walks_the_same_paths():
    """One embreex call per round (separate kernels, slow to compile) walks exactly the fused mode's paths."""
    mesh, mat, lights = _sphere_scene()
    kw = dict(photons=20_000, seed=3, beam_distances=False)
    a = simulate(mesh, mat, lights, MCOptions(engine="fused", **kw))
    b = simulate(mesh, mat, lights, MCOptions(engine="batched", **kw))
    assert (b.events, b.boundary_events, b.boundary_tests) == (a.events, a.boundary_events, a.boundary_tests)
    _assert_same(a, b, exact=False)


@pytest.mark.slow
def test_auto_engine_falls_back_to_batched(monkeypatch):
    mesh, mat, lights = _sphere_scene()
    kw = dict(photons=3000, seed=3, beam_distances=False)
    a = simulate(mesh, mat, lights, MCOptions(engine="batched", **kw))
    monkeypatch.setattr(montecarlo_embree, "_library", lambda: None)   # no bindable Embree library
    _assert_same(a, simulate(mesh, mat, lights, MCOptions(engine="auto", **kw)))
    with pytest.raises(MeshshadeError, match="fused"):
        simulate(mesh, mat, lights, MCOptions(engine="fused", **kw))


def test_half_space_certificates_change_cost_not_paths(monkeypatch):
    """The certificates only skip rays whose answer is 'no hit within the free path': identical walks."""
    mesh = Mesh.from_arrays(*box((10.0, 10.0, 5.0)))
    args = (mesh, Material(9.0, 1.0, eta=1.5), [BeamLight((0.123, 0.0456, 10.0), (0.0, 0.0, -1.0))])
    kw = dict(photons=4000, seed=8, beam_distances=False)
    with_planes = simulate(*args, MCOptions(**kw))
    assert montecarlo_interior.PLANE_MAX_FACES >= 12                  # the box gets certificates ...
    monkeypatch.setattr(montecarlo_interior, "PLANE_MAX_FACES", 0)   # ... and here none
    without = simulate(*args, MCOptions(**kw))
    assert (with_planes.events, with_planes.boundary_events) == (without.events, without.boundary_events)
    assert with_planes.boundary_tests < 0.7 * without.boundary_tests
    _assert_same(with_planes, without, exact=False)


# ------------------------------------------------------------------------------------------------ energy balance
def test_energy_balance_exact_with_point_beam_and_directional_lights():
    mesh, mat, _ = _sphere_scene()
    lights = [PointLight((0.0, 0.0, 12.0), 3.0), BeamLight((0.1, 0.2, 20.0), (0.0, 0.0, -1.0), 0.5),
              DirectionalLight((1.0, 0.0, 0.0), 0.2)]
    r = simulate(mesh, mat, lights, MCOptions(photons=6000, seed=9, beam_distances=False))
    total = sum(r.totals[k] for k in TOTAL_KEYS) + r.lost
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)
    assert np.all(r.lost == 0.0)
    exit_frac = (r.totals["diffuse_reflectance"] + r.totals["transmittance"]) * r.incident_power
    np.testing.assert_allclose(r.face_power.sum(0), exit_frac, rtol=1e-10)
    np.testing.assert_allclose(r.vertex_power.sum(0), r.face_power.sum(0), rtol=1e-12)
    assert r.beam_exits[0]["weight"].size > 0


# ------------------------------------------------------------------------------------------------ time budget
def _long_lived():
    # albedo 0.99999 in a sphere of 30 mean free paths: ~1e3 events per photon, photons always in flight
    return Mesh.from_arrays(*icosphere(3.0, 2)), Material(10.0, 1e-4, eta=1.4), [DirectionalLight((0, 0, -1.0))]


def test_time_budget_overshoot_bounded(mc_work_clock):
    """Module docstring of the engine: the walk ends by the drain prediction before the budget (nothing lost),
    at the latest at budget (1 + HARD_OVERSHOOT) plus one round, on the walk's own clock."""
    mesh, mat, lights = _long_lived()
    simulate(mesh, mat, lights, MCOptions(photons=200, beam_distances=False))   # compile / load the kernels
    clock = mc_work_clock()
    budget = 0.6
    r = simulate(mesh, mat, lights, MCOptions(photons=None, time_budget=budget, beam_distances=False))
    assert r.photons > 100 and r.seconds == clock.t
    assert clock.t <= budget * (1 + engine.HARD_OVERSHOOT) + clock.longest_round, (clock.t, clock.longest_round)
    assert clock.longest_round <= 2 * engine.ROUND_FRACTION * budget   # rounds stay near ROUND_FRACTION budget
    assert np.all(r.lost == 0.0)
    total = sum(r.totals[k] for k in TOTAL_KEYS) + r.lost
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)


def test_time_budget_hard_cut_off_books_lost(monkeypatch, mc_work_clock):
    mesh, mat, lights = _long_lived()
    monkeypatch.setattr(engine, "DRAIN_SAFETY", 0.0)      # never stop emission early: force the hard limit
    monkeypatch.setattr(engine, "HARD_OVERSHOOT", 0.0)
    simulate(mesh, mat, lights, MCOptions(photons=None, time_budget=0.05, beam_distances=False))   # compile cut_off
    clock = mc_work_clock()
    budget = 0.3
    r = simulate(mesh, mat, lights, MCOptions(photons=None, time_budget=budget, beam_distances=False))
    # cut off at the first check past the budget: within one round of it on the walk's own clock
    assert budget <= clock.t <= budget + clock.longest_round, (clock.t, clock.longest_round)
    assert r.lost[0] > 0.0
    total = sum(r.totals[k] for k in TOTAL_KEYS) + r.lost
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------------------ vs baseline
def _region_power(r, mesh):
    """Exit power (3 channels) summed over 8 regions of the sphere (octants of the face centroids), with stderr."""
    c = mesh.vertices[mesh.faces].mean(axis=1)
    octant = (c[:, 0] > 0) * 4 + (c[:, 1] > 0) * 2 + (c[:, 2] > 0)
    onehot = np.eye(8)[octant]                                # (m, 8)
    return onehot.T @ r.face_power, np.sqrt(onehot.T @ (r.face_power_stderr ** 2))


def test_pooled_engine_agrees_with_wavefront_baseline():
    mesh, mat, lights = _sphere_scene(level=3)
    new = simulate(mesh, mat, lights, MCOptions(photons=24_000, seed=31, beam_distances=False))
    old = simulate(mesh, mat, lights, MCOptions(photons=24_000, seed=32, beam_distances=False, fast_interior=False))
    z = []
    for key in ("specular_reflectance", "diffuse_reflectance", "transmittance"):
        se = np.hypot(new.totals[key + "_stderr"], old.totals[key + "_stderr"])
        z.append((new.totals[key] - old.totals[key]) / se)
    (pn, sn), (po, so) = _region_power(new, mesh), _region_power(old, mesh)
    lit = po > 1e-3 * po.max()                                   # regions with exit power (stderr > 0)
    z.append(((pn - po) / np.hypot(sn, so))[lit])
    z = np.concatenate([np.ravel(x) for x in z])
    assert z.size >= 20 and np.all(np.isfinite(z))
    assert np.max(np.abs(z)) < Z_MAX, z
