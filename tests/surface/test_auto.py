"""``--model auto``: the per-sample decisions (meshshade/surface/auto.py) and their use in the bake and the CLI."""
import contextlib

import numpy as np
import pytest
import trimesh
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from meshshade import transport
from meshshade.cli.main import main
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box, icosphere
from meshshade.geometry.topology import vertex_adjacency
from meshshade.io import write_ply
from meshshade.kernels.curvature import curvature_ratios
from meshshade.kernels.dipole import dipole_profile
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import material_from_options
from meshshade.surface import auto, cutoff_radii, zones
from meshshade.surface.models import Kernel
from meshshade.transport import BakeOptions, SurfaceOptions

SKIN = material_from_options("skin1")


# ------------------------------------------------------------------------------------------- graph dilation
def test_dilated_max_matches_breadth_first_search(rng):
    V, F = icosphere(1.0, 2)
    n = len(V)
    vals = rng.random(n)
    indptr, indices = vertex_adjacency(n, F)
    # independent route: hop distances of the unweighted vertex graph from scipy's csgraph
    A = csr_matrix((np.ones(indices.size), indices, indptr), shape=(n, n))
    hops = shortest_path(A, unweighted=True)
    for rings in (0, 1, 2, 5):
        want = np.array([vals[hops[v] <= rings].max() for v in range(n)])
        np.testing.assert_array_equal(auto.dilated_max(vals, indptr, indices, rings), want)


# ------------------------------------------------------------------------------------------- bounds
@pytest.mark.parametrize("name", ["skin1", "marble", "ketchup"])
def test_curvature_bound_bounds_delta_of_every_pair(name, rng):
    """|delta| = |k_n(phi) a + k_n(phi + pi/2) b| <= kmax W for random curvatures, azimuths and rho <= radius."""
    with pytest.warns(Warning) if name == "ketchup" else contextlib.nullcontext():
        mat = material_from_options(name)
    radius = np.array([12.0, 7.0, 3.0])
    W = auto.curvature_bound_mm(mat, radius)
    for c in range(3):
        ch = mat.channel(c)
        st = ch["sigma_t_prime"]
        rho_mm = rng.random(4000) * radius[c]
        a, b = curvature_ratios(rho_mm * st, albedo_prime=ch["albedo_prime"], eta=ch["eta"])
        k1, k2 = rng.normal(0, 0.05, (2, rho_mm.size))
        phi = rng.random(rho_mm.size) * 2 * np.pi
        kn = k1 * np.cos(phi) ** 2 + k2 * np.sin(phi) ** 2
        kn90 = k1 * np.sin(phi) ** 2 + k2 * np.cos(phi) ** 2
        delta = kn * a / st + kn90 * b / st  # a, b in optical units, curvature in 1/mm
        kmax = np.maximum(np.abs(k1), np.abs(k2))
        assert np.all(np.abs(delta) <= kmax * W[c] * (1 + 1e-12))
        # and the bound is attained (to the grid) on a sphere at the radius: W = C(radius) there
        a_r, b_r = curvature_ratios(radius[c] * st, albedo_prime=ch["albedo_prime"], eta=ch["eta"])
        assert W[c] == pytest.approx((abs(a_r) + abs(b_r)) / st, rel=0.02)


# ------------------------------------------------------------------------------------------- decisions
def test_plan_flat_surface_uses_dipole_and_arc():
    k = np.zeros(5)
    plan = auto.plan_sources(k, k, k, k, SKIN, 10.0, 20.0)
    assert np.all(plan.kernel == Kernel.DIPOLE_SURFACE) and not plan.exact_geodesic.any() and plan.far_dipole.all()
    assert plan.counts()["auto_kernel_dipole"] == 5 and plan.counts()["auto_geodesic_arc"] == 5


