"""The add-on's conversions of Blender's units and lights (meshshade.blender.convert; no bpy needed).

Expected values are Blender's documented conventions worked out by hand here: a Blender unit is
``scale_length`` metres; a sun's strength is W/m² of irradiance; a point light of power P W radiates P/(4π) W/sr;
a light shines along its local -Z axis.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from meshshade.blender.convert import (BlenderLight, BlenderWorld, colour_groups, convert_lights, convert_world,
                                       light_direction, mm_per_blender_unit, point_intensity, sun_irradiance,
                                       world_faces, world_vertices_mm)
from meshshade.blender.job import light_spec
from meshshade.errors import LightError, UnitsError
from meshshade.io import write_exr
from meshshade.light import AreaLight, DirectionalLight, EnvironmentLight, PointLight, parse_light_spec


def rot_x(deg):
    a = math.radians(deg)
    M = np.eye(4)
    M[1:3, 1:3] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    return M


def test_unit_scale_is_metres_per_unit():
    assert mm_per_blender_unit(1.0) == 1000.0        # Blender's default: 1 unit = 1 m
    assert mm_per_blender_unit(0.001) == 1.0
    assert mm_per_blender_unit(0.01) == 10.0
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(UnitsError):
            mm_per_blender_unit(bad)


def test_world_vertices_apply_the_transform_then_the_unit():
    M = rot_x(90.0)
    M[:3, :3] *= 2.0
    M[:3, 3] = (1.0, 2.0, 3.0)
    local = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    # by hand: Rx(90) sends y to z and z to -y; scaled by 2, moved by (1, 2, 3), 10 mm per unit
    np.testing.assert_allclose(world_vertices_mm(local, M, 10.0), [[10.0, 20.0, 50.0], [10.0, 0.0, 30.0]],
                               atol=1e-12)


def test_a_mirroring_transform_flips_the_winding():
    F = np.array([[0, 1, 2]])
    assert world_faces(F, np.eye(4)).tolist() == [[0, 1, 2]]
    assert world_faces(F, np.diag([-1.0, 1.0, 1.0, 1.0])).tolist() == [[0, 2, 1]]


def test_lights_shine_along_their_local_minus_z():
    np.testing.assert_allclose(light_direction(np.eye(4)), [0, 0, -1])
    np.testing.assert_allclose(light_direction(rot_x(90.0)), [0, 1, 0], atol=1e-15)
    M = np.eye(4)
    M[:3, :3] *= 5.0   # scale does not change the direction
    np.testing.assert_allclose(light_direction(M), [0, 0, -1])


def test_strengths():
    assert sun_irradiance(1000.0) == pytest.approx(1e-3)            # 1000 W/m^2 = 1e-3 W/mm^2
    assert point_intensity(4.0 * math.pi) == pytest.approx(1.0)     # 4 pi W over 4 pi sr
    assert point_intensity(100.0) == pytest.approx(7.957747154594767)   # 100 / (4 pi)


def test_convert_lights_sun_point_spot_and_what_is_left_out():
    M = np.eye(4)
    M[:3, 3] = (0.0, 0.0, 5.0)
    lights = [BlenderLight("Sun", "SUN", 500.0, (1.0, 0.5, 0.25), rot_x(90.0)),
              BlenderLight("Lamp", "POINT", 10.0, (1, 1, 1), M),
              BlenderLight("Spot", "SPOT", 10.0, (1, 1, 1), M, spot_size=math.radians(30), spot_blend=0.2),
              BlenderLight("Mesh", "MESH", 10.0, (1, 1, 1), M),
              BlenderLight("Off", "POINT", 0.0, (1, 1, 1), M)]
    out, notes = convert_lights(lights, mm_per_unit=10.0)
    assert len(out) == 3 and len(notes) == 2
    (sun, c_sun), (point, _), (spot, _) = out
    assert isinstance(sun, DirectionalLight) and sun.irradiance == pytest.approx(5e-4)
    np.testing.assert_allclose(sun.direction, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(c_sun, [1.0, 0.5, 0.25])
    assert isinstance(point, PointLight) and point.spot is None
    assert point.position == (0.0, 0.0, 50.0) and point.intensity == pytest.approx(10 / (4 * math.pi))
    assert spot.spot is not None and spot.spot.angle == pytest.approx(math.radians(30))
    assert spot.spot.axis == (0.0, 0.0, -1.0) and spot.intensity == point.intensity
    assert "mesh light 'Mesh' left out" in notes[0] and "'Off' left out" in notes[1]


def test_no_usable_light_is_one_line_error():
    with pytest.raises(LightError, match="no sun, point, spot or area light.*area 'A'"):
        convert_lights([BlenderLight("A", "AREA", 0.0)], 1.0)
    with pytest.raises(LightError, match="no sun, point, spot or area light.*none"):
        convert_lights([], 1.0, world=BlenderWorld(strength=0.0))
    with pytest.raises(LightError, match="must be finite"):
        convert_lights([BlenderLight("S", "SUN", float("nan"))], 1.0)


def test_colour_groups_keep_order_and_merge_equal_colours():
    a, b, c = (DirectionalLight((0, 0, -1), 1.0), PointLight((0, 0, 9), 1.0), DirectionalLight((0, 1, 0), 2.0))
    groups = colour_groups([(a, np.array([1.0, 1, 1])), (b, np.array([1.0, 0, 0])), (c, np.array([1.0, 1, 1]))])
    assert [g[1] for g in groups] == [[a, c], [b]]
    np.testing.assert_array_equal(groups[1][0], [1, 0, 0])


# ------------------------------------------------------------------------------------------------ area lights
def test_area_lights_shape_size_power_and_transform():
    """Blender's area light faces its local -Z, size along local X, size_y along Y (DISK: size is the diameter),
    the object's scale applied; power in W as Cycles' Lambertian emitter (radiance P / (pi A))."""
    M = rot_x(90.0)                      # local -Z -> world +Y, local Y -> world Z
    M[:3, 0] *= 2.0                      # scaled 2x along its local X
    M[:3, 3] = (1.0, -3.0, 2.0)
    cases = [("SQUARE", 0.5, 9.0, "rect", (10.0, 5.0)), ("RECTANGLE", 0.5, 0.25, "rect", (10.0, 2.5)),
             ("DISK", 0.5, 9.0, "disc", (5.0, 2.5)), ("ELLIPSE", 0.5, 0.25, "disc", (5.0, 1.25))]
    for shape, size, size_y, kind, mm in cases:
        out, notes = convert_lights([BlenderLight("A", "AREA", 40.0, (1, 1, 1), M, shape=shape, size=size,
                                                  size_y=size_y)], mm_per_unit=10.0)
        (light, colour), = out
        assert isinstance(light, AreaLight) and not notes
        assert light.shape == kind and light.size == pytest.approx(mm)
        assert light.position == pytest.approx((10.0, -30.0, 20.0))
        np.testing.assert_allclose(light.normal, [0, 1, 0], atol=1e-15)
        np.testing.assert_allclose(light.up, [0, 0, 1], atol=1e-15)        # local Y: the size_y axis
        assert light.power == 40.0
        u, v = light.axes()
        np.testing.assert_allclose(np.abs(u), [1, 0, 0], atol=1e-15)      # size along local X (scaled)
    _, notes = convert_lights([BlenderLight("A", "AREA", 40.0, (1, 1, 1), M, spread=math.radians(60))], 10.0)
    assert "spread" in notes[0]


# ------------------------------------------------------------------------------------------------ the World
def _exr(tmp_path):
    p = tmp_path / "sky.exr"
    write_exr(p, np.full((8, 16, 3), 0.5, np.float32))
    return p


def test_world_environment_texture_strength_rotation_and_axes(tmp_path):
    """Background strength S: W/(m^2 sr) per unit of the image -> S x 1e-6 W/(mm^2 sr); Mapping (Point) Z
    rotation in degrees, Texture type the other way; the add-on's meshes are Blender's world: up = z."""
    p = _exr(tmp_path)
    (light, colour), = convert_world(BlenderWorld(strength=2.0, image=str(p), mapping="POINT",
                                                  rotation=(0.0, 0.0, math.radians(30.0))))[0]
    assert isinstance(light, EnvironmentLight) and light.path == str(p)
    assert light.strength == pytest.approx(2e-6) and light.rotation_deg == pytest.approx(30.0) and light.up == "z"
    np.testing.assert_array_equal(colour, [1, 1, 1])
    (light, _), = convert_world(BlenderWorld(strength=1.0, image=str(p), mapping="TEXTURE",
                                             rotation=(0.0, 0.0, math.radians(30.0))))[0]
    assert light.rotation_deg == pytest.approx(-30.0)
    out, notes = convert_world(BlenderWorld(strength=1.0, image=str(p), mapping="POINT",
                                            rotation=(0.1, 0.0, 0.0), scale=(2.0, 1.0, 1.0)))
    assert len(out) == 1 and any("X and Y" in n for n in notes) and any("scale" in n for n in notes)


def test_world_constant_colour_other_setups_and_bad_files(tmp_path):
    (light, colour), = convert_world(BlenderWorld(strength=3.0, color=(0.2, 0.4, 0.8)))[0]
    assert light.is_uniform and light.strength == pytest.approx(3e-6)
    np.testing.assert_allclose(colour, [0.2, 0.4, 0.8])
    for world, needle in ((BlenderWorld(strength=0.0), "strength is zero"),
                          (BlenderWorld(color=(0.0, 0.0, 0.0)), "black"),
                          (BlenderWorld(other="a Sky Texture node into the Background's colour"), "Sky Texture"),
                          (BlenderWorld(image=""), "no file"),
                          (BlenderWorld(image=str(_exr(tmp_path)), projection="MIRROR_BALL"), "equirectangular")):
        out, notes = convert_world(world)
        assert out == [] and needle in notes[0]
    with pytest.raises(LightError, match="does not exist"):
        convert_world(BlenderWorld(image=str(tmp_path / "missing.exr")))
    # a World alone lights the scene; with lights it joins them
    out, _ = convert_lights([], 1.0, world=BlenderWorld(strength=1.0, color=(1, 1, 1)))
    assert len(out) == 1
    out, _ = convert_lights([BlenderLight("Sun", "SUN", 1.0)], 1.0, world=BlenderWorld(strength=1.0))
    assert len(out) == 2


def test_light_specs_of_the_new_lights_read_back_as_the_same_lights(tmp_path):
    p = _exr(tmp_path)
    env = parse_light_spec(f"env:{p}:2.5e-06:33.5:z")
    for light in (env, EnvironmentLight.uniform(0.125),
                  AreaLight((1.5, -2.0, 30.0), (0.0, 0.3, -1.0), "disc", (2.0, 3.0), 4.0, up=(0.0, 1.0, 0.2)),
                  AreaLight((1.5, -2.0, 30.0), (0.0, 0.3, -1.0), "rect", (2.0, 3.0), 4.0)):
        assert parse_light_spec(light_spec(light)) == light
    with pytest.raises(Exception, match="no --light spec"):
        light_spec(EnvironmentLight(np.arange(1.0, 9.0).reshape(2, 4)))


# --- a material slot's Principled BSDF -------------------------------------------------------------------------
def test_principled_medium_mean_free_path_and_colour():
    """radius x scale x mm per unit is 1/sigma_t' (docs/physics.md §17); the base colour is the medium's diffuse
    reflectance: the medium made from skin1's own reflectance and mean free path is skin1 (reference: the preset's
    coefficients, Jensen et al. 2001 Table 2, and its reflectance by the model's total of eq. (106))."""
    from meshshade.blender.convert import PrincipledSlot, principled_medium
    from meshshade.kernels.painted_reflectance import model_total_reflectance
    from meshshade.materials import Material

    skin = Material.preset("skin1")
    colour = model_total_reflectance(skin.albedo_prime, skin.eta, 0.0)
    mpu = 10.0                                              # 1 unit = 1 cm
    radius = 1.0 / (skin.sigma_t_prime * 0.05 * mpu)        # so that radius x 0.05 x 10 = 1/sigma_t'
    medium, notes = principled_medium(PrincipledSlot("Skin", tuple(colour), None, tuple(radius), 0.05, 1.3), mpu)
    np.testing.assert_allclose(medium["sigma_s_prime"], skin.sigma_s_prime, rtol=1e-6)
    np.testing.assert_allclose(medium["sigma_a"], skin.sigma_a, rtol=1e-5)
    assert medium["eta"] == 1.3 and medium["albedo_map"] is None and notes == []
    # twice the scale: half sigma_t', the same albedo
    twice, _ = principled_medium(PrincipledSlot("Skin", tuple(colour), None, tuple(radius), 0.1, 1.3), mpu)
    np.testing.assert_allclose(np.add(twice["sigma_s_prime"], twice["sigma_a"]), 0.5 * skin.sigma_t_prime, rtol=1e-12)


