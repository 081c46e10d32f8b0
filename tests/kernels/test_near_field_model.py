"""The fitted near-field model (meshshade.kernels.near_field): exact single scattering plus d'Eon dipoles at fixed
depths on the beam, with strengths fitted to the exact half-space Monte Carlo (tools/tables/make_near_field_table.py).

Held out: the media here are checked against a fresh Monte Carlo run with seeds the table never used, and most lie
between the grid's nodes (eta = 1.3, g = 0.8, skin1's albedos), so the check covers the fit and the interpolation.
Targets (issue 14, half-space): ring averages within 10 % for 0.1 <= s < 0.5 mm and 5 % beyond, totals within 1 %
(plus the Monte Carlo's own 4 standard errors).
"""
from __future__ import annotations

import cProfile
import json
import math
import pstats

import numpy as np
import pytest
from scipy.integrate import quad

from meshshade.kernels import near_field_table as table
from meshshade.kernels.near_field import (FIT_DOMAIN, incidence_gain, near_field_model, near_field_profile,
                                          near_field_ring, near_field_sources, near_field_total)
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile

HELD_OUT = [(1.0, 0.01, 1.3, 0.0), (1.0, 0.1, 1.0, 0.0), (1.0, 0.1, 1.3, 0.8), (0.74, 0.032, 1.3, 0.0),
            (1.01, 0.48, 1.3, 0.0)]


@pytest.mark.parametrize("sigma_s_prime, sigma_a, eta, g", HELD_OUT)
def test_held_out_media_meet_the_near_field_targets(sigma_s_prime, sigma_a, eta, g):
    m = Material(sigma_s_prime, sigma_a, eta, g)
    s = np.array([0.1, 0.25, 0.5, 1.0, 2.0, 4.0])
    mc = shape_mc_profile(m, s, shape="plane", photons=300_000, seed=777)
    st = float(m.sigma_t_prime[0])
    a = float(m.albedo_prime[0])
    model = near_field_ring(mc.lo * st, mc.hi * st, albedo_prime=a, eta=eta, g=g) * st * st
    ref, err = mc.reflectance[0], mc.stderr[0]
    tol = np.where(s < 0.5, 0.10, 0.05) * ref + 4.0 * err
    assert np.all(np.abs(model - ref) < tol), (model / ref - 1.0, err / ref)
    total = near_field_total(albedo_prime=a, eta=eta, g=g)
    assert abs(total - mc.total[0]) < 0.01 * mc.total[0] + 4.0 * mc.total_stderr[0], (total, mc.total[0])


@pytest.mark.parametrize("a, eta, g", [(0.99, 1.3, 0.0), (0.9, 1.0, 0.8), (0.7, 1.6, 0.4)])
def test_profile_ring_and_total_agree(a, eta, g):
    f = lambda r: 2 * math.pi * r * near_field_profile(r, albedo_prime=a, eta=eta, g=g)  # noqa: E731
    total = sum(quad(f, lo, hi, limit=400, epsrel=1e-10)[0] for lo, hi in ((0, 0.01), (0.01, 1), (1, 20), (20, 400)))
    assert total == pytest.approx(near_field_total(albedo_prime=a, eta=eta, g=g), rel=1e-6)
    lo, hi = 0.3, 0.4
    want = quad(f, lo, hi, epsrel=1e-11)[0] / (math.pi * (hi * hi - lo * lo))
    assert near_field_ring(lo, hi, albedo_prime=a, eta=eta, g=g) == pytest.approx(want, rel=1e-8)


def test_interpolation_returns_the_nodes_and_is_continuous():
    i, j, k = 3, 2, 1
    a = 1.0 - 10.0 ** table.X_NODES[i]
    depths, w, clamped = near_field_sources(a, table.ETA_NODES[j], table.G_NODES[k])
    np.testing.assert_allclose(w, table.WEIGHTS[i, j, k], rtol=1e-12, atol=1e-15)
    assert not clamped and np.array_equal(depths, table.DEPTHS)
    eps = 1e-9
    _, w1, _ = near_field_sources(a + eps, table.ETA_NODES[j] + eps, table.G_NODES[k] + eps)
    np.testing.assert_allclose(w1, w, atol=1e-6)


def test_outside_the_fitted_domain_is_clamped_and_said():
    assert near_field_sources(0.9999, 1.3, 0.0)[2] and near_field_sources(0.9, 1.3, 0.95)[2]
    assert not near_field_sources(0.95, 1.3, 0.5)[2] and not near_field_sources(0.05, 1.3, 0.0)[2]
    assert near_field_sources(0.01, 1.3, 0.0)[2]
    lo, hi = FIT_DOMAIN["albedo_prime"]
    assert 0.015 < lo < 0.02 and 0.998 < hi < 1.0      # the grid's x nodes -0.008 and -3 (make_near_field_table)