def test_plan_small_sphere_uses_exact_sphere_and_saddle_uses_fitted():
    """Out of first-order range: the exact sphere where the neighbourhood is that sphere, the fitted model
    elsewhere (a saddle, a cylinder, an umbilic point on a bumpy surface)."""
    R0 = 10.0
    k1 = np.array([1 / R0, 0.05, 0.03])
    k2 = np.array([1 / R0, -0.05, 0.0])
    cut = cutoff_radii(SKIN, 1e-4)
    kn = np.maximum(np.abs(k1), np.abs(k2))
    plan = auto.plan_sources(k1, k2, kn, kn, SKIN, cut.max(), cut)
    assert plan.kernel.tolist() == [Kernel.EXACT_SPHERE, Kernel.FITTED, Kernel.FITTED]
    assert plan.exact_geodesic.all() and not plan.far_dipole.any()
    # the same umbilic point on a bumpy surface (larger or smaller curvatures within the cutoff): fitted
    bumpy = auto.plan_sources(k1[:1], k2[:1], kn[:1], 1.5 * kn[:1], SKIN, cut.max(), cut)
    dent = auto.plan_sources(k1[:1], k2[:1], kn[:1], kn[:1], SKIN, cut.max(), cut, kmin_far=[0.0])
    assert bumpy.kernel[0] == Kernel.FITTED and dent.kernel[0] == Kernel.FITTED


def test_plan_threshold_is_the_documented_bound():
    """Just below / above curvature_tol / (W): dipole / curved (the decision is the stated inequality)."""
    radius = cutoff_radii(SKIN, 1e-4)
    W = auto.curvature_bound_mm(SKIN, radius).max()
    k = np.array([0.99, 1.01]) * 1e-2 / W
    plan = auto.plan_sources(k, k * 0.5, k, k, SKIN, radius.max(), radius)
    assert plan.kernel.tolist() == [Kernel.DIPOLE_SURFACE, Kernel.CURVED]
    assert plan.far_dipole.tolist() == [True, False]


def test_plan_rejects_bad_tolerances():
    with pytest.raises(ValueError, match="curvature_tol"):
        auto.plan_sources([0.0], [0.0], [0.0], [0.0], SKIN, 5.0, 5.0, curvature_tol=-1)
    with pytest.raises(ValueError, match="geodesic_tol"):
        auto.plan_sources([0.0], [0.0], [0.0], [0.0], SKIN, 5.0, 5.0, geodesic_tol=float("nan"))


# ------------------------------------------------------------------------------------------- bake
@pytest.fixture(scope="module")
def sphere10():
    return Mesh.from_arrays(*icosphere(10.0, 3))


def test_auto_with_everything_forced_curved_equals_curved(sphere10):
    """With curvature_tol = 0, validity_tol = inf and geodesic_tol = 0 auto must reproduce `curved` exactly."""
    light = [DirectionalLight((0.3, -0.2, -1.0), 1.0)]
    ref = transport.bake(sphere10, SKIN, light, BakeOptions(model="curved", surface=SurfaceOptions(transport="direct")))
    opts = dict(curvature_tol=0.0, validity_tol=np.inf, geodesic_tol=0.0)
    got = transport.bake(sphere10, SKIN, light, BakeOptions(
        model="auto", surface=SurfaceOptions(auto=opts, far_field="off", transport="direct")))
    assert got.stats["auto_kernel_curved"] == got.stats["entry_samples"]
    np.testing.assert_allclose(got.radiance, ref.radiance, rtol=1e-12, atol=0)
    # far zone on geodesics shared by groups of samples (default) or on arc geodesics, exact within r_near.
    # Groups: the law of cosines on the centre's constant-curvature triangle (test_sample_groups: ~1e-3 mm
    # mean). Arcs follow the smooth sphere's great circles, while the polyhedral geodesics of this coarse sphere
    # (1.3 mm edges) are shorter by O(h^2), ~0.3 % (test_neighbourhood); at s ~ 20 mm the red kernel falls by
    # d ln R/ds ~ -(sigma_tr + 2/s) ~ -0.37/mm, so the dim far side may move by up to 0.3 % * 20 mm * 0.37/mm ~ 2.2 %
    lit = ref.radiance > 1e-3 * ref.radiance.max(axis=0)
    assert zones.groups_pay(sphere10, cutoff_radii(SKIN, 1e-4))
    for far_geodesic, zone, max_tol, median_tol in (("shared", "zone_exact_near_shared_far", 0.01, 2e-4),
                                                   ("arc", "zone_exact_near_arc_far", 0.025, 2e-3)):
        split = transport.bake(sphere10, SKIN, light, BakeOptions(
            model="auto", surface=SurfaceOptions(auto=opts, far_geodesic=far_geodesic, transport="direct")))
        assert split.stats[zone] == split.stats["entry_samples"]
        if far_geodesic == "shared":  # one exact far query per group instead of per sample
            assert split.stats["geodesic_pairs_computed"] < 0.6 * ref.stats["geodesic_pairs_computed"]
        rel = np.abs(split.radiance - ref.radiance)[lit] / ref.radiance[lit]
        assert rel.max() < max_tol and np.median(rel) < median_tol, (far_geodesic, rel.max(), np.median(rel))
    # geodesic="arc" caps auto at arc geodesics everywhere
    arc = transport.bake(sphere10, SKIN, light, BakeOptions(
        model="auto", surface=SurfaceOptions(auto=opts, geodesic="arc", transport="direct")))
    assert arc.stats["zone_arc"] == arc.stats["entry_samples"] and arc.stats["auto_geodesic_exact"] == 0


