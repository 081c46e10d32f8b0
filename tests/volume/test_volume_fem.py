"""The volume diffusion solve (docs/physics.md §15): element identities, and convergence at second order to two
exact solutions of the same boundary-value problem, computed by independent routes:

* the half-space with the extrapolated (Robin) boundary, a point source at depth z': its exitance is the Hankel
  integral of eq. (93), evaluated here by scipy quadrature and checked against mpmath, and its total is the closed
  form exp(-sigma_tr z') / (1 + 2 A D sigma_tr);
* the ball with the same boundary, a point source on its axis: the Legendre series of eq. (94) with modified
  spherical Bessel functions evaluated in mpmath (30 digits).

Meshes are refined by halving every cell (nested), the source sits at the same point at every level, and the
order is measured from the mean relative error of the exitance at the boundary nodes; P1 gives 2 for the fluence.
"""
from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from scipy import integrate, special

from meshshade.volume import (DiffusionOperator, assemble_diffusion, boundary_faces, locate_points,
                              point_source_vector, tet_geometry)
from meshshade.volume.tetmesh import ball_tetrahedra, box_tetrahedra, graded_axis

SIGMA_S_PRIME, SIGMA_A, A = 1.0, 0.05, 2.5          # 1/mm, 1/mm; A of eta ~ 1.3 (any A >= 1 serves the check)
D = 1.0 / (3.0 * (SIGMA_S_PRIME + SIGMA_A))
SIGMA_TR = math.sqrt(SIGMA_A / D)


# ------------------------------------------------------------------------------------------------ identities
def _box(m=1):
    ax = graded_axis(-3.0, 3.0, 0.4, 0.5, 1.4)
    az = graded_axis(-2.0, 0.0, 0.0, 0.3, 1.4)
    return box_tetrahedra(ax, ax[::-1] * -1.0, az)


