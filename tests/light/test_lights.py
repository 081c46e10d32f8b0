"""Tests of meshshade.light: spec parsing, beam/directional/point entry samples, shadowing and its culling."""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import trimesh
from scipy.integrate import quad

from meshshade.errors import LightError, MeshshadeError, UnitsError
from meshshade.geometry.convexity import is_convex
from meshshade.geometry.topology import winding_number
from meshshade.kernels.fresnel import fresnel_transmittance_entry
from meshshade.light import BeamLight, DirectionalLight, EntrySamples, PointLight, entry_samples, parse_light_spec
from meshshade.light.shadows import ShadowCuller
from meshshade.light.samples import beam_footprint, check_exitance
from meshshade.light.sources import BEAM_SAMPLES
from meshshade.raycast import NumpyScene, make_scene

ETA = 1.3


def as_arrays(m: trimesh.Trimesh):
    """vertices, faces, area-weighted vertex normals, barycentric vertex areas (1/3 of incident face areas)."""
    V, F = np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces)
    A = np.zeros(len(V))
    np.add.at(A, F.ravel(), np.repeat(m.area_faces / 3.0, 3))
    fn = np.asarray(m.face_normals) * m.area_faces[:, None]
    N = np.zeros_like(V)
    np.add.at(N, F.ravel(), np.repeat(fn, 3, axis=0))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    return V, F, N, A


def sphere(radius=10.0, subdivisions=4, center=(0.0, 0.0, 0.0)):
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    m.apply_translation(center)
    return as_arrays(m)


def big_and_small_spheres(level=4):
    """A 10 mm sphere at the origin and a 3 mm sphere 20 mm above it (+z), as one mesh."""
    big = trimesh.creation.icosphere(subdivisions=level, radius=10.0)
    small = trimesh.creation.icosphere(subdivisions=level - 1, radius=3.0)
    small.apply_translation([0.0, 0.0, 20.0])
    return as_arrays(trimesh.util.concatenate([big, small])), len(big.vertices)


def cos_weighted_mean_Ft(eta):
    """2 int_0^1 mu F_t(mu) dmu: the mean transmittance of a sphere under parallel light."""
    return 2.0 * quad(lambda mu: mu * float(fresnel_transmittance_entry(mu, eta)), 0.0, 1.0, epsabs=1e-13)[0]


# ------------------------------------------------------------------------------------------------------------
# parsing
# ------------------------------------------------------------------------------------------------------------

def test_parse_light_spec_beam():
    light = parse_light_spec("beam:1,2,3:0,0,-2:0.5")
    assert light == BeamLight((1.0, 2.0, 3.0), (0.0, 0.0, -1.0), 0.5)
    assert parse_light_spec(" BEAM : 1, 2, 3 : 0,0,1 ").power == 1.0


def test_parse_light_spec_units_scale_positions_only():
    beam = parse_light_spec("beam:1,2,3:0,3,4:2", mm_per_unit=10.0)
    assert beam.origin == (10.0, 20.0, 30.0)
    assert beam.direction == pytest.approx((0.0, 0.6, 0.8))
    assert beam.power == 2.0
    point = parse_light_spec("point:1,0,-1:5", mm_per_unit=25.4)
    assert point.position == (25.4, 0.0, -25.4) and point.intensity == 5.0
    directional = parse_light_spec("directional:0,0,-5:0.25", mm_per_unit=1000.0)
    assert directional == DirectionalLight((0.0, 0.0, -1.0), 0.25)


def test_parse_light_spec_defaults():
    assert parse_light_spec("directional:1,0,0") == DirectionalLight((1.0, 0.0, 0.0), 1.0)
    assert parse_light_spec("point:0,0,50") == PointLight((0.0, 0.0, 50.0), 1.0)


