"""Principal curvatures and directions per vertex: an adapter over libigl's quadric fit.

``igl.principal_curvature(V, F, radius, useKring)`` (Panozzo, Puppo & Rocca 2010, "Efficient multi-scale
curvature and crease estimation") fits the height function ``z = a u^2 + b uv + c v^2 + d u + e v`` over a
neighbourhood of each vertex and returns the eigen-decomposition of its shape operator. Its ``radius`` is an
**integer**: with ``useKring=False`` (used here) the neighbourhood is the vertices reachable through edges whose
Euclidean distance from the centre is below ``radius * h``, ``h`` the mean half-edge length of the mesh (at least
six vertices are taken); values below 2 are raised to 2 by libigl. This adapter takes the neighbourhood radius in
mm and converts it once: ``radius = max(2, round(radius_mm / h))``; the radius actually used,
``radius * h``, is returned in ``PrincipalCurvatures.radius_mm``.

Conventions (docs/physics.md §1.3)
--------------------------
* ``k1 >= k2`` per vertex, in 1/mm; positive where the surface bends away from its normal (convex, with outward
  normals), so a sphere of radius R has ``k1 = k2 = +1/R``. libigl already follows this sign for the winding's
  right-hand-rule normals (checked on spheres in the tests); the adapter only enforces ``k1 >= k2``.
* ``d1, d2`` are unit tangent directions re-orthogonalised against the area-weighted vertex normal ``n``, with
  ``(d1, d2, n)`` right-handed (``d2 = n x d1``). Their sign is otherwise arbitrary (a direction, not a vector).

Robustness
----------
libigl is called on the non-degenerate faces and the vertices they use only (it crashes on unreferenced
vertices and NaN-normal faces), and never where its fit plane is undefined. libigl takes the plane of a vertex's
fit from the sum of the unit vertex normals over the vertex's neighbourhood (``getProjPlane``). Two ways that
fails, found by experiment on libigl 2.6 (``tests/geometry/test_curvature_odd_meshes.py``): (1) a vertex whose
area-weighted normal is exactly zero gets a NaN normal (libigl normalises the rows without a check), and every
neighbourhood that contains it makes ``rotateForward`` recurse without end: a certain segmentation fault, exit 139
(a "bow-tie": two tetrahedra mirrored through a shared vertex; faces duplicated with the opposite winding); (2) a
neighbourhood whose normals sum to zero divides 0 by 0 and reads an uninitialised index (``chooseMax``): garbage,
or a crash, depending on what the stack holds (a small closed symmetric component, e.g. an octahedron or a cube
smaller than the fit radius, or a thin symmetric rod). ``_fit_plane_undefined`` repeats libigl's neighbourhood
search exactly (``getSphere``: vertices reachable through vertices closer than ``radius`` mean edge lengths,
topped up to six by the nearest further ones) and flags every vertex whose normal, or whose neighbourhood's sum of
normals, cancels to ``PLANE_CANCEL_TOL`` (a tolerance, so that rounding differences from libigl's own sums cannot
matter); the faces around flagged vertices are left out of libigl's input (repeated until nothing is flagged) and
those vertices take the fallback below, counted in ``n_no_plane``. Unreferenced vertices and degenerate faces are
removed beforehand (see above); isolated triangles and components of fewer than six vertices are reported bad by
libigl before it looks for a plane; these take the fallback as well.
A vertex where it fails gets the median ``k1``, ``k2`` of its valid neighbours
(up to ``FALLBACK_RINGS`` rings out) and a neighbour's first direction projected onto its tangent plane; a vertex
with no valid vertex within those rings gets the umbilic value ``k1 = k2 = H`` of the cotangent Laplacian.
Failure means: reported bad by libigl, non-finite, in a component too small to fit a quadric, or an outlier with
``max(|k1|, |k2|) * h_local > OUTLIER_KH`` (``h_local`` the mean incident edge length), which comes from an
ill-conditioned fit, e.g. across a fin thinner than the neighbourhood, and which the vertices could not represent
anyway. Unreferenced vertices get ``k1 = k2 = 0`` and an arbitrary frame. The counts are in the result, and a
``MeshDefectWarning`` is emitted when any fallback was needed (about 0.5 % of the vertices of the Lee Perry-Smith
head scan and 0.1 % of blub, none on the other seven test meshes).

Accuracy (measured with the default radius of 2 mean edge lengths; checked in tests/test_geometry_curvature.py)
--------------------------------------------------------------------------------------------------------------
* icosphere R = 10 mm: max relative error of k1, k2 is 2.1 % at 3 subdivisions (mean edge h = 1.5 mm), 0.50 % at
  4, 0.13 % at 5, 0.03 % at 6: second order in h (fitted order 2.0); the bias is positive (the quadric fit sees
  the sphere's quartic term), about ``(radius / R)^2``.
* capped cylinder R = 5 mm, 64 segments, away from the caps: k1 within 1.0 % of 1/R, |k2| < 0.0021/R, d2
  parallel to the axis to rounding error (0.25 % and 0.0005/R with 128 segments).
* torus R = 20, r = 5 mm, 192 x 64: k1 = 1/r within 1.0 %; k2 = 1/(R + r) within 0.5 % on the outer equator
  and -1/(R - r) within 0.4 % on the inner one (4x smaller at 384 x 128).
* quadric surfaces (the saddle ``z = k (x^2 - y^2) / 2``) are reproduced to rounding error.
Errors grow roughly as ``(radius / R_curvature)^2`` with a wider neighbourhood; near creases and thin features
(shorter than the neighbourhood) the values are smoothed estimates, not pointwise curvatures.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import sparse

from meshshade.geometry.mesh import MeshDefectWarning, face_geometry
from meshshade.geometry.topology import vertex_adjacency

__all__ = ["PrincipalCurvatures", "principal_curvatures", "DEFAULT_RADIUS_EDGES", "FALLBACK_RINGS", "OUTLIER_KH",
           "PLANE_CANCEL_TOL"]

#: default neighbourhood radius, in mean edge lengths (libigl's minimum; the most accurate on smooth meshes)
DEFAULT_RADIUS_EDGES = 2.0
#: how many rings out a failed vertex looks for valid neighbours
FALLBACK_RINGS = 3
#: |k| * (mean incident edge length) above this is treated as a failed fit (a circle through vertices spaced h
#: apart has |k| <= 2 / h, so 4 / h is beyond anything the mesh can represent)
OUTLIER_KH = 4.0
#: a vertex's fit plane is undefined (libigl would crash) when its area-weighted normal, or the sum of the unit
#: normals over its fit neighbourhood, is no longer than this fraction of what cancelled (see Robustness)
PLANE_CANCEL_TOL = 1e-9
#: rounds of leaving faces out of libigl's input before giving up on the fit altogether (each round removes faces)
MAX_EXCLUSION_ROUNDS = 32
#: libigl's minimum neighbourhood size (``getSphere(..., min=6)``; fewer vertices: reported bad, no plane)
_LIBIGL_MIN_NEIGHBOURS = 6


@dataclass(frozen=True, eq=False)
class PrincipalCurvatures:
    """Per-vertex principal curvatures; unpacks as ``k1, k2, d1, d2 = principal_curvatures(V, F)``.

    Attributes
    ----------
    k1, k2 : (n,) float64, 1/mm (inverse units of the input vertices), k1 >= k2, convex positive
    d1, d2 : (n, 3) float64, unit principal directions, ``(d1, d2, normal)`` right-handed
    normals : (n, 3) float64, the area-weighted unit vertex normals used for the frames (0 if unreferenced)
    radius_mm : float, neighbourhood radius actually used (an integer multiple of the mean half-edge length)
    fallback : (n,) bool, vertices whose values were filled in because libigl failed there (or was not asked)
    n_unreferenced : int, vertices used by no non-degenerate face (k = 0, arbitrary frame)
    n_no_plane : int, fallback vertices left out of libigl's fit because the normals cancel there (bow-tie
        vertices, double-sided faces, small symmetric components; see the module docstring)
    """

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normals: np.ndarray
    radius_mm: float
    fallback: np.ndarray
    n_unreferenced: int = 0
    n_no_plane: int = 0

    def __iter__(self):
        return iter((self.k1, self.k2, self.d1, self.d2))

    @property
    def n_fallback(self) -> int:
        return int(self.fallback.sum())

    @property
    def mean(self) -> np.ndarray:
        """(n,) mean curvature (k1 + k2) / 2."""
        return 0.5 * (self.k1 + self.k2)

    @property
    def gaussian(self) -> np.ndarray:
        """(n,) Gaussian curvature k1 k2."""
        return self.k1 * self.k2

    def __repr__(self) -> str:
        return (f"PrincipalCurvatures({self.k1.size} vertices, radius_mm={self.radius_mm:.4g}, "
                f"k1 in [{self.k1.min():.4g}, {self.k1.max():.4g}], k2 in [{self.k2.min():.4g}, "
                f"{self.k2.max():.4g}], {self.n_fallback} fallback ({self.n_no_plane} without a fit plane), "
                f"{self.n_unreferenced} unreferenced)")


def _any_tangent(n: np.ndarray) -> np.ndarray:
    """(k, 3) unit vectors orthogonal to the unit rows of ``n`` (deterministic; any vector where n = 0)."""
    axis = np.zeros_like(n)
    axis[np.arange(n.shape[0]), np.argmin(np.abs(n), axis=1)] = 1.0
    t = axis - np.einsum("ij,ij->i", axis, n)[:, None] * n
    return t / np.linalg.norm(t, axis=1, keepdims=True)


def _tangent_frames(d1, d2, normals):
    """Re-orthogonalise ``d1`` against ``normals`` (using ``d2`` where d1 vanished) and set d2 = n x d1."""
    n = normals
    t = d1 - np.einsum("ij,ij->i", d1, n)[:, None] * n
    norm = np.linalg.norm(t, axis=1)
    weak = ~(norm > 1e-6)
    if weak.any():  # libigl returns a zero direction where its curvature is exactly 0: rebuild from d2
        alt = np.cross(d2[weak], n[weak])
        t[weak], norm[weak] = alt, np.linalg.norm(alt, axis=1)
    weak = ~(norm > 1e-6)
    t = t / np.where(weak, 1.0, norm)[:, None]
    if weak.any():
        t[weak] = _any_tangent(n[weak])
    return t, np.cross(n, t)


def _cotan_mean_curvature(V, F, normals):
    """Umbilic fallback: H = -(Delta x . n) / 2 with the cotangent Laplacian and barycentric areas."""
    import igl  # lazy: libigl takes ~0.5 s to import; only the curvature fit needs it

    L = igl.cotmatrix(V, F)
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_BARYCENTRIC)
    area = np.asarray(M.diagonal()).reshape(-1)
    lap = np.asarray(L @ V)
    with np.errstate(divide="ignore", invalid="ignore"):
        H = -0.5 * np.einsum("ij,ij->i", lap, normals) / area
    return np.where(np.isfinite(H), H, 0.0)


@njit(cache=True)
def _heap_push(hd, hv, size, d, v):
    """libstdc++'s ``push_heap`` on (hd, hv)[:size] with libigl's comparer (a min-heap on distance)."""
    hole = size
    parent = (hole - 1) // 2
    while hole > 0 and hd[parent] > d:
        hd[hole], hv[hole] = hd[parent], hv[parent]
        hole = parent
        parent = (hole - 1) // 2
    hd[hole], hv[hole] = d, v
    return size + 1


@njit(cache=True)
def _heap_pop(hd, hv, size):
    """libstdc++'s ``pop_heap`` (``__adjust_heap``, then ``__push_heap``): the top (nearest) pair is removed."""
    last = size - 1
    d, v = hd[last], hv[last]
    n = last                      # the heap's new length
    hole = 0
    child = 0
    while child < (n - 1) // 2:
        child = 2 * (child + 1)
        if hd[child] > hd[child - 1]:   # comp(first[child], first[child - 1])
            child -= 1
        hd[hole], hv[hole] = hd[child], hv[child]
        hole = child
    if (n & 1) == 0 and child == (n - 2) // 2 and n > 0:
        child = 2 * (child + 1)
        hd[hole], hv[hole] = hd[child - 1], hv[child - 1]
        hole = child - 1
    parent = (hole - 1) // 2
    while hole > 0 and hd[parent] > d:
        hd[hole], hv[hole] = hd[parent], hv[parent]
        hole = parent
        parent = (hole - 1) // 2
    if n > 0:
        hd[hole], hv[hole] = d, v
    return n