def test_auto_on_small_sphere_picks_the_exact_sphere(sphere10):
    """R0 = 10 mm in skin is umbilic and outside first-order validity: auto = the exact-sphere model there."""
    light = [BeamLight((0.3, 0.2, 40.0), (0, 0, -1))]
    ref = transport.bake(sphere10, SKIN, light, BakeOptions(model="exact-sphere"))
    got = transport.bake(sphere10, SKIN, light, BakeOptions(model="auto"))
    assert got.stats["auto_kernel_exact-sphere"] == 1 and got.stats["auto_geodesic_exact"] == 1
    np.testing.assert_allclose(got.radiance, ref.radiance, rtol=1e-12, atol=0)


def test_auto_flat_forced_dipole_equals_geodesic_dipole(sphere10):
    """curvature_tol = inf: every sample uses the planar dipole of the geodesic distance = curved at k = 0."""
    light = [BeamLight((0.3, 0.2, 40.0), (0, 0, -1))]
    got = transport.bake(sphere10, SKIN, light, BakeOptions(
        model="auto", surface=SurfaceOptions(auto=dict(curvature_tol=np.inf, geodesic_tol=0.0))))
    assert got.stats["auto_kernel_dipole"] == 1
    d = got.beam_distance
    ok = np.isfinite(d) & (d > 1.0)
    F_t = got.samples.power[0]
    for c in range(3):
        ch = SKIN.channel(c)
        st = ch["sigma_t_prime"]
        want = F_t * dipole_profile(d[ok] * st, albedo_prime=ch["albedo_prime"], eta=ch["eta"]) * st * st
        keep = d[ok] <= got.cutoff_mm[c]
        np.testing.assert_allclose(got.radiance[ok, c][keep], want[keep], rtol=1e-10)


def test_groups_pay_on_a_fine_large_mesh():
    """The cost estimate: a 60 mm sphere with 0.6 mm edges in skin (cutoff 28 mm, groups of 2.4 mm)
    saves most geodesic pairs; a 4 mm sphere with 1.3 mm edges (near zone = the whole sphere) saves nothing."""
    cut = cutoff_radii(SKIN, 1e-4)
    big = Mesh.from_arrays(*icosphere(60.0, 6))
    small = Mesh.from_arrays(*icosphere(4.0, 2))
    assert zones.groups_pay(big, cut) and not zones.groups_pay(small, cut)


# ------------------------------------------------------------------------------------------- CLI
def test_cli_auto_reports_decisions(tmp_path, capsys):
    V, F = icosphere(10.0, 3)
    src = tmp_path / "s.ply"
    write_ply(src, V, F)
    out, npz = tmp_path / "o.ply", tmp_path / "o.npz"
    assert main(["bake", str(src), "--material", "skin1", "--light", "beam:0,0,40:0,0,-1", "--model", "auto",
                 "--out", str(out), "--npz", str(npz)]) == 0
    text = capsys.readouterr().out
    assert "auto: kernel dipole 0, curved 0, exact-sphere 1, fitted 0 entry samples" in text
    header = out.read_bytes().split(b"end_header")[0].decode("ascii")
    assert "comment meshshade auto: kernel dipole 0, curved 0, exact-sphere 1" in header
    assert trimesh.load(out, process=False).vertices.shape == V.shape
    data = np.load(npz)
    assert data["auto_kernel"].tolist() == [Kernel.EXACT_SPHERE]
    assert data["auto_exact_geodesic"].tolist() == [True]


# ------------------------------------------------------------------------------------------- far field in the bake
MARBLE = material_from_options("marble")