@pytest.mark.parametrize("spec, fragment", [
    ("sky:0,0,0:0,0,1", "unknown light type 'sky'"),
    ("area:0,0,0:0,0,1", "must look like area"),
    ("", "empty light spec"),
    ("beam:0,0,0", "must look like beam:ox,oy,oz:dx,dy,dz[:power[:radius]]"),
    ("beam:0,0,0:0,0,1:1:2:3", "must look like beam"),
    ("directional", "must look like directional"),
    ("point:1,2,3:4:5", "must look like point"),
    ("beam:0,0:0,0,1", "beam origin needs 3 comma-separated numbers"),
    ("beam:0,0,0:0,0,x", "beam direction needs 3 comma-separated numbers"),
    ("beam:0,0,nan:0,0,1", "beam origin must be finite"),
    ("point:inf,0,0", "point light position must be finite"),
    ("beam:0,0,0:0,0,0", "beam direction must be non-zero"),
    ("directional:0,0,0", "directional light direction must be non-zero"),
    ("beam:0,0,0:0,0,1:-1", "beam power must be > 0 and at most 1e20 W, got -1.0"),
    ("beam:0,0,0:0,0,1:0", "beam power must be > 0 and at most 1e20 W, got 0.0"),
    ("beam:0,0,0:0,0,1:1e21", "beam power must be > 0 and at most 1e20 W, got 1e21"),
    ("beam:0,0,0:0,0,1:nan", "beam power must be finite"),
    ("beam:0,0,0:0,0,1:lots", "beam power must be a number"),
    ("beam:0,0,0:0,0,1:1:-2", "beam radius must be >= 0"),
    ("beam:0,0,0:0,0,1:1:inf", "beam radius must be finite"),
    ("directional:0,0,1:-0.1", "directional irradiance must be > 0 and at most 1e20 W/mm^2"),
    ("directional:0,0,-1:1e308", "directional irradiance must be > 0 and at most 1e20 W/mm^2, got 1e308"),
    ("directional:0,0,-1:0", "directional irradiance must be > 0"),
    ("point:0,0,0:-3", "point light intensity must be > 0 and at most 1e20 W/sr"),
    ("point:0,0,0:inf", "point light intensity must be finite"),
])
def test_parse_light_spec_errors(spec, fragment):
    with pytest.raises(LightError) as info:
        parse_light_spec(spec)
    message = str(info.value)
    assert fragment in message
    assert "\n" not in message
    assert isinstance(info.value, MeshshadeError)


def test_parse_light_spec_bad_units():
    with pytest.raises(UnitsError):
        parse_light_spec("point:0,0,1", mm_per_unit=0.0)


def test_lights_validate_at_construction_and_are_frozen():
    with pytest.raises(LightError, match="non-zero"):
        BeamLight((0, 0, 0), (0, 0, 0))
    with pytest.raises(LightError, match="3 numbers"):
        PointLight((0, 0), 1.0)
    with pytest.raises(LightError, match="> 0"):
        DirectionalLight((0, 0, 1), -1.0)
    with pytest.raises(LightError, match="must be a number"):
        BeamLight((0, 0, 0), (0, 0, 1), True)
    assert BeamLight((0, 0, 0), (0, 0, 1), 1e20).power == 1e20  # MAX_LIGHT_STRENGTH itself is allowed
    light = PointLight(np.array([1, 2, 3]), 2)
    assert light.position == (1.0, 2.0, 3.0) and isinstance(light.intensity, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        light.intensity = 3.0
    assert hash(light) == hash(PointLight((1.0, 2.0, 3.0), 2.0))


# ------------------------------------------------------------------------------------------------------------
# beams
# ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("backend", ["embree", "numpy"])
@pytest.mark.parametrize("offset", [0.0, 3.0, 9.8])       # 9.8 of R = 10: grazing-ish, cos ~ 0.2
def test_entry_samples_beam_on_sphere(backend, offset):
    R = 10.0
    V, F, N, A = sphere(R, 4)
    scene = make_scene(V, F, backend)
    light = BeamLight((offset, 0.0, -50.0), (0.0, 0.0, 1.0), 2.0)
    es = entry_samples(V, F, N, A, [light], scene, ETA)
    assert len(es) == 1 and es.vertex[0] == -1 and es.face[0] >= 0 and es.light_index[0] == 0
    # analytic entry point on the sphere, within the mesh's sagitta
    edge = np.max(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1))
    cos_analytic = np.sqrt(R * R - offset**2) / R
    expected = np.array([offset, 0.0, -np.sqrt(R * R - offset**2)])
    assert np.linalg.norm(es.positions[0] - expected) <= edge**2 / (4 * R) / cos_analytic
    # the point lies on the hit face and matches the barycentric interpolation
    tri = V[F[es.face[0]]]
    np.testing.assert_allclose(es.bary[0] @ tri, es.positions[0], atol=1e-12)
    np.testing.assert_allclose(np.dot(es.positions[0] - tri[0], es.normals[0]), 0.0, atol=1e-12)
    # power = P F_t(cos) with cos from the geometric face normal; and close to the analytic cosine
    assert es.cos_incidence[0] == pytest.approx(-es.normals[0] @ light.direction, rel=1e-14)
    # a face normal is within ~edge/R radians of the sphere's normal anywhere on the face
    sin_analytic = offset / R
    assert es.cos_incidence[0] == pytest.approx(cos_analytic, abs=sin_analytic * edge / R + 1e-3)
    assert es.power[0] == pytest.approx(2.0 * fresnel_transmittance_entry(es.cos_incidence[0], ETA), rel=1e-14)
    assert es.incident_power[0] == 2.0
    assert es.specular_power[0] + es.power[0] == pytest.approx(2.0, rel=1e-14)
    assert es.stats["beam_rays"] == 1 and es.stats["shadow_rays_cast"] == 0


