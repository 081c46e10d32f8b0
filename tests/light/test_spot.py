"""Spot lights: a point light with a cone (``PointLight(spot=Spot(...))``, ``--light spot:...``), as Blender's spot.

References: the falloff is checked against Cycles' definition written out here independently (smoothstep of
(cos theta - cos(angle/2)) / ((1 - cos(angle/2)) blend)), and a spot's entry samples against the point light's
of the same intensity times that falloff, computed by the test from the geometry.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.errors import LightError
from meshshade.geometry.procedural import icosphere
from meshshade.light import PointLight, entry_samples, parse_light_spec
from meshshade.light.sources import Spot, describe_light
from meshshade.geometry.mesh import Mesh


def cycles_smoothstep(x):
    """Cycles' smoothstepf: 0 below 0, 1 above 1, 3x^2 - 2x^3 between."""
    return 0.0 if x <= 0.0 else 1.0 if x >= 1.0 else x * x * (3.0 - 2.0 * x)


def test_hard_cone_is_a_step_at_half_the_angle():
    sp = Spot((0, 0, -1), math.radians(60.0), 0.0)
    inside, outside = math.cos(math.radians(29.9)), math.cos(math.radians(30.1))
    assert sp.falloff(np.array([1.0, inside, outside, -1.0])).tolist() == [1.0, 1.0, 0.0, 0.0]


@settings(max_examples=200, deadline=None)
@given(angle=st.floats(0.01, math.pi), blend=st.floats(0.0, 1.0), theta=st.floats(0.0, math.pi))
def test_falloff_matches_cycles_definition(angle, blend, theta):
    sp = Spot((0, 0, 1), angle, blend)
    c = math.cos(angle / 2)
    x = math.cos(theta)
    if (1 - c) * blend == 0.0:   # blend 0 (or underflowing with the cone's width): the limit, a hard edge
        expected = 1.0 if x >= c else 0.0
    else:
        expected = cycles_smoothstep((x - c) / ((1 - c) * blend))
    got = float(sp.falloff(np.array([x]))[0])
    assert 0.0 <= got <= 1.0
    assert got == pytest.approx(expected, abs=1e-12)


def test_towards_measures_the_angle_from_the_axis():
    sp = Spot((0, 0, -2.0), math.radians(90.0), 0.5)   # axis normalised on construction
    d = np.array([[0, 0, -5.0], [0, 3.0, -3.0], [1.0, 0, 0]])
    np.testing.assert_allclose(sp.towards(d), sp.falloff(np.array([1.0, math.sqrt(0.5), 0.0])))


@pytest.mark.parametrize("kwargs", [dict(angle=0.0), dict(angle=3.2), dict(blend=-0.1), dict(blend=1.5),
                                    dict(angle=float("nan"))])
def test_spot_refuses_bad_cones(kwargs):
    with pytest.raises(LightError):
        Spot((0, 0, 1), **{"angle": 1.0, "blend": 0.1, **kwargs})


def test_spec_parses_spots_with_blenders_defaults_and_mm_scale():
    lt = parse_light_spec("spot:1,2,3:0,0,-1:5", mm_per_unit=10.0)
    assert lt.position == (10.0, 20.0, 30.0) and lt.intensity == 5.0
    assert lt.spot.axis == (0.0, 0.0, -1.0)
    assert lt.spot.angle == pytest.approx(math.radians(45.0)) and lt.spot.blend == 0.15
    lt = parse_light_spec("spot:0,0,9:0,0,-1:2:30:0.5")
    assert lt.spot.angle == pytest.approx(math.radians(30.0)) and lt.spot.blend == 0.5
    assert "spot light 0" in describe_light(lt, 0) and "cone 30 deg" in describe_light(lt, 0)
    for bad in ("spot:0,0,9", "spot:0,0,9:0,0,-1:1:200", "spot:0,0,9:0,0,-1:1:30:2", "spot:0,0,9:0,0,0"):
        with pytest.raises(LightError):
            parse_light_spec(bad)


