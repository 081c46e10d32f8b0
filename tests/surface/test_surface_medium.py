"""The surface models' record of a material (meshshade/surface/medium.py): made once per bake, read by every stage.

References: the cutoff and far-field radii are checked against the dipole's reflectance integrated here by scipy's
quad from Jensen's closed form written out in this file (eq. (15): alpha'/(4 pi) [z_r (1 + mu d_r) e^{-mu d_r} /
d_r^3 + z_v (1 + mu d_v) e^{-mu d_v} / d_v^3], with mu, z_r, z_v from the Groenhuis polynomial, Jensen et al. 2001
eq. 5), not against the functions that compute them. The counts are cProfile's.
"""
from __future__ import annotations

import cProfile
import math
import pstats

import numpy as np
import pytest
from scipy.integrate import quad

from meshshade.errors import ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.surface.hierarchical import SurfaceTransport
from meshshade.surface.medium import CHECK_CUTOFF_TOL, SurfaceMedium, surface_medium
from meshshade.surface.options import SurfaceOptions
from meshshade.transport import BakeOptions, bake

SKIN = Material.preset("skin1")


def _jensen_profile(r_mm, sigma_s, sigma_a, eta):
    """Jensen's planar dipole R_d(r) [1/mm^2] written out (Jensen et al. 2001 eqs. 4-5)."""
    st = sigma_s + sigma_a
    alb = sigma_s / st
    f_dr = -1.440 / eta ** 2 + 0.710 / eta + 0.668 + 0.0636 * eta
    A = (1 + f_dr) / (1 - f_dr)
    s_tr = math.sqrt(3 * sigma_a * st)
    z_r = 1 / st
    z_v = z_r * (1 + 4 * A / 3)
    d_r, d_v = math.hypot(r_mm, z_r), math.hypot(r_mm, z_v)
    return alb / (4 * math.pi) * (z_r * (1 + s_tr * d_r) * math.exp(-s_tr * d_r) / d_r ** 3
                                  + z_v * (1 + s_tr * d_v) * math.exp(-s_tr * d_v) / d_v ** 3)


def _tail_share(radius_mm, c, material):
    """The share of the dipole's total reflectance beyond ``radius_mm`` in channel ``c`` (quad, 2 pi r dr)."""
    args = (float(material.sigma_s_prime[c]), float(material.sigma_a[c]), float(material.eta))
    f = lambda r: 2 * math.pi * r * _jensen_profile(r, *args)  # noqa: E731
    total = quad(f, 0, 50, limit=400, points=[0.1, 1, 5])[0] + quad(f, 50, np.inf, limit=400)[0]
    beyond = quad(f, radius_mm, radius_mm + 50, limit=400)[0] + quad(f, radius_mm + 50, np.inf, limit=400)[0]
    return beyond / total


@pytest.mark.parametrize("name", ["skin1", "marble"])
def test_the_records_radii_hold_their_tails(name):
    """The cutoff, the distance check's and the far field's radii leave beyond them the share of the dipole's
    total they are made for (quad of Jensen's profile, within 2 %)."""
    material = Material.preset(name)
    opts = SurfaceOptions(cutoff_tol=1e-4, far_tol=0.1)
    m = surface_medium(material, opts)
    for c in range(3):
        for radius, tol in ((m.cutoff_mm[c], 1e-4), (m.check_cutoff_mm[c], CHECK_CUTOFF_TOL), (m.far_mm[c], 0.1)):
            assert _tail_share(radius, c, material) == pytest.approx(tol, rel=0.02)
    assert not m.cutoff_mm.flags.writeable and not m.far_mm.flags.writeable


def test_the_record_is_the_materials_and_the_options():
    """It answers what the kernels read of a material, carries the near field only with the beam source model,
    and a SurfaceMedium given where a material is expected is used as it is."""
    point = surface_medium(SKIN, SurfaceOptions())
    beam = surface_medium(SKIN, SurfaceOptions(source_model="beam"))
    assert point.near is None and beam.near is not None and beam.source_model == "beam"
    assert np.array_equal(point.sigma_t_prime, SKIN.sigma_t_prime) and point.eta == SKIN.eta
    assert point.channel(1) == SKIN.channel(1) and point.describe() == SKIN.describe()
    assert surface_medium(point) is point
    assert surface_medium(point, SurfaceOptions()) is point
    with pytest.raises(ParameterError, match="other options"):
        surface_medium(point, SurfaceOptions(source_model="beam"))
    with pytest.raises(ValueError, match="source_model"):
        SurfaceMedium(SKIN, cutoff_tol=1e-4, source_model="disc")


def test_a_transport_built_for_other_options_refuses_the_record():
    mesh = Mesh.from_arrays(*icosphere(10.0, 2))
    m = surface_medium(SKIN, SurfaceOptions(cutoff_tol=1e-3))
    with pytest.raises(Exception, match="other options"):
        SurfaceTransport.build(mesh, m, "dipole", SurfaceOptions(cutoff_tol=1e-4))


def _calls(fn, names) -> dict:
    """Calls of the functions ``names`` (``module.py:function``) while ``fn`` runs (cProfile)."""
    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    out = {}
    for (file, _line, name), (_cc, nc, *_rest) in pstats.Stats(pr).stats.items():
        key = f"{file.replace(chr(92), '/').rsplit('/', 1)[-1]}:{name}"
        if key in names:
            out[key] = out.get(key, 0) + nc
    return out


@pytest.mark.parametrize("transport", ["hierarchical", "direct"])
def test_a_surface_bake_makes_the_record_once_and_every_stage_reads_it(transport):
    """One record per bake: the radii computed once each (the cutoff was computed 3 times per hierarchical bake
    before: by the bake, the transport and its distance check), one set of sphere tables (the transport and the
    beams' direct sum made one each before)."""
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    lights = [DirectionalLight((0, 0, -1)), BeamLight((0, 0, 30), (0, 0, -1))]
    opts = BakeOptions(model="exact-sphere", surface=SurfaceOptions(transport=transport, source_model="beam"))
    bake(mesh, SKIN, lights, opts)   # compiled code and caches
    material = Material(SKIN.sigma_s_prime, SKIN.sigma_a, SKIN.eta, name="again")
    names = {"medium.py:__init__", "dipole.py:dipole_cutoff_radii", "gather.py:cutoff_radii",
             "farfield.py:far_field_radius", "kernel_evaluation.py:__init__"}
    got = _calls(lambda: bake(mesh, material, lights, opts), names)
    assert got == {"medium.py:__init__": 1, "dipole.py:dipole_cutoff_radii": 3,   # the cutoff, the distance
                   "kernel_evaluation.py:__init__": 1}, got                        # check's and the far field's
