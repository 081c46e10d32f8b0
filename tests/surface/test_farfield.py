"""Clustered far-field dipole sum (meshshade/surface/farfield.py, surface/farfield_loops.py).

References: the dipole and its t-derivatives from an mpmath implementation of Jensen's formula
(docs/physics.md eq. (15))
differentiated by mpmath; the far-field sums from a brute-force numpy double loop over all pairs with
kernels/dipole.py:dipole_profile (tiny inputs) and from the cKDTree direct twin (larger inputs, itself checked
against the brute force). The error bound ``|M - M_exact| <= error_bound <= rel_tol * M_exact`` is the claim
under test; measured errors must stay under it for every receiver and channel.
"""
from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from meshshade.surface import farfield_loops as fk
from meshshade.errors import MeshshadeError
from meshshade.surface.farfield import SourceTree, far_field_exitance, far_field_exitance_pairwise, far_field_radius
from meshshade.geometry.procedural import box, icosphere
from meshshade.kernels.dipole import dipole_profile, dipole_tail_reflectance, dipole_total_reflectance
from meshshade.kernels.optics import diffusion_params
from meshshade.materials import Material
from meshshade.surface.gather import cutoff_radii

MATERIALS = ("skin1", "marble", "wholemilk")


def brute_force(src, power, recv, material, r_near, cutoff):
    """All pairs, numpy, with kernels/dipole.py (independent of the numba code)."""
    r = np.linalg.norm(recv[:, None, :] - src[None, :, :], axis=2)
    M = np.zeros((len(recv), 3))
    for c in range(3):
        ch = material.channel(c)
        st = ch["sigma_t_prime"]
        R = dipole_profile(r * st, albedo_prime=ch["albedo_prime"], eta=ch["eta"]) * st * st
        mask = (r > np.broadcast_to(r_near, 3)[c]) & (r <= np.broadcast_to(cutoff, 3)[c])
        M[:, c] = (R * mask) @ power[:, c]
    return M


def params(material, c):
    p = diffusion_params(material.albedo_prime[c], material.eta)
    return float(p.albedo_prime), float(p.mu), float(p.z_v)


def assert_within_bound(M, M_exact, stats, rel_tol):
    """|M - M_exact| <= error_bound <= rel_tol M_exact, with float64 rounding slack."""
    E = stats["error_bound"]
    slack = 1e-12 * M_exact + 1e-300
    assert np.all(np.abs(M - M_exact) <= E + slack), np.max((np.abs(M - M_exact) - E) / np.maximum(M_exact, 1e-300))
    assert np.all(E <= rel_tol * M_exact * (1 + 1e-9) + slack)


# ---------------------------------------------------------------------------------------------- derivatives
def _mp_G(t, al, mu, zv):
    """Jensen's dipole as a function of t = r^2/2, in mpmath (docs/physics.md eq. (15), optical units, z_r = 1)."""
    tot = 0
    for z in (mp.mpf(1), mp.mpf(zv)):
        d = mp.sqrt(2 * t + z * z)
        tot += z * (mu * d + 1) * mp.exp(-mu * d) / d**3
    return al / (4 * mp.pi) * tot


@pytest.mark.parametrize("name", MATERIALS)
def test_dipole_taylor_opt_matches_mpmath_derivatives(name):
    m = Material.preset(name)
    for c in range(3):
        al, mu, zv = params(m, c)
        for r in (0.0, 0.3, 2.0, 7.5, 40.0):
            G, G1, G2 = fk.dipole_taylor_opt(r, al, mu, zv)
            with mp.workdps(40):
                t = mp.mpf(r) ** 2 / 2
                ref = [float(mp.diff(lambda s: _mp_G(s, al, mu, zv), t, n)) for n in range(3)]
            np.testing.assert_allclose([G, G1, G2], ref, rtol=1e-12)
            ch = m.channel(c)
            np.testing.assert_allclose(fk.dipole_opt(r, al, mu, zv),
                                       dipole_profile(r, albedo_prime=ch["albedo_prime"], eta=ch["eta"]),
                                       rtol=1e-14)