def test_entry_samples_beam_through_a_vertex():
    """A beam aimed exactly at a vertex (the icosphere's vertices lie on axes of symmetry) must hit."""
    V, F, N, A = sphere(10.0, 3)
    target = V[0]
    light = BeamLight(tuple(target * 5.0), tuple(-target), 1.0)
    es = entry_samples(V, F, N, A, light, None, ETA)
    np.testing.assert_allclose(es.positions[0], target, atol=1e-9)


def test_entry_samples_beam_misses_or_starts_inside():
    V, F, N, A = sphere(10.0, 2)
    with pytest.raises(LightError, match="misses the mesh") as info:
        entry_samples(V, F, N, A, [BeamLight((20.0, 0.0, -50.0), (0.0, 0.0, 1.0))], None, ETA)
    assert "\n" not in str(info.value)
    with pytest.raises(LightError, match="misses the mesh"):
        entry_samples(V, F, N, A, [BeamLight((0.0, 0.0, -50.0), (0.0, 0.0, -1.0))], None, ETA)
    with pytest.raises(LightError, match="inside the mesh"):
        entry_samples(V, F, N, A, [BeamLight((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))], None, ETA)


# ------------------------------------------------------------------------------------------------------------
# directional lights
# ------------------------------------------------------------------------------------------------------------

def test_entry_samples_directional_on_sphere():
    R, E = 10.0, 0.3
    V, F, N, A = sphere(R, 5)
    d = np.array([1.0, -2.0, 0.5])
    d /= np.linalg.norm(d)
    es = entry_samples(V, F, N, A, [DirectionalLight(tuple(d), E)], None, ETA)
    lit = np.flatnonzero(N @ -d > 0)
    np.testing.assert_array_equal(np.sort(es.vertex), lit)                 # exactly the facing hemisphere
    assert np.all(es.face == -1) and np.all(np.isnan(es.bary))
    np.testing.assert_allclose(es.positions, V[es.vertex])
    np.testing.assert_allclose(es.cos_incidence, N[es.vertex] @ -d, rtol=1e-14)
    np.testing.assert_allclose(es.power, E * es.cos_incidence * A[es.vertex]
                               * fresnel_transmittance_entry(es.cos_incidence, ETA), rtol=1e-14)
    # total: E pi R^2 <F_t>, up to the discretisation (vertex areas sum to the polyhedron's, ~0.1 % low at
    # 10242 vertices, and the terminator is resolved to one ring of vertices)
    expected = E * np.pi * R * R * cos_weighted_mean_Ft(ETA)
    assert es.power.sum() == pytest.approx(expected, rel=5e-3)
    assert es.incident_power[0] == pytest.approx(E * np.pi * R * R, rel=5e-3)
    assert es.incident_power[0] == pytest.approx(es.power.sum() + es.specular_power[0], rel=1e-13)
    np.testing.assert_allclose(es.entering_power, [es.power.sum()])


def test_entry_samples_directional_converges_under_refinement():
    """The error of the total entering power decreases as the icosphere is refined (levels 2..5)."""
    R = 10.0
    expected = np.pi * R * R * cos_weighted_mean_Ft(ETA)
    errors = []
    for level in (2, 3, 4, 5):
        V, F, N, A = sphere(R, level)
        es = entry_samples(V, F, N, A, [DirectionalLight((0.3, 0.1, -1.0))], None, ETA)
        errors.append(abs(es.power.sum() / expected - 1.0))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 3e-3