@njit(cache=True)
def _fit_plane_undefined(V, F, indptr, indices, normals, radius, tol):
    """(n,) bool: vertices where libigl's fit plane is undefined (the sum of unit normals over the neighbourhood
    cancels to ``tol`` times its size), for libigl's input ``V``, ``F`` (vertices used by no face: False).

    Repeats ``CurvatureCalculator::getSphere`` (libigl 2.6): breadth-first from the vertex through neighbours
    (``indptr``/``indices``: sorted unique neighbours, as ``igl::adjacency_list``) closer than
    ``radius * mean half-edge length`` (the mean over the face corners, in face order); while fewer than six
    vertices were taken, farther neighbours are remembered and then taken nearest first (the same binary heap,
    so ties break alike). Then the sum of ``normals`` over them in that order, as ``getProjPlane``.
    """
    n = V.shape[0]
    m = F.shape[0]
    total = 0.0
    for f in range(m):
        for j in range(3):
            a, b = F[f, j], F[f, (j + 1) % 3]
            dx, dy, dz = V[a, 0] - V[b, 0], V[a, 1] - V[b, 1], V[a, 2] - V[b, 2]
            total += np.sqrt(dx * dx + dy * dy + dz * dz)
    r = total / (3 * m) * radius if m > 0 else 0.0
    out = np.zeros(n, dtype=np.bool_)
    stamp = np.full(n, -1, dtype=np.int64)
    vv = np.empty(n, dtype=np.int64)
    hd = np.empty(n, dtype=np.float64)
    hv = np.empty(n, dtype=np.int64)
    for i in range(n):
        if indptr[i + 1] == indptr[i]:
            continue
        x, y, z = V[i, 0], V[i, 1], V[i, 2]
        head = 0
        tail = 1
        vv[0] = i
        stamp[i] = i
        hs = np.int64(0)   # not the literal 0: numba would compile _heap_push/_heap_pop for Literal[int](0) too
        while head < tail:           # the queue is vv itself: popped in order, appended in order
            t = vv[head]
            head += 1
            for k in range(indptr[t], indptr[t + 1]):
                nb = indices[k]
                if stamp[nb] != i:
                    dx, dy, dz = x - V[nb, 0], y - V[nb, 1], z - V[nb, 2]
                    d = np.sqrt(dx * dx + dy * dy + dz * dz)
                    if d < r:
                        vv[tail] = nb
                        tail += 1
                    elif head < _LIBIGL_MIN_NEIGHBOURS:
                        hs = _heap_push(hd, hv, hs, d, nb)
                    stamp[nb] = i
        while hs > 0 and tail < _LIBIGL_MIN_NEIGHBOURS:
            c = hv[0]
            hs = _heap_pop(hd, hv, hs)
            vv[tail] = c
            tail += 1
            for k in range(indptr[c], indptr[c + 1]):
                nb = indices[k]
                if stamp[nb] != i:
                    dx, dy, dz = x - V[nb, 0], y - V[nb, 1], z - V[nb, 2]
                    hs = _heap_push(hd, hv, hs, np.sqrt(dx * dx + dy * dy + dz * dz), nb)
                    stamp[nb] = i
        if tail < _LIBIGL_MIN_NEIGHBOURS:
            continue                 # libigl reports the vertex bad before it looks for a plane
        sa = sb = sc = 0.0
        for q in range(tail):
            j = vv[q]
            sa += normals[j, 0]
            sb += normals[j, 1]
            sc += normals[j, 2]
        size = sa * sa + sb * sb + sc * sc
        if not (np.isfinite(size) and size > (tol * tail) ** 2):
            out[i] = True
    return out


