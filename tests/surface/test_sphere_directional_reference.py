"""A sphere under a directional light against its exact integrated reference (issue 13's accuracy target).

Scene: the bench's ``sphere_r20_directional`` (meshshade/bench/scenes.py: radius 20 mm, 1.5 mm edges at icosphere
level 4), sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3, a directional light along -z, ``model="exact-sphere"``.
The reference (tests/surface/_sphere_reference.py) integrates the exact sphere series over the lit cap with the
Fresnel entry written out independently; it is checked here first (convergence, energy, planar limit, Fresnel
edges), then the bake is held to it. Errors are relative, over every vertex whose reference exitance exceeds
1e-3 of its peak (here the whole sphere, shadow side included).

What limits the bake, measured (docs/physics.md §8.2): the near-field quadrature (the source-patch rule of
pair_kernel.patch_average_factor, fixed: -2.5 % bias on the lit side at level 4 before), the cutoff radius from the
planar dipole's tail (39.7 mm < the 62.8 mm half circumference: the far shadow side loses up to 72 % at the
default ``cutoff_tol``; these tests pass ``cutoff_tol=1e-8``, which reaches the antipode) and the local radius of
the quadric curvature fit (0.45 % short at level 4, +1.8 % at the antipode with the direct sum).
"""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.kernels.dipole import dipole_profile, dipole_total_reflectance
from meshshade.kernels.sphere import sphere_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport.baking import bake
from meshshade.surface.patch_average import PATCH_AVERAGE_RADII, patch_average_factor
from meshshade.transport import BakeOptions, SurfaceOptions

_spec = importlib.util.spec_from_file_location("_sphere_reference", Path(__file__).with_name("_sphere_reference.py"))
ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ref)

R = 20.0                                            # mm, radius (the bench's sphere_r20_directional)
MAT = Material(1.0, 0.01, 1.3, name="low absorption")
SUN = DirectionalLight((0.0, 0.0, -1.0), 1.0)
FULL_CUTOFF = 1e-8                                  # cutoff_tol whose radius (88 mm) covers the whole sphere


def _alpha_T(radius, material=MAT):
    st = float(material.sigma_t_prime[0])
    return float(sphere_total_reflectance(R0_opt=radius * st, albedo_prime=float(material.albedo_prime[0]),
                                          eta=material.eta))


# ------------------------------------------------------------------------------------------------ the reference
def test_reference_converges_under_refinement():
    beta = np.linspace(0.0, np.pi, 61)
    M = ref.sphere_directional_exitance(beta, R_mm=R, material=MAT)
    fine = ref.sphere_directional_exitance(beta, R_mm=R, material=MAT, n_gamma=32, n_psi=48)
    mask = fine > 1e-3 * fine.max()
    assert mask.all()                                # low absorption: the whole sphere is above 1e-3 of the peak
    assert np.max(np.abs(M / fine - 1)) < 1e-6      # measured 3e-8


def test_reference_returns_the_sphere_albedo_of_the_entering_power():
    """int M dA = (power entering) x alpha' T (closed form, docs/physics.md eq. (33)): a check of the geometry of
    the transport integral (lit arc, Jacobian, symmetry factor) independent of the kernel's shape."""
    out = ref.exitant_power(R_mm=R, material=MAT)
    entering = ref.entering_power(R_mm=R, eta=MAT.eta)
    assert out == pytest.approx(entering * _alpha_T(R), rel=1e-8)    # measured 8e-14


def test_reference_planar_limit():
    """On a huge sphere the sub-light point sees normal incidence over the whole kernel: M(0) -> F_t(1) alpha' T
    (the cosine and Fresnel factors vary by (s/R)^2 ~ 1e-7 over the kernel's reach)."""
    big = 1e4
    M0 = ref.sphere_directional_exitance(np.array([0.0]), R_mm=big, material=MAT)[0]
    assert M0 == pytest.approx(float(ref.fresnel_transmittance(1.0, MAT.eta)) * _alpha_T(big), rel=1e-6)


