"""The hierarchical transport (meshshade/surface/hierarchical.py) against the direct sum, its clusters against
their own leaves, the sigma points' moments, the distance check, reuse across lights, and the CLI option.

Reference values: the direct sum (transport="direct", every pair within the cutoff with exact polyhedral
geodesics: today's reference path, tested against the exact sphere and Monte Carlo elsewhere) and, for the
clusters, the same traversal with clusters switched off (theta -> 0: every far pair summed one by one).
"""
import logging

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.cli.main import main
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, torus
from meshshade.io import write_ply
from meshshade.light import BeamLight, DirectionalLight, entry_samples
from meshshade.materials import material_from_options
from meshshade.transport.baking import bake
from meshshade.surface.farfield_loops import kd_permutation, node_ranges, tree_depth
from meshshade.surface.hierarchical import (VERIFY_TOL, FarFieldUnsupported, SurfaceTransport, verify_far_field,
                                              vertex_power)
from meshshade.surface.hierarchy_loops import cluster_geometry
from meshshade.transport import BakeOptions, SurfaceOptions

SKIN = material_from_options("skin1")
MARBLE = material_from_options("marble")
SUN = DirectionalLight((0.3, -0.4, -1.0), 1.0)


@pytest.fixture(scope="module")
def sphere3():
    return Mesh(*icosphere(10.0, 3))


def _errors(M, R):
    """Per channel (mean |e|, p99 |e|) over vertices above 1e-3 of the channel's peak."""
    out = []
    for c in range(3):
        m = R[:, c] > 1e-3 * R[:, c].max()
        e = np.abs(M[m, c] - R[m, c]) / R[m, c]
        out.append((e.mean(), np.percentile(e, 99)))
    return np.array(out)


#: Tolerances against the direct sum. The far field's arc distances follow the smooth sphere; the direct sum's
#: polyhedral geodesics undershoot it by O(h^2) (docs/physics.md §1.3: 0.26 % at 1.5 mm edges on a 10 mm sphere,
#: about 0.5 % at level 3's 1.9 mm), which alone makes the hierarchical result up to ~0.6 % lower at level 3 (the
#: signed mean error is checked to be that undershoot's sign); level 4 (slow) holds the issue's 0.5 % mean and
#: 2 % p99. Measured at level 3 (2026-11-23): mean <= 0.61 %, p99 <= 2.5 % (exact-sphere, marble, blue).
LEVEL_TOL = {3: (8e-3, 3e-2), 4: (5e-3, 2e-2)}


def _check_against_direct(mesh, material, model, level):
    ref = bake(mesh, material, [SUN], BakeOptions(model=model, surface=SurfaceOptions(transport="direct")))
    got = bake(mesh, material, [SUN], BakeOptions(model=model, surface=SurfaceOptions(transport="hierarchical")))
    assert got.stats["transport"] == "hierarchical" and ref.stats["transport"] == "direct"
    err = _errors(got.radiance, ref.radiance)
    mean_tol, p99_tol = LEVEL_TOL[level]
    assert np.all(err[:, 0] <= mean_tol) and np.all(err[:, 1] <= p99_tol), err
    lit = ref.radiance[:, 0] > 1e-3 * ref.radiance[:, 0].max()
    if model != "dipole":  # the chord dipole uses no geodesics
        assert np.mean(got.radiance[lit, 0] / ref.radiance[lit, 0] - 1) < 1e-3
    return got, ref


@pytest.mark.parametrize("model", ["dipole", "curved", "exact-sphere", "auto"])
@pytest.mark.parametrize("material", [SKIN, MARBLE], ids=["skin1", "marble"])
def test_hierarchical_matches_the_direct_sum_on_a_sphere(sphere3, model, material):
    got, ref = _check_against_direct(sphere3, material, model, 3)
    # energy: the exitant power of the two transports agrees as well
    np.testing.assert_allclose(got.stats["exitant_power"], ref.stats["exitant_power"], rtol=5e-3)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["dipole", "curved", "exact-sphere", "auto"])
def test_hierarchical_matches_the_direct_sum_on_a_finer_sphere(model):
    _check_against_direct(Mesh(*icosphere(10.0, 4)), SKIN, model, 4)


def test_auto_transport_uses_the_hierarchy_on_a_sphere_and_beams_stay_direct(sphere3):
    lights = [SUN, BeamLight((0.0, 0.0, 30.0), (0.0, 0.0, -1.0), 1.0)]
    ref = bake(sphere3, SKIN, lights, BakeOptions(model="auto", surface=SurfaceOptions(transport="direct")))
    got = bake(sphere3, SKIN, lights, BakeOptions(model="auto"))
    assert got.stats["transport"] == "hierarchical"
    assert got.beam_distance is not None and got.plan is not None and got.plan.kernel.shape == (len(got.samples),)
    np.testing.assert_array_equal(got.plan.kernel[got.samples.vertex < 0], ref.plan.kernel[ref.samples.vertex < 0])
    err = _errors(got.radiance, ref.radiance)
    assert np.all(err[:, 0] <= 5e-3) and np.all(err[:, 1] <= 2.5e-2), err


