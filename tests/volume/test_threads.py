"""The volume's compiled loops over independent items (the assembly's rows, the point walk, the near field's pairs)
are serial loops run on blocks of items by the pacing threads (:func:`meshshade.pacing.run_in_blocks`): their
results must not depend on the thread count or on where the blocks end, bit for bit, and the assembly's
degenerate-tetrahedron error must name the same tetrahedron whatever the blocks.

Each check runs once with one thread (``numba.set_num_threads(1)``: the default blocks, in the calling thread)
and twice with two worker threads in small blocks of two different sizes (the module's ``run_in_blocks``
replaced by one that fixes ``n_threads`` and ``block`` and counts the blocks), so a block that skips, repeats or
shifts an item, or a value carried from one item to the next within a block, shows as a difference.
"""
from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.materials import Material
from meshshade.pacing import run_in_blocks
from meshshade.volume import NearFieldCorrection, assemble_channels, boundary_faces, fem, locate, near_field
from meshshade.volume.locate import tet_neighbours, walk_locate
from meshshade.volume.tetmesh import box_tetrahedra, graded_axis

#: (block sizes of the two-thread runs): small and odd, so blocks end at many places
BLOCKS = (7, 61)


def _box():
    """The graded box of test_volume_fem (320 nodes)."""
    ax = graded_axis(-3.0, 3.0, 0.4, 0.5, 1.4)
    az = graded_axis(-2.0, 0.0, 0.0, 0.3, 1.4)
    return box_tetrahedra(ax, ax[::-1] * -1.0, az)


def _runs(monkeypatch, module, compute):
    """``compute()`` with one thread and default blocks, then with two threads in each of :data:`BLOCKS`; the three
    results and the number of blocks each two-thread run made."""
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = compute()
    finally:
        numba.set_num_threads(before)
    out, calls = [one], []
    for block in BLOCKS:
        count = []

        def counted(run, k, *, _block=block, _count=count, **kw):
            """run_in_blocks on two threads in blocks of ``_block``, each block noted in ``_count``."""
            kw.update(n_threads=2, block=_block)
            return run_in_blocks(lambda a, b: _count.append((a, b)) or run(a, b), k, **kw)

        with monkeypatch.context() as m:
            m.setattr(module, "run_in_blocks", counted)
            out.append(compute())
        calls.append(len(count))
    return out, calls


def _assert_same(results):
    """Every result's arrays equal the first's, bit for bit and of the same dtype."""
    first = results[0]
    for other in results[1:]:
        assert len(other) == len(first)
        for a, b in zip(first, other):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("lumped", [False, True])
def test_assembly_does_not_depend_on_threads_or_blocks(monkeypatch, lumped):
    """The pattern's two row passes and the element rows, against the same assembly in other blocks."""
    nodes, tets = _box()
    faces = boundary_faces(tets, nodes)
    results, calls = _runs(monkeypatch, fem, lambda: assemble_channels(nodes, tets, faces, D=[0.3, 0.5],
                                                                       sigma_a=[0.05, 0.01], A=[2.5, 1.5],
                                                                       lumped=lumped))
    assert nodes.shape[0] > 4 * BLOCKS[1]
    assert calls[0] >= 3 * math.ceil(nodes.shape[0] / BLOCKS[0])   # row counts, row columns, element rows
    _assert_same(results)