def test_entry_samples_convex_mesh_skips_every_shadow_ray():
    V, F, N, A = sphere(10.0, 4)

    class NoRays(NumpyScene):
        def occluded(self, *args, **kwargs):
            raise AssertionError("no shadow ray should be cast on a convex mesh")

    es = entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, -1.0)), PointLight((0.0, 30.0, 0.0), 50.0)],
                       NoRays(V, F), ETA)
    assert es.stats["mesh_convex"] is True
    assert es.stats["shadow_rays_cast"] == 0
    assert es.stats["shadow_rays_skipped"] == es.stats["skipped_convex"] == es.stats["candidates"] == len(es)


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_entry_samples_small_sphere_shadows_big_one(backend):
    (V, F, N, A), n_big = big_and_small_spheres()
    es = entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, -1.0), 1.0)], make_scene(V, F, backend), ETA)
    assert es.stats["mesh_convex"] is False
    assert es.stats["shadow_rays_cast"] > 0
    lit = np.zeros(len(V), dtype=bool)
    lit[es.vertex] = True
    on_big = np.arange(len(V)) < n_big
    facing = N[:, 2] > 0
    rho = np.hypot(V[:, 0], V[:, 1])                       # distance from the shadow axis
    # the small sphere's shadow cylinder (radius 3) on the big sphere's top; its mesh radius is 3 minus a sagitta
    assert not lit[on_big & facing & (rho < 2.9)].any()
    assert lit[on_big & facing & (rho > 3.05)].all()
    assert (on_big & facing & (rho < 2.9)).sum() > 30
    assert lit[~on_big & facing].all()                      # the small sphere itself is fully lit on top
    # the convex-hull rule runs only with the brute-force backend, where rays are expensive
    assert (es.stats["skipped_hull"] > 0) == (backend == "numpy")


@pytest.mark.parametrize("backend", ["embree", "numpy"])
@pytest.mark.parametrize("scene_kind", ["two_spheres", "torus", "sphere"])
def test_entry_samples_shadow_culling_changes_nothing(scene_kind, backend, monkeypatch):
    """Samples with the culling rules (convex mesh; convex hull with the numpy backend) equal samples with every
    shadow ray cast (rules disabled)."""
    if scene_kind == "two_spheres":
        (V, F, N, A), _ = big_and_small_spheres(level=3)
    elif scene_kind == "torus":
        V, F, N, A = as_arrays(trimesh.creation.torus(10.0, 3.0, major_sections=48, minor_sections=24))
    else:
        V, F, N, A = sphere(10.0, 3)
    lights = [DirectionalLight((0.2, 0.3, -1.0)), DirectionalLight((1.0, 0.0, 0.0)),
              PointLight((5.0, -3.0, 40.0), 100.0)]
    scene = make_scene(V, F, backend)
    culled = entry_samples(V, F, N, A, lights, scene, ETA)
    assert (culled.stats["shadow_rays_skipped"] > 0) == (scene_kind == "sphere" or backend == "numpy")
    monkeypatch.setattr(ShadowCuller, "COS_TOL", np.inf)
    brute = entry_samples(V, F, N, A, lights, scene, ETA)
    assert brute.stats["shadow_rays_skipped"] == 0
    assert brute.stats["shadow_rays_cast"] == culled.stats["candidates"]
    np.testing.assert_array_equal(culled.vertex, brute.vertex)
    np.testing.assert_array_equal(culled.light_index, brute.light_index)
    np.testing.assert_array_equal(culled.power, brute.power)


def test_entry_samples_backends_agree():
    (V, F, N, A), _ = big_and_small_spheres()
    lights = [DirectionalLight((0.1, 0.0, -1.0)), PointLight((0.0, 4.0, 30.0), 10.0),
              BeamLight((1.0, 1.0, 60.0), (0.0, 0.0, -1.0))]
    a = entry_samples(V, F, N, A, lights, make_scene(V, F, "embree"), ETA)
    b = entry_samples(V, F, N, A, lights, make_scene(V, F, "numpy"), ETA)
    np.testing.assert_array_equal(a.vertex, b.vertex)
    np.testing.assert_allclose(a.power, b.power, rtol=1e-12)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-12)