@pytest.mark.parametrize("model", ["dipole", "curved"])
def test_clusters_converge_to_their_leaves(model):
    """Clusters (four sigma points each) against the same far field summed pair by pair: the error falls
    faster than theta^2 (third order: the sigma points carry the first and second moments)."""
    mesh = Mesh(*icosphere(10.0, 4))
    core = SurfaceTransport.build(mesh, SKIN, model, theta=1e-9)
    samples = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [SUN], eta=SKIN.eta)
    pv = vertex_power(samples, mesh.n_vertices)
    leaves, stats = core.exitance(pv)
    assert stats["far_clusters"] == 0 or stats["far_clusters"] < 0.01 * stats["far_pairs"]
    err = {}
    for theta in (0.2, 0.4):
        core.theta = theta
        M, s = core.exitance(pv)
        assert s["far_clusters"] > 0
        err[theta] = np.mean(np.abs(M[:, 0] - leaves[:, 0]) / leaves[:, 0])
    assert err[0.2] <= 5e-4
    assert err[0.4] >= 4.0 * err[0.2]  # ratio 2^2 would be second order; measured ~8


def test_sigma_points_carry_the_cluster_moments(rng):
    k = 200
    pos = rng.normal(size=(k, 3)) * [3.0, 1.0, 0.05]
    nrm = np.tile([0.0, 0.0, 1.0], (k, 1))
    shape = np.tile([0.1, 0.05, 0.0, 0.0, 0.0, 0.0], (k, 1))
    power = rng.uniform(0.1, 1.0, k)
    depth = tree_depth(k, 16)
    lo, hi = node_ranges(k, depth)
    perm = kd_permutation(pos, depth, lo, hi)
    pos, power = np.ascontiguousarray(pos[perm]), np.ascontiguousarray(power[perm])
    P, sig, nsig, ssig, nmean, cone, Smean, rad, rn, srow = cluster_geometry(
        pos, nrm, shape, power, np.zeros(k), np.zeros(k), np.full(k, -1), np.zeros(k), lo, hi)
    for node in (0, 1, 5):
        a, b = lo[node], hi[node]
        w = power[a:b]
        c = (w[:, None] * pos[a:b]).sum(axis=0) / w.sum()
        np.testing.assert_allclose(P[node], w.sum(), rtol=1e-12)
        np.testing.assert_allclose(sig[node].mean(axis=0), c, atol=1e-12)
        Q = np.einsum("i,ij,ik->jk", w, pos[a:b] - c, pos[a:b] - c) / w.sum()
        lam, vec = np.linalg.eigh(Q)
        Q2 = (vec[:, 1:] * lam[1:]) @ vec[:, 1:].T  # the two largest axes
        Qs = np.einsum("qj,qk->jk", sig[node] - c, sig[node] - c) / 4.0
        np.testing.assert_allclose(Qs, Q2, atol=1e-10 * np.abs(Q).max())
        # the shape operator carried to each sigma point's normal keeps its trace and stays tangent to it
        np.testing.assert_allclose(ssig[node][:, :3].sum(axis=1), 0.15, rtol=1e-12)
        for q in range(4):
            np.testing.assert_allclose(_full(ssig[node][q]) @ nsig[node][q], 0.0, atol=1e-12)
        assert rad[node] >= np.linalg.norm(pos[a:b] - c, axis=1).max() - 1e-12


def _full(s6):
    xx, yy, zz, xy, xz, yz = s6
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def test_the_distance_check_refuses_a_thin_torus_and_auto_falls_back(caplog):
    mesh = Mesh(*torus(4.0, 2.5, 48, 24))
    with pytest.raises(FarFieldUnsupported, match="not accurate on this mesh"):
        SurfaceTransport.build(mesh, SKIN, "dipole")
    res = bake(mesh, SKIN, [SUN], BakeOptions(model="dipole"))
    assert res.stats["transport"].startswith("direct (hierarchical far field not accurate")
    with caplog.at_level(logging.WARNING, logger="meshshade"):
        forced = bake(mesh, SKIN, [SUN], BakeOptions(model="dipole", surface=SurfaceOptions(transport="hierarchical")))
    assert forced.stats["transport"] == "hierarchical" and "asked for" in caplog.text


