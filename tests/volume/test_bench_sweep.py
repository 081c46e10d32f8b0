"""The accuracy sweep's code (tools/benchmarks/bench_sweep.py, issue 47): its errors, ratios, power and summary
against figures worked out by hand, and the whole path of its Monte Carlo runs on a tiny scene (a sphere of 162
vertices, a few thousand photons): the device's mode writes the runs, the import puts them into a temporary asset
cache, the sweep finds them there and its row holds together; with trimesh and libigl blocked for the device's mode.

Expected values: exitances chosen so that every relative error is a round number (the reference 1 everywhere), and
the areas 1..6 so that the total power is a weighted mean worked out by hand below.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bench_sweep as bs
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.materials import Material

ROOT = Path(__file__).resolve().parents[2]
LIT = np.array([True, True, True, False, False, False])
AREAS = np.arange(1.0, 7.0)                       # sum 21
REF = np.ones((6, 3))
MC = np.repeat(np.array([1.05, 0.95, 1.05, 1.08, 0.92, 1.08])[:, None], 3, axis=1)      # lit 5 %, unlit 8 %
BAKE_A = np.repeat(np.array([1.02, 0.98, 1.02, 1.10, 0.90, 1.10])[:, None], 3, axis=1)  # lit 2 %, unlit 10 %
BAKE_B = np.repeat(np.array([1.01, 0.99, 1.01, 1.02, 0.98, 1.02])[:, None], 3, axis=1)  # lit 1 %, unlit 2 %


def _row(scene, bake):
    m = bs.pair_metrics(bake, MC, REF, LIT, AREAS)
    return {"row": "pair", "scene": scene, "material": "skin1", "bake": {"seconds": 1.5, **m["bake"]},
            "mc": {"photons": 2000, **m["mc"]}, "reference": {"photons": 4000}, "ratio": m["ratio"],
            "targets": m["targets"], "meets_targets": m["meets_targets"]}


def test_pair_metrics_errors_ratios_power_and_targets_by_hand():
    a = bs.pair_metrics(BAKE_A, MC, REF, LIT, AREAS)
    assert a["bake"]["lit"] == pytest.approx([0.02] * 3) and a["bake"]["unlit"] == pytest.approx([0.10] * 3)
    assert a["mc"]["lit"] == pytest.approx([0.05] * 3) and a["mc"]["unlit"] == pytest.approx([0.08] * 3)
    assert a["ratio"]["lit"] == pytest.approx([0.4] * 3) and a["ratio"]["unlit"] == pytest.approx([1.25] * 3)
    # power: sum(a_v f_v) / sum(a_v) - 1 = (1.02 + 1.96 + 3.06 + 4.4 + 4.5 + 6.6) / 21 - 1 = 0.54 / 21
    assert a["bake"]["power"] == pytest.approx([0.54 / 21] * 3, abs=1e-4)
    assert a["mc"]["power"] == pytest.approx([0.5 / 21] * 3, abs=1e-4)  # (1.05 + 1.9 + 3.15 + 4.32 + 4.6 + 6.48) / 21
    assert a["targets"] == {"lit<=0.8": True, "unlit<=1.2": False, "power<=1%": False}
    assert a["meets_targets"] is False
    b = bs.pair_metrics(BAKE_B, MC, REF, LIT, AREAS)
    assert b["ratio"]["lit"] == pytest.approx([0.2] * 3) and b["ratio"]["unlit"] == pytest.approx([0.25] * 3)
    assert b["bake"]["power"] == pytest.approx([0.12 / 21] * 3, abs=1e-4)  # 21.12 / 21 - 1: within 1 %
    assert b["meets_targets"] is True


def test_summary_pools_pairs_and_channels_by_hand():
    s = bs.summary([_row("spot50", BAKE_A), _row("head200", BAKE_B), {"row": "pair", "skipped": "mesh not found"}])
    assert s["pairs"] == 2
    assert s["means"]["bake_lit"] == pytest.approx([0.015] * 3)
    assert s["means"]["bake_unlit"] == pytest.approx([0.06] * 3)
    assert s["means"]["mc_unlit"] == pytest.approx([0.08] * 3)
    assert s["lit_ratio_of_means"] == pytest.approx(0.3)          # 0.015 / 0.05 (the unlit ones: 0.06 / 0.08)
    assert s["mean_of_pair_lit_ratios"] == pytest.approx(0.3)     # (0.4 + 0.2) / 2
    assert s["lit_sweep<=0.6"] is True
    assert s["pairs_meeting_targets"] == ["head200:skin1"]
    assert s["pairs_missing_targets"] == {"spot50:skin1": ["unlit<=1.2", "power<=1%"]}
    assert s["bake_seconds"] == {"total": 3.0, "mean": 1.5, "max": 1.5}


def test_mc_code_version_follows_the_walk_not_the_bake(tmp_path):
    """The key changes with a file the Monte Carlo imports, not with one of the bake's alone."""
    import shutil

    pkg = tmp_path / "meshshade"
    shutil.copytree(ROOT / "meshshade", pkg, ignore=shutil.ignore_patterns("__pycache__"))
    v0 = bs.mc_code_version(pkg)
    (pkg / "volume" / "transport.py").write_text((pkg / "volume" / "transport.py").read_text() + "\n# bake\n")
    assert bs.mc_code_version(pkg) == v0
    (pkg / "montecarlo" / "sampling.py").write_text((pkg / "montecarlo" / "sampling.py").read_text() + "\n# mc\n")
    v1 = bs.mc_code_version(pkg)
    assert v1 != v0
    (pkg / "light" / "sources.py").write_text((pkg / "light" / "sources.py").read_text() + "\n# light\n")
    assert bs.mc_code_version(pkg) != v1


