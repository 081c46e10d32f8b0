"""Monte Carlo split across Dask workers (meshshade.montecarlo.distributed), on a real LocalCluster.

The merged run must equal the single-process run (the same photon paths: counts exactly, tallies to the order of
the sums) and be bitwise the same for any number of workers.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from meshshade.batch import dask_cluster, open_client
from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.io import read_baked_ply, write_ply
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.montecarlo import MCOptions, beam_radial_power, distributed, simulate
from meshshade.montecarlo.engine import ENTRY_CHUNK
from meshshade.montecarlo.walks import prepare_walks, walk_group

MESH = Mesh(*icosphere(10.0, 2))
SKIN = Material.preset("skin1")                                   # three channel groups
GREY = Material([1.0, 1.0, 1.0], [0.01, 0.01, 0.01], eta=1.3)    # one
SUN = [DirectionalLight((0.3, -0.4, -1.0), 1.0)]
BEAM = [BeamLight((0.0, 0.0, 30.0), (0.0, 0.0, -1.0), 1.0)]
PHOTONS = 3 * ENTRY_CHUNK + 1234                                  # four chunks, the last one partial


@pytest.fixture(scope="module")
def one_worker():
    with open_client(workers=1, quiet=True) as client:
        yield client


@given(st.integers(1, 10**12))
def test_split_partitions_the_chunks_independently_of_workers(n):
    ranges = distributed.split_chunks(n)
    n_chunks = -(-n // ENTRY_CHUNK)
    assert ranges[0][0] == 0 and ranges[-1][1] == n_chunks
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:])) and all(c0 < c1 for c0, c1 in ranges)
    assert len(ranges) <= distributed.TASKS_PER_GROUP
    assert sum(distributed._photons_in(r, n) for r in ranges) == n


def test_chunk_ranges_of_one_run_add_up_to_the_whole_run():
    """The engine's chunk ranges (no Dask): the photon paths of a partition are the whole run's."""
    setup = prepare_walks(MESH, GREY, SUN)
    kw = dict(seed=5, n_batches=8, pool=None, keep_beam=False)
    whole = walk_group(setup, 0, PHOTONS, **kw)
    parts = [walk_group(setup, 0, PHOTONS, chunks=c, **kw) for c in ((0, 1), (1, 3), (3, 4))]
    total = parts[0] + parts[1] + parts[2]
    assert total.emitted == whole.emitted == PHOTONS and total.events == whole.events
    assert total.boundary == whole.boundary
    np.testing.assert_allclose(total.face, whole.face, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(total.tot, whole.tot, rtol=1e-12, atol=1e-18)
    off = walk_group(setup, 0, PHOTONS, chunks=(1, 3), **{**kw, "seed": 6})
    assert not np.allclose(off.face, parts[1].face)                # the seed still matters


@pytest.mark.parametrize("material", [SKIN, GREY], ids=["skin1", "grey"])
def test_two_workers_equal_one_worker_bitwise_and_one_process_to_rounding(material, dask_client, one_worker):
    local = simulate(MESH, material, SUN, MCOptions(photons=PHOTONS, seed=11))
    two = simulate(MESH, material, SUN, MCOptions(photons=PHOTONS, seed=11), client=dask_client)
    one = simulate(MESH, material, SUN, MCOptions(photons=PHOTONS, seed=11), client=one_worker)
    for a in ("face_power", "face_power_stderr", "vertex_power", "radiance", "radiance_stderr", "lost"):
        assert np.array_equal(getattr(one, a), getattr(two, a)), a
    for k in one.totals:
        assert np.array_equal(one.totals[k], two.totals[k]), k
    assert (two.photons, two.events, two.boundary_events) == (local.photons, local.events, local.boundary_events)
    np.testing.assert_allclose(two.face_power, local.face_power, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(two.radiance_stderr, local.radiance_stderr, rtol=1e-9, atol=1e-20)
    for k in local.totals:
        np.testing.assert_allclose(two.totals[k], local.totals[k], rtol=1e-12, atol=1e-15)


def test_beam_exits_give_the_same_radial_profile(dask_client):
    local = simulate(MESH, GREY, BEAM, MCOptions(photons=PHOTONS, seed=2))
    split = simulate(MESH, GREY, BEAM, MCOptions(photons=PHOTONS, seed=2), client=dask_client)
    edges = np.linspace(0.0, 10.0, 21)
    (pa, sa), (pb, sb) = beam_radial_power(local, MESH, edges), beam_radial_power(split, MESH, edges)
    assert pa[0].sum() > 0
    np.testing.assert_allclose(pb, pa, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(sb, sa, rtol=1e-9, atol=1e-18)
    assert split.beam_entry[0] == local.beam_entry[0]


def test_each_worker_builds_the_walk_set_up_once(dask_client):
    dask_client.run(lambda: distributed._SETUPS.clear())
    for seed in (1, 2):
        simulate(MESH, GREY, SUN, MCOptions(photons=PHOTONS, seed=seed), client=dask_client)
    sizes = dask_client.run(lambda: len(distributed._SETUPS))
    assert set(sizes.values()) <= {1}        # one set-up per worker for both runs (a worker may have had no task)


def test_what_cannot_be_split_is_refused(dask_client):
    with pytest.raises(MeshshadeError, match="time budget"):
        simulate(MESH, GREY, SUN, MCOptions(photons=None, time_budget=1.0), client=dask_client)
    with pytest.raises(MeshshadeError, match="fast_interior"):
        simulate(MESH, GREY, SUN, MCOptions(photons=1000, fast_interior=False), client=dask_client)


def test_mc_command_with_workers_writes_what_mc_writes(tmp_path, capsys, monkeypatch):
    from meshshade.cli.main import main

    write_ply(tmp_path / "ball.ply", MESH.vertices, MESH.faces)
    base = ["mc", tmp_path / "ball.ply", "--material", "skin1", "--light", "directional:0,0,-1", "--photons",
            str(PHOTONS), "--seed", "4", "--quiet"]
    assert main([str(a) for a in [*base, "--out", tmp_path / "a.ply"]]) == 0
    assert main([str(a) for a in [*base, "--out", tmp_path / "b.ply", "--workers", "2"]]) == 0
    a, b = (read_baked_ply(tmp_path / f)[1] for f in ("a.ply", "b.ply"))
    np.testing.assert_allclose(b, a, rtol=1e-6)                    # float32 in the file
    capsys.readouterr()
    for extra, needle in ((["--time-budget", "2", "--workers", "2"], "cannot be split"),
                          (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not allowed with"),
                          (["--workers", "0"], "--workers"),
                          (["--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler")):
        monkeypatch.setattr(dask_cluster, "CONNECT_TIMEOUT", 1)
        rc = main([str(a) for a in [*base, "--out", tmp_path / "c.ply", *extra]])
        err = capsys.readouterr().err
        assert rc == 2 and "Traceback" not in err, err
        assert err.strip().splitlines()[-1].startswith("meshshade: error:") and needle in err, err
        assert not (tmp_path / "c.ply").exists()