def test_element_identities():
    nodes, tets = _box()
    vol, grad = tet_geometry(nodes, tets)
    np.testing.assert_allclose(vol.sum(), 6.0 * 6.0 * 2.0, rtol=1e-12)
    np.testing.assert_allclose(grad.sum(axis=1), 0.0, atol=1e-12)          # the basis sums to one
    faces = boundary_faces(tets, nodes)
    a, b, c = nodes[faces[:, 0]], nodes[faces[:, 1]], nodes[faces[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    np.testing.assert_allclose(area.sum(), 2 * (36.0 + 2 * 6.0 * 2.0), rtol=1e-12)
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3.0 - np.array([0.0, 0.0, -1.0]))
    assert np.all(outward > 0)
    K = assemble_diffusion(nodes, tets, faces, D=D, sigma_a=SIGMA_A, A=A)
    assert abs(K - K.T).max() < 1e-14 * abs(K).max()
    # 1^T K 1 = sigma_a |Omega| + |dOmega| / (2A): the stiffness annihilates constants
    np.testing.assert_allclose(K.sum(), SIGMA_A * 72.0 + area.sum() / (2 * A), rtol=1e-12)
    # patch test: with sigma_a = 0 a linear fluence is in the kernel of every interior row
    K0 = assemble_diffusion(nodes, tets, faces, D=D, sigma_a=0.0, A=A)
    interior = np.setdiff1d(np.arange(nodes.shape[0]), faces.ravel())
    lin = 0.3 * nodes[:, 0] - 1.7 * nodes[:, 1] + 0.5 * nodes[:, 2] + 2.0
    assert np.abs((K0 @ lin)[interior]).max() < 1e-12


def test_locate_points_reproduces_points():
    nodes, tets = _box()
    rng = np.random.default_rng(4)
    pts = rng.uniform([-2.9, -2.9, -1.9], [2.9, 2.9, -0.05], size=(500, 3))
    tet, bary = locate_points(nodes, tets, pts)
    assert np.all(bary >= 0) and np.allclose(bary.sum(axis=1), 1.0)
    np.testing.assert_allclose(np.einsum("ij,ijk->ik", bary, nodes[tets[tet]]), pts, atol=1e-12)
    q = point_source_vector(nodes.shape[0], tets, tet, bary, np.full(500, 2.0))
    np.testing.assert_allclose(q.sum(), 1000.0, rtol=1e-12)


# ------------------------------------------------------------------------------------------------ half-space
def robin_half_space_exitance(rho, depth):
    """Eq. (93): M(rho) = 1/(2 pi) int_0^inf k J0(k rho) exp(-mu depth) / (1 + 2 A D mu) dk,
    mu = sqrt(k^2 + sigma_a / D), for a unit point source at ``depth`` (scipy quadrature)."""
    def f(k):
        mu = math.sqrt(k * k + SIGMA_A / D)
        return k * special.j0(k * rho) * math.exp(-mu * depth) / (1.0 + 2.0 * A * D * mu)
    val, _ = integrate.quad(f, 0.0, 60.0 / depth, limit=4000, epsabs=1e-15, epsrel=1e-12)
    return val / (2.0 * math.pi)


def test_half_space_reference_against_mpmath():
    depth = 1.0 / (SIGMA_S_PRIME + SIGMA_A)
    mp.mp.dps = 25
    for rho in (1.0, 4.0):
        f = lambda k: k * mp.besselj(0, k * rho) * mp.exp(-mp.sqrt(k * k + SIGMA_A / D) * depth) / (  # noqa: E731
            1 + 2 * A * D * mp.sqrt(k * k + SIGMA_A / D))
        ref = mp.quad(f, mp.linspace(0, 80, 81) + [mp.inf]) / (2 * mp.pi)
        assert robin_half_space_exitance(rho, depth) == pytest.approx(float(ref), rel=1e-9)


def _refine(axis, m):
    return np.concatenate([np.linspace(axis[i], axis[i + 1], m + 1)[:-1] for i in range(axis.size - 1)]
                          + [axis[-1:]])


def test_slab_converges_to_the_robin_half_space_at_second_order():
    """A 32 x 32 x 16 mm block (sigma_tr = 0.40 /mm: its sides and bottom are 6 diffusion lengths away), graded
    towards the source at depth 1/sigma_t' below the centre of the top, refined x1, x2, x3: the exitance on the top
    from 1 to 8 mm converges at order ~2 and the total through the top to the closed form."""
    depth = 1.0 / (SIGMA_S_PRIME + SIGMA_A)
    ax = graded_axis(-16.0, 16.0, 0.0, 0.8, 1.35)
    az = graded_axis(-16.0, 0.0, 0.0, 0.4, 1.35)
    errors, totals, hs = [], [], []
    for m in (1, 2, 3):
        nodes, tets = box_tetrahedra(_refine(ax, m), _refine(ax, m), _refine(az, m))
        op = DiffusionOperator(nodes, tets, D=D, sigma_a=SIGMA_A, A=A)
        tet, bary = locate_points(nodes, tets, [[0.0, 0.0, -depth]])
        M = op.solve(point_source_vector(nodes.shape[0], tets, tet, bary, [1.0])) / (2.0 * A)
        line = np.isclose(nodes[:, 2], 0.0) & np.isclose(nodes[:, 1], 0.0) & (nodes[:, 0] >= 1.0) & \
            (nodes[:, 0] <= 8.0)
        ref = np.array([robin_half_space_exitance(x, depth) for x in nodes[line, 0]])
        errors.append(np.mean(np.abs(M[line] / ref - 1.0)))
        f = op.faces[np.all(np.isclose(nodes[op.faces][:, :, 2], 0.0), axis=1)]
        a, b, c = nodes[f[:, 0]], nodes[f[:, 1]], nodes[f[:, 2]]
        totals.append(np.sum(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1) * M[f].mean(axis=1)))
        hs.append(1.0 / m)
    order = [math.log(errors[i] / errors[i + 1]) / math.log(hs[i] / hs[i + 1]) for i in range(2)]
    assert min(order) > 1.7, (errors, order)
    assert errors[-1] < 0.02, errors
    total = math.exp(-SIGMA_TR * depth) / (1.0 + 2.0 * A * D * SIGMA_TR)
    assert abs(totals[-1] / total - 1.0) < 1e-3, (totals, total)
    assert abs(totals[-1] / total - 1.0) < abs(totals[0] / total - 1.0)