def test_one_transport_serves_many_lights(sphere3):
    core = SurfaceTransport.build(sphere3, SKIN, "curved")
    other = DirectionalLight((-1.0, 0.2, 0.1), 0.5)
    both = bake(sphere3, SKIN, [SUN, other], BakeOptions(model="curved"), reuse=core)
    again = bake(sphere3, SKIN, [SUN, other], BakeOptions(
        model="curved", surface=SurfaceOptions(transport="hierarchical")))
    np.testing.assert_allclose(both.radiance, again.radiance, rtol=1e-12, atol=0)
    one = bake(sphere3, SKIN, [SUN], BakeOptions(model="curved"), reuse=core)
    two = bake(sphere3, SKIN, [other], BakeOptions(model="curved"), reuse=core)
    # M is linear in the sources; the clusters depend on the power distribution, so only to the cluster error
    err = _errors(one.radiance + two.radiance, both.radiance)
    assert np.all(err[:, 0] <= 2e-3), err
    with pytest.raises(ValueError, match="built for another"):
        bake(sphere3, MARBLE, [SUN], BakeOptions(model="curved"), reuse=core)


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(0.0, 1e6), min_size=1, max_size=8), st.integers(0, 2**31 - 1))
def test_exitance_is_finite_and_non_negative_for_any_powers(powers, seed):
    core = _core_for_property()
    rng = np.random.default_rng(seed)
    pv = np.zeros(core.mesh.n_vertices)
    pv[rng.choice(pv.size, len(powers), replace=False)] = powers
    M, _ = core.exitance(pv)
    assert np.all(np.isfinite(M)) and np.all(M >= 0)
    if pv.sum() == 0:
        assert not M.any()


_CORE = {}


def _core_for_property():
    if "c" not in _CORE:
        _CORE["c"] = SurfaceTransport.build(Mesh(*icosphere(10.0, 2)), SKIN, "auto")
    return _CORE["c"]


def test_cli_transport_option(tmp_path, capsys):
    V, F = icosphere(10.0, 3)
    mesh = tmp_path / "s.ply"
    write_ply(mesh, V, F)
    out = {}
    for t in ("direct", "hierarchical"):
        rc = main(["bake", str(mesh), "--material", "skin1", "--light", "directional:0,0,-1", "--model", "curved",
                   "--transport", t, "--out", str(tmp_path / f"{t}.ply"), "--npz", str(tmp_path / f"{t}.npz")])
        assert rc == 0
        out[t] = np.load(tmp_path / f"{t}.npz")["radiance"]
    capsys.readouterr()
    assert _errors(out["hierarchical"], out["direct"])[:, 0].max() <= LEVEL_TOL[3][0]
    rc = main(["bake", str(mesh), "--material", "skin1", "--light", "directional:0,0,-1", "--transport", "fast",
               "--out", str(tmp_path / "x.ply")])
    assert rc == 2 and "--transport" in capsys.readouterr().err
    # the volume model (the default) has its own transport: asking for a surface one is a clear error
    rc = main(["bake", str(mesh), "--material", "skin1", "--light", "directional:0,0,-1", "--transport", "direct",
               "--out", str(tmp_path / "x.ply")])
    err = capsys.readouterr().err
    assert rc == 2 and "surface models" in err and len(err.strip().splitlines()) == 1


def test_the_far_field_verification_sees_the_arc_errors_of_a_lit_configuration(sphere3):
    """verify_far_field (receiver side, actual powers) is small on a sphere (arcs exact) and large on the thin
    torus (arcs across the hole; conservative there: the dipole's far share is small at this resolution)."""
    res = bake(sphere3, SKIN, [SUN], BakeOptions(model="dipole", surface=SurfaceOptions(transport="auto")))
    assert res.stats["transport"] == "hierarchical"
    v = res.stats["far_field_verified"]
    assert v["receivers"] == 24 and v["mean"] < 2e-3
    mesh = Mesh(*torus(4.0, 2.5, 48, 24))
    core = SurfaceTransport.build(mesh, SKIN, "dipole", near_patch_radii=5.0)
    samples = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [SUN], eta=SKIN.eta)
    pv = vertex_power(samples, mesh.n_vertices)
    M, _ = core.exitance(pv)
    v = verify_far_field(core, M, pv)
    assert v["mean"] > 5 * VERIFY_TOL[0]
    assert bake(mesh, SKIN, [SUN], BakeOptions(model="dipole")).stats["transport"].startswith("direct (")


def test_far_field_does_not_depend_on_threads_or_blocks(sphere3, monkeypatch):
    """The far-field traversal is a serial loop run on blocks of receivers by the pacing threads: one thread with
    the default blocks and two threads with blocks of 64 receivers must give the same bits (each receiver is
    computed on its own; a scratch value carried from one receiver to the next within a block would differ)."""
    import numba

    from meshshade.surface import hierarchical

    core = SurfaceTransport.build(sphere3, SKIN, "curved")
    rng = np.random.default_rng(5)
    pv = rng.random(sphere3.n_vertices) * (rng.random(sphere3.n_vertices) < 0.3)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        M1, s1 = core.exitance(pv)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        monkeypatch.setattr(hierarchical, "RECEIVER_BLOCK", 64)
        M2, s2 = core.exitance(pv)
    finally:
        numba.set_num_threads(before)
    assert s1["far_pairs"] > 0 and s1["far_clusters"] > 0
    assert (s1["far_pairs"], s1["far_clusters"]) == (s2["far_pairs"], s2["far_clusters"])
    np.testing.assert_array_equal(M1, M2)