@pytest.fixture(scope="module")
def sphere40():
    return Mesh.from_arrays(*icosphere(40.0, 3))


def test_far_field_dipole_model_matches_no_far_field(sphere40):
    """The dipole model's kernel is R_d(chord) in the near zone too, so moving pairs beyond r_near to the (exact,
    "direct") far-field sum must reproduce the plain bake up to the pairs the partition treats differently: those
    with chord <= cutoff < geodesic (added) and chord <= r_near < geodesic (dropped). On a convex sphere of radius
    40 mm the chord and geodesic differ by s^3/(24 R^2) < 3.5 mm at 48 mm, so only pairs within that shell of the
    cutoff (where the dipole holds ~1e-4 of its energy) differ. Where the exitance comes from nearby sources
    (M > 5 % of the peak: the lit side and past the terminator) that share is < 1e-3; in the dim far side, which
    is lit only through the shell, it is not small (measured up to 8 %), and the test says nothing there."""
    light = [DirectionalLight((0.3, -0.2, -1.0), 1.0)]
    off = transport.bake(sphere40, MARBLE, light, BakeOptions(
        model="dipole", surface=SurfaceOptions(geodesic="arc", transport="direct")))
    direct = transport.bake(sphere40, MARBLE, light, BakeOptions(
        model="dipole", surface=SurfaceOptions(geodesic="arc", far_field="pairwise", transport="direct")))
    clustered = transport.bake(sphere40, MARBLE, light, BakeOptions(
        model="dipole", surface=SurfaceOptions(geodesic="arc", far_field="clustered", far_rel_tol=1e-2)))
    assert direct.stats["zone_arc_near"] == direct.stats["entry_samples"]
    assert np.all(np.array(direct.stats["near_mm"]) < np.array(direct.stats["cutoff_mm"]))
    lit = off.radiance > 5e-2 * off.radiance.max(axis=0)
    rel = np.abs(direct.radiance - off.radiance)[lit] / off.radiance[lit]
    assert rel.max() < 1e-3, rel.max()
    # the clustered sum is within its guaranteed relative error of the direct one (on the far part, hence total)
    pos = direct.radiance > 0
    rel_c = np.abs(clustered.radiance - direct.radiance)[pos] / direct.radiance[pos]
    assert np.all(rel_c <= 1e-2 * (1 + 1e-9))  # (cluster acceptance itself: tests/test_farfield.py)


def test_auto_uses_clustered_far_field_only_where_flat(sphere40):
    """On a 40 mm sphere in marble nothing is flat on the scale of the 48 mm cutoff: no clustered far field;
    with curvature_tol = inf (declare everything flat) all vertex samples go to the clustered zone."""
    light = [DirectionalLight((0.3, -0.2, -1.0), 1.0)]
    r = transport.bake(sphere40, MARBLE, light, BakeOptions(model="auto", surface=SurfaceOptions(transport="direct")))
    assert r.stats.get("zone_exact_near", 0) + r.stats.get("zone_arc_near", 0) == 0
    flat = transport.bake(sphere40, MARBLE, light, BakeOptions(
        model="auto", surface=SurfaceOptions(auto=dict(curvature_tol=np.inf), transport="direct")))
    assert flat.stats.get("zone_exact_near", 0) + flat.stats.get("zone_arc_near", 0) == flat.stats["entry_samples"]
    # the clustered far field covers every (vertex, source, channel) pair with near_c < chord <= cutoff_c: an
    # independent brute-force count (numpy, all pairs) equals the leaf pairs when no cluster is accepted (rel_tol
    # 1e-2 on these 321 sources: 110340 pairs), else clusters replace some of them
    y = flat.samples.positions[flat.samples.power > 0]
    chord = np.sqrt(((sphere40.vertices[:, None, :] - y[None, :, :]) ** 2).sum(-1))
    near, cut = flat.stats["near_mm"], flat.stats["cutoff_mm"]
    n_far = sum(int(np.count_nonzero((chord > near[c]) & (chord <= cut[c]))) for c in range(3))
    assert n_far > 0
    if flat.stats["far_clusters_accepted"] == 0:
        assert flat.stats["far_pairs_exact"] == n_far
    else:
        assert flat.stats["far_pairs_exact"] < n_far