def test_principled_medium_image_weight_and_bad_slots():
    from meshshade.blender.convert import PrincipledSlot, principled_medium
    from meshshade.errors import MaterialError

    medium, notes = principled_medium(PrincipledSlot("Spot", None, "/x/spot.png", (1.0, 0.5, 0.25), 2.0, 1.4, 0.5),
                                      1.0)
    assert medium["albedo_map"] == "/x/spot.png"
    np.testing.assert_allclose(np.add(medium["sigma_s_prime"], medium["sigma_a"]), [0.5, 1.0, 2.0], rtol=1e-12)
    assert len(notes) == 1 and "Subsurface Weight 0.5" in notes[0]
    with pytest.raises(MaterialError, match="'Rock'.*Subsurface Weight is 0"):
        principled_medium(PrincipledSlot("Rock", (0.5, 0.5, 0.5), None, (1, 1, 1), 1.0, 1.3, 0.0), 1.0)
    with pytest.raises(MaterialError, match="'Flat'.*positive in every channel"):
        principled_medium(PrincipledSlot("Flat", (0.5, 0.5, 0.5), None, (1, 0, 1), 1.0, 1.3), 1.0)
    with pytest.raises(MaterialError, match="'White'.*Base Color.*must lie in"):
        principled_medium(PrincipledSlot("White", (1.0, 0.5, 0.5), None, (1, 1, 1), 1.0, 1.3), 1.0)


