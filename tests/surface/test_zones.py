"""Zones of the bake (meshshade/surface/zones.py): named methods and the assignment per entry sample."""
import numpy as np

from meshshade.surface import zones
from meshshade.surface.auto import AutoPlan
from meshshade.surface.zones import ZONES, assign_zones


def test_zones_are_named_and_indexed_by_their_constants():
    names = [z.name for z in ZONES]
    assert names == ["exact", "arc", "exact_near_arc_far", "exact_near", "arc_near", "exact_near_shared_far"]
    for name, z in zip(names, ZONES):
        assert getattr(zones, name.upper()) == names.index(name)
        assert z.inner_method in ("exact", "arc")
        assert z.outer_method in (None, "arc", "exact-shared")
        assert not (z.far_field and z.outer_method is not None)  # far-field zones gather only to r_near
    assert ZONES[zones.EXACT_NEAR_SHARED_FAR].solver_methods == ("exact", "exact")
    assert ZONES[zones.EXACT_NEAR_ARC_FAR].solver_methods == ("exact", "arc")
    assert ZONES[zones.ARC_NEAR].solver_methods == ("arc",)


def test_assign_zones_without_plan():
    area = np.array([True, False, True])
    np.testing.assert_array_equal(assign_zones(3, area, "off", "exact", None), [zones.EXACT] * 3)
    np.testing.assert_array_equal(assign_zones(3, area, "clustered", "exact", None),
                                  [zones.EXACT_NEAR, zones.EXACT, zones.EXACT_NEAR])
    np.testing.assert_array_equal(assign_zones(3, area, "direct", "arc", None),
                                  [zones.ARC_NEAR, zones.ARC, zones.ARC_NEAR])


def test_assign_zones_with_plan():
    # samples: 0 beam (not area), 1 curved exact, 2 flat exact, 3 flat arc, 4 curved arc
    area = np.array([False, True, True, True, True])
    plan = AutoPlan(kernel=np.zeros(5, np.int8), exact_geodesic=np.array([True, True, True, False, False]),
                    far_dipole=np.array([False, False, True, True, False]))
    got = assign_zones(5, area, "clustered", "exact", plan, "shared")
    np.testing.assert_array_equal(got, [zones.EXACT, zones.EXACT_NEAR_SHARED_FAR, zones.EXACT_NEAR, zones.ARC_NEAR,
                                        zones.ARC])
    got = assign_zones(5, area, "clustered", "exact", plan, "arc")
    assert got[1] == zones.EXACT_NEAR_ARC_FAR
    got = assign_zones(5, area, "clustered", "exact", plan, "none")
    assert got[1] == zones.EXACT
    # geodesic="arc" caps auto at arc geodesics (and the far zone of curved samples at arc)
    got = assign_zones(5, area, "clustered", "arc", plan, "shared")
    np.testing.assert_array_equal(got, [zones.ARC, zones.ARC, zones.ARC_NEAR, zones.ARC_NEAR, zones.ARC])
    got = assign_zones(5, area, "off", "exact", plan, "shared")
    np.testing.assert_array_equal(got, [zones.EXACT, zones.EXACT, zones.EXACT, zones.ARC, zones.ARC])
