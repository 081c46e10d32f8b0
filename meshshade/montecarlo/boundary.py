"""Where the Monte Carlo's medium ends: the bake's inside {w > 1/2} as a closed surface of triangles (the walk
surface).

The default bake finds the object's inside with the generalised winding number w (docs/physics.md §15,
:mod:`meshshade.volume.inside`): the medium is {w > 1/2}, so an open scan, overlapping parts, duplicated faces
and fins all have one, and a hole is closed by the level surface w = 1/2. The random walk
(:mod:`meshshade.montecarlo.engine`) asks Embree for the next face along a photon's path and treats it as the
surface. :func:`walk_surface` gives it a surface on which that is true (docs/physics.md §10, eqs. (127)-(129)):

1. **Classify the faces** (:func:`face_sides`, :func:`probe_sides`, eq. (127)): w is evaluated a small distance
   (``SIDE_OFFSET`` of the face's longest edge, at least ``SIDE_FLOOR`` of the mesh's half-diagonal) in front of
   and behind each face's centroid. Where the two values lie on different sides of 1/2 the face is a boundary:
   kept with the medium behind it (turned round where the medium is in front). Where they lie on the same side (a
   face inside the medium: the inner faces of overlapping parts; or outside it: a fin standing out) the face is
   *transparent*, index-matched on both sides, and is left out of the walk's Embree scene, so a photon passes
   through it without a ray, a Fresnel draw or a tally. Faces with the same three corners are one sheet
   (:func:`coincident_faces`): one of them carries the sheet's class, the others are left out (a duplicated face
   changes nothing; a face and its reversed copy, whose winding cancels, are no surface).
2. **Follow the seams** (:func:`split_seams`): where overlapping parts cross, faces next to a face of another class
   are probed near their corners too and, where the probes disagree, split in four, recursively (``SEAM_LEVELS``),
   so the walk surface follows the seam to 1/32 of an edge; a part still straddling at the last level is kept, so
   the seam is closed rather than open.
3. **Close the holes** (:func:`rim_loops`, :func:`lid_rings`, :func:`project_to_level`, eq. (128)): the rims
   (edges of the walk surface without a partner the other way round, with an edge of the mesh's own open boundary)
   are traced into loops; each loop is spanned by a disc of rings (the rim scaled towards its centroid, as many
   rings as the rim's radius holds rim edges; a fan where the rim is not star-shaped about its centroid) whose
   inner points are moved along the rim's mean normal onto the level surface w = 1/2 (the crossing nearest the
   rim's plane, by bisection). The lid shares the rim's vertex positions bit for bit, so Embree's watertight
   traversal cannot slip between lid and mesh; and any disc spanning the rim closes the medium (a path from
   w > 1/2 to w < 1/2 must cross the closed surface mesh + lid), so even a folded fan leaks nothing. A loop whose
   centre finds no level crossing, or finds it on another sheet (closer than ``LID_CLEARANCE`` of its radius to a
   face), is left open. The level surface depends on the rim alone (the solid angle of an open surface depends
   only on its boundary curve): across a planar rim it is the flat disc.

The lid faces are boundary faces with Fresnel, as a face is (the bake's lattice ends there with its Robin
condition): light shining into a hole enters through the lid, and a photon leaving through a lid leaves the
object (it is in the totals, diffuse or transmitted as for any face, but on no mesh vertex: the lid has its own
copies of the rim's vertices, after the mesh's ``n`` vertices). The parts of split faces have their own corners
too; what they tally goes back to the face's vertices by the corners' barycentrics (``WalkSurface.vertex_map``,
eq. (129)).

A closed, consistently oriented mesh without overlapping parts gives every face the class "boundary" and no rim:
the walk surface is then the mesh's own arrays (``identity``), and a run is bitwise what it was before this module
existed. Pure array work over the winding numbers of :class:`meshshade.volume.inside.SurfaceVolume` (the triangle
hierarchy's fast winding number, :mod:`meshshade.volume.triangle_tree`); no I/O.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import sparse

from meshshade.volume.inside import SurfaceVolume

__all__ = ["WalkSurface", "walk_surface", "face_sides", "probe_sides", "coincident_faces", "welded_ids", "split_seams",
           "quarter", "rim_edges", "rim_loops", "lid_rings", "project_to_level", "SIDE_OFFSET", "SIDE_FLOOR",
           "SEAM_LEVELS", "LID_CLEARANCE", "BOUNDARY", "REVERSED", "TRANSPARENT"]

#: the two winding-number probes of a face sit SIDE_OFFSET of its longest edge, and at least SIDE_FLOOR of the
#: mesh's half-diagonal, in front of and behind its centroid: far below a wall's thickness (a 0.2 mm slab of 20 mm
#: faces: 0.003 mm), far above rounding (the floor was measured on marching-cubes meshes with libigl's float32
#: winding number, below which a sliver's probes no longer saw its sheet; the float64 triangle hierarchy that
#: replaced it needs no more, and the floor is kept)
SIDE_OFFSET, SIDE_FLOOR = 1e-4, 1e-5
#: most halvings of a face that a seam of overlapping parts crosses (the seam is then followed to 1/32 of an edge)
SEAM_LEVELS = 5
#: a probe whose winding number lies within PROBE_UNSURE of 1/2 is evaluated again with the triangle hierarchy's
#: expansion taken only beyond PROBE_BETA times a node's radius (within ~1e-7 of the exact sum of the triangles'
#: solid angles, against ~6e-4 at the volume's beta = 2: measured beside a fin on a 20 mm sphere, where the exact
#: value is 1/2 - 2.7e-4)
PROBE_UNSURE, PROBE_BETA = 0.02, 16.0
#: where the probes' jump is not the sheet's, they move this many times nearer (down to the floor)
PROBE_SHRINK = 16.0
#: a lid's centre must land at least this fraction of its rim's radius away from every face of the mesh
LID_CLEARANCE = 0.1
#: the level crossing of a lid point is searched within +-LID_REACH x the rim's radius along the rim's normal,
#: first on 2 x LID_STEPS intervals, then by LID_BISECTIONS bisections of the interval nearest the rim's plane
LID_REACH, LID_STEPS, LID_BISECTIONS = 1.0, 16, 40
#: most rings of a lid (a rim of radius r and mean edge e gets round(r / e) rings, at least 1)
MAX_RINGS = 64
#: classes of a face
BOUNDARY, REVERSED, TRANSPARENT = np.int8(1), np.int8(-1), np.int8(0)


def face_sides(w_front, w_back) -> np.ndarray:
    """(m,) int8 class of each face from the winding numbers just in front of it (``w_front``, the side its normal
    points to) and just behind it (``w_back``): BOUNDARY (1) when only the back is in the medium {w > 1/2},
    REVERSED (-1) when only the front is, TRANSPARENT (0) when both or neither are (eq. (127))."""
    inside_front = np.asarray(w_front) > 0.5
    inside_back = np.asarray(w_back) > 0.5
    return np.where(inside_back & ~inside_front, BOUNDARY,
                    np.where(inside_front & ~inside_back, REVERSED, TRANSPARENT)).astype(np.int8)


def welded_ids(vertices) -> np.ndarray:
    """(n,) int64: the same id for vertices at exactly the same position (the first such vertex's index)."""
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    _, first, inverse = np.unique(V, axis=0, return_index=True, return_inverse=True)
    return first[inverse.reshape(-1)].astype(np.int64)


def coincident_faces(faces) -> tuple[np.ndarray, np.ndarray]:
    """Faces with the same three corners (welded ids ``faces`` (m, 3)) are one sheet.

    Returns (rep (m,) int64, net (m,) int64): ``rep[f]`` the sheet's first face, ``net[f]`` the sheet's winding
    multiplicity relative to ``rep[f]``'s orientation (copies wound as ``rep`` count +1, reversed ones -1; a face
    with a repeated corner has ``net`` 0)."""
    F = np.asarray(faces, dtype=np.int64)
    order = np.argsort(F, axis=1, kind="stable")
    key = np.take_along_axis(F, order, axis=1)
    # the corners' cyclic order: an even permutation of the sorted triple keeps the orientation
    parity = np.where((order[:, 0] == 0) & (order[:, 1] == 1) | (order[:, 0] == 1) & (order[:, 1] == 2)
                      | (order[:, 0] == 2) & (order[:, 1] == 0), 1, -1)
    parity = np.where((key[:, 0] == key[:, 1]) | (key[:, 1] == key[:, 2]), 0, parity)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    rep = first[inverse].astype(np.int64)
    rel = parity * parity[rep]
    net = np.bincount(inverse, weights=rel, minlength=first.size).astype(np.int64)[inverse]
    return rep, net


#: where the probes of a face sit before they move off it (barycentric rows): its centroid, and 0.98 of the way
#: from it towards each corner; the first alone classifies a face, all four find a seam that separates corners
PROBE_POINTS = np.array([[1 / 3, 1 / 3, 1 / 3]] + [list(0.02 / 3 + 0.98 * np.eye(3)[j]) for j in range(3)])


def _probes(tri, offset, at=0):
    """(front, back) probe points of triangles ``tri`` (k, 3, 3): the point ``PROBE_POINTS[at]`` of each, moved by
    ``offset`` (mm, (k,)) along (front) and against (back) its unit normal."""
    c = np.einsum("j,kjd->kd", PROBE_POINTS[at], tri)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
    d = np.asarray(offset, dtype=np.float64)[:, None] * n
    return c + d, c - d


def probe_sides(volume: SurfaceVolume, tri, net, floor, at=0) -> np.ndarray:
    """(k,) int8 :func:`face_sides` of triangles ``tri`` (k, 3, 3) (coordinates of ``volume``'s vertices) at their
    probe point ``at`` (:data:`PROBE_POINTS`), ``net`` (k,) their sheets' multiplicities: the probes start
    ``SIDE_OFFSET`` of the longest edge off the face (at least ``floor``) and move ``PROBE_SHRINK`` times nearer,
    down to ``floor``, while the jump w_back - w_front is not the sheet's (they then straddle another sheet too: a
    wall thinner than the offset)."""
    tri = np.asarray(tri, dtype=np.float64)
    edge = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    offset = np.maximum(SIDE_OFFSET * edge, floor)
    side = np.zeros(tri.shape[0], dtype=np.int8)
    todo = np.arange(tri.shape[0])
    while todo.size:
        f, b = _probes(tri[todo], offset[todo], at)
        P = np.concatenate([f, b])
        w = volume.winding(P)
        # near 1/2 (beside a lone sheet: a fin, w = +-(1/2 - O(offset / edge))) the expansion's error (~1e-3)
        # decides the class: such probes are summed again with the hierarchy opened further
        unsure = np.flatnonzero(np.abs(w - 0.5) < PROBE_UNSURE)
        if unsure.size:
            w[unsure] = volume.tree.winding(P[unsure], PROBE_BETA)
        wf, wb = w[:todo.size], w[todo.size:]
        side[todo] = face_sides(wf, wb)
        bad = (np.abs((wb - wf) - net[todo]) > 0.5) & (offset[todo] > floor)
        todo = todo[bad]
        offset[todo] = np.maximum(offset[todo] / PROBE_SHRINK, floor)
    return side


def quarter(bary) -> np.ndarray:
    """(4s, 3, 3): each triangle of barycentric corner rows ``bary`` (s, 3, 3) split into four at its edges'
    midpoints (corner children first, the middle one last; orientation kept)."""
    b0, b1, b2 = bary[:, 0], bary[:, 1], bary[:, 2]
    m01, m12, m20 = 0.5 * (b0 + b1), 0.5 * (b1 + b2), 0.5 * (b2 + b0)
    kids = np.stack([np.stack([b0, m01, m20], 1), np.stack([m01, b1, m12], 1), np.stack([m20, m12, b2], 1),
                     np.stack([m01, m12, m20], 1)], axis=1)
    return kids.reshape(-1, 3, 3)


def split_seams(volume: SurfaceVolume, tri, net, floor, levels: int = None):
    """The parts of triangles ``tri`` (k, 3, 3) on the medium's boundary, where a seam of overlapping parts may
    cross them (eq. (127) on sub-triangles).

    Each triangle is probed at its four :data:`PROBE_POINTS`; where they all agree it keeps that class, otherwise
    it is split in four (:func:`quarter`) and its children are probed, down to ``levels`` (``SEAM_LEVELS``) splits.
    A sub-triangle still straddling at the last level is kept as a boundary (wound as its boundary probes say), so
    the seam is closed, with at most a sub-triangle of surface left inside the medium. Returns (parent (s,) int64
    index into ``tri``, bary (s, 3, 3) corner rows in the parent, side (s,) int8), transparent parts left out."""
    levels = SEAM_LEVELS if levels is None else int(levels)
    tri = np.asarray(tri, dtype=np.float64)
    net = np.asarray(net)
    parent = np.arange(tri.shape[0])
    bary = np.broadcast_to(np.eye(3), (tri.shape[0], 3, 3)).copy()
    out = []
    for level in range(levels + 1):
        if parent.size == 0:
            break
        T = np.einsum("sij,sjd->sid", bary, tri[parent])
        votes = np.stack([probe_sides(volume, T, net[parent], floor, at) for at in range(len(PROBE_POINTS))], 1)
        same = np.all(votes == votes[:, :1], axis=1)
        cls = np.where(same, votes[:, 0],
                       np.where(np.any(votes == BOUNDARY, axis=1), BOUNDARY,
                                np.where(np.any(votes == REVERSED, axis=1), REVERSED, TRANSPARENT))).astype(np.int8)
        done = same | (level == levels)
        keep = done & (cls != TRANSPARENT)
        out.append((parent[keep], bary[keep], cls[keep]))
        parent, bary = np.repeat(parent[~done], 4), quarter(bary[~done])
    if not out:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3, 3)), np.zeros(0, dtype=np.int8)
    return (np.concatenate([o[0] for o in out]).astype(np.int64), np.concatenate([o[1] for o in out]),
            np.concatenate([o[2] for o in out]).astype(np.int8))