def test_profile_near_field_beam_is_the_near_field_in_mm(tmp_path):
    from meshshade.cli.main import main
    from meshshade.errors import MeshshadeError
    from meshshade.profiles import Shape, reflectance_profile

    m = Material.preset("skin1")
    s = np.array([0.1, 0.5, 2.0])
    for model in ("dipole", "exact", "curved"):   # on the plane every model's near field is the half-space's
        R = reflectance_profile(m, s, model=model, source_model="beam")
        for c in range(3):
            st = float(m.sigma_t_prime[c])
            want = near_field_profile(s * st, albedo_prime=float(m.albedo_prime[c]), eta=m.eta, g=m.g) * st * st
            np.testing.assert_allclose(R[c], want, rtol=1e-12)
    # the dipole on a sphere: at the chord, as the point-source dipole
    Rs = reflectance_profile(m, np.array([5.0]), model="dipole", shape=Shape.make("sphere", 5.0), source_model="beam")
    chord = 2 * 5.0 * math.sin(0.5)
    st = float(m.sigma_t_prime[0])
    assert Rs[0, 0] == pytest.approx(near_field_profile(chord * st, albedo_prime=float(m.albedo_prime[0]), eta=m.eta,
                                                        g=m.g) * st * st, rel=1e-12)
    with pytest.raises(MeshshadeError, match="--source-model beam"):
        reflectance_profile(m, s, model="beam")
    with pytest.raises(MeshshadeError, match="source model"):
        reflectance_profile(m, s, source_model="pencil")
    assert main(["profile", "--material", "skin1", "--models", "dipole,curved", "--source-model", "beam", "--distances",
                 "0.1,1", "--plot", str(tmp_path / "p.png"), "--quiet"]) == 0
    assert (tmp_path / "p.png").stat().st_size > 0
    assert main(["profile", "--material", "skin1", "--models", "beam"]) == 2
    # both near fields in one call: curves named model and model+beam, Monte Carlo once
    from meshshade.profiles import profile_rows
    rows = profile_rows(m, s, models=["exact", "mc"], shapes=[Shape.make("sphere", 10.0)], photons=20_000,
                        source_model=["point", "beam"])
    assert sorted({r["model"] for r in rows}) == ["exact", "exact+beam", "mc"] and len(rows) == 9
    assert main(["profile", "--material", "skin1", "--shape", "sphere", "--radius", "10", "--models", "exact,curved",
                 "--source-model", "point,beam", "--distances", "0.1,1", "--csv", str(tmp_path / "p.csv"),
                 "--quiet"]) == 0
    assert "curved+beam" in (tmp_path / "p.csv").read_text()


@pytest.mark.parametrize("material", [Material(1.0, 0.01, 1.3, 0.0), Material(1.0, 0.1, 1.3, 0.0),
                                      Material(1.0, 0.1, 1.0, 0.8)], ids=["a0.99", "a0.91", "a0.91-eta1-g0.8"])
def test_oblique_incidence_totals_against_monte_carlo(material):
    """eq. (81) at 70 degrees incidence against the exact half-space Monte Carlo entering at that angle (600k
    photons, seed 41, total stderr ~0.1 %). Measured: +3.2 %, +5.8 %, -8.4 % (the normal-incidence model: -4.3 %,
    -10 %, -32 %): the depth projection gets much of the change, not all of it, and overshoots at g = 0."""
    a, eta, g = float(material.albedo_prime[0]), material.eta, material.g
    mc = shape_mc_profile(material, np.array([1.0]), photons=600_000, seed=41, incidence_deg=70.0)
    cos_t = math.sqrt(1.0 - (math.sin(math.radians(70.0)) / eta) ** 2)
    oblique = near_field_total(albedo_prime=a, eta=eta, g=g, cos_t=cos_t) / mc.total[0] - 1.0
    normal = near_field_total(albedo_prime=a, eta=eta, g=g) / mc.total[0] - 1.0
    assert abs(oblique) < abs(normal) - 0.005 and abs(oblique) < 0.09, (oblique, normal)


#: media of the incidence-gain check, by test id
GAIN_MEDIA = {"skin1": Material.preset("skin1"), "a0.99-eta1-g0.8": Material(1.0, 0.01, 1.0, 0.8),
              "a0.77-eta1.5": Material(1.0, 0.3, 1.5, 0.0)}
_NORMAL_RUNS = {}


def _normal_incidence_run(name):
    """The normal-incidence half-space run of GAIN_MEDIA[name] (300k photons, seed 91), made once for both angles
    (deterministic for its seed: the same numbers as running it in each test)."""
    if name not in _NORMAL_RUNS:
        _NORMAL_RUNS[name] = shape_mc_profile(GAIN_MEDIA[name], np.array([1.0]), photons=300_000, seed=91)
    return _NORMAL_RUNS[name]


