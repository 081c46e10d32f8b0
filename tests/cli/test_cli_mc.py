"""`meshshade mc`: time budget end to end (bounded wall time, exact balance in the summary), pool independence,
bad input exits 2."""
from __future__ import annotations

import json

import numpy as np
import pytest

from meshshade.cli.main import main
from meshshade.geometry.procedural import icosphere
from meshshade.io import write_ply

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")
KEYS = ("specular_reflectance", "diffuse_reflectance", "transmittance", "absorbed")


def _mesh(tmp_path):
    V, F = icosphere(4.0, 2)
    src = tmp_path / "s.ply"
    write_ply(src, V, F)
    return src


def _mc(src, out, *extra):
    return main(["mc", str(src), "--sigma-s-prime", "2", "--sigma-a", "0.01", "--light", "directional:0,0,-1",
                 "--out", str(out / "o.ply"), "--summary", str(out / "o.json"), "-q", *extra])


def test_cli_mc_time_budget_bounded(tmp_path, mc_work_clock):
    """--time-budget reaches the engine: the summary's seconds, on the walk's own clock (tests/conftest.py; wall
    time flakes under load), stay within budget (1 + HARD_OVERSHOOT = 0.25) plus one round."""
    src = _mesh(tmp_path)
    assert _mc(src, tmp_path, "--photons", "500") == 0          # compile / load the kernels
    clock = mc_work_clock()
    budget = 0.5
    assert _mc(src, tmp_path, "--time-budget", str(budget)) == 0
    s = json.loads((tmp_path / "o.json").read_text())
    assert s["photons"] > 100 and s["seconds"] == pytest.approx(clock.t, rel=1e-12)
    assert s["seconds"] <= 1.25 * budget + clock.longest_round, (s["seconds"], clock.longest_round)
    assert sum(s[k] for k in KEYS) + s["lost"] == pytest.approx(1.0, abs=1e-12)


def test_cli_mc_pool_does_not_change_the_result(tmp_path):
    src = _mesh(tmp_path)
    res = []
    for pool in ("4096", "300"):
        assert _mc(src, tmp_path, "--photons", "3000", "--seed", "5", "--pool", pool) == 0
        res.append(json.loads((tmp_path / "o.json").read_text()))
    assert res[0]["events"] == res[1]["events"]
    for k in KEYS:
        np.testing.assert_allclose(res[0][k], res[1][k], rtol=1e-10)


@pytest.mark.parametrize("extra", [["--pool", "0"], ["--seed", "-1"], ["--time-budget", "0"]])
def test_cli_mc_bad_numbers_exit_2(tmp_path, capsys, extra):
    assert _mc(_mesh(tmp_path), tmp_path, "--photons", "100", *extra) == 2
    assert "error" in capsys.readouterr().err
