"""The hierarchical transport: exitance from vertex sources at a cost near-linear in the vertex count.

The direct sum (transport="direct", transport/baking.py) pays an exact geodesic and a kernel value for every
(source, vertex) pair within the cutoff: O(N x disc) pairs, N^2 on a mesh refined at fixed size. Here every
vertex v is a potential source with the power Phi_v its light gives it, and the exitance splits by the chord
distance of each pair (docs/physics.md §9.1, eq. (71)):

* **near zone** — pairs within a few patch radii of the source (``r_near(u) = near_patch_radii * a_u``, a_u the
  radius of the source's dual patch; chord <= r_near(u), found by a geodesic query to 1.1 r_near(u), so pairs
  across a fold are dropped): the model's own kernel (PairKernel, exact or arc geodesics, the patch average of
  eq. (58)), computed once per mesh and material into a sparse matrix per channel, ``M_near = W Phi``;
* **far zone** — every other pair within the cutoff: a k-d tree of the lit sources per kernel kind, traversed
  per receiver (surface/hierarchy_loops.py). A cluster of radius a at distance d >= a/theta is replaced by
  four sigma points carrying its zeroth to second moments, with its mean normal and mean shape operator (the
  kernel stays expanded at the source, as in the direct sum); closer clusters are opened, and leaves are summed
  pair by pair. Surface distances of far pairs are arcs from the chord and the two normals (eq. (59)).

Cost: the near zone is O(N) pairs (about 25 per vertex at 5 patch radii); a receiver visits O(log(cutoff/r_near)
/ theta^2) clusters, so the far field is O(N log N). :class:`SurfaceTransport` holds everything that depends
only on the mesh, material and model (curvatures, frames, the auto plan, the near-zone matrices, the trees), so
that each further light, frame or bake costs only its rays, one sparse product and one traversal.

Pure array work; no I/O.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError, ParameterError
from meshshade.geometry.curvature import principal_curvatures
from meshshade.kernels.dipole import dipole_profile
from meshshade.materials import Material
from meshshade.pacing import Pacer, default_threads, run_paced
from meshshade.progress import Progress
from meshshade.surface.auto import AutoPlan, neighbourhood_curvature, plan_sources
from meshshade.surface.farfield import _receiver_order
from meshshade.surface.farfield_loops import kd_permutation, node_ranges, tree_depth
from meshshade.surface.hierarchy_loops import (FAR_TRAVERSE, Clusters, FarFactors, Opening, TreeSources,
                                                   cluster_geometry)
from meshshade.surface.kernel_evaluation import kernel_params
from meshshade.surface.medium import SurfaceMedium, surface_medium
from meshshade.surface.models import MODEL_KERNEL, MODELS, Kernel
from meshshade.surface.options import SurfaceOptions, options_from_keywords
from meshshade.surface.source_factors import drift_angles, refracted_drift
from meshshade.surface.pair_kernel import PairKernel, source_frames
from meshshade.surface.patch_average import PATCH_AVERAGE_RADII, patch_average_factor
from meshshade.surface.zones import NEAR_MARGIN, neighbourhood_solver

#: candidate near radii of each source, in radii of its dual patch (>= PATCH_AVERAGE_RADII: the far field is
#: point to point); :func:`far_distance_check` picks the smallest whose far-field distances are good enough
NEAR_PATCH_RADII = (5.0, 7.0, 10.0, 14.0, 20.0)
#: tolerance of the far field's distance model: mean and max over the sampled sources of the error the arcs make in
#: a source's total exitance (:func:`far_distance_check`)
FAR_DISTANCE_TOL = (3e-3, 2e-2)
#: the distance check looks within the radius holding all but CHECK_CUTOFF_TOL of the dipole's total
#: (surface/medium.py) and within the radius holding about this many vertices around a source (time)
CHECK_MAX_PAIRS = 4_000
#: receivers sampled by verify_far_field, and its tolerance (mean, max of the relative error of M). The check
#: measures distances through the planar dipole; the curved kernel is more sensitive to the pair geometry (on bob at
#: 50 mm, skin1, the curved kernel's far field differs from the direct sum's by 3.6 % where this proxy reads 0.55 %),
#: hence a tolerance well below the transport's 0.5 % target (spheres read 0.07 %)
VERIFY_RECEIVERS = 24
VERIFY_TOL = (2e-3, 1e-2)
#: sources sampled by the distance check (exact geodesic queries to the cutoff)
DISTANCE_CHECK_SOURCES = 24
#: opening criterion: a cluster of radius a is used whole at distance d >= a / THETA
THETA = 0.3
#: clusters whose normals spread wider than acos(CONE_MIN) are opened (folds, creases, thin parts)
CONE_MIN = 0.8
#: sources per leaf of the trees
LEAF_SIZE = 16
#: the most receivers per traversal call (calls are paced to about pacing.BLOCK_SECONDS; progress and Ctrl-C
#: between calls)
RECEIVER_BLOCK = 16384
#: seconds per receiver of the far-field traversal assumed before a call has been timed (pacing.Pacer's prior): about
#: 0.4 ms on one thread on a pebble of 41k vertices under a directional light, less on smaller meshes
PRIOR_SECONDS_PER_RECEIVER = 4e-4


class FarFieldUnsupported(MeshshadeError):
    """The far field's distance model is not accurate enough on this mesh at any candidate near radius.

    ``check`` holds :func:`far_distance_check`'s measurements."""

    def __init__(self, check: dict):
        self.check = check
        worst = check["errors"][-1]
        super().__init__(f"the hierarchical far field's arc distances are not accurate on this mesh (error of a "
                         f"source's exitance: mean {worst['mean']:.3g}, max {worst['max']:.3g} at "
                         f"{worst['near_patch_radii']:g} patch radii; tolerance {FAR_DISTANCE_TOL[0]:g} / "
                         f"{FAR_DISTANCE_TOL[1]:g}); use the direct transport")