def _tiny_scene(folder: Path) -> None:
    """A sphere of radius 5 mm, 162 vertices, exported under a sweep scene's name (the device reads names only)."""
    V, F = icosphere(5.0, 2)
    bs.export_scene(bs.Scene("spot50", V, F, (DirectionalLight((0.3, -0.4, -0.866), 1.0),)), folder)


@pytest.mark.slow  # 5-13 s: two small Monte Carlo runs and a bake
def test_device_runs_import_and_sweep_row_on_a_tiny_scene(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("MESHSHADE_ASSET_CACHE", str(tmp_path / "cache"))
    scenes, runs = tmp_path / "scenes", tmp_path / "runs"
    _tiny_scene(scenes)
    small = ["--pairs", "spot50:skin1", "--reference-photons", "4000", "--photons", "2000", "-q"]
    assert bs.main(["--references-only", "--scenes-from", str(scenes), "--out", str(runs), *small]) == 0
    assert sorted(p.name for p in runs.iterdir()) == ["spot50_skin1_2000_202.npz", "spot50_skin1_4000_101.npz"]
    assert bs.main(["--import-references", str(runs)]) == 0
    out = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [r["written"] for r in out if r["row"] == "import"] == [True, True]
    scene = bs.load_scene(scenes, "spot50")
    mesh, mat = scene.mesh(), Material.preset("skin1")
    got, where = bs.cached_run("spot50", mesh, mat, scene.lights, 4000, 101, compute=False)
    assert where == "cache"
    with np.load(runs / "spot50_skin1_4000_101.npz") as d:
        assert np.array_equal(got["radiance"], d["radiance"])
    # another seed, another key: not found without computing
    assert bs.cached_run("spot50", mesh, mat, scene.lights, 4000, 102, compute=False)[0] is None

    ns = type("A", (), {"reference_photons": 4000, "reference_seed": 101, "photons": 2000, "seed": 202,
                        "allow_other_mc_version": False, "cached_only": True, "quiet": True})()
    row = bs.pair_row(scene, "skin1", ns)
    assert row["reference"]["from"] == "cache" and row["mc"]["from"] == "cache"
    assert 0 < row["lit_vertices"] < mesh.n_vertices
    for side in ("bake", "mc"):
        assert all(0.0 <= x < 1.0 for x in row[side]["lit"]), row[side]
        assert all(abs(p) < 0.2 for p in row[side]["power"]), row[side]
    assert row["bake"]["model"] == "volume"
    s = bs.summary([row])
    assert s["pairs"] == 1 and s["reference_photons"] == [4000] and s["mc_photons"] == [2000]


@pytest.mark.slow  # 5-11 s: a fresh process
def test_device_mode_needs_neither_trimesh_nor_libigl(tmp_path):
    scenes, runs = tmp_path / "scenes", tmp_path / "runs"
    _tiny_scene(scenes)
    code = ("import sys, runpy; sys.modules['trimesh'] = None; sys.modules['igl'] = None; "
            f"sys.argv = ['bench_sweep.py', '--references-only', '--scenes-from', {str(scenes)!r}, '--out', "
            f"{str(runs)!r}, '--pairs', 'spot50:ketchup', '--reference-photons', '2000', '--photons', '1000']; "
            f"runpy.run_path({str(ROOT / 'tools' / 'benchmarks' / 'bench_sweep.py')!r}, run_name='__main__')")
    env = {**os.environ, "MESHSHADE_ASSET_CACHE": "off"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert sorted(p.name for p in runs.iterdir()) == ["spot50_ketchup_1000_202.npz", "spot50_ketchup_2000_101.npz"]


def test_bad_input_is_one_line_and_exit_2(capsys, monkeypatch):
    monkeypatch.setenv("MESHSHADE_ASSET_CACHE", "off")   # with --cached-only: a check let through runs nothing
    for argv, says in ((["--pairs", "spot50:jelly"], "unknown material 'jelly'"),
                       (["--scenes", "moon"], "unknown scene 'moon'"),
                       (["--seed", "101"], "the reference's"),
                       (["--references-only"], "needs --out")):
        with pytest.raises(SystemExit) as exc:
            bs.main([*argv, "--cached-only", "-q"])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert says in err and len(err.splitlines()) == 1
