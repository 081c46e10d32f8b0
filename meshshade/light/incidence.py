"""Light from many directions at once: what an environment or area light delivers at each surface point.

For a point x with outward normal n and area A, the power entering the medium is

    P(x) = A integral L(w) cos(theta) F_t(cos theta) V(x, w) dw          (environment, docs/physics.md eq. (120))

(the area light's is the same integral over its emitter, eq. (122)), with V the visibility (Embree shadow rays: the
object shadows itself) and F_t the Fresnel transmittance. It is estimated per point from K directions:

* **environment**: multiple importance sampling (the balance heuristic, Veach & Guibas 1995) of two strategies,
  half the directions drawn in proportion to the map's luminance (:class:`~meshshade.light.environment.MapSampler`)
  and half cosine-weighted about n: each direction w contributes ``L cos / (m (p_map(w) + cos / pi))`` for m
  directions per strategy (eq. (123)). The map finds a small bright source; the cosine catches a dim, wide sky
  that a map sampled by luminance would leave to a few directions;
* **area light**: points uniform over the emitter (:func:`~meshshade.light.area.emitter_points`), each
  ``A_e L_e cos_e cos_x / (m d^2)``.

The K directions of a point are R = 4 independent *replicates*, each a randomly shifted lattice of the unit square
(x_j = (j + 1/2)/m, y_j = frac(j g), g the golden ratio's conjugate, shifted by a uniform vector modulo 1: a
randomised quasi-Monte Carlo rule, Cranley & Patterson 1976): each replicate is unbiased and stratified, and their
spread gives each point's standard error (eq. (124)). K is chosen for a stated relative standard error of each
point's entering power (the light's ``error``, default 0.5 %, ``--light-error``): two pilots of 16 and 64 directions
on up to 256 points measure the error and how fast it falls, and K follows (:func:`choose_directions`), up to
the light's ``max_directions``. The error left is measured the same way on every point and reported
(``Incidence.rel_error``; the bake's ``stats["quadrature"]``). Why 0.5 %: on a 642-vertex sphere of skin under a
uniform sky, the bake against the sum of 256 directional lights is 1.6 / 2.6 / 3.2 % off at the 99th percentile
(r/g/b) at 1 %, and 1.4 / 2.1 / 2.5 % at 0.5 %, close to the floor the aggregated samples leave (1.4 / 2.0 / 2.5 %
at 0.25 %; tests/light/test_environment_bake.py, docs/benchmarks.md).

Shadow rays start at the point, offset along n, and go through Embree from the worker threads
(:func:`~meshshade.light.sky_loops.shadow_rows`; the scene's own ``occluded`` where the direct binding does not
load). On a mesh certified convex a direction above one of the point's own faces cannot be shadowed
(:class:`SupportingPlanes`, the rule of :class:`~meshshade.light.shadows.ShadowCuller`) and casts no ray.

What a point receives is kept as its moments (:attr:`Incidence.moments`: powers and the refracted directions'
mean and spread), and :func:`incidence_part` turns them into the entry samples of
:func:`meshshade.light.samples.entry_samples`: up to four per lit vertex (``aggregate``, the default;
:func:`aggregate_samples`) that keep the vertex's entering power and its sources' mean depth, drift and spread,
or one per (vertex, direction).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from meshshade.geometry.convexity import is_convex
from meshshade.geometry.mesh import face_normals
from meshshade.light.sky_loops import (AREA_ROWS, ENVIRONMENT_ROWS, MOMENTS, SUPPORT_COS, pack_sky, quadrature_rows,
                                       row_moments, shadow_rows)
from meshshade.light.sources import AreaLight, EnvironmentLight
from meshshade.pacing import run_in_blocks

__all__ = ["Incidence", "light_incidence", "choose_directions", "incidence_part", "aggregate_samples",
           "tangent_frames", "SupportingPlanes",
           "REPLICATES", "PILOT_DIRECTIONS", "PILOT_POINTS", "MIN_DIRECTIONS"]

#: independent shifted lattices per point (their spread is the point's standard error)
REPLICATES = 4
#: directions per point of the pilot that chooses K, and the most points it looks at
PILOT_DIRECTIONS = 64
PILOT_POINTS = 256
#: the fewest directions per point
MIN_DIRECTIONS = 16
#: (point, direction) rows held in memory at once
CHUNK_ROWS = 1 << 20
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class Incidence:
    """What one environment or area light delivers to ``n`` surface points.

    Attributes
    ----------
    moments : (n, 8) float64, per point (:data:`~meshshade.light.sky_loops.MOMENTS`): the entering power W (after
        Fresnel), the incident power W, and the entering-power-weighted sums of the refracted direction's
        cos theta_t, of its tangential components a1, a2 along the point's tangents (:func:`tangent_frames`) and
        of a1^2, a2^2, a1 a2: what a transport needs to place the sources of the light's whole fan of directions
    directions : int, directions (emitter points for an area light) per point
    rel_error : (n,) float64, each point's estimated relative standard error of its incident power (0 where
        nothing arrives)
    point, direction, incident, entering, cos : the rows (one per (point, direction) that brings light: its point,
        the unit direction in which the light travels, its incident and entering power W, its cosine of
        incidence); empty unless asked for (``rows=True``)
    stats : dict, ``directions``, ``pilot_error``, ``rel_error_rms`` (weighted by power), ``rel_error_p99``,
        ``rays_cast``, ``rays_skipped``, ``seconds`` (the whole estimate, pilots included)
    """

    moments: np.ndarray
    directions: int
    rel_error: np.ndarray
    point: np.ndarray
    direction: np.ndarray
    incident: np.ndarray
    entering: np.ndarray
    cos: np.ndarray
    stats: dict = field(default_factory=dict)

    def incident_power(self) -> np.ndarray:
        """(n,) W incident per point."""
        return self.moments[:, 1].copy()

    def entering_power(self) -> np.ndarray:
        """(n,) W entering per point."""
        return self.moments[:, 0].copy()


class SupportingPlanes:
    """Shadow rays a convex mesh makes unnecessary: from vertex p along w nothing can be hit when one of p's faces
    has ``n_f . w > 1e-6`` (its plane supports the convex mesh; :class:`~meshshade.light.shadows.ShadowCuller`).
    Holds, for a mesh certified convex (:func:`~meshshade.geometry.convexity.is_convex`), each vertex's faces
    (``adjacent`` (n, deg), padded with the row of zeros at the end of ``normals``); for any other mesh no column,
    so no ray is skipped. The compiled rows apply the rule (:func:`~meshshade.light.sky_loops.quadrature_rows`)."""

    def __init__(self, vertices, faces):
        V, F = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
        self.convex = bool(is_convex(V, F))
        self.adjacent = np.zeros((V.shape[0], 0), dtype=np.int64)
        self.normals = np.zeros((1, 3))
        if self.convex:
            fn = face_normals(V, F)
            self.normals = np.vstack([fn, np.zeros((1, 3))])      # row m: padding (never supports)
            corner = F.ravel()
            order = np.argsort(corner, kind="stable")
            counts = np.bincount(corner, minlength=V.shape[0])
            start = np.concatenate([[0], np.cumsum(counts)[:-1]])
            rank = np.arange(corner.size) - np.repeat(start, counts)
            adj = np.full((V.shape[0], max(int(counts.max()), 1)), F.shape[0], dtype=np.int64)
            adj[corner[order], rank] = order // 3
            self.adjacent = adj


# ------------------------------------------------------------------------------------------------ the rule
def _lattice(m: int) -> tuple[np.ndarray, np.ndarray]:
    j = np.arange(m)
    return (j + 0.5) / m, np.mod(j * _GOLDEN, 1.0)


def tangent_frames(n) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (k, 3) completing the unit normals ``n`` (k, 3) to right-handed frames (t1, t2, n) (Duff et
    al. 2017, branchless: the frame :attr:`Incidence.moments` are expressed in)."""
    s = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t1 = np.stack([1.0 + s * n[:, 0] ** 2 * a, s * b, -s * n[:, 0]], axis=1)
    t2 = np.stack([b, s + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t1, t2


def _per_point(light) -> tuple[int, int]:
    """(strategies S, the multiple K must be of): an environment draws R x 2 x m, an area light R x m."""
    return (2, 2 * REPLICATES) if isinstance(light, EnvironmentLight) else (1, REPLICATES)


def light_incidence(light, points, normals, areas, scene, eta, *, directions: int | None = None,
                    planes: SupportingPlanes | None = None, vertex_ids=None, rows: bool = False) -> Incidence:
    """What ``light`` (an :class:`~meshshade.light.sources.EnvironmentLight` or
    :class:`~meshshade.light.sources.AreaLight`) delivers to each of the surface ``points`` (n, 3) mm with unit
    outward ``normals`` (n, 3) and ``areas`` (n,) mm^2, in a medium of relative index ``eta``: an
    :class:`Incidence` (module docstring).

    scene : the ray scene of the mesh (:func:`meshshade.raycast.make_scene`), for the shadow rays;
    directions : directions (emitter points) per point, a multiple of 8 (environment) or 4 (area light); None:
        chosen by :func:`choose_directions` for the light's ``error``;
    planes, vertex_ids : a mesh's :class:`SupportingPlanes` and the vertex of each point, to skip the shadow
        rays a convex mesh makes unnecessary;
    rows : also keep every (point, direction) row (memory: about 60 bytes a row).
    """
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    Nrm = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    Ar = np.asarray(areas, dtype=np.float64).reshape(-1)
    ids = None if vertex_ids is None else np.asarray(vertex_ids, dtype=np.int64)
    t0 = time.perf_counter()
    rays = _Rays(scene, planes)
    pilot = None
    if directions is None:
        directions, pilot = _choose(light, (P, Nrm, Ar), ids, rays, eta)
    inc = _estimate(light, (P, Nrm, Ar), ids, rays, eta, directions, salt=1, keep_rows=rows)
    inc.stats["pilot_error"] = pilot
    inc.stats["rays_cast"], inc.stats["rays_skipped"] = rays.cast, rays.skipped
    inc.stats["seconds"] = round(time.perf_counter() - t0, 4)
    return inc


class _Rays:
    """The shadow rays of one light's quadrature: Embree from the worker threads where the direct binding loads
    (:class:`~meshshade.raycast.embree_direct.DirectEmbreeScene`), else the scene's own ``occluded``; rays a convex
    mesh makes unnecessary (``planes``) are not cast."""

    def __init__(self, scene, planes):
        self.scene, self.planes = scene, planes
        # the scene's own direct binding (built once per scene), None without the Embree 4 library: embreex
        self.direct = getattr(scene, "direct", None) if getattr(scene, "backend", None) == "embree" else None
        self.cast = self.skipped = 0

    def occluded(self, sure, origins, w, tmax) -> np.ndarray:
        """(k,) bool: whether the rays from ``origins`` (k, 3) along unit ``w`` meet the mesh within ``tmax``;
        ``sure`` (k,) the rows known unshadowed (no ray cast)."""
        out = np.zeros(w.shape[0], dtype=bool)
        ray = np.flatnonzero(~sure)
        self.cast += int(ray.size)
        self.skipped += int(w.shape[0] - ray.size)
        if ray.size == 0:
            return out
        o = np.ascontiguousarray(origins[ray])
        d = np.ascontiguousarray(w[ray])
        t = np.ascontiguousarray(tmax[ray])
        if self.direct is None:
            out[ray] = self.scene.occluded(o, d, t)
            return out
        occ = np.zeros(ray.size, dtype=np.bool_)
        center = np.ascontiguousarray(self.scene.center, dtype=np.float64)
        direct = self.direct
        run_in_blocks(lambda a, b: shadow_rows(a, b, o, d, t, center, direct.intersect, direct.handle, occ),
                      ray.size, min_block=4096)
        out[ray] = occ
        return out


def _light_tables(light):
    """(the light's parameter row (24,), SkyTables): what :func:`~meshshade.light.sky_loops.quadrature_rows` reads."""
    params = np.zeros((1, 24))
    sky = pack_sky([light], params)
    return params[0], sky


def _estimate(light, surface, vertex_ids, rays: _Rays, eta, directions, salt, keep_rows=False) -> Incidence:
    """:func:`light_incidence` with K = ``directions`` over ``surface`` = (points, normals, areas) starting from mesh
    vertices ``vertex_ids`` (or None); ``salt`` keys the random shifts (the pilots' differ from the run's)."""
    P, Nrm, Ar = surface
    S, multiple = _per_point(light)
    if directions % multiple or directions < multiple:
        raise ValueError(f"directions must be a positive multiple of {multiple}, got {directions}")
    K = int(directions)
    m = K // (REPLICATES * S)
    n = P.shape[0]
    rng = np.random.default_rng(np.random.SeedSequence([light.seed, salt]))
    shifts = rng.random((n, REPLICATES, S, 2))
    lx, ly = _lattice(m)
    prm, sky = _light_tables(light)
    kind = ENVIRONMENT_ROWS if isinstance(light, EnvironmentLight) else AREA_ROWS
    origin_pt = rays.scene.offset_origins(P, Nrm, +1.0) if n else np.zeros((0, 3))
    planes = rays.planes
    if planes is not None and planes.convex and vertex_ids is not None:
        adjacent, fnormals = np.ascontiguousarray(planes.adjacent[vertex_ids]), planes.normals
    else:
        adjacent, fnormals = np.zeros((n, 0), dtype=np.int64), np.zeros((1, 3))
    T1, T2 = tangent_frames(Nrm) if n else (np.zeros((0, 3)), np.zeros((0, 3)))
    moments = np.zeros((n, MOMENTS))
    rep_sum = np.zeros((n, REPLICATES))
    kept = {k: [] for k in ("point", "direction", "incident", "entering", "cos")}
    step = max(1, CHUNK_ROWS // K)
    for c0 in range(0, n, step):
        c1 = min(n, c0 + step)
        n_rows = (c1 - c0) * K
        w, value, cos, tmax = np.empty((n_rows, 3)), np.empty(n_rows), np.empty(n_rows), np.empty(n_rows)
        sure = np.empty(n_rows, dtype=np.bool_)
        Pc, Nc, Sc, Ac = (np.ascontiguousarray(x[c0:c1]) for x in (P, Nrm, shifts, adjacent))
        run_in_blocks(lambda a, b: quadrature_rows(a, b, kind, Pc, Nc, Sc, lx, ly, prm, sky.row_cdf, sky.flat_cdf,
                                                   sky.lum, sky.cos_edges, Ac, fnormals, w, value, cos, tmax, sure),
                      c1 - c0, min_block=max(1, 16384 // K))
        live = np.flatnonzero(value > 0.0)
        pt = c0 + live // K
        occ = rays.occluded(sure[live], origin_pt[pt], w[live], tmax[live])
        live, pt = live[~occ], pt[~occ]
        rep = (live % K) // (S * m)
        wl, cl = np.ascontiguousarray(w[live]), cos[live]
        entering = np.empty(live.size)
        row_moments(pt, rep, wl, cl, value[live], Ar, Nrm, T1, T2, float(eta), float(REPLICATES), entering, moments,
                    rep_sum)
        if keep_rows:
            kept["point"].append(pt)
            kept["direction"].append(-wl)
            kept["incident"].append(value[live] * Ar[pt] / REPLICATES)
            kept["entering"].append(entering)
            kept["cos"].append(cl)
    cat = {k: (np.concatenate(v) if v else np.zeros((0, 3) if k == "direction" else 0)) for k, v in kept.items()}
    mean = rep_sum.mean(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(mean > 0.0, rep_sum.std(axis=1, ddof=1) / math.sqrt(REPLICATES) / mean, 0.0)
    weight = mean * Ar
    lit = weight > 0.0
    stats = {"directions": K,
             "rel_error_rms": float(math.sqrt(np.sum(weight * rel ** 2) / weight.sum())) if lit.any() else 0.0,
             "rel_error_p99": float(np.percentile(rel[lit], 99)) if lit.any() else 0.0}
    return Incidence(moments, K, rel, cat["point"].astype(np.int64), cat["direction"], cat["incident"],
                     cat["entering"], cat["cos"], stats)


def choose_directions(light, points, normals, areas, scene, eta, *, planes=None, vertex_ids=None) -> tuple[int, float]:
    """(K, the pilot's error at the larger pilot): the directions per point for the light's relative standard
    ``error``. Two pilots on up to :data:`PILOT_POINTS` points spread over the list, of K_a and K_b = 4 K_a
    directions (K_b = :data:`PILOT_DIRECTIONS`), measure the power-weighted rms relative errors e_a and e_b and so
    the rule's convergence rate ``alpha = ln(e_a / e_b) / ln 4``, taken within [1/2, 1] (1/2: plain Monte Carlo; a
    stratified rule converges faster where the integrand is smooth, about as fast where shadows cut it); then
    ``K = K_b (e_b / error)^(1 / alpha)``, rounded up to the rule's multiple, within
    [:data:`MIN_DIRECTIONS`, ``light.max_directions``]."""
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    Nrm = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    Ar = np.asarray(areas, dtype=np.float64).reshape(-1)
    ids = None if vertex_ids is None else np.asarray(vertex_ids, dtype=np.int64)
    return _choose(light, (P, Nrm, Ar), ids, _Rays(scene, planes), eta)


def _choose(light, surface, vertex_ids, rays, eta) -> tuple[int, float]:
    P, Nrm, Ar = surface
    n = P.shape[0]
    _, multiple = _per_point(light)
    if n == 0:
        return MIN_DIRECTIONS, 0.0
    pick = np.unique(np.linspace(0, n - 1, min(n, PILOT_POINTS)).round().astype(np.int64))
    sub = (P[pick], Nrm[pick], Ar[pick])
    ids = None if vertex_ids is None else vertex_ids[pick]
    k_b = PILOT_DIRECTIONS
    k_a = k_b // 4
    e_a = _estimate(light, sub, ids, rays, eta, k_a, salt=2).stats["rel_error_rms"]
    e_b = _estimate(light, sub, ids, rays, eta, k_b, salt=3).stats["rel_error_rms"]
    if not e_b > 0.0:
        return MIN_DIRECTIONS, float(e_b)
    alpha = min(0.75, max(0.5, math.log(e_a / e_b) / math.log(4.0))) if e_a > 0.0 else 0.5
    k = k_b * (e_b / light.error) ** (1.0 / alpha)
    top = light.max_directions // multiple * multiple
    k = int(math.ceil(k / multiple) * multiple) if math.isfinite(k) and k < top else top
    return int(min(max(k, MIN_DIRECTIONS), top)), float(e_b)


def _facing_emitter(light, V) -> np.ndarray:
    """(n,) bool: vertices that can see some of the light (an area light: in front of its plane)."""
    if isinstance(light, AreaLight):
        return (V - np.array(light.position)) @ np.array(light.normal) > 0.0
    return np.ones(V.shape[0], dtype=bool)


def incidence_part(light, i: int, V, F, N, A, get_scene, eta, stats: dict) -> dict:
    """Entry samples of environment or area light ``i`` (the dict of arrays that
    :func:`meshshade.light.samples.entry_samples` concatenates): up to four per lit vertex (``light.aggregate``,
    :func:`aggregate_samples`) or one per (vertex, direction); ``stats["quadrature"]`` gains the light's
    :attr:`Incidence.stats`."""
    idx = np.flatnonzero((A > 0.0) & _facing_emitter(light, V))
    stats["candidates"] = stats.get("candidates", 0) + int(idx.size)
    planes = SupportingPlanes(V, F)
    inc = light_incidence(light, V[idx], N[idx], A[idx], get_scene(), eta, planes=planes, vertex_ids=idx,
                          rows=not light.aggregate)
    stats.setdefault("quadrature", []).append({"light": i, **inc.stats})
    incident = float(inc.moments[:, 1].sum())
    specular = incident - float(inc.moments[:, 0].sum())
    if light.aggregate:
        j, power, d, cos = aggregate_samples(inc, N[idx], eta)
        v = idx[j]
    else:
        keep = inc.entering > 0.0
        v, power, d, cos = idx[inc.point[keep]], inc.entering[keep], inc.direction[keep], inc.cos[keep]
    k = v.size
    return {"positions": V[v], "face": np.full(k, -1), "bary": np.full((k, 3), np.nan), "vertex": v,
            "normals": N[v], "power": power, "cos": cos, "light_index": np.full(k, i), "directions": d,
            "incident": incident, "specular": specular}


def aggregate_samples(inc: Incidence, normals, eta):
    """Each lit point's fan of directions as at most four entry samples: ``(point (k,), entering power (k,) W,
    incident direction (k, 3), its cosine (k,))``.

    The four share the point's mean cosine of refraction c (the entering-power-weighted mean of cos theta_t, so
    the sources' mean depth is kept); their refracted directions' tangential parts have length sqrt(1 - c^2) and
    point along +e1, -e1, +e2, -e2, the principal axes of the tangential spread (the eigenvectors of the weighted
    mean of a a^T); their powers keep the point's entering power, its mean tangential drift and the ratio of the
    spread along the two axes (docs/physics.md eq. (126)). A point lit from one direction (a sun in the map)
    keeps one sample along it; a point under a uniform sky gets four of equal power. Samples of zero power are
    dropped. ``normals`` (n, 3): the points' unit normals (the frame of :attr:`Incidence.moments`)."""
    mom = inc.moments
    lit = np.flatnonzero(mom[:, 0] > 0.0)
    P = mom[lit, 0]
    c = np.clip(mom[lit, 2] / P, 0.0, 1.0)
    m1, m2 = mom[lit, 3] / P, mom[lit, 4] / P
    s11, s22, s12 = mom[lit, 5] / P, mom[lit, 6] / P, mom[lit, 7] / P
    ang = 0.5 * np.arctan2(2.0 * s12, s11 - s22)          # the first principal axis of the 2 x 2 spread
    ca, sa = np.cos(ang), np.sin(ang)
    lam1 = ca * ca * s11 + 2.0 * ca * sa * s12 + sa * sa * s22
    lam2 = sa * sa * s11 - 2.0 * ca * sa * s12 + ca * ca * s22
    tot = lam1 + lam2
    frac = np.where(tot > 0.0, lam1 / np.where(tot > 0.0, tot, 1.0), 1.0)
    st = np.sqrt(np.clip(1.0 - c * c, 0.0, None))
    safe = np.where(st > 0.0, st, 1.0)
    q1 = np.where(st > 0.0, (ca * m1 + sa * m2) / safe, 0.0)
    q2 = np.where(st > 0.0, (-sa * m1 + ca * m2) / safe, 0.0)
    share = np.clip(np.stack([frac + q1, frac - q1, 1.0 - frac + q2, 1.0 - frac - q2], axis=1) / 2.0, 0.0, None)
    share /= share.sum(axis=1, keepdims=True)
    nv = np.asarray(normals, dtype=np.float64)[lit]
    t1, t2 = tangent_frames(np.asarray(normals, dtype=np.float64))
    e1 = ca[:, None] * t1[lit] + sa[:, None] * t2[lit]
    e2 = -sa[:, None] * t1[lit] + ca[:, None] * t2[lit]
    axes = np.stack([e1, -e1, e2, -e2], axis=1)                         # (l, 4, 3)
    tangent = axes * (st * eta)[:, None, None]                          # outside: eta sin(theta_t)
    sn = np.linalg.norm(tangent, axis=2, keepdims=True)
    tangent *= np.minimum(1.0, (1.0 - 1e-12) / np.maximum(sn, 1e-300))
    cos_i = np.sqrt(np.clip(1.0 - np.einsum("ijk,ijk->ij", tangent, tangent), 0.0, 1.0))
    d = tangent - cos_i[..., None] * nv[:, None, :]
    keep = share > 0.0
    point = np.repeat(lit, 4).reshape(-1, 4)
    return point[keep], (P[:, None] * share)[keep], d[keep], cos_i[keep]