def test_principled_medium_radius_or_scale_from_an_image():
    """An image feeding Subsurface Radius takes the radius's place (the base at a radius of 1: 1/sigma_t' = image x
    Scale x mm per unit), one feeding Subsurface Scale the scale's (the base at a scale of 1); both: refused."""
    from meshshade.blender.convert import PrincipledSlot, principled_medium
    from meshshade.errors import MaterialError

    colour = (0.5, 0.4, 0.3)
    by_radius, notes = principled_medium(PrincipledSlot("R", colour, None, (9.0, 9.0, 9.0), 2.0, 1.3,
                                                        radius_image="/x/r.exr"), 10.0)
    assert by_radius["radius_map"] == "/x/r.exr" and notes == []
    np.testing.assert_allclose(np.add(by_radius["sigma_s_prime"], by_radius["sigma_a"]), 1.0 / 20.0, rtol=1e-12)
    by_scale, notes = principled_medium(PrincipledSlot("S", colour, None, (1.0, 0.5, 0.25), 7.0, 1.3,
                                                       scale_image="/x/s.png", radius_image_is_data=False), 10.0)
    assert by_scale["radius_map"] == "/x/s.png"
    np.testing.assert_allclose(np.add(by_scale["sigma_s_prime"], by_scale["sigma_a"]), [0.1, 0.2, 0.4], rtol=1e-12)
    assert len(notes) == 1 and "Non-Color" in notes[0]
    plain, _ = principled_medium(PrincipledSlot("P", colour, None, (1.0, 1.0, 1.0), 1.0, 1.3), 1.0)
    assert plain["radius_map"] is None
    with pytest.raises(MaterialError, match="'B'.*both Subsurface Radius and Subsurface Scale"):
        principled_medium(PrincipledSlot("B", colour, None, (1, 1, 1), 1.0, 1.3, radius_image="/a.png",
                                         scale_image="/b.png"), 1.0)
