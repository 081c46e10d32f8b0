"""The volume transport (docs/physics.md §15.1): the sources it gives the volume, the near field on top, the solver,
and the bake that uses them by default.

Independent routes: the exponential's moments (the line source), the closed-form totals of eqs. (75)-(76) and (93),
scipy's sparse direct solver, and on a flat slab the near-field model's own total (eq. (76) with the incidence gain
of eq. (86)): with a converged volume the two parts must add up to it exactly; measured within 0.02 % (red), 0.5 %
(green) and 1.8 % (blue) at the top's centre of a 30 x 30 x 15 mm box meshed at 1 mm, the blue limited by the
volume's resolution.
"""
import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from meshshade.errors import MeshshadeError, ParameterError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere
from meshshade.asset_cache import AssetCache
from meshshade.kernels.beam_diffusion import dipole_variant
from meshshade.kernels.fresnel import fresnel_transmittance_entry
from meshshade.kernels.near_field import incidence_gain, near_field_total
from meshshade.kernels.robin_halfspace import robin_point_source_total
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake, describe_result
from meshshade.volume.near_field import NearFieldCorrection
from meshshade.volume.sources import line_source_rule
from meshshade.volume.solve import pcg_jacobi
from meshshade.volume.transport import VolumeTransport

SKIN = Material.preset("skin1")


def test_source_rule_matches_the_line_source_moments():
    """alpha' exp(-t): moments alpha' k!; the 4-point rule is exact up to degree 7."""
    for a in (0.3, 0.9, 0.999):
        t, w = line_source_rule(a)
        for k in range(8):
            assert float(np.sum(w * t ** k)) == pytest.approx(a * math.factorial(k), rel=1e-10)


def test_correction_tables_carry_the_model_minus_the_volume_total():
    """cum(radius) + rest is the signed total W T_near - sum_j W_j T_Robin(tau_j cos_t), both in closed form."""
    corr = NearFieldCorrection(SKIN)
    for c, table in enumerate(corr.tables):
        a = float(SKIN.albedo_prime[c])
        v = dipole_variant(a, SKIN.eta, "better")
        for i, ct in enumerate(table.cos_t):
            gain = incidence_gain(albedo_prime=a, eta=SKIN.eta, g=SKIN.g, cos_t=float(ct))
            robin = sum(W * robin_point_source_total(tau * ct, D=v.D, mu=v.mu, A=v.z_b / (2 * v.D))
                        for tau, W in zip(table.tau, table.W))
            total = gain * near_field_total(albedo_prime=a, eta=SKIN.eta, g=SKIN.g) - robin
            assert table.cum[i, -1] + table.rest[i] == pytest.approx(total, rel=1e-9, abs=1e-12)
        assert 0 < corr.radius_mm[c] < 20.0


def test_near_field_in_blocks_of_sources_equals_one_block(monkeypatch):
    """The pair sum taken in blocks of nearby sources (bounded memory on dense meshes) is the same sum: against
    one block holding every pair, to rounding."""
    import meshshade.volume.near_field as nf

    mesh = Mesh.from_arrays(*icosphere(8.0, 3))
    rng = np.random.default_rng(3)
    k = 300
    src = mesh.vertices[rng.choice(mesh.n_vertices, k, replace=False)]
    normal = src / np.linalg.norm(src, axis=1, keepdims=True)
    args = (src, normal, rng.uniform(0.5, 1.0, k), rng.uniform(0.3, 1.0, k), np.full(k, 0.2), mesh.vertices,
            mesh.vertex_normals, np.sqrt(mesh.vertex_areas / math.pi))
    corr = NearFieldCorrection(SKIN)
    whole, pairs = corr.exitance(*args)
    monkeypatch.setattr(nf, "PAIR_BLOCK", 2000)
    blocks, pairs_b = corr.exitance(*args)
    assert pairs_b == pairs and pairs > 10 * 2000
    np.testing.assert_allclose(blocks, whole, rtol=1e-12, atol=1e-12 * np.abs(whole).max())


@pytest.mark.parametrize("k", [1, 3])
def test_pcg_matches_a_direct_solve(k):
    rng = np.random.default_rng(3)
    n = 400
    A0 = sp.random(n, n, density=0.02, random_state=4)
    base = (A0 @ A0.T + sp.eye(n) * 0.5).tocsr()
    mats = [(base + sp.eye(n) * (0.1 * c)).tocsr() for c in range(k)]
    for m in mats:
        m.sort_indices()
    pattern = sum(mats).tocsr()
    pattern.sort_indices()
    data = np.stack([np.asarray(m[pattern.nonzero()]).ravel() for m in mats], axis=1)
    # rows of pattern.nonzero() are in CSR order already
    b = rng.random((n, k))
    x, its, ok = pcg_jacobi(pattern.indptr, pattern.indices, data, b, rtol=1e-12)
    assert ok.all() and np.all(its > 0)
    for c in range(k):
        np.testing.assert_allclose(x[:, c], spla.spsolve(mats[c].tocsc(), b[:, c]), rtol=1e-8, atol=1e-12)