@pytest.mark.parametrize("name", MATERIALS)
def test_third_derivative_bound_opt_dominates_and_decreases(name):
    """T(r) >= |G'''| r^3 + 3|G''| r (the bound on |D^3 f[u,u,u]|/|u|^3) at r, and T is non-increasing."""
    m = Material.preset(name)
    for c in range(3):
        al, mu, zv = params(m, c)
        grid = np.concatenate([[0.0], np.geomspace(1e-3, 200.0, 400)])
        T = np.array([fk.third_derivative_bound_opt(r, al, mu, zv) for r in grid])
        assert np.all(np.diff(T) <= 0)
        for r in (0.0, 0.5, 1.7, 6.0, 30.0):
            with mp.workdps(40):
                t = mp.mpf(r) ** 2 / 2
                g2 = mp.diff(lambda s: _mp_G(s, al, mu, zv), t, 2)
                g3 = mp.diff(lambda s: _mp_G(s, al, mu, zv), t, 3)
                need = float(abs(g3) * mp.mpf(r) ** 3 + 3 * abs(g2) * r)
            assert fk.third_derivative_bound_opt(r, al, mu, zv) >= need * (1 - 1e-12)


# ---------------------------------------------------------------------------------------------- tree
def test_source_tree_structure_and_moments(rng):
    k = 203
    pos = rng.normal(size=(k, 3)) * [5.0, 1.0, 0.2]
    pw = rng.uniform(0, 1, (k, 3))
    pw[:20, 1] = 0.0
    tree = SourceTree.build(pos, pw, leaf_size=4)
    assert np.array_equal(np.sort(tree.perm), np.arange(k))
    np.testing.assert_array_equal(tree.positions, pos[tree.perm])
    lo, hi = tree.node_lo, tree.node_hi
    assert np.all(hi[tree.first_leaf:] - lo[tree.first_leaf:] <= 4)
    for i in range(tree.first_leaf):
        left, right = 2 * i + 1, 2 * i + 2
        assert lo[left] == lo[i] and hi[right] == hi[i] and hi[left] == lo[right]
        L, R = tree.positions[lo[left]:hi[left]], tree.positions[lo[right]:hi[right]]
        assert any(L[:, ax].max() <= R[:, ax].min() for ax in range(3))  # a k-d split
    for i in range(len(lo)):
        y, w = tree.positions[lo[i]:hi[i]], tree.power[lo[i]:hi[i]]
        for c in range(3):
            P = w[:, c].sum()
            C = (w[:, c] @ y) / P
            d = y - C
            np.testing.assert_allclose(tree.node_power[i, c], P, rtol=1e-13)
            np.testing.assert_allclose(tree.node_centroid[i, c], C, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(tree.node_radius[i, c], np.linalg.norm(d, axis=1).max(), rtol=1e-12)
            Q = (w[:, c, None, None] * d[:, :, None] * d[:, None, :]).sum(0)
            np.testing.assert_allclose(tree.node_q[i, c], Q[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]],
                                       rtol=1e-10, atol=1e-12 * P)
            np.testing.assert_allclose(tree.node_m3[i, c], (w[:, c] @ np.linalg.norm(d, axis=1) ** 3) / P,
                                       rtol=1e-12)


# ---------------------------------------------------------------------------------------------- direct twin
@pytest.mark.parametrize("name", MATERIALS)
def test_far_field_exitance_pairwise_matches_brute_force(name, rng):
    m = Material.preset(name)
    src = rng.uniform(-8, 8, (300, 3))
    pw = rng.uniform(0, 2, (300, 3))
    recv = np.concatenate([rng.uniform(-8, 8, (100, 3)), src[:50]])
    r_near, cut = 0.6 / m.sigma_t_prime, np.array([9.0, 7.0, 5.0])
    M, stats = far_field_exitance_pairwise((src, pw), recv, m, r_near, cut)
    np.testing.assert_allclose(M, brute_force(src, pw, recv, m, r_near, cut), rtol=1e-12, atol=0)
    assert stats["pairs_exact"] > 0