def arc_distances(chord, k_chord):
    """Array twin of :func:`~meshshade.surface.hierarchy_loops.arc_length` (the far field's surface distance)."""
    w = np.minimum(np.abs(k_chord), 1.0)
    return np.where(w < 1e-4, chord * (1.0 + w * w / 6.0), chord * np.arcsin(w) / np.maximum(w, 1e-300))


def _exact_and_arc(mesh, idx, rmax):
    """For each vertex x of ``idx``: ``(i, x, cand, s, chord, arc)`` over the vertices ``cand`` within the chord
    ``rmax`` of x: exact geodesic distances ``s`` (inf beyond the geodesic radius rmax), chords and the far
    field's arcs (eq. (59), normals of both ends). One exact query for all of ``idx``; distances are symmetric."""
    V, N = mesh.vertices, mesh.vertex_normals
    nb = neighbourhood_solver("exact", mesh).query(V[idx], np.full(idx.size, -1), np.full((idx.size, 3), np.nan),
                                                    idx, N[idx], rmax)
    src = nb.source_index()
    ball = cKDTree(V).query_ball_point(V[idx], rmax)
    dist = np.full(mesh.n_vertices, np.inf)
    for i, x in enumerate(idx):
        mine = src == i
        dist[nb.vertex[mine]] = nb.distance[mine]
        dist[x] = 0.0
        cand = np.asarray(ball[i], dtype=np.int64)
        s = dist[cand]
        dist[nb.vertex[mine]] = np.inf
        chord = np.linalg.norm(V[cand] - V[x], axis=1)
        kc = np.einsum("ij,ij->i", N[x] - N[cand], V[x] - V[cand]) / np.maximum(chord, 1e-300) * 0.5
        yield i, x, cand, s, chord, arc_distances(chord, kc)


def _dipole_mm(material: "Material | SurfaceMedium", c: int, r):
    """The planar dipole of channel c at distances r [mm] (inf allowed: 0), 1/mm^2."""
    ch = material.channel(c)
    st = ch["sigma_t_prime"]
    R = dipole_profile(np.where(np.isfinite(r), r, 0.0) * st, albedo_prime=ch["albedo_prime"], eta=ch["eta"]) * st * st
    return np.where(np.isfinite(r), R, 0.0)