def test_reference_fresnel_edges():
    eta = 1.3
    assert ref.fresnel_transmittance(1.0, eta) == pytest.approx(1.0 - ((eta - 1) / (eta + 1)) ** 2, rel=1e-14)
    assert ref.fresnel_transmittance(0.0, eta) == pytest.approx(0.0, abs=1e-15)
    assert np.all(ref.fresnel_transmittance(np.linspace(0.1, 1, 10), 1.0) == pytest.approx(1.0, abs=1e-15))


# ------------------------------------------------------------------------------------------------ the patch rule
KW = {"albedo_prime": 1 / 1.01, "eta": 1.3}


def _brute_disc_average(s, a):
    """Average of the dipole over the disc of radius a centred at distance s (optical units): Gauss-Legendre in
    polar coordinates about the disc's centre (the dipole is analytic in the plane: no singular point; a wide
    disc needs the nodes to resolve the kernel's width, one transport length, near its rim)."""
    n = 240 if a < 5 else 800
    x, w = np.polynomial.legendre.leggauss(n)
    rho, w_rho = 0.5 * a * (x + 1.0), 0.5 * a * w
    phi, w_phi = np.pi * (x + 1.0), np.pi * w
    d = np.sqrt(s * s + rho[:, None] ** 2 + 2.0 * s * rho[:, None] * np.cos(phi[None, :]))
    return float(np.sum(dipole_profile(d, **KW) * (rho * w_rho)[:, None] * w_phi[None, :])) / (np.pi * a * a)


@pytest.mark.parametrize("a", [0.05, 0.7, 3.0, 20.0])
def test_patch_rule_is_the_disc_average_off_the_self_pair(a):
    s = a * np.array([0.3, 0.999, 1.0, 1.2, 2.0, 3.9])
    got = patch_average_factor(s, np.full(s.size, a), sigma_t_prime=1.0, **KW)
    want = np.array([_brute_disc_average(x, a) for x in s]) / dipole_profile(s, **KW)
    assert np.allclose(got, want, rtol=2e-4, atol=0)       # the table's bicubic interpolation: < 1e-4 measured


def _lattice_total(points, cell_area):
    """sum over lattice sites of cell_area R_d(|y|) x patch factor (as the bake weighs them), receiver at 0."""
    r = np.linalg.norm(points, axis=1)
    a = np.full(r.size, np.sqrt(cell_area / np.pi))
    f = np.ones(r.size)
    near = r < PATCH_AVERAGE_RADII * a
    f[near] = patch_average_factor(r[near], a[near], sigma_t_prime=1.0, **KW)
    return cell_area * float(np.sum(dipole_profile(r, **KW) * f))


@pytest.mark.parametrize("h", [0.3, 0.75, 1.5, 3.0, 6.0])
def test_patch_rule_returns_the_dipole_total_on_lattices(h):
    """Uniform light on a plane: the exitance at a vertex is E F_t alpha' T_d whatever the spacing h (in transport
    lengths). The self term is calibrated on the triangular lattice (exact here, in a rotated and independently
    built copy); a square lattice (a different triangulation) stays within 0.8 % (before: -1.2 % to -2.5 % on both)."""
    n = int(100 / h) + 2
    i, j = (g.ravel() for g in np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1)))
    c, s = np.cos(0.3), np.sin(0.3)
    hexa = np.stack([h * (i + 0.5 * j), h * np.sqrt(3) / 2 * j], axis=1) @ np.array([[c, s], [-s, c]])
    square = np.stack([h * i, h * j], axis=1)
    total = float(dipole_total_reflectance(**KW))
    for pts, area, tol in ((hexa, np.sqrt(3) / 2 * h * h, 1e-4), (square, h * h, 1e-2)):
        pts = pts[np.linalg.norm(pts, axis=1) < 100.0]     # the dipole's tail beyond 100: below 1e-7 of the total
        assert _lattice_total(pts, area) == pytest.approx(total, rel=tol)


