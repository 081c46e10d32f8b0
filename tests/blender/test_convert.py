"""The add-on's conversions of Blender's units and lights (meshshade.blender.convert; no bpy needed).

Expected values are Blender's documented conventions worked out by hand here: a Blender unit is
``scale_length`` metres; a sun's strength is W/m² of irradiance; a point light of power P W radiates P/(4π) W/sr;
a light shines along its local -Z axis.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from meshshade.blender.convert import (BlenderLight, colour_groups, convert_lights, light_direction,
                                       mm_per_blender_unit, point_intensity, sun_irradiance,
                                       world_faces, world_vertices_mm)
from meshshade.errors import LightError, UnitsError
from meshshade.light import DirectionalLight, PointLight


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
              BlenderLight("Area", "AREA", 10.0, (1, 1, 1), M),
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
    assert "area light 'Area' left out" in notes[0] and "'Off' left out" in notes[1]


def test_no_usable_light_is_one_line_error():
    with pytest.raises(LightError, match="no sun, point or spot light.*area 'A'"):
        convert_lights([BlenderLight("A", "AREA", 1.0)], 1.0)
    with pytest.raises(LightError, match="no sun, point or spot light.*none"):
        convert_lights([], 1.0)
    with pytest.raises(LightError, match="must be finite"):
        convert_lights([BlenderLight("S", "SUN", float("nan"))], 1.0)


def test_colour_groups_keep_order_and_merge_equal_colours():
    a, b, c = (DirectionalLight((0, 0, -1), 1.0), PointLight((0, 0, 9), 1.0), DirectionalLight((0, 1, 0), 2.0))
    groups = colour_groups([(a, np.array([1.0, 1, 1])), (b, np.array([1.0, 0, 0])), (c, np.array([1.0, 1, 1]))])
    assert [g[1] for g in groups] == [[a, c], [b]]
    np.testing.assert_array_equal(groups[1][0], [1, 0, 0])