def far_distance_check(mesh, medium: SurfaceMedium, cut, patch, *, candidates=NEAR_PATCH_RADII,
                       n_sources: int = DISTANCE_CHECK_SOURCES, tol=FAR_DISTANCE_TOL, seed: int = 0) -> dict:
    """Measure the far field's distance model on ``mesh`` and pick the near radius (in patch radii).

    The far field takes the surface distance of a pair from its chord and normals (arc, docs/physics.md
    eq. (59)); the direct sum takes exact polyhedral geodesics within the cutoff (pairs across a fold, close in
    space but far along the surface, never count). For ``n_sources`` vertices (seeded) the exact geodesics to the
    cutoff and every vertex within the cutoff's chord are compared, per channel, through the planar dipole:

        e_u(f) = |sum_{chord > f a_u, arc <= cut} R(arc) - sum_{chord > f a_u, s <= cut} R(s)| / sum_{s <= cut} R(s),

    the error the far field's distances make in the exitance a lit source u causes (its patch radius a_u),
    were its far pairs summed exactly. The smallest candidate f with mean_u e_u <= tol[0] and max_u e_u <= tol[1]
    (worst channel) is chosen. The comparison covers the pairs within the radius holding all but CHECK_CUTOFF_TOL
    of the dipole's total and about CHECK_MAX_PAIRS vertices (``radius_mm``). Returns ``{"near_patch_radii": f or
    None, "radius_mm": ..., "errors": [{"near_patch_radii", "mean", "max"}, ...]}`` (one row per candidate tried).
    """
    n = mesh.n_vertices
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(n, size=min(n, n_sources), replace=False))
    cut = np.minimum(cut, medium.check_cutoff_mm)  # the part of the kernel that matters
    # and at most about CHECK_MAX_PAIRS exact geodesics per source (window propagation slows down on fine meshes)
    cut = np.minimum(cut, np.sqrt(CHECK_MAX_PAIRS * np.median(mesh.vertex_areas) / np.pi))
    rmax = float(np.max(cut))
    err = np.zeros((len(candidates), idx.size, 3))
    for i, u, cand, s, chord, arc in _exact_and_arc(mesh, idx, rmax):
        for c in range(3):
            Rs = np.where(s <= cut[c], _dipole_mm(medium, c, s), 0.0)
            Ra = np.where(arc <= cut[c], _dipole_mm(medium, c, arc), 0.0)
            tot = Rs.sum()
            for j, f in enumerate(candidates):
                far = chord > f * patch[u]
                err[j, i, c] = abs(Ra[far].sum() - Rs[far].sum()) / tot if tot > 0 else 0.0
    rows = []
    for j, f in enumerate(candidates):
        worst = err[j].max(axis=1)
        rows.append({"near_patch_radii": float(f), "mean": float(worst.mean()), "max": float(worst.max())})
        if rows[-1]["mean"] <= tol[0] and rows[-1]["max"] <= tol[1]:
            return {"near_patch_radii": float(f), "radius_mm": rmax, "errors": rows}
    return {"near_patch_radii": None, "radius_mm": rmax, "errors": rows}


class VertexSources:
    """Every vertex as a potential entry sample (the geometry of EntrySamples' vertex samples)."""

    def __init__(self, mesh):
        n = mesh.n_vertices
        self.positions = mesh.vertices
        self.normals = mesh.vertex_normals
        self.vertex = np.arange(n, dtype=np.int64)
        self.face = np.full(n, -1, dtype=np.int64)
        self.bary = np.full((n, 3), np.nan)

    def __len__(self) -> int:
        return len(self.vertex)


@dataclass(frozen=True, eq=False)
class _Tree:
    rows: np.ndarray      # vertex index of each tree row
    lo: np.ndarray
    hi: np.ndarray
    depth: int

    @property
    def first_leaf(self) -> int:
        return (1 << self.depth) - 1


