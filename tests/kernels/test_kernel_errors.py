"""Error policy of meshshade.kernels (meshshade/kernels/__init__.py): bad material parameters raise MaterialError
in every kernel; other bad arguments raise ValueError (the cylinder: MeshshadeError), never MaterialError."""
from __future__ import annotations

import numpy as np
import pytest

from meshshade.errors import MaterialError, MeshshadeError
from meshshade.kernels.curvature import (CurvatureTable, curvature_coefficients, curvature_profile, curvature_ratios,
                                         curvature_relative_coefficient, curvature_validity)
from meshshade.kernels.cylinder import cylinder_exact_profile, cylinder_exact_profile_geodesic
from meshshade.kernels.dipole import (dipole_cutoff_radius, dipole_profile, dipole_tail_reflectance,
                                      dipole_total_reflectance)
from meshshade.kernels.optics import check_material
from meshshade.kernels.sphere import sphere_chord_dipole_profile, sphere_series_profile, sphere_total_reflectance

#: every kernel that takes a material, as a function of (albedo_prime, eta)
KERNELS = {
    "check_material": lambda a, e: check_material(a, e),
    "dipole_profile": lambda a, e: dipole_profile(1.0, albedo_prime=a, eta=e),
    "dipole_total_reflectance": lambda a, e: dipole_total_reflectance(albedo_prime=a, eta=e),
    "dipole_tail_reflectance": lambda a, e: dipole_tail_reflectance(1.0, albedo_prime=a, eta=e),
    "dipole_cutoff_radius": lambda a, e: dipole_cutoff_radius(1e-3, albedo_prime=a, eta=e),
    "curvature_profile": lambda a, e: curvature_profile(1.0, 0.2, k1_opt=0.1, k2_opt=0.0, albedo_prime=a, eta=e),
    "curvature_coefficients": lambda a, e: curvature_coefficients(1.0, albedo_prime=a, eta=e),
    "curvature_ratios": lambda a, e: curvature_ratios(1.0, albedo_prime=a, eta=e),
    "curvature_relative_coefficient": lambda a, e: curvature_relative_coefficient(1.0, albedo_prime=a, eta=e),
    "curvature_validity": lambda a, e: curvature_validity(1.0, 0.1, albedo_prime=a, eta=e),
    "CurvatureTable": lambda a, e: CurvatureTable(a, e, 4.0),
    "sphere_series_profile": lambda a, e: sphere_series_profile(0.1, R0_opt=10.0, albedo_prime=a, eta=e),
    "sphere_total_reflectance": lambda a, e: sphere_total_reflectance(R0_opt=10.0, albedo_prime=a, eta=e),
    "sphere_chord_dipole_profile": lambda a, e: sphere_chord_dipole_profile(0.1, R0_opt=10.0, albedo_prime=a, eta=e),
    "cylinder_exact_profile": lambda a, e: cylinder_exact_profile(0.1, 0.0, R0_opt=10.0, albedo_prime=a, eta=e),
    "cylinder_exact_profile_geodesic": lambda a, e: cylinder_exact_profile_geodesic(1.0, 0.3, R0_opt=10.0,
                                                                                   albedo_prime=a, eta=e),
}
BAD_MATERIALS = [(1.5, 1.3), (-0.1, 1.3), (np.nan, 1.3), (np.inf, 1.3), (0.9, 0.0), (0.9, -1.3), (0.9, np.nan),
                 (0.9, np.inf), ("skin", 1.3), (0.9, "glass"), (0.9, 0.5), (0.9, 2.6), (0.9, 60.0)]


@pytest.mark.parametrize("albedo,eta", BAD_MATERIALS)
@pytest.mark.parametrize("name", KERNELS)
def test_bad_material_raises_material_error(name, albedo, eta):
    with pytest.raises(MaterialError):
        KERNELS[name](albedo, eta)


@pytest.mark.parametrize("name", KERNELS)
def test_good_material_is_accepted(name):
    KERNELS[name](0.9, 1.3)


@pytest.mark.parametrize("name", ["dipole_profile", "curvature_profile", "curvature_ratios",
                                  "sphere_total_reflectance"])
def test_bad_material_in_an_array_raises_material_error(name):
    with pytest.raises(MaterialError):
        KERNELS[name](np.array([0.5, 0.9, 1.2]), 1.3)
    with pytest.raises(MaterialError):
        KERNELS[name](0.9, np.array([1.3, 0.0]))


def test_single_material_kernels_reject_material_arrays_with_material_error():
    for name in ("CurvatureTable", "sphere_series_profile", "cylinder_exact_profile"):
        with pytest.raises(MaterialError):
            KERNELS[name](np.array([0.5, 0.9]), 1.3)


def test_cylinder_needs_a_positive_albedo():
    with pytest.raises(MaterialError):
        KERNELS["cylinder_exact_profile"](0.0, 1.3)


def test_material_error_names_the_value():
    with pytest.raises(MaterialError, match=r"albedo_prime .*\[0, 1\], got 1\.5"):
        dipole_profile(1.0, albedo_prime=1.5, eta=1.3)
    with pytest.raises(MaterialError, match=r"eta .*must be finite and lie in \[1, 2\.5\].*got 0\.0"):
        curvature_ratios(1.0, albedo_prime=0.9, eta=[1.3, 0.0])
    with pytest.raises(MaterialError, match=r"eta .*\[1, 2\.5\].*got 100\.0"):
        dipole_profile(1.0, albedo_prime=0.9, eta=100.0)


@pytest.mark.parametrize("eta", [1.0, 1.7, 2.5])
@pytest.mark.parametrize("name", KERNELS)
def test_eta_domain_edges_are_accepted_everywhere(name, eta):
    """One domain of eta for every kernel (kernels/optics.check_eta): [1, 2.5], both ends included."""
    KERNELS[name](0.9, eta)


@pytest.mark.parametrize("call", [
    lambda: curvature_profile(-1.0, 0.0, k1_opt=0.1, k2_opt=0.0, albedo_prime=0.9, eta=1.3),
    lambda: curvature_profile(1.0, 0.0, k1_opt=np.inf, k2_opt=0.0, albedo_prime=0.9, eta=1.3),
    lambda: curvature_profile(1.0, 0.0, k1_opt=0.1, k2_opt=0.0, albedo_prime=0.9, eta=1.3, policy="linear"),
    lambda: curvature_ratios(np.nan, albedo_prime=0.9, eta=1.3),
    lambda: CurvatureTable(0.9, 1.3, -1.0),
    lambda: sphere_series_profile(4.0, R0_opt=10.0, albedo_prime=0.9, eta=1.3),
    lambda: sphere_series_profile(0.1, R0_opt=-1.0, albedo_prime=0.9, eta=1.3),
    lambda: sphere_total_reflectance(R0_opt=np.array([1.0, -1.0]), albedo_prime=0.9, eta=1.3),
])
def test_other_bad_arguments_raise_value_error_not_material_error(call):
    with pytest.raises(ValueError) as info:
        call()
    assert not isinstance(info.value, MaterialError)


@pytest.mark.parametrize("kwargs", [dict(R0_opt=0.4), dict(R0_opt=np.nan), dict(rtol=np.nan)])
def test_cylinder_geometry_errors_are_meshshade_errors_not_material_errors(kwargs):
    args = {"R0_opt": 10.0, "albedo_prime": 0.9, "eta": 1.3, **kwargs}
    with pytest.raises(MeshshadeError) as info:
        cylinder_exact_profile(0.1, 0.0, **args)
    assert not isinstance(info.value, MaterialError)
