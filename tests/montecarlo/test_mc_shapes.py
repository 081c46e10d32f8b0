"""Monte Carlo on exact shapes (meshshade.montecarlo.shapes): exact exit distances, ring tallies, scattering order.

References, all independent of the code under test:
* the singly scattered profile of the half-space, a closed-form depth integral (done here by scipy quadrature
  after an exact inner integral): R1(r) = sigma_s int_0^inf exp(-sigma_t (z + l)) p(-z/l) (1 - F(z/l)) z / l^3 dz,
  l = sqrt(r^2 + z^2), p the Henyey-Greenstein phase function per steradian, F Fresnel's reflectance from inside;
* the total diffuse reflectance of the half-space from adding-doubling (iadpython, a thick slab index-matched
  below);
* geometry: a sphere and a cylinder of radius 2000 mm give the half-space's rings (at every cylinder azimuth).
"""
from __future__ import annotations

import math

import iadpython as iad
import numpy as np
import pytest
from scipy.integrate import quad

from meshshade.errors import ParameterError
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile


def fresnel_inside(cos_i, eta):
    """Unpolarised Fresnel reflectance from the medium (index eta) into air at incidence cos_i (written out)."""
    if eta == 1.0:
        return 0.0
    sin_t = eta * math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    if sin_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t * sin_t)
    rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rp = (eta * cos_t - cos_i) / (eta * cos_t + cos_i)
    return 0.5 * (rs * rs + rp * rp)


def single_scatter_ring(sigma_s, sigma_a, g, eta, lo, hi):
    """Ring average over lo <= r < hi of R1(r) [mm^-2] per unit entering power (module docstring). In polar
    coordinates r = rho sin(a), z = rho cos(a) the integrand's 2 pi r z / l^3 dr dz becomes 2 pi sin a cos a
    drho da and the rho integral is exact."""
    st = sigma_s + sigma_a

    def f(a):
        c, s = math.cos(a), math.sin(a)
        k = st * (1.0 + c)
        r1 = lo / s
        r2 = hi / s
        inner = (math.exp(-k * r1) - math.exp(-k * r2)) / k
        p = (1 - g * g) / (4 * math.pi * (1 + g * g + 2 * g * c) ** 1.5)   # cos(theta) = -cos(a)
        return 2 * math.pi * s * c * p * (1.0 - fresnel_inside(c, eta)) * inner

    val, _ = quad(f, 1e-12, math.pi / 2, limit=400, epsabs=0, epsrel=1e-10)
    return sigma_s * val / (math.pi * (hi * hi - lo * lo))


CASES = [(1.0, 0.01, 0.0, 1.0), (1.0, 0.01, 0.0, 1.3), (1.0, 0.1, 0.8, 1.3), (2.0, 0.05, 0.5, 1.4)]


@pytest.mark.parametrize("sigma_s_prime, sigma_a, g, eta", CASES)
def test_single_scattering_of_the_half_space_is_exact(sigma_s_prime, sigma_a, g, eta):
    m = Material(sigma_s_prime, sigma_a, eta, g)
    s = np.array([0.05, 0.2, 0.5, 1.0, 2.0])
    p = shape_mc_profile(m, s, shape="plane", photons=400_000, seed=3)
    sigma_s = sigma_s_prime / (1 - g)
    for j in range(s.size):
        ref = single_scatter_ring(sigma_s, sigma_a, g, eta, p.lo[j], p.hi[j])
        got, err = p.single[0, j], p.single_stderr[0, j]
        if ref * math.pi * (p.hi[j] ** 2 - p.lo[j] ** 2) * 400_000 < 50:   # fewer than ~50 photons expected
            continue
        assert abs(got - ref) < 4.0 * err + 1e-9, (s[j], got, ref, err)