@pytest.fixture(scope="module")
def slab():
    return Mesh.from_arrays(*box((30.0, 30.0, 15.0), 30))


@pytest.mark.parametrize("theta", [0.0, 45.0])
def test_flat_slab_returns_the_near_field_model(slab, theta):
    """At the top's centre (7.5 mm from its edges... 4 diffusion lengths in red) a uniform sun gives
    E cos(theta) F_t W(theta) T_near per unit irradiance: measured 1.0001/0.995/0.982 at 0 deg, 1.001/0.990/0.991
    at 45 deg (per-vertex spread 0.7/2.1/3.4 %: the jittered tetrahedra)."""
    d = (math.sin(math.radians(theta)), 0.0, -math.cos(math.radians(theta)))
    res = bake(slab, SKIN, [DirectionalLight(d, 1.0)])
    assert res.model == "volume" and res.stats["transport"] == "volume"
    V = slab.vertices
    top = (np.abs(V[:, 2] - 7.5) < 1e-9) & (np.abs(V[:, 0]) <= 3.0) & (np.abs(V[:, 1]) <= 3.0)
    ci = math.cos(math.radians(theta))
    ct = math.sqrt(1.0 - (math.sin(math.radians(theta)) / SKIN.eta) ** 2)
    ft = float(fresnel_transmittance_entry(np.array([ci]), SKIN.eta)[0])
    for c, tol in ((0, 0.01), (1, 0.015), (2, 0.03)):
        a = float(SKIN.albedo_prime[c])
        T = near_field_total(albedo_prime=a, eta=SKIN.eta, g=SKIN.g) * incidence_gain(
            albedo_prime=a, eta=SKIN.eta, g=SKIN.g, cos_t=ct)
        assert res.radiance[top, c].mean() / (ci * ft * T) == pytest.approx(1.0, abs=tol), c


@pytest.fixture(scope="module")
def ball():
    return Mesh.from_arrays(*icosphere(10.0, 3))


def test_volume_is_the_default_and_reusable(ball, tmp_path, monkeypatch):
    monkeypatch.setenv("MESHSHADE_ASSET_CACHE", str(tmp_path))
    light = [DirectionalLight((0.0, 0.3, -1.0), 1.0)]
    first = bake(ball, SKIN, light, volume_cache=AssetCache("volume"))
    assert first.model == "volume" and isinstance(first.volume, VolumeTransport)
    assert first.stats["volume_tetrahedra_cached"] is False and len(list(tmp_path.glob("volume/*.npz"))) == 1
    again = bake(ball, SKIN, light, volume_cache=AssetCache("volume"))
    assert again.stats["volume_tetrahedra_cached"] is True
    np.testing.assert_array_equal(first.radiance, again.radiance)
    reused = bake(ball, SKIN, light, volume=first.volume)
    np.testing.assert_array_equal(first.radiance, reused.radiance)
    assert "volume:" in describe_result(first) and "tetrahedra" in describe_result(first)
    assert np.all(first.radiance >= 0) and first.radiance.max() > 0


def test_beam_power_balance(ball):
    """Every entering watt either leaves (the exitant power) or is absorbed: the exitant power is below the
    entering power and above the half-space's near-field total fraction of it (a ball returns more than a plane)."""
    res = bake(ball, SKIN, [BeamLight((0.0, 0.0, 30.0), (0.0, 0.0, -1.0))])
    ex = np.array(res.stats["exitant_power"])
    entering = res.stats["entering_power"]
    totals = np.array([near_field_total(albedo_prime=float(a), eta=SKIN.eta, g=SKIN.g) for a in SKIN.albedo_prime])
    assert np.all(ex < entering) and np.all(ex > 0.9 * totals * entering)


def test_open_mesh_falls_back_and_says_why(ball, caplog):
    V, F = icosphere(10.0, 3)
    keep = V[F].mean(axis=1)[:, 2] < 8.0        # cut a cap off: an open surface
    res = bake(Mesh.from_arrays(V, F[keep]), SKIN, [DirectionalLight((0.0, 0.0, 1.0), 1.0)])
    assert res.model == "auto" and "volume transport not used: the mesh is not closed" in res.stats["transport"]
    assert res.stats["near_field"] == "beam"