def _area_weighted_normals(V, F, n, cross=None):
    """(n, 3) unit area-weighted vertex normals of faces F (as libigl's ``per_vertex_normals``), and (n,) bool where
    the incident faces' normals cancel (zero, or below ``PLANE_CANCEL_TOL`` of their summed lengths; True where no
    face is incident). ``cross``: the faces' ``(v1 - v0) x (v2 - v0)`` if already known."""
    if cross is None:
        cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    idx = F.reshape(-1)
    rep = np.repeat(cross, 3, axis=0)
    acc = np.stack([np.bincount(idx, weights=rep[:, j], minlength=n) for j in range(3)], 1)
    mag = np.bincount(idx, weights=np.repeat(np.linalg.norm(cross, axis=1), 3), minlength=n)
    nn = np.linalg.norm(acc, axis=1)
    cancel = ~(nn > PLANE_CANCEL_TOL * mag)
    unit = np.divide(acc, nn[:, None], out=np.zeros_like(acc), where=~cancel[:, None])
    return unit, cancel


def _faces_for_libigl(V, F, r_int: int, cross, adjacency):
    """The faces of (V, F) that libigl can fit safely: F without the faces around vertices whose fit plane is
    undefined (their normals cancel, ``_fit_plane_undefined``), repeated until no vertex is flagged (leaving faces
    out changes the neighbourhoods and the mean edge length). ``cross`` and ``adjacency`` (``vertex_adjacency``)
    are those of F. Returns (faces, no_plane (n,) bool); the faces are F itself when nothing was flagged."""
    n = V.shape[0]
    no_plane = np.zeros(n, bool)
    Fl = F
    for _ in range(MAX_EXCLUSION_ROUNDS):
        if Fl.shape[0] == 0:
            return Fl, no_plane
        first = Fl is F
        unit, cancel = _area_weighted_normals(V, Fl, n, cross if first else None)
        referenced = np.zeros(n, bool)
        referenced[Fl.reshape(-1)] = True
        bad = cancel & referenced
        if not bad.any():
            indptr, indices = adjacency if first else vertex_adjacency(n, Fl)
            bad = _fit_plane_undefined(V, Fl, indptr, indices, unit, float(r_int), PLANE_CANCEL_TOL)
            if not bad.any():
                return Fl, no_plane
        no_plane |= bad
        Fl = Fl[~bad[Fl].any(axis=1)]
    # pathological: still flagged after MAX_EXCLUSION_ROUNDS rounds; no fit at all (every vertex falls back)
    no_plane[F.reshape(-1)] = True
    return F[:0], no_plane


