"""The volume bake reports its stages as progress (issue 40): with stderr not a terminal and the line interval at
0, one line per stage, each naming the stage that runs next, ending at 100 %; nothing with progress off. The
asset cache of the tetrahedral volume is gone: its argument warns."""
from __future__ import annotations

import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.progress import INTERVAL_ENV
from meshshade.transport.baking import VOLUME_STAGES, bake
from meshshade.transport import BakeOptions


def test_each_stage_is_reported(monkeypatch, capsys):
    monkeypatch.setenv(INTERVAL_ENV, "0")
    mesh = Mesh.from_arrays(*icosphere(8.0, 3))
    sun = [DirectionalLight((0.0, 0.0, -1.0), 1.0)]
    res = bake(mesh, Material.preset("skin1"), sun, BakeOptions(progress=True))
    lines = [x for x in capsys.readouterr().err.splitlines() if x.startswith("meshshade: bake:")]
    assert set(res.timings) == set(VOLUME_STAGES)                  # every stage ran and was timed
    named = [x.rsplit("[", 1)[1].rstrip("]") for x in lines]
    assert named == list(VOLUME_STAGES)[1:] + ["uncollided"]        # the next stage, then the last again
    assert "100 %" in lines[-1]
    bake(mesh, Material.preset("skin1"), sun, reuse=res.volume)
    assert capsys.readouterr().err == ""


def test_the_volume_cache_argument_is_deprecated():
    mesh = Mesh.from_arrays(*icosphere(8.0, 2))
    with pytest.warns(DeprecationWarning, match="volume_cache"):
        bake(mesh, Material.preset("skin1"), [DirectionalLight((0.0, 0.0, -1.0), 1.0)], volume_cache=object())