def _directed_keys(F, n):
    """int64 keys a * n + b of the half-edges (a, b) of faces ``F`` (k, 3), (k, 3)."""
    return F * np.int64(n) + np.roll(F, -1, axis=1)


def rim_edges(faces, n_ids: int) -> np.ndarray:
    """(r, 2) int64 directed edges (a, b) of the oriented ``faces`` (welded ids < n_ids) that have no partner
    (b, a): the rims of the surface's holes (an edge used twice the same way and never the other counts twice)."""
    F = np.asarray(faces, dtype=np.int64)
    if F.shape[0] == 0:
        return np.zeros((0, 2), dtype=np.int64)
    n = np.int64(n_ids)
    fwd = _directed_keys(F, n).reshape(-1)
    a, b = fwd // n, fwd % n
    fwd = fwd[a != b]
    rev = (fwd % n) * n + fwd // n
    keys, counts = np.unique(fwd, return_counts=True)
    rk, rc = np.unique(rev, return_counts=True)
    pos = np.searchsorted(rk, keys)
    pos = np.minimum(pos, max(rk.size - 1, 0))
    partner = np.where((rk.size > 0) & (rk[pos] == keys), rc[pos], 0)
    excess = counts - partner
    keep = excess > 0
    out = np.repeat(keys[keep], excess[keep])
    return np.stack([out // n, out % n], axis=1)


@njit(cache=True)
def _trace_loops(src, dst, n_ids):
    """Closed loops of directed edges (src[i] -> dst[i]): (vertex sequence, loop offsets, ok per loop).

    At a vertex with several outgoing edges the first unused one is taken; a walk that cannot return to its start
    (an open chain) is reported with ok = False."""
    e = src.shape[0]
    order = np.argsort(src, kind="mergesort")
    start = np.zeros(n_ids + 1, dtype=np.int64)
    for i in range(e):
        start[src[i] + 1] += 1
    for v in range(n_ids):
        start[v + 1] += start[v]
    cursor = start[:-1].copy()
    used = np.zeros(e, dtype=np.bool_)
    seq = np.empty(e, dtype=np.int64)
    offsets = np.zeros(e + 1, dtype=np.int64)
    ok = np.zeros(e, dtype=np.bool_)
    n_seq = 0
    n_loops = 0
    for k in range(e):
        first = order[k]
        if used[first]:
            continue
        v0 = src[first]
        cur = first
        closed = False
        while True:
            used[cur] = True
            seq[n_seq] = src[cur]
            n_seq += 1
            nxt = dst[cur]
            if nxt == v0:
                closed = True
                break
            j = cursor[nxt]
            while j < start[nxt + 1] and used[order[j]]:
                j += 1
            cursor[nxt] = j
            if j >= start[nxt + 1]:
                break
            cur = order[j]
        ok[n_loops] = closed
        n_loops += 1
        offsets[n_loops] = n_seq
    return seq[:n_seq], offsets[:n_loops + 1], ok[:n_loops]


def rim_loops(rims, n_ids: int) -> tuple[list[np.ndarray], int]:
    """The rim edges ``rims`` (r, 2) traced into closed loops: (loops, open chains), each loop an array of vertex
    ids in the edges' direction (a loop of fewer than 3 vertices counts as open)."""
    rims = np.asarray(rims, dtype=np.int64)
    if rims.shape[0] == 0:
        return [], 0
    seq, off, ok = _trace_loops(np.ascontiguousarray(rims[:, 0]), np.ascontiguousarray(rims[:, 1]), int(n_ids))
    loops = [seq[off[i]:off[i + 1]] for i in range(ok.size) if ok[i] and off[i + 1] - off[i] >= 3]
    return loops, int(ok.size - len(loops))


def lid_rings(P) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """A disc spanning the rim ``P`` (k, 3) (vertex positions in the direction of the mesh faces' edges).

    Rings are the rim scaled towards its centroid c (ring j of R at 1 - j/R; R = round(mean radius / mean rim
    edge), clipped to [1, MAX_RINGS]) and c itself; where the rim is not star-shaped about c in the plane of its
    mean normal, a single fan (R = 1). Returns (points (p, 3): ring 1 .. R - 1 then c, faces (t, 3) indexing the
    rim as 0 .. k - 1 and the points from k on, wound so that the lid continues the mesh's orientation (the rim's
    edges appear reversed), unit normal (3,) of the rim's plane pointing out of the medium, radius mean |P - c|,
    star (bool))."""
    P = np.asarray(P, dtype=np.float64)
    k = P.shape[0]
    c = P.mean(axis=0)
    nxt = np.roll(P, -1, axis=0)
    normal = -np.cross(P - c, nxt - c).sum(axis=0)      # Newell's normal of the reversed rim
    nn = np.linalg.norm(normal)
    normal = normal / nn if nn > 0 else np.array([0.0, 0.0, 1.0])
    area = np.cross(nxt - c, P - c) @ normal            # triangles (P_i+1, P_i, c) seen along the normal
    star = bool(np.all(area > 0.0))
    radius = float(np.mean(np.linalg.norm(P - c, axis=1)))
    edge = float(np.mean(np.linalg.norm(nxt - P, axis=1)))
    R = int(np.clip(round(radius / edge), 1, MAX_RINGS)) if (star and edge > 0) else 1
    s = 1.0 - np.arange(1, R) / R
    points = np.concatenate([(c + s[:, None, None] * (P - c)[None]).reshape(-1, 3), c[None]])
    i = np.arange(k)
    ip = (i + 1) % k
    ring = lambda j, idx: np.where(j == 0, idx, k + (j - 1) * k + idx)  # noqa: E731
    faces = []
    for j in range(R - 1):      # quads between ring j and ring j + 1 (a loop over the few rings, not vertices)
        a, b = ring(j, ip), ring(j, i)
        cc, dd = ring(j + 1, i), ring(j + 1, ip)
        faces += [np.stack([a, b, cc], axis=1), np.stack([a, cc, dd], axis=1)]
    centre = k + (R - 1) * k
    faces.append(np.stack([ring(R - 1, ip), ring(R - 1, i), np.full(k, centre)], axis=1))
    return points, np.concatenate(faces).astype(np.int64), normal, radius, star


def project_to_level(volume: SurfaceVolume, points, directions, reach) -> tuple[np.ndarray, np.ndarray]:
    """Move ``points`` (p, 3) along unit ``directions`` (p, 3) onto the level surface w = 1/2 (eq. (128)).

    On each line x + t d, |t| <= reach (p,), the crossing from w > 1/2 (t below) to w <= 1/2 (t above) nearest
    t = 0 is bracketed on 2 ``LID_STEPS`` intervals and bisected ``LID_BISECTIONS`` times. Returns (t (p,), found
    (p,) bool); t = 0 where no crossing was found."""
    X = np.asarray(points, dtype=np.float64)
    D = np.asarray(directions, dtype=np.float64)
    p = X.shape[0]
    if p == 0:
        return np.zeros(0), np.zeros(0, dtype=bool)
    grid = np.linspace(-1.0, 1.0, 2 * LID_STEPS + 1)
    T = np.asarray(reach, dtype=np.float64)[:, None] * grid[None, :]              # (p, g)
    w = volume.winding((X[:, None, :] + T[..., None] * D[:, None, :]).reshape(-1, 3)).reshape(T.shape)
    cross = (w[:, :-1] > 0.5) & (w[:, 1:] <= 0.5)
    mid = np.abs(0.5 * (grid[:-1] + grid[1:]))
    score = np.where(cross, mid[None, :], np.inf)
    j = np.argmin(score, axis=1)
    found = np.isfinite(score[np.arange(p), j])
    lo = T[np.arange(p), j]
    hi = T[np.arange(p), j + 1]
    idx = np.flatnonzero(found)
    lo, hi = lo[idx], hi[idx]
    for _ in range(LID_BISECTIONS):   # bisection steps, each one batched over every point
        m = 0.5 * (lo + hi)
        inside = volume.winding(X[idx] + m[:, None] * D[idx]) > 0.5
        lo = np.where(inside, m, lo)
        hi = np.where(inside, hi, m)
    t = np.zeros(p)
    t[idx] = 0.5 * (lo + hi)
    return t, found


@dataclass(frozen=True, eq=False)
class WalkSurface:
    """The closed surface the walk runs in: the mesh's boundary faces (turned round where the medium is in front;
    split along a seam where overlapping parts cross them) and the lids of its holes.

    Attributes
    ----------
    vertices : (n_w, 3) float64 mm, the mesh's ``n_mesh_vertices`` vertices first, then new ones (the lids' copies
        of their rims and inner points; the corners of the parts of split faces)
    faces : (m_w, 3) int64, every face with the medium behind it; normals : (m_w, 3) unit; areas : (m_w,) mm^2
    face_of : (m_w,) int64, the mesh face each walk face is (a part of) (-1: a lid face)
    flipped : (m_w,) bool, a whole mesh face wound the other way round
    split : (m_w,) int64, row of ``split_bary`` for a part of a split face (-1: a whole face or a lid)
    split_bary : (s, 3, 3), barycentric rows of each part's corners in its mesh face's corner order
    vertex_map : None, or sparse (n_w - n_mesh_vertices, n_mesh_vertices): how a quantity tallied on a new vertex
        belongs to the mesh's vertices (a split face's corner: its barycentrics in its face; a lid's vertex: nowhere)
    n_mesh_vertices, n_mesh_faces : int; holes : lids built; open_loops : rims of the mesh's holes left open;
        transparent : mesh faces left out (index-matched); reversed : faces turned round; split_faces : faces
        split along a seam; open_edges : the mesh's edges that one face alone uses
    identity : the walk surface is the mesh itself (every face a boundary with the medium behind, no lid)
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    face_of: np.ndarray
    flipped: np.ndarray
    n_mesh_vertices: int
    n_mesh_faces: int
    split: np.ndarray | None = None
    split_bary: np.ndarray | None = None
    vertex_map: object = None
    holes: int = 0
    open_loops: int = 0
    transparent: int = 0
    reversed: int = 0
    split_faces: int = 0
    open_edges: int = 0
    identity: bool = False

    @classmethod
    def of_faces(cls, mesh) -> "WalkSurface":
        """Every face of ``mesh`` a boundary with the medium behind it, no lid: the walk before issue 47 (kept to
        measure against, and for meshes that enclose no volume)."""
        m = mesh.n_faces
        return cls(mesh.vertices, mesh.faces, mesh.face_normals, mesh.face_areas, np.arange(m, dtype=np.int64),
                   np.zeros(m, dtype=bool), mesh.n_vertices, m, identity=True)

    @property
    def lid(self) -> np.ndarray:
        """(m_w,) bool: lid faces."""
        return self.face_of < 0

    @property
    def walk_face(self) -> np.ndarray:
        """(m,) int64: the walk face of each mesh face walked whole (-1: left out, or split)."""
        out = np.full(self.n_mesh_faces, -1, dtype=np.int64)
        whole = np.flatnonzero(self.face_of >= 0) if self.split is None else \
            np.flatnonzero((self.face_of >= 0) & (self.split < 0))
        out[self.face_of[whole]] = whole
        return out

    def mesh_vertex_tally(self, per_vertex) -> np.ndarray:
        """Per-walk-vertex tallies (..., n_w) as per-mesh-vertex tallies (..., n): the mesh's own, plus a split
        face's corners' by their barycentrics; the lids' vertices belong to no mesh vertex."""
        t = np.asarray(per_vertex)
        n = self.n_mesh_vertices
        out = np.array(t[..., :n], dtype=np.float64, copy=True)
        if self.vertex_map is not None and t.shape[-1] > n:
            extra = t[..., n:].reshape(-1, t.shape[-1] - n)
            out += (self.vertex_map.T @ extra.T).T.reshape(out.shape)
        return out

    def mesh_face_tally(self, per_face) -> np.ndarray:
        """Per-walk-face tallies (B, m_w) as per-mesh-face tallies (B, m): parts of a split face added, lid faces
        dropped, transparent faces 0."""
        t = np.asarray(per_face, dtype=np.float64)
        keep = np.flatnonzero(self.face_of >= 0)
        out = np.zeros((t.shape[0], self.n_mesh_faces))
        np.add.at(out.T, self.face_of[keep], t[:, keep].T)
        return out

    def vertex_areas(self) -> np.ndarray:
        """(n,) mm^2: a third of the area of each walk face around each mesh vertex (eq. (129); split faces' parts by
        their corners' barycentrics; lids and transparent faces are around none: the exitance of a vertex is the power
        through the boundary around it over its area)."""
        w = np.repeat(self.areas / 3.0, 3)
        per = np.bincount(self.faces.reshape(-1), weights=w, minlength=self.vertices.shape[0])
        return self.mesh_vertex_tally(per)

    def mesh_bary(self, walk_faces, bary) -> tuple[np.ndarray, np.ndarray]:
        """Exit or entry points on walk faces (``walk_faces`` (k,), ``bary`` (k, 3)) as (mesh face, barycentrics
        in the mesh face's corner order); mesh face -1 on a lid."""
        walk_faces = np.asarray(walk_faces, dtype=np.int64)
        b = np.array(bary, dtype=np.float64, copy=True).reshape(-1, 3)
        flip = self.flipped[walk_faces]
        b[flip] = b[flip][:, [0, 2, 1]]
        if self.split is not None:
            part = self.split[walk_faces]
            sel = np.flatnonzero(part >= 0)
            b[sel] = np.einsum("kj,kjd->kd", b[sel], self.split_bary[part[sel]])
        return self.face_of[walk_faces], b

    def describe(self) -> str | None:
        """One line on what the walk does with this mesh beyond its faces, or None for the identity."""
        if self.identity:
            return None
        parts = []
        if self.holes:
            parts.append(f"{self.holes} hole(s) closed by lids on the winding number's level surface w = 1/2, as the "
                         "bake's volume closes them (light enters and leaves through a lid with Fresnel; what "
                         "leaves there is in the totals, on no vertex)")
        if self.transparent or self.split_faces:
            parts.append(f"{self.transparent} face(s) with the medium on both sides or neither (duplicated faces, "
                         "overlapping parts, fins) are index-matched: photons pass through them"
                         + (f"; {self.split_faces} face(s) that a seam of overlapping parts crosses are walked "
                            "only where they bound the medium" if self.split_faces else ""))
        if self.reversed:
            parts.append(f"{self.reversed} face(s) with the medium in front of them are walked turned round")
        if self.open_loops:
            parts.append(f"{self.open_loops} rim(s) of holes left open (no level surface across them away from the "
                         "mesh: photons reaching them walk on outside, and exitance there is too low)")
        where = f"the mesh is open ({self.open_edges} boundary edges): " if self.open_edges else ""
        return f"Monte Carlo: {where}the walk's medium is the bake's inside {{w > 1/2}}: " + "; ".join(parts)


def walk_surface(mesh) -> WalkSurface:
    """The :class:`WalkSurface` of ``mesh`` (a validated :class:`~meshshade.geometry.mesh.Mesh`); see the module
    docstring. The mesh's own arrays when it is already the boundary of {w > 1/2} with no hole."""
    V, F = mesh.vertices, mesh.faces
    n, m = V.shape[0], F.shape[0]
    good = ~mesh.degenerate_face_mask
    ids = welded_ids(V)
    Fw = ids[F]
    rep, net = coincident_faces(Fw)
    probe = np.flatnonzero(good & (rep == np.arange(m)) & (net != 0))
    lo, hi = V.min(axis=0), V.max(axis=0)
    centre, floor = 0.5 * (lo + hi), SIDE_FLOOR * 0.5 * float(np.linalg.norm(hi - lo))
    Vc = V - centre                     # coordinates centred: the probes' offsets are small against them
    volume = SurfaceVolume(Vc, F)
    side = np.zeros(m, dtype=np.int8)
    side[probe] = probe_sides(volume, Vc[F[probe]], net[probe], floor)
    slivers = _edge_keys(Fw[~good], n)
    if np.all(side[good] == BOUNDARY) and np.all(rep[good] == np.flatnonzero(good)):
        if _rims(Fw[good], n, slivers).shape[0] == 0:
            return WalkSurface(V, F, mesh.face_normals, mesh.face_areas, np.arange(m, dtype=np.int64),
                               np.zeros(m, dtype=bool), n, m, identity=True)
    if not np.any(side != TRANSPARENT):           # no volume: {w > 1/2} is empty (a flat sheet)
        return WalkSurface.of_faces(mesh)
    seam = _seam_candidates(Fw, probe, side, n)
    s_parent, s_bary, s_side = split_seams(volume, Vc[F[seam]], net[seam], floor)
    whole_part = np.all(s_bary == np.eye(3), axis=(1, 2))     # faces settled by their first probes
    side[seam] = TRANSPARENT
    side[seam[s_parent[whole_part]]] = s_side[whole_part]
    parts = np.flatnonzero(~whole_part)
    keep = np.flatnonzero(side != TRANSPARENT)
    flip = side[keep] == REVERSED
    Fk = F[keep].copy()
    Fk[flip] = Fk[flip][:, [0, 2, 1]]
    Nk = mesh.face_normals[keep] * np.where(flip, -1.0, 1.0)[:, None]
    # the split faces' parts: their corners (mesh vertices where they are the face's, new ones otherwise)
    pV, pF, pB, p_face, p_map = _parts(V, F, seam[s_parent[parts]], s_bary[parts], s_side[parts], n)
    p_norm = mesh.face_normals[p_face] * np.where(s_side[parts] == REVERSED, -1.0, 1.0)[:, None]
    # holes: the rims of the whole faces and of the split faces taken whole (wound as their first part)
    split_whole, first = np.unique(p_face, return_index=True)
    Fs = F[split_whole].copy()
    turn = s_side[parts][first] == REVERSED
    Fs[turn] = Fs[turn][:, [0, 2, 1]]
    loops, _ = rim_loops(_rims(np.concatenate([ids[Fk], ids[Fs]]), n, slivers), n)
    holes, open_edges = _holes(loops, Fw[good], n)
    lidV, lidF, n_holes, n_unfilled = _lids(V, centre, [lp for lp, h in zip(loops, holes) if h], volume,
                                            n + pV.shape[0])
    verts = np.concatenate([V, pV, lidV])
    cross = np.cross(verts[lidF[:, 1]] - verts[lidF[:, 0]], verts[lidF[:, 2]] - verts[lidF[:, 0]])
    la = np.linalg.norm(cross, axis=1)
    ln = np.divide(cross, la[:, None], out=np.zeros_like(cross), where=la[:, None] > 0)
    p_area = 0.5 * np.linalg.norm(np.cross(verts[pF[:, 1]] - verts[pF[:, 0]], verts[pF[:, 2]] - verts[pF[:, 0]]),
                                  axis=1)
    m_k, m_p, m_l = keep.size, pF.shape[0], lidF.shape[0]
    vertex_map = None
    if pV.shape[0] or lidV.shape[0]:          # a lid's vertices belong to no mesh vertex: empty rows
        rows, cols, weights = p_map
        vertex_map = sparse.csr_matrix((weights, (rows, cols)), shape=(pV.shape[0] + lidV.shape[0], n))
    split = np.concatenate([np.full(m_k, -1), np.arange(m_p), np.full(m_l, -1)]).astype(np.int64)
    return WalkSurface(verts, np.concatenate([Fk, pF, lidF]).astype(np.int64), np.concatenate([Nk, p_norm, ln]),
                       np.concatenate([mesh.face_areas[keep], p_area, 0.5 * la]),
                       np.concatenate([keep, p_face, np.full(m_l, -1)]).astype(np.int64),
                       np.concatenate([flip, np.zeros(m_p + m_l, dtype=bool)]), n, m, split=split, split_bary=pB,
                       vertex_map=vertex_map, holes=n_holes, open_loops=n_unfilled,
                       transparent=int(m - np.count_nonzero(~good) - keep.size - split_whole.size),
                       reversed=int(np.count_nonzero(flip)), split_faces=int(split_whole.size),
                       open_edges=open_edges)


def _edge_keys(F, n):
    """Sorted unique undirected edge keys min * n + max of faces ``F`` (k, 3)."""
    a, b = F.reshape(-1), np.roll(F, -1, axis=1).reshape(-1)
    return np.unique(np.minimum(a, b) * np.int64(n) + np.maximum(a, b))


def _rims(F, n, slivers):
    """:func:`rim_edges` of ``F`` less the edges of zero-area faces (``slivers``, undirected keys): a sliver
    covers no area, so the rim along it is no hole."""
    rims = rim_edges(F, n)
    if rims.shape[0] and slivers.size:
        key = np.minimum(rims[:, 0], rims[:, 1]) * np.int64(n) + np.maximum(rims[:, 0], rims[:, 1])
        rims = rims[~np.isin(key, slivers)]
    return rims


def _holes(loops, F_good, n) -> tuple[list[bool], int]:
    """Which rim loops are the mesh's holes: those with an edge that only one face of the mesh uses (a loop opened
    only by leaving out transparent faces, as along a seam, is none); and the number of such edges."""
    a, b = F_good.reshape(-1), np.roll(F_good, -1, axis=1).reshape(-1)
    keep = a != b
    keys, counts = np.unique(np.minimum(a, b)[keep] * np.int64(n) + np.maximum(a, b)[keep], return_counts=True)
    open_keys = keys[counts == 1]
    out = []
    for lp in loops:            # a loop over rims, not vertices
        a, b = lp, np.roll(lp, -1)
        out.append(bool(np.isin(np.minimum(a, b) * np.int64(n) + np.maximum(a, b), open_keys).any()))
    return out, int(open_keys.size)


def _seam_candidates(Fw, probe, side, n) -> np.ndarray:
    """Sheet representatives that share an edge with a representative of another class, and their edge
    neighbours: where a seam of overlapping parts may cross the faces (sorted)."""
    und = np.sort(np.stack([Fw, np.roll(Fw, -1, axis=1)], axis=2), axis=2)          # (m, 3, 2)
    key = und[..., 0] * np.int64(n) + und[..., 1]
    kp = key[probe]
    classes = [np.unique(kp[side[probe] == c].reshape(-1)) for c in (BOUNDARY, REVERSED, TRANSPARENT)]
    mixed = np.zeros(kp.shape[0], dtype=bool)
    for c, cls in enumerate((BOUNDARY, REVERSED, TRANSPARENT)):
        others = np.unique(np.concatenate([classes[o] for o in range(3) if o != c]))
        mine = side[probe] == cls
        mixed[mine] = np.isin(kp[mine], others).any(axis=1)
    if not mixed.any():
        return np.zeros(0, dtype=np.int64)
    near = np.isin(kp, np.unique(kp[mixed].reshape(-1))).any(axis=1)
    return probe[near | mixed]


def _parts(V, F, parent_face, bary, side, n):
    """The split faces' parts as walk faces: (new vertices (q, 3), faces (s, 3), barycentric rows (s, 3, 3) in the
    mesh face's order, mesh face (s,), (rows, mesh vertices, weights) of the new vertices' map).

    A part's corner that is its face's corner is that mesh vertex; the others are new vertices, shared where two
    parts have the same corner (the same mesh vertices and weights; an edge's points are evaluated in the order
    of the edge's vertex ids, so both faces of the edge place them bit for bit alike)."""
    s = parent_face.size
    if s == 0:
        return (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3, 3)), np.zeros(0, dtype=np.int64),
                (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)))
    bary = bary.copy()
    rev = side == REVERSED
    bary[rev] = bary[rev][:, [0, 2, 1]]
    corners = F[parent_face]                                   # (s, 3) mesh vertex ids
    b = bary.reshape(-1, 3)                                    # (3s, 3) one row per corner of a part
    vid = np.repeat(corners, 3, axis=0)                        # (3s, 3)
    ids = np.where(b > 0.0, vid, -1)
    order = np.argsort(ids, axis=1, kind="stable")
    ids_s = np.take_along_axis(ids, order, axis=1)
    b_s = np.take_along_axis(b, order, axis=1)
    corner = np.sum(b > 0.0, axis=1) == 1                      # the face's own corner
    out = np.empty(b.shape[0], dtype=np.int64)
    out[corner] = ids_s[corner, 2]
    other = np.flatnonzero(~corner)
    key = np.concatenate([ids_s[other].astype(np.float64), b_s[other]], axis=1)
    uniq, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    out[other] = n + inv
    # positions: the terms in the order of their vertex ids (exact zeros added last change nothing)
    ii, bb = ids_s[other[first]], b_s[other[first]]
    P = np.zeros((uniq.shape[0], 3))
    for j in range(3):          # three terms
        P += bb[:, j, None] * V[np.maximum(ii[:, j], 0)] * (ii[:, j, None] >= 0)
    rows = np.repeat(np.arange(uniq.shape[0]), 3)
    cols = ii.reshape(-1)
    w = bb.reshape(-1)
    ok = cols >= 0
    return P, out.reshape(s, 3), bary, parent_face.astype(np.int64), (rows[ok], cols[ok], w[ok])