def test_pattern_rows_past_the_row_buffer(monkeypatch):
    """A node in 150 tetrahedra of its own (over 450 neighbours: the row buffer of 256 grows) among random ones: the
    pattern is each row's sorted distinct neighbours, itself included (numpy's reference), whatever the blocks."""
    rng = np.random.default_rng(13)
    nodes = rng.normal(size=(600, 3))
    fan = np.concatenate([np.zeros((150, 1), np.int64), 1 + np.arange(450).reshape(150, 3)], axis=1)
    tets = np.concatenate([fan, rng.permuted(np.tile(np.arange(600), (400, 1)), axis=1)[:, :4]])
    results, _ = _runs(monkeypatch, fem, lambda: assemble_channels(nodes, tets, np.zeros((0, 3), np.int64), D=[0.3],
                                                                   sigma_a=[0.05], A=[2.5])[:2])
    _assert_same(results)
    indptr, indices = results[0]
    i = np.repeat(tets, 4, axis=1).ravel()
    j = np.tile(tets, (1, 4)).ravel()
    ref = np.unique(np.concatenate([i * 600 + j, np.arange(600) * 601]))
    np.testing.assert_array_equal(indptr, np.searchsorted(ref // 600, np.arange(601)))
    np.testing.assert_array_equal(indices, ref % 600)
    assert indptr[1] - indptr[0] >= 451


def _degenerate_box():
    """The box with three zero-volume tetrahedra appended: T, on the highest nodes, T + 1, which holds node 0 (so
    it is met first in row order, though its index is higher), and T + 2 on nodes 3-5 (met later in the same
    blocks as T + 1)."""
    nodes, tets = _box()
    T, N = tets.shape[0], nodes.shape[0]
    extra = np.array([[N - 1, N - 2, N - 1, N - 3], [0, 1, 1, 2], [3, 4, 4, 5]], dtype=tets.dtype)
    return nodes, np.concatenate([tets, extra]), T


def test_degenerate_tetrahedron_named_whatever_the_blocks(monkeypatch):
    """The first degenerate tetrahedron in row order (the one holding node 0), with one thread and in blocks on
    two, not the last one met in its block nor the one in the last block; alone, the one on the highest nodes."""
    nodes, tets, T = _degenerate_box()
    faces = boundary_faces(_box()[1], nodes)

    def named(t):
        def compute():
            with pytest.raises(MeshshadeError, match=r"degenerate tetrahedron (\d+) ") as err:
                assemble_channels(nodes, t, faces, D=[0.3], sigma_a=[0.05], A=[2.5])
            return (np.array(int(err.value.args[0].split()[2])),)
        results, calls = _runs(monkeypatch, fem, compute)
        assert min(calls) > 2
        return [int(r[0]) for r in results]

    assert named(tets) == [T + 1] * 3
    assert named(tets[:T + 1]) == [T] * 3


def test_walk_does_not_depend_on_threads_or_blocks(monkeypatch):
    """Points inside and outside the box, walked from their nearest centroids: tetrahedra, barycentrics and
    status."""
    nodes, tets = _box()
    pts = np.random.default_rng(11).uniform([-3.5, -3.5, -2.5], [3.5, 3.5, 0.5], size=(2000, 3))
    start = cKDTree(nodes[tets].mean(axis=1)).query(pts, k=1)[1].astype(np.int64)
    nb = tet_neighbours(tets)

    def compute():
        tet, bary = np.full(len(pts), -7, dtype=np.int64), np.full((len(pts), 4), np.nan)
        status = walk_locate(nodes, tets, nb, pts, start, tet, bary)
        return status, tet, bary

    results, calls = _runs(monkeypatch, locate, compute)
    assert calls == [math.ceil(len(pts) / b) for b in BLOCKS]
    status = results[0][0]
    assert np.any(status == 1) and np.any(status == 0)
    _assert_same(results)


def test_near_field_pairs_do_not_depend_on_threads_or_blocks(monkeypatch):
    """The near-field correction on a sphere of 2.5k vertices from sources at a third of them, half of them point
    entries (the receiver's patch) and half patches, some facing away: the sum over pairs per receiver."""
    V, F = icosphere(6.0, 4)
    mesh = Mesh.from_arrays(V, F, source="x")
    corr = NearFieldCorrection(Material.preset("marble"))
    rng = np.random.default_rng(12)
    src = rng.choice(len(V), size=len(V) // 3, replace=False)
    normals = mesh.vertex_normals[src] * np.where(rng.random(src.size) < 0.1, -1.0, 1.0)[:, None]
    radius = np.where(rng.random(src.size) < 0.5, 0.0, np.sqrt(mesh.vertex_areas[src] / math.pi))
    args = (mesh.vertices[src], normals, rng.random(src.size), rng.uniform(0.5, 1.0, src.size), radius,
            mesh.vertices, mesh.vertex_normals, np.sqrt(mesh.vertex_areas / math.pi))

    def compute():
        dM, pairs = corr.exitance(*args)
        return dM, np.array(pairs)

    results, calls = _runs(monkeypatch, near_field, compute)
    pairs = int(results[0][1])
    assert pairs > 100 * BLOCKS[1] and calls == [math.ceil(pairs / b) for b in BLOCKS]
    assert np.count_nonzero(results[0][0]) > 0.9 * results[0][0].size
    _assert_same(results)

