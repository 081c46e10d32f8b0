"""Transport: per-vertex radiant exitance M(x_o) = sum_i Phi_i R(x_o; x_i) over entry samples (the bake).

The kernel is expanded at the entry point x_i (physics.md f): rho is the geodesic distance from x_i to x_o,
phi the direction of x_o in x_i's tangent plane from x_i's first principal direction, and k1, k2 are x_i's
principal curvatures. Models:

* ``dipole``: Jensen's usage, R_d(|x_o - x_i|) (chord distance);
* ``curved``: the first-order k1/k2 kernel with its positivity policy (kernels/curvature.py);
* ``exact-sphere``: the exact sphere series with the local radius 2/(k1 + k2) (for validation on spheres;
  where the surface is not convex it falls back to the dipole and counts it);
* ``auto``: per entry sample the cheapest of these that the scene calls for, and exact or arc geodesics
  (meshshade/transport/auto.py; the decisions are counted in ``stats``).

Each entry sample reaches the vertices within a cutoff radius chosen per channel from the dipole's closed-form
tail (the reflectance beyond it is below ``cutoff_tol`` of the total). Sources are processed in chunks so that
memory stays bounded; the gather per chunk is vectorised (``np.bincount``), never a Python loop over vertices.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.kernels.dipole import dipole_cutoff_radius, dipole_profile
from meshshade.materials import Material
from meshshade.transport.zones import NEAR_MARGIN, ZONES, assign_zones, cluster_geometry, clusters_pay, neighbourhood_solver

log = logging.getLogger("meshshade")

MODELS = ("dipole", "curved", "exact-sphere", "auto")
#: pairs evaluated per chunk (memory ~ 100 bytes per pair)
PAIRS_PER_CHUNK = 4_000_000


@dataclass(frozen=True)
class SourceFrames:
    """Entry-sample geometry the kernel needs, (k,) or (k, 3) float64: curvatures in 1/mm, unit frames."""

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normals: np.ndarray


def source_frames(samples, curv, faces) -> SourceFrames:
    """Principal curvatures and frames at entry samples: vertex values for vertex samples, barycentric
    interpolation (directions sign-aligned, re-orthogonalised to the sample's normal) inside a triangle."""
    k = len(samples)
    k1, k2 = np.empty(k), np.empty(k)
    d1 = np.empty((k, 3))
    at_v = samples.vertex >= 0
    iv = samples.vertex[at_v]
    k1[at_v], k2[at_v], d1[at_v] = curv.k1[iv], curv.k2[iv], curv.d1[iv]
    tri = ~at_v
    if np.any(tri):
        F = faces[samples.face[tri]]
        b = samples.bary[tri]
        k1[tri] = np.einsum("ij,ij->i", b, curv.k1[F])
        k2[tri] = np.einsum("ij,ij->i", b, curv.k2[F])
        D = curv.d1[F]  # (t, 3, 3): principal directions are defined up to sign: align to corner 0
        sign = np.sign(np.einsum("ijk,ik->ij", D, D[:, 0]))
        sign[sign == 0] = 1.0
        d1[tri] = np.einsum("ij,ijk->ik", b * sign, D)
    n = samples.normals / np.linalg.norm(samples.normals, axis=1, keepdims=True)
    d1 = d1 - np.einsum("ij,ij->i", d1, n)[:, None] * n
    norm = np.linalg.norm(d1, axis=1)
    bad = norm < 1e-12
    if np.any(bad):  # umbilic or failed frame: any tangent direction will do (k1 = k2 there)
        alt = np.where(np.abs(n[bad, 0:1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        d1[bad] = np.cross(n[bad], alt)
        norm[bad] = np.linalg.norm(d1[bad], axis=1)
    d1 /= norm[:, None]
    d2 = np.cross(n, d1)
    return SourceFrames(k1, k2, d1, d2, n)


def cutoff_radii(material: Material, tol: float) -> np.ndarray:
    """(3,) mm: per channel, the radius beyond which the dipole's reflectance is below ``tol`` of its total."""
    out = np.empty(3)
    for c in range(3):
        ch = material.channel(c)
        out[c] = dipole_cutoff_radius(tol, albedo_prime=ch["albedo_prime"], eta=ch["eta"]) / ch["sigma_t_prime"]
    return out


class PairKernel:
    """Evaluates R [mm^-2] of one model and material for arrays of (source, exit) pairs.

    Channels with equal parameters are computed once. For ``exact-sphere`` the series is tabulated once per
    distinct local radius (radii rounded to ``sphere_radius_rtol``) on a fine angle grid and interpolated.
    """

    def __init__(self, model: str, material: Material, frames: SourceFrames, *, rtol: float = 1e-10,
                 sphere_radius_rtol: float = 1e-3, plan=None):
        if model not in MODELS:
            raise MeshshadeError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
        if model == "auto" and plan is None:
            raise ValueError("model 'auto' needs the per-sample plan (meshshade.transport.auto.plan_sources)")
        self.model, self.material, self.frames, self.plan = model, material, frames, plan
        self.channels: list[tuple[int, list[int]]] = []  # (representative channel, channels it stands for)
        seen: dict = {}
        for c in range(3):
            key = (material.albedo_prime[c], material.sigma_t_prime[c])
            if key in seen:
                self.channels[seen[key]][1].append(c)
            else:
                seen[key] = len(self.channels)
                self.channels.append((c, [c]))
        self.stats: dict = {}
        self._tables: dict = {}  # curved: one CurvatureTable per channel
        if model in ("exact-sphere", "auto"):
            H = 0.5 * (frames.k1 + frames.k2)
            convex = H > 0
            radius = np.where(convex, 1.0 / np.where(convex, H, 1.0), 1.0)  # local radius 2/(k1 + k2)
            q = np.where(convex, np.round(np.log(radius) / np.log1p(
                sphere_radius_rtol)), -1).astype(np.int64)
            self._radius_bin = q
            self._sphere_tables: dict = {}
            if model == "exact-sphere":
                self.stats["exact_sphere_fallback_dipole"] = int((~convex).sum())
                self.stats["exact_sphere_radius_bins"] = int(np.unique(q[convex]).size)
        self.rtol = rtol
        self.sphere_radius_rtol = sphere_radius_rtol

    def evaluate(self, c: int, src, s, chord, phi) -> np.ndarray:
        """R [mm^-2] of channel ``c`` for pairs with source indices ``src`` (into the frames), geodesic distance
        ``s`` [mm], chord [mm] and azimuth ``phi`` [rad]."""
        if self.model != "auto":
            return self._evaluate(self.model, c, src, s, chord, phi)
        from meshshade.transport.auto import KERNEL_NAMES  # noqa: PLC0415

        out = np.empty(s.shape)
        kind = self.plan.kernel[src]
        for i, name in enumerate(KERNEL_NAMES):
            m = kind == i
            if np.any(m):  # "dipole" in auto: the planar dipole of the geodesic distance (curved at k = 0)
                out[m] = self._evaluate("dipole-geodesic" if name == "dipole" else name, c, src[m], s[m],
                                        chord[m], phi[m])
        return out

    def _evaluate(self, model, c, src, s, chord, phi):
        ch = self.material.channel(c)
        st, par = ch["sigma_t_prime"], {"albedo_prime": ch["albedo_prime"], "eta": ch["eta"]}
        if model == "dipole":
            return dipole_profile(chord * st, **par) * st * st
        if model == "dipole-geodesic":
            return dipole_profile(s * st, **par) * st * st
        if model == "curved":
            table = self._curvature_table(c, st, par, float(s.max()) if s.size else 0.0)
            f = self.frames
            R, valid = table.profile(s * st, phi, k1_opt=f.k1[src] / st, k2_opt=f.k2[src] / st,
                                     return_validity=True)
            self.stats["curved_pairs_out_of_first_order_range"] = (
                self.stats.get("curved_pairs_out_of_first_order_range", 0) + int((~valid).sum()))
            return R * st * st
        return self._exact_sphere(c, st, par, src, s, chord)

    def _curvature_table(self, c, st, par, s_max):
        """One Chebyshev table of the curvature coefficients per channel, grown when a longer distance shows up."""
        from meshshade.kernels.curvature import CurvatureTable  # noqa: PLC0415

        t = self._tables.get(c)
        if t is None or t.rho_max_opt < s_max * st:
            t = self._tables[c] = CurvatureTable(par["albedo_prime"], par["eta"], max(s_max * st * 1.25, 10.0))
        return t

    def _exact_sphere(self, c, st, par, src, s, chord):
        from meshshade.kernels.sphere import sphere_series_profile  # noqa: PLC0415

        out = np.empty(s.shape)
        bins = self._radius_bin[src]
        flat = bins < 0
        out[flat] = dipole_profile(chord[flat] * st, **par) * st * st
        for b in np.unique(bins[~flat]):
            sel = bins == b
            key = (c, int(b))
            if key not in self._sphere_tables:
                R0 = float(np.exp(b * np.log1p(self.sphere_radius_rtol)))
                theta = np.linspace(0.0, np.pi, 4097)
                vals = sphere_series_profile(theta, R0_opt=R0 * st, rtol=self.rtol, **par) * st * st
                self._sphere_tables[key] = (R0, theta, vals)
            R0, theta, vals = self._sphere_tables[key]
            th = np.clip(s[sel] / R0, 0.0, np.pi)
            if th.size <= theta.size:  # few pairs (a beam): evaluate the series exactly
                out[sel] = sphere_series_profile(th, R0_opt=R0 * st, rtol=self.rtol, **par) * st * st
            else:  # log-linear interpolation; relative error < 1e-5 for R0 >= 1 transport length
                out[sel] = np.exp(np.interp(th, theta, np.log(np.maximum(vals, 1e-300))))
        return out


@dataclass(frozen=True)
class BakeResult:
    """Per-vertex result of :func:`bake`.

    radiance : (n, 3) float64 W/mm^2 — linear radiant exitance per channel (r, g, b)
    k1, k2 : (n,) 1/mm; d1, d2 : (n, 3) — principal curvatures and directions of the mesh
    samples : EntrySamples — where light entered and how much
    beam_distance : (n,) mm or None — geodesic distance of each vertex from the first beam's entry point
                    (inf beyond the neighbourhood)
    cutoff_mm : (3,) — neighbourhood radius per channel
    timings : dict stage -> seconds; stats : dict of counts (pairs, skipped work, fallbacks, auto decisions)
    plan : meshshade.transport.auto.AutoPlan or None — the per-sample decisions of ``model="auto"``
    """

    radiance: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    samples: object
    beam_distance: np.ndarray | None
    cutoff_mm: np.ndarray
    model: str
    material: Material
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    plan: object = None


#: source patches are averaged over (ring average) for pairs closer than this many patch radii
PATCH_AVERAGE_RADII = 4.0


def patch_average_factor(s_mm, a_mm, *, albedo_prime, eta, sigma_t_prime):
    """Ratio of the dipole averaged over a source patch to its point value, for pairs at distance ``s_mm``.

    A vertex sample stands for a patch of radius ``a = sqrt(area/pi)`` lit uniformly; the exitance it causes at
    distance s is the kernel averaged over that patch. Point sampling over-counts badly when the kernel's width
    (~z_r) is below the edge length (the self term alone can exceed the power entering). The average is taken
    over the ring |r - s| <= a with the dipole's closed-form tail T(r) = int_r^inf R_d 2 pi r dr:

        R_bar(s) = [T(max(s - a, 0)) - T(s + a)] / (pi ((s + a)^2 - max(s - a, 0)^2))

    (the exact disc average at s = 0, -> R_d(s) for s >> a). Other models are multiplied by the same ratio
    (curvature changes little across one patch). Returns (k,) float64 > 0.
    """
    from meshshade.kernels.dipole import dipole_tail_reflectance  # noqa: PLC0415

    s = np.asarray(s_mm, dtype=np.float64) * sigma_t_prime
    a = np.asarray(a_mm, dtype=np.float64) * sigma_t_prime
    lo = np.maximum(s - a, 0.0)
    hi = s + a
    kw = {"albedo_prime": albedo_prime, "eta": eta}
    ring = np.pi * (hi * hi - lo * lo)
    with np.errstate(invalid="ignore", divide="ignore"):
        avg = (dipole_tail_reflectance(lo, **kw) - dipole_tail_reflectance(hi, **kw)) / ring
        f = avg / dipole_profile(s, **kw)
    return np.where((a > 0) & np.isfinite(f) & (f > 0), f, 1.0)


def gather(kernel: PairKernel, n_vertices: int, power, cutoff_mm, pairs_iter, source_radius=None,
           chord_cutoff_mm=None) -> tuple[np.ndarray, dict]:
    """Accumulate M[v, c] = sum_i power_i R_c(pair) over the pair chunks yielded by ``pairs_iter``.

    ``pairs_iter`` yields ``(src, vertex, s, chord, phi)`` arrays (src indexes ``power`` and the kernel's
    frames). Channel c uses only pairs with s <= cutoff_mm[c] (beyond, its reflectance is negligible);
    ``cutoff_mm`` is (3,), or (k, 3) per source and channel. ``chord_cutoff_mm`` (k, 3) or None: pairs must
    also have chord <= it (the near zone of sources whose far field is summed by clusters).
    ``source_radius`` (k,) mm: patch radius of each source (0 for a pencil beam), see
    :func:`patch_average_factor`.
    """
    M = np.zeros((n_vertices, 3))
    cutoff_mm = np.asarray(cutoff_mm, dtype=np.float64)
    n_pairs = np.zeros(3, dtype=np.int64)
    for src, vtx, s, chord, phi in pairs_iter:
        for c, same in kernel.channels:
            keep = s <= (cutoff_mm[c] if cutoff_mm.ndim == 1 else cutoff_mm[src, c])
            if chord_cutoff_mm is not None:
                keep &= chord <= chord_cutoff_mm[src, c]
            if not np.any(keep):
                continue
            R = kernel.evaluate(c, src[keep], s[keep], chord[keep], phi[keep])
            if source_radius is not None:
                a = source_radius[src[keep]]
                near = np.flatnonzero(s[keep] < PATCH_AVERAGE_RADII * a)
                if near.size:
                    ch = kernel.material.channel(c)
                    R[near] *= patch_average_factor(s[keep][near], a[near], albedo_prime=ch["albedo_prime"],
                                                    eta=ch["eta"], sigma_t_prime=ch["sigma_t_prime"])
            acc = np.bincount(vtx[keep], weights=power[src[keep]] * R, minlength=n_vertices)
            n_pairs[c] += int(keep.sum())
            for cc in same:
                M[:, cc] += acc
    return M, {"pairs_evaluated": int(n_pairs.sum()), "channels_computed": len(kernel.channels)}


def describe_scale(mesh, material: Material) -> str:
    """One line: mesh size in mm and in transport mean free paths (per channel), so unit mistakes show."""
    size = mesh.bbox_size_mm
    mfp = size.max() * material.sigma_t_prime
    return (f"mesh: {mesh.n_vertices} vertices, {mesh.n_faces} faces, {size[0]:.4g} x {size[1]:.4g} x "
            f"{size[2]:.4g} mm (largest extent = {mfp[0]:.4g}/{mfp[1]:.4g}/{mfp[2]:.4g} transport mean free "
            f"paths r/g/b; mean edge {mesh.mean_edge_length:.4g} mm); material {material.describe()}")


def bake(mesh, material: Material, lights, *, model: str = "curved", cutoff_tol: float = 1e-4,
         curvature_radius_mm: float | None = None, backend: str = "embree", progress: bool = False,
         rtol: float = 1e-10, geodesic: str = "exact", auto_options: dict | None = None,
         far_field: str | None = None, far_tol: float = 0.1, far_rel_tol: float = 1e-2,
         far_geodesic: str = "cluster") -> BakeResult:
    """Per-vertex radiant exitance of ``mesh`` (a :class:`~meshshade.geometry.mesh.Mesh` in mm) lit by ``lights``.

    Returns a :class:`BakeResult`; ``radiance`` is W/mm^2 per unit light power (beam, W), irradiance
    (directional, W/mm^2) or intensity (point, W/sr). Stages are timed in ``result.timings``.

    ``geodesic``: "exact" (polyhedral window propagation, the reference; default) or "arc" (curvature-corrected
    chords over an edge-path search: 1e-4 on smooth meshes such as spheres and tori and about 5x faster, but
    1-11 % low on average on bumpy scanned meshes; see geometry/geodesics/arc.py). With ``model="auto"``
    the geodesic method is chosen per entry sample ("arc" restricts it to arc) and ``auto_options`` may override
    the tolerances of :func:`meshshade.transport.auto.plan_sources`.

    ``far_field``: "off", "clustered" or "direct" (default: "clustered" for ``auto``, "off" otherwise; "off" with
    ``auto`` also turns off the shared far-zone geodesics, leaving exact or arc geodesics per sample). When on,
    the pairs of *vertex* entry samples (directional and point lights; beams have few samples and keep the full
    geodesic neighbourhood) are split at the chord radius ``r_near`` per channel beyond which the dipole's tail
    holds ``far_tol`` of its energy (farfield.far_field_radius): closer pairs are gathered over geodesic
    neighbourhoods with the model's kernel, farther ones are summed with the planar dipole of the chord distance
    by a source tree with relative error <= ``far_rel_tol`` on that part (farfield.py; "direct" sums them
    exactly, for validation). Pairs whose chord is within r_near but whose geodesic distance is not (across a
    fold) are dropped, as the geodesic neighbourhood drops them without the far field.
    ``far_geodesic`` ("cluster" or "arc"): how ``auto`` finds the far-zone geodesics of curved vertex samples:
    one exact query per cluster of nearby samples, each member's distance from the centre's by the law of
    cosines in the tangent plane (source_clusters.py), or the arc method.
    """
    from meshshade.geometry.curvature import principal_curvatures  # noqa: PLC0415
    from meshshade.light.samples import BeamLight, entry_samples  # noqa: PLC0415
    from meshshade.raycast.scene import make_scene  # noqa: PLC0415

    if model not in MODELS:
        raise MeshshadeError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    if not (0 < cutoff_tol < 1):
        raise MeshshadeError(f"cutoff tolerance must lie in (0, 1), got {cutoff_tol}")
    if curvature_radius_mm is not None and not (np.isfinite(curvature_radius_mm) and curvature_radius_mm > 0):
        raise MeshshadeError(f"curvature radius must be a positive number of mm, got {curvature_radius_mm}")
    if geodesic not in ("exact", "arc"):
        raise MeshshadeError(f"unknown geodesic method {geodesic!r}; choose exact or arc")
    lights = list(lights) if isinstance(lights, (list, tuple)) else [lights]
    timings, t0 = {}, time.perf_counter()

    def lap(name):
        nonlocal t0
        t = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + t - t0
        t0 = t

    V, F = mesh.vertices, mesh.faces
    curv = principal_curvatures(V, F, radius_mm=curvature_radius_mm)
    lap("curvature")
    scene = make_scene(V, F, backend=backend)  # face ids must index mesh.faces
    samples = entry_samples(V, F, mesh.vertex_normals, mesh.vertex_areas, lights, scene=scene, eta=material.eta)
    lap("rays")
    frames = source_frames(samples, curv, F)
    cut = np.minimum(cutoff_radii(material, cutoff_tol), mesh.scale)
    k = len(samples)
    far_field = far_field or ("clustered" if model == "auto" else "off")
    if far_field not in ("off", "clustered", "direct"):
        raise MeshshadeError(f"unknown far-field method {far_field!r}; choose off, clustered or direct")
    area = samples.vertex >= 0  # vertex samples of directional and point lights
    near = cut.copy()
    if far_field != "off" and np.any(area):
        from meshshade.transport.farfield import far_field_radius  # noqa: PLC0415
        # the far field is a point-to-point sum: keep every pair that needs the source-patch average near
        a_max = float(np.sqrt(mesh.vertex_areas[samples.vertex[area]].max() / np.pi))
        near = np.minimum(np.maximum(far_field_radius(material, far_tol), PATCH_AVERAGE_RADII * a_max), cut)
    if not np.any(near < cut):
        far_field = "off"
    plan = None
    if model == "auto":
        from meshshade.transport.auto import neighbourhood_curvature, plan_sources  # noqa: PLC0415

        near_radius = (np.where(area, NEAR_MARGIN * near.max(), cut.max()) if far_field != "off"
                       else np.full(k, cut.max()))
        # per sample: max |k| within the near radius, and max |k| and max (-k2) within the cutoff
        vals = np.stack([np.maximum(np.abs(curv.k1), np.abs(curv.k2)), -curv.k2], axis=1)
        kn_near, kn_far = neighbourhood_curvature(samples, vals, V, F, [near_radius, cut.max()],
                                                  mesh.mean_edge_length)
        k_near, k_far, kmin_far = kn_near[:, 0], kn_far[:, 0], -kn_far[:, 1]
        plan = plan_sources(frames.k1, frames.k2, k_near, k_far, material, near_radius, cut, kmin_far=kmin_far,
                            **(auto_options or {}))
        if geodesic != "exact":
            plan = replace(plan, exact_geodesic=np.zeros(k, dtype=bool))
        lap("auto")
    if plan is not None and far_geodesic == "cluster" and not clusters_pay(mesh, cut):
        far_geodesic = "none"  # small mesh or short cutoff: shared far-zone geodesics would not save work
    zone = assign_zones(k, area, far_field, geodesic, plan, far_geodesic)
    clustered = np.array([zz[3] for zz in ZONES])[zone]  # sources whose pairs beyond r_near go to the far sum
    groups = [(z, np.flatnonzero(zone == z)) for z in range(len(ZONES))]
    groups = [(z, idx) for z, idx in groups if idx.size]
    # per source and channel: the radius of the geodesic gather; clustered sources keep the near pairs by
    # *chord* <= r_near (the far-field sum takes chord > r_near, so nothing is counted twice), found within a
    # geodesic radius NEAR_MARGIN r_near (pairs with a short chord but a longer geodesic lie across a fold or gap
    # and are dropped; README: 0.4-2.5 % of near pairs on bumpy scans, none on flat surroundings)
    src_cut = np.where(clustered[:, None], NEAR_MARGIN * near[None, :], cut[None, :])
    chord_cut = np.where(clustered[:, None], near[None, :], np.inf)
    kernel = PairKernel(model, material, frames, rtol=rtol, plan=plan)
    methods = {m.replace("-cluster", "") for z, _ in groups for m in ZONES[z][1:3] if m}
    solvers = {m: neighbourhood_solver(m, mesh) for m in methods}
    lap("neighbourhoods")
    stats = {"entry_samples": k, "cutoff_mm": cut.tolist(), **samples.stats,
             **{f"zone_{ZONES[z][0]}": int(idx.size) for z, idx in groups}}
    if plan is not None:
        stats.update(plan.counts())
        log.info(plan.describe())
    beam_distance = None
    M = np.zeros((mesh.n_vertices, 3))
    if k:
        # chunk sizes from the expected neighbours per source (area of the cutoff disc over area per vertex)
        per_vertex_area = mesh.total_area / max(mesh.n_vertices, 1)
        expected = max(1.0, np.pi * float(np.mean(src_cut.max(axis=1) ** 2)) / per_vertex_area)
        chunk = int(max(1, min(k, PAIRS_PER_CHUNK // expected)))
        bar = None
        if progress and k > chunk:
            from tqdm import tqdm  # noqa: PLC0415
            # no bar when stderr is not a terminal (pipes, logs): errors stay one clean line there
            bar = tqdm(total=k, desc="gather", unit="src", leave=False, disable=None)
        n_pairs = n_geo = 0  # pairs gathered; pairs whose geodesic distance a solver computed

        def query(method, sel, radius):
            nb = solvers[method].query(samples.positions[sel], samples.face[sel], samples.bary[sel],
                                       samples.vertex[sel], frames.normals[sel], radius, d1=frames.d1[sel],
                                       d2=frames.d2[sel], k1=frames.k1[sel], k2=frames.k2[sel])
            return sel[nb.source_index()], nb.vertex.astype(np.int64), nb.distance, nb.chord, nb.phi

        def cluster_pairs(idx):
            """Zone exact_near_cluster_far: exact near pairs per sample, far pairs from cluster centres."""
            from meshshade.transport.clusters import cluster_sources, expand_far_pairs  # noqa: PLC0415

            nonlocal n_pairs, n_geo
            size, near_c = cluster_geometry(mesh, cut)
            order, ptr = cluster_sources(samples.positions[idx], frames.normals[idx], size)
            order = idx[order]
            centre_rows = np.repeat(np.arange(ptr.size - 1), np.diff(ptr))
            centre_of = order[ptr[:-1]][centre_rows]  # the centre sample of each entry of ``order``
            n = np.int64(mesh.n_vertices)
            a_max = float(np.max(np.linalg.norm(samples.positions[order] - samples.positions[centre_of], axis=1)))
            c_chunk = max(1, int(chunk * (ptr.size - 1) / max(order.size, 1)))
            for c0 in range(0, ptr.size - 1, c_chunk):
                c1 = min(ptr.size - 1, c0 + c_chunk)
                mem = order[ptr[c0]:ptr[c1]]
                cen = order[ptr[c0:c1]]
                pn = query("exact", mem, near_c)
                pc = query("exact", cen, cut.max() + a_max)
                keys = np.sort(pn[0] * n + pn[1])
                pf = expand_far_pairs(pc, (mem, centre_of[ptr[c0]:ptr[c1]]), samples.positions, V, frames,
                                      exclude_keys=keys, max_distance=cut.max())
                p = tuple(np.concatenate([x, y]) for x, y in zip(pn, pf))
                n_pairs += p[0].size
                n_geo += pn[0].size + pc[0].size
                lap("neighbourhoods")
                yield p
                lap("gather")
                if bar is not None:
                    bar.update(mem.size)

        def pairs():
            nonlocal n_pairs, n_geo
            for z, idx in groups:
                _, inner, outer, _ = ZONES[z]
                if outer == "exact-cluster":
                    yield from cluster_pairs(idx)
                    continue
                for a in range(0, idx.size, chunk):
                    sel = idx[a:a + chunk]
                    if outer is None:  # one method over the source's whole gather radius
                        p = query(inner, sel, src_cut[sel].max(axis=1))
                    else:  # exact geodesics in the near zone, arc geodesics for the rest of the neighbourhood
                        pi, po = query(inner, sel, NEAR_MARGIN * near.max()), query(outer, sel, cut.max())
                        n = np.int64(mesh.n_vertices)
                        fresh = ~np.isin(po[0] * n + po[1], pi[0] * n + pi[1])
                        p = tuple(np.concatenate([x, y[fresh]]) for x, y in zip(pi, po))
                    n_pairs += p[0].size
                    n_geo += p[0].size if outer is None else pi[0].size + po[0].size
                    lap("neighbourhoods")
                    yield p
                    lap("gather")
                    if bar is not None:
                        bar.update(sel.size)

        # vertex samples of directional/point lights stand for their vertex's area; beam samples are points
        radius = np.where(samples.vertex >= 0, np.sqrt(mesh.vertex_areas[np.maximum(samples.vertex, 0)] / np.pi),
                          0.0)
        try:
            M, gstats = gather(kernel, mesh.n_vertices, samples.power, src_cut, pairs(), source_radius=radius,
                               chord_cutoff_mm=chord_cut)
        finally:  # also on KeyboardInterrupt: the bar clears its line before the error message is printed
            if bar is not None:
                bar.close()
        stats.update(gstats, pairs_found=n_pairs, geodesic_pairs_computed=n_geo)
        if np.any(clustered):
            from meshshade.transport.farfield import far_field_exitance, far_field_exitance_direct  # noqa: PLC0415
            fn = far_field_exitance if far_field == "clustered" else far_field_exitance_direct
            M_far, fstats = fn((samples.positions[clustered], samples.power[clustered]), V, material, near, cut,
                               rel_tol=far_rel_tol)
            M += M_far
            stats.update(far_field=far_field, near_mm=near.tolist(), far_field_rel_tol=far_rel_tol,
                         far_pairs_exact=fstats["pairs_exact"],
                         far_clusters_accepted=fstats.get("clusters_accepted", 0))
            lap("far field")
        first_beam = next((i for i, L in enumerate(lights) if isinstance(L, BeamLight)), None)
        if first_beam is not None:
            j = int(np.flatnonzero(samples.light_index == first_beam)[0])
            method = ZONES[zone[j]][1]
            nb = solvers[method].query(samples.positions[j:j + 1], samples.face[j:j + 1], samples.bary[j:j + 1],
                                       samples.vertex[j:j + 1], samples.normals[j:j + 1], src_cut[j].max())
            beam_distance = np.full(mesh.n_vertices, np.inf)
            beam_distance[nb.vertex] = nb.distance
            lap("neighbourhoods")
    stats.update(kernel.stats)
    stats["exitant_power"] = (M * mesh.vertex_areas[:, None]).sum(axis=0).tolist()
    stats["entering_power"] = float(samples.power.sum())
    return BakeResult(M, curv.k1, curv.k2, curv.d1, curv.d2, samples, beam_distance, cut, model, material,
                      timings, stats, plan)


def describe_result(result: BakeResult) -> str:
    s = result.stats
    t = ", ".join(f"{k} {v:.3g} s" for k, v in result.timings.items())
    ex = s["exitant_power"]
    far = (f" (area lights: geodesic near field within {max(s['near_mm']):.3g} mm, {s['far_field']} far field "
           f"beyond)" if "near_mm" in s else "")
    if s.get("geodesic_pairs_computed", s.get("pairs_found")) != s.get("pairs_found"):
        far += f", {s['geodesic_pairs_computed']} geodesic distances computed"
    zones = ", ".join(f"{k[5:]} {v}" for k, v in s.items() if k.startswith("zone_"))
    far += f" [zones: {zones}]" if zones and result.model == "auto" else ""
    return (f"{result.model}: {s['entry_samples']} entry samples, {s.get('pairs_found', 0)} pairs within "
            f"{max(s['cutoff_mm']):.3g} mm{far}; entering {s['entering_power']:.4g} W, exitant "
            f"{ex[0]:.4g}/{ex[1]:.4g}/{ex[2]:.4g} W (r/g/b); {t}")


def write_bake(result: BakeResult, mesh, out, *, npz=None) -> None:
    """Write the PLY (radiance_r/g/b float W/mm^2 + uchar red/green/blue, tone-mapped) and optionally an NPZ."""
    from meshshade import io  # noqa: PLC0415
    from meshshade.output.tonemap import tonemap  # noqa: PLC0415

    M = result.radiance
    props = {"radiance_r": M[:, 0], "radiance_g": M[:, 1], "radiance_b": M[:, 2]}
    colours = tonemap(M, operator="drago")
    comments = [f"meshshade model {result.model}", f"meshshade material {result.material.describe()}",
                "meshshade radiance_r/g/b: linear radiant exitance in W/mm^2 per unit light power/irradiance"]
    if result.plan is not None:
        comments.append(f"meshshade {result.plan.describe()}")
    io.write_mesh_ply(out, mesh, props, colours, comments=comments)
    if npz:
        arrays = dict(radiance=M, k1=result.k1, k2=result.k2, d1=result.d1, d2=result.d2,
                      vertex_areas=mesh.vertex_areas, cutoff_mm=result.cutoff_mm,
                      entry_positions=result.samples.positions, entry_power=result.samples.power)
        if result.beam_distance is not None:
            arrays["beam_distance"] = result.beam_distance
        if result.plan is not None:  # per entry sample: 0 dipole, 1 curved, 2 exact-sphere; exact geodesics
            arrays["auto_kernel"] = result.plan.kernel
            arrays["auto_exact_geodesic"] = result.plan.exact_geodesic
        io.write_npz(npz, **arrays)
