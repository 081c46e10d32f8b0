"""Error policy of meshshade.kernels (meshshade/kernels/__init__.py): bad material parameters raise MaterialError
in every kernel; other bad arguments raise ValueError (the cylinder: MeshshadeError), never MaterialError; and a
good material, on the edges of eta's domain too, gives the kernel's value, not just no exception (issue 42).

The values are checked against tests/data/domain_edge_reference.csv, written offline in mpmath by
tools/references/precompute_domain_edge_references.py (imports nothing from meshshade: the planar dipole's
closed forms and quadratures, docs/physics.md eqs. (15)-(16); the t-integrals of the curvature coefficients, eqs.
(49)-(50); the Bessel series of the sphere and of the cylinder), and the dipole's cutoff radius against a tanh-sinh
quadrature of its tail at run time.
"""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from mpmath import mp, mpf

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
    "cylinder_exact_profile": lambda a, e: cylinder_exact_profile(0.1, 0.0, R0_opt=3.0, albedo_prime=a, eta=e),
    "cylinder_exact_profile_geodesic": lambda a, e: cylinder_exact_profile_geodesic(1.0, 0.3, R0_opt=3.0,
                                                                                   albedo_prime=a, eta=e),
}
BAD_MATERIALS = [(1.5, 1.3), (-0.1, 1.3), (np.nan, 1.3), (np.inf, 1.3), (0.9, 0.0), (0.9, -1.3), (0.9, np.nan),
                 (0.9, np.inf), ("skin", 1.3), (0.9, "glass"), (0.9, 0.5), (0.9, 2.6), (0.9, 60.0)]


@pytest.mark.parametrize("albedo,eta", BAD_MATERIALS)
@pytest.mark.parametrize("name", KERNELS)
def test_bad_material_raises_material_error(name, albedo, eta):
    with pytest.raises(MaterialError):
        KERNELS[name](albedo, eta)


@pytest.fixture(scope="module")
def edge_reference(reference_csv):
    """(eta, quantity, x, y) -> value of tests/data/domain_edge_reference.csv (alpha' = 0.9 throughout)."""
    header, rows = reference_csv("domain_edge_reference.csv")
    assert header["generator"] == "tools/references/precompute_domain_edge_references.py"
    assert {r["albedo_prime"] for r in rows} == {"0.9"}
    return {(float(r["eta"]), r["quantity"], r["x"], r["y"]): float(r["value"]) for r in rows}


def _dipole_tail_ratio_by_quadrature(r_opt, albedo, eta):
    """int_r^inf R_d 2 pi r dr / int_0^inf R_d 2 pi r dr by tanh-sinh quadrature in mpmath (30 digits), with R_d
    and the dipole parameters of tools/references/precompute_dipole_references.py (independent of meshshade)."""
    path = Path(__file__).resolve().parents[2] / "tools" / "references" / "precompute_dipole_references.py"
    spec = importlib.util.spec_from_file_location("dipole_ref", path)
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)
    with mp.workdps(30):
        p = ref.params(mpf(albedo), mpf(eta))
        r = mpf(r_opt)
        f = lambda t: 2 * mp.pi * t * ref.R_d(t, p)  # noqa: E731
        tail = mp.quad(f, [r, r + 1, r + 10, r + 100, mp.inf])
        total = mp.quad(f, [0, p["z_r"], p["z_v"], 10, 100, mp.inf])
        return float(tail / total)


