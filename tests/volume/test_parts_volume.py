"""Parts of different media in the volume bake (issue 49, docs/physics.md §17 "Parts"): which part owns a point
(nested, touching), a nested part is a solid not a cavity, parts of one medium bake exactly as that medium, the
per-cube path with equal media agrees with the homogeneous one to rounding, each part's medium is where it
belongs, an absorbing neighbour only takes light away, and what is refused."""
import warnings

import numpy as np
import pytest

from meshshade.errors import MaterialError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import nested_spheres, split_sphere
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.parts import PartedMaterial
from meshshade.transport import BakeOptions
from meshshade.transport.baking import bake
from meshshade.volume.media import PartsMedium
from meshshade.volume.options import VolumeOptions

SUN = DirectionalLight((0.0, 0.0, -1.0), 1.0)


def _mesh(V, F):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # two components; the repair turns the nested/touching parts inward
        return Mesh.from_arrays(V, F)


@pytest.fixture(scope="module")
def nested():
    V, F, part = nested_spheres(10.0, 4.0, 3, 2)
    return _mesh(V, F), part


@pytest.fixture(scope="module")
def split():
    V, F, part = split_sphere(10.0, (1.0, 0.0, 0.0), 10)
    return _mesh(V, F), part


# --- which part owns a point -----------------------------------------------------------------------------------
def test_the_innermost_part_owns_a_point_whatever_the_parts_order(nested):
    mesh, part = nested
    pts = np.array([[0, 0, 0.5], [0, 0, 2.0], [0, 0, 6.0], [0, 9.0, 0], [0, 0, 12.0], [30.0, 0, 0]])
    want = np.array([1, 1, 0, 0, -1, -1])
    skin, marble = Material.preset("skin1"), Material.preset("marble")
    pm = PartedMaterial([skin, marble], part, ["outer", "ball"])
    om = pm.oriented(mesh)
    np.testing.assert_array_equal(pm.part_at(om.vertices, om.faces, pts), want)
    swapped = PartedMaterial([marble, skin], 1 - part, ["ball", "outer"])   # the ball listed first
    np.testing.assert_array_equal(swapped.part_at(om.vertices, om.faces, pts), np.where(want >= 0, 1 - want, -1))


def test_touching_parts_each_own_their_side(split):
    mesh, part = split
    pm = PartedMaterial([Material.preset("skin1"), Material.preset("marble")], part, ["a", "b"])
    om = pm.oriented(mesh)
    x = np.linspace(-9.5, 9.5, 20)
    pts = np.stack([x, 0.3 * np.ones_like(x), -0.2 * np.ones_like(x)], axis=1)
    got = pm.part_at(om.vertices, om.faces, pts)
    np.testing.assert_array_equal(got, np.where(x > 0, 0, 1))


def test_a_nested_part_is_a_solid_not_a_cavity(nested):
    """The mesh's repair turns a closed surface inside another inward (a cavity's wall); a part is a solid: the
    parts' orientation turns it back (each part's enclosed volume positive), vertex order unchanged."""
    mesh, part = nested
    F = np.asarray(mesh.faces)
    det = np.einsum("ij,ij->i", mesh.vertices[F[:, 0]], np.cross(mesh.vertices[F[:, 1]], mesh.vertices[F[:, 2]]))
    assert det[part == 1].sum() < 0                      # what the repair did (the premise)
    pm = PartedMaterial([Material.preset("skin1"), Material.preset("marble")], part)
    om = pm.oriented(mesh)
    F2 = np.asarray(om.faces)
    det2 = np.einsum("ij,ij->i", om.vertices[F2[:, 0]], np.cross(om.vertices[F2[:, 1]], om.vertices[F2[:, 2]]))
    assert det2[part == 0].sum() > 0 and det2[part == 1].sum() > 0
    assert pm.oriented(mesh) is om                        # kept per mesh (a bake of it is reused)
    np.testing.assert_array_equal(om.vertices, mesh.vertices)


# --- the bake ----------------------------------------------------------------------------------------------------
def test_parts_of_one_medium_bake_bit_for_bit_as_that_medium(nested):
    """Parts whose materials are one medium (equal coefficients, names aside) take the homogeneous path: the
    same numbers to the bit as the plain bake of the (part-oriented) mesh."""
    mesh, part = nested
    skin = Material.preset("skin1")
    pm = PartedMaterial([skin, Material.preset("skin1")], part, ["outer", "ball"])
    got = bake(mesh, pm, SUN)
    one = bake(pm.oriented(mesh), skin, SUN)
    np.testing.assert_array_equal(got.radiance, one.radiance)


def test_the_per_cube_path_with_equal_media_agrees_to_rounding(nested, monkeypatch):
    """The varying medium's own path (D and sigma_a per cube in the matrices, sources and near field per
    medium) with both parts skin1 against the homogeneous bake: the same linear system summed in another
    order, so equal to rounding (measured 3e-15 of the peak; 1e-12 here)."""
    mesh, part = nested
    skin = Material.preset("skin1")
    monkeypatch.setattr(PartsMedium, "force_cubes", True)
    pm = PartedMaterial([skin, skin], part, ["outer", "ball"])
    got = bake(mesh, pm, SUN)
    assert got.volume.coef[0, 0] == 1.0                   # the per-cube path ran
    one = bake(pm.oriented(mesh), skin, SUN)
    assert np.abs(got.radiance - one.radiance).max() <= 1e-12 * one.radiance.max()


