"""topology.vertex_adjacency against independent routes (a Python set per vertex, scipy's sparse graph)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from meshshade.geometry import procedural
from meshshade.geometry.topology import vertex_adjacency


def _adjacency_by_sets(n, faces):
    """Reference: loop over the faces, collect each vertex's distinct co-corners in a set."""
    nbrs = [set() for _ in range(n)]
    for face in np.asarray(faces).tolist():
        for a in face:
            for b in face:
                if a != b:
                    nbrs[a].add(b)
    return [sorted(s) for s in nbrs]


def _rows(indptr, indices):
    return [indices[indptr[v]:indptr[v + 1]].tolist() for v in range(indptr.size - 1)]


def test_vertex_adjacency_tiny_mesh_by_hand():
    # two triangles sharing edge 1-2, a vertex (4) used by no face, a face with a repeated index (edge 0-3 only)
    F = np.array([[0, 1, 2], [2, 1, 3], [0, 0, 3]])
    indptr, indices = vertex_adjacency(5, F)
    assert indptr.dtype == np.int64 and indices.dtype == np.int64
    assert _rows(indptr, indices) == [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2], []]


@pytest.mark.parametrize("mesh", ["icosphere", "torus", "random"])
def test_vertex_adjacency_matches_sets_and_scipy(mesh):
    if mesh == "icosphere":
        V, F = procedural.icosphere(10.0, 2)
    elif mesh == "torus":
        V, F = procedural.torus(20.0, 5.0, 24, 10)
    else:  # random faces: repeated indices, duplicate faces, unreferenced vertices
        rng = np.random.default_rng(3)
        V, F = np.zeros((40, 3)), rng.integers(0, 35, (120, 3))
    n = V.shape[0]
    indptr, indices = vertex_adjacency(n, F)
    assert _rows(indptr, indices) == _adjacency_by_sets(n, F)
    # scipy: symmetric boolean graph of the face edges without the diagonal; canonical CSR rows are sorted
    rows = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    cols = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    g = sparse.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    g = ((g + g.T) != 0).astype(np.int8).tolil()
    g.setdiag(0)
    g = g.tocsr()
    g.eliminate_zeros()
    g.sort_indices()
    np.testing.assert_array_equal(indptr, g.indptr)
    np.testing.assert_array_equal(indices, g.indices)


def test_vertex_adjacency_no_faces():
    indptr, indices = vertex_adjacency(3, np.zeros((0, 3), np.int64))
    np.testing.assert_array_equal(indptr, np.zeros(4, np.int64))
    assert indices.size == 0
