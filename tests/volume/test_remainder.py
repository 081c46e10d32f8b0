"""The volume's correction, eq. (103) (meshshade/volume/remainder.py).

* A flat surface under uniform light: the correction at every receiver is E T(theta_t), T the total of f of eq.
  (102) = W(theta_t) x the near-field model's total minus the Robin half-space's total of the smoothed line
  sources. The reference total is written here: the near-field model's total and W from the public kernels
  (meshshade.kernels.near_field), the Robin half-space's from its closed form for a point source at optical depth
  z (the one-dimensional Green's function with phi - 2 A D phi' = 0: exitance exp(-mu z) / (1 + 2 A D mu)), the
  line by numpy's 6-point Gauss-Laguerre rule, the sideways Gaussian's weight exp(-mu^2 s^2 / 2) (eq. (100)). Not
  the tables of the code under test.
* The approximations (Barnes-Hut beyond the near radius, the far part at one receiver per cube and interpolated)
  against the exact sum over every pair on a lit bumpy surface with a shadow edge.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from meshshade.kernels.beam_diffusion import dipole_variant
from meshshade.kernels.near_field import incidence_gain, near_field_total
from meshshade.materials import Material
from meshshade.volume.remainder import RemainderTables, remainder_exitance

SKIN = Material.preset("skin1")


def reference_total(material, c, spread_mm, cos_t):
    a, eta, g = float(material.albedo_prime[c]), float(material.eta), float(material.g)
    v = dipole_variant(a, eta, "better")
    A = v.z_b / (2.0 * v.D)
    s = spread_mm * float(material.sigma_t_prime[c])
    x, w = np.polynomial.laguerre.laggauss(6)
    long_total = math.exp(-0.5 * (v.mu * s) ** 2) * float(np.sum(a * w * np.exp(-v.mu * x * cos_t))) / (
        1.0 + 2.0 * A * v.D * v.mu)
    near = incidence_gain(albedo_prime=a, eta=eta, g=g, cos_t=cos_t) * near_field_total(albedo_prime=a, eta=eta, g=g)
    return near - long_total


def near_totals(material):
    return np.array([near_field_total(albedo_prime=float(material.albedo_prime[c]), eta=float(material.eta),
                                      g=float(material.g)) for c in range(3)])


def plane(spacing, half):
    u = np.arange(-half, half + 1e-9, spacing)
    X, Y = np.meshgrid(u, u)
    pos = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    return pos, np.tile([0.0, 0.0, 1.0], (pos.shape[0], 1))


@pytest.mark.parametrize("cos_t", [1.0, 0.8])
def test_uniform_light_on_a_plane_gives_the_total(cos_t):
    spread = 0.4
    tables = RemainderTables(SKIN, spread)
    h = 0.25
    pos, nrm = plane(h, 20.0)
    k = pos.shape[0]
    src = {"pos": pos, "normal": nrm, "power": np.full(k, h * h), "area": np.full(k, h * h),
           "cos_t": np.full(k, cos_t), "light": np.zeros(k, dtype=np.int64)}
    centre = np.flatnonzero(np.linalg.norm(pos, axis=1) < 3.0)
    rec = {"pos": pos[centre], "normal": nrm[centre], "radius": np.full(centre.size, h / math.sqrt(math.pi)),
           "E": np.ones((centre.size, 1)), "cos_t": np.full((centre.size, 1), cos_t)}
    M, pairs = remainder_exitance(tables, src, rec)
    expected = np.array([reference_total(SKIN, c, spread, cos_t) for c in range(3)])
    assert pairs > 0
    # T is a small difference of two totals near 0.1-0.45: held to 1.5e-3 of the near-field model's total
    err = np.abs(M - expected) / near_totals(SKIN)
    assert err.max() < 1.5e-3, err.max(axis=0)                      # measured 0.9e-3


def bumpy_lit_surface(rng):
    h = 0.3
    pos, _ = plane(h, 12.0)
    z = 1.5 * np.sin(pos[:, 0] / 3.0) * np.cos(pos[:, 1] / 4.0)
    pos[:, 2] = z
    gx = 0.5 * np.cos(pos[:, 0] / 3.0) * np.cos(pos[:, 1] / 4.0)
    gy = -0.375 * np.sin(pos[:, 0] / 3.0) * np.sin(pos[:, 1] / 4.0)
    nrm = np.stack([-gx, -gy, np.ones_like(gx)], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    E = np.where(pos[:, 0] < 2.0, 1.0, 0.0) * (1.0 + 0.3 * rng.random(pos.shape[0]))   # a shadow edge at x = 2
    cos_t = 0.75 + 0.25 * rng.random(pos.shape[0])
    k = pos.shape[0]
    src = {"pos": pos, "normal": nrm, "power": E * h * h, "area": np.full(k, h * h), "cos_t": cos_t,
           "light": np.zeros(k, dtype=np.int64)}
    rec = {"pos": pos, "normal": nrm, "radius": np.full(k, h / math.sqrt(math.pi)), "E": E[:, None],
           "cos_t": cos_t[:, None]}
    return src, rec


def test_far_approximations_against_every_pair():
    rng = np.random.default_rng(5)
    tables = RemainderTables(SKIN, 0.4)
    src, rec = bumpy_lit_surface(rng)
    exact, pairs_exact = remainder_exitance(tables, src, rec, theta=0.0)
    fast, pairs_fast = remainder_exitance(tables, src, rec)
    scale = rec["E"].max() * near_totals(SKIN)                      # the near-field model's exitance
    err = np.abs(fast - exact) / scale
    assert pairs_fast < 0.1 * pairs_exact                           # measured 8.7 %
    assert err.max() < 5e-3, err.max(axis=0)                        # measured 0.14 / 0.22 / 0.16 % (the shadow edge)
    assert err.mean() < 1.5e-3, err.mean(axis=0)                    # measured 0.05 / 0.08 / 0.05 %


def test_blended_tables_in_one_pass_are_each_tables_pass_interpolated():
    # a painted receiver between two tabulated albedos (eq. (108)): one pass evaluating both tables per pair must
    # give what one pass per table gives, interpolated at the receiver afterwards (the sums are linear in f)
    rng = np.random.default_rng(11)
    src, rec = bumpy_lit_surface(rng)
    tables = [RemainderTables(Material(a * SKIN.sigma_t_prime, (1 - a) * SKIN.sigma_t_prime, SKIN.eta), 0.4)
              for a in (np.array([0.99, 0.95, 0.9]), np.array([0.9, 0.6, 0.5]), np.array([0.5, 0.2, 0.1]))]
    n = rec["pos"].shape[0]
    node = rng.integers(0, 2, size=(n, 3))
    weight = rng.random((n, 3))
    weight[::7] = 0.0                                 # some receivers exactly on a table
    parts = [remainder_exitance(tb, src, rec)[0] for tb in tables]
    rows = np.arange(n)[:, None]
    chan = np.arange(3)[None, :]
    stack = np.stack(parts)                           # (3 tables, n, 3)
    expected = (1.0 - weight) * stack[node, rows, chan] + weight * stack[node + 1, rows, chan]
    got, pairs = remainder_exitance(tables, src, rec, blend=(node, weight))
    assert pairs > 0
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    # one table and no blend is the plain call, bit for bit
    one, _ = remainder_exitance([tables[1]], src, rec, blend=(np.zeros((n, 3), int), np.zeros((n, 3))))
    np.testing.assert_array_equal(one, parts[1])
    with pytest.raises(ValueError, match="blend"):
        remainder_exitance(tables, src, rec)


def test_tables_of_other_mean_free_paths_blend_at_their_corners():
    # a receiver between tabulated albedos and mean free paths (eq. (133)): four corners per channel, weights of
    # the receiver's, in one pass; against one pass per table combined at the receiver afterwards
    rng = np.random.default_rng(12)
    src, rec = bumpy_lit_surface(rng)
    corners = [(a, s) for a in (np.array([0.99, 0.95, 0.9]), np.array([0.8, 0.7, 0.6])) for s in (0.6, 1.0, 1.7)]
    tables = [RemainderTables(Material(a * s * SKIN.sigma_t_prime, (1 - a) * s * SKIN.sigma_t_prime, SKIN.eta), 0.4)
              for a, s in corners]
    assert len({tuple(tb.log_r0) for tb in tables}) == 3          # the tables' distances differ with sigma_t'
    n = rec["pos"].shape[0]
    node = rng.integers(0, len(tables), size=(n, 3, 4))
    weight = rng.random((n, 3, 4))
    weight /= weight.sum(axis=2, keepdims=True)
    weight[::5, :, 1:] = 0.0                           # some receivers on one table
    weight[::5, :, 0] = 1.0
    stack = np.stack([remainder_exitance(tb, src, rec)[0] for tb in tables])        # (tables, n, 3)
    expected = np.sum(weight * stack[node, np.arange(n)[:, None, None], np.arange(3)[None, :, None]], axis=2)
    got, pairs = remainder_exitance(tables, src, rec, blend=(node, weight))
    assert pairs > 0
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    # the two-node form is the corners' form with the node and the next
    node2, w2 = rng.integers(0, len(tables) - 1, size=(n, 3)), rng.random((n, 3))
    a, _ = remainder_exitance(tables, src, rec, blend=(node2, w2))
    b, _ = remainder_exitance(tables, src, rec, blend=(np.stack([node2, node2 + 1], 2), np.stack([1 - w2, w2], 2)))
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="blend"):
        remainder_exitance(tables, src, rec, blend=(node + 1, weight))        # a table index past the last


def test_entries_of_another_medium_weigh_their_power_by_their_own_kernel():
    # eq. (134): with the entries' media, a pair weighs the entry's power by f of the entry's medium and the
    # subtraction E A_j by the receiver's. Independently, from one-table sums (every pair one by one: theta 0):
    # sum_j (P_j - E A_j) f_A + E T_A over all entries, plus sum_j P_j (f_B - f_A) over the entries in medium B
    rng = np.random.default_rng(13)
    src, rec = bumpy_lit_surface(rng)
    tables = [RemainderTables(Material(a * SKIN.sigma_t_prime, (1 - a) * SKIN.sigma_t_prime, SKIN.eta), 0.4)
              for a in (np.array([0.99, 0.95, 0.9]), np.array([0.8, 0.7, 0.6]))]
    n, k = rec["pos"].shape[0], src["pos"].shape[0]
    in_b = src["pos"][:, 0] > 1.0
    rec_blend = (np.zeros((n, 3, 1), int), np.ones((n, 3, 1)))
    src_blend = (np.broadcast_to(in_b[:, None, None], (k, 3, 1)).astype(int), np.ones((k, 3, 1)))
    got, _ = remainder_exitance(tables, src, rec, theta=0.0, blend=rec_blend, src_blend=src_blend)
    dark = {key: (v[in_b] if isinstance(v, np.ndarray) and v.shape[:1] == (k,) else v) for key, v in src.items()}
    no_light = {**rec, "E": np.zeros_like(rec["E"])}
    expected = (remainder_exitance(tables[0], src, rec, theta=0.0)[0]
                + remainder_exitance(tables[1], dark, no_light, theta=0.0)[0]
                - remainder_exitance(tables[0], dark, no_light, theta=0.0)[0])
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
    assert np.abs(got - remainder_exitance(tables[0], src, rec, theta=0.0)[0]).max() > 1e-3 * np.abs(got).max()
    # entries all in the receivers' medium: the receivers' sum
    same, _ = remainder_exitance(tables, src, rec, blend=rec_blend, src_blend=(np.zeros((k, 3, 1), int),
                                                                               np.ones((k, 3, 1))))
    np.testing.assert_allclose(same, remainder_exitance(tables, src, rec, blend=rec_blend)[0], rtol=1e-12,
                               atol=1e-15)
