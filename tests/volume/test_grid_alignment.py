"""A box whose faces lie on the lattice's planes (issue 47's sweep follow-up, found 2026-12-04): the lattice is
anchored in world coordinates with spacings 2^(k/4) mm, so a box 100 x 100 x 20 mm centred at the origin has its
faces exactly on lattice planes at h0 = 1 mm, and its lattice nodes on the surface have depth 0. The bake then reads
43 % too much exitance in the middle of the lit face in apple (2.5 times the entering power leaves the box); the same
box moved by (0.37, 0.21, 0.37) mm reads within 0.4 % of the half-space's total reflectance (the model's own,
eq. (106)). Not fixed: snapping node depths within 0.05 mm of the surface to +-0.05 mm brings the aligned box to
+6 %, but moves every mesh's boundary; reading the field 1e-6 h0 inside changes nothing (the cause is in the
solution, not the read). Strict xfail: it fails the suite when fixed, so that the test is made a plain one."""
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.painted_reflectance import model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake


def _centre_off(shift):
    m = Material.preset("apple")
    V, F = box((100.0, 100.0, 20.0), 25)
    mid = (np.abs(V[:, 0]) <= 10) & (np.abs(V[:, 1]) <= 10) & (V[:, 2] > 10 - 1e-6)
    r = bake(Mesh.from_arrays(V + np.asarray(shift), F), m, DirectionalLight([0, 0, -1.0], 1.0))
    T0 = 1.0 - float(fresnel_reflectance(1.0, 1.0, m.eta))
    return r.radiance[mid].mean(axis=0) / T0 / model_total_reflectance(m.albedo_prime, m.eta, m.g) - 1.0


@pytest.mark.slow
def test_a_box_off_the_lattice_planes_reflects_the_half_spaces_total():
    # -0.10 / -0.06 / +0.30 % with the sampling surface at h0 (2026-12-04, stop 55); +1.1 / +1.3 / +1.7 % at 2 h0,
    # where the entries lay 4 sideways spreads apart and the sum of their Gaussians rippled at them
    assert np.all(np.abs(_centre_off([0.37, 0.21, 0.37])) < 0.01)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="faces on the lattice's planes: +43 / +43 / +27 % (not fixed; module docstring)")
def test_a_box_on_the_lattice_planes_reflects_the_half_spaces_total():
    assert np.all(np.abs(_centre_off([0.0, 0.0, 0.0])) < 0.01)
