"""The near-field model in the bake (``source_model="beam"``, surface/source_factors.py, docs/physics.md eq. (80)).

References are independent of the bake's sums: the near-field model's closed-form total and profile
(kernels.near_field, eq. (76)) and the planar dipole's closed-form total. A 100 mm sphere stands in for the
half-space (its curvature changes totals by < 1 %)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from meshshade.cli.main import main
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import write_ply
from meshshade.kernels.dipole import dipole_total_reflectance
from meshshade.kernels.near_field import incidence_gain, near_field_profile, near_field_total
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.output.render import PixelGather
from meshshade.transport.baking import bake
from meshshade.surface.source_factors import near_field_factors
from meshshade.transport import BakeOptions, SurfaceOptions

SKIN = Material.preset("skin1")
R = 100.0


def _totals(kind):
    f = near_field_total if kind == "beam" else dipole_total_reflectance
    return np.array([f(albedo_prime=float(SKIN.albedo_prime[c]), eta=SKIN.eta) for c in range(3)])


@pytest.fixture(scope="module")
def sphere5():
    return Mesh(*icosphere(R, 5))


@pytest.mark.parametrize("level", [5, 6])
def test_a_beam_delivers_the_near_field_total_at_any_resolution(level, sphere5):
    """Each vertex averages the near field over its patch, so the exitant power is the model's total even where
    edges (3.5 mm at level 5) are wider than the kernel's peak; the point source's point values are not (measured
    +56 % to +438 % at level 5, within 2 % at level 7)."""
    mesh = sphere5 if level == 5 else Mesh(*icosphere(R, level))
    res = bake(mesh, SKIN, [BeamLight((0.3, 0.2, R + 10.0), (0.0, 0.0, -1.0))], BakeOptions(
        model="dipole", surface=SurfaceOptions(source_model="beam")))
    e = np.array(res.stats["exitant_power"]) / res.stats["entering_power"]
    assert res.stats["near_field"] == "beam"
    np.testing.assert_allclose(e, _totals("beam"), rtol=0.012)


@pytest.mark.parametrize("material", [SKIN, Material(1.0, 0.002, 1.3, 0.0)], ids=["skin1", "alpha0.998"])
@pytest.mark.parametrize("transport", ["direct", "hierarchical"])
def test_directional_light_carries_the_near_field_total(transport, material, sphere5):
    """Vertex samples (patch factors, the self pair, the far field's tail scale, the incidence scale, the drift):
    the exitant power is each sample's entering power times the near-field model's total times its incidence gain
    (eq. (86), computed here sample by sample from kernels.near_field; the drift of eq. (88) moves light, not
    energy), where the point source gives the dipole's total
    (skin1 at normal incidence: +0.7 %, -6.5 %, -12.2 %; grazing light adds up to 16-28 %). At alpha' = 0.998 most
    of the light travels beyond the near radius, into the far field (clusters), whose tail scale is 0.96."""
    light = DirectionalLight((0.0, 0.0, -1.0))
    res = {nf: bake(sphere5, material, [light], BakeOptions(model="dipole", surface=SurfaceOptions(
               source_model=nf, transport=transport, geodesic="arc",
               far_field="clustered" if transport == "direct" else None))) for nf in ("point", "beam")}
    P = {nf: np.array(r.stats["exitant_power"]) for nf, r in res.items()}
    smp = res["beam"].samples
    ct = np.round(np.sqrt(1.0 - (1.0 - smp.cos_incidence ** 2) / material.eta ** 2), 3)   # 1e-3 bins
    u, inv = np.unique(ct, return_inverse=True)
    ratio = []
    for c in range(3):
        kw = {"albedo_prime": float(material.albedo_prime[c]), "eta": material.eta}
        tot = near_field_total(**kw) * np.array([incidence_gain(cos_t=x, **kw) for x in u])[inv.ravel()]
        ratio.append(np.sum(smp.power * tot) / (np.sum(smp.power) * dipole_total_reflectance(**kw)))
    np.testing.assert_allclose(P["beam"] / P["point"], ratio, rtol=5e-3)


def test_a_beam_bake_follows_the_near_field_profile():
    mesh = Mesh(*icosphere(R, 6))
    entry = np.array([0.3, 0.2, np.sqrt(R * R - 0.13)])
    res = bake(mesh, SKIN, [BeamLight((0.3, 0.2, R + 10.0), (0.0, 0.0, -1.0))], BakeOptions(
        model="dipole", surface=SurfaceOptions(source_model="beam")))
    s = res.beam_distance
    sel = (s > 4.0) & (s < 12.0)     # two patch radii and more from the entry point
    assert sel.sum() > 50
    for c in range(3):
        st, a = float(SKIN.sigma_t_prime[c]), float(SKIN.albedo_prime[c])
        sel_c = sel & (s < 0.8 * res.cutoff_mm[c])    # well inside the channel's cutoff
        want = near_field_profile(s[sel_c] * st, albedo_prime=a, eta=SKIN.eta) * st * st * res.stats["entering_power"]
        rel = res.radiance[sel_c, c] / want - 1.0
        assert np.abs(np.mean(rel)) < 0.02 and np.max(np.abs(rel)) < 0.05, (c, np.mean(rel), np.max(np.abs(rel)))
    assert np.linalg.norm(entry) == pytest.approx(R)
    # per-pixel: the gather at the vertices is the bake
    g = PixelGather(mesh, res)
    f = mesh.faces[:50]
    bary = np.tile([1.0, 0.0, 0.0], (50, 1))
    np.testing.assert_allclose(g(mesh.vertices[f[:, 0]], np.arange(50), bary), res.radiance[f[:, 0]], rtol=1e-9,
                               atol=1e-12 * res.radiance.max())


def test_factors_are_the_point_ratio_for_points_and_small_patches():
    f = near_field_factors(SKIN)
    s = np.array([8.0, 12.0])
    for c in range(3):
        st, a = float(SKIN.sigma_t_prime[c]), float(SKIN.albedo_prime[c])
        from meshshade.kernels.dipole import dipole_profile
        want = near_field_profile(s * st, albedo_prime=a, eta=SKIN.eta) / dipole_profile(s * st, albedo_prime=a,
                                                                                        eta=SKIN.eta)
        np.testing.assert_allclose(f.pair_factor(c, s, 0.0), want, rtol=5e-4)   # the log-log table: < 2e-4
        # a small patch: the disc averages' ratio is the point ratio
        np.testing.assert_allclose(f.pair_factor(c, s, np.array([0.05, 0.05])), want, rtol=2e-3)


def test_cli_near_field_switch(tmp_path):
    mesh = Mesh(*icosphere(10.0, 3))
    src = tmp_path / "s.ply"
    write_ply(src, mesh.vertices, mesh.faces)
    outs = {}
    for nf in ("point", "beam"):
        out = tmp_path / f"{nf}.ply"
        npz = tmp_path / f"{nf}.npz"
        assert main(["bake", str(src), "--units", "mm", "--material", "skin1",
                     "--light", "directional:0,0,-1", "--model",
                     "curved", "--source-model", nf, "--out", str(out), "--npz", str(npz), "--quiet"]) == 0
        outs[nf] = np.load(npz)["radiance"]
    assert not np.allclose(outs["point"], outs["beam"])
    assert main(["compare", str(src), "--units", "mm", "--material", "skin1",
                 "--light", "directional:0,0,-1", "--models",
                 "curved,curved", "--source-model", "point,beam", "--width", "32", "--height", "32", "--spp", "1",
                 "--out", str(tmp_path / "cmp"), "--quiet"]) == 0
    stats = json.loads((tmp_path / "cmp" / "stats.json").read_text())
    assert stats["models"] == ["curved", "curved+beam"] and (tmp_path / "cmp" / "curved+beam.exr").exists()
    assert main(["compare", str(src), "--units", "mm", "--material", "skin1",
                 "--light", "directional:0,0,-1", "--models",
                 "curved,curved", "--out", str(tmp_path / "cmp2"), "--quiet"]) == 2
    assert main(["render", str(src), "--units", "mm", "--material", "skin1", "--light", "directional:0,0,-1",
                 "--source-model", "beam", "--width", "32", "--height", "32", "--spp", "1", "--out",
                 str(tmp_path / "r"), "--quiet"]) == 0
    assert main(["bake", str(src), "--units", "mm", "--material", "skin1", "--light", "directional:0,0,-1",
                 "--source-model", "pencil", "--out", str(tmp_path / "x.ply")]) == 2


TAIL_MEDIUM = Material(1.0, 0.002, 1.3, 0.0)


@pytest.fixture(scope="module")
def tail_reference(sphere5):
    """The direct sum of every pair with its near-field factor, no far field (alpha' = 0.998, a sun along -z): the
    reference of both far fields below, baked once for the module."""
    return bake(sphere5, TAIL_MEDIUM, [DirectionalLight((0.0, 0.0, -1.0))], BakeOptions(
        model="dipole", surface=SurfaceOptions(
            source_model="beam", transport="direct", geodesic="arc", far_field="off")))


@pytest.mark.parametrize("kw", [{"transport": "direct", "far_field": "clustered", "far_tol": 0.5},
                                {"transport": "hierarchical"}], ids=["direct-clustered", "hierarchical"])
def test_the_far_field_carries_the_near_field_models_tail(kw, sphere5, tail_reference):
    """The far field sums the planar dipole times the near field's factor N(s) per pair (per cluster at its
    centroid distance) and matches the direct sum of every pair with its near-field factor. alpha' = 0.998, most
    light beyond the near radius (8.7-9.7 mm). The hierarchical far field carries the light's sideways drift
    (eq. (88)) as the reference does: measured 3e-5 in energy, 2e-4 mean per vertex. The direct sum's clustered
    far field leaves the drift out beyond r_near (docs/limitations.md), which moves light between vertices but not
    its energy: measured 1.5e-5 in energy and 1.8 % mean per vertex here, where most light is in the far field
    (3.1 % with no drift at all), so that case is held to 2.5 %."""
    ref = tail_reference
    res = bake(sphere5, TAIL_MEDIUM, [DirectionalLight((0.0, 0.0, -1.0))],
               BakeOptions(model="dipole", surface=SurfaceOptions(source_model="beam", geodesic="arc", **kw)))
    e = res.stats["exitant_power"][0] / ref.stats["exitant_power"][0] - 1.0
    lit = ref.radiance[:, 0] > 1e-3 * ref.radiance[:, 0].max()
    rel = np.abs(res.radiance[lit, 0] / ref.radiance[lit, 0] - 1.0)
    tol = 3e-3 if kw["transport"] == "hierarchical" else 2.5e-2
    assert abs(e) < 1e-3 and rel.mean() < tol, (e, rel.mean())