def test_no_light_reaching_the_mesh_is_an_error_one_among_several_a_warning():
    """An open patch facing +z, lit from below: no vertex faces the light. Alone: LightError (the result would be
    all zeros) naming the light, why, and the reversed direction; with a light that does reach it: a warning."""
    patch = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], faces=[[0, 1, 2], [1, 3, 2]])
    V, F, N, A = as_arrays(patch)
    with pytest.raises(LightError) as info:
        entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, 1.0))], None, ETA)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith("directional light 0 (travelling along (0, 0, 1)") and "reaches no vertex" in msg
    assert "faces away from it or is shadowed" in msg and "did you mean directional:0,0,-1?" in msg
    with pytest.raises(LightError, match=r"^no light reaches the mesh .*directional light 0 .*point light 1 "):
        entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, 1.0)), PointLight((0.5, 0.5, -3.0))], None, ETA)
    with pytest.warns(UserWarning, match=r"directional light 0 .* reaches no vertex"):
        es = entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, 1.0)), DirectionalLight((0.0, 0.0, -1.0))],
                           None, ETA)
    assert len(es) == 4 and np.all(es.light_index == 1)
    assert es.incident_power[0] == 0.0 and es.specular_power[0] == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lit = entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, -1.0))], None, ETA)
    assert len(lit) == 4 and lit.power.sum() == pytest.approx(float(fresnel_transmittance_entry(1.0, ETA)))


def test_a_beam_that_misses_is_an_error_even_among_other_lights():
    V, F, N, A = sphere(10.0, 2)
    with pytest.raises(LightError, match=r"beam light 1 \(from \(30, 0, 50\) mm .*\) misses the mesh$"):
        entry_samples(V, F, N, A, [DirectionalLight((0.0, 0.0, -1.0)), BeamLight((30.0, 0.0, 50.0), (0, 0, -1.0))],
                      None, ETA)
    with pytest.raises(LightError, match=r"mesh lies behind the origin: did you mean direction 0,0,-1\?"):
        entry_samples(V, F, N, A, [BeamLight((0.0, 0.0, 50.0), (0, 0, 1.0))], None, ETA)


# ------------------------------------------------------------------------------------------------------------
# point lights
# ------------------------------------------------------------------------------------------------------------

def test_entry_samples_point_light_inverse_square():
    R, I = 10.0, 100.0
    V, F, N, A = sphere(R, 4)
    top = int(np.argmax(V[:, 2]))                           # the vertex on the +z axis
    powers = {}
    for dist in (20.0, 40.0):
        es = entry_samples(V, F, N, A, [PointLight((0.0, 0.0, R + dist), I)], None, ETA)
        j = np.flatnonzero(es.vertex == top)[0]
        assert es.cos_incidence[j] == pytest.approx(1.0, abs=1e-12)
        assert es.power[j] == pytest.approx(I / dist**2 * A[top] * fresnel_transmittance_entry(1.0, ETA), rel=1e-12)
        powers[dist] = es.power[j]
    assert powers[20.0] / powers[40.0] == pytest.approx(4.0, rel=1e-12)
    # far away, the sphere's total approaches I pi R^2 <F_t> / d^2 (light from the centre distance D)
    D = 1e4
    es = entry_samples(V, F, N, A, [PointLight((0.0, 0.0, D), I)], None, ETA)
    assert es.power.sum() == pytest.approx(I * np.pi * R * R * cos_weighted_mean_Ft(ETA) / D**2, rel=1e-2)


def test_entry_samples_point_light_sees_only_its_cap():
    """A point light at distance D from the centre lights the cap cos(theta) > R / D (tangent cone)."""
    R, D = 10.0, 25.0
    V, F, N, A = sphere(R, 4)
    es = entry_samples(V, F, N, A, [PointLight((0.0, 0.0, D))], None, ETA)
    z = V[:, 2] / R
    lit = np.zeros(len(V), dtype=bool)
    lit[es.vertex] = True
    assert lit[z > R / D + 0.02].all() and not lit[z < R / D - 0.02].any()


def test_entry_samples_point_light_inside_mesh():
    V, F, N, A = sphere(10.0, 2)
    with pytest.raises(LightError, match="inside the mesh"):
        entry_samples(V, F, N, A, [PointLight((1.0, 2.0, 3.0))], None, ETA)


