"""Arc geodesic neighbourhoods (approximate, method "arc"): ball-restricted Dijkstra + curvature-corrected chord.

Same query and result (:class:`~meshshade.geometry.geodesics.neighbourhoods.Neighbourhoods`) as
:class:`~meshshade.geometry.geodesics.neighbourhoods.GeodesicNeighbourhoods`, about 4-5x faster per pair in bakes
(tools/benchmarks/bench_bake.py).  Per source x_i (a serial compiled loop over a block of sources with its own
stamp-marked scratch arrays, so nothing is cleared between sources and no work is O(N^2); the blocks run on
worker threads, :func:`meshshade.pacing.run_paced`):

1. Topology.  A Dijkstra over mesh edges from the source vertex (or the three corners of its face), entering only
   vertices inside the ball ``|x_o - x_i| <= cutoff`` and with edge-path length ``d_graph <= 1.6 cutoff``.
   A vertex with geodesic distance <= cutoff has a surface path inside the ball, so vertices of the ball that are
   not connected to the source inside it (the other of two touching fingers, the far arm of a U) are never
   reached: no leaks across gaps.  (Walking the edges inside the ball *is* the spatial candidate search; a
   separate hash grid would only produce the same candidates plus the disconnected ones, then drop them.)
   Edge paths overestimate the geodesic by 0-15 % on regular meshes, so ``d_graph`` is an upper bound.
2. Distance.  The curvature-corrected chord ``s = (2/k) asin(k c / 2)``, ``k = (n_o - n_i).(x_o - x_i) / c^2``
   from unit vertex normals (series for small ``k c``): exact on spheres and for normal sections of smooth
   surfaces.  It is accepted when ``c <= s <= (1 + eps) d_graph`` and ``d_graph <= r_max s`` (``r_max`` = 1.6:
   structured meshes such as the procedural torus have edge paths up to ~1.5x the geodesic, so 1.3 rejected 19 %
   of valid pairs there).  Otherwise (a *fallback*, counted in ``stats``) the path is "string-pulled" along the
   Dijkstra tree: ``s(o) = min_a s(a) + s_arc(a, o)`` over up to 48 ancestors a whose tree path to o passes the
   same test (the parent always does).  An optional midpoint test (``tau``) is off by default: the Dijkstra tree's
   midpoint lies laterally off the geodesic, so it rejected good arcs (3 % mean error on spheres at tau = 0.03).
3. ``phi`` with :func:`~meshshade.geometry.geodesics.neighbourhoods.tangent_azimuth`, exactly as the window query.

Results are CSR rows in the order the Dijkstra settles vertices (nearest first along edges).

Measured error (r_max = 1.6; pairs beyond 2 mean edges; reference = exact polyhedral geodesics of the window
solver; 40 random sources, 30 on scans; scans scaled to the given size; normals ``Mesh(V, F).vertex_normals``):

    =====================================  ===========  ==========  ==========  ==========  ================
    mesh (size, cutoff)                    max |rel|    mean |rel|  p99 |rel|   bias        fallback pairs
    =====================================  ===========  ==========  ==========  ==========  ================
    icosphere R=60 L5 (10k), 28 mm         3.4e-4       1.4e-4      2.3e-4      +1.4e-4     0
    icosphere R=10 L4, face sources, 5 mm  5.5e-4       1.6e-4      4.5e-4      +1.5e-4     0.016 %
    torus 40/15 (10k), 14 mm               7.9e-4       2.4e-4      7.5e-4      +4e-5       0
    spot (150 mm), 20 mm                   0.31         0.011       0.16        -0.010      0.11 %
    bunny (150 mm), 20 mm                  0.28         0.016       0.14        -0.014      0.02 %
    hand (180 mm), 20 mm                   0.30         0.013       0.16        -0.011      0.34 %
    Lee Perry-Smith head (200 mm), 20 mm   0.66         0.11        0.32        -0.107      15 %
    =====================================  ===========  ==========  ==========  ==========  ================

So: within 0.1 % of exact (and of great circles, exactly with exact normals) on spheres and the torus, i.e.
wherever the geodesic is close to a normal section; on scanned meshes the chord arc UNDERSHOOTS where the
surface between the two points is bumpy or folded (mean -1 %, p99 -15 %; the coarse, sliver-rich head -11 %)
and 0.5-3 % more vertices fall inside the cutoff than exactly.  Vertex sets on spheres/torus agree with the
exact ones except within 0.02 % of the cutoff.  Known failure: the far arm of a tight fold (U-strip, 0.5 mm
radius) seen from within ~6 mm of the fold passes the ratio test (the chord is short but the edge path only
1.2-1.5x longer); no leaks occur across gaps (touching spheres, folds seen from further away).

Speed: ``tools/benchmarks/bench_arc_neighbourhood.py`` (see the commit message for figures on this machine).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from meshshade.geometry.geodesics.neighbourhoods import (PRIOR_SECONDS_PER_PAIR, GeodesicNeighbourhoods,
                                                           Neighbourhoods, assemble_neighbourhoods, expected_work)
from meshshade.geometry.mesh import face_normals
from meshshade.pacing import Pacer, default_threads, pace_rate, run_paced

__all__ = ["ArcGeodesicNeighbourhoods", "ACCURACY"]

#: measured accuracy table (filled from tools/benchmarks/bench_arc_neighbourhood.py --accuracy); see the docstring
ACCURACY: dict = {}

_ANCESTORS = 48       # string-pulling depth of the fallback
_PRUNE = 1.6          # Dijkstra stops at d_graph > _PRUNE * cutoff


@njit(cache=True, inline="always")
def _arc(x0, y0, z0, nx0, ny0, nz0, x1, y1, z1, nx1, ny1, nz1):
    """Curvature-corrected chord between two points with unit normals; (chord, arc), arc = -1 if invalid."""
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    c2 = dx * dx + dy * dy + dz * dz
    c = np.sqrt(c2)
    if c2 == 0.0:
        return 0.0, 0.0
    kap = ((nx1 - nx0) * dx + (ny1 - ny0) * dy + (nz1 - nz0) * dz) / c2
    h = 0.5 * kap * c
    ah = abs(h)
    if ah < 1e-3:
        h2 = h * h
        return c, c * (1.0 + h2 * (1.0 / 6.0 + h2 * (3.0 / 40.0)))
    if ah >= 1.0:
        return c, -1.0
    return c, c * np.arcsin(ah) / ah


@njit(cache=True)
def _heap_push(hv, hk, pos, size, v, key):
    """Insert or decrease-key in an indexed binary min-heap; returns the new size."""
    i = pos[v]
    if i < 0:
        i = size
        size += 1
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= key:
            break
        hv[i] = hv[p]
        hk[i] = hk[p]
        pos[hv[i]] = i
        i = p
    hv[i] = v
    hk[i] = key
    pos[v] = i
    return size


@njit(cache=True)
def _heap_pop(hv, hk, pos, size):
    """Remove the minimum (returned as hv[size-1] slot semantics: returns (v, new size))."""
    v = hv[0]
    pos[v] = -2
    size -= 1
    if size == 0:
        return v, 0
    lv = hv[size]
    lk = hk[size]
    i = 0
    while True:
        l = 2 * i + 1
        if l >= size:
            break
        r = l + 1
        m = l
        if r < size and hk[r] < hk[l]:
            m = r
        if hk[m] >= lk:
            break
        hv[i] = hv[m]
        hk[i] = hk[m]
        pos[hv[i]] = i
        i = m
    hv[i] = lv
    hk[i] = lk
    pos[lv] = i
    return v, size


@njit(cache=True, nogil=True)
def _arc_block(src_v, src_corner, src_pt, src_n, cut, X, N, e_ptr, e_nbr, e_len, cap, r_max, eps, tau):
    """Neighbourhoods of k sources written into (k, cap) slots; counts may exceed cap (caller re-runs those).
    Serial, without the GIL: blocks of sources run on the pacing threads.

    src_v: (k,) source vertex or -1; src_corner: (k, 3) face corners (used when src_v < 0);
    src_pt / src_n: (k, 3) position and unit normal used for the arc; returns counts, vertex, dist, fallbacks.
    """
    k = src_v.shape[0]
    n = X.shape[0]
    counts = np.zeros(k, np.int64)
    nfall = np.zeros(k, np.int64)
    out_v = np.empty((k, cap), np.int32)
    out_d = np.empty((k, cap), np.float64)
    stamp = np.full(n, -1, np.int64)
    pos = np.empty(n, np.int64)
    dg = np.empty(n, np.float64)
    est = np.empty(n, np.float64)
    par = np.empty(n, np.int64)
    hv = np.empty(n, np.int64)
    hk = np.empty(n, np.float64)
    for i in range(k):
        sx, sy, sz = src_pt[i, 0], src_pt[i, 1], src_pt[i, 2]
        snx, sny, snz = src_n[i, 0], src_n[i, 1], src_n[i, 2]
        R = cut[i]
        R2 = R * R
        dmax = _PRUNE * R
        size = np.int64(0)   # not the literal 0: numba would compile _heap_push for Literal[int](0) too
        cnt = 0
        fb = 0
        if src_v[i] >= 0:
            v = src_v[i]
            stamp[v] = i
            pos[v] = -1
            dg[v] = 0.0
            par[v] = -1
            size = _heap_push(hv, hk, pos, size, v, 0.0)
        else:
            for j in range(3):
                v = src_corner[i, j]
                dx, dy, dz = X[v, 0] - sx, X[v, 1] - sy, X[v, 2] - sz
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                if d > R:
                    continue
                if stamp[v] != i:
                    stamp[v] = i
                    pos[v] = -1
                    dg[v] = d
                    par[v] = -1
                    size = _heap_push(hv, hk, pos, size, v, d)
        while size > 0:
            v, size = _heap_pop(hv, hk, pos, size)
            d = dg[v]
            # distance estimate
            c, s = _arc(sx, sy, sz, snx, sny, snz, X[v, 0], X[v, 1], X[v, 2], N[v, 0], N[v, 1], N[v, 2])
            fbk = 0
            if c == 0.0:
                e = 0.0
            elif s > 0.0 and s <= d * (1.0 + eps) and d <= r_max * s:
                e = s
                # midpoint test: the arc through the tree path's midpoint m must not be much longer
                a = par[v]
                while a >= 0 and dg[a] > 0.5 * d:
                    a = par[a]
                if a >= 0 and dg[a] > 0.0:
                    ca, sa = _arc(X[a, 0], X[a, 1], X[a, 2], N[a, 0], N[a, 1], N[a, 2],
                                  X[v, 0], X[v, 1], X[v, 2], N[v, 0], N[v, 1], N[v, 2])
                    if sa < 0.0:
                        sa = d - dg[a]
                    if est[a] + sa > (1.0 + tau) * s:
                        e = est[a] + sa
                        fbk = 1
            else:
                fbk = 1
                e = d
                a = par[v]
                m = 0
                while a >= 0 and m < _ANCESTORS:
                    ca, sa = _arc(X[a, 0], X[a, 1], X[a, 2], N[a, 0], N[a, 1], N[a, 2],
                                  X[v, 0], X[v, 1], X[v, 2], N[v, 0], N[v, 1], N[v, 2])
                    dd = d - dg[a]
                    if sa > 0.0 and sa <= dd * (1.0 + eps) and dd <= r_max * sa and est[a] + sa < e:
                        e = est[a] + sa
                    a = par[a]
                    m += 1
                if e < c:
                    e = c
            est[v] = e
            if e <= R:
                fb += fbk
                if cnt < cap:
                    out_v[i, cnt] = v
                    out_d[i, cnt] = e
                cnt += 1
            # relax
            for q in range(e_ptr[v], e_ptr[v + 1]):
                w = e_nbr[q]
                nd = d + e_len[q]
                if nd > dmax:
                    continue
                if stamp[w] == i:
                    if pos[w] == -2 or nd >= dg[w]:
                        continue
                else:
                    dx, dy, dz = X[w, 0] - sx, X[w, 1] - sy, X[w, 2] - sz
                    if dx * dx + dy * dy + dz * dz > R2:
                        continue
                    stamp[w] = i
                    pos[w] = -1
                dg[w] = nd
                par[w] = v
                size = _heap_push(hv, hk, pos, size, w, nd)
        counts[i] = cnt
        nfall[i] = fb
    return counts, out_v, out_d, nfall


class ArcGeodesicNeighbourhoods:
    """Arc geodesic-neighbourhood solver (method "arc", approximate); same :meth:`query` as ``GeodesicNeighbourhoods``.

    Parameters
    ----------
    vertices : (n, 3) float64 mm; faces : (m, 3) int
    vertex_normals : (n, 3) or None
        Unit vertex normals (area-weighted when None); they set both the tangent planes and the curvature of the
        arc correction, so smooth (e.g. angle- or area-weighted) normals matter.
    r_max : float
        Largest accepted ``d_graph / s_arc`` (see the module docstring).
    eps : float
        Accepted ``s_arc / d_graph - 1``.
    n_threads : int or None
    """

    method = "arc"

    def __init__(self, vertices, faces, vertex_normals=None, *, r_max: float = 1.6, eps: float = 0.02,
                 tau: float = np.inf,
                 n_threads: int | None = None):
        self._base = GeodesicNeighbourhoods(vertices, faces, vertex_normals, n_threads=n_threads)
        t = self._base._topo
        self.vertices = self._base.vertices
        self.faces = self._base.faces
        self.vertex_normals = self._base.vertex_normals
        self.r_max = float(r_max)
        self.eps = float(eps)
        self.tau = float(tau)
        self.n_threads = int(n_threads or default_threads())
        self._vperm, self._vinv = t["vperm"], t["vinv"]
        self._X = np.ascontiguousarray(self.vertices[self._vperm])
        self._N = np.ascontiguousarray(self.vertex_normals[self._vperm])
        self._e = (t["e_ptr"], t["e_nbr"], t["e_len"])
        self._area_per_vertex = 0.5 * float(np.linalg.norm(face_normals(self.vertices, self.faces, unit=False),
                                                           axis=1).sum()) / len(self.vertices)
        self._cap = None
        self._pace: dict = {}  # measured speed of the kernel calls per size class (pace_rate)
        self.stats: dict = {}

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def mean_edge_length(self) -> float:
        return self._base.mean_edge_length

    def __repr__(self) -> str:
        return (f"ArcGeodesicNeighbourhoods({self.n_vertices} vertices, {self.faces.shape[0]} faces, "
                f"r_max={self.r_max:g}, threads={self.n_threads})")

    def _run(self, sv, corners, pts, nrm, cut):
        """One kernel call with capacity re-runs for overflowing rows; returns counts, vertex, dist, fallbacks.
        Runs on the pacing threads: the slot capacity (``self._cap``) only sizes the slots, never a result."""
        k = sv.shape[0]
        cap = self._cap
        args = (self._X, self._N, *self._e)
        counts, ov, od, fb = _arc_block(sv, corners, pts, nrm, cut, *args, cap, self.r_max, self.eps, self.tau)
        over = np.flatnonzero(counts > cap)
        if over.size:  # rows longer than the slot capacity: re-run them with enough room
            cap2 = int(counts[over].max())
            self._cap = int(min(self.n_vertices, 1.25 * cap2))
            _, ov2, od2, _ = _arc_block(sv[over], corners[over], pts[over], nrm[over], cut[over], *args, cap2,
                                        self.r_max, self.eps, self.tau)
            where = np.full(k, -1)
            where[over] = np.arange(over.size)
            vv = [ov[j, :counts[j]] if where[j] < 0 else ov2[where[j], :counts[j]] for j in range(k)]
            dd = [od[j, :counts[j]] if where[j] < 0 else od2[where[j], :counts[j]] for j in range(k)]
            return counts, np.concatenate(vv), np.concatenate(dd), fb
        mask = np.arange(cap)[None, :] < counts[:, None]
        return counts, ov[mask], od[mask], fb

    def query(self, source_points, source_faces, source_bary, source_vertex, source_normals, cutoff_mm, *,
              d1=None, d2=None, k1=None, k2=None, chord: bool = True, tangent: bool = False,
              progress=None, block_size: int | None = None) -> Neighbourhoods:
        """Vertices within ``cutoff_mm`` (approximate) geodesic distance of each source.

        Same parameters and result as :meth:`GeodesicNeighbourhoods.query` (method "arc").  After the call,
        ``self.stats`` holds ``pairs``, ``fallback_pairs`` (pairs whose distance did not come from the direct arc
        test) and ``fallback_fraction``.
        """
        pts, sf, bary, sv, nrm = self._base._sources(source_points, source_faces, source_bary, source_vertex,
                                                     source_normals)
        k = sv.shape[0]
        cut = np.broadcast_to(np.asarray(cutoff_mm, dtype=np.float64), (k,)).copy()
        if not np.all(cut >= 0) or np.any(np.isnan(cut)):
            raise ValueError("cutoff_mm must be >= 0 (inf allowed)")
        V, F, NV = self.vertices, self.faces, self.vertex_normals
        on_face = sv < 0
        fc = F[np.maximum(sf, 0)]
        corners = np.ascontiguousarray(self._vinv[fc])
        psv = np.where(on_face, -1, self._vinv[np.maximum(sv, 0)]).astype(np.int64)
        # arc normal: the vertex normal, or the barycentric blend of the face's vertex normals
        an = np.where(on_face[:, None], np.einsum("kj,kjc->kc", bary, NV[fc]), NV[np.maximum(sv, 0)])
        an /= np.where((ln := np.linalg.norm(an, axis=1, keepdims=True)) > 0, ln, 1.0)
        if self._cap is None:  # slots per source, from the first query's largest cutoff (grown on overflow)
            fin = cut[np.isfinite(cut)]
            rmax = float(fin.max()) if fin.size else np.inf
            self._cap = int(min(self.n_vertices, max(64, 1.5 * np.pi * rmax ** 2 / max(self._area_per_vertex,
                                                                                      1e-300))))
        # blocks of sources of about pacing.BLOCK_SECONDS each on the worker threads (Ctrl-C acts between calls)
        if block_size:
            pacer = Pacer(np.ones(k), seconds=np.inf, min_block=int(block_size), max_block=int(block_size))
        else:
            work = expected_work(cut, self.n_vertices, self._area_per_vertex)
            pacer = Pacer(work, pace_rate(self._pace, work), prior=PRIOR_SECONDS_PER_PAIR, max_block=4096)
        res = run_paced(lambda a, b: self._run(psv[a:b], corners[a:b], np.ascontiguousarray(pts[a:b]),
                                               np.ascontiguousarray(an[a:b]), cut[a:b]),
                        pacer, k, n_threads=self.n_threads, progress=progress)
        counts = np.concatenate([r[0] for r in res]) if res else np.zeros(0, np.int64)
        vertex = (self._vperm[np.concatenate([r[1] for r in res])].astype(np.int32) if res
                  else np.zeros(0, np.int32))
        dist = np.concatenate([r[2] for r in res]) if res else np.zeros(0)
        nfb = int(sum(int(r[3].sum()) for r in res))
        n_pairs = int(counts.sum())
        self.stats = {"pairs": n_pairs, "settled_fallbacks": nfb, "fallback_fraction": nfb / max(1, n_pairs)}
        return assemble_neighbourhoods(Neighbourhoods.from_counts(counts, vertex, dist, cut, self.method), V, pts,
                                       nrm, d1=d1, d2=d2, k1=k1, k2=k2, chord=chord, tangent=tangent)