@pytest.mark.parametrize("kwargs, word", [({"source_model": "point"}, "beam source model"),
                                          ({"transport": "direct"}, "surface models"),
                                          ({"far_field": "clustered"}, "far-field option")])
def test_options_of_the_surface_models_are_refused(ball, kwargs, word):
    with pytest.raises(ParameterError, match=word):
        bake(ball, SKIN, [DirectionalLight((0.0, 0.0, -1.0), 1.0)], **kwargs)


def test_a_volume_of_another_mesh_is_refused(ball):
    other = Mesh.from_arrays(*icosphere(10.0, 2))
    vt = VolumeTransport.build(other, SKIN)
    with pytest.raises(MeshshadeError, match="another mesh"):
        bake(ball, SKIN, [DirectionalLight((0.0, 0.0, -1.0), 1.0)], volume=vt)


def test_per_pixel_near_field_equals_the_bake_at_vertices(ball):
    """render's per-pixel exitance (PixelGather) with the volume model: the bake's value at every vertex, and
    at a beam's entry point the near field evaluated there (measured 10, 8 and 4 % above the interpolated value,
    r/g/b)."""
    from meshshade.output.render import PixelGather

    res = bake(ball, SKIN, [BeamLight((0.3, 0.2, 30.0), (0.0, 0.0, -1.0))])
    gather = PixelGather(ball, res)
    F = ball.faces
    face = np.repeat(np.arange(F.shape[0]), 3)
    bary = np.tile(np.eye(3), (F.shape[0], 1))
    points = ball.vertices[F.reshape(-1)]
    np.testing.assert_allclose(gather(points, face, bary), res.radiance[F.reshape(-1)], rtol=1e-9, atol=1e-15)
    entry = res.samples.positions[0]
    f0 = int(res.samples.face[0])
    at_entry = gather(entry[None], np.array([f0]), res.samples.bary[:1])
    interpolated = res.samples.bary[0] @ res.radiance[F[f0]]
    assert np.all(at_entry > 1.02 * interpolated)      # the beam's peak, which interpolation flattens


def test_a_material_far_below_the_mesh_resolution_uses_the_surface_models(ball):
    """sigma_a = 50 /mm (diffusion length 0.011 mm against 1.5 mm edges): layers that thin would be slivers, and
    the light stays within a vertex's patch: the bake says so and uses auto; the result is finite and positive."""
    with pytest.warns(Warning, match="albedo"):     # diffusion's validity, said when the material is made
        mat = Material([1.0, 1.0, 1.0], [50.0, 50.0, 50.0])
    res = bake(ball, mat, [BeamLight((0.0, 0.0, 30.0), (0.0, 0.0, -1.0))])
    assert res.model == "auto" and "far below the mesh's edge length" in res.stats["transport"]
    assert np.all(np.isfinite(res.radiance)) and res.radiance.max() > 0


def test_a_surface_vertex_in_no_tetrahedron_is_read_by_interpolation():
    """A surface vertex left in no tetrahedron (a spike's tip the mesher could not keep; here planted by removing
    the tetrahedra around one vertex of a ball): the operator stays definite (1 on its diagonal), the vertex's
    exitance is interpolated in the tetrahedron holding it, said in stats, and stays near the full mesh's value
    there (the dent costs one patch of volume: measured +7.3 / +6.4 / +5.7 %, r/g/b)."""
    mesh = Mesh.from_arrays(*icosphere(10.0, 3))
    full = VolumeTransport.build(mesh, SKIN)
    tm = full.tetra
    keep = ~np.any(tm.tets == 0, axis=1)
    dented = VolumeTransport.build(mesh, SKIN, tetra=tm._replace(tets=tm.tets[keep]))
    assert dented.stats["volume_vertices_interpolated"] == 1 and full.stats["volume_vertices_interpolated"] == 0
    light = [DirectionalLight((0.3, 0.2, -1.0), 1.0)]
    a = bake(mesh, SKIN, light, volume=full).radiance
    b = bake(mesh, SKIN, light, volume=dented).radiance
    assert np.all(np.isfinite(b)) and np.all(b[0] > 0)
    np.testing.assert_allclose(b[0], a[0], rtol=0.1)
    far = np.linalg.norm(mesh.vertices - mesh.vertices[0], axis=1) > 5.0
    np.testing.assert_allclose(b[far], a[far], rtol=0.02, atol=1e-4 * a.max())