def test_entry_samples_point_light_shadow_stops_at_the_light():
    """A point light between the two spheres lights both facing caps: the shadow ray ends at the light."""
    (V, F, N, A), n_big = big_and_small_spheres()
    es = entry_samples(V, F, N, A, [PointLight((0.0, 0.0, 14.0), 1.0)], None, ETA)
    on_big = es.vertex < n_big
    assert on_big.any() and (~on_big).any()
    assert es.stats["shadow_rays_cast"] > 0


# ------------------------------------------------------------------------------------------------------------
# bookkeeping
# ------------------------------------------------------------------------------------------------------------

def test_entry_samples_multiple_lights_and_shapes():
    V, F, N, A = sphere(10.0, 3)
    lights = [BeamLight((0.0, 0.0, -40.0), (0.0, 0.0, 1.0), 3.0), DirectionalLight((1.0, 0.0, 0.0), 0.01),
              PointLight((0.0, 50.0, 0.0), 20.0)]
    es = entry_samples(V, F, N, A, lights, None, 1.0)      # eta = 1: nothing reflected
    assert isinstance(es, EntrySamples)
    k = len(es)
    assert es.positions.shape == (k, 3) and es.normals.shape == (k, 3) and es.bary.shape == (k, 3)
    for name in ("face", "vertex", "light_index"):
        assert getattr(es, name).shape == (k,) and getattr(es, name).dtype == np.int64
    for name in ("power", "cos_incidence"):
        assert getattr(es, name).shape == (k,) and getattr(es, name).dtype == np.float64
    assert set(np.unique(es.light_index)) == {0, 1, 2}
    assert np.all(es.specular_power == 0.0)
    np.testing.assert_allclose(es.entering_power, es.incident_power, rtol=1e-14)
    assert es.entering_power[0] == 3.0
    assert np.all((es.cos_incidence > 0) & (es.cos_incidence <= 1 + 1e-15))
    np.testing.assert_allclose(np.linalg.norm(es.normals, axis=1), 1.0)
    assert "EntrySamples(k=" in repr(es)


def test_is_convex_certificate():
    ico = trimesh.creation.icosphere(subdivisions=3)
    box = trimesh.creation.box().subdivide()                     # coplanar faces count as convex
    assert is_convex(ico.vertices, ico.faces)
    assert is_convex(box.vertices, box.faces)
    assert not is_convex(ico.vertices, ico.faces[:, ::-1])        # inward faces
    assert not is_convex(ico.vertices, ico.faces[1:])             # open
    tor = trimesh.creation.torus(10.0, 3.0)
    assert not is_convex(tor.vertices, tor.faces)                 # genus 1
    two = trimesh.util.concatenate([ico, trimesh.creation.icosphere(1).apply_translation([5.0, 0, 0])])
    assert not is_convex(two.vertices, two.faces)                 # two components
    dented = np.array(ico.vertices)
    dented[0] *= 0.99
    assert not is_convex(dented, ico.faces)                       # one concave vertex


def test_winding_number_inside_outside():
    V, F, _, _ = sphere(1.0, 2)
    assert winding_number([0.1, 0.2, 0.0], V, F) == pytest.approx(1.0, abs=1e-9)
    assert winding_number([3.0, 0.0, 0.0], V, F) == pytest.approx(0.0, abs=1e-9)
    assert winding_number([0.0, 0.0, 0.0], V, F[:, ::-1]) == pytest.approx(-1.0, abs=1e-9)


