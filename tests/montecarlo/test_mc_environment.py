"""The in-mesh Monte Carlo under environment and area lights (issue 43): it emits what the bake receives.

Both the Monte Carlo's emitter and the bake's quadrature are unbiased estimators of the power arriving on the
mesh, over its faces (face normals) and over its vertex patches (vertex normals) respectively. Each is checked
against its own exact expectation from an independent route, so the two agree up to the mesh's discretisation,
which is reported:

* a uniform sky on a convex mesh: pi L per unit area on every patch and every face (the cosine-weighted
  hemisphere), and 2 pi L integral mu F_t(mu) d mu entering (F_t by mpmath);
* a map on a convex mesh: sum over faces (or vertex patches) of area x integral L cos+ d omega, that integral by
  the midpoint quadrature over each pixel of tests/light/test_environment.py (its own pixel geometry);
* a disc emitter above a flat plate: the integral over the plate of pi L F, F the view factor from a differential
  element parallel to a disc of radius r at height h and lateral offset a, F = (1/2) [1 - (h^2 + a^2 - r^2) /
  sqrt((h^2 + a^2 + r^2)^2 - 4 r^2 a^2)] (Howell's catalog, "plane element to parallel disk"; it reduces to the
  coaxial r^2 / (r^2 + h^2) at a = 0), integrated by scipy.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from scipy import integrate

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import AreaLight, EnvironmentLight, entry_samples
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, TOTAL_KEYS, simulate
from meshshade.montecarlo.emitter import Emitter
from meshshade.raycast import make_scene

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "light"))
from test_environment import entering_fraction, pixel_cos_integrals  # noqa: E402

ETA = 1.3


def emitted(mesh, light, n=300_000, seed=3):
    """(incident, entering) W of n photons of the numpy emitter, with their standard errors."""
    scene = make_scene(mesh.vertices, mesh.faces)
    em = Emitter(mesh.vertices, mesh.faces, mesh.face_normals, mesh.face_areas, [light], scene, ETA)
    _l, _f, _p, _d, w_in, _spec, inc = em.emit(n, n, np.random.default_rng(seed))
    return (inc.sum(), inc.std() * math.sqrt(n)), (w_in.sum(), w_in.std() * math.sqrt(n))


def baked(mesh, light):
    """(incident W, entering W, standard error of the incident from the per-vertex reported errors)."""
    s = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light], eta=ETA)
    return s.incident_power[0], s.power.sum(), s


def test_uniform_sky_on_a_sphere_both_exact():
    L = 0.02
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    area = mesh.face_areas.sum()
    (inc, se), (ent, se_e) = emitted(mesh, EnvironmentLight.uniform(L))
    assert abs(inc - math.pi * L * area) < 5 * se
    assert abs(ent - math.pi * L * area * entering_fraction(ETA)) < 5 * se_e
    b_inc, b_ent, _ = baked(mesh, EnvironmentLight.uniform(L))
    assert b_inc == np.float64(b_inc) and abs(b_inc / (math.pi * L * area) - 1) < 2e-3   # per-vertex error ~1 %
    assert abs(b_ent / (math.pi * L * area * entering_fraction(ETA)) - 1) < 2e-3          # averaged over 642


def test_a_map_on_a_convex_mesh_each_against_its_expectation(rng):
    H, W = 4, 8
    Y = rng.random((H, W)) + 0.05
    Y[1, 2] = 12.0
    light = EnvironmentLight(Y, rotation_deg=25.0)
    mesh = Mesh.from_arrays(*icosphere(10.0, 2))

    def E(n):
        return float(np.sum(Y * pixel_cos_integrals(H, W, n, "y", 25.0, sub=12)))

    face_exact = sum(a * E(n) for a, n in zip(mesh.face_areas, mesh.face_normals))
    vertex_exact = sum(a * E(n) for a, n in zip(mesh.vertex_areas, mesh.vertex_normals))
    (inc, se), _ = emitted(mesh, light)
    assert abs(inc - face_exact) < 5 * se and se < 5e-3 * face_exact
    b_inc, _, s = baked(mesh, light)
    q = s.stats["quadrature"][0]
    # the bake's standard error from the per-vertex errors it reports (independent vertices)
    per_vertex = np.bincount(s.vertex, weights=s.power, minlength=mesh.n_vertices)
    se_b = q["rel_error_rms"] * math.sqrt(np.sum(per_vertex ** 2)) * (b_inc / s.power.sum())
    assert abs(b_inc - vertex_exact) < 5 * se_b + 1e-9 * vertex_exact
    # what the two discretisations of the surface differ by, on this 162-vertex sphere
    assert abs(face_exact / vertex_exact - 1) < 0.01


def _plate(n=24, half=10.0):
    x = np.linspace(-half, half, n + 1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    idx = np.arange(V.shape[0]).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return Mesh.from_arrays(V, F)


def test_disc_over_a_plate_against_the_view_factor_integral():
    r, h, P = 4.0, 6.0, 3.0
    light = AreaLight((2.0, 1.0, h), (0, 0, -1.0), "disc", (r,), power=P)
    L = P / (math.pi * math.pi * r * r)

    def F(x, y):
        a2 = (x - 2.0) ** 2 + (y - 1.0) ** 2
        return 0.5 * (1 - (h * h + a2 - r * r) / math.sqrt((h * h + a2 + r * r) ** 2 - 4 * r * r * a2))

    assert F(2.0, 1.0) == r * r / (r * r + h * h) or abs(F(2.0, 1.0) - r * r / (r * r + h * h)) < 1e-15
    exact = integrate.dblquad(lambda y, x: math.pi * L * F(x, y), -10, 10, -10, 10, epsabs=1e-12, epsrel=1e-10)[0]
    mesh = _plate()
    (inc, se), _ = emitted(mesh, light)
    assert abs(inc - exact) < 5 * se and se < 5e-3 * exact
    b_inc, _, _ = baked(mesh, light)
    assert abs(b_inc / exact - 1) < 0.01        # vertex patches of a 24 x 24 plate (0.83 mm) and ~1 % per vertex


def test_simulate_under_a_sky_and_an_area_light_is_balanced_and_reproducible():
    mesh = Mesh.from_arrays(*icosphere(5.0, 2))
    mat = Material((1.0, 2.0, 0.5), (0.05, 0.1, 0.2), eta=ETA)
    Y = np.ones((8, 16))
    Y[2, 3] = 30.0
    lights = [EnvironmentLight(Y), AreaLight((0, 0, 15.0), (0, 0, -1.0), "rect", (6.0, 4.0), power=0.5)]
    a = simulate(mesh, mat, lights, MCOptions(photons=4000, seed=5, beam_distances=False))
    b = simulate(mesh, mat, lights, MCOptions(photons=4000, seed=5, beam_distances=False))
    c = simulate(mesh, mat, lights, MCOptions(photons=4000, seed=6, beam_distances=False))
    total = sum(a.totals[k] for k in TOTAL_KEYS) + a.lost
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.radiance, b.radiance)
    assert not np.array_equal(a.radiance, c.radiance)