@dataclass(eq=False)
class SurfaceTransport:
    """What the hierarchical transport of one mesh, material and model reuses across lights and frames.

    Build with :meth:`build`; :meth:`exitance` maps vertex-sample powers to exitance. Attributes: ``mesh``,
    ``medium`` (the :class:`~meshshade.surface.medium.SurfaceMedium` it was built for; ``material`` its material),
    ``model``; ``curvature`` (PrincipalCurvatures of the vertices); ``frames`` (SourceFrames of
    every vertex); ``plan`` (AutoPlan per vertex for ``model="auto"``, else None); ``kind`` (n,) int8 kernel
    per vertex as a source (models.Kernel); ``cutoff_mm`` (3,); ``near_mm`` (n,) near radius per
    source; ``near`` the sparse near-zone matrices per computed channel (receiver rows, source columns,
    1/mm^2 with the patch average); ``timings`` and ``stats`` of the build.
    """

    mesh: object
    medium: SurfaceMedium
    model: str
    curvature: object
    frames: object
    plan: object
    kind: np.ndarray
    cutoff_mm: np.ndarray
    near_mm: np.ndarray
    patch_mm: np.ndarray
    channels: list
    near: dict
    theta: float
    trees: dict
    shape: np.ndarray
    sphere_row: np.ndarray
    log_radius: np.ndarray
    params: object
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    #: the source model, "point" or "beam" (surface/source_factors.py: with "beam" the near matrices and every far
    #: pair carry the near-field factor N(s) of eq. (80))
    source_model: str = "point"
    #: with the source model "beam": the near pairs' sources, distances and azimuths (:class:`NearPairs`) for the
    #: drift factor of each light; None otherwise
    near_pairs: object = None

    @property
    def material(self) -> Material:
        """The material the transport was built for."""
        return self.medium.material

    # ------------------------------------------------------------------------------------------------ build
    @classmethod
    def build(cls, mesh, material: "Material | SurfaceMedium", model: str = "auto",
              options: SurfaceOptions | None = None, *, curvature=None, theta: float = THETA, near_patch_radii: float | None = None,
              progress: bool | str = False, **deprecated) -> "SurfaceTransport":
        """The geometric work for ``mesh`` (a Mesh in mm), ``material`` and ``model`` (one of MODELS).
        ``material``: a Material, or the :class:`~meshshade.surface.medium.SurfaceMedium` a bake made of it (made
        here from the options otherwise).

        ``options`` (:class:`~meshshade.surface.options.SurfaceOptions`, default ones for None): its ``geodesic``
        ("exact" or "arc": the near zone's geodesics; with ``auto``, exact where the plan asks for it and "exact"
        is allowed), ``cutoff_tol``, ``curvature_radius_mm``, ``rtol``, ``auto`` and ``source_model`` ("point", the
        default, or "beam": surface/source_factors.py, the near matrices and the far field's pairs carry the
        near-field factor N(s)). ``curvature``: PrincipalCurvatures of the mesh, if already computed. ``theta`` in
        (0, 1): the clusters' opening criterion. ``near_patch_radii`` (>= 4, or None): the near radius in patch
        radii; None lets :func:`far_distance_check` choose it from NEAR_PATCH_RADII on this mesh, and raises
        :class:`FarFieldUnsupported` when none of them makes the far field's distances accurate enough (bake's
        ``transport="auto"`` then uses the direct sum). The former keywords (``geodesic``, ``cutoff_tol``,
        ``curvature_radius_mm``, ``auto_options``, ``rtol``, ``source_model``, ``near_field``) are accepted with a
        DeprecationWarning.
        """
        options = options_from_keywords(options, deprecated, "SurfaceTransport.build")
        source_model = options.source_model or "point"
        geodesic, rtol = options.geodesic, options.rtol
        if model not in MODELS:
            raise ParameterError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
        if not 0.0 < float(theta) < 1.0:
            raise ParameterError(f"theta (cluster opening criterion) must lie in (0, 1), got {theta!r}")
        if near_patch_radii is not None and not PATCH_AVERAGE_RADII <= float(near_patch_radii) <= 1e3:
            raise ParameterError(f"near_patch_radii must lie in [{PATCH_AVERAGE_RADII:g}, 1000], "
                                 f"got {near_patch_radii!r}")
        timings: dict = {}
        t0 = time.perf_counter()
        curv = curvature if curvature is not None else principal_curvatures(
            mesh.vertices, mesh.faces, radius_mm=options.curvature_radius_mm)
        timings["curvature"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        src = VertexSources(mesh)
        frames = source_frames(src, curv, mesh.faces)
        n = mesh.n_vertices
        medium = surface_medium(material, options, source_model)
        cut = np.minimum(medium.cutoff_mm, mesh.scale)
        patch = np.sqrt(mesh.vertex_areas / np.pi)
        check = None
        if near_patch_radii is None:
            check = far_distance_check(mesh, medium, cut, patch)
            timings["distance check"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            if check["near_patch_radii"] is None:
                raise FarFieldUnsupported(check)
            near_patch_radii = check["near_patch_radii"]
        near_mm = np.minimum(near_patch_radii * patch, cut.max())
        plan = None
        if model == "auto":
            vals = np.stack([np.maximum(np.abs(curv.k1), np.abs(curv.k2)), -curv.k2], axis=1)
            kn_near, kn_far = neighbourhood_curvature(src, vals, mesh.vertices, mesh.faces,
                                                      [NEAR_MARGIN * near_mm, cut.max()], mesh.mean_edge_length)
            plan = plan_sources(frames.k1, frames.k2, kn_near[:, 0], kn_far[:, 0], medium, NEAR_MARGIN * near_mm,
                                cut, kmin_far=-kn_far[:, 1], **options.auto.keywords())
        H = 0.5 * (frames.k1 + frames.k2)
        kind = (np.asarray(plan.kernel, dtype=np.int8) if model == "auto"
                else np.full(n, MODEL_KERNEL[model], dtype=np.int8))
        if model == "exact-sphere":   # not convex: the chord dipole, a tree of its own
            kind[H <= 0] = Kernel.DIPOLE_CHORD
        timings["plan"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        sphere = medium.sphere
        sph_row = np.full(n, -1, dtype=np.int64)
        sph_row[kind == Kernel.EXACT_SPHERE] = sphere.rows(H[kind == Kernel.EXACT_SPHERE])
        logr = np.where(sph_row >= 0, np.log(sphere.r0[np.maximum(sph_row, 0)] if sphere.r0.size else 1.0), 0.0)
        params = kernel_params(medium, cut, sphere)
        timings["sphere tables"] = time.perf_counter() - t0
        factors = medium.near
        # the near matrices read the same tables as the far field (no series at single pairs)
        kernel = PairKernel(model, medium, frames, rtol=rtol, plan=plan, near=factors, params=params,
                            sphere=sphere, sphere_series_pairs=0)
        kernel.pair_points = (src.positions, mesh.vertices, mesh.vertex_normals, curv.k1, curv.k2, curv.d1)
        t0 = time.perf_counter()
        if model == "auto":
            exact = plan.exact_geodesic & (geodesic == "exact")
        else:
            exact = np.full(n, geodesic == "exact")
        near, near_pairs, nstats = _near_matrices(mesh, src, frames, kernel, exact, near_mm, patch, progress)
        timings["near zone"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        shape = _shape_operators(frames)
        trees = {}
        for k in np.unique(kind):
            rows = np.flatnonzero(kind == k)
            depth = int(tree_depth(max(rows.size, 1), LEAF_SIZE))
            lo, hi = node_ranges(rows.size, depth)
            perm = kd_permutation(np.ascontiguousarray(mesh.vertices[rows]), depth, lo, hi)
            trees[int(k)] = _Tree(rows[perm], lo, hi, depth)
        timings["trees"] = time.perf_counter() - t0
        stats = {"near_pairs": nstats["pairs"], "near_pairs_exact_geodesic": nstats["exact_pairs"],
                 "near_mm_median": float(np.median(near_mm)), "near_patch_radii": float(near_patch_radii),
                 **({"far_distance_error": check["errors"]} if check else {}),
                 **{f"sources_{k.name.lower()}": int((kind == k).sum()) for k in Kernel}}
        if model == "exact-sphere":
            stats["exact_sphere_fallback_dipole"] = int((H <= 0).sum())
        return cls(mesh, medium, model, curv, frames, plan, kind, cut, near_mm, patch, kernel.channels, near,
                   float(theta), trees, shape, sph_row, logr, params, timings, stats, source_model, near_pairs)

    # ------------------------------------------------------------------------------------------------ use
    def sample_plan(self, samples):
        """The auto plan per entry sample (that of its vertex; rows of point samples are placeholders), or None."""
        if self.plan is None:
            return None
        v = np.maximum(samples.vertex, 0)
        return AutoPlan(self.plan.kernel[v], self.plan.exact_geodesic[v], self.plan.far_dipole[v])

    def exitance(self, vertex_power, *, drift=None, progress: bool | str = False) -> tuple[np.ndarray, dict]:
        """Exitance M (n, 3) [W/mm^2] of the vertex sources with powers ``vertex_power`` (n,) W (0 where unlit),
        or (n, 3) per channel (the near field's incidence scale makes them differ: one pass per distinct column),
        and stats (timings, cluster and pair counts). ``drift`` (n, 3) or None (only with the near field "beam"):
        each vertex's refracted tangential direction (near_field.refracted_drift, power-weighted over its lights:
        :func:`vertex_drift`); its light then drifts sideways by drift / sigma_t' (docs/physics.md §13.4): the
        near pairs and the far field's pairs and clusters carry the drift factor of eq. (88), one pass per channel."""
        mesh = self.mesh
        n = mesh.n_vertices
        pv = np.asarray(vertex_power, dtype=np.float64)
        if drift is not None:
            if self.near_pairs is None:
                raise ParameterError("a light's drift needs a transport built with source_model='beam'")
            drift = np.asarray(drift, dtype=np.float64)
            if drift.shape != (n, 3) or not np.all(np.isfinite(drift)):
                raise ParameterError(f"drift must be a finite (n, 3) = ({n}, 3) array")
            if pv.ndim == 1:
                pv = np.repeat(pv[:, None], 3, axis=1)
        if pv.ndim == 2 and pv.shape == (n, 3):
            st = np.asarray(self.medium.sigma_t_prime, dtype=np.float64)

            def alike(k, c):
                return np.array_equal(pv[:, k], pv[:, c]) and (drift is None or st[k] == st[c])

            M = np.zeros((n, 3))
            stats: dict = {"far_pairs": 0, "far_clusters": 0, "timings": {}}
            done: list = []
            for c in range(3):
                j = next((k for k in done if alike(k, c)), None)
                if j is not None:
                    M[:, c] = M[:, j]
                    continue
                done.append(c)
                Mc, sc = self._exitance(pv[:, c], None if drift is None else (c, drift), progress)
                same = [k for k in range(3) if alike(k, c)]
                M[:, same] = Mc[:, same]
                stats["far_pairs"] += sc["far_pairs"]
                stats["far_clusters"] += sc["far_clusters"]
                for k, v in sc["timings"].items():
                    stats["timings"][k] = stats["timings"].get(k, 0.0) + v
            return M, stats
        return self._exitance(pv, None, progress)   # checks the (n,) powers

    def _exitance(self, pv, drift, progress):
        """:meth:`exitance` of one power column ``pv`` (n,); ``drift``: None or (channel, (n, 3) drift), which
        makes only that channel's column right."""
        mesh = self.mesh
        n = mesh.n_vertices
        if pv.shape != (n,) or not np.all(np.isfinite(pv)) or np.any(pv < 0):
            raise ParameterError(f"vertex_power must be a finite (n,) = ({n},) array >= 0 [W]")
        chan = None
        dslope, dlog0, dlogstep, dst = np.zeros(0), 0.0, 1.0, 1.0
        nlog = np.zeros((3, 0))
        if self.source_model == "beam":   # the near field's factor N(s) on every far pair (eq. (80))
            factors = self.medium.near
            nlog = factors.log_ratio_table()
            _, dlog0, dlogstep = factors.slope_table(0)
        if drift is not None:
            chan, d = drift
            dst = float(self.medium.sigma_t_prime[chan])
            d_mm = d / dst    # the drift in mm (eq. (87))
            sin_t, psi = drift_angles(d, self.frames.d1, self.frames.d2)
            dslope, dlog0, dlogstep = self.medium.near.slope_table(chan)
        timings: dict = {}
        t0 = time.perf_counter()
        M = np.zeros((n, 3))
        for c, same in self.channels:
            W = self.near[c]
            if chan is not None and chan in same:   # this light's drift factor on every near pair (eq. (88))
                P = self.near_pairs
                W = W.copy()
                W.data *= self.medium.near.drift_factor(
                    chan, P.s, self.patch_mm[P.source], sin_t[P.source], np.cos(P.phi - psi[P.source]))
            m = W @ pv
            for cc in same:
                M[:, cc] = m
        timings["near zone"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        rep = np.arange(3)
        for c, same in self.channels:
            rep[same] = c
        recv = mesh.vertices
        rnrm = mesh.vertex_normals
        order = _receiver_order(recv)
        counts = np.zeros(2, dtype=np.int64)
        lit_trees = []
        for k, tree in self.trees.items():
            power = np.ascontiguousarray(pv[tree.rows])
            if not np.any(power > 0):
                continue
            r = tree.rows
            geo = Clusters(*cluster_geometry(
                np.ascontiguousarray(mesh.vertices[r]), np.ascontiguousarray(self.frames.normals[r]),
                np.ascontiguousarray(self.shape[r]), power, np.ascontiguousarray(self.patch_mm[r]),
                np.ascontiguousarray(self.near_mm[r]), np.ascontiguousarray(self.sphere_row[r]),
                np.ascontiguousarray(self.log_radius[r]), tree.lo, tree.hi))
            lit_trees.append((k, tree, power, geo))
        timings["clusters"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        bar = Progress(progress if isinstance(progress, str) else "bake", n * max(len(lit_trees), 1), "receivers",
                       enabled=bool(progress) and bool(lit_trees))
        with bar:
            opening = Opening(self.cutoff_mm, self.theta, CONE_MIN)
            for k, tree, power, geo in lit_trees:
                r = tree.rows
                sources = TreeSources(np.ascontiguousarray(mesh.vertices[r]),
                                     np.ascontiguousarray(self.frames.normals[r]), np.ascontiguousarray(self.shape[r]),
                                     power, np.ascontiguousarray(self.near_mm[r]),
                                     np.ascontiguousarray(self.sphere_row[r]), tree.lo, tree.hi, tree.first_leaf)
                far = FarFactors(*_drift_args(None if chan is None else d_mm[r], power, tree), dslope, dlog0,
                                 dlogstep, dst, nlog)
                traverse = FAR_TRAVERSE[int(k)]
                done = [0]

                def block(a, b, traverse=traverse, sources=sources, geo=geo, far=far):
                    return traverse(recv, rnrm, order[a:b], sources, geo, opening, rep, self.params, far)

                def advance(d, _total, done=done):
                    bar.update(d - done[0])
                    done[0] = d

                # blocks of receivers of about pacing.BLOCK_SECONDS on the worker threads (Ctrl-C between blocks)
                pacer = Pacer(np.ones(n), prior=PRIOR_SECONDS_PER_RECEIVER, min_block=64, max_block=RECEIVER_BLOCK)
                res = run_paced(block, pacer, n, n_threads=default_threads(), progress=advance)
                M[order] += np.concatenate([r[0] for r in res])
                counts += np.concatenate([r[1] for r in res]).sum(axis=0)
        timings["far field"] = time.perf_counter() - t0
        stats = {"far_pairs": int(counts[0]), "far_clusters": int(counts[1]), "timings": timings}
        return M, stats


def _shape_operators(frames) -> np.ndarray:
    """(n, 6) shape operator k1 d1 d1^T + k2 d2 d2^T as (xx, yy, zz, xy, xz, yz), 1/mm."""
    d1, d2, k1, k2 = frames.d1, frames.d2, frames.k1[:, None], frames.k2[:, None]
    S = np.empty((len(d1), 6))
    for q, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        S[:, q] = (k1 * d1[:, i:i + 1] * d1[:, j:j + 1] + k2 * d2[:, i:i + 1] * d2[:, j:j + 1])[:, 0]
    return S


def _near_matrices(mesh, src, frames, kernel: PairKernel, exact, near_mm, patch, progress):
    """Sparse near-zone matrices per computed channel: W[v, u] = R(v; u) w_patch for the pairs with chord <=
    near_mm[u] found within geodesic NEAR_MARGIN near_mm[u] of u (exact geodesics where ``exact``, arc elsewhere)."""
    n = mesh.n_vertices
    parts = {c: [] for c, _ in kernel.channels}
    rows_all, cols_all, geo_s, geo_phi = [], [], [], []
    n_pairs = n_exact = 0
    bar = Progress(progress if isinstance(progress, str) else "bake", n, "sources (near zone)",
                   enabled=bool(progress))
    with bar:
        for method, sel_all in (("exact", np.flatnonzero(exact)), ("arc", np.flatnonzero(~exact))):
            if sel_all.size == 0:
                continue
            solver = neighbourhood_solver(method, mesh)
            per_source = np.pi * (NEAR_MARGIN * near_mm[sel_all]) ** 2 / np.maximum(mesh.vertex_areas[sel_all], 1e-300)
            chunk = max(256, int(4_000_000 // max(1.0, float(np.mean(per_source)))))
            for a in range(0, sel_all.size, chunk):
                sel = sel_all[a:a + chunk]
                done = [0]

                def credit(k, total, done=done):
                    bar.update(k - done[0])
                    done[0] = k
                nb = solver.query(src.positions[sel], src.face[sel], src.bary[sel], src.vertex[sel],
                                  frames.normals[sel], NEAR_MARGIN * near_mm[sel], d1=frames.d1[sel],
                                  d2=frames.d2[sel], k1=frames.k1[sel], k2=frames.k2[sel], progress=credit)
                s_idx = sel[nb.source_index()]
                vtx = nb.vertex.astype(np.int64)
                keep = nb.chord <= near_mm[s_idx]
                s_idx, vtx, s, chord, phi = s_idx[keep], vtx[keep], nb.distance[keep], nb.chord[keep], nb.phi[keep]
                phi = np.where(np.isfinite(phi), phi, 0.0)  # a degenerate frame (normals that cancel): any azimuth
                for c, _ in kernel.channels:
                    R = kernel.evaluate(c, s_idx, s, chord, phi, vtx)
                    a_p = patch[s_idx]
                    close = np.flatnonzero(s < PATCH_AVERAGE_RADII * a_p)
                    if close.size:
                        ch = kernel.material.channel(c)
                        R[close] *= patch_average_factor(s[close], a_p[close], albedo_prime=ch["albedo_prime"],
                                                         eta=ch["eta"], sigma_t_prime=ch["sigma_t_prime"])
                    if kernel.near_factors is not None:
                        R *= kernel.near_factors.pair_factor(c, s, a_p)
                    parts[c].append(R)
                rows_all.append(vtx)
                cols_all.append(s_idx)
                if kernel.near_factors is not None:   # the drift factor (eq. (88)) needs each pair's s and phi
                    geo_s.append(s.astype(np.float32))
                    geo_phi.append(phi.astype(np.float32))
                n_pairs += vtx.size
                n_exact += vtx.size if method == "exact" else 0
                bar.update(sel.size - done[0])
    rows = np.concatenate(rows_all) if rows_all else np.zeros(0, np.int64)
    cols = np.concatenate(cols_all) if cols_all else np.zeros(0, np.int64)
    near = {}
    for c, _ in kernel.channels:
        vals = np.concatenate(parts[c]) if parts[c] else np.zeros(0)
        near[c] = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    geometry = None
    if kernel.near_factors is not None:
        # the CSR order of the pairs (each (receiver, source) pair occurs once): the drift factor is computed in
        # pair order and permuted into the matrices' data
        order = sp.csr_matrix((np.arange(1, rows.size + 1, dtype=np.float64), (rows, cols)), shape=(n, n))
        perm = order.data.astype(np.int64) - 1
        cat = (lambda parts_: np.concatenate(parts_) if parts_ else np.zeros(0, np.float32))
        geometry = NearPairs(cols[perm].astype(np.int32), cat(geo_s)[perm], cat(geo_phi)[perm])
    return near, geometry, {"pairs": int(n_pairs), "exact_pairs": int(n_exact)}


@dataclass(frozen=True)
class NearPairs:
    """The near matrices' pairs in their CSR data order: source vertex (nnz,) int32, geodesic distance s (mm) and
    azimuth phi in the source frame (rad), float32 (12 bytes per pair, a third of the three channels' matrices):
    what the drift factor of eq. (88) needs per light."""

    source: np.ndarray
    s: np.ndarray
    phi: np.ndarray


def verify_far_field(core: "SurfaceTransport", M, vertex_power, *, n_receivers: int = VERIFY_RECEIVERS,
                     seed: int = 0) -> dict:
    """Check the far field's arc distances on the lit configuration itself, at sampled receivers.

    For ``n_receivers`` vertices (seeded, among those with M above 1e-3 of each channel's peak) the far pairs'
    contribution is summed twice through the planar dipole of the surface distance, with the arcs the far field
    uses and with exact geodesics (a receiver's query; distances are symmetric), weighted by the actual source
    powers:  e_x = |sum_far Phi_u R(arc) - sum_far Phi_u R(s)| / M(x). Pairs within the cutoff's chord but beyond
    its geodesic (across a fold) count only in the first sum. Returns ``{"mean", "max", "receivers"}``, the worst
    channel's mean and max of e_x (pairs within the cutoff and about CHECK_MAX_PAIRS vertices of the receiver).
    Where shadowed receivers see light only from across a gap, this is what the
    source-side :func:`far_distance_check` cannot see.
    """
    mesh = core.mesh
    pv = np.asarray(vertex_power, dtype=np.float64)
    lit = np.flatnonzero(np.all(M > 1e-3 * M.max(axis=0), axis=1))
    if lit.size == 0:
        return {"mean": 0.0, "max": 0.0, "receivers": 0}
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(lit, size=min(lit.size, n_receivers), replace=False))
    # within the cutoff and about CHECK_MAX_PAIRS vertices of each receiver (time, as far_distance_check)
    cut = np.minimum(core.cutoff_mm, np.sqrt(CHECK_MAX_PAIRS * np.median(mesh.vertex_areas) / np.pi))
    err = np.zeros((idx.size, 3))
    for i, x, cand, s, chord, arc in _exact_and_arc(mesh, idx, float(np.max(cut))):
        far = (chord > core.near_mm[cand]) & (pv[cand] > 0)
        for c in range(3):
            a = (pv[cand] * np.where(arc <= cut[c], _dipole_mm(core.medium, c, arc), 0.0))[far].sum()
            b = (pv[cand] * np.where(s <= cut[c], _dipole_mm(core.medium, c, s), 0.0))[far].sum()
            err[i, c] = abs(a - b) / M[x, c] if M[x, c] > 0 else 0.0
    worst = err.max(axis=1)
    return {"mean": float(worst.mean()), "max": float(worst.max()), "receivers": int(idx.size)}


def vertex_power(samples, n_vertices: int, scale=None) -> np.ndarray:
    """(n,) W: the power of the vertex samples of ``samples`` (EntrySamples) summed per vertex (several lights);
    with ``scale`` (k, 3) per sample and channel, (n, 3): the powers times it."""
    at_v = samples.vertex >= 0
    if scale is None:
        return np.bincount(samples.vertex[at_v], weights=samples.power[at_v], minlength=n_vertices)
    return np.stack([np.bincount(samples.vertex[at_v], weights=samples.power[at_v] * scale[at_v, c],
                                 minlength=n_vertices) for c in range(3)], axis=1)


def _drift_args(drift_rows, power, tree):
    """(drift (k, 3) mm in tree order, its power-weighted mean per node (nodes, 3)) for far_traverse; zero-size
    placeholders without a drift."""
    if drift_rows is None:
        return np.zeros((1, 3)), np.zeros((1, 3))
    w = power[:, None] * drift_rows
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(w, axis=0)])
    cp = np.concatenate([[0.0], np.cumsum(power)])
    tot = cp[tree.hi] - cp[tree.lo]
    node = (cs[tree.hi] - cs[tree.lo]) / np.where(tot > 0, tot, 1.0)[:, None]
    return np.ascontiguousarray(drift_rows), np.ascontiguousarray(node)


def vertex_drift(samples, n_vertices: int, eta: float) -> np.ndarray:
    """(n, 3): each vertex's refracted tangential direction (near_field.refracted_drift) averaged over the vertex
    samples of ``samples`` at it, weighted by their power (several lights at one vertex: to first order the drift
    of their sum is the power-weighted mean); zero where no light enters."""
    at_v = samples.vertex >= 0
    v = refracted_drift(samples.normals[at_v], samples.directions[at_v], eta)
    w = samples.power[at_v]
    num = np.stack([np.bincount(samples.vertex[at_v], weights=w * v[:, k], minlength=n_vertices) for k in range(3)],
                   axis=1)
    den = np.bincount(samples.vertex[at_v], weights=w, minlength=n_vertices)
    return np.where(den[:, None] > 0, num / np.where(den > 0, den, 1.0)[:, None], 0.0)
