"""Faces on the lattice's planes (issue 47's sweep follow-up, found 2026-12-04; fixed 2026-12-05): the lattice is
anchored in world coordinates with spacings 2^(k/4) mm, so a box centred at the origin with faces at whole millimetres
has them exactly on lattice planes at h0 = 1 mm, its corners there at depth 0.

Two faults, both fixed: the corners on the surface were put a hair *inside* after the cubes had been kept or dropped
by their corners' sides, so the cube inside was uncut and the cube outside dropped: the face had no boundary term
(the 100 x 100 x 20 mm box's cut surface 12,800 of 28,000 mm^2), and the middle of its lit face read +43 / +43 / +27 %
in apple, 2.5 times the entering power leaving (now a hair outside, before the cubes are chosen:
lattice.snap_corner_depths). And a point a hair outside every kept cube (a face 1e-9 to 1e-4 h0 off a plane) was read
half a cube inside: +10 / +10 / +4 % (now moved in by 1e-3 h0 first: VolumeTransport._read).

What is left is the lattice's own error, which depends on where the surface lies in its cubes: the 100 mm box in apple
with its top face at 13 positions within one cube reads -0.29 ... +0.37 / -0.25 ... +0.44 / +0.09 ... +1.77 % off the
half-space's total (eq. (106)); on the plane itself +0.37 / +0.44 / +1.77 % (2026-12-05;
docs/limitations.md), so the blue channel misses 1 % there (strict xfail)."""
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.painted_reflectance import model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake
from meshshade.transport.options import BakeOptions
from meshshade.volume.options import VolumeOptions


def _centre_off(shift):
    m = Material.preset("apple")
    V, F = box((100.0, 100.0, 20.0), 25)
    mid = (np.abs(V[:, 0]) <= 10) & (np.abs(V[:, 1]) <= 10) & (V[:, 2] > 10 - 1e-6)
    r = bake(Mesh.from_arrays(V + np.asarray(shift), F), m, DirectionalLight([0, 0, -1.0], 1.0))
    T0 = 1.0 - float(fresnel_reflectance(1.0, 1.0, m.eta))
    return r.radiance[mid].mean(axis=0) / T0 / model_total_reflectance(m.albedo_prime, m.eta, m.g) - 1.0


@pytest.mark.parametrize("offset", [0.0, 1e-9, 1e-6, -1e-6])
def test_a_box_on_or_a_hair_off_the_lattice_planes_bakes_as_one_off_them(offset):
    # a 40 x 40 x 10 mm box of apple at h0 = 1 mm (its faces on the lattice's planes at offset 0) against the same
    # box moved 0.37 mm: the lattice's cut surface (before: about half of it lost at offset 0 and 1e-9) and the
    # middle of the lit face (before: +10 / +10 / +4 % at 1e-6; measured now within 0.7 / 0.8 / 1.7 %, the lattice's
    # own error moving with the face's place in its cubes)
    V, F = box((40.0, 40.0, 10.0), 10)
    mid = (np.abs(V[:, 0]) <= 5) & (np.abs(V[:, 1]) <= 5) & (V[:, 2] > 5 - 1e-6)
    opts = BakeOptions(volume=VolumeOptions(h0=1.0))
    sun = DirectionalLight([0, 0, -1.0], 1.0)
    ref = bake(Mesh.from_arrays(V + 0.37, F), Material.preset("apple"), sun, opts)
    got = bake(Mesh.from_arrays(V + offset, F), Material.preset("apple"), sun, opts)
    assert got.stats["volume_resolution_mm"] == 1.0
    assert abs(got.stats["volume_surface_mm2"] / ref.stats["volume_surface_mm2"] - 1.0) < 5e-3
    rel = got.radiance[mid].mean(axis=0) / ref.radiance[mid].mean(axis=0) - 1.0
    assert np.all(np.abs(rel) < 0.02), rel


def test_two_boxes_meeting_on_a_lattice_plane_are_one_medium():
    # two closed 20 x 40 x 10 mm boxes sharing their face x = 0 (on a lattice plane at h0 = 1 mm; the medium on both
    # sides of it, as the split sphere's hemispheres): the lattice's cut surface is the outer one, as one 40 x 40 x
    # 10 mm box's at the same place (measured +1.1 % on the planes, +0.1 % moved 0.37 mm off them). Before
    # (2026-12-05) the corners on the shared face were put outside with every corner on the surface: a void between
    # the boxes, +5.0 % of cut surface here (the split sphere of bench_parts.py: 281 mm^2 inside it, 5.3 % of its red
    # light lost); lattice.snap_corner_depths now probes each such corner's eight diagonal neighbours
    V, F = box((20.0, 40.0, 10.0), 5)
    pair_v, pair_f = np.concatenate([V - [10.0, 0.0, 0.0], V + [10.0, 0.0, 0.0]]), np.concatenate([F, F + len(V)])
    one_v, one_f = box((40.0, 40.0, 10.0), 10)
    opts = BakeOptions(volume=VolumeOptions(h0=1.0))
    sun = DirectionalLight([0.0, 0.0, -1.0], 1.0)
    for shift in (0.0, 0.37):
        with pytest.warns(Warning):                 # two components touching: the mesh says so
            pair = Mesh.from_arrays(pair_v + shift, pair_f)
        got = bake(pair, Material.preset("skin1"), sun, opts)
        ref = bake(Mesh.from_arrays(one_v + shift, one_f), Material.preset("skin1"), sun, opts)
        assert abs(got.stats["volume_surface_mm2"] / ref.stats["volume_surface_mm2"] - 1.0) < 0.02, shift


@pytest.mark.slow
def test_a_box_off_the_lattice_planes_reflects_the_half_spaces_total():
    # -0.10 / -0.06 / +0.30 % with the sampling surface at h0 (2026-12-04, stop 55); +1.1 / +1.3 / +1.7 % at 2 h0,
    # where the entries lay 4 sideways spreads apart and the sum of their Gaussians rippled at them
    assert np.all(np.abs(_centre_off([0.37, 0.21, 0.37])) < 0.01)


@pytest.mark.slow
def test_a_box_on_the_lattice_planes_is_within_the_lattices_band():
    # +0.37 / +0.44 / +1.77 % (2026-12-05); +43 / +43 / +27 % before the fix (module docstring)
    assert np.all(np.abs(_centre_off([0.0, 0.0, 0.0])) < 0.02)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="faces on the lattice's planes: +0.37 / +0.44 / +1.77 % (the lattice's error "
                   "at this place of the face in its cubes; module docstring)")
def test_a_box_on_the_lattice_planes_reflects_the_half_spaces_total():
    assert np.all(np.abs(_centre_off([0.0, 0.0, 0.0])) < 0.01)
