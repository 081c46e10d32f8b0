"""Triangle-mesh topology: edges, components, winding repair and outward orientation (pure array functions).

Everything here works on ``V, F`` arrays and never reorders, merges or removes vertices: a repair only permutes
the corners of a face, as ``(a, b, c) -> (a, c, b)`` (the first corner is kept). ``mesh.validate_mesh`` is the
policy layer that calls these helpers, counts defects and words the warnings.

Conventions
-----------
* A *topological* face is a face with three distinct indices. Faces with a repeated index have no edges and are
  left out of every topological computation; faces whose corners are distinct but collinear (zero area) keep
  their edges, so that a sliver does not open a hole in an otherwise closed surface.
* A *patch* is a set of faces connected through manifold edges (edges with exactly two topological faces).
  Winding is made consistent per patch; a patch is *closed* when each of its edges is used by exactly two of its
  faces.
* Outward orientation follows the nesting rule of CGAL's ``orient_to_bound_a_volume``: a closed patch nested in
  an even number of other closed patches (usually zero) gets positive signed volume, one nested in an odd
  number (the wall of a cavity) gets negative signed volume, so every normal points out of the material.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from meshshade.geometry.sorting import counting_order, pair_table, sorted_unique

__all__ = ["EdgeTopology", "edge_topology", "vertex_adjacency", "vertex_components", "consistent_winding",
           "orient_outward", "winding_number", "signed_volumes"]


@dataclass(frozen=True, eq=False)
class EdgeTopology:
    """Undirected edges of the topological faces.

    Attributes
    ----------
    edges : (e, 2) int64, sorted pairs ``i < j``
    face_count : (e,) int64, number of topological faces using each edge
    halfedge_edge : (t, 3) int64, edge id of half-edge ``(F[f, k], F[f, (k+1) % 3])`` of each topological face
    halfedge_forward : (t, 3) bool, whether that half-edge runs from the lower to the higher vertex index
    topo_faces : (t,) int64, indices (into F) of the topological faces
    """

    edges: np.ndarray
    face_count: np.ndarray
    halfedge_edge: np.ndarray
    halfedge_forward: np.ndarray
    topo_faces: np.ndarray

    @property
    def n_boundary(self) -> int:
        """Edges used by exactly one face (open boundary)."""
        return int(np.count_nonzero(self.face_count == 1))

    @property
    def n_nonmanifold(self) -> int:
        """Edges used by three or more faces."""
        return int(np.count_nonzero(self.face_count > 2))


def edge_topology(faces) -> EdgeTopology:
    """Build the undirected edge table of ``faces`` ((m, 3) int); faces with a repeated index are skipped."""
    F = np.asarray(faces, dtype=np.int64)
    topo = np.flatnonzero((F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2]))
    Ft = F[topo]
    a = Ft.reshape(-1)
    b = np.roll(Ft, -1, axis=1).reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    edges, inverse, counts = pair_table(lo, hi, int(F.max()) + 1 if F.size else 1)
    return EdgeTopology(edges=edges, face_count=counts,
                        halfedge_edge=inverse.reshape(-1, 3).astype(np.int64),
                        halfedge_forward=(a < b).reshape(-1, 3), topo_faces=topo)


def vertex_adjacency(n_vertices: int, faces) -> tuple[np.ndarray, np.ndarray]:
    """Vertex graph of ``faces`` as CSR: the unique neighbours of every vertex, sorted.

    Two vertices are neighbours when they are distinct corners of a common face (so a face with a repeated index
    still contributes its one edge; self-loops never appear). Every undirected edge is listed in both rows.

    Parameters
    ----------
    n_vertices : int, number of vertices n (rows of the result; indices in ``faces`` must be below it)
    faces : (m, 3) int array

    Returns
    -------
    indptr : (n + 1,) int64, row v is ``indices[indptr[v]:indptr[v + 1]]``
    indices : (2 e,) int64, neighbour vertex indices, ascending within each row
    """
    F = np.asarray(faces, dtype=np.int64)
    a = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    b = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    keep = a != b
    a, b = a[keep], b[keep]
    pairs, _, _ = pair_table(np.concatenate([a, b]), np.concatenate([b, a]), int(n_vertices))  # by row, column
    indptr = np.zeros(n_vertices + 1, dtype=np.int64)
    indptr[1:] = np.cumsum(np.bincount(pairs[:, 0], minlength=n_vertices))
    return indptr, pairs[:, 1]


def vertex_components(n_vertices: int, faces) -> tuple[int, np.ndarray]:
    """Connected components of the referenced vertices (vertices sharing a face are connected).

    Returns
    -------
    n_components : int, number of components that contain at least one face
    labels : (n,) int64, component id per vertex in ``0 .. n_components-1``, -1 for unreferenced vertices
    """
    F = np.asarray(faces, dtype=np.int64)
    rows = np.concatenate([F[:, 0], F[:, 1]])
    cols = np.concatenate([F[:, 1], F[:, 2]])
    graph = sparse.coo_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(n_vertices, n_vertices))
    _, raw = csgraph.connected_components(graph, directed=False)
    referenced = np.zeros(n_vertices, bool)
    referenced[F.reshape(-1)] = True
    labels = np.full(n_vertices, -1, np.int64)
    # renumber the components that hold faces in order of their lowest vertex index (deterministic)
    _, first, inv = np.unique(raw[referenced], return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))
    labels[referenced] = rank[inv]
    return int(first.size), labels


def _manifold_pairs(topo: EdgeTopology):
    """Face pairs across manifold edges: (f_a, f_b, same_direction) with indices into ``topo.topo_faces``."""
    he_edge = topo.halfedge_edge.reshape(-1)
    he_face = np.repeat(np.arange(topo.halfedge_edge.shape[0]), 3)
    he_fwd = topo.halfedge_forward.reshape(-1)
    manifold = topo.face_count[he_edge] == 2
    he_edge, he_face, he_fwd = he_edge[manifold], he_face[manifold], he_fwd[manifold]
    order = counting_order(he_edge, topo.edges.shape[0])
    he_face, he_fwd = he_face[order], he_fwd[order]
    fa, fb = he_face[0::2], he_face[1::2]
    same = he_fwd[0::2] == he_fwd[1::2]  # both faces walk the edge the same way: inconsistent winding
    keep = fa != fb  # a face using the same edge twice (possible only with repeated geometry) is ignored
    fa, fb, same = fa[keep], fb[keep], same[keep]
    # two faces sharing several edges (a doubled triangle) are one adjacency: keep the first pair
    n_f = int(max(fa.max(initial=0), fb.max(initial=0)) + 1)
    _, inverse, _ = pair_table(np.minimum(fa, fb), np.maximum(fa, fb), n_f)
    first = np.full(inverse.max(initial=-1) + 1, fa.size, dtype=np.int64)
    np.minimum.at(first, inverse, np.arange(fa.size))
    first = np.sort(first)
    return fa[first], fb[first], same[first]


def _patch_labels(n_topo: int, fa, fb) -> tuple[int, np.ndarray]:
    graph = sparse.coo_matrix((np.ones(fa.size, np.int8), (fa, fb)), shape=(n_topo, n_topo))
    return csgraph.connected_components(graph, directed=False)


def consistent_winding(faces, topo: EdgeTopology | None = None):
    """Make the winding consistent across every manifold edge, by a breadth-first walk over face adjacency.

    Within each patch the walk starts at the lowest-index face and flips a neighbour whenever both faces run
    along their shared edge in the same direction. If the result flips more than half of a patch, the whole patch
    is inverted instead, so that the orientation of the file's majority of faces is kept.

    Parameters
    ----------
    faces : (m, 3) int array
    topo : EdgeTopology of ``faces``, optional (recomputed when omitted)

    Returns
    -------
    new_faces : (m, 3) int64, flipped faces written as ``(a, c, b)``
    flipped : (m,) bool, faces whose corner order was changed
    n_conflicts : int, manifold edges still inconsistent afterwards (> 0 only for non-orientable patches,
        e.g. a Moebius strip, where no consistent winding exists)
    """
    F = np.array(faces, dtype=np.int64)
    topo = edge_topology(F) if topo is None else topo
    flipped = np.zeros(F.shape[0], bool)
    fa, fb, same = _manifold_pairs(topo)
    if not same.any():
        return F, flipped, 0
    n_topo = topo.topo_faces.size
    n_patch, patch = _patch_labels(n_topo, fa, fb)
    # a virtual root (node n_topo) linked to the lowest face of every patch gives one deterministic BFS
    roots = np.unique(patch, return_index=True)[1]
    rows = np.concatenate([fa, fb, np.full(roots.size, n_topo)])
    cols = np.concatenate([fb, fa, roots])
    parity = np.concatenate([same, same, np.zeros(roots.size, bool)]).astype(np.int8) + 1  # 1 keep, 2 flip
    graph = sparse.csr_matrix((parity, (rows, cols)), shape=(n_topo + 1, n_topo + 1))
    order, pred = csgraph.breadth_first_order(graph, n_topo, directed=True, return_predecessors=True)
    flip_t = np.zeros(n_topo + 1, bool)
    rel = np.asarray(graph[pred[order[1:]], order[1:]]).reshape(-1) == 2
    flip_list = flip_t.tolist()
    pred_list = pred.tolist()
    for node, r in zip(order[1:].tolist(), rel.tolist()):
        flip_list[node] = flip_list[pred_list[node]] ^ r
    flip_t = np.array(flip_list[:n_topo], bool)
    # keep the majority orientation of each patch
    n_flip = np.bincount(patch, weights=flip_t, minlength=n_patch)
    n_size = np.bincount(patch, minlength=n_patch)
    invert = n_flip * 2 > n_size
    flip_t ^= invert[patch]
    n_conflicts = int(np.count_nonzero((flip_t[fa] ^ flip_t[fb]) != same))
    flipped[topo.topo_faces[flip_t]] = True
    F[flipped] = F[flipped][:, [0, 2, 1]]
    return F, flipped, n_conflicts


def signed_volumes(vertices, faces, labels, n_labels: int) -> np.ndarray:
    """Signed volume enclosed by each group of faces, ``sum det(v0, v1, v2) / 6`` (about the vertex centroid).

    Meaningful only for closed groups, where it does not depend on the origin. Returns (n_labels,) float64.
    """
    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces, np.int64)
    c = V.mean(axis=0)
    a, b, d = V[F[:, 0]] - c, V[F[:, 1]] - c, V[F[:, 2]] - c
    det = np.einsum("ij,ij->i", a, np.cross(b, d)) / 6.0
    return np.bincount(labels, weights=det, minlength=n_labels)


def winding_number(point, vertices, faces) -> float:
    """Generalized winding number of a closed oriented surface at ``point`` (Jacobson et al. 2013).

    Sum of the triangles' signed solid angles over 4 pi, each from the Van Oosterom & Strackee (1983) formula.
    About 1 inside a positively oriented closed surface, 0 outside, -1 inside a negatively oriented one.
    """
    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces, np.int64)
    p = np.asarray(point, np.float64)
    a, b, c = V[F[:, 0]] - p, V[F[:, 1]] - p, V[F[:, 2]] - p
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb
           + np.einsum("ij,ij->i", b, c) * la)
    return float(np.sum(2.0 * np.arctan2(num, den)) / (4.0 * np.pi))


def _nesting_parity(V, Ft, patch, n_patch, ids, vol) -> np.ndarray:
    """+1 or -1 per closed patch in ``ids``: (-1)**(number of other closed patches that contain it)."""
    order = np.argsort(patch, kind="stable")
    starts = np.concatenate([[0], np.cumsum(np.bincount(patch, minlength=n_patch))])
    corners = V[Ft[order]]  # (t, 3, 3), faces grouped by patch
    lo = np.minimum.reduceat(corners.min(axis=1), starts[:-1], axis=0)[ids]
    hi = np.maximum.reduceat(corners.max(axis=1), starts[:-1], axis=0)[ids]
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    out = np.ones(ids.size)
    for k, i in enumerate(ids):
        s, e = starts[i], starts[i + 1]
        probe = corners[s + np.argmax(areas[s:e])].mean(axis=0)  # centroid of its largest face
        inside_box = np.all((probe >= lo) & (probe <= hi), axis=1)
        inside_box[k] = False
        depth = 0
        for k2 in np.flatnonzero(inside_box):
            j = ids[k2]
            w = winding_number(probe, V, Ft[order[starts[j]:starts[j + 1]]]) * np.sign(vol[j])
            depth += int(w > 0.5)
        out[k] = 1.0 if depth % 2 == 0 else -1.0
    return out


def orient_outward(vertices, faces, topo: EdgeTopology | None = None, *, rel_volume_tol: float = 1e-9):
    """Flip closed patches so that normals point out of the enclosed material (see module docstring).

    Expects consistently wound faces (``consistent_winding`` first). ``topo`` may be the edge table of the faces
    *before* that repair: only its undirected information (edges, adjacency) is used, which flips do not change.
    Open patches are left as they are: their
    inside is undefined. A closed patch whose |signed volume| is below ``rel_volume_tol * scale**3`` (a flat,
    doubly covered sheet) is also left alone; ``scale`` is the bounding-box diagonal of the referenced vertices.

    Returns
    -------
    new_faces : (m, 3) int64
    flipped : (m,) bool, faces whose corner order was changed
    n_patches_flipped : int
    n_closed : int, number of closed patches
    """
    V = np.asarray(vertices, np.float64)
    F = np.array(faces, dtype=np.int64)
    topo = edge_topology(F) if topo is None else topo
    flipped = np.zeros(F.shape[0], bool)
    n_topo = topo.topo_faces.size
    if n_topo == 0:
        return F, flipped, 0, 0
    fa, fb, _ = _manifold_pairs(topo)
    n_patch, patch = _patch_labels(n_topo, fa, fb)
    # closed patch: each (patch, edge) pair is used exactly twice
    _, pe_inv, pe_cnt = pair_table(topo.halfedge_edge.reshape(-1), np.repeat(patch, 3),
                                   max(int(topo.edges.shape[0]), n_patch) + 1)
    bad = np.zeros(n_patch, bool)
    bad[np.repeat(patch, 3)[pe_cnt[pe_inv] != 2]] = True
    closed = ~bad
    n_closed = int(np.count_nonzero(closed))
    if n_closed == 0:
        return F, flipped, 0, 0
    Ft = F[topo.topo_faces]
    vol = signed_volumes(V, Ft, patch, n_patch)
    used = V[sorted_unique(Ft)]
    scale = float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
    solid = closed & (np.abs(vol) > rel_volume_tol * scale**3)
    target = np.ones(n_patch)
    ids = np.flatnonzero(solid)
    if ids.size > 1:
        target[ids] = _nesting_parity(V, Ft, patch, n_patch, ids, vol)
    flip_patch = solid & (np.sign(vol) != target)
    flip_t = flip_patch[patch]
    flipped[topo.topo_faces[flip_t]] = True
    F[flipped] = F[flipped][:, [0, 2, 1]]
    return F, flipped, int(np.count_nonzero(flip_patch)), n_closed
