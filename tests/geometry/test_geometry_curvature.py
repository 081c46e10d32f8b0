"""libigl curvature adapter: closed forms on procedural shapes, conventions, robustness, convergence."""
from __future__ import annotations

import warnings

import igl
import numpy as np
import pytest

from meshshade.geometry import procedural
from meshshade.geometry.curvature import PrincipalCurvatures, principal_curvatures
from meshshade.geometry.mesh import MeshDefectWarning
from meshshade.io import load_mesh


def _check_frames(c: PrincipalCurvatures, mask=slice(None)):
    d1, d2, n = c.d1[mask], c.d2[mask], c.normals[mask]
    np.testing.assert_allclose(np.linalg.norm(d1, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d2, axis=1), 1.0, atol=1e-12)
    assert np.abs(np.einsum("ij,ij->i", d1, d2)).max() < 1e-12
    assert np.abs(np.einsum("ij,ij->i", d1, n)).max() < 1e-12
    np.testing.assert_allclose(np.einsum("ij,ij->i", np.cross(d1, d2), n), 1.0, atol=1e-12)


def test_principal_curvatures_sphere_positive_and_umbilic():
    V, F = procedural.icosphere(10.0, 4)
    c = principal_curvatures(V, F)
    k1, k2, d1, d2 = c  # unpacks like a tuple
    assert np.all(k1 >= k2)
    np.testing.assert_allclose(k1, 0.1, rtol=0.01)
    np.testing.assert_allclose(k2, 0.1, rtol=0.01)
    assert c.n_fallback == 0 and c.n_unreferenced == 0
    _check_frames(c)
    # normals are outward on an outward sphere
    assert np.all(np.einsum("ij,ij->i", c.normals, V) > 0)


def test_principal_curvatures_sign_flips_with_orientation():
    V, F = procedural.icosphere(10.0, 3)
    k1, k2, _, _ = principal_curvatures(V, F[:, ::-1])
    assert np.all(k1 >= k2)
    np.testing.assert_allclose(k2, -0.1, rtol=0.03)


def test_principal_curvatures_cylinder_far_from_caps():
    R = 5.0
    V, F = procedural.capped_cylinder(R, 60.0, 64, 96)
    c = principal_curvatures(V, F)
    side = (np.abs(V[:, 2]) < 15.0) & (np.hypot(V[:, 0], V[:, 1]) > R * 0.999)
    assert side.sum() > 1000
    np.testing.assert_allclose(c.k1[side], 1 / R, rtol=0.012)
    assert np.abs(c.k2[side]).max() < 0.005 / R
    assert np.abs(c.d2[side, 2]).min() > 1 - 1e-9  # d2 along the axis
    _check_frames(c, side)


@pytest.mark.parametrize("where, k1_exact, k2_exact", [("outer", 1 / 5.0, 1 / 25.0), ("inner", 1 / 5.0, -1 / 15.0)])
def test_principal_curvatures_torus_equators(where, k1_exact, k2_exact):
    V, F = procedural.torus(20.0, 5.0, 192, 64)
    c = principal_curvatures(V, F)
    rho = np.hypot(V[:, 0], V[:, 1])
    ring = np.isclose(rho, 25.0 if where == "outer" else 15.0) & np.isclose(V[:, 2], 0.0, atol=1e-9)
    assert ring.sum() == 192
    np.testing.assert_allclose(c.k1[ring], k1_exact, rtol=0.012)
    np.testing.assert_allclose(c.k2[ring], k2_exact, atol=0.006 * k1_exact)  # error relative to the larger k
    # d1 runs around the tube (in the meridian plane), d2 along the parallel (horizontal)
    assert np.abs(c.d2[ring, 2]).max() < 1e-6
    assert np.abs(c.d1[ring, 2]).min() > 1 - 1e-6


def test_principal_curvatures_saddle_center():
    k = 0.1
    V, F = procedural.saddle_patch(k, 5.0, 41)
    c = principal_curvatures(V, F)
    centre = np.argmin(np.linalg.norm(V[:, :2], axis=1))
    assert np.linalg.norm(V[centre]) == 0.0
    np.testing.assert_allclose([c.k1[centre], c.k2[centre]], [k, -k], rtol=1e-6)
    np.testing.assert_allclose(np.abs(c.d1[centre]), [0, 1, 0], atol=1e-9)  # +k along y (convex-positive)
    assert np.all(np.isfinite(c.k1)) and np.all(c.k1 >= c.k2)


def test_principal_curvatures_flat_has_zero_and_valid_frames():
    V, F = procedural.box(10.0, 6)
    c = principal_curvatures(V, F)
    face_centres = np.sum(np.abs(V) <= 5.0 - 2 * 10.0 / 6 + 1e-9, axis=1) == 2  # >= 2 cells from every edge
    assert face_centres.sum() > 0
    np.testing.assert_allclose(c.k1[face_centres], 0.0, atol=1e-9)
    _check_frames(c)