# ------------------------------------------------------------------------------------------------ ball
def robin_ball_exitance(gamma, radius, r_source, terms=220):
    """Eq. (94): exitance at polar angle ``gamma`` (array) on the ball of ``radius`` with the Robin boundary, for a
    unit point source on the axis at ``r_source``; modified spherical Bessel functions in mpmath (30 digits).

    phi(R, gamma) = kappa beta / (4 pi D x^2) sum_l (2l + 1) P_l(cos gamma) i_l(kappa r') / (i_l(x) + beta i_l'(x)),
    x = kappa R, beta = 2 A D kappa, i_l' = i_{l+1} + (l / x) i_l; M = phi / (2A).
    """
    mp.mp.dps = 30
    kappa = mp.sqrt(mp.mpf(SIGMA_A) / D)
    x, beta, y = kappa * radius, 2 * A * D * kappa, kappa * r_source

    def i_l(l, z):
        return mp.sqrt(mp.pi / (2 * z)) * mp.besseli(l + mp.mpf(1) / 2, z)

    coef = np.array([float((2 * l + 1) * i_l(l, y) / (i_l(l, x) + beta * (i_l(l + 1, x) + l / x * i_l(l, x))))
                     for l in range(terms)])
    assert abs(coef[-1]) < 1e-14 * abs(coef[0])          # the series has converged
    c = np.cos(np.asarray(gamma, dtype=np.float64))
    p_prev, p = np.ones_like(c), c
    total = coef[0] * p_prev + coef[1] * p
    for l in range(1, terms - 1):
        p_prev, p = p, ((2 * l + 1) * c * p - l * p_prev) / (l + 1)
        total = total + coef[l + 1] * p
    return float(kappa * beta / (4 * mp.pi * D * x * x)) * total / (2.0 * A)


def test_ball_converges_to_the_robin_sphere_series_at_second_order():
    """A 5 mm ball (cube mapped onto it, 10, 20 and 40 cells per axis), source 1 mm below the top on the axis (a
    node at every level): the exitance at the boundary nodes between 0.2 and 1.6 rad from the source converges at
    order ~2 to the series."""
    radius, depth = 5.0, 1.0
    errors = []
    for n in (10, 20, 40):
        nodes, tets = ball_tetrahedra(radius, n)
        op = DiffusionOperator(nodes, tets, D=D, sigma_a=SIGMA_A, A=A)
        tet, bary = locate_points(nodes, tets, [[0.0, 0.0, radius - depth]])
        M = op.solve(point_source_vector(nodes.shape[0], tets, tet, bary, [1.0])) / (2.0 * A)
        r = np.linalg.norm(nodes, axis=1)
        on = np.isclose(r, radius)
        gamma = np.arccos(np.clip(nodes[on, 2] / radius, -1.0, 1.0))
        keep = (gamma > 0.2) & (gamma < 1.6)
        ref = robin_ball_exitance(gamma[keep], radius, radius - depth)
        errors.append(np.mean(np.abs(M[on][keep] / ref - 1.0)))
    order = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert min(order) > 1.8, (errors, order)
    assert errors[-1] < 0.006, errors


def test_walk_locates_as_the_candidate_search():
    """The compiled neighbour walk against the candidate search (its oracle) on a graded box and on the mesh of a
    surface: for points inside, the same point rebuilt from either answer and the same tetrahedron except for
    points on a shared face; points outside clamped onto the mesh (barycentrics >= 0, the point moved no farther
    than its distance to the mesh plus the size of the tetrahedron it lands in)."""
    import igl

    from meshshade.geometry.procedural import icosphere
    from meshshade.volume import surface_tetrahedra
    rng = np.random.default_rng(7)
    nodes, tets = _box()
    V, F = icosphere(5.0, 3)
    tm = surface_tetrahedra(V, F)
    box_pts = rng.uniform([-3.2, -3.2, -2.1], [3.2, 3.2, 0.1], size=(3000, 3))
    ball_pts = rng.uniform(-5.2, 5.2, size=(3000, 3))
    cases = [(nodes, tets, box_pts, np.all((np.abs(box_pts[:, :2]) < 3.0), axis=1) & (box_pts[:, 2] > -2.0)
              & (box_pts[:, 2] < 0.0)),
             (tm.nodes, tm.tets, ball_pts, igl.fast_winding_number(V, F, ball_pts) > 0.5)]
    for nd, tt, pts, inside in cases:
        assert 0.05 < np.mean(~inside) < 0.95
        t1, b1 = locate_points(nd, tt, pts)
        t2, b2 = locate_points(nd, tt, pts, walk=False)
        assert np.all(b1 >= 0) and np.allclose(b1.sum(axis=1), 1.0)
        p1 = np.einsum("ij,ijk->ik", b1, nd[tt[t1]])
        p2 = np.einsum("ij,ijk->ik", b2, nd[tt[t2]])
        np.testing.assert_allclose(p1[inside], pts[inside], atol=1e-9)
        np.testing.assert_allclose(p2[inside], pts[inside], atol=1e-9)
        on_face = np.min(b2, axis=1) < 1e-9
        assert np.all((t1 == t2)[inside] | on_face[inside])
        size = np.linalg.norm(np.ptp(nd[tt[t1]], axis=1), axis=1)
        away = np.sqrt(igl.point_mesh_squared_distance(pts, nd, boundary_faces(tt, nd))[0])
        assert np.all(np.linalg.norm(p1 - pts, axis=1)[~inside] <= (away + size)[~inside])