def test_finite_width_beam_spreads_power_over_many_entry_points():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    N = np.asarray(sphere.vertex_normals)
    A = np.full(len(V), sphere.area / len(V))
    beam = parse_light_spec("beam:0,0,50:0,0,-1:2.0:3", mm_per_unit=1.0)
    assert isinstance(beam, BeamLight) and beam.radius == 3.0 and beam.power == 2.0
    s = entry_samples(V, F, N, A, [beam], eta=1.3)
    assert len(s) == BEAM_SAMPLES
    r = np.hypot(s.positions[:, 0], s.positions[:, 1])
    assert r.max() <= 3.0 + 1e-9 and r.min() < 0.5
    # every ray hits: the incident power is the beam's; entering = incident - specular
    assert s.incident_power[0] == pytest.approx(2.0)
    assert s.power.sum() + s.specular_power[0] == pytest.approx(2.0)
    # a beam wider than the sphere: its power beyond the sphere's cross-section is lost; its 64 rays would hit
    # with 16 of them, while 1281 vertices lie lit in its cylinder: those sample it (irradiance P / (pi R^2))
    wide = entry_samples(V, F, N, A, [BeamLight((0, 0, 50), (0, 0, -1), 1.0, radius=20.0)], eta=1.3)
    assert wide.incident_power[0] == pytest.approx(10.0 ** 2 / 20.0 ** 2, rel=5e-3)
    assert len(wide) > BEAM_SAMPLES and np.all(wide.vertex >= 0) and np.all(V[wide.vertex, 2] >= -1e-9)


@pytest.mark.parametrize("radius", [11.0, 150.0, 1e6])
def test_wide_beam_around_a_small_mesh_is_not_a_miss(radius):
    """Issue 17: a beam of radius 150 mm on a 10 mm sphere, axis through the centre, was reported as a miss
    because its 64 fixed rays all pass beside the sphere (the innermost ring has radius 13 mm). It lights the
    sphere's cross-section with irradiance P / (pi R^2)."""
    V, F, N, A = sphere(10.0, 3)
    es = entry_samples(V, F, N, A, [BeamLight((0, 0, 40), (0, 0, -1), 2.0, radius=radius)], None, ETA)
    expected = 2.0 * 10.0 ** 2 / radius ** 2
    assert es.incident_power[0] == pytest.approx(expected, rel=1e-2)
    assert np.all(es.power >= 0) and np.all(np.isfinite(es.power))


def test_wide_beam_reaching_only_a_thin_mesh_between_its_rays():
    """A sphere of radius 0.5 mm off the axis of a beam of radius 30 mm: no ray of the sunflower hits it, its lit
    vertices still do (and carry the beam's irradiance times their projected area)."""
    V, F, N, A = sphere(0.5, 3, center=(7.0, 3.0, 0.0))
    light = BeamLight((0, 0, 40), (0, 0, -1), 1.0, radius=30.0)
    scene = make_scene(V, F)
    assert not np.any(scene.first_hit(light.ray_origins(), np.broadcast_to(light.direction, (BEAM_SAMPLES, 3))).hit)
    es = entry_samples(V, F, N, A, [light], scene, ETA)
    assert es.incident_power[0] == pytest.approx(0.5 ** 2 / 30.0 ** 2, rel=2e-2)


def test_beam_footprint_excludes_shadowed_and_back_vertices():
    """Big sphere with a small one 20 mm above it, beam along -z of radius 2.5 mm: only the small sphere's top is
    lit; the big sphere's vertices under it lie in the cylinder but are shadowed."""
    (V, F, N, A), n_big = big_and_small_spheres(3)
    light = BeamLight((0, 0, 50), (0, 0, -1), 1.0, radius=2.5)
    idx, cos = beam_footprint(light, V, N, A, make_scene(V, F))
    assert idx.size > 0 and np.all(idx >= n_big) and np.all(V[idx, 2] > 20.0) and np.all(cos > 0)
    in_cylinder = (np.hypot(V[:, 0], V[:, 1]) <= 2.5) & (N[:, 2] > 0)
    assert np.any(in_cylinder[:n_big])   # the big sphere's top is in the cylinder, and shadowed
    # a beam starting between the spheres (below the small one) lights the big sphere
    low = BeamLight((0, 0, 12), (0, 0, -1), 1.0, radius=2.5)
    idx, _ = beam_footprint(low, V, N, A, make_scene(V, F))
    assert idx.size > 0 and np.all(idx < n_big)


def test_check_exitance_turns_an_overflow_into_an_error_naming_the_light():
    lights = [DirectionalLight((0.0, 0.0, -1.0), 1e20)]
    check_exitance(np.ones((4, 3)), lights)
    check_exitance(np.zeros((0, 3)), lights)
    for bad, word in ((np.inf, "not finite"), (np.nan, "not finite"), (-1e-3, "negative")):
        M = np.ones((4, 3))
        M[2, 1] = bad
        with pytest.raises(LightError, match=rf"radiance is {word} for directional light 0 .*irradiance 1e\+20"):
            check_exitance(M, lights)