@pytest.mark.parametrize("name", sorted(GAIN_MEDIA))
@pytest.mark.parametrize("angle", [70.0, 80.0])
def test_incidence_gain_against_a_fresh_monte_carlo(name, angle):
    """eq. (86): the near-field total times its incidence gain against the exact half-space Monte Carlo entering
    at 70 and 80 degrees, with seeds the table never used, for media and angles between its nodes (skin1's three
    channels; alpha' 0.99 with eta = 1 and g = 0.8; alpha' 0.77 at eta = 1.5). Eq. (81) alone was off by up to
    +8 % (skin1 blue at 80 degrees) and -8.4 % (g = 0.8 at 70); held to 1.5 % plus four standard errors."""
    material = GAIN_MEDIA[name]
    mc0 = _normal_incidence_run(name)
    mc = shape_mc_profile(material, np.array([1.0]), photons=300_000, seed=92, incidence_deg=angle)
    for c in range(1 if material.is_grey else 3):
        a, eta, g = float(material.albedo_prime[c]), material.eta, material.g
        cos_t = math.sqrt(1.0 - (math.sin(math.radians(angle)) / eta) ** 2)
        gain = mc.total[c] / mc0.total[c]
        err = gain * math.hypot(mc.total_stderr[c] / mc.total[c], mc0.total_stderr[c] / mc0.total[c])
        model = incidence_gain(albedo_prime=a, eta=eta, g=g, cos_t=cos_t)
        assert abs(model / gain - 1.0) < 0.015 + 4.0 * err / gain, (c, model, gain, err)


@pytest.mark.parametrize("shape", ["plane", "sphere"])
def test_the_near_field_table_tool_runs(shape, capsys):
    """tools/studies/near_field_table.py (the validation tables of docs/validation.md "Near the light") on both
    shapes, with few photons: one summary line per model (its half-space path once lost a helper and failed with a
    NameError)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "tools" / "studies" / "near_field_table.py"
    spec = importlib.util.spec_from_file_location("near_field_table_tool", path)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    assert tool.main(["--photons", "4000", "--media", "skin1", "--shape", shape, "--radius", "20"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines() if x.startswith("{")]
    models = tool.SPHERE_MODELS if shape == "sphere" else tool.MODELS
    assert sorted(r["summary"] for r in lines if "summary" in r) == sorted(models)


@pytest.mark.parametrize("eta", [1.0, 1.3, 1.5])
@pytest.mark.parametrize("g", [0.0, 0.5])
def test_low_albedo_totals_against_adding_doubling(eta, g):
    """Below alpha' = 0.5 (the table's nodes down to 0.018, issue 47: ketchup) the model's total diffuse reflectance
    against adding-doubling's (iadpython, an independent solver: a slab 400 optical depths thick, index-matched
    below), at albedos between the nodes: within 3 % (measured at most 2.0 %; with alpha' = 0.5's sources, as before
    the nodes, 10-20 times too much)."""
    import iadpython as iad

    for a in (0.03, 0.067, 0.15, 0.3, 0.45):
        ss, sa = a / (1.0 - g), 1.0 - a
        sample = iad.Sample(a=ss / (ss + sa), b=(ss + sa) * 400.0, g=g, n=eta, n_above=1.0, n_below=eta,
                            quad_pts=32)
        r_spec = ((eta - 1.0) / (eta + 1.0)) ** 2
        diffuse = (float(sample.rt()[0]) - r_spec) / (1.0 - r_spec)   # per unit entering power
        model = float(near_field_total(albedo_prime=a, eta=eta, g=g))
        assert abs(model / diffuse - 1.0) < 0.03, (a, model, diffuse)


def test_the_model_checks_its_medium_and_makes_single_scattering_once():
    """The near-field model's single scattering is a record made with the model (issue 48: per-channel constants
    computed once): its profile, rings, total and incidence gain neither re-check the medium nor recompute the
    real coefficients (before, every call of each did both). The medium's model and near_field_model's agree."""
    medium = Material([1.2, 0.9, 0.6], [0.03, 0.08, 0.2], 1.4, g=0.8).medium
    model = medium.near_field(2)
    r = np.linspace(0.01, 5.0, 64)
    pr = cProfile.Profile()
    pr.enable()
    model.profile(r), model.ring(r, r + 0.1), model.total(), model.total(0.7), model.incidence_gain(0.8)
    pr.disable()
    called = {name for (_f, _l, name) in pstats.Stats(pr).stats}
    assert not called & {"check_material", "real_coefficients", "_angles", "_angular_factor"}, called
    other = near_field_model(float(medium.albedo_prime[2]), 1.4, 0.8)
    np.testing.assert_allclose(model.profile(r), other.profile(r), rtol=1e-14)
    # the real coefficients in optical units: sigma_s = sigma_s' / (1 - g) = 3 /mm, sigma_a = 0.2 /mm, over
    # sigma_t' = 0.8 /mm
    assert model.single.sigma_t == pytest.approx((0.6 / 0.2 + 0.2) / 0.8, rel=1e-14)