# ---------------------------------------------------------------------------------------------- the bound
def test_cluster_expansion_error_is_third_order_and_bounded(rng):
    """One cluster (the tree's root is a leaf, always accepted): error ~ h^3 and below the stated bound."""
    m = Material.preset("marble")
    base = rng.normal(size=(40, 3))
    pw = rng.uniform(0.2, 1.0, (40, 3))
    recv = np.array([[14.0, 3.0, -2.0], [0.0, 0.0, 25.0]])
    errs, hs = [], np.array([2.0, 1.0, 0.5, 0.25])
    for h in hs:
        src = base * h
        M, stats = far_field_exitance(SourceTree.build(src, pw, leaf_size=64), recv, m, 0.0, 60.0, rel_tol=1e300)
        assert stats["pairs_exact"] == 0 and stats["clusters_accepted"] == 6
        ref = brute_force(src, pw, recv, m, 0.0, 60.0)
        assert np.all(np.abs(M - ref) <= stats["error_bound"] + 1e-13 * ref)
        errs.append(np.max(np.abs(M - ref) / ref))
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert slope >= 2.7, (slope, errs)


def _geometry(kind, rng):
    if kind == "sphere":  # cube-sphere, 1016 vertices, ~0.7 mm spacing
        V, _ = box(1.0, subdivisions=13)
        V = V / np.linalg.norm(V, axis=1, keepdims=True) * 6.0
    elif kind == "box":  # 1016 vertices
        V, _ = box((16.0, 11.0, 7.0), subdivisions=13)
    else:  # a random cloud (a volume, not a surface)
        V = rng.uniform(-7.0, 7.0, (1000, 3))
    return V


@pytest.mark.parametrize("kind", ["sphere", "box", "cloud"])
@pytest.mark.parametrize("name", MATERIALS)
def test_far_field_exitance_error_below_bound(kind, name, rng):
    """Across tolerances: |M - M_direct| <= error_bound <= rel_tol M_direct for every receiver and channel;
    clusters are really used (the test would catch an always-exact traversal) and the work drops."""
    m = Material.preset(name)
    V = _geometry(kind, rng)
    pw = rng.uniform(0.0, 1.0, (len(V), 3)) * (V[:, 2:3] > -3.0)  # a dark region sees only the far field
    recv = np.concatenate([V, rng.uniform(-8, 8, (100, 3))])
    r_near = 3.0 / m.sigma_t_prime
    cut = cutoff_radii(m, 1e-4)
    tree = SourceTree.build(V, pw, leaf_size=4)  # small leaves: many clusters at this size, a harder test
    M_d, sd = far_field_exitance_pairwise((V, pw), recv, m, r_near, cut)
    assert np.mean(M_d > 0) > 0.5
    for tol in (1e-3, 1e-2, 1e-1):
        M, stats = far_field_exitance(tree, recv, m, r_near, cut, rel_tol=tol)
        assert_within_bound(M, M_d, stats, tol)
        if tol >= 1e-2:
            assert stats["clusters_accepted"] > 0
    assert stats["pairs_exact"] + stats["clusters_accepted"] < sd["pairs_exact"]
    assert np.max(np.abs(M - M_d)) > 0  # clustering happened and changed the result


@pytest.mark.parametrize("name", MATERIALS)
def test_far_field_exitance_budget_and_cutoff_straddling_within_bound(name, rng):
    """The global budget (running lower bound of M) accepts clusters, including clusters that straddle the
    cutoff (their sources beyond it are excluded by the direct sum's mask): the bound still holds."""
    m = Material.preset(name)
    V, _ = box(1.0, subdivisions=16)
    V = V / np.linalg.norm(V, axis=1, keepdims=True) * 10.0
    pw = rng.uniform(0.5, 1.0, (len(V), 3)) * (V[:, 2:3] > 0)
    r_near, cut = 2.0 / m.sigma_t_prime, np.array([9.0, 6.0, 4.0])
    M_d, _ = far_field_exitance_pairwise((V, pw), V, m, r_near, cut)
    tree = SourceTree.build(V, pw, leaf_size=4)
    M, stats = far_field_exitance(tree, V, m, r_near, cut, rel_tol=0.1, budget_share=0.5)
    assert stats["clusters_from_budget"] > 0
    assert_within_bound(M, M_d, stats, 0.1)
    M0, stats0 = far_field_exitance(tree, V, m, r_near, cut, rel_tol=0.1, budget_share=0.0)
    assert stats0["clusters_from_budget"] == 0
    assert_within_bound(M0, M_d, stats0, 0.1)


