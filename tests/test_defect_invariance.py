"""Defect invariance of the default bake (issue 41): a scanned hand (../shared/meshes/hand.obj, 190 mm long, skin1,
a sun travelling from the wrist towards the fingers) made imperfect by tools/benchmarks/mesh_defects.py, exactly
as tools/benchmarks/bench_defects.py makes it, must keep the volume model and the clean bake's exitance away from
the defects: mean |M_defect / M_clean - 1| <= 2 % and p99 <= 6 % per channel on the vertices farther than
EXCLUDE_MM from every defect (whose clean exitance is above 1e-3 of the channel's peak).

Slow (a bake each, about 10 s). Failed on the code of 2ded9bb, whose volume transport needed a closed mesh (13.6-15.6 %
mean with the surface transport); the lattice volume holds every case (docs/benchmarks.md: within 25 mm of six
holes the red light's p99 is still 8.6 % at 15 mm). Flipped faces are repaired into the clean mesh and stray
vertices are used by no face: those two bakes are identical.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.transport import bake

import bench_defects  # tools/benchmarks/, on sys.path by tests/conftest.py
import mesh_defects  # tools/benchmarks/, on sys.path by tests/conftest.py

#: the issue's "more than 10-25 mm from the defect": the lenient end (holes move red light 10-15 mm away: p99 8.6 %
#: at 15 mm on this hand, docs/benchmarks.md)
EXCLUDE_MM = 25.0
TARGET_MEAN, TARGET_P99 = 0.02, 0.06




bench = bench_defects
md = mesh_defects

pytestmark = pytest.mark.slow


def _bake(V, F, sun):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = Mesh.from_arrays(V, F)
        return bake(mesh, Material.preset("skin1"), [DirectionalLight(sun, 1.0)])


@pytest.fixture(scope="module")
def hand(shared_meshes):
    V, F, sun = bench.scene_arrays("hand190")
    clean = _bake(V, F, sun)
    assert clean.model == "volume" and clean.stats["transport"] == "volume"
    return V, F, sun, np.asarray(clean.radiance)


@pytest.mark.parametrize("defect", ["holes6", "dup5", "ball6", "fin", "stray10", "flip10"])
def test_default_bake_of_a_defective_scan_matches_the_clean_one_away_from_the_defects(hand, defect):
    V, F, sun, clean = hand
    d = bench.defective(defect, V, F, sun)
    res = _bake(d.vertices, d.faces, sun)
    assert res.model == "volume" and res.stats["transport"] == "volume", res.stats["transport"]
    n = V.shape[0]
    referenced = np.zeros(d.vertices.shape[0], dtype=bool)
    referenced[d.faces.reshape(-1)] = True
    keep = md.far_from(V, d.points, EXCLUDE_MM) & referenced[:n]
    got = md.relative_change(np.asarray(res.radiance)[:n], clean, keep)
    assert got["finite"] and min(got["count"]) >= 1000            # not a vacuous comparison
    assert max(got["mean"]) <= TARGET_MEAN, got
    assert max(got["p99"]) <= TARGET_P99, got