def test_neighbourhood_curvature_ball_query_and_dilation_agree_on_a_sphere_patch():
    """Both routes (k-d ball for few samples, graph dilation for many) are >= the max over the geodesic disc and
    pick the one bump within reach: a unit bump value at one vertex is seen by samples within the radius only."""
    V, F = icosphere(10.0, 3)
    vals = np.zeros(len(V))
    vals[0] = 1.0
    d0 = np.linalg.norm(V - V[0], axis=1)
    idx = np.argsort(d0)[::40]
    samples = type("S", (), {"vertex": idx, "face": np.full(idx.size, -1), "positions": V[idx],
                             "__len__": lambda self: idx.size})()
    edge = float(np.mean(np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1)))
    (ball,) = auto.neighbourhood_curvature(samples, vals, V, F, [5.0], edge, ball_query_below=10 ** 9)
    (dil,) = auto.neighbourhood_curvature(samples, vals, V, F, [5.0], edge, ball_query_below=0)
    assert np.all(ball[d0[idx] <= 5.0, 0] == 1) and np.all(ball[d0[idx] > 5.0, 0] == 0)
    assert np.all(dil[d0[idx] <= 5.0, 0] == 1)  # dilation by ceil(5/edge) + 1 rings reaches at least 5 mm
    assert np.all(dil[d0[idx] > 12.0, 0] == 0)  # and not absurdly far


def test_cli_far_field_flag(tmp_path):
    V, F = icosphere(40.0, 3)
    src = tmp_path / "s.ply"
    write_ply(src, V, F)
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    common = ["bake", str(src), "--material", "marble", "--light", "directional:0,0,-1:1", "--model", "dipole",
              "--geodesic", "arc", "-q"]
    assert main(common + ["--out", str(tmp_path / "a.ply"), "--npz", str(a)]) == 0
    assert main(common + ["--far-field", "clustered", "--out", str(tmp_path / "b.ply"), "--npz", str(b)]) == 0
    ra, rb = np.load(a)["radiance"], np.load(b)["radiance"]
    lit = ra > 5e-2 * ra.max(axis=0)
    assert not np.array_equal(ra, rb)  # the far field did something ...
    assert np.max(np.abs(rb - ra)[lit] / ra[lit]) < 1e-2  # ... within 1 % where light is (see the test above)
    assert main(common + ["--far-field", "bogus", "--out", str(tmp_path / "c.ply")]) == 2  # argparse's error


def test_auto_on_a_large_marble_box_uses_dipole_arc_and_far_field():
    """Face interiors of a 300 mm box are flat on marble's 48 mm cutoff: dipole kernel, arc geodesics and the
    clustered far field there; the fitted model (out of first-order range) and exact geodesics near edges and
    corners. Auto must stay close to `fitted` everywhere (the fitted model is the dipole at k = 0, exactly) while
    computing fewer geodesic pairs."""
    mesh = Mesh.from_arrays(*box((300.0, 300.0, 300.0), 30))
    light = [DirectionalLight((0.2, 0.1, -1.0), 1.0)]
    ref = transport.bake(mesh, MARBLE, light, BakeOptions(model="fitted", surface=SurfaceOptions(transport="direct")))
    got = transport.bake(mesh, MARBLE, light, BakeOptions(model="auto", surface=SurfaceOptions(transport="direct")))
    s = got.stats
    assert s["auto_kernel_dipole"] > 0 and s["auto_kernel_curved"] + s["auto_kernel_fitted"] > 0
    assert s.get("zone_arc_near", 0) + s.get("zone_exact_near", 0) > 0 and s["far_field"] == "clustered"
    assert s["geodesic_pairs_computed"] < ref.stats["geodesic_pairs_computed"]
    # where every pair within the cutoff stays on one face the two are the same kernel (the fitted model's pairs
    # across an edge see the edge's bend, eq. (85), which auto's dipole sources do not)
    v = mesh.vertices
    inner = np.sort(150.0 - np.abs(v), axis=1)[:, 1] > cutoff_radii(MARBLE, 1e-4).max()
    lit = (ref.radiance[:, 0] > 1e-3 * ref.radiance[:, 0].max()) & inner
    assert lit.sum() > 200
    rel = np.abs(got.radiance - ref.radiance)[lit, 0] / ref.radiance[lit, 0]
    assert rel.mean() < 5e-3 and np.quantile(rel, 0.99) < 0.02, (rel.mean(), np.quantile(rel, 0.99))