def test_far_field_exitance_rel_tol_zero_is_exact(rng):
    m = Material.preset("wholemilk")
    V, _ = icosphere(10.0, subdivisions=3)
    pw = rng.uniform(0, 1, (len(V), 3))
    M, stats = far_field_exitance((V, pw), V, m, 1.0, [30.0, 20.0, 10.0], rel_tol=0.0)
    np.testing.assert_allclose(M, brute_force(V, pw, V, m, 1.0, np.array([30.0, 20.0, 10.0])), rtol=1e-12)
    assert stats["clusters_accepted"] == 0


# ---------------------------------------------------------------------------------------------- degenerate
def test_far_field_exitance_coincident_sources_are_exact(rng):
    m = Material.preset("marble")
    src = np.tile([[1.0, 2.0, 3.0]], (50, 1))
    pw = rng.uniform(0, 1, (50, 3))
    recv = rng.uniform(-20, 20, (300, 3))
    M, stats = far_field_exitance((src, pw), recv, m, 0.5, 40.0, rel_tol=1e-3)
    np.testing.assert_allclose(M, brute_force(src, pw, recv, m, 0.5, 40.0), rtol=1e-12)
    # the centroid of coincident points differs from them by rounding only: a bound at the 1e-40 level
    assert stats["clusters_accepted"] > 0 and np.all(stats["error_bound"] <= 1e-12 * M)


def test_far_field_exitance_single_source_and_receivers_on_sources(rng):
    m = Material.preset("skin1")
    src, pw = np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 2.0, 3.0]])
    recv = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 100.0, 0.0]])
    M, _ = far_field_exitance((src, pw), recv, m, 1.0, 28.0)
    np.testing.assert_allclose(M, brute_force(src, pw, recv, m, 1.0, 28.0), rtol=1e-14)
    assert np.all(M[0] == 0) and np.all(M[2] == 0) and np.all(M[1] > 0)  # r = 0 <= r_near; beyond the cutoff
    # receivers exactly on sources and at a symmetric cluster's centroid, with r_near = 0
    V = rng.normal(size=(500, 3)) * 4.0
    V = np.concatenate([V, -V])
    pw = np.ones((1000, 3))
    recv = np.concatenate([V[:100], [[0.0, 0.0, 0.0]]])
    M, stats = far_field_exitance((V, pw), recv, m, 0.0, 30.0, rel_tol=1e-2)
    assert_within_bound(M, brute_force(V, pw, recv, m, 0.0, 30.0), stats, 1e-2)


def test_far_field_exitance_zero_power_and_empty_inputs(rng):
    m = Material.preset("marble")
    V = rng.uniform(-5, 5, (400, 3))
    M, stats = far_field_exitance((V, np.zeros((400, 3))), V, m, 0.5, 20.0)
    assert np.all(M == 0) and stats["pairs_exact"] == 0 and stats["clusters_accepted"] == 0
    pw = rng.uniform(0, 1, (400, 3))
    pw[:, 1] = 0.0
    M, stats = far_field_exitance((V, pw), V, m, 0.5, 20.0, rel_tol=1e-2)
    assert np.all(M[:, 1] == 0) and np.all(M[:, [0, 2]] > 0)
    assert_within_bound(M, brute_force(V, pw, V, m, 0.5, 20.0), stats, 1e-2)
    M, _ = far_field_exitance((np.zeros((0, 3)), np.zeros((0, 3))), V, m, 0.5, 20.0)
    assert M.shape == (400, 3) and np.all(M == 0)
    M, _ = far_field_exitance((V, pw), np.zeros((0, 3)), m, 0.5, 20.0)
    assert M.shape == (0, 3)
    M, _ = far_field_exitance((V, pw), V, m, 20.0, 20.0)  # empty annulus
    assert np.all(M == 0)