def test_the_walk_itself_finds_the_inside_points():
    """The walk, without the search behind it, settles every point inside the box, at the right place."""
    from scipy.spatial import cKDTree

    from meshshade.volume.locate import tet_neighbours, walk_locate
    nodes, tets = _box()
    pts = np.random.default_rng(8).uniform([-2.9, -2.9, -1.9], [2.9, 2.9, -0.05], size=(3000, 3))
    start = cKDTree(nodes[tets].mean(axis=1)).query(pts, k=1)[1].astype(np.int64)
    tet, bary = np.zeros(3000, dtype=np.int64), np.zeros((3000, 4))
    status = walk_locate(nodes, tets, tet_neighbours(tets), pts, start, tet, bary)
    assert np.all(status == 1)
    np.testing.assert_allclose(np.einsum("ij,ijk->ik", bary, nodes[tets[tet]]), pts, atol=1e-12)
    assert np.all(bary >= -1e-12)


@pytest.mark.parametrize("lumped", [False, True])
def test_compiled_assembly_matches_the_element_sum(lumped):
    """The compiled assembly (pattern from the edges, elements added in place) against the matrix summed from
    the vectorised element geometry (:func:`tet_geometry`) in a COO build: the textbook P1 matrices, stiffness
    vol grad_i . grad_j, mass vol (1 + delta_ij) / 20 (lumped vol / 4), boundary area (1 + delta_ij) / 12 (lumped
    area / 3). A node of no tetrahedron gets 1 on its diagonal."""
    import scipy.sparse as sp

    nodes, tets = _box()
    nodes = np.concatenate([nodes, [[10.0, 10.0, 10.0]]])           # an isolated node
    faces = boundary_faces(tets, nodes)
    vol, grad = tet_geometry(nodes, tets)
    N = nodes.shape[0]
    Se = vol[:, None, None] * np.einsum("tik,tjk->tij", grad, grad)
    Me = (vol / 20.0)[:, None, None] * (5.0 * np.eye(4) if lumped else np.ones((4, 4)) + np.eye(4))
    a, b, c = nodes[faces[:, 0]], nodes[faces[:, 1]], nodes[faces[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    Be = (area / 12.0)[:, None, None] * (4.0 * np.eye(3) if lumped else np.ones((3, 3)) + np.eye(3))

    def coo(E, idx):
        k = idx.shape[1]
        return sp.coo_matrix((E.reshape(-1), (np.repeat(idx, k, axis=1).reshape(-1), np.tile(idx, (1, k)).reshape(-1))),
                             shape=(N, N)).tocsr()
    ref = D * coo(Se, tets) + SIGMA_A * coo(Me, tets) + coo(Be, faces) / (2 * A)
    ref = ref + sp.diags(np.r_[np.zeros(N - 1), 1.0])
    K = assemble_diffusion(nodes, tets, faces, D=D, sigma_a=SIGMA_A, A=A, lumped=lumped)
    assert abs(K - ref).max() < 1e-13 * abs(ref).max()
    assert K[N - 1, N - 1] == 1.0 and K[N - 1].nnz == 1