def test_each_part_shades_as_its_own_medium_away_from_the_seam():
    """A 20 mm sphere half skin1 (x > 0), half marble: skin1's short reach (1/kappa 0.8 mm in blue, 1.5 mm in
    green, 3.7 mm in red) makes its half, beyond 6 mm from the seam, shade as an all-skin1 sphere does there:
    measured 0.56 / 0.04 / 0.00 % mean over lit vertices (red reaches the marble a little), 1.5 / 0.3 / 0.1 %
    here. (Marble's own lattice spacing, 1 mm with no finer cubes at its edges, needs no refining in skin1's
    0.84 mm lattice, so the skin half's lattice is skin1's own; planted: marble's edges refined as at 2 mm with
    h0 / 2 at its edges, 0.5 / 0.9 / 1.1 %, fails.) The parts' media swapped, the entries' sources or the receivers' near field in the
    wrong medium fail it by far."""
    V, F, part = split_sphere(20.0, (1.0, 0.0, 0.0), 12)
    mesh = _mesh(V, F)
    skin, marble = Material.preset("skin1"), Material.preset("marble")
    pm = PartedMaterial([skin, marble], part, ["skin", "marble"])
    got = bake(mesh, pm, SUN)
    om = pm.oriented(mesh)
    all_skin = bake(om, skin, SUN)
    v = om.vertices
    far = ~got.volume.buried & (v[:, 0] > 6.0) & (v[:, 2] > 4.0)
    assert far.sum() > 50
    err = np.abs(got.radiance[far] / all_skin.radiance[far] - 1.0).mean(axis=0)
    assert np.all(err < [0.015, 0.003, 0.001]), err
    marble_side = ~got.volume.buried & (v[:, 0] < -6.0) & (v[:, 2] > 4.0)
    assert np.all(got.radiance[marble_side].mean(axis=0) > 1.2 * got.radiance[far].mean(axis=0))


def test_an_absorbing_neighbour_only_takes_light_away(split):
    """Marble beside a more absorbing marble (sigma_a x 10, x 100) against all marble on the same lattice spacing:
    the marble half's lit vertices beyond 6 mm from the seam get less light, and less the more the neighbour
    absorbs (diffusion's maximum principle; measured -0.7 / -0.3 / -0.1 % and -1.2 / -0.5 / -0.15 %). Caught: the
    edges of light refined for the fastest medium only (the marble half's terminator under-resolved: +3-7 %)."""
    mesh, part = split
    marble = Material.preset("marble")
    opt = BakeOptions(volume=VolumeOptions(h0=1.0))
    om = PartedMaterial([marble, marble], part, ["x", "marble"]).oriented(mesh)
    ref = bake(om, marble, SUN, opt).radiance
    v = om.vertices
    side = (v[:, 0] < -6.0) & (v[:, 2] > 2.0)
    means = []
    for f in (10.0, 100.0):
        X = Material(marble.sigma_s_prime, np.asarray(marble.sigma_a) * f, marble.eta, marble.g, "X")
        got = bake(mesh, PartedMaterial([X, marble], part, ["x", "marble"]), SUN, opt).radiance
        means.append((got[side] / ref[side]).mean(axis=0))
    assert np.all(means[0] < 1.0) and np.all(means[1] < means[0]), means


def test_a_nested_ball_of_a_longer_reach_adds_light_and_stays_buried(nested):
    """A marble ball in skin1: more light comes out than from all skin1 (marble absorbs less), less than from all
    marble; the ball's vertices are buried (no exitance reported there)."""
    mesh, part = nested
    skin, marble = Material.preset("skin1"), Material.preset("marble")
    pm = PartedMaterial([skin, marble], part, ["outer", "ball"])
    got = bake(mesh, pm, SUN)
    om = pm.oriented(mesh)
    lo, hi = bake(om, skin, SUN), bake(om, marble, SUN)
    p, p_lo, p_hi = (np.array(r.stats["exitant_power"]) for r in (got, lo, hi))
    assert p[0] > p_lo[0] * (1 + 1e-4) and np.all(p < p_hi)
    assert got.volume.buried[np.unique(om.faces[part == 1])].all()
    assert not got.volume.buried[np.unique(om.faces[part == 0])].any()


# --- refused -----------------------------------------------------------------------------------------------------
def test_surface_models_refuse_parts_in_one_line(nested):
    mesh, part = nested
    pm = PartedMaterial([Material.preset("skin1"), Material.preset("marble")], part)
    with pytest.raises(ParameterError, match="material of parts") as e:
        bake(mesh, pm, SUN, BakeOptions(model="dipole"))
    assert "\n" not in str(e.value)


def test_parts_of_different_indices_are_refused(nested):
    mesh, part = nested
    pm = PartedMaterial([Material.preset("skin1"), Material.preset("regular-milk")], part)   # 1.3 and 1.33
    with pytest.raises(MaterialError, match="index-matched"):
        bake(mesh, pm, SUN)


def test_from_names_builds_parts_and_refuses_what_matches_nothing():
    names = {"skin": np.array([1, 1, 0, 0], bool), "ball": np.array([0, 0, 1, 1], bool),
             "all": np.ones(4, bool)}
    skin, marble = Material.preset("skin1"), Material.preset("marble")
    pm = PartedMaterial.from_names(names, [("ball", marble)], skin)
    np.testing.assert_array_equal(pm.face_part, [1, 1, 0, 0])
    assert pm.names == ("ball", "rest")
    with pytest.raises(MaterialError, match="no part named 'bal'.*skin, ball, all"):
        PartedMaterial.from_names(names, [("bal", marble)], skin)
    with pytest.raises(MaterialError, match="2 faces .* in none"):
        PartedMaterial.from_names(names, [("ball", marble)], None)
    with pytest.raises(MaterialError, match="keep no faces"):
        PartedMaterial.from_names(names, [("ball", marble), ("all", skin)], None)
