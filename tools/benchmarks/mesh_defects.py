"""Defect generators: a clean mesh made imperfect on purpose, as real assets are (issue 41).

Each generator is a pure function of ``(vertices, faces)`` (and a seed where it chooses something) that returns a
:class:`Defected`: the new arrays and *where* the defects are, so that a benchmark or a test can compare the
defective mesh's per-vertex results with the clean mesh's away from them (:func:`far_from`,
:func:`relative_change`). Why here and not in the package: meshshade never makes meshes worse; these exist to
measure that a bake does not care about harmless defects (tools/benchmarks/bench_defects.py,
tests/test_defect_invariance.py).

Guarantees of every generator
-----------------------------
* The input's ``n`` vertices come first, **unchanged and in their original order** (``out.vertices[:n]`` equals
  ``vertices``), so results per vertex line up with the clean mesh's; new vertices (a ball, a fin's tip, stray
  vertices) are appended after them.
* Faces that are kept keep their relative order; new faces are appended at the end.
* Deterministic: the same inputs and ``seed`` give the same output (``numpy.random.default_rng(seed)``).
* Lengths (``points``, ``radius``, ``height``...) are in the units of ``vertices`` (mm in the benchmarks).

Generators: :func:`punch_holes` (the faces of the 2-ring around k vertices removed), :func:`cut_discs` (the faces
within a distance of given points removed: round holes of a chosen size), :func:`duplicate_faces`,
:func:`add_part` / :func:`add_ball` (an overlapping extra part), :func:`add_fin` (faces sharing one edge: a
non-manifold edge), :func:`add_stray_vertices` (unreferenced vertices), :func:`flip_faces` (reversed winding).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from meshshade.geometry.procedural import icosphere

__all__ = ["Defected", "punch_holes", "cut_discs", "duplicate_faces", "add_part", "add_ball", "add_fin",
           "add_stray_vertices", "flip_faces", "far_from", "relative_change", "vertex_faces", "ring_faces",
           "boundary_vertices"]


class Defected(NamedTuple):
    """A defective mesh and where its defects are.

    Attributes
    ----------
    vertices : (n', 3) float64, the input's n vertices first (unchanged, in order), then any new ones
    faces : (m', 3) int64
    points : (k, 3) float64, the defect locations (units of ``vertices``): hole centres, duplicated faces'
        centroids, a ball's centre, a fin's edge midpoint, stray vertices, flipped faces' centroids
    details : dict, what was done (``kind`` and the indices involved), JSON-friendly
    """

    vertices: np.ndarray
    faces: np.ndarray
    points: np.ndarray
    details: dict


def _arrays(vertices, faces):
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"vertices must be (n, 3) and faces (m, 3); got {V.shape} and {F.shape}")
    return V, F


def _count(k, name, most):
    k = int(k)
    if k < 0 or k > most:
        raise ValueError(f"{name} must be in [0, {most}]; got {k}")
    return k


def _centroids(V, F):
    return V[F].mean(axis=1) if F.size else np.zeros((0, 3))


def _face_normals(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0), 0.5 * length[:, 0]


def vertex_faces(n_vertices: int, faces) -> sparse.csr_matrix:
    """(n, m) incidence: entry (v, f) is 1 when vertex v is a corner of face f."""
    F = np.asarray(faces, dtype=np.int64)
    rows = F.reshape(-1)
    cols = np.repeat(np.arange(F.shape[0]), 3)
    inc = sparse.csr_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(n_vertices, F.shape[0]))
    inc.data[:] = 1  # a face with a repeated corner counts once
    return inc


def _ring(inc, F, centre: int, rings: int):
    """(faces of the rings-ring around centre, the vertices of those faces), both sorted."""
    verts = np.array([int(centre)])
    got = np.zeros(0, np.int64)
    for _ in range(rings):
        got = np.unique(inc[verts].indices).astype(np.int64)
        verts = np.unique(F[got])
    return got, verts


def ring_faces(n_vertices: int, faces, centre: int, rings: int = 2) -> np.ndarray:
    """Sorted indices of the faces of the ``rings``-ring around vertex ``centre``.

    The 1-ring faces are the faces incident to ``centre``; the r-ring faces are the faces incident to any vertex
    of the (r-1)-ring faces (so the 2-ring faces are every face that touches the centre or one of its
    neighbours: 24 faces around a vertex of valence 6 in a regular triangulation, 6 + 18).
    """
    if rings < 1:
        raise ValueError(f"rings must be >= 1; got {rings}")
    F = np.asarray(faces, dtype=np.int64)
    return _ring(vertex_faces(n_vertices, F), F, centre, rings)[0]


def boundary_vertices(n_vertices: int, faces) -> np.ndarray:
    """(n,) bool: vertices on an edge used by one face only (an open boundary) or by three or more."""
    F = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    e = e[e[:, 0] != e[:, 1]]
    keys, counts = np.unique(e[:, 0] * np.int64(n_vertices) + e[:, 1], return_counts=True)
    bad = keys[counts != 2]
    out = np.zeros(n_vertices, dtype=bool)
    out[bad // n_vertices] = True
    out[bad % n_vertices] = True
    return out


def punch_holes(vertices, faces, k: int, *, seed: int = 0, rings: int = 2, min_separation: float | None = None,
                centres=None) -> Defected:
    """Remove the ``rings``-ring faces (:func:`ring_faces`) around ``k`` vertices: ``k`` small holes.

    Parameters
    ----------
    vertices : (n, 3) float, faces : (m, 3) int
    k : int, number of holes (ignored when ``centres`` is given)
    seed : int, chooses the centres: vertices taken in the order of a seeded permutation, keeping one when it is
        at least ``min_separation`` from every centre kept so far and its ring touches no open or non-manifold
        edge (so the holes stay separate and each opens a closed surface)
    rings : int, 2 (the issue's "2-ring faces"); 1 removes only the faces incident to the centre
    min_separation : float, distance between centres (units of ``vertices``); default 10 % of the longest side
        of the bounding box
    centres : optional sequence of vertex indices: punch exactly there (no choice, ``seed`` unused)

    Returns
    -------
    :class:`Defected`; ``points`` are the centres' positions; ``details``: ``centres`` (vertex ids),
    ``removed_faces`` (face ids of the input, sorted), ``unreferenced`` (vertices left without a face, kept in
    place since vertices are never removed: with ``rings=2`` each centre and its neighbours).

    Raises
    ------
    ValueError when fewer than ``k`` admissible centres exist.
    """
    V, F = _arrays(vertices, faces)
    if rings < 1:
        raise ValueError(f"rings must be >= 1; got {rings}")
    n = V.shape[0]
    inc = vertex_faces(n, F)
    on_edge = boundary_vertices(n, F)

    if centres is not None:
        chosen = [int(c) for c in centres]
        rings_of = [_ring(inc, F, c, rings)[0] for c in chosen]
    else:
        k = _count(k, "k", n)
        sep = 0.1 * float(np.ptp(V, axis=0).max()) if min_separation is None else float(min_separation)
        used = np.unique(F)
        order = np.random.default_rng(seed).permutation(used)
        chosen, rings_of = [], []
        for c in order:
            if len(chosen) == k:
                break
            if chosen and np.min(np.linalg.norm(V[chosen] - V[c], axis=1)) < sep:
                continue
            got, verts = _ring(inc, F, int(c), rings)
            if got.size == 0 or on_edge[verts].any():
                continue
            chosen.append(int(c))
            rings_of.append(got)
        if len(chosen) < k:
            raise ValueError(f"only {len(chosen)} of {k} hole centres found {sep:g} apart away from open or "
                             "non-manifold edges; lower min_separation")
    removed = np.unique(np.concatenate(rings_of)) if rings_of else np.zeros(0, np.int64)
    keep = np.ones(F.shape[0], dtype=bool)
    keep[removed] = False
    F2 = F[keep]
    referenced = np.zeros(n, bool)
    referenced[F2.reshape(-1)] = True
    was = np.zeros(n, bool)
    was[F.reshape(-1)] = True
    return Defected(V.copy(), F2, V[chosen].copy(),
                    {"kind": "holes", "rings": int(rings), "centres": chosen, "removed_faces": removed.tolist(),
                     "unreferenced": np.flatnonzero(was & ~referenced).tolist()})


def cut_discs(vertices, faces, centres, radius: float) -> Defected:
    """Remove every face whose centroid lies within ``radius`` of one of ``centres`` (k, 3): round holes about
    2 ``radius`` across on a mesh finer than that (their rims follow the faces' edges).

    Returns :class:`Defected`; ``points``: the centres; ``details``: ``radius``, ``removed_faces`` (sorted ids of
    the input's faces).
    """
    V, F = _arrays(vertices, faces)
    if not radius > 0:
        raise ValueError(f"radius must be > 0; got {radius}")
    P = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    d, _ = cKDTree(P).query(_centroids(V, F), k=1)
    removed = np.flatnonzero(d < radius)
    return Defected(V.copy(), F[d >= radius], P.copy(),
                    {"kind": "round holes", "radius": float(radius), "removed_faces": removed.tolist()})


def duplicate_faces(vertices, faces, k: int, *, seed: int = 0, reverse: bool = False) -> Defected:
    """Append copies of ``k`` distinct faces chosen with ``seed`` (the same corners; ``reverse``: reversed winding,
    a double-sided face). ``points``: the duplicated faces' centroids; ``details["duplicated"]``: their ids."""
    V, F = _arrays(vertices, faces)
    k = _count(k, "k", F.shape[0])
    picked = np.sort(np.random.default_rng(seed).choice(F.shape[0], size=k, replace=False))
    extra = F[picked][:, [0, 2, 1]] if reverse else F[picked]
    return Defected(V.copy(), np.concatenate([F, extra]), _centroids(V, F[picked]),
                    {"kind": "duplicated faces", "duplicated": picked.tolist(), "reversed": bool(reverse)})


def add_part(vertices, faces, part_vertices, part_faces, *, points=None) -> Defected:
    """Append another part (its vertices after the input's, its faces after the input's faces, renumbered).

    ``points``: where to report the defect (default: the part's vertex centroid).
    """
    V, F = _arrays(vertices, faces)
    PV, PF = _arrays(part_vertices, part_faces)
    pts = PV.mean(axis=0, keepdims=True) if points is None else np.atleast_2d(np.asarray(points, np.float64))
    n = V.shape[0]
    return Defected(np.concatenate([V, PV]), np.concatenate([F, PF + n]), pts,
                    {"kind": "extra part", "new_vertices": [n, n + PV.shape[0]], "new_faces": PF.shape[0]})


def add_ball(vertices, faces, centre, radius: float, *, subdivisions: int = 2) -> Defected:
    """Append an icosphere of ``radius`` centred at ``centre`` (a closed, outward-wound second part that overlaps
    the mesh where ``centre`` is on or near its surface: half inside when ``centre`` is a surface vertex).

    ``subdivisions``: of the icosahedron (2: 162 vertices, edges about radius / 2). ``points``: ``[centre]``.
    """
    if not radius > 0:
        raise ValueError(f"radius must be > 0; got {radius}")
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    BV, BF = icosphere(float(radius), int(subdivisions))
    out = add_part(vertices, faces, BV + c, BF, points=c)
    return out._replace(details={**out.details, "kind": "ball", "radius": float(radius),
                                 "centre": c.tolist()})


def add_fin(vertices, faces, *, seed: int = 0, edge=None, n_fins: int = 1, height: float | None = None) -> Defected:
    """Make one edge non-manifold: ``n_fins`` triangles (a fin each) standing on an edge shared by two faces.

    Each fin is the face ``(a, b, tip)`` on the edge ``(a, b)``, its tip a new vertex at the edge's midpoint plus
    ``height`` along the mean normal of the edge's two faces, tilted about the edge by angles spread over
    [-45, 45] degrees when there are several fins. The edge is then used by ``2 + n_fins`` faces.

    Parameters
    ----------
    seed : int, chooses the edge among the manifold edges when ``edge`` is None
    edge : optional (a, b) vertex indices of an edge used by exactly two faces
    n_fins : int >= 1
    height : float, default the edge's length

    Returns
    -------
    :class:`Defected`; ``points``: the edge's midpoint; ``details``: ``edge``, ``tips`` (new vertex ids).
    """
    V, F = _arrays(vertices, faces)
    if n_fins < 1:
        raise ValueError(f"n_fins must be >= 1; got {n_fins}")
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    face_of = np.tile(np.arange(F.shape[0]), 3)
    keys = e[:, 0] * np.int64(V.shape[0]) + e[:, 1]
    uniq, inv, counts = np.unique(keys, return_inverse=True, return_counts=True)
    if edge is None:
        manifold = np.flatnonzero((counts == 2) & (uniq // V.shape[0] != uniq % V.shape[0]))
        if manifold.size == 0:
            raise ValueError("the mesh has no edge shared by exactly two faces")
        pick = int(np.random.default_rng(seed).choice(manifold))
        a, b = int(uniq[pick] // V.shape[0]), int(uniq[pick] % V.shape[0])
    else:
        a, b = sorted(int(x) for x in edge)
        hits = np.flatnonzero(uniq == a * np.int64(V.shape[0]) + b)
        if hits.size == 0 or counts[hits[0]] != 2:
            raise ValueError(f"edge ({a}, {b}) is not an edge shared by exactly two faces")
        pick = int(hits[0])
    two = face_of[inv == pick]
    normals, _ = _face_normals(V, F[two])
    n = normals.sum(axis=0)
    axis = V[b] - V[a]
    length = float(np.linalg.norm(axis))
    axis /= length
    n -= axis * (n @ axis)
    if np.linalg.norm(n) < 1e-12:  # a folded edge: any direction perpendicular to it
        n = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    n /= np.linalg.norm(n)
    side = np.cross(axis, n)
    h = length if height is None else float(height)
    angles = np.radians(np.linspace(-45.0, 45.0, n_fins)) if n_fins > 1 else np.zeros(1)
    mid = 0.5 * (V[a] + V[b])
    tips = mid + h * (np.cos(angles)[:, None] * n + np.sin(angles)[:, None] * side)
    ids = V.shape[0] + np.arange(n_fins)
    fins = np.stack([np.full(n_fins, a), np.full(n_fins, b), ids], axis=1)
    return Defected(np.concatenate([V, tips]), np.concatenate([F, fins]), mid[None, :],
                    {"kind": "fin", "edge": [a, b], "tips": ids.tolist(), "height": h})


def add_stray_vertices(vertices, faces, k: int, *, seed: int = 0, mode: str = "surface",
                       spread: float = 0.0) -> Defected:
    """Append ``k`` vertices that no face uses (as range scans keep the points they did not connect).

    ``mode="surface"``: at uniformly random points of the surface (faces chosen by area), moved along the face
    normal by a uniform offset in [-spread, spread]; ``mode="bbox"``: uniformly in the bounding box of the
    referenced vertices. ``points``: the new vertices' positions; ``details["new_vertices"]``: [first, end).
    """
    V, F = _arrays(vertices, faces)
    k = int(k)
    if k < 0:
        raise ValueError(f"k must be >= 0; got {k}")
    rng = np.random.default_rng(seed)
    if mode == "surface":
        normals, area = _face_normals(V, F)
        f = rng.choice(F.shape[0], size=k, p=area / area.sum())
        r1, r2 = rng.random(k), rng.random(k)
        s = np.sqrt(r1)
        bary = np.stack([1.0 - s, s * (1.0 - r2), s * r2], axis=1)
        P = np.einsum("ij,ijk->ik", bary, V[F[f]]) + normals[f] * rng.uniform(-spread, spread, k)[:, None]
    elif mode == "bbox":
        used = V[np.unique(F)]
        lo, hi = used.min(axis=0), used.max(axis=0)
        P = lo + rng.random((k, 3)) * (hi - lo)
    else:
        raise ValueError(f"mode must be 'surface' or 'bbox'; got {mode!r}")
    n = V.shape[0]
    return Defected(np.concatenate([V, P]), F.copy(), P.copy(),
                    {"kind": "stray vertices", "mode": mode, "new_vertices": [n, n + k]})


def flip_faces(vertices, faces, k: int, *, seed: int = 0) -> Defected:
    """Reverse the winding of ``k`` faces chosen with ``seed``, in place (rows keep their positions).

    Chosen so that no two flipped faces share an edge, so each is an isolated winding error that a consistent
    winding walk puts back. ``points``: the flipped faces' centroids; ``details["flipped"]``: their ids.
    """
    V, F = _arrays(vertices, faces)
    k = _count(k, "k", F.shape[0])
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, inv = np.unique(e[:, 0] * np.int64(V.shape[0]) + e[:, 1], return_inverse=True)
    edges_of = inv.reshape(3, -1).T
    taken = np.zeros(inv.max() + 1, dtype=bool)
    picked = []
    for f in np.random.default_rng(seed).permutation(F.shape[0]):
        if len(picked) == k:
            break
        if taken[edges_of[f]].any():
            continue
        taken[edges_of[f]] = True
        picked.append(int(f))
    if len(picked) < k:
        raise ValueError(f"only {len(picked)} of {k} faces found that share no edge")
    picked = np.sort(np.array(picked, dtype=np.int64))
    F2 = F.copy()
    F2[picked] = F2[picked][:, [0, 2, 1]]
    return Defected(V.copy(), F2, _centroids(V, F[picked]), {"kind": "flipped faces", "flipped": picked.tolist()})


def far_from(vertices, points, distance: float) -> np.ndarray:
    """(n,) bool: vertices farther than ``distance`` from every one of ``points`` (all True without points)."""
    V = np.asarray(vertices, dtype=np.float64)
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] == 0 or distance <= 0:
        return np.ones(V.shape[0], dtype=bool)
    d, _ = cKDTree(P).query(V, k=1)
    return d > distance


def relative_change(defect, clean, keep, *, peak_fraction: float = 1e-3) -> dict:
    """|defect / clean - 1| per channel over the ``keep`` vertices whose clean value is above ``peak_fraction``
    of the channel's peak (over every vertex of ``clean``).

    Parameters
    ----------
    defect, clean : (n, c) float, per-vertex values of the same n vertices (pass ``defect[:n]``)
    keep : (n,) bool

    Returns
    -------
    dict with lists of length c: ``mean``, ``p99``, ``max`` (None for a channel without vertices), ``count``;
    and ``finite`` (whether every kept value of ``defect`` is finite)
    """
    D = np.asarray(defect, dtype=np.float64)
    C = np.asarray(clean, dtype=np.float64)
    if D.shape != C.shape:
        raise ValueError(f"defect {D.shape} and clean {C.shape} must have the same shape")
    keep = np.asarray(keep, dtype=bool)
    out = {"mean": [], "p99": [], "max": [], "count": [], "finite": bool(np.isfinite(D[keep]).all())}
    for c in range(C.shape[1]):
        sel = keep & (C[:, c] > peak_fraction * C[:, c].max())
        rel = np.abs(D[sel, c] / C[sel, c] - 1.0)
        out["count"].append(int(sel.sum()))
        for key, fn in (("mean", np.mean), ("p99", lambda x: np.percentile(x, 99)), ("max", np.max)):
            out[key].append(float(fn(rel)) if rel.size else None)
    return out
