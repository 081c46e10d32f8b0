"""The volume bake on a flat face of a thick block under a sun at normal incidence is the half-space's diffuse
reflectance: the reference is adding-doubling (iadpython, an independent solver: a slab 400 optical depths thick,
index-matched below, its specular part taken off), per unit entering power times (1 - F(0)).

Skin1 meets it (+0.1 / +1.2 / -1.6 %); so does marble (reduced albedo 0.999, decay lengths 4-8.5 mm): -0.3 / -0.3
/ -0.2 % on the 80 x 80 x 40 mm block (-0.5 / -0.7 / -0.8 % with the 2-point sideways rule), since eq. (103)'s
subtraction covers every pair. Before, it covered the pairs
within 2.5 mm of the receiver only and left the rest to the sampled sum, whose quadrature of marble's long f missed
by -0.08 of the receiver's irradiance: the lit centre read -9.9 / -11.9 / -13.6 % (80 x 80 x 40 mm), the deficit
moving with the sources' sideways spread and h0 and not with the lattice's grading (issue 47: much of the power the
sweep found missing in marble and whole milk). Planted: the subtraction within 2.5 mm only -> marble fails.

The same face with the lattice's finest cubes everywhere (as around every edge of light): the sources' sideways
Gaussian must be resolved there, since those cubes are as fine as its width. With a 2 x 2 Gauss-Hermite rule the
lattice saw four lumps per entry and marble's face read -23.4 / -29.9 / -35.5 % (skin1's on its 40 x 20 mm block
-1.3 / -2.5 / -4.8 %); with 6 x 6 points -0.7 / -0.0 / +0.5 % (skin1 -0.9 / -2.0 / -2.5 %), and with the sampling
surface at h0 (2026-12-04, stop 55) -1.6 / -1.1 / -0.8 % (skin1 -0.6 / -1.1 / -1.3 %); all of the default lattice's
figures above are re-measured at h0 too. Planted: 2 points -> both fail (skin1's blue by -4.8 % against the 4 %
allowed).
"""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from meshshade.geometry.mesh import Mesh
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake
from meshshade.volume import lattice as volume_lattice
from meshshade.volume import transport as volume_transport


def _adding_doubling_reflectance(material, c):
    """Diffuse reflectance of a half-space of ``material``'s channel ``c`` per unit incident irradiance at normal
    incidence (iadpython: total minus the specular surface reflection)."""
    import iadpython as iad

    ss, sa, eta = float(material.sigma_s_prime[c]), float(material.sigma_a[c]), float(material.eta)
    sample = iad.Sample(a=ss / (ss + sa), b=(ss + sa) * 400.0, g=0.0, n=eta, n_above=1.0, n_below=eta, quad_pts=32)
    return float(sample.rt()[0]) - ((eta - 1.0) / (eta + 1.0)) ** 2


def _centre_exitance(material, size, height, cells=None):
    box = trimesh.creation.box(extents=(size, size, height))
    for _ in range(5):
        box = box.subdivide()
    shift = np.array([0.37, 0.23, 0.11])                       # off the lattice's planes (docs/limitations.md)
    V = box.vertices + shift
    top = (np.abs(V[:, 2] - (height / 2 + shift[2])) < 1e-9) & (np.hypot(*(V[:, :2] - shift[:2]).T) < 0.1 * size)
    res = bake(Mesh.from_arrays(V, box.faces), material, [DirectionalLight((0, 0, -1.0), 1.0)])
    if cells is not None:
        cells.extend(res.stats["volume_cells_per_level"])
    return res.radiance[top].mean(axis=0)


@pytest.mark.parametrize("name, size, height", [("skin1", 60.0, 30.0), ("marble", 80.0, 40.0)])
def test_a_flat_face_reflects_the_half_space(name, size, height):
    material = Material.preset(name)
    got = _centre_exitance(material, size, height)
    ref = np.array([_adding_doubling_reflectance(material, c) for c in range(3)])
    np.testing.assert_allclose(got, ref, rtol=0.03)


@pytest.mark.parametrize("name, size, height", [("skin1", 40.0, 20.0), ("marble", 80.0, 40.0)])
def test_a_flat_face_on_the_finest_cubes_reflects_the_half_space(name, size, height, monkeypatch):
    def finest_everywhere(depth, lo, hi, grading, refine=None, **kw):
        return volume_lattice.build_lattice(depth, lo, hi, grading, refine=lambda c: np.ones(len(c), dtype=bool),
                                            **kw)

    monkeypatch.setattr(volume_transport, "build_lattice", finest_everywhere)
    material = Material.preset(name)
    cells = []
    got = _centre_exitance(material, size, height, cells)
    assert cells[0] > 4 * cells[1], cells                    # the surface on the finest cubes
    ref = np.array([_adding_doubling_reflectance(material, c) for c in range(3)])
    np.testing.assert_allclose(got, ref, rtol=0.04)