def test_far_field_exitance_translation_and_rotation(rng):
    m = Material.preset("wholemilk")
    V, _ = icosphere(8.0, subdivisions=3)
    pw = rng.uniform(0, 1, (len(V), 3))
    ref = brute_force(V, pw, V, m, 1.0, 20.0)
    Qm, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    W = V @ Qm.T + [1e4, -2e4, 5e3]  # far from the origin: moments must stay accurate
    M, stats = far_field_exitance(SourceTree.build(W, pw, leaf_size=4), W, m, 1.0, 20.0, rel_tol=0.1)
    assert stats["clusters_accepted"] > 0
    E = stats["error_bound"]
    assert np.all(np.abs(M - ref) <= E + 1e-9 * ref)  # translation by 2e4 mm costs ~1e-12 relative in r


def test_far_field_exitance_bad_input():
    m = Material.preset("marble")
    V = np.zeros((3, 3))
    ok = np.ones((3, 3))
    for args, kw in [((V, -ok), {}), ((V[:, :2], ok), {}), ((V, ok[:2]), {}),
                     ((np.full((3, 3), np.nan), ok), {})]:
        with pytest.raises(MeshshadeError):
            far_field_exitance(args, V, m, 1.0, 10.0, **kw)
    with pytest.raises(MeshshadeError):
        far_field_exitance((V, ok), V, m, -1.0, 10.0)
    with pytest.raises(MeshshadeError):
        far_field_exitance((V, ok), V, m, 1.0, 0.0)
    with pytest.raises(MeshshadeError):
        far_field_exitance((V, ok), V, m, 1.0, 10.0, rel_tol=-0.1)
    with pytest.raises(MeshshadeError):
        far_field_exitance((V, ok), V, m, 1.0, 10.0, budget_share=1.0)
    with pytest.raises(MeshshadeError):
        far_field_exitance_pairwise("nonsense", V, m, 1.0, 10.0)
    with pytest.raises(MeshshadeError):
        far_field_radius(m, 1.5)


@pytest.mark.parametrize("name", MATERIALS)
def test_far_field_radius_tail_fraction(name):
    m = Material.preset(name)
    r = far_field_radius(m, 0.05)
    for c in range(3):
        ch = m.channel(c)
        kw = {"albedo_prime": ch["albedo_prime"], "eta": ch["eta"]}
        frac = dipole_tail_reflectance(r[c] * ch["sigma_t_prime"], **kw) / dipole_total_reflectance(**kw)
        np.testing.assert_allclose(frac, 0.05, rtol=1e-9)


# ---------------------------------------------------------------------------------------------- scaling
@pytest.mark.slow
def test_far_field_work_per_receiver_grows_slowly():
    """Cube-sphere of 50 mm, marble, r_near = 3 transport lengths: 4x the vertices (4x the direct neighbourhood)
    must cost well under 2x the work per receiver; the error bound holds at 10k against the direct sum."""
    m = Material.preset("marble")
    cut = cutoff_radii(m, 1e-4)
    work = []
    for s in (41, 82):  # 10088 and 40346 vertices
        V, _ = box(1.0, subdivisions=s)
        V = V / np.linalg.norm(V, axis=1, keepdims=True) * 25.0
        pw = np.repeat(np.clip(V[:, 2:3], 0, None), 3, axis=1) / 25.0 * (np.pi * 50.0**2 / len(V))
        M, stats = far_field_exitance((V, pw), V, m, 3.0 / m.sigma_t_prime, cut, rel_tol=0.1)
        work.append((stats["pairs_exact"] + stats["clusters_accepted"]) / len(V))
        if s == 41:
            M_d, _ = far_field_exitance_pairwise((V, pw), V, m, 3.0 / m.sigma_t_prime, cut)
            assert_within_bound(M, M_d, stats, 0.1)
    assert work[1] < 2.0 * work[0], work
