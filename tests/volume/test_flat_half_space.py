"""The volume bake on a flat face of a thick block under a sun at normal incidence is the half-space's diffuse
reflectance: the reference is adding-doubling (iadpython, an independent solver: a slab 400 optical depths thick,
index-matched below, its specular part taken off), per unit entering power times (1 - F(0)).

Skin1 meets it (-0.5 / +0.2 / -2.4 %); marble (reduced albedo 0.999, decay lengths 4-8.5 mm) does not at the
default spacing (h0 = 2 mm): its lit centre reads -9.9 / -11.9 / -13.6 % on the 80 x 80 x 40 mm block and -9.0 /
-10.5 / -11.7 % on a 120 x 120 x 60 mm one (issue 47: the power the sweep finds missing on the hand and the head in
marble and whole milk). Measured on the larger block (2026-12-04): the deficit does not move with the grading's
levels or with where the face cuts the lattice's cubes, and moves with the sources' sideways spread at a fixed
lattice (spread 0.84 / 1.0 / 1.2 mm: 3.6 / 9 / 13 % low in red), and with h0 (2, 1.68, 1.41, 1.19, 1 mm: 9, 2, 7,
3, 1 % low in red).
"""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from meshshade.geometry.mesh import Mesh
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake


def _adding_doubling_reflectance(material, c):
    """Diffuse reflectance of a half-space of ``material``'s channel ``c`` per unit incident irradiance at normal
    incidence (iadpython: total minus the specular surface reflection)."""
    import iadpython as iad

    ss, sa, eta = float(material.sigma_s_prime[c]), float(material.sigma_a[c]), float(material.eta)
    sample = iad.Sample(a=ss / (ss + sa), b=(ss + sa) * 400.0, g=0.0, n=eta, n_above=1.0, n_below=eta, quad_pts=32)
    return float(sample.rt()[0]) - ((eta - 1.0) / (eta + 1.0)) ** 2


def _centre_exitance(material, size, height):
    box = trimesh.creation.box(extents=(size, size, height))
    for _ in range(5):
        box = box.subdivide()
    shift = np.array([0.37, 0.23, 0.11])                       # off the lattice's planes (docs/limitations.md)
    V = box.vertices + shift
    top = (np.abs(V[:, 2] - (height / 2 + shift[2])) < 1e-9) & (np.hypot(*(V[:, :2] - shift[:2]).T) < 0.1 * size)
    res = bake(Mesh.from_arrays(V, box.faces), material, [DirectionalLight((0, 0, -1.0), 1.0)])
    return res.radiance[top].mean(axis=0)


@pytest.mark.parametrize("name, size, height", [
    ("skin1", 60.0, 30.0),
    pytest.param("marble", 80.0, 40.0, marks=pytest.mark.xfail(
        strict=True, reason="issue 47: marble's flat lit face reads 9-14 % low at h0 = 2 mm (module docstring)"))])
def test_a_flat_face_reflects_the_half_space(name, size, height):
    material = Material.preset(name)
    got = _centre_exitance(material, size, height)
    ref = np.array([_adding_doubling_reflectance(material, c) for c in range(3)])
    np.testing.assert_allclose(got, ref, rtol=0.03)