@pytest.mark.parametrize("sigma_s_prime, sigma_a, g, eta", CASES)
def test_total_diffuse_reflectance_of_the_half_space_matches_adding_doubling(sigma_s_prime, sigma_a, g, eta):
    m = Material(sigma_s_prime, sigma_a, eta, g)
    p = shape_mc_profile(m, [1.0], shape="plane", photons=400_000, seed=5)
    sigma_s = sigma_s_prime / (1 - g)
    ref = iad.Sample(a=sigma_s / (sigma_s + sigma_a), b=(sigma_s + sigma_a) * 400.0, g=g, n=eta, n_above=1.0,
                     n_below=eta, quad_pts=32)
    R_total = float(ref.rt()[0])                       # specular + diffuse, per unit incident power
    r_spec = ((eta - 1.0) / (eta + 1.0)) ** 2          # normal incidence
    diffuse = (R_total - r_spec) / (1.0 - r_spec)      # per unit entering power, as the Monte Carlo's
    assert abs(p.total[0] - diffuse) < 4.0 * p.total_stderr[0] + 1e-3, (p.total[0], diffuse, p.total_stderr[0])


def test_a_large_sphere_and_cylinder_give_the_half_spaces_rings():
    m = Material(1.0, 0.05, 1.3, 0.0)
    s = np.array([0.1, 0.5, 1.0, 2.0])
    kw = dict(photons=300_000, seed=11)
    plane = shape_mc_profile(m, s, shape="plane", **kw)
    others = [shape_mc_profile(m, s, shape="sphere", radius_mm=2000.0, **kw),
              shape_mc_profile(m, s, shape="cylinder", radius_mm=2000.0, azimuth_deg=0.0, **kw),
              shape_mc_profile(m, s, shape="cylinder", radius_mm=2000.0, azimuth_deg=90.0, **kw),
              shape_mc_profile(m, s, shape="cylinder", radius_mm=2000.0, azimuth_deg=45.0, sector_deg=45.0, **kw)]
    for o in others:
        err = np.hypot(o.stderr[0], plane.stderr[0])
        assert np.all(np.abs(o.reflectance[0] - plane.reflectance[0]) < 4.0 * err), (o, o.reflectance[0],
                                                                                     plane.reflectance[0], err)


def test_curvature_shows_on_a_small_sphere():
    """A 2 mm sphere of a weakly absorbing medium: light that would leave a half-space far away comes back around
    the sphere, so the far rings are brighter than the half-space's (as the exact diffusion solution says)."""
    m = Material(1.0, 0.01, 1.3, 0.0)
    s = np.array([3.0, 5.0])
    sphere = shape_mc_profile(m, s, shape="sphere", radius_mm=2.0, photons=100_000, seed=2)
    plane = shape_mc_profile(m, s, shape="plane", photons=100_000, seed=2)
    assert np.all(sphere.reflectance[0] > 2.0 * plane.reflectance[0])


def test_runs_are_reproducible_and_channels_share_runs():
    m = Material((1.0, 1.0, 2.0), (0.01, 0.01, 0.05), 1.3, 0.0)
    a = shape_mc_profile(m, [0.5, 1.0], shape="plane", photons=20_000, seed=7)
    b = shape_mc_profile(m, [0.5, 1.0], shape="plane", photons=20_000, seed=7)
    c = shape_mc_profile(m, [0.5, 1.0], shape="plane", photons=20_000, seed=8)
    np.testing.assert_array_equal(a.reflectance, b.reflectance)
    assert not np.array_equal(a.reflectance, c.reflectance)
    np.testing.assert_array_equal(a.reflectance[0], a.reflectance[1])    # equal coefficients: one run
    assert not np.array_equal(a.reflectance[0], a.reflectance[2])
    assert "ShapeProfile plane" in repr(a)


