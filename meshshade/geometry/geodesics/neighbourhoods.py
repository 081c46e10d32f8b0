"""Geodesic neighbourhoods: every mesh vertex within a cutoff geodesic distance of each entry sample.

For each entry sample x_i (a vertex, or a point inside a face given by barycentric weights) the transport needs
every vertex x_o with geodesic distance rho(x_i, x_o) <= cutoff, the distance itself, the chord |x_o - x_i| and
the azimuth phi of x_o in x_i's tangent frame (docs/physics.md §1.3).  :class:`GeodesicNeighbourhoods` holds the mesh
set-up (half-edge frames, adjacency); :meth:`GeodesicNeighbourhoods.query` returns a CSR :class:`Neighbourhoods`.

Method (``method="window"``, the default): exact polyhedral geodesics
    A bounded single-source propagation per sample on the mesh's own connectivity (two surfaces that touch in
    space but are far apart along the surface never see each other): the continuous-Dijkstra window propagation
    of Mitchell, Mount & Papadimitriou (1987) with the ordering and pruning of Xin & Wang (2009, "ICH"), plus
    pseudo-sources at saddle and boundary vertices.  It stops at the cutoff, so the work per sample is
    proportional to its neighbourhood, never to the mesh (no O(N^2)).  Agreement with ``igl.exact_geodesic``
    (MMP) is ~1e-15 relative on a torus, spot, bunny and hand, 2e-14 on the sliver-rich Lee Perry-Smith head;
    every distance is the length of an actual path, so none undershoots the exact polyhedral distance.
    Against the *smooth* surface the mesh stands for, the polyhedral distance of an inscribed mesh undershoots
    by O(h^2): on a 10 mm sphere -0.26 / -0.07 / -0.018 / -0.0045 % (max) at edges of 1.5 / 0.75 / 0.38 / 0.19 mm
    (fitted order 1.96); on a 5 mm cylinder with 0.47 mm edges -0.018 %.
    Saddle vertices emit pseudo-source windows only into the sector where a path through them can be shortest
    (MMP's rule).  Cost: 10-25 windows per vertex (14 on a sphere, 25 on the sliver-rich head), ~0.15 us each,
    i.e. about 2-4 us per (source, neighbour) pair on one core (``tools/benchmarks/bench_neighbourhood.py``).
Faster, less accurate (``method="fmm"``, ``"dijkstra"``)
    ``"fmm"``: first-order fast marching (Kimmel & Sethian 1998) with the point-source triangle update of
    Novotni & Klein (2002) and re-opening, on the same bucket queue; exact on flat meshes without obtuse
    triangles (0.5 % max on a random Delaunay plate), about 4x cheaper than "window"; max error 0.1-0.7 % on
    icospheres, the torus and spot, 1-2 % on bunny and hand, 5 % on the head (obtuse triangles).  ``"dijkstra"``
    (edge paths) overestimates by 16-60 % (max; 8-15 % mean) and is kept as the baseline.

Azimuth
    phi is the angle, from the sample's first principal direction d1, of the projection of x_o - x_i onto the
    sample's tangent plane.  The projection deviates from the geodesic's true initial direction by
    ``(rho^2 / 6) k_n (k1 - k2) sin(phi) cos(phi)`` (from the Darboux frame; zero on spheres and along principal
    directions, 0.01 rad at rho = 0.4 R on a cylinder); passing ``k1, k2`` removes that leading term
    (:func:`tangent_azimuth`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshshade.geometry.geodesics import _graph_loops as _g
from meshshade.geometry.geodesics import _window_loops as _k
from meshshade.geometry.geodesics._saddle_loops import _build_fans
from meshshade.geometry.mesh import face_geometry, face_normals
from meshshade.geometry.topology import vertex_adjacency
from meshshade.pacing import Pacer, default_threads, pace_rate, run_paced

__all__ = ["GeodesicNeighbourhoods", "Neighbourhoods", "geodesic_neighbourhoods", "geodesic_distances_from",
           "tangent_azimuth", "METHODS"]

METHODS = ("window", "fmm", "dijkstra")
#: barycentric weights are kept at least this far inside their face (a source on an edge lights both faces)
_BARY_FLOOR = 1e-9
#: seconds per unit of work (one expected pair, :func:`expected_work`) assumed before any kernel call of a query
#: has been timed (:class:`meshshade.pacing.Pacer`'s ``prior``): the slowest measured, exact windows over a whole
#: pebble of 10k vertices or half an icosphere of 41k (30-40 us per pair; 1-13 us is typical over a few hundred
#: vertices)
PRIOR_SECONDS_PER_PAIR = 4e-5
#: work of one source beyond its expected pairs (seeding, the queue), in pairs
SOURCE_OVERHEAD_PAIRS = 16.0
#: pairs per slice of :func:`assemble_neighbourhoods` (each numpy call on a slice takes a few tens of ms)
ASSEMBLE_PAIRS = 1 << 19


# ---------------------------------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False, repr=False)
class Neighbourhoods:
    """Vertices within the cutoff of each source, as CSR rows (row i = source i).

    Attributes
    ----------
    indptr : (k + 1,) int64
        Row i is ``slice(indptr[i], indptr[i + 1])`` of the pair arrays.
    vertex : (nnz,) int32
        Vertex index of each pair, in the order the propagation reached them (nearest first is not guaranteed).
    distance : (nnz,) float64, mm
        Geodesic distance from the source, ``0 <= distance <= cutoff`` of the row.
    chord : (nnz,) float64, mm or None
        Straight-line distance ``|x_o - x_i|`` (Jensen's dipole argument, docs/physics.md §4.3).
    tangent : (nnz, 3) float64 or None
        Unit projection of ``x_o - x_i`` onto the source's tangent plane (zero for x_o = x_i).
    phi : (nnz,) float64, radians in (-pi, pi] or None
        Azimuth of the pair in the source frame (only when the query was given ``d1, d2``).
    cutoff : (k,) float64, mm
    method : str
    """

    indptr: np.ndarray
    vertex: np.ndarray
    distance: np.ndarray
    chord: np.ndarray | None
    tangent: np.ndarray | None
    phi: np.ndarray | None
    cutoff: np.ndarray
    method: str

    @property
    def n_sources(self) -> int:
        return int(self.indptr.shape[0] - 1)

    @property
    def n_pairs(self) -> int:
        return int(self.indptr[-1])

    @property
    def counts(self) -> np.ndarray:
        """(k,) int64: neighbours per source."""
        return np.diff(self.indptr)

    def source_index(self) -> np.ndarray:
        """(nnz,) int64: the source (row) of each pair."""
        return np.repeat(np.arange(self.n_sources), self.counts)

    def row(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(vertex, distance)`` of source ``i``."""
        s = slice(self.indptr[i], self.indptr[i + 1])
        return self.vertex[s], self.distance[s]

    @classmethod
    def from_counts(cls, counts, vertex, distance, cutoff, method: str) -> "Neighbourhoods":
        """Rows of ``counts`` (k,) pairs each over the flat ``vertex`` and ``distance`` arrays, without chord,
        tangent or phi (:func:`assemble_neighbourhoods` adds them)."""
        indptr = np.r_[0, np.cumsum(counts)].astype(np.int64)
        return cls(indptr, vertex, distance, None, None, None, cutoff, method)

    def __repr__(self) -> str:
        c = self.counts
        mean = float(c.mean()) if c.size else 0.0
        extra = [n for n in ("chord", "tangent", "phi") if getattr(self, n) is not None]
        return (f"Neighbourhoods({self.n_sources} sources, {self.n_pairs} pairs, {mean:.1f} per source, "
                f"method={self.method!r}, with {', '.join(extra) or 'distances only'})")


# ---------------------------------------------------------------------------------------------------------------
# set-up
# ---------------------------------------------------------------------------------------------------------------

def _readonly(a):
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _build_topology(V: np.ndarray, F: np.ndarray) -> dict:
    """Half-edge frames, twins, one-rings and edge CSR of the non-degenerate faces (vectorised numpy)."""
    n, m = V.shape[0], F.shape[0]
    tail = F.reshape(-1)
    head = np.roll(F, -1, axis=1).reshape(-1)
    opp = np.roll(F, -2, axis=1).reshape(-1)
    e_ab = V[head] - V[tail]
    e_ao = V[opp] - V[tail]
    L = np.linalg.norm(e_ab, axis=1)
    good_face = ~face_geometry(V, F)[1]  # degenerate faces (mesh.DEGENERATE_REL_TOL) are left out
    good = np.repeat(good_face, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        ox = np.where(good, np.einsum("ij,ij->i", e_ao, e_ab) / np.where(good, L, 1.0), 0.0)
        # height from the cross product (no cancellation for slivers)
        oy = np.where(good, np.linalg.norm(np.cross(e_ab, e_ao), axis=1) / np.where(good, L, 1.0), 0.0)
    # twins: undirected edges shared by exactly two good faces
    lo, hi = np.minimum(tail, head), np.maximum(tail, head)
    key = lo * np.int64(n) + hi
    idx = np.flatnonzero(good)
    order = idx[np.argsort(key[idx], kind="stable")]
    sk = key[order]
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    sizes = np.diff(np.r_[starts, sk.size])
    twin = np.full(3 * m, -1, np.int64)
    pair = starts[sizes == 2]
    h1, h2 = order[pair], order[pair + 1]
    twin[h1], twin[h2] = h2, h1
    reversed_twin = np.zeros(3 * m, bool)
    reversed_twin[h1] = tail[h1] == head[h2]
    reversed_twin[h2] = reversed_twin[h1]
    tox = np.where(reversed_twin, L, 0.0)
    tsx = np.where(reversed_twin, -1.0, 1.0)
    # open boundary or non-manifold edges: their vertices become pseudo-source emitters
    open_he = good & (twin < 0)
    # angle at the opposite corner of each half-edge (the corner's share of its cone angle)
    ox_b, oy_b = ox - L, oy
    angle = np.arctan2(np.abs(ox * oy_b - oy * ox_b), ox * ox_b + oy * oy_b)
    angle_sum = np.bincount(opp[good], weights=angle[good], minlength=n)
    open_vertex = np.zeros(n, bool)  # on an open or non-manifold edge: always a pseudo-source
    open_vertex[tail[open_he]] = True
    open_vertex[head[open_he]] = True
    # one-ring: half-edges opposite each vertex
    v_he = idx[np.argsort(opp[idx], kind="stable")]
    v_ptr = np.r_[0, np.cumsum(np.bincount(opp[idx], minlength=n))].astype(np.int64)
    # undirected edge CSR (both directions) of the good faces. Each row lists the higher-index neighbours first
    # (both halves ascending): the graph searches break ties in this order, so it fixes the bits of their results
    e_ptr, dst = vertex_adjacency(n, F[good_face])
    src = np.repeat(np.arange(n), np.diff(e_ptr))
    dst = dst[np.argsort(2 * src + (dst < src), kind="stable")]
    e_len = np.linalg.norm(V[dst] - V[src], axis=1)
    out = dict(he_tail=tail, he_head=head, he_opp=opp, he_twin=twin, he_tox=tox, he_tsx=tsx, he_len=L,
               he_ox=ox, he_oy=oy, v_ptr=v_ptr, v_he=v_he.astype(np.int64), angle_excess=angle_sum - 2.0 * np.pi,
               open_vertex=open_vertex,
               he_corner=np.where(good, angle, 0.0), v_theta=angle_sum,
               e_ptr=e_ptr, e_nbr=dst, e_len=e_len, good_face=good_face,
               n_boundary_edges=int(np.count_nonzero(sizes == 1)),
               n_nonmanifold_edges=int(np.count_nonzero(sizes > 2)),
               mean_edge=float(e_len.mean()) if e_len.size else 0.0,
               max_edge=float(e_len.max()) if e_len.size else 0.0)
    return {k: (_readonly(v) if isinstance(v, np.ndarray) else v) for k, v in out.items()}


def _morton_order(P: np.ndarray) -> np.ndarray:
    """Permutation sorting points along a 3-D Morton (Z-order) curve, 21 bits per axis (memory locality)."""
    if P.shape[0] == 0:
        return np.zeros(0, np.int64)
    lo = P.min(axis=0)
    span = float(np.max(P.max(axis=0) - lo)) or 1.0
    q = np.clip(((P - lo) / span * (2**21 - 1)).astype(np.int64), 0, 2**21 - 1)

    def spread(x):
        x = x & 0x1FFFFF
        x = (x | (x << 32)) & 0x1F00000000FFFF
        x = (x | (x << 16)) & 0x1F0000FF0000FF
        x = (x | (x << 8)) & 0x100F00F00F00F00F
        x = (x | (x << 4)) & 0x10C30C30C30C30C3
        return (x | (x << 2)) & 0x1249249249249249

    code = spread(q[:, 0]) | (spread(q[:, 1]) << 1) | (spread(q[:, 2]) << 2)
    return np.argsort(code, kind="stable")


# ---------------------------------------------------------------------------------------------------------------
# cost model of a query (for the pacing of its kernel calls, meshshade.pacing)
# ---------------------------------------------------------------------------------------------------------------

def expected_work(cutoff_mm, n_vertices: int, area_per_vertex: float) -> np.ndarray:
    """(k,) work estimate of each source, in pairs: the vertices expected within its cutoff (the disc's area over
    the mean area per vertex, at most all vertices) plus a constant per source."""
    cut = np.asarray(cutoff_mm, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        pairs = np.minimum(np.pi * cut * cut / max(area_per_vertex, 1e-300), float(n_vertices))
    return np.where(np.isnan(pairs), float(n_vertices), pairs) + SOURCE_OVERHEAD_PAIRS


# ---------------------------------------------------------------------------------------------------------------
# solver
# ---------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False, repr=False)
class GeodesicNeighbourhoods:
    """Reusable geodesic-neighbourhood solver for one mesh (lengths in mm).

    Parameters
    ----------
    vertices : (n, 3) float64, mm
    faces : (m, 3) int64
        Degenerate faces (repeated index or zero area) are ignored; source face indices refer to this array.
    vertex_normals : (n, 3) float64 or None
        Unit normals; the default tangent plane of vertex sources when :meth:`query` gets no normals.
        Computed (area-weighted) when None.
    method : {"window", "fmm", "dijkstra"}
        See the module docstring; "window" is exact.
    n_threads : int or None
        Worker threads for :meth:`query` (the kernels release the GIL); default: usable CPUs.
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = None
    method: str = "window"
    n_threads: int | None = None

    def __post_init__(self):
        V = np.asarray(self.vertices, dtype=np.float64)
        F = np.asarray(self.faces)
        if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] == 0:
            raise ValueError(f"vertices must be (n, 3), got shape {V.shape}")
        if not np.all(np.isfinite(V)):
            raise ValueError("vertices contain NaN or Inf")
        if F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer):
            raise ValueError(f"faces must be (m, 3) integers, got shape {F.shape} dtype {F.dtype}")
        F = F.astype(np.int64)
        if F.size and (F.min() < 0 or F.max() >= V.shape[0]):
            raise ValueError("face indices out of range")
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r}; choose one of {', '.join(METHODS)}")
        if self.n_threads is not None and int(self.n_threads) < 1:
            raise ValueError(f"n_threads must be >= 1, got {self.n_threads}")
        # internal Z-order of vertices and faces: neighbours share cache lines (2x faster graph searches)
        vperm = _morton_order(V)
        vinv = np.empty_like(vperm)
        vinv[vperm] = np.arange(vperm.size)
        fperm = _morton_order(V[F].mean(axis=1)) if F.size else np.zeros(0, np.int64)
        finv = np.empty_like(fperm)
        finv[fperm] = np.arange(fperm.size)
        topo = _build_topology(V[vperm], vinv[F[fperm]] if F.size else F)
        topo.update(vperm=_readonly(vperm), vinv=_readonly(vinv), finv=_readonly(finv))
        # pseudo-sources: open/non-manifold vertices and saddles (cone angle above 2 pi)
        topo["emitter"] = _readonly(topo["open_vertex"] | (topo["angle_excess"] > 2.0 * np.pi * 1e-9))
        fan_start, fan_ok = _build_fans(V.shape[0], topo["he_twin"], topo["he_tsx"], topo["he_corner"],
                                        topo["v_ptr"], topo["v_he"])
        topo.update(fan_start=_readonly(fan_start), fan_ok=_readonly(fan_ok))
        if self.vertex_normals is None:
            fn = face_normals(V, F, unit=False)  # area-weighted
            N = np.zeros_like(V)
            for c in range(3):
                N += np.stack([np.bincount(F[:, c], weights=fn[:, j], minlength=V.shape[0]) for j in range(3)], 1)
        else:
            N = np.asarray(self.vertex_normals, dtype=np.float64)
            if N.shape != V.shape:
                raise ValueError(f"vertex_normals must be {V.shape}, got {N.shape}")
        with np.errstate(invalid="ignore", divide="ignore"):
            N = N / np.linalg.norm(N, axis=1, keepdims=True)
        N = np.where(np.isfinite(N), N, 0.0)
        object.__setattr__(self, "vertices", _readonly(V))
        object.__setattr__(self, "faces", _readonly(F))
        object.__setattr__(self, "vertex_normals", _readonly(N))
        object.__setattr__(self, "_topo", topo)
        cross = face_geometry(V, F)[0] if F.size else np.zeros((0, 3))
        object.__setattr__(self, "_area_per_vertex", 0.5 * float(np.linalg.norm(cross, axis=1).sum()) / V.shape[0])
        object.__setattr__(self, "_pace", {})  # measured speed of the kernel calls per size class (pace_rate)

    # -- description -------------------------------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def mean_edge_length(self) -> float:
        """Mean length of the (undirected) edges of the non-degenerate faces, mm."""
        return self._topo["mean_edge"]

    def __repr__(self) -> str:
        t = self._topo
        return (f"GeodesicNeighbourhoods({self.n_vertices} vertices, {self.faces.shape[0]} faces, "
                f"mean edge {t['mean_edge']:.4g} mm, method={self.method!r}, "
                f"{t['n_boundary_edges']} boundary / {t['n_nonmanifold_edges']} non-manifold edges, "
                f"{int(t['emitter'].sum())} saddle/boundary vertices, "
                f"{int((~t['good_face']).sum())} degenerate faces ignored)")

    # -- queries -----------------------------------------------------------------------------------------------
    def _sources(self, source_points, source_faces, source_bary, source_vertex, source_normals):
        """Validate and complete the source arrays (positions, faces, bary, vertex, normals)."""
        V, F = self.vertices, self.faces
        sv = None if source_vertex is None else np.atleast_1d(np.asarray(source_vertex, dtype=np.int64))
        sf = None if source_faces is None else np.atleast_1d(np.asarray(source_faces, dtype=np.int64))
        k = sv.shape[0] if sv is not None else (sf.shape[0] if sf is not None else None)
        if k is None:
            raise ValueError("give source_vertex (vertex sources) and/or source_faces with source_bary")
        sv = np.full(k, -1, np.int64) if sv is None else sv
        sf = np.full(k, -1, np.int64) if sf is None else sf
        if sv.shape != (k,) or sf.shape != (k,):
            raise ValueError("source_vertex and source_faces must have the same length k")
        if np.any(sv >= self.n_vertices) or np.any(sf >= F.shape[0]):
            raise ValueError("source vertex or face index out of range")
        on_face = sv < 0
        if np.any(on_face & (sf < 0)):
            raise ValueError("each source needs a vertex index >= 0 or a face index >= 0")
        bary = np.zeros((k, 3))
        if np.any(on_face):
            if source_bary is None:
                raise ValueError("face sources need source_bary")
            b = np.asarray(source_bary, dtype=np.float64).reshape(k, 3)[on_face]
            if not np.all(np.isfinite(b)) or np.any(b < -1e-6) or np.any(np.abs(b.sum(1) - 1) > 1e-6):
                raise ValueError("source_bary must be finite, non-negative and sum to 1 for face sources")
            if not np.all(self._topo["good_face"][self._topo["finv"][sf[on_face]]]):
                raise ValueError("a source lies on a degenerate (zero-area) face")
            b = np.maximum(b, _BARY_FLOOR)
            bary[on_face] = b / b.sum(axis=1, keepdims=True)
        pts_bary = np.where(on_face[:, None], np.einsum("kj,kjc->kc", bary, V[F[np.maximum(sf, 0)]]),
                            V[np.maximum(sv, 0)])
        if source_points is None:
            pts = pts_bary
        else:
            pts = np.asarray(source_points, dtype=np.float64).reshape(k, 3)
            tol = 1e-6 * max(1.0, float(np.abs(V).max())) + 1e-3 * self.mean_edge_length
            if np.any(np.linalg.norm(pts - pts_bary, axis=1) > tol):
                raise ValueError("source_points disagree with source_vertex / source_faces + source_bary "
                                 "(face indices must refer to the solver's faces)")
        if source_normals is None:
            fn = face_normals(V, F[np.maximum(sf, 0)], unit=False)
            nrm = np.where(on_face[:, None], fn, self.vertex_normals[np.maximum(sv, 0)])
        else:
            nrm = np.asarray(source_normals, dtype=np.float64).reshape(k, 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        return pts, sf, bary, sv, np.where(np.isfinite(nrm), nrm, 0.0)

    def _run_block(self, sv, sf, bary, cut, stop=None):
        t = self._topo
        sv = np.where(sv >= 0, t["vinv"][np.maximum(sv, 0)], -1)
        sf = np.where(sf >= 0, t["finv"][np.maximum(sf, 0)], -1)
        counts, vertex, dist = self._run_internal(sv, sf, bary, cut, np.zeros(1, np.int64) if stop is None else stop)
        return counts, t["vperm"][vertex].astype(np.int32), dist

    def _run_internal(self, sv, sf, bary, cut, stop):
        t = self._topo
        # bucket queue: width 1/8 mean edge, enough buckets to span the largest jump of a key (3 longest edges)
        delta = t["mean_edge"] / 8.0 if t["mean_edge"] > 0 else 1.0
        nb = int(min(1 << 16, max(64, np.ceil(3.0 * t["max_edge"] / delta) + 2)))
        q = (1.0 / delta, nb)
        if self.method == "window":
            return _k._window_block(sv, sf, bary, cut, self.n_vertices, t["he_tail"], t["he_head"], t["he_opp"],
                                    t["he_twin"], t["he_tox"], t["he_tsx"], t["he_len"], t["he_ox"], t["he_oy"],
                                    t["v_ptr"], t["v_he"], t["emitter"], *q,
                                    t["fan_start"], t["fan_ok"], t["he_corner"], t["v_theta"], stop)
        return _g._vertex_queue_block(sv, sf, bary, cut, self.n_vertices, t["e_ptr"], t["e_nbr"], t["e_len"],
                                     t["he_tail"], t["he_head"], t["he_len"], t["he_ox"], t["he_oy"],
                                     t["v_ptr"], t["v_he"], self.method == "fmm", *q)

    def query(self, source_points, source_faces, source_bary, source_vertex, source_normals, cutoff_mm, *,
              d1=None, d2=None, k1=None, k2=None, chord: bool = True, tangent: bool = False,
              progress=None, block_size: int | None = None) -> Neighbourhoods:
        """Vertices within ``cutoff_mm`` geodesic distance of each source.

        Parameters
        ----------
        source_points : (k, 3) float64 mm or None
            Source positions (checked against vertex / face + bary; derived from them when None).
        source_faces : (k,) int or None
            Face of each face source (index into ``faces``), -1 for vertex sources.
        source_bary : (k, 3) float64 or None
            Barycentric weights of ``faces[source_faces]``'s corners (ignored for vertex sources; may be NaN).
        source_vertex : (k,) int or None
            Vertex of each vertex source, -1 for face sources.
        source_normals : (k, 3) float64 or None
            Tangent-plane normals (default: vertex normal / face normal).
        cutoff_mm : float or (k,) float64, mm
        d1, d2 : (k, 3) float64 or None
            Principal directions; when given, ``phi`` is returned.
        k1, k2 : (k,) float64 1/mm or None
            Principal curvatures; when given with d1, d2, phi gets the leading-order geodesic correction.
        chord, tangent : bool
            Whether to return ``chord`` (8 bytes/pair) and ``tangent`` (24 bytes/pair).
        progress : callable(done, total) or None
            Called after each block of sources with the number of sources done.
        block_size : int or None
            Sources per kernel call (default: as many as take about :data:`meshshade.pacing.BLOCK_SECONDS`, by the
            pairs expected within the cutoff and the measured speed of the previous calls, so that Ctrl-C acts
            within about that long; at most 512 and a quarter of the sources per thread). Results do not depend on
            it.

        Returns
        -------
        Neighbourhoods
        """
        pts, sf, bary, sv, nrm = self._sources(source_points, source_faces, source_bary, source_vertex,
                                               source_normals)
        k = sv.shape[0]
        cut = np.broadcast_to(np.asarray(cutoff_mm, dtype=np.float64), (k,)).copy()
        if not np.all(cut >= 0) or np.any(np.isnan(cut)):
            raise ValueError("cutoff_mm must be >= 0 (inf allowed)")
        nthreads = int(self.n_threads or default_threads())
        most = max(1, min(512, -(-k // (4 * nthreads))))  # several blocks per thread, for balance
        if block_size:
            pacer = Pacer(np.ones(k), seconds=np.inf, min_block=int(block_size), max_block=int(block_size))
        else:
            work = expected_work(cut, self.n_vertices, self._area_per_vertex)
            pacer = Pacer(work, pace_rate(self._pace, work), prior=PRIOR_SECONDS_PER_PAIR, max_block=most)
        stop = np.zeros(1, np.int64)  # set by run_paced when interrupted: running window loops return early
        results = run_paced(lambda a, b: self._run_block(sv[a:b], sf[a:b], bary[a:b], cut[a:b], stop), pacer, k,
                            n_threads=nthreads, progress=progress, stop=stop)
        counts = np.concatenate([r[0] for r in results]) if results else np.zeros(0, np.int64)
        vertex = np.concatenate([r[1] for r in results]) if results else np.zeros(0, np.int32)
        dist = np.concatenate([r[2] for r in results]) if results else np.zeros(0)
        return assemble_neighbourhoods(Neighbourhoods.from_counts(counts, vertex, dist, cut, self.method),
                                       self.vertices, pts, nrm, d1=d1, d2=d2, k1=k1, k2=k2, chord=chord,
                                       tangent=tangent)

    def distances_from(self, *, vertex: int | None = None, face: int | None = None, bary=None,
                       cutoff_mm: float = np.inf) -> np.ndarray:
        """(n,) float64 mm: geodesic distance of every vertex from one source (inf beyond ``cutoff_mm``).

        Give either ``vertex`` or ``face`` with ``bary`` (3,).
        """
        if (vertex is None) == (face is None):
            raise ValueError("give exactly one of vertex= or face= (with bary=)")
        nb = self.query(None, None if face is None else [face], None if bary is None else [bary],
                        None if vertex is None else [vertex], None, cutoff_mm, chord=False)
        out = np.full(self.n_vertices, np.inf)
        out[nb.vertex] = nb.distance
        return out


def assemble_neighbourhoods(rows: Neighbourhoods, V, pts, nrm, *, d1=None, d2=None, k1=None, k2=None, chord=True,
                            tangent=False) -> Neighbourhoods:
    """``rows`` (the solver's pairs, :meth:`Neighbourhoods.from_counts`) with the chord, the unit tangent
    (projection of x_o - x_i on the source's tangent plane) and, when the principal directions are given, the
    azimuth phi (:func:`tangent_azimuth`) added. Shared by every solver.

    ``V`` (n, 3) mm: the mesh's vertices; ``pts``, ``nrm`` (k, 3): the sources' positions (mm) and unit normals.
    The pairs are processed in slices of :data:`ASSEMBLE_PAIRS` (row by row, so the result does not depend on
    it): each numpy call stays short and Ctrl-C is acted upon between them."""
    indptr, vertex, dist, cut, method = rows.indptr, rows.vertex, rows.distance, rows.cutoff, rows.method
    counts, k = rows.counts, rows.n_sources
    want_phi = d1 is not None and d2 is not None
    ch = tan = phi = None
    if not (chord or tangent or want_phi):
        return Neighbourhoods(indptr, vertex, dist, ch, tan, phi, cut, method)
    p = int(indptr[-1])
    src = np.repeat(np.arange(k), counts)
    ch = np.empty(p) if chord else None
    tan = np.empty((p, 3)) if tangent else None
    phi = np.empty(p) if want_phi else None
    if want_phi:
        d1 = np.asarray(d1, dtype=np.float64).reshape(k, 3)
        d2 = np.asarray(d2, dtype=np.float64).reshape(k, 3)
        k1 = None if k1 is None else np.broadcast_to(np.asarray(k1, np.float64), (k,))
        k2 = None if k2 is None else np.broadcast_to(np.asarray(k2, np.float64), (k,))
    for a in range(0, p, ASSEMBLE_PAIRS):
        sl = slice(a, min(p, a + ASSEMBLE_PAIRS))
        s = src[sl]
        diff = V[vertex[sl]] - pts[s]
        if chord:
            ch[sl] = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        if tangent or want_phi:
            t = diff - np.einsum("ij,ij->i", diff, nrm[s])[:, None] * nrm[s]
            ln = np.linalg.norm(t, axis=1)
            t /= np.where(ln > 0, ln, 1.0)[:, None]
            if want_phi:
                phi[sl] = tangent_azimuth(t, d1[s], d2[s], dist[sl], None if k1 is None else k1[s],
                                          None if k2 is None else k2[s])
            if tangent:
                tan[sl] = t
    return Neighbourhoods(indptr, vertex, dist, ch, tan, phi, cut, method)


def tangent_azimuth(tangent, d1, d2, rho=None, k1=None, k2=None) -> np.ndarray:
    """Azimuth of unit tangent directions from d1 towards d2, radians in (-pi, pi].

    ``phi_proj = atan2(t.d2, t.d1)``.  With ``rho, k1, k2`` the leading deviation of the chord projection from the
    geodesic's initial direction is removed: a geodesic leaving at angle phi (Darboux frame, x''' projected on the
    tangent plane = -k_n^2 T - k_n tau_g B) projects at ``phi + (rho^2/6) k_n(phi) (k1 - k2) sin(phi) cos(phi)``,
    ``k_n = k1 cos^2 + k2 sin^2``, so ``phi = phi_proj - (that term at phi_proj)`` to O(rho^4).

    Parameters
    ----------
    tangent, d1, d2 : (p, 3) float64; rho : (p,) mm; k1, k2 : (p,) 1/mm
    """
    phi = np.arctan2(np.einsum("ij,ij->i", tangent, d2), np.einsum("ij,ij->i", tangent, d1))
    if rho is not None and k1 is not None and k2 is not None:
        c, s = np.cos(phi), np.sin(phi)
        kn = k1 * c * c + k2 * s * s
        phi = phi - (np.asarray(rho) ** 2 / 6.0) * kn * (k1 - k2) * s * c
        phi = np.angle(np.exp(1j * phi))
    return phi


def geodesic_neighbourhoods(vertices, faces, source_points, source_faces, source_bary, source_vertex,
                            source_normals, cutoff_mm, *, vertex_normals=None, method: str = "window",
                            **query_kwargs) -> Neighbourhoods:
    """One-off :meth:`GeodesicNeighbourhoods.query` (builds the solver, queries once)."""
    solver = GeodesicNeighbourhoods(vertices, faces, vertex_normals, method=method)
    return solver.query(source_points, source_faces, source_bary, source_vertex, source_normals, cutoff_mm,
                        **query_kwargs)


def geodesic_distances_from(vertices, faces, *, vertex: int | None = None, face: int | None = None, bary=None,
                            cutoff_mm: float = np.inf, method: str = "window"):
    """(n,) float64 mm: geodesic distance of every vertex from one source point (inf beyond ``cutoff_mm``).

    The source is ``vertex`` or a point of ``face`` with barycentric weights ``bary``; e.g. a beam's entry point
    (its hit face and barycentrics).
    """
    solver = GeodesicNeighbourhoods(vertices, faces, method=method, n_threads=1)
    return solver.distances_from(vertex=vertex, face=face, bary=bary, cutoff_mm=cutoff_mm)
