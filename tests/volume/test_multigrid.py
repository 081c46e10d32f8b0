"""The channels' operators and their multigrid conjugate gradients (meshshade/volume/multigrid.py), against
scipy.

* solve_channels with the V-cycle matches scipy.sparse.linalg.spsolve of each channel's matrix K_c = D_c S +
  sigma_a,c diag(m) + B / (2 A_c) (built here from the assembly's CSR arrays) on a ball of radius 9 mm with skin1's
  constants at the transport's resolution, and its residual |b - K_c x| / |b| is within the requested tolerance
  for skin1 and for marble (a 12 mm ball, three multigrid levels); the iterations stay at most 30 (measured: 10
  and 11 at rtol 1e-6, 15 and 18 at 1e-10).
* The coarse levels: the prolongation reproduces linear functions and sums to one (partition of unity), the
  coarse P1 functions are fine ones (the interpolant of P v equals the coarse function v at random points of the
  fine lattice: the spaces are nested), the coarse matrices are P^T S P, P^T B P and P^T m to rounding.
"""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from meshshade.materials import Material
from meshshade.volume.cutfem import assemble
from meshshade.volume.lattice import build_lattice, coarser_lattice
from meshshade.volume.multigrid import ChannelOperator, Multigrid, prolongation, solve_channels
from meshshade.volume.resolution import volume_resolution

_spec = importlib.util.spec_from_file_location("_volume_reference", Path(__file__).with_name("_volume_reference.py"))
ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ref)


def _problem(name, R, h0):
    """(lattice, assembly, operator, multigrid, coef) of a ball of radius R (mm) of material ``name`` at the
    transport's resolution (``h0`` forced or None), level 0 within 6 mm of its top (an edge of light)."""
    mat = Material.preset(name)
    c = np.array([0.23, -0.11, 0.37])
    res = volume_resolution(mat, 4 * math.pi * R * R, np.full(3, 2 * R), h0=h0)
    top = c + [0.0, 0.0, R]
    lat = build_lattice(ref.ball_depth(c, R), c - R, c + R, res.grading,
                        refine=lambda x: np.linalg.norm(x - top, axis=1) < 6.0)
    asm = assemble(lat)
    m = mat.medium
    coef = np.stack([m.D, 1.0 / (2.0 * m.A), m.sigma_a], axis=1)
    op = ChannelOperator(asm, coef)
    return lat, asm, op, Multigrid(lat, op), coef


@pytest.fixture(scope="module")
def skin():
    return _problem("skin1", 9.0, None)


@pytest.fixture(scope="module")
def marble():
    return _problem("marble", 12.0, 0.7)


def matrices(asm, coef):
    S = sp.csr_matrix((asm.s_data, asm.indices, asm.indptr), shape=(asm.n, asm.n))
    B = sp.csr_matrix((asm.b_data, asm.indices, asm.indptr), shape=(asm.n, asm.n))
    return S, B, [(coef[k, 0] * S + coef[k, 1] * B + sp.diags(coef[k, 2] * asm.m)).tocsr() for k in range(3)]


def _loads(n, seed):
    rng = np.random.default_rng(seed)
    b = np.zeros((n, 3))
    idx = rng.choice(n, 60, replace=False)
    b[idx] = rng.random((60, 3))
    return b


def test_operator_applies_each_channels_matrix(skin):
    lat, asm, op, mg, coef = skin
    _, _, K = matrices(asm, coef)
    x = np.random.default_rng(1).standard_normal((asm.n, 3))
    y = op(x)
    for k in range(3):
        np.testing.assert_allclose(y[:, k], K[k] @ x[:, k], rtol=0, atol=1e-13 * np.abs(y[:, k]).max())
        np.testing.assert_allclose(op.diag[:, k], K[k].diagonal(), rtol=1e-14)


def test_solve_matches_a_direct_solve(skin):
    lat, asm, op, mg, coef = skin
    assert len(mg.sizes) >= 2
    _, _, K = matrices(asm, coef)
    b = _loads(asm.n, 2)
    x, its = solve_channels(op, mg, b, rtol=1e-10)
    assert np.all(its <= 30), its
    for k in range(3):
        xd = spla.spsolve(K[k].tocsc(), b[:, k])
        np.testing.assert_allclose(x[:, k], xd, rtol=0, atol=1e-8 * np.abs(xd).max())


