"""Painted media in the volume transport (docs/physics.md §17, issue 49): a constant paint equal to a preset's own
total diffuse reflectance reproduces the preset's bake; a uniform paint on a flat slab under a sun at normal
incidence reflects its colour in the middle; the surface models refuse a painted material."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.errors import MaterialError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere, spherical_uv
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.painted_reflectance import albedo_for_reflectance, model_total_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.painted import PaintedMaterial
from meshshade.transport.baking import bake
from meshshade.transport.options import BakeOptions
from meshshade.volume.options import VolumeOptions


@pytest.fixture(scope="module")
def ball():
    V, F = icosphere(8.0, 3)
    return Mesh.from_arrays(V, F)


def test_a_constant_paint_of_a_presets_own_colour_reproduces_its_bake(ball):
    base = Material.preset("skin1")
    C = model_total_reflectance(base.albedo_prime, base.eta, base.g)      # the preset's own R_d, eq. (105)
    painted = PaintedMaterial(base, colour=np.broadcast_to(C, (ball.n_vertices, 3)))
    sun = DirectionalLight([0.3, -0.2, -1.0], 1.0)
    ref = bake(ball, base, sun).radiance
    got = bake(ball, painted, sun).radiance
    lit = ref > 1e-3 * ref.max(axis=0)
    rel = np.abs(got - ref)[lit] / ref[lit]
    assert rel.max() < 1e-3


def test_surface_models_refuse_a_painted_material(ball):
    painted = PaintedMaterial(Material.preset("skin1"), colour=np.full((ball.n_vertices, 3), 0.4))
    with pytest.raises(ParameterError, match="needs the volume model"):
        bake(ball, painted, DirectionalLight([0, 0, -1.0], 1.0), BakeOptions(model="dipole"))


@pytest.mark.parametrize("bad", [0.0, 1.0])
def test_a_colour_no_medium_has_is_refused(ball, bad):
    with pytest.raises(MaterialError, match="painted colour must lie in"):
        PaintedMaterial(Material.preset("skin1"), colour=np.full((ball.n_vertices, 3), bad))


def test_a_map_without_uvs_is_refused():
    with pytest.raises(MaterialError, match="UVs"):
        PaintedMaterial(Material.preset("skin1"), image=np.full((4, 4, 3), 0.5))


#: measured at the default options (h0 0.84-1.41 mm), % off C in r/g/b (tools/studies/painted_slab.py --bake): the
#: issue's 1 % is met at 0.5 only. At 0.8 and 0.95 the slab is thin for the medium: a laterally infinite 20 mm slab of
#: the same diffusion theory (1-D, closed form, the same script) already returns 2.2 / 0.8 / 0.2 % and 9.9 / 6.8 /
#: 4.1 % less than the half-space (light leaves through the bottom), and the 100 mm box loses more at its sides. At
#: 0.05, the volume model's own error on the flat slab at its default lattice (a homogeneous material of the same
#: albedo bakes the same values). Re-measured 2026-12-04 (stop 55) with the sampling surface at h0 (0.5 was +0.6 /
#: +1.1 / +1.7 % at 2 h0, now -0.13 / +0.26 / +0.50 %); at 0.2 the box's faces lie on the lattice's planes (h0 1 mm):
#: +14 / +13 / +13 % until the grid-alignment fault was fixed (2026-12-05, tests/volume/test_grid_alignment.py), now
#: +1.6 / +0.9 / +1.6 %, the lattice's own error at that place of the faces in its cubes (moved 0.37 mm off the planes,
#: tools/studies/painted_slab.py: -0.6 / +0.0 / +0.8 %).
SLAB_MEASURED = {0.05: "+0.5 / +1.7 / -2.9 %", 0.2: "+1.6 / +0.9 / +1.6 % (faces on the lattice's planes)",
                 0.8: "-2.3 / -0.9 / -0.1 % (1-D slab: -2.2 / -0.8 / -0.2 %)",
                 0.95: "-10 / -7.0 / -4.2 % (1-D slab: -9.9 / -6.8 / -4.1 %)"}


@pytest.mark.slow
@pytest.mark.parametrize("C", [pytest.param(c, marks=pytest.mark.xfail(strict=True, reason=f"measured {m}"))
                               for c, m in SLAB_MEASURED.items()] + [0.5])
def test_a_uniformly_painted_slab_reflects_its_colour(C):
    # box 100 x 100 x 20 mm, sun at normal incidence on its top: the exitance over the central 20 x 20 mm of the
    # lit face per unit of entering irradiance (1 - F(0), Fresnel at normal incidence) is the painted colour
    V, F = box((100.0, 100.0, 20.0), 25)
    mesh = Mesh.from_arrays(V, F)
    base = Material.preset("skin1")
    painted = PaintedMaterial(base, colour=np.full((mesh.n_vertices, 3), C))
    r = bake(mesh, painted, DirectionalLight([0, 0, -1.0], 1.0))
    mid = (np.abs(mesh.vertices[:, 0]) <= 10) & (np.abs(mesh.vertices[:, 1]) <= 10) & (mesh.vertices[:, 2] > 9.99)
    T0 = 1.0 - float(fresnel_reflectance(1.0, 1.0, base.eta))
    got = r.radiance[mid].mean(axis=0) / T0
    np.testing.assert_allclose(got, C, rtol=0.01)


def test_each_half_of_a_two_colour_ball_far_from_the_border_bakes_as_its_own_medium():
    # a 15 mm ball painted 0.15 where x > 0 and 0.35 where x < 0, lit from +z: the vertices more than 10 mm from
    # the border (several diffusion lengths: 1/kappa <= 3.2 mm) against bakes of the two homogeneous media (eq. (106)
    # per colour) on the same lattice spacing (the painted one resolves its darker paint; measured: within 0.5 %
    # median); the near field must take the receiver's medium, the volume each cube's
    V, F = icosphere(15.0, 3)
    mesh = Mesh.from_arrays(V, F)
    base = Material.preset("skin1")
    C = np.where(mesh.vertices[:, :1] > 0, 0.15, 0.35) * np.ones((1, 3))
    sun = DirectionalLight([0.0, 0.0, -1.0], 1.0)
    painted = bake(mesh, PaintedMaterial(base, colour=C), sun)
    got = painted.radiance
    same_lattice = BakeOptions(volume=VolumeOptions(h0=painted.stats["volume_resolution_mm"]))
    for colour, side in ((0.15, mesh.vertices[:, 0] > 10.0), (0.35, mesh.vertices[:, 0] < -10.0)):
        a = albedo_for_reflectance(np.full(3, colour), base.eta, base.g)
        ref = bake(mesh, Material(a * base.sigma_t_prime, (1 - a) * base.sigma_t_prime, base.eta), sun,
                   same_lattice).radiance
        sel = side & (ref[:, 2] > 1e-2 * ref[:, 2].max())
        assert sel.sum() >= 10
        rel = np.abs(got[sel] - ref[sel]) / ref[sel]
        assert np.all(np.median(rel, axis=0) < 0.01), (colour, np.median(rel, axis=0))


def test_a_paint_for_another_mesh_is_refused(ball):
    painted = PaintedMaterial(Material.preset("skin1"), colour=np.full((ball.n_vertices + 1, 3), 0.4))
    with pytest.raises(MaterialError, match="vertex colours for a mesh of"):
        bake(ball, painted, DirectionalLight([0, 0, -1.0], 1.0))


# ------------------------------------------------------------------------------------------------ radius maps
def test_a_constant_radius_map_bakes_as_the_scaled_material(ball):
    # eq. (132): the base's own colour with its mean free path times m everywhere is the homogeneous material of
    # sigma_t' / m (a different lattice, sources and near field than the base's: all must follow the map)
    base = Material.preset("skin1")
    m = 1.6
    sun = DirectionalLight([0.3, -0.2, -1.0], 1.0)
    ref = bake(ball, Material(base.sigma_s_prime / m, base.sigma_a / m, base.eta, base.g), sun).radiance
    got = bake(ball, PaintedMaterial(base, radius=np.full(ball.n_vertices, m)), sun).radiance
    lit = ref > 1e-3 * ref.max(axis=0)
    rel = np.abs(got - ref)[lit] / ref[lit]
    assert rel.max() < 1e-6


def test_each_half_of_a_two_radius_ball_far_from_the_border_bakes_as_its_own_medium():
    # a 15 mm ball of skin1 whose mean free path is 0.5x where x > 0 and 1.0x where x < 0, lit from +z: the vertices
    # more than 10 mm from the border (1/kappa <= 3.7 mm) against the two homogeneous media on the same lattice
    # spacing; the sources' depths, the cubes' D and sigma_a and the near field's tables must take the local mean
    # free path
    V, F = icosphere(15.0, 3)
    mesh = Mesh.from_arrays(V, F)
    base = Material.preset("skin1")
    R = np.where(mesh.vertices[:, 0] > 0, 0.5, 1.0)
    sun = DirectionalLight([0.0, 0.0, -1.0], 1.0)
    painted = bake(mesh, PaintedMaterial(base, radius=R), sun)
    same_lattice = BakeOptions(volume=VolumeOptions(h0=painted.stats["volume_resolution_mm"]))
    for m, side in ((0.5, mesh.vertices[:, 0] > 10.0), (1.0, mesh.vertices[:, 0] < -10.0)):
        ref = bake(mesh, Material(base.sigma_s_prime / m, base.sigma_a / m, base.eta), sun, same_lattice).radiance
        sel = side & (ref[:, 2] > 1e-2 * ref[:, 2].max())
        assert sel.sum() >= 10
        rel = np.abs(painted.radiance[sel] - ref[sel]) / ref[sel]
        assert np.all(np.median(rel, axis=0) < 0.01), (m, np.median(rel, axis=0))


@pytest.mark.parametrize("radius, needle", [(np.zeros(4), "not a finite factor above 0"),
                                            (np.array([1.0, np.nan, 1.0, 1.0]), "not a finite factor above 0"),
                                            (np.ones((4, 2)), "must be")])
def test_a_radius_no_medium_has_is_refused(radius, needle):
    with pytest.raises(MaterialError, match=needle):
        PaintedMaterial(Material.preset("skin1"), radius=radius)


def test_a_radius_map_without_uvs_or_for_other_vertices_is_refused(ball):
    with pytest.raises(MaterialError, match="radius map needs the mesh's texture coordinates"):
        PaintedMaterial(Material.preset("skin1"), radius_image=np.ones((4, 4)))
    with pytest.raises(MaterialError, match="radius map has 5 vertex values"):
        PaintedMaterial(Material.preset("skin1"), colour=np.full((4, 3), 0.4), radius=np.ones(5))
    with pytest.raises(MaterialError, match="for a mesh of 642 vertices"):
        bake(ball, PaintedMaterial(Material.preset("skin1"), radius=np.ones(ball.n_vertices + 1)),
             DirectionalLight([0, 0, -1.0], 1.0))
    uv = spherical_uv(ball.vertices, ball.faces)
    with pytest.raises(MaterialError, match="vertex radius factors for a mesh of"):
        bake(ball, PaintedMaterial(Material.preset("skin1"), image=np.full((2, 2, 3), 0.4), uv=uv,
                                   radius=np.ones(ball.n_vertices - 1)), DirectionalLight([0, 0, -1.0], 1.0))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 3), st.integers(1, 9), st.floats(0.01, 0.999), st.floats(1.01, 20.0), st.integers(0, 2**31 - 1))
def test_the_blend_weights_interpolate_each_receivers_medium(ka, ks, albedo_lo, st_ratio, seed):
    # eqs. (108), (133): per receiver and channel the corners' weights are >= 0, sum to 1, and their weighted node
    # coordinates give back the receiver's own log10(1 - alpha') and ln sigma_t' (bilinear interpolation is exact on
    # linear functions); the corners are tables of the grid
    from meshshade.volume.media import PaintedMedium, _nodes
    rng = np.random.default_rng(seed)
    n = 200
    albedo = rng.uniform(albedo_lo, 0.9999, size=(n, 3)) if ka > 1 else np.full((n, 3), albedo_lo)
    sig = np.exp(rng.uniform(0.0, np.log(st_ratio), size=(n, 3))) if ks > 1 else np.ones((n, 3))
    pm = PaintedMedium.__new__(PaintedMedium)
    pm._node_x = _nodes(np.log10(1.0 - albedo))
    pm._node_y = _nodes(np.log(sig), np.log(1.25), 9)
    blend = pm._blend(albedo, sig)
    ka, ks = len(pm._node_x), len(pm._node_y)
    if ka * ks == 1:
        assert blend is None
        return
    t, w = blend
    assert t.min() >= 0 and t.max() < ka * ks and np.all(w >= -1e-15)
    np.testing.assert_allclose(w.sum(axis=2), 1.0, rtol=0, atol=1e-12)
    chan = np.arange(3)[None, :, None]
    x = np.sum(w * pm._node_x[t // ks, chan], axis=2)
    y = np.sum(w * pm._node_y[t % ks, chan], axis=2)
    np.testing.assert_allclose(x, np.log10(1.0 - albedo), rtol=0, atol=1e-9)
    np.testing.assert_allclose(y, np.log(sig), rtol=0, atol=1e-9)