# ------------------------------------------------------------------------------------------------ the bake
def _errors(result, mesh, channel=0):
    """(mean, max) relative error over vertices above 1e-3 of the reference's peak: all, lit side, shadow side."""
    u = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1, keepdims=True)
    beta = np.arccos(np.clip(u[:, 2], -1.0, 1.0))
    M_ref = ref.sphere_directional_exitance(beta, R_mm=R, material=result.material, channel=channel)
    e = np.abs(result.radiance[:, channel] / M_ref - 1.0)
    mask = M_ref > 1e-3 * M_ref.max()
    lit = beta < 0.5 * np.pi
    return {k: (float(e[m].mean()), float(e[m].max())) for k, m in
            (("all", mask), ("lit", mask & lit), ("shadow", mask & ~lit))}


@pytest.fixture(scope="module")
def level3():
    return Mesh(*icosphere(R, 3))


@pytest.mark.parametrize("transport", ["direct", "hierarchical"])
def test_level3_bake_against_the_reference(level3, transport):
    """Level 3 (3 mm edges, 3 transport lengths): lit side measured 1.1 %/3.4 % (direct) and 1.15 %/3.5 %
    (hierarchical), mean/max; before the near-field fix 3.3 %/5.5 % (a -3.3 % bias). The whole sphere (2.4 %/8.0 %
    direct, 2.0 %/7.3 % hierarchical) is dominated by the quadric fit's local radius, 1.8 % short at this level."""
    res = bake(level3, MAT, [SUN], BakeOptions(
        model="exact-sphere", surface=SurfaceOptions(cutoff_tol=FULL_CUTOFF, transport=transport)))
    assert res.stats["transport"] == transport
    err = _errors(res, level3)
    assert err["lit"][0] <= 0.015 and err["lit"][1] <= 0.04, err
    assert err["all"][0] <= 0.026 and err["all"][1] <= 0.085, err


def test_level4_meets_the_issue_target():
    """Issue 13: mean <= 0.5 %, max <= 2 % at level 4 over every vertex above 1e-3 of the peak. Measured with the
    default (hierarchical) transport: 0.42 %/1.60 % (before the fix 1.41 %/4.22 %); lit 0.35 %/1.60 %, shadow
    0.50 %/1.57 %; level 5: 0.11 %/0.74 % (before 0.78 %/2.21 %)."""
    mesh = Mesh(*icosphere(R, 4))
    res = bake(mesh, MAT, [SUN], BakeOptions(model="exact-sphere", surface=SurfaceOptions(cutoff_tol=FULL_CUTOFF)))
    err = _errors(res, mesh)
    assert err["all"][0] <= 0.005 and err["all"][1] <= 0.02, err
    assert err["lit"][0] <= 0.004, err


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the direct sum's shadow side follows the quadric fit's local radius "
                   "(geometry/curvature.py: 19.91 mm for 20 mm at level 4), +0.3 to +1.8 % from the terminator to "
                   "the antipode: mean 0.59 %, max 1.81 % (lit side 0.35 %/1.55 %); "
                   "with the exact radius 0.23 %/1.61 %")
def test_level4_direct_sum_meets_the_issue_target():
    mesh = Mesh(*icosphere(R, 4))   # ~40 s: every pair of 2562 vertices with exact polyhedral geodesics
    res = bake(mesh, MAT, [SUN], BakeOptions(
        model="exact-sphere", surface=SurfaceOptions(cutoff_tol=FULL_CUTOFF, transport="direct")))
    err = _errors(res, mesh)
    assert err["lit"][0] <= 0.004 and err["lit"][1] <= 0.02, err        # the near field itself holds
    assert err["all"][0] <= 0.005 and err["all"][1] <= 0.02, err


@pytest.mark.xfail(strict=True, reason="the default cutoff (cutoff_tol 1e-4 of the planar dipole's total: 39.7 mm) "
                   "is shorter than the sphere's half circumference (62.8 mm), and the sphere kernel's far tail is "
                   "far above the dipole's: the shadow side loses up to 70 % (surface/gather.py cutoff_radii)")
def test_default_cutoff_reaches_the_shadow_side(level3):
    res = bake(level3, MAT, [SUN], BakeOptions(model="exact-sphere"))
    err = _errors(res, level3)
    assert err["shadow"][1] <= 0.1, err