def test_principal_curvatures_radius_in_mm():
    V, F = procedural.icosphere(10.0, 4)
    small = principal_curvatures(V, F)
    h = small.radius_mm / 2
    big = principal_curvatures(V, F, radius_mm=5 * h)
    assert big.radius_mm == pytest.approx(5 * h)
    assert principal_curvatures(V, F, radius_mm=0.1 * h).radius_mm == pytest.approx(2 * h)  # libigl minimum
    # a wider fit sees more of the sphere's quartic term: larger (still positive) bias
    assert np.abs(big.k1 * 10 - 1).max() > np.abs(small.k1 * 10 - 1).max()
    with pytest.raises(ValueError):
        principal_curvatures(V, F, radius_mm=-1.0)


def test_principal_curvatures_units_scale_inversely():
    V, F = procedural.torus(2.0, 0.5, 64, 32)
    a = principal_curvatures(V, F)
    b = principal_curvatures(V * 10.0, F)
    np.testing.assert_allclose(b.k1, a.k1 / 10.0, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.k2, a.k2 / 10.0, rtol=1e-9, atol=1e-12)


def test_principal_curvatures_robust_to_unreferenced_small_components_and_degenerate_faces():
    V, F = procedural.icosphere(10.0, 3)
    n = V.shape[0]
    tet = np.array([[30, 30, 30], [31, 30, 30], [30, 31, 30], [30, 30, 31]], float)
    V2 = np.vstack([V, [[50.0, 50.0, 50.0]], tet])
    F2 = np.vstack([F, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]) + n + 1, [[0, 1, 0]]])
    with pytest.warns(MeshDefectWarning, match="libigl failed at 4 vertices"):
        c = principal_curvatures(V2, F2)
    assert c.n_unreferenced == 1 and c.n_fallback == 4
    assert np.all(np.isfinite(c.k1)) and np.all(np.isfinite(c.d1)) and np.all(c.k1 >= c.k2)
    assert c.k1[n] == 0.0 and c.k2[n] == 0.0  # the unreferenced vertex
    assert np.all(c.k1[n + 1:] > 0)  # the tetrahedron is convex: umbilic cotangent fallback is positive
    np.testing.assert_allclose(c.k1[:n], 0.1, rtol=0.03)  # the sphere is unaffected
    keep = np.r_[np.arange(n), np.arange(n + 1, n + 5)]
    _check_frames(c, keep)


def test_principal_curvatures_open_boundary_is_finite():
    V, F = procedural.icosphere(10.0, 3)
    upper = V[F].mean(axis=1)[:, 2] > 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)
        c = principal_curvatures(V, F[upper])
    used = np.unique(F[upper])
    assert np.all(np.isfinite(c.k1[used])) and np.all(c.k1[used] >= c.k2[used])
    top = used[V[used, 2] > 5.0]
    np.testing.assert_allclose(c.k1[top], 0.1, rtol=0.03)


def test_principal_curvatures_converges_second_order_on_sphere():
    h, err = [], []
    for s in range(2, 6):
        V, F = procedural.icosphere(10.0, s)
        c = principal_curvatures(V, F)
        h.append(c.radius_mm / 2)
        err.append(max(np.abs(c.k1 * 10 - 1).max(), np.abs(c.k2 * 10 - 1).max()))
    order = np.polyfit(np.log(h), np.log(err), 1)[0]
    assert order > 2.0 - 0.3, (h, err, order)
    assert err[-1] < 0.002


SHARED = ["armadillo.obj", "blub.obj", "bob.obj", "boot.obj", "bunny.ply", "hand.obj", "lee_perry_smith_head.obj",
          "skull.obj", "spot.obj"]


@pytest.mark.parametrize("name", SHARED)
def test_principal_curvatures_shared_meshes_finite(shared_meshes, name):
    mesh = load_mesh(shared_meshes / name)
    V = mesh.vertices * (100.0 / mesh.scale)  # about 100 mm across
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshDefectWarning)  # blub's fins, the head's scan folds: a few outliers
        c = principal_curvatures(V, mesh.faces)
    assert c.n_fallback < 0.01 * len(V)
    assert np.all(np.isfinite(c.k1)) and np.all(np.isfinite(c.k2))
    assert np.all(np.isfinite(c.d1)) and np.all(np.isfinite(c.d2))
    assert np.all(c.k1 >= c.k2)
    assert c.n_unreferenced == 0
    _check_frames(c)
    assert np.sum(mesh.vertex_areas * c.mean) > 0  # closed and outward: positive total mean curvature


def test_principal_curvatures_replaces_nan_and_outliers_by_neighbour_median(monkeypatch):
    V, F = procedural.icosphere(10.0, 3)
    real = igl.principal_curvature

    def broken(V_, F_, radius, use_kring):
        d1, d2, k1, k2, bad = real(V_, F_, radius, use_kring)
        k1, k2, d1 = k1.copy(), k2.copy(), d1.copy()
        k1[5], d1[5] = np.nan, np.nan
        k2[7] = -1e4  # a radius of curvature far below the edge length
        return d1, d2, k1, k2, bad

    monkeypatch.setattr(igl, "principal_curvature", broken)
    with pytest.warns(MeshDefectWarning, match="failed at 2 vertices"):
        c = principal_curvatures(V, F)
    assert np.flatnonzero(c.fallback).tolist() == [5, 7]
    np.testing.assert_allclose(c.k1[[5, 7]], 0.1, rtol=0.03)
    np.testing.assert_allclose(c.k2[[5, 7]], 0.1, rtol=0.03)
    _check_frames(c)