def _expected(name, eta, ref):
    """(expected value or tuple of values, rtol) of ``KERNELS[name](0.9, eta)``; ``ref`` as edge_reference."""
    def v(quantity, x="", y=""):
        return ref[(eta, quantity, x, y)]

    a1, b1 = v("curv_a", "1.0"), v("curv_b", "1.0")
    if name == "check_material":
        return (0.9, eta), 0.0                                       # the inputs, as float64
    if name == "dipole_profile":
        return v("dipole_R_d", "1.0"), 1e-13                         # closed form in float64: rounding only
    if name == "dipole_total_reflectance":
        return v("dipole_total"), 1e-13
    if name == "dipole_tail_reflectance":
        return v("dipole_tail", "1.0"), 1e-13
    if name == "curvature_profile":
        # physics.md eq. (53), soft policy: min(R_d(rho) e^{s(delta)}, R_d(0) e^{s(delta_0)}), s(d) = d/sqrt(1 +
        # (d/2)^2), delta = k_n(phi) a + k_n(phi + pi/2) b with k1 = 0.1, k2 = 0, phi = 0.2; delta_0 = (k1+k2) a(0)
        delta = 0.1 * math.cos(0.2) ** 2 * a1 + 0.1 * math.sin(0.2) ** 2 * b1
        delta0 = 0.1 * v("curv_a", "0.0")
        soft = lambda d: d / math.sqrt(1.0 + (d / 2.0) ** 2)  # noqa: E731
        return min(v("dipole_R_d", "1.0") * math.exp(soft(delta)), v("dipole_R_d", "0.0") * math.exp(soft(delta0))), \
            1e-9                                                     # table interpolation < 4e-11 in a, b
    if name == "curvature_coefficients":
        return (v("curv_A", "1.0"), v("curv_B", "1.0")), 1e-9        # direct quadrature (test_curvature_kernel)
    if name == "curvature_ratios":
        return (a1, b1), 1e-9
    if name == "curvature_relative_coefficient":
        return a1 + b1, 1e-9                                          # C = alpha'(A + B)/R_d = a + b, eq. (51)
    if name == "curvature_validity":
        return 0.1 * (abs(a1) + abs(b1) + 1.0) <= 0.25, 0.0        # |k| (|a| + |b| + z_r) <= tol
    if name == "sphere_series_profile":
        # truncation below rtol = 1e-10 of the peak R_sph(0), which is < 5x the value at theta = 0.1 here
        return v("sphere_series", "10.0", "0.1"), 1e-9
    if name == "sphere_total_reflectance":
        return v("sphere_total", "10.0"), 1e-12                      # closed form eq. (33) in float64
    if name == "sphere_chord_dipole_profile":
        return v("sphere_chord", "10.0", "0.1"), 1e-13
    if name == "cylinder_exact_profile":
        return v("cylinder", "3.0", "theta=0.1 z=0"), 1e-8            # the kernel's default rtol = 1e-8
    if name == "cylinder_exact_profile_geodesic":
        return v("cylinder", "3.0", "rho=1.0 phi=0.3"), 1e-8
    raise AssertionError(f"no reference for {name}")


def _check_value(name, eta, ref):
    """The kernel's value at alpha' = 0.9 and ``eta`` equals the mpmath reference (not only: no exception)."""
    got = KERNELS[name](0.9, eta)
    if name == "CurvatureTable":                                     # the table's ratios at rho = 1
        got, (want, rtol) = got.ratios(1.0), _expected("curvature_ratios", eta, ref)
    elif name == "dipole_cutoff_radius":                             # where the tail is 1e-3 of the total
        assert np.isfinite(got) and got > 0, got
        got, want, rtol = _dipole_tail_ratio_by_quadrature(float(got), 0.9, eta), 1e-3, 1e-9
    else:
        want, rtol = _expected(name, eta, ref)
    if isinstance(want, bool):
        assert bool(got) is want and np.asarray(got).dtype == bool, (name, eta, got)
        return
    got = tuple(np.asarray(g, dtype=np.float64) for g in (got if isinstance(got, tuple) else (got,)))
    want = want if isinstance(want, tuple) else (want,)
    assert len(got) == len(want), (name, got)
    for g, w in zip(got, want):
        assert g.shape == () and g.dtype == np.float64, (name, g)
        np.testing.assert_allclose(g, w, rtol=rtol, atol=0.0, err_msg=f"{name} at eta = {eta}")


@pytest.mark.parametrize("name", KERNELS)
def test_good_material_is_accepted(name, edge_reference):
    """alpha' = 0.9, eta = 1.3: accepted, and the value is the mpmath reference's (a NaN or a wrong branch fails)."""
    _check_value(name, 1.3, edge_reference)


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
def test_eta_domain_edges_are_accepted_everywhere(name, eta, edge_reference):
    """One domain of eta for every kernel (kernels/optics.check_eta): [1, 2.5], both ends included; at each the
    kernel's value is the mpmath reference's."""
    _check_value(name, eta, edge_reference)


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