def _lids(V, centre, loops, volume: SurfaceVolume, n: int):
    """Lid vertices (q, 3) and faces (t, 3) (indices from ``n`` on) of the rim ``loops``, the number of lids and
    of loops left open (no level crossing at the centre, or one on another sheet). ``volume`` is built on the
    vertices ``V - centre``; the lids' rim copies are ``V``'s own values, bit for bit."""
    if not loops:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), 0, 0
    built = [lid_rings(V[loop] - centre) for loop in loops]          # one lid per hole (a loop over holes)
    pts = np.concatenate([b[0] for b in built])
    dirs = np.concatenate([np.broadcast_to(b[2], b[0].shape) for b in built])
    reach = np.concatenate([np.full(b[0].shape[0], LID_REACH * b[3]) for b in built])
    t, found = project_to_level(volume, pts, dirs, reach)
    placed = pts + t[:, None] * dirs
    ends = np.cumsum([b[0].shape[0] for b in built])
    mid = ends - 1                                           # each lid's last point is its centre
    clear = np.abs(volume.depth(placed[mid], bound=float(np.max(reach)) + 1.0, exact=True))
    radius = np.array([b[3] for b in built])
    ok = found[mid] & (clear >= LID_CLEARANCE * radius)
    verts, faces = [], []
    count = n
    start = 0
    for i, (loop, b) in enumerate(zip(loops, built)):     # assemble (a loop over holes)
        stop = ends[i]
        if ok[i]:
            k = loop.size
            verts += [V[loop], placed[start:stop] + centre]
            faces.append(b[1] + count)
            count += k + (stop - start)
        start = stop
    if not faces:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), 0, len(loops)
    return np.concatenate(verts), np.concatenate(faces), int(ok.sum()), int((~ok).sum())