def test_spot_samples_are_the_point_lights_times_the_falloff():
    V, F = icosphere(10.0, 4)
    mesh = Mesh.from_arrays(V, F)
    pos = (0.0, 0.0, 40.0)
    axis = np.array([0.3, 0.0, -1.0]) / np.linalg.norm([0.3, 0.0, -1.0])
    spot = PointLight(pos, 2.0, spot=Spot(tuple(axis), math.radians(20.0), 0.3))
    args = (mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas)
    s_spot = entry_samples(*args, [spot], eta=1.3)
    s_point = entry_samples(*args, [PointLight(pos, 2.0)], eta=1.3)
    # the test's own falloff from the geometry
    d = mesh.vertices[s_point.vertex] - np.array(pos)
    cos = d @ axis / np.linalg.norm(d, axis=1)
    c = math.cos(math.radians(10.0))
    t = np.clip((cos - c) / ((1 - c) * 0.3), 0.0, 1.0)
    fall = t * t * (3 - 2 * t)
    lit = fall > 0
    assert 0 < lit.sum() < s_point.vertex.size          # the cone cuts the lit cap
    np.testing.assert_array_equal(s_spot.vertex, s_point.vertex[lit])
    np.testing.assert_allclose(s_spot.power, s_point.power[lit] * fall[lit], rtol=1e-12)


def test_a_cone_that_misses_the_mesh_is_a_light_that_reaches_nothing():
    V, F = icosphere(10.0, 3)
    mesh = Mesh.from_arrays(V, F)
    away = PointLight((0.0, 0.0, 40.0), 1.0, spot=Spot((0.0, 0.0, 1.0), math.radians(30.0), 0.0))
    with pytest.raises(LightError, match="reaches no vertex"):
        entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [away], eta=1.3)


def test_monte_carlo_photons_of_a_spot_carry_the_falloff():
    """Monte Carlo's emitter: every photon's incident weight is the point light's times the falloff at its entry
    point (importance-corrected from the face centroid), so the total incident power is the integral of
    I f(theta) cos / r^2 over the lit surface; compared with the same integral done by the test on the faces."""
    from meshshade.montecarlo.emitter import Emitter
    from meshshade.raycast import make_scene

    V, F = icosphere(10.0, 4)
    mesh = Mesh.from_arrays(V, F)
    pos = np.array([0.0, 0.0, 40.0])
    spot = PointLight(tuple(pos), 2.0, spot=Spot((0.0, 0.0, -1.0), math.radians(16.0), 0.5))
    em = Emitter(mesh.vertices, mesh.faces, mesh.face_normals, mesh.face_areas, [spot], make_scene(
        mesh.vertices, mesh.faces), 1.3)
    rng = np.random.default_rng(5)
    n = 200_000
    _light, face, points, _dirs, _w_in, _spec, incident = em.emit(n, n, rng)
    d = points - pos
    cos_axis = -d[:, 2] / np.linalg.norm(d, axis=1)
    assert np.all(incident[cos_axis < math.cos(math.radians(8.0)) - 1e-9] == 0.0)   # nothing outside the cone
    # the test's integral: 16-point-per-face quadrature of I f cos / r^2 over faces facing the light
    tri = mesh.vertices[mesh.faces]
    rs = np.random.default_rng(0).random((64, 2))
    r1 = np.sqrt(rs[:, 0])
    bary = np.stack([1 - r1, r1 * (1 - rs[:, 1]), r1 * rs[:, 1]], axis=1)
    pts = np.einsum("qk,fkj->fqj", bary, tri)
    delta = pos - pts
    dist = np.linalg.norm(delta, axis=2)
    cos_n = np.einsum("fqj,fj->fq", delta, mesh.face_normals) / dist
    cth = delta[:, :, 2] / dist
    cc = math.cos(math.radians(8.0))
    t = np.clip((cth - cc) / ((1 - cc) * 0.5), 0, 1)
    E = 2.0 * t * t * (3 - 2 * t) * np.clip(cos_n, 0, None) / dist ** 2
    expected = float((E.mean(axis=1) * mesh.face_areas).sum())
    assert incident.sum() == pytest.approx(expected, rel=0.02)
