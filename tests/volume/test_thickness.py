"""The object's local thickness (meshshade.volume.thickness, docs/physics.md §15.2, eq. (135)) and the lattice's
refinement of its thin parts: closed forms of the shape diameter on a sphere and a slab, the float32 Embree
distances against the float64 brute force, open meshes, and which cubes the thin parts get."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from meshshade.geometry.mesh import Mesh
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.raycast import make_scene
from meshshade.volume import resolution as volume_resolution
from meshshade.volume.thickness import CONE_DEG, shape_diameter, surface_thickness
from meshshade.volume.transport import VolumeTransport


def test_a_sphere_reads_its_chord_at_the_cone_s_angle():
    """Closed form: a chord of a sphere of radius R at an angle theta to the inward normal is 2 R cos(theta); eight of
    the nine rays are tilted by CONE_DEG, so the median is that chord (the normal's own ray, 2R, is the ninth).
    The faceted sphere's vertices lie on it; its chords end on flat facets, 1e-3 inside."""
    m = trimesh.creation.icosphere(5, 10.0)
    t = shape_diameter(make_scene(m.vertices, m.faces), m.vertices, m.vertex_normals)
    np.testing.assert_allclose(t, 20.0 * math.cos(math.radians(CONE_DEG)), rtol=2e-3)


def test_a_slab_reads_its_thickness_over_the_cone_s_cosine():
    """A 60 x 60 x 4 mm slab, the middle of its faces: the tilted rays cross it in 4 / cos(theta) (closed form; the
    rays are cast in float32, about 2.5e-5 off)."""
    box = trimesh.creation.box(extents=(60.0, 60.0, 4.0)).subdivide_to_size(2.0)
    V, N = box.vertices, box.vertex_normals
    middle = (np.abs(np.abs(V[:, 2]) - 2.0) < 1e-9) & (np.hypot(V[:, 0], V[:, 1]) < 20.0)
    t = shape_diameter(make_scene(V, box.faces), V[middle], N[middle])
    np.testing.assert_allclose(t, 4.0 / math.cos(math.radians(CONE_DEG)), rtol=1e-4)


def test_embree_distances_match_the_float64_brute_force():
    """The fast path (float32 Embree on the worker threads) against the numpy twin's float64 first hits, on rays
    from random points inside a bumpy closed mesh in random directions."""
    rng = np.random.default_rng(3)
    m = trimesh.creation.icosphere(3, 10.0)
    m.vertices *= 1.0 + 0.15 * np.sin(3.0 * m.vertices[:, [0]] / 10.0)
    o = rng.normal(size=(2000, 3))
    o *= (rng.uniform(0.0, 6.0, 2000) / np.linalg.norm(o, axis=1))[:, None]
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    fast = make_scene(m.vertices, m.faces).first_hit_distances(o, d)
    slow = make_scene(m.vertices, m.faces, backend="numpy").first_hit_distances(o, d)
    assert np.all(np.isfinite(slow))                   # every ray from inside leaves through a face
    np.testing.assert_allclose(fast, slow, rtol=0, atol=2e-5)


def test_rays_out_through_a_hole_read_infinite_and_zero_normals_are_skipped():
    """A bowl (the lower half of a sphere, open at the top): its bottom's inward rays leave through the opening and
    meet nothing, so the thickness there is inf; a zero normal gives inf without casting."""
    m = trimesh.creation.icosphere(4, 10.0)
    keep = m.vertices[m.faces].mean(axis=1)[:, 2] < 0.0
    bowl = trimesh.Trimesh(m.vertices, m.faces[keep], process=True)
    bottom = np.argmin(bowl.vertices[:, 2])
    N = bowl.vertex_normals.copy()
    N[0] = 0.0
    t = shape_diameter(make_scene(bowl.vertices, bowl.faces), bowl.vertices[[bottom, 0]], N[[bottom, 0]])
    assert np.all(np.isinf(t))


def test_probes_give_each_point_its_nearest_probe_s_thickness():
    """surface_thickness casts from one point per cube of ``spacing`` and gives the others their nearest probe's
    value: on a sphere (thickness constant) the same as casting from every point; on a body with a thin plate
    the thin points stay thin (within one spacing of the plate's edge)."""
    m = trimesh.creation.icosphere(5, 10.0)
    scene = make_scene(m.vertices, m.faces)
    every = shape_diameter(scene, m.vertices, m.vertex_normals)
    probed = surface_thickness(scene, m.vertices, m.vertex_normals, 2.0)
    np.testing.assert_allclose(probed, every, rtol=1e-3)


def _block_with_wings(t):
    """A 40 x 40 x 30 mm block with a 120 x 50 x ``t`` mm plate through it (two overlapping boxes: their union is
    the inside, the winding number), off the lattice's planes."""
    block = trimesh.creation.box(extents=(40.0, 40.0, 30.0)).subdivide_to_size(2.0)
    plate = trimesh.creation.box(extents=(120.0, 50.0, t)).subdivide_to_size(2.0)
    V = np.concatenate([block.vertices, plate.vertices]) + np.array([0.37, 0.23, 0.11])
    F = np.concatenate([block.faces, plate.faces + len(block.vertices)])
    with pytest.warns(Warning):                      # two overlapping parts
        return Mesh.from_arrays(V, F)


def test_thin_parts_are_resolved_at_half_the_spacing_and_said_so():
    """Marble (no finer cubes at its edges of light: kappa h0 = 1/4) on a block with 3 mm wings: the wings, thinner
    than 4 h0 = 4 mm, are resolved at h0 / 2 and the block's bulk at h0: level-0 cubes only within reach of the
    wings, the stats say how much of the surface is thin and from what thickness. Planted: the thin parts
    ignored -> no level-0 cube, fails."""
    mesh = _block_with_wings(3.0)
    marble = Material.preset("marble")
    vt = VolumeTransport.build(mesh, marble)
    res = vt.resolution
    assert res.h0 == pytest.approx(1.0) and res.refine_radius == 0.0
    assert vt.stats["volume_thin_below_mm"] == pytest.approx(min(4.0 * res.h0, 2.0 / float(np.min(res.kappa))))
    # the wings' faces are most of the surface: 2 x (120 x 50 - 40 x 40) = 8,800 of about 14,000 mm^2
    assert 0.5 < vt.stats["volume_thin_fraction"] < 0.8
    # on the block's faces away from the wings only the points within about 1 mm of its edges read thin (there the
    # tilted rays leave through the neighbouring face: the shape diameter of a convex edge)
    S = vt.surface.samples
    p = S.vertices - np.array([0.37, 0.23, 0.11])
    block = (np.abs(p[:, 0]) < 19.99) & (np.abs(p[:, 2]) > 1.5 + 2.0)
    edge = np.sum(np.abs(p[:, :2]) > 19.0, axis=1) + (np.abs(np.abs(p[:, 2]) - 15.0) < 1.0) >= 2
    assert block.sum() > 500 and not np.any(vt.thin[block & ~edge])
    vt.exitance(_sun_samples(vt))
    lat = vt.lattice
    centres = (lat.ijk[lat.level == 0] + 0.5) * lat.grading.h0
    assert len(centres) > 0
    # the finest cubes lie in the wings or within the reach of one (half the threshold and a cube's diagonal), but
    # for the few about the block's edges; and they fill the wings (3 mm at h0 / 2: 6 cubes across)
    reach = 0.5 * res.thin_below + math.sqrt(3.0) * res.h0
    c = centres - np.array([0.37, 0.23, 0.11])
    in_wing = np.abs(c[:, 2]) < 1.5 + reach
    assert in_wing.mean() > 0.99, in_wing.mean()
    wing_volume = 2.0 * 39.0 * 50.0 * 3.0              # the plate beyond 21 mm of the block's middle
    fine_in_wings = np.sum((np.abs(c[:, 2]) < 1.5) & (np.abs(c[:, 0]) > 21.0)) * (0.5 * res.h0) ** 3
    assert fine_in_wings > 0.95 * wing_volume, (fine_in_wings, wing_volume)


def test_a_thick_body_gets_no_finer_cubes():
    """A marble ball of radius 20 mm: nothing thin (its shape diameter is 37.6 mm everywhere), no level-0 cube
    (marble's edges of light are not refined)."""
    ball = trimesh.creation.icosphere(4, 20.0)
    mesh = Mesh.from_arrays(ball.vertices + np.array([0.37, 0.23, 0.11]), ball.faces)
    vt = VolumeTransport.build(mesh, Material.preset("marble"))
    assert vt.stats["volume_thin_fraction"] == 0.0 and not vt.thin.any()
    vt.exitance(_sun_samples(vt))
    assert vt.stats["volume_cells_per_level"][0] == 0


def _sun_samples(vt):
    from meshshade.light.samples import entry_samples

    S = vt.surface.samples
    return entry_samples(S.vertices, S.faces, S.vertex_normals, S.vertex_areas, [DirectionalLight((0, 0, -1.0), 1.0)],
                         scene=make_scene(S.vertices, S.faces), eta=float(vt.material.eta))


def test_the_threshold_follows_the_farthest_reaching_channel_and_the_spacing():
    """thin_below = min(THIN_CELLS_ACROSS h0, THIN_DECAYS / kappa_min): skin1 (h0 0.84 mm) 3.36 mm; marble 4 mm."""
    for name in ("skin1", "marble"):
        mat = Material.preset(name)
        res = volume_resolution.volume_resolution(mat, 1e4, np.full(3, 100.0))
        kappa = np.asarray(mat.medium.kappa)
        assert res.thin_below == pytest.approx(min(volume_resolution.THIN_CELLS_ACROSS * res.h0,
                                                   volume_resolution.THIN_DECAYS / kappa.min()))


def test_check_says_where_the_lattice_is_finer():
    """``meshshade check`` (check_mesh / format_check) reports the thin parts' share of the surface and threshold as
    the bake's stats do, and the edges of light only where the material refines them."""
    from meshshade.check import check_mesh, format_check

    mesh = _block_with_wings(3.0)
    marble = Material.preset("marble")
    vt = VolumeTransport.build(mesh, marble)
    report = check_mesh(mesh, marble)
    v = report["volume"]
    assert v["thin_fraction"] == pytest.approx(vt.stats["volume_thin_fraction"], abs=1e-4)
    assert v["thin_below_mm"] == pytest.approx(vt.stats["volume_thin_below_mm"], abs=1e-4)
    text = format_check(report)
    assert f"on {100 * v['thin_fraction']:.1f}% of the surface (parts thinner than 4 mm)" in text
    assert "edges of light" not in text                  # marble's edges are resolved at h0
    skin = format_check(check_mesh(mesh, Material.preset("skin1")))
    assert "mm of edges of light and on" in skin
