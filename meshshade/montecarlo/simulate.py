"""Monte Carlo reference: a volumetric random walk inside the closed mesh that the diffusion models shade.

Physics (MCML conventions, Wang, Jacques & Zheng 1995, *Comput. Methods Programs Biomed.* 47:131):

* photons enter from the lights (beam, directional, point); at entry the unpolarised Fresnel reflectance
  F(cos) (index 1 outside, ``eta`` inside) is split off *deterministically* as specular power and the rest is
  refracted (Snell) into the medium;
* free paths s = -ln(u)/sigma_t with sigma_t = sigma_s + sigma_a, sigma_s = sigma_s'/(1 - g);
* at an interaction the weight is multiplied by the single-scattering albedo sigma_s/sigma_t (the removed part
  is tallied as absorbed) and the direction is sampled from the Henyey-Greenstein phase function (isotropic at
  g = 0);
* a boundary is found with a batched Embree ``first_hit`` from the photon's position along its direction: if
  the hit is nearer than the sampled free path, the photon reaches the surface and is reflected with
  probability F(cos_i) (from index eta into 1; total internal reflection gives F = 1) or leaves, and its weight
  is tallied on the exit face (with the barycentrics of the exit point, so also on the face's vertices);
* Russian roulette below ``ROULETTE_THRESHOLD`` times the photon's initial weight: survive with probability
  1/``ROULETTE_BOOST`` with the weight multiplied by ``ROULETTE_BOOST``. The roulette's net weight change is
  booked in ``absorbed`` (its expectation is zero, so ``absorbed`` stays unbiased) so that specular + diffuse +
  transmitted + absorbed (+ lost) = 1 holds *exactly* per channel, not only on average.

Channels: one walk per distinct (sigma_s', sigma_a) pair; channels with equal coefficients (grey materials)
share one walk and are copied. (Per-channel weights on one path are only valid when sigma_t is equal across
channels; separate walks are simpler and always correct.)

Engines: the default pooled engine (:mod:`meshshade.montecarlo.engine`) walks a regenerating pool of photons
with numba kernels, certifies short free flights with a safe-distance grid and asks Embree only for the others;
``fast_interior=False`` selects the baseline numpy wavefront (:mod:`meshshade.montecarlo.wavefront_oracle`, one Embree
query per photon and step). Both follow the physics above and give the same distributions.

Uncertainty: photon ``i`` belongs to batch ``i % n_batches``; every reported quantity is also tallied per batch
and its standard error is the batch-means estimate std(batch values, ddof=1)/sqrt(n_batches).

Pure computation, no file I/O (``write_mc`` delegates writing to :mod:`meshshade.io`).
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from meshshade.errors import LightError, MeshshadeError
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.geometry.topology import winding_number
from meshshade.light.samples import BeamLight, DirectionalLight, PointLight
from meshshade.materials import Material

ROULETTE_THRESHOLD = 1e-4
ROULETTE_BOOST = 10.0
DEFAULT_BATCHES = 16
TOTAL_KEYS = ("specular_reflectance", "diffuse_reflectance", "transmittance", "absorbed")


# ------------------------------------------------------------------------------------------------ sampling
def _orthonormal_basis(d):
    """(t, b) unit vectors orthogonal to unit ``d`` (n, 3) (Duff et al. 2017, branchless)."""
    sign = np.where(d[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + d[:, 2])
    b = d[:, 0] * d[:, 1] * a
    t = np.stack([1.0 + sign * d[:, 0] ** 2 * a, sign * b, -sign * d[:, 0]], axis=1)
    s = np.stack([b, sign + d[:, 1] ** 2 * a, -d[:, 1]], axis=1)
    return t, s


def sample_hg_cos(g: float, u) -> np.ndarray:
    """cos(theta) of the Henyey-Greenstein phase function with anisotropy ``g`` by inversion (u uniform in [0, 1))."""
    u = np.asarray(u, dtype=np.float64)
    if abs(g) < 1e-6:
        return 1.0 - 2.0 * u
    tmp = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - tmp * tmp) / (2.0 * g), -1.0, 1.0)


def scatter_directions(d, g: float, rng) -> np.ndarray:
    """New unit directions (n, 3) after HG scattering of unit directions ``d`` (n, 3)."""
    n = d.shape[0]
    cos_t = sample_hg_cos(g, rng.random(n))
    sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
    phi = 2.0 * np.pi * rng.random(n)
    t, b = _orthonormal_basis(d)
    out = (sin_t * np.cos(phi))[:, None] * t + (sin_t * np.sin(phi))[:, None] * b + cos_t[:, None] * d
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def refract_in(d, n, eta: float) -> np.ndarray:
    """Refract unit directions ``d`` arriving from outside (index 1) through outward unit normals ``n`` into eta."""
    cos_i = np.clip(-np.einsum("ij,ij->i", d, n), 0.0, 1.0)
    sin2_t = (1.0 - cos_i ** 2) / eta ** 2
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    out = d / eta + (cos_i / eta - cos_t)[:, None] * n
    return out / np.linalg.norm(out, axis=1, keepdims=True)


# ------------------------------------------------------------------------------------------------ emitters
class _Emitter:
    """Draws photons from the lights: entry point (face, bary), inward direction, weight (W), specular part.

    Every photon carries ``P_total / N`` W times a correction for point lights; shadowed directional/point
    photons carry no incident power (weight 0).
    """

    def __init__(self, V, F, normals, areas, lights, scene, eta):
        self.V, self.F, self.N, self.A, self.scene, self.eta = V, F, normals, areas, scene, eta
        self.lights = list(lights)
        if not self.lights:
            raise LightError("Monte Carlo needs at least one light")
        self.parts = []
        power = []
        for i, light in enumerate(self.lights):
            if isinstance(light, BeamLight):
                o, d = np.array(light.origin), np.array(light.direction)
                if abs(winding_number(o, V, F)) > 0.5:
                    raise LightError(f"beam light {i} starts inside the mesh (origin {light.origin} mm)")
                hits = scene.first_hit(o, d, exact=True)
                f = int(hits.face[0])
                if f < 0 or float(normals[f] @ d) >= 0.0:
                    raise LightError(f"beam light {i} from {light.origin} mm along {light.direction} misses "
                                     "the mesh (or reaches the back of a face)")
                self.parts.append(("beam", f, hits.bary[0], d))
                power.append(light.power)
            elif isinstance(light, (DirectionalLight, PointLight)):
                c = V[F].mean(axis=1)
                if isinstance(light, DirectionalLight):
                    cos = normals @ (-np.array(light.direction))
                    w = light.irradiance * np.clip(cos, 0.0, None) * areas
                else:
                    pos = np.array(light.position)
                    if abs(winding_number(pos, V, F)) > 0.5:
                        raise LightError(f"point light {i} at {light.position} mm is inside the mesh")
                    delta = pos - c
                    r2 = np.einsum("ij,ij->i", delta, delta)
                    cos = np.einsum("ij,ij->i", normals, delta) / np.sqrt(r2)
                    w = light.intensity * np.clip(cos, 0.0, None) * areas / r2
                total = float(w.sum())
                if not total > 0.0:
                    raise LightError(f"light {i} ({light!r}) faces no part of the mesh")
                self.parts.append(("area", np.cumsum(w) / total, w, light))
                power.append(total)
            else:
                raise LightError(f"light {i} is not a BeamLight, DirectionalLight or PointLight: {light!r}")
        self.light_power = np.array(power, dtype=np.float64)   # W (for area lights: centroid estimate)
        self.total_power = float(self.light_power.sum())
        self.light_cdf = np.cumsum(self.light_power) / self.total_power
        # faces whose normal faces each light (diffuse reflectance vs transmittance)
        self.facing = np.zeros((len(self.lights), F.shape[0]), dtype=bool)
        c = V[F].mean(axis=1)
        for i, light in enumerate(self.lights):
            if isinstance(light, PointLight):
                self.facing[i] = np.einsum("ij,ij->i", normals, np.array(light.position) - c) > 0.0
            else:
                self.facing[i] = normals @ (-np.array(light.direction)) > 0.0

    def emit(self, k: int, n_total: int, rng):
        """k photons: (light, face, points, dirs_in, weight_in, specular, incident).

        points are moved just inside the surface; weight_in = incident x (1 - F), specular = incident x F.
        """
        light = np.minimum(np.searchsorted(self.light_cdf, rng.random(k), side="right"), len(self.lights) - 1)
        face = np.zeros(k, dtype=np.int64)
        points = np.zeros((k, 3))
        dirs = np.zeros((k, 3))
        Fr = np.zeros(k)
        weight = np.full(k, self.total_power / n_total)
        for i, part in enumerate(self.parts):
            sel = np.flatnonzero(light == i)
            if sel.size == 0:
                continue
            if part[0] == "beam":   # one entry for all its photons
                f, b, d = part[1], part[2], part[3]
                p1, d1, F1 = self._enter(np.array([f]), np.asarray(b, dtype=np.float64)[None], np.asarray(d)[None])
                face[sel], points[sel], dirs[sel], Fr[sel] = f, p1[0], d1[0], F1[0]
                continue
            _, cdf, w_face, lt = part
            f = np.minimum(np.searchsorted(cdf, rng.random(sel.size), side="right"), cdf.size - 1)
            r1, r2 = np.sqrt(rng.random(sel.size)), rng.random(sel.size)
            b = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
            p = np.einsum("ij,ijk->ik", b, self.V[self.F[f]])
            if isinstance(lt, DirectionalLight):
                d = np.broadcast_to(np.array(lt.direction), (sel.size, 3))
                to_light, t_max = -d, np.inf
            else:
                delta = p - np.array(lt.position)
                dist = np.linalg.norm(delta, axis=1)
                d = delta / dist[:, None]
                to_light, t_max = -d, dist
                # importance weight: true irradiance at the point over the face-centroid value used for sampling
                cos = np.clip(-np.einsum("ij,ij->i", self.N[f], d), 0.0, None)
                weight[sel] *= lt.intensity * cos / dist ** 2 * self.A[f] / w_face[f]
            origin = self.scene.offset_origins(p, self.N[f], sign=1.0)
            shadow = self.scene.occluded(origin, to_light, t_max)
            weight[sel[shadow]] = 0.0
            face[sel] = f
            points[sel], dirs[sel], Fr[sel] = self._enter(f, b, d)
        return light, face, points, dirs, weight * (1.0 - Fr), weight * Fr, weight.copy()

    def _enter(self, face, bary, d_out):
        """Entry of photons arriving along d_out (n, 3) at (face, bary): (point just inside, refracted direction,
        Fresnel reflectance F(cos_i) from index 1 into eta)."""
        points = np.einsum("ij,ijk->ik", bary, self.V[self.F[face]])
        n = self.N[face]
        cos_i = np.clip(-np.einsum("ij,ij->i", d_out, n), 0.0, 1.0)
        Fr = fresnel_reflectance(cos_i, 1.0, self.eta)
        return self.scene.offset_origins(points, n, sign=-1.0), refract_in(d_out, n, self.eta), Fr


# ------------------------------------------------------------------------------------------------ results
@dataclass
class MCResult:
    """Tallies of a Monte Carlo run (all powers in W, per channel r, g, b; stderr by batch means).

    face_power : (m, 3) W leaving each face; vertex_power : (n, 3) W, exit power split by barycentrics;
    radiance : (n, 3) W/mm^2, vertex_power / vertex area (exitance), with radiance_stderr;
    totals : dict key -> (3,) fractions of the incident power (TOTAL_KEYS) and ``<key>_stderr``;
    lost : (3,) fraction lost to numerical leaks (rays that miss the mesh from inside) and to photons cut off at
        the hard time limit of a ``time_budget`` run, normally 0;
    beam_exits : per channel, dict of arrays ``face``, ``bary``, ``weight`` (W), ``batch`` for photons of the
        first beam light (for radial profiles); beam_entry : (face, bary) of that beam, or None;
    boundary_tests : ray casts (Embree queries) made by the walk; seconds / cpu_seconds : wall-clock and process
        CPU time (all threads) of the walk, without the set-up (scene, safe-distance grid, emitter).
    """

    material: Material
    face_power: np.ndarray
    face_power_stderr: np.ndarray
    vertex_power: np.ndarray
    radiance: np.ndarray
    radiance_stderr: np.ndarray
    totals: dict
    lost: np.ndarray
    incident_power: np.ndarray
    entering_power: np.ndarray
    photons: int
    events: int
    boundary_events: int
    seconds: float
    n_batches: int
    beam_exits: list = field(default_factory=list)
    beam_entry: tuple | None = None
    beam_distance: np.ndarray | None = None
    boundary_tests: int = 0
    cpu_seconds: float = 0.0

    @property
    def events_per_second(self) -> float:
        return self.events / max(self.seconds, 1e-12)


def _batch_stats(per_batch):
    """(B, ...) batch totals -> (mean of the sum-estimate, stderr of the sum) with equal-size batches."""
    B = per_batch.shape[0]
    total = per_batch.sum(axis=0)
    stderr = np.std(per_batch * B, axis=0, ddof=1) / np.sqrt(B) if B > 1 else np.zeros_like(total)
    return total, stderr


def simulate(mesh, material: Material, lights, *, photons: int | None = 100_000, seed: int = 0,
             time_budget: float | None = None, n_batches: int = DEFAULT_BATCHES, pool: int | None = None,
             keep_beam_exits: bool = True, beam_distances: bool = True, fast_interior: bool = True,
             engine: str = "auto", progress: bool = False) -> MCResult:
    """Monte Carlo random walk inside ``mesh`` lit by ``lights``; see the module docstring.

    Parameters
    ----------
    mesh : Mesh (closed, outward faces; vertices in mm)
    material : Material (uses sigma_s', sigma_a, eta and g)
    lights : light or sequence of BeamLight / DirectionalLight / PointLight
    photons : photons per channel group (with ``time_budget``: an upper bound, None = unbounded)
    seed : int >= 0, makes the run reproducible: with the pooled engine photon ``i`` of channel group ``k`` draws
        every random number from a stream keyed by (seed, k, i), so the result is bitwise identical for any
        number of threads and photon i's path does not depend on ``pool``
    time_budget : float seconds or None, counted from the call: emission stops when the photons in flight are
        predicted to finish within the budget; photons still in flight at 1.25 x the budget are cut off and
        their weight is reported as ``lost`` (see :mod:`meshshade.montecarlo.engine` for the bound; the baseline
        wavefront, ``fast_interior=False``, finishes all photons in flight)
    n_batches : batches for the standard errors (>= 2)
    pool : photon slots advanced together (default 2**18 for the pooled engine, 2**16 for the baseline)
    beam_distances : compute per-vertex geodesic distances from the first beam's entry point
    fast_interior : True: the pooled engine (numba interior walks inside a conservative safe-distance grid,
        one batched Embree query per round, :mod:`meshshade.montecarlo.engine`); False: the plain numpy
        wavefront with an Embree query every step (the baseline: same distribution, different random streams)
    engine : pooled engine's Embree calls: "direct" (rtcIntersect1 from the numba threads,
        :mod:`meshshade.raycast.embree_direct`), "batched" (one embreex call per round) or "auto" (direct when the
        Embree library can be bound, else batched). Both give the same photon paths up to float32 ties.

    Returns
    -------
    MCResult
    """
    from meshshade.montecarlo.engine import PoolWalk  # noqa: PLC0415
    from meshshade.montecarlo.wavefront_oracle import WavefrontWalk  # noqa: PLC0415
    from meshshade.raycast.scene import make_scene  # noqa: PLC0415

    if isinstance(lights, (BeamLight, DirectionalLight, PointLight)):
        lights = [lights]
    if photons is None and time_budget is None:
        raise MeshshadeError("give a photon count or a time budget")
    if photons is not None and photons < n_batches:
        raise MeshshadeError(f"need at least {n_batches} photons (one per batch), got {photons}")
    if n_batches < 2:
        raise MeshshadeError("n_batches must be at least 2 for a standard error")
    if int(seed) < 0:
        raise MeshshadeError(f"seed must be a non-negative integer, got {seed}")
    t_start = time.perf_counter()
    n_photons = int(photons) if photons is not None else 1 << 62
    V, F = mesh.vertices, mesh.faces
    normals, areas = mesh.face_normals, mesh.face_areas
    scene = make_scene(V, F)
    grid = direct = None
    if engine not in ("auto", "direct", "batched"):
        raise MeshshadeError(f"engine must be 'auto', 'direct' or 'batched', got {engine!r}")
    if fast_interior:
        from meshshade.montecarlo.interior import SafeDistanceGrid  # noqa: PLC0415
        sigma_t_max = float(np.max(material.sigma_s_prime / (1.0 - material.g) + material.sigma_a))
        # no half-space certificates under a time budget: their set-up would be spent before the first photon
        use_planes = sigma_t_max > 0 and time_budget is None
        grid = SafeDistanceGrid(V, F, mean_free_path=1.0 / sigma_t_max if use_planes else None)
        if engine != "batched" and getattr(scene, "backend", "") == "embree":
            from meshshade.raycast.embree_direct import DirectEmbreeScene  # noqa: PLC0415
            try:
                direct = DirectEmbreeScene(V, F, scene.center)
            except (RuntimeError, OSError) as exc:
                if engine == "direct":
                    raise MeshshadeError(f"engine='direct' is not available here ({exc}); use 'batched'") from exc
    emitter = _Emitter(V, F, normals, areas, lights, scene, material.eta)
    g = material.g
    sigma_s = material.sigma_s_prime / (1.0 - g)
    groups: dict = {}
    for c in range(3):
        groups.setdefault((float(sigma_s[c]), float(material.sigma_a[c])), []).append(c)
    children = np.random.SeedSequence(seed).spawn(len(groups))
    t0, c0 = time.perf_counter(), time.process_time()
    face_p = np.zeros((F.shape[0], 3)); face_se = np.zeros_like(face_p)
    vert_p = np.zeros((V.shape[0], 3)); vert_se = np.zeros_like(vert_p)
    tot = np.zeros((7, 3)); tot_se = np.zeros((7, 3))
    frac = np.zeros((5, 3)); frac_se = np.zeros((5, 3))
    events = boundary = rays = 0
    emitted_max = 0
    exits = [None] * 3
    bar = None
    if progress:
        from tqdm import tqdm  # noqa: PLC0415
        bar = tqdm(total=None if photons is None else n_photons * len(groups), desc="mc", unit="photon",
                   leave=False)
    try:
        for gi, (((ss, sa), chans), child) in enumerate(zip(groups.items(), children)):
            common = dict(sigma_s=ss, sigma_a=sa, g=g, eta=material.eta, n_batches=n_batches,
                          keep_beam=keep_beam_exits)
            budget = None
            if time_budget is not None:  # what is left, shared by the remaining groups
                budget = max(time_budget - (time.perf_counter() - t_start), 0.0) / (len(groups) - gi)
            if fast_interior:
                walk = PoolWalk(V, F, normals, emitter, scene, grid, seed=seed, group=gi, direct=direct, **common)
                emitted = walk.run(n_photons, pool=pool, time_budget=budget, progress=bar)
                rays += walk.rays
            else:
                walk = WavefrontWalk(V, F, normals, emitter, scene, **common)
                emitted = walk.run(n_photons, np.random.default_rng(child), pool=pool or 1 << 16,
                                   time_budget=budget, progress=bar)
                rays += walk.rays
            emitted_max = max(emitted_max, emitted)
            scale = n_photons / emitted if emitted else 1.0
            # photon weights were P/n_photons: rescale when the time budget stopped emission early
            fp, fse = _batch_stats(walk.face * scale)
            vp, vse = _batch_stats(walk.face_vert * scale)
            tt, tse = _batch_stats(walk.tot * scale)
            inc = walk.tot[:, 5]
            ratios = walk.tot[:, :5] / np.where(inc > 0, inc, np.nan)[:, None]          # (B, 5) per batch
            fr = tt[:5] / tt[5] if tt[5] > 0 else np.zeros(5)
            with warnings.catch_warnings():   # a budget run with fewer photons than batches: NaN, not a warning
                warnings.simplefilter("ignore", RuntimeWarning)
                fse_tot = np.nanstd(ratios, axis=0, ddof=1) / np.sqrt(n_batches)
            group_exits = None
            if keep_beam_exits and walk.exits["face"]:
                group_exits = {k: np.concatenate(v) for k, v in walk.exits.items()}
                group_exits["weight"] = group_exits["weight"] * scale
            for c in chans:
                face_p[:, c], face_se[:, c], vert_p[:, c], vert_se[:, c] = fp, fse, vp, vse
                tot[:, c], tot_se[:, c], frac[:, c], frac_se[:, c] = tt, tse, fr, fse_tot
                if keep_beam_exits and walk.exits["face"]:
                    exits[c] = group_exits   # channels of one group share the (read-only) arrays
            events += walk.events
            boundary += walk.boundary
    finally:
        if bar is not None:
            bar.close()
    seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    va = mesh.vertex_areas
    with np.errstate(divide="ignore", invalid="ignore"):
        radiance = np.where(va[:, None] > 0, vert_p / va[:, None], 0.0)
        radiance_se = np.where(va[:, None] > 0, vert_se / va[:, None], 0.0)
    totals = {}
    for i, key in enumerate(TOTAL_KEYS):
        totals[key] = frac[i]
        totals[key + "_stderr"] = frac_se[i]
    beam_entry = None
    beam_distance = None
    b = emitter.parts[next((i for i, lt in enumerate(emitter.lights) if isinstance(lt, BeamLight)), -1)] \
        if any(isinstance(lt, BeamLight) for lt in emitter.lights) else None
    if b is not None:
        beam_entry = (int(b[1]), np.asarray(b[2]))
        if beam_distances:
            from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods  # noqa: PLC0415
            beam_distance = GeodesicNeighbourhoods(V, F).distances_from(face=beam_entry[0], bary=beam_entry[1])
    return MCResult(material=material, face_power=face_p, face_power_stderr=face_se, vertex_power=vert_p,
                    radiance=radiance, radiance_stderr=radiance_se, totals=totals, lost=frac[4],
                    incident_power=tot[5], entering_power=tot[6], photons=emitted_max, events=events,
                    boundary_events=boundary, seconds=seconds, n_batches=n_batches, boundary_tests=rays,
                    cpu_seconds=cpu_seconds,
                    beam_exits=exits if keep_beam_exits else [], beam_entry=beam_entry,
                    beam_distance=beam_distance)


# ------------------------------------------------------------------------------------------------ profiles
def radial_exitance(exit_distance, weight, batch, distances_mm, *, halfwidth_mm, annulus_area, n_batches,
                    entering_power):
    """Exitance per unit entering power [mm^-2] in annuli [s - h, s + h] (clipped at 0) around each distance.

    exit_distance, weight, batch : (k,) exit geodesic distance (mm), power (W), batch index
    annulus_area : callable (a, b) -> area (mm^2) of the surface between geodesic distances a and b
    Returns (value (n,), stderr (n,)).
    """
    s = np.asarray(distances_mm, dtype=np.float64)
    h = np.broadcast_to(np.asarray(halfwidth_mm, dtype=np.float64), s.shape)
    lo, hi = np.maximum(s - h, 0.0), s + h
    per = np.zeros((n_batches, s.size))
    for j in range(s.size):
        sel = (exit_distance >= lo[j]) & (exit_distance < hi[j])
        per[:, j] = np.bincount(batch[sel], weights=weight[sel], minlength=n_batches) / annulus_area(lo[j], hi[j])
    per /= entering_power
    return _batch_stats(per)


def mc_profile(material: Material, distances_mm, *, shape, photons: int = 200_000, seed: int = 0,
               subdivisions: int | None = None, return_stderr: bool = False):
    """Monte Carlo reflectance profile [mm^-2] per unit entering power, (3, n), for a unit beam at a sphere's pole.

    The sphere is an icosphere of ``shape.radius_mm`` (subdivision chosen so edges are <= ~R/30, at most 6);
    the beam enters at normal incidence at the north pole; exit points are tallied against their great-circle
    distance from the pole in annuli of half-width max(0.1 s, 0.05/sigma_t'_min) (exact spherical annulus area).
    """
    from meshshade.geometry.mesh import Mesh  # noqa: PLC0415
    from meshshade.geometry.procedural import icosphere  # noqa: PLC0415

    if shape is None or shape.kind != "sphere":
        raise MeshshadeError("the Monte Carlo profile is implemented for --shape sphere only "
                             "(use `meshshade mc` on a mesh for other geometry)")
    R = float(shape.radius_mm)
    s = np.asarray(distances_mm, dtype=np.float64)
    level = subdivisions if subdivisions is not None else 5 if R <= 20 else 6
    V, F = icosphere(R, level)
    # rotate so that no vertex sits on the pole: the beam then enters inside a face
    ang = 0.0123
    rot = np.array([[1, 0, 0], [0, np.cos(ang), -np.sin(ang)], [0, np.sin(ang), np.cos(ang)]])
    mesh = Mesh.from_arrays(V @ rot.T, F)
    beam = BeamLight((0.0, 0.0, 2.0 * R + 1.0), (0.0, 0.0, -1.0), 1.0)
    res = simulate(mesh, material, [beam], photons=photons, seed=seed, beam_distances=False)
    h = np.maximum(0.1 * s, 0.05 / float(np.min(material.sigma_t_prime)))
    area = lambda a, b: 2.0 * np.pi * R * R * (np.cos(a / R) - np.cos(min(b / R, np.pi)))  # noqa: E731
    out = np.zeros((3, s.size))
    err = np.zeros((3, s.size))
    for c in range(3):
        ex = res.beam_exits[c]
        if ex is None:
            continue
        p = np.einsum("ij,ijk->ik", ex["bary"], mesh.vertices[mesh.faces[ex["face"]]])
        dist = R * np.arctan2(np.linalg.norm(p[:, :2], axis=1), p[:, 2])
        out[c], err[c] = radial_exitance(dist, ex["weight"], ex["batch"], s, halfwidth_mm=h, annulus_area=area,
                                         n_batches=res.n_batches, entering_power=float(res.entering_power[c]))
    return (out, err) if return_stderr else out


def beam_radial_power(result: MCResult, mesh, edges_mm):
    """Exit power of the first beam's photons against geodesic distance from its entry point, per channel.

    The distance of an exit point is the barycentric interpolation of ``result.beam_distance`` (exact polyhedral
    geodesic distances of the vertices from the entry point). edges_mm : (k + 1,) increasing bin edges [mm].
    Returns (power (3, k) W, stderr (3, k) W).
    """
    edges = np.asarray(edges_mm, dtype=np.float64)
    out, err = np.zeros((3, edges.size - 1)), np.zeros((3, edges.size - 1))
    if result.beam_distance is None:
        raise MeshshadeError("no beam light (or beam_distances=False): no geodesic distance tally")
    for c, ex in enumerate(result.beam_exits):
        if ex is None:
            continue
        dist = np.einsum("ij,ij->i", ex["bary"], result.beam_distance[mesh.faces[ex["face"]]])
        k = np.searchsorted(edges, dist, side="right") - 1
        ok = (k >= 0) & (k < edges.size - 1)
        per = np.zeros((result.n_batches, edges.size - 1))
        np.add.at(per, (ex["batch"][ok], k[ok]), ex["weight"][ok])
        out[c], err[c] = _batch_stats(per)
    return out, err


# ------------------------------------------------------------------------------------------------ output
def summary_dict(result: MCResult) -> dict:
    """The JSON summary: totals (three values, or one for a grey material) with stderrs, photons, events, seconds."""
    grey = result.material.is_grey
    out = {}
    for key, val in result.totals.items():
        out[key] = float(val[0]) if grey else [float(x) for x in val]
    out.update(lost=float(result.lost[0]) if grey else [float(x) for x in result.lost],
               photons=int(result.photons), events=int(result.events),
               boundary_events=int(result.boundary_events), boundary_tests=int(result.boundary_tests),
               seconds=float(result.seconds), cpu_seconds=float(result.cpu_seconds),
               events_per_second=float(result.events_per_second), n_batches=int(result.n_batches),
               material=result.material.to_dict())
    return out


def describe_mc(result: MCResult) -> str:
    t = result.totals
    f = lambda k: f"{t[k][0]:.5f}±{t[k + '_stderr'][0]:.5f}"  # noqa: E731
    return (f"mc: {result.photons} photons, {result.events} scattering events in {result.seconds:.2f} s "
            f"({result.events_per_second:.3g}/s); R_spec {f('specular_reflectance')}, "
            f"R_diffuse {f('diffuse_reflectance')}, T {f('transmittance')}, A {f('absorbed')} (channel r)")


def write_mc(result: MCResult, mesh, out, *, npz=None, summary=None) -> None:
    """Write the PLY (radiance_r/g/b W/mm^2, stderr_r/g/b, uchar colours), optional NPZ and JSON summary."""
    from meshshade import io  # noqa: PLC0415
    from meshshade.output.tonemap import tonemap  # noqa: PLC0415

    M, S = result.radiance, result.radiance_stderr
    props = {f"radiance_{c}": M[:, i] for i, c in enumerate("rgb")}
    props.update({f"stderr_{c}": S[:, i] for i, c in enumerate("rgb")})
    comments = ["meshshade model mc", f"meshshade material {result.material.describe()}",
                f"meshshade photons {result.photons} seed-reproducible",
                "meshshade radiance_r/g/b: linear radiant exitance in W/mm^2; stderr_r/g/b its standard error"]
    io.write_mesh_ply(out, mesh, props, tonemap(M, operator="drago"), comments=comments)
    if npz:
        arrays = dict(radiance=M, radiance_stderr=S, face_power=result.face_power,
                      face_power_stderr=result.face_power_stderr, vertex_power=result.vertex_power,
                      vertex_areas=mesh.vertex_areas)
        if result.beam_distance is not None:
            arrays["beam_distance"] = result.beam_distance
            finite = result.beam_distance[np.isfinite(result.beam_distance)]
            edges = np.linspace(0.0, 1.000001 * float(finite.max()) if finite.size else 1.0, 101)
            power, stderr = beam_radial_power(result, mesh, edges)
            arrays.update(beam_radial_edges_mm=edges, beam_radial_power=power.T, beam_radial_power_stderr=stderr.T)
        io.write_npz(npz, **arrays)
    if summary:
        io.write_json(summary, summary_dict(result))