@pytest.mark.parametrize("kwargs, match", [
    (dict(shape="saddle"), "exact on plane, sphere, cylinder"),
    (dict(shape="sphere"), "needs a radius"),
    (dict(shape="sphere", radius_mm=1.0), "half the circumference"),
    (dict(photons=3), "photons must be"),
    (dict(shape="cylinder", radius_mm=50.0, sector_deg=60.0), "sector half-width"),
])
def test_bad_arguments_are_one_line_errors(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        shape_mc_profile(Material(1.0, 0.01, 1.3), [2.0, 4.0], **kwargs)


def test_sphere_agrees_with_the_mesh_engine_on_an_icosphere():
    """An independent code path: the mesh engine (Embree boundary, level-6 icosphere, exits at their exact
    positions on the facets) against the exact sphere, R = 10 mm, beyond the first millimetre (within the noise
    and 2 % for the facets)."""
    from meshshade.montecarlo import mc_profile
    from meshshade.profiles import Shape

    m = Material(1.0, 0.02, 1.3, 0.0)
    s = np.array([1.0, 2.0, 5.0, 10.0])
    exact = shape_mc_profile(m, s, shape="sphere", radius_mm=10.0, photons=400_000, seed=4)
    mesh, err = mc_profile(m, s, shape=Shape.make("sphere", 10.0), photons=400_000, seed=4, subdivisions=6,
                           return_stderr=True)
    tol = 4.0 * np.hypot(exact.stderr[0], err[0]) + 0.02 * exact.reflectance[0]
    assert np.all(np.abs(mesh[0] - exact.reflectance[0]) < tol), (mesh[0], exact.reflectance[0], tol)


def test_cylinder_rings_that_wrap_around_are_nan():
    p = shape_mc_profile(Material(1.0, 0.01, 1.3), [1.0, 4.0], shape="cylinder", radius_mm=1.0, photons=2_000)
    assert np.isfinite(p.reflectance[0, 0]) and np.isnan(p.reflectance[0, 1])   # pi R = 3.14 mm around
    q = shape_mc_profile(Material(1.0, 0.01, 1.3), [4.0], shape="cylinder", radius_mm=1.0, azimuth_deg=90.0,
                         photons=2_000)
    assert np.isfinite(q.reflectance[0, 0])                                         # along the axis: no wrap


def test_profile_command_takes_mc_on_plane_sphere_and_cylinder(tmp_path, capsys):
    from meshshade.cli.main import main

    csv = tmp_path / "p.csv"
    assert main(["profile", "--sigma-s-prime", "1", "--sigma-a", "0.01", "--models", "dipole,mc", "--distances",
                 "0.1,1,2", "--photons", "20000", "--seed", "4", "--csv", str(csv)]) == 0
    lines = csv.read_text().splitlines()
    assert lines[0] == "model,channel,distance_mm,reflectance_per_mm2,stderr_per_mm2"
    mc = [ln.split(",") for ln in lines[1:] if ln.startswith("mc,r,")]
    direct = shape_mc_profile(Material(1.0, 0.01, 1.3), [0.1, 1.0, 2.0], photons=20_000, seed=4)
    np.testing.assert_allclose([float(r[3]) for r in mc], direct.reflectance[0], rtol=1e-15)
    np.testing.assert_allclose([float(r[4]) for r in mc], direct.stderr[0], rtol=1e-5)
    assert all(ln.split(",")[4] == "" for ln in lines[1:] if ln.startswith("dipole,"))
    capsys.readouterr()
    for shape in (["--shape", "sphere", "--radius", "10"],
                  ["--shape", "cylinder", "--radius", "10", "--azimuth", "90"]):
        assert main(["profile", "--material", "marble", "--models", "mc", "--distances", "1,2", "--photons", "5000",
                     *shape]) == 0
        assert "±" in capsys.readouterr().out
    assert main(["profile", "--material", "marble", "--models", "mc", "--shape", "saddle", "--radius", "5",
                 "--distances", "1"]) == 2
    err = capsys.readouterr().err
    assert "exact on a plane, sphere, cylinder, cavity or bore" in err and err.count("\n") == 1