def principal_curvatures(vertices, faces, *, radius_mm: float | None = None) -> PrincipalCurvatures:
    """Principal curvatures ``k1 >= k2`` (1/mm) and unit tangent directions at every vertex.

    Parameters
    ----------
    vertices : (n, 3) float64, mm (any unit works: curvatures come out in its inverse)
    faces : (m, 3) int64, outward-oriented (e.g. ``Mesh.faces``); degenerate faces are ignored
    radius_mm : float, optional
        Neighbourhood radius of the quadric fit, in mm; default ``DEFAULT_RADIUS_EDGES`` mean edge lengths.
        Rounded to a whole number (>= 2) of mean half-edge lengths (see the module docstring).

    Returns
    -------
    PrincipalCurvatures (unpacks to ``k1, k2, d1, d2``). All values are finite.
    """
    import igl  # lazy: libigl takes ~0.5 s to import; only the curvature fit needs it

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    n = V.shape[0]
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"expected (n, 3) vertices and (m, 3) faces, got {V.shape} and {F.shape}")
    cross, degenerate = face_geometry(V, F)
    keep = ~degenerate
    Fg, cross = F[keep], cross[keep]
    used = np.flatnonzero(np.bincount(Fg.reshape(-1), minlength=n))  # (np.unique: 30x slower on numpy 2.4)
    if used.size == 0:
        raise ValueError("no non-degenerate faces")
    remap = np.full(n, -1, np.int64)
    remap[used] = np.arange(used.size)
    Vc, Fc = V[used], np.ascontiguousarray(remap[Fg])

    # area-weighted vertex normals
    rep = np.repeat(cross, 3, axis=0)
    acc = np.stack([np.bincount(Fc.reshape(-1), weights=rep[:, j], minlength=used.size) for j in range(3)], 1)
    nn = np.linalg.norm(acc, axis=1, keepdims=True)
    normals = np.divide(acc, nn, out=np.zeros_like(acc), where=nn > 0)

    # neighbourhood radius: libigl's unit is the mean half-edge length of the mesh it is given
    h = float(np.linalg.norm(Vc[Fc] - Vc[np.roll(Fc, -1, axis=1)], axis=2).mean())
    if radius_mm is None:
        radius_mm = DEFAULT_RADIUS_EDGES * h
    if not (np.isfinite(radius_mm) and radius_mm > 0):
        raise ValueError(f"radius_mm must be positive, got {radius_mm!r}")
    r_int = max(2, int(round(radius_mm / h)))

    # libigl only where its fit plane is defined (it would crash elsewhere; see Robustness); NaN = not fitted
    adjacency = vertex_adjacency(used.size, Fc)
    Fl, _ = _faces_for_libigl(Vc, Fc, r_int, cross, adjacency)
    in_fit = np.zeros(used.size, bool)
    in_fit[Fl.reshape(-1)] = True
    k1, k2 = np.full(used.size, np.nan), np.full(used.size, np.nan)
    d1, d2 = np.full((used.size, 3), np.nan), np.full((used.size, 3), np.nan)
    bad = np.zeros(0, np.int64)
    if Fl.shape[0]:
        fit = np.flatnonzero(in_fit)
        local = np.full(used.size, -1, np.int64)
        local[fit] = np.arange(fit.size)
        whole = fit.size == used.size and Fl is Fc  # the usual case: libigl gets the whole mesh
        Vf = Vc if whole else np.ascontiguousarray(Vc[fit])
        Ff = Fc if whole else np.ascontiguousarray(local[Fl])
        e1, e2, c1, c2, bad = igl.principal_curvature(Vf, Ff, r_int, False)
        d1[fit], d2[fit] = np.asarray(e1, np.float64), np.asarray(e2, np.float64)
        k1[fit], k2[fit] = np.asarray(c1, np.float64).reshape(-1), np.asarray(c2, np.float64).reshape(-1)
        bad = fit[np.asarray(bad, dtype=np.int64)]
    failed = ~(np.isfinite(k1) & np.isfinite(k2) & np.isfinite(d1).all(axis=1) & np.isfinite(d2).all(axis=1))
    failed[bad] = True
    failed |= ~(nn[:, 0] > 0)
    # a curvature radius far below the local edge length cannot come from the vertex positions: fit failure
    a, b = Fc.reshape(-1), np.roll(Fc, -1, axis=1).reshape(-1)
    length = np.linalg.norm(Vc[a] - Vc[b], axis=1)
    h_local = (np.bincount(a, length, used.size) + np.bincount(b, length, used.size)) / np.maximum(
        np.bincount(a, minlength=used.size) + np.bincount(b, minlength=used.size), 1)
    with np.errstate(invalid="ignore"):
        failed |= np.maximum(np.abs(k1), np.abs(k2)) * h_local > OUTLIER_KH
    k1, k2 = np.where(failed, 0.0, k1), np.where(failed, 0.0, k2)
    d1[failed], d2[failed] = 0.0, 0.0

    if failed.any():
        k1, k2, d1, unresolved = _fill_from_neighbours(adjacency, k1, k2, d1, failed)
        if unresolved.any():
            H = _cotan_mean_curvature(Vc, Fc, normals)
            k1[unresolved] = k2[unresolved] = H[unresolved]
            d1[unresolved] = 0.0
        d2[failed] = 0.0
    # a normal is needed for every frame: fall back to libigl's plane where the area-weighted one vanished
    no_normal = ~(nn[:, 0] > 0)
    if no_normal.any():
        alt = np.cross(d1[no_normal], d2[no_normal])
        an = np.linalg.norm(alt, axis=1, keepdims=True)
        normals[no_normal] = np.divide(alt, an, out=np.zeros_like(alt), where=an > 0)
    swap = k1 < k2
    k1, k2 = np.where(swap, k2, k1), np.where(swap, k1, k2)
    d1[swap], d2[swap] = d2[swap].copy(), d1[swap].copy()
    t1, t2 = _tangent_frames(d1, d2, normals)

    out = {name: np.zeros((n, 3)) for name in ("d1", "d2", "normals")}
    K1, K2 = np.zeros(n), np.zeros(n)
    K1[used], K2[used] = k1 + 0.0, k2 + 0.0  # + 0.0 turns libigl's -0.0 on flat regions into 0.0
    out["d1"][used], out["d2"][used], out["normals"][used] = t1, t2, normals
    unref = np.setdiff1d(np.arange(n), used)
    if unref.size:
        out["d1"][unref] = np.eye(3)[0]
        out["d2"][unref] = np.eye(3)[1]
    fallback = np.zeros(n, bool)
    fallback[used] = failed
    n_no_plane = int(used.size - in_fit.sum())
    if failed.any():
        n_libigl = int(failed.sum()) - n_no_plane
        parts = ([f"libigl failed at {n_libigl} vertices (no fit, or |k| above {OUTLIER_KH:g} / local edge "
                  "length)"] if n_libigl else [])
        if n_no_plane:
            parts.append(f"{n_no_plane} vertices have no tangent plane (the surface normals cancel within the fit "
                         "neighbourhood: a non-manifold 'bow-tie' vertex, faces duplicated with opposite winding or "
                         "a small symmetric component) and were left out of libigl's fit")
        warnings.warn(f"principal_curvatures: {'; '.join(parts)}; filled from neighbours' median (or the "
                      "cotangent mean curvature where no neighbour was fitted)", MeshDefectWarning, stacklevel=2)
    for a in (K1, K2, *out.values(), fallback):
        a.setflags(write=False)
    return PrincipalCurvatures(k1=K1, k2=K2, d1=out["d1"], d2=out["d2"], normals=out["normals"],
                               radius_mm=float(r_int * h), fallback=fallback, n_unreferenced=int(unref.size),
                               n_no_plane=n_no_plane)


