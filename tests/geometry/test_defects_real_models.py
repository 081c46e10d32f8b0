"""The list of real models of issue 41 (tools/benchmarks/real_models.toml) and the counts its benchmark reports
(tools/benchmarks/real_models.py: topology_counts): the list is complete and consistent without the files;
with the files (shared/models/ or ../shared/models/, never committed; skipped otherwise), each is the recorded
file at the recorded size."""
from __future__ import annotations

import re

import numpy as np
import pytest

import real_models  # tools/benchmarks/, on sys.path by tests/conftest.py





rm = real_models
ENTRIES = rm.entries()


def test_real_models_list_is_complete_and_consistent():
    assert len(ENTRIES) >= 8
    names = [e["name"] for e in ENTRIES]
    files = [e["file"] for e in ENTRIES]
    assert len(set(names)) == len(names) and len(set(files)) == len(files)
    for e in ENTRIES:
        missing = [k for k in rm.REQUIRED if k not in e]
        assert not missing, f"{e.get('name')}: missing {missing}"
        assert re.fullmatch(r"[0-9a-f]{64}", e["sha256"]), e["name"]
        assert re.fullmatch(r"[0-9a-f]{40}", e["commit"]) and re.fullmatch(r"[0-9a-f]{40}", e["file_commit"])
        assert re.fullmatch(r"[A-Za-z0-9_.-]+/[A-Za-z0-9_.-]+", e["repository"]), e["name"]
        assert 70 <= round(e["size_mm"]) <= 840 and e["mm_per_unit"] > 0, e["name"]   # the sizes, in mm
        assert e["licence"].strip(), e["name"]
        assert rm.url(e).startswith(f"https://github.com/{e['repository']}/blob/{e['commit']}/")


def test_topology_counts_by_hand():
    # a tetrahedron, one of its faces duplicated (reversed), a separate triangle, a vertex no face uses,
    # and a degenerate face (repeated corner)
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5], [6, 5, 5], [5, 6, 5], [9, 9, 9]])
    tet = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]
    F = np.array(tet + [[1, 0, 2], [4, 5, 6], [4, 4, 5]])
    got = rm.topology_counts(V, F)
    assert got["vertices"] == 8 and got["faces"] == 7
    assert got["parts"] == 2
    assert got["boundary_edges"] == 3                   # the lone triangle's edges
    assert got["nonmanifold_edges"] == 3                # the duplicated face's edges are used three times
    assert got["duplicated_faces"] == 1
    assert got["degenerate_faces"] == 1
    assert got["unreferenced_vertices"] == 1
    assert got["size"] == pytest.approx(6.0)
    closed = rm.topology_counts(V[:4], np.array(tet))
    assert closed["parts"] == 1 and closed["boundary_edges"] == 0 and closed["nonmanifold_edges"] == 0


def test_topology_counts_bow_tie():
    # two triangles that share one vertex only
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    got = rm.topology_counts(V, np.array([[0, 1, 2], [0, 3, 4]]))
    assert got["nonmanifold_vertices"] == 1 and got["parts"] == 1 and got["boundary_edges"] == 6


@pytest.fixture(scope="module")
def models_dir():
    folder = rm.models_dir()
    if folder is None:
        pytest.skip(rm.missing_reason())
    return folder


@pytest.mark.parametrize("entry", ENTRIES, ids=[e["name"] for e in ENTRIES])
def test_real_model_file_is_the_one_recorded(models_dir, entry):
    path = rm.model_path(entry, models_dir)
    if path is None:
        pytest.skip(f"{entry['file']} not in {models_dir}")
    assert rm.sha256(path) == entry["sha256"]


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES, ids=[e["name"] for e in ENTRIES])
def test_real_model_loads_at_its_recorded_size(models_dir, entry):
    if rm.model_path(entry, models_dir) is None:
        pytest.skip(f"{entry['file']} not in {models_dir}")
    V, F = rm.load_arrays(entry, models_dir)
    got = rm.topology_counts(V, F)
    assert got["size"] == pytest.approx(entry["size_mm"], abs=0.06)
    assert got["vertices"] <= 62_194                        # up to the 62k