@pytest.mark.parametrize("which", ["skin", "marble"])
def test_solve_reaches_the_requested_residual_in_few_iterations(skin, marble, which):
    lat, asm, op, mg, coef = skin if which == "skin" else marble
    if which == "marble":
        assert len(mg.sizes) >= 3, mg.sizes
    _, _, K = matrices(asm, coef)
    b = _loads(asm.n, 3)
    for rtol in (1e-6, 1e-10):
        x, its = solve_channels(op, mg, b, rtol=rtol)
        assert np.all(its >= 1) and np.all(its <= 30), (rtol, its)
        for k in range(3):
            assert np.linalg.norm(b[:, k] - K[k] @ x[:, k]) <= rtol * np.linalg.norm(b[:, k]), (rtol, k)


def test_zero_load_is_zero_and_a_channel_without_load_takes_no_iterations(skin):
    lat, asm, op, mg, coef = skin
    b = _loads(asm.n, 4)
    b[:, 1] = 0.0
    x, its = solve_channels(op, mg, b)
    assert its[1] == 0 and np.all(x[:, 1] == 0.0) and its[0] > 0


@pytest.mark.parametrize("which", ["skin", "marble"])
def test_coarse_levels_are_galerkin_products_of_nested_spaces(skin, marble, which, rng):
    lat, asm, op, mg, coef = skin if which == "skin" else marble
    # the first coarse level, rebuilt as the multigrid builds it
    clat = coarser_lattice(lat, None)
    P, cnodes = prolongation(lat.nodes[asm.free], clat)
    for _ in range(4):
        if P.shape[1] <= 0.5 * P.shape[0]:
            break
        clat = coarser_lattice(clat, None)
        P, cnodes = prolongation(lat.nodes[asm.free], clat)
    assert (P != mg.P[0]).nnz == 0 and P.shape == mg.P[0].shape
    # linear functions reproduced, rows summing to one
    g = np.array([0.4, -1.2, 0.7])
    np.testing.assert_allclose(P @ (clat.nodes[cnodes] @ g + 2.0), lat.nodes[asm.free] @ g + 2.0, rtol=0,
                               atol=1e-12 * np.abs(lat.nodes).max())
    np.testing.assert_allclose(np.asarray(P.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-14)
    # nested: the fine interpolant of P v is the coarse function v, at random points of the fine lattice
    v = rng.standard_normal(P.shape[1])
    fine_vals = asm.to_nodes((P @ v)[:, None])[:, 0]
    pts = lat.nodes[asm.free][rng.choice(asm.n, 300)] + rng.uniform(-0.5, 0.5, (300, 3)) * lat.grading.h0
    fc, fb, fn = lat.locate(pts)
    cc, cb, cn = clat.locate(pts)
    keep = (fc >= 0) & (cc >= 0)
    # the coarse nodes' values: v on cnodes, hanging coarse nodes the mean of their parents
    cv = np.zeros(clat.n_nodes)
    cv[cnodes] = v
    for _ in range(32):
        cv[clat.hanging] = 0.5 * (cv[clat.parents[:, 0]] + cv[clat.parents[:, 1]])
    on_fine = np.einsum("pk,pk->p", fb, fine_vals[fn])
    on_coarse = np.einsum("pk,pk->p", cb, cv[cn])
    # only points whose coarse tetrahedron's corners all carry unknowns (cnodes or hanging from them)
    known = np.zeros(clat.n_nodes, dtype=bool)
    known[cnodes] = True
    for _ in range(32):
        known[clat.hanging] = known[clat.parents[:, 0]] & known[clat.parents[:, 1]]
    keep &= np.all(known[cn] | (cb == 0.0), axis=1)
    # and whose fine tetrahedron's corners carry unknowns too (a node with no inside in its support has none)
    full = np.abs(asm.to_nodes(np.ones((asm.n, 1)))[:, 0] - 1.0) < 1e-12
    keep &= np.all(full[fn] | (fb == 0.0), axis=1)
    assert keep.sum() > 200
    np.testing.assert_allclose(on_fine[keep], on_coarse[keep], rtol=0, atol=1e-12 * np.abs(v).max())
    # the coarse level's matrices are P^T (.) P
    S, B, _ = matrices(asm, coef)
    coarse = mg.ops[1].asm
    Sc, Bc, _ = matrices(coarse, coef)
    for got, fine in ((Sc, S), (Bc, B)):
        want = (P.T @ fine @ P).tocsr()
        assert abs(got - want).max() <= 1e-13 * abs(want).max()
    np.testing.assert_allclose(coarse.m, P.T @ asm.m, rtol=1e-13, atol=1e-15 * asm.m.max())