def _fill_from_neighbours(adjacency, k1, k2, d1, failed):
    """Median k1, k2 (and the first valid neighbour's d1) of valid vertices within FALLBACK_RINGS rings
    (``adjacency``: ``vertex_adjacency`` of the fitted mesh)."""
    nv = k1.size
    indptr, indices = adjacency
    adj = sparse.csr_matrix((np.ones(indices.size, bool), indices, indptr), shape=(nv, nv))
    valid = ~failed
    todo = np.flatnonzero(failed)
    reach = sparse.csr_matrix((np.ones(todo.size, bool), (np.arange(todo.size), todo)), shape=(todo.size, nv))
    pending = np.ones(todo.size, bool)
    for _ in range(FALLBACK_RINGS):
        reach = (reach + reach @ adj).astype(bool).tocsr()
        for row in np.flatnonzero(pending):
            nb = reach.indices[reach.indptr[row]:reach.indptr[row + 1]]
            nb = nb[valid[nb]]
            if nb.size:
                v = todo[row]
                k1[v], k2[v] = np.median(k1[nb]), np.median(k2[nb])
                d1[v] = d1[nb.min()]
                pending[row] = False
        if not pending.any():
            break
    todo = todo[pending]
    unresolved = np.zeros(nv, bool)
    unresolved[todo] = True
    return k1, k2, d1, unresolved
