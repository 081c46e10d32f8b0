"""Monte Carlo reference: a volumetric random walk inside the mesh that the diffusion models shade.

The medium is the bake's inside, {w > 1/2} of the mesh's generalised winding number: the walk runs on its boundary
(:mod:`meshshade.montecarlo.boundary`: holes closed by lids on the level surface w = 1/2, faces with the medium on
both sides or neither left out, seams of overlapping parts followed), which for a closed mesh is the mesh itself.

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

Where: in this process, or split across the workers of a Dask client (``client=``,
:mod:`meshshade.montecarlo.distributed`; the same result for any number of workers). The set-up and the walk of one
channel group over a range of photons are :mod:`meshshade.montecarlo.walks`, shared by both.

Engines: the default pooled engine (:mod:`meshshade.montecarlo.engine`) walks a regenerating pool of photons
with compiled loops, certifies short free flights with a safe-distance grid and asks Embree only for the others;
``fast_interior=False`` selects the baseline numpy wavefront (:mod:`meshshade.montecarlo.wavefront_oracle`, one Embree
query per photon and step; kept as the oracle of the tests and benchmarks). Both follow the physics above and give
the same distributions. Photons enter through :class:`meshshade.montecarlo.emitter.Emitter`; the sampling
functions and roulette constants are in :mod:`meshshade.montecarlo.sampling`.

Uncertainty: photon ``i`` belongs to batch ``i % n_batches``; every reported quantity is also tallied per batch
and its standard error is the batch-means estimate std(batch values, ddof=1)/sqrt(n_batches).

Pure computation, no file I/O (results are written by :func:`meshshade.output.mc_file.write_mc`, through
:mod:`meshshade.io`).
"""
from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from meshshade.errors import MaterialError, MeshshadeError
from meshshade.geometry.geodesics.neighbourhoods import GeodesicNeighbourhoods
from meshshade.light import BeamLight
from meshshade.light.samples import check_exitance
from meshshade.materials import Material
from meshshade.montecarlo.boundary import WalkSurface, walk_surface
from meshshade.montecarlo.distributed import walk_on_client
from meshshade.montecarlo.media import is_varying, painted_groups, part_groups, walk_mesh
from meshshade.montecarlo.varying_walk import prepare_varying_walks, walk_varying_group
from meshshade.montecarlo.walks import channel_groups, check_engine, make_emitter, prepare_walks, walk_group
from meshshade.painted import PaintedMaterial
from meshshade.preview import mesh_preview
from meshshade.progress import Progress
from meshshade.raycast import make_scene

__all__ = ["DEFAULT_BATCHES", "TOTAL_KEYS", "MCOptions", "MCResult", "batch_stats", "check_mc_options", "simulate",
           "mc_options_from_keywords"]

DEFAULT_BATCHES = 16
#: MCOptions.inside: the medium {w > 1/2} of the winding number (the bake's), or every face a boundary
INSIDE_CHOICES = ("winding", "faces")
TOTAL_KEYS = ("specular_reflectance", "diffuse_reflectance", "transmittance", "absorbed")


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
    boundary_tests : ray casts (Embree queries) made by the walk; null_collisions : tentative collisions of a walk
        in a varying medium that were null (delta tracking, :mod:`meshshade.montecarlo.varying_walk`);
        seconds / cpu_seconds : wall-clock and process CPU time (all threads) of the walk, without the set-up
        (scene, safe-distance grid, emitter).
    surface : the :class:`~meshshade.montecarlo.boundary.WalkSurface` walked in (the medium's boundary: the mesh
        itself when closed, else its boundary faces and the lids of its holes); lid_power, lid_power_stderr : (3,)
        W leaving through the lids (part of the diffuse and transmitted totals, on no vertex and no face).
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
    photons_per_channel: np.ndarray | None = None
    surface: WalkSurface | None = None
    lid_power: np.ndarray | None = None
    lid_power_stderr: np.ndarray | None = None
    null_collisions: int = 0

    @property
    def events_per_second(self) -> float:
        return self.events / max(self.seconds, 1e-12)

    def __repr__(self) -> str:
        t = self.totals
        return (f"<MCResult {self.material.name}: {self.photons} photons per channel group, {self.events} events in "
                f"{self.seconds:.3g} s; diffuse reflectance {t['diffuse_reflectance'][0]:.4g} "
                f"± {t['diffuse_reflectance_stderr'][0]:.2g} (r)>")

    def plot(self, mesh, **kwargs):
        """A matplotlib figure of ``mesh`` (the mesh of the run) coloured by the Monte Carlo exitance
        (:func:`meshshade.preview.mesh_preview`; keyword arguments go there)."""
        kwargs.setdefault("title", f"Monte Carlo, {self.material.name}, {self.photons} photons")
        return mesh_preview(mesh.vertices, mesh.faces, self.radiance, **kwargs)


def batch_stats(per_batch):
    """(B, ...) batch totals -> (mean of the sum-estimate, stderr of the sum) with equal-size batches.

    per_batch : (B, ...) float64, the quantity summed over each batch's photons (B equal-size batches).
    Returns (total (...), stderr (...)): the sum over batches and its batch-means standard error.
    """
    B = per_batch.shape[0]
    total = per_batch.sum(axis=0)
    stderr = np.std(per_batch * B, axis=0, ddof=1) / np.sqrt(B) if B > 1 else np.zeros_like(total)
    return total, stderr


#: most photons per channel group: photon indices key the per-photon random streams and are counted in int64
#: (a time-budget run without a photon count uses this as its unbounded count)
MAX_PHOTONS = 1 << 62
#: optimistic throughput for the run-time estimate: 2.5e7 events/s per core, 1.6x the best measured (30.7 M
#: events/s on 2 cores, MCML semi-infinite case, docs/benchmarks.md); every photon costs at least one event
MAX_EVENTS_PER_SECOND_PER_CORE = 2.5e7
#: runs estimated (at that optimistic rate) above this are refused unless a time budget bounds them: 1 day
MAX_RUN_SECONDS = 86400.0
#: with a time budget, each channel group gets at least this fraction of its equal share of the budget (a group
#: that overran its share cannot leave the next ones nothing: the run then overruns instead, by at most this)
MIN_GROUP_SHARE = 0.5
#: most batches (per-batch tallies hold n_batches x faces floats) and photons walked together (~200 bytes each)
MAX_BATCHES = 256
MAX_POOL = 1 << 22


def _count(value, name: str, lo: int, hi: int | None, hi_text: str = "") -> int:
    """An integer count in [lo, hi] (hi None: no upper bound; an integral float such as 1e5 is accepted);
    MeshshadeError naming ``name``, the value and the range otherwise."""
    ok = not isinstance(value, (bool, str)) and isinstance(value, (int, float, np.integer, np.floating))
    if ok and not isinstance(value, (int, np.integer)):
        ok = math.isfinite(value) and float(value).is_integer()
    if not ok or int(value) < lo or (hi is not None and int(value) > hi):
        rng = f"[{lo}, {hi_text or hi}]" if hi is not None else f">= {lo}"
        raise MeshshadeError(f"{name} must be an integer {'in ' if hi is not None else ''}{rng}, got {value!r}")
    return int(value)


def _duration(seconds: float) -> str:
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("hours", 3600), ("minutes", 60)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def check_mc_options(photons=100_000, *, seed=0, time_budget=None, n_batches=DEFAULT_BATCHES, pool=None,
                     engine="auto", groups=1) -> tuple:
    """Validate :func:`simulate`'s arguments before any work; returns ``(photons, seed, time_budget, n_batches,
    pool)`` normalised (ints, floats). One-line MeshshadeError naming the argument, its value and what is allowed:

    * ``photons``: None (only with a time budget) or an integer in [n_batches, ``MAX_PHOTONS`` = 2^62]; without a
      ``time_budget``, also refused when even at the optimistic ``MAX_EVENTS_PER_SECOND_PER_CORE`` on every core
      (one event per photon, ``groups`` channel groups) the run would exceed ``MAX_RUN_SECONDS`` (1 day): the
      message gives the estimate and how to proceed (fewer photons, or a time budget);
    * ``seed``: an integer in [0, 2^64); ``time_budget``: None or a finite number of seconds > 0;
    * ``n_batches``: an integer in [2, ``MAX_BATCHES``]; ``pool``: None or an integer in [1, ``MAX_POOL``];
    * ``engine``: "auto", "fused" or "batched" ("direct": the former spelling of "fused", deprecated).
    """
    if time_budget is not None:
        t = float(time_budget) if isinstance(time_budget, (int, float, np.number)) and \
            not isinstance(time_budget, bool) else math.nan
        if not (0.0 < t < math.inf):
            raise MeshshadeError(f"time_budget must be a finite number of seconds > 0, got {time_budget!r}")
        time_budget = t
    n_batches = _count(n_batches, "n_batches (batches for the standard errors)", 2, MAX_BATCHES)
    if photons is None:
        if time_budget is None:
            raise MeshshadeError("give a photon count or a time budget")
    else:
        photons = _count(photons, "photons", n_batches, None)
    seed = _count(seed, "seed", 0, (1 << 64) - 1, "2^64 - 1")
    if pool is not None:
        pool = _count(pool, "pool (photons walked together)", 1, MAX_POOL)
    check_engine(engine)
    if photons is not None:
        cores = os.cpu_count() or 1
        least = photons * groups / (MAX_EVENTS_PER_SECOND_PER_CORE * cores)
        estimate = (f"would take at least {_duration(least)} ({groups} channel group(s), one event per photon at "
                    f"{MAX_EVENTS_PER_SECOND_PER_CORE:.2g} events/s on each of {cores} cores)").replace("e+0", "e")
        if photons > MAX_PHOTONS:
            raise MeshshadeError(f"photons = {photons:.3g} exceeds 2^62 = {MAX_PHOTONS:.3g}, the most that the "
                                 f"per-photon random streams and int64 counters support, and {estimate}")
        if time_budget is None and least > MAX_RUN_SECONDS:
            raise MeshshadeError(
                f"photons = {photons:.3g} {estimate}, beyond the {MAX_RUN_SECONDS / 86400:g}-day limit: use fewer "
                "photons, or a time budget (--time-budget SECONDS; time_budget= in Python) to stop in time")
    return photons, seed, time_budget, n_batches, pool


@dataclass(frozen=True)
class MCOptions:
    """How :func:`simulate` walks; a frozen record, checked where it is made (:func:`check_mc_options`: a one-line
    MeshshadeError naming the option, its value and what is allowed).

    photons : photons per channel group (with ``time_budget``: an upper bound, None = unbounded)
    seed : int >= 0, makes the run reproducible: with the pooled engine photon ``i`` of channel group ``k`` draws
        every random number from a stream keyed by (seed, k, i), so the result is bitwise identical for any
        number of threads and photon i's path does not depend on ``pool``
    time_budget : float seconds or None, counted from the call: emission stops when the photons in flight are
        predicted to finish within the budget; photons still in flight at 1.25 x the budget are cut off and
        their weight is reported as ``lost``. The channel groups walk one after the other, each on what is left
        shared by those still to come, but at least ``MIN_GROUP_SHARE`` of an equal share, and every group walks
        at least its first round of photons (see :mod:`meshshade.montecarlo.engine` for the bound; the baseline
        wavefront, ``fast_interior=False``, finishes all photons in flight)
    n_batches : batches for the standard errors (>= 2)
    pool : photon slots advanced together (default 2**18 for the pooled engine, 2**16 for the baseline)
    engine : pooled engine's Embree calls: "fused" (rtcIntersect1 from the numba threads, inside the walk,
        :mod:`meshshade.raycast.embree_direct`), "batched" (one embreex call per round) or "auto" (fused when the
        Embree library can be bound, else batched). Both give the same photon paths up to float32 ties. "direct":
        the former spelling of "fused" (deprecated: a DeprecationWarning).
    fast_interior : True: the pooled engine (numba interior walks inside a conservative safe-distance grid,
        one batched Embree query per round, :mod:`meshshade.montecarlo.engine`); False: the plain numpy
        wavefront with an Embree query every step (the baseline: same distribution, different random streams)
    keep_beam_exits : keep the exit points of a beam's photons (``MCResult.beam_exits``)
    beam_distances : compute per-vertex geodesic distances from the first beam's entry point
    inside : where the medium is. "winding" (default): the bake's inside {w > 1/2} of the mesh's generalised
        winding number (:func:`meshshade.montecarlo.boundary.walk_surface`: holes closed by lids on w = 1/2 with
        Fresnel as at a face, faces with the medium on both sides or neither passed through; a closed mesh is
        walked as it is). "faces": every face a boundary with the medium behind it, no lid
        (:meth:`WalkSurface.of_faces <meshshade.montecarlo.boundary.WalkSurface.of_faces>`: the walk before issue
        47, in which a photon walks out through a hole; kept to measure against)
    """

    photons: int | None = 100_000
    seed: int = 0
    time_budget: float | None = None
    n_batches: int = DEFAULT_BATCHES
    pool: int | None = None
    engine: str = "auto"
    fast_interior: bool = True
    keep_beam_exits: bool = True
    beam_distances: bool = True
    inside: str = "winding"

    def __post_init__(self):
        engine = check_engine(self.engine, stacklevel=4)
        photons, seed, time_budget, n_batches, pool = check_mc_options(
            self.photons, seed=self.seed, time_budget=self.time_budget, n_batches=self.n_batches, pool=self.pool,
            engine=engine)
        for name, value in (("photons", photons), ("seed", seed), ("time_budget", time_budget),
                            ("n_batches", n_batches), ("pool", pool), ("engine", engine)):
            object.__setattr__(self, name, value)
        for name in ("fast_interior", "keep_beam_exits", "beam_distances"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise MeshshadeError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if self.inside not in INSIDE_CHOICES:
            raise MeshshadeError(f"inside must be one of {', '.join(map(repr, INSIDE_CHOICES))}, got {self.inside!r}")


#: fields of MCOptions that never were keywords of simulate (not accepted as deprecated ones)
NEW_FIELDS = ("inside",)


def mc_options_from_keywords(options: MCOptions | None, keywords: dict, where: str = "simulate",
                             stacklevel: int = 3) -> MCOptions:
    """``options`` (default ones for None) with the former keyword arguments ``keywords`` of ``where`` (the fields
    of :class:`MCOptions`) applied, with a DeprecationWarning attributed ``stacklevel`` frames up; an unknown
    keyword is a TypeError, as Python's own."""
    options = MCOptions() if options is None else options
    if not isinstance(options, MCOptions):
        raise MeshshadeError(f"{where}: options must be MCOptions or None, got {type(options).__name__}")
    if not keywords:
        return options
    unknown = sorted(set(keywords) - (set(MCOptions.__dataclass_fields__) - set(NEW_FIELDS)))
    if unknown:
        raise TypeError(f"{where}() got an unexpected keyword argument {unknown[0]!r}")
    warnings.warn(f"{where}({', '.join(f'{k}=' for k in keywords)}...) is deprecated; pass "
                  "options=MCOptions(...) (meshshade.montecarlo)", DeprecationWarning, stacklevel=stacklevel)
    return replace(options, **keywords)


def simulate(mesh, material: Material, lights, options: MCOptions | None = None, *, progress: bool | str = False,
             client=None, **deprecated) -> MCResult:
    """Monte Carlo random walk inside ``mesh`` lit by ``lights``; see the module docstring.

    Parameters
    ----------
    mesh : Mesh (vertices in mm). The medium is the bake's inside {w > 1/2} of its generalised winding number
        (:mod:`meshshade.montecarlo.boundary`; ``MCOptions.inside``): holes are closed by lids on the level surface
        w = 1/2, faces with the medium on both sides or neither are passed through; a closed mesh is walked as it is
    material : Material (its medium's sigma_s, sigma_a, and eta, g), or a varying medium: a
        :class:`~meshshade.painted.PaintedMaterial` (each point the medium of the nearest surface point, its colour
        the diffuse reflectance there, §17) or a :class:`~meshshade.parts.PartedMaterial` (each point the medium of
        the innermost part owning it), walked by delta tracking (:mod:`meshshade.montecarlo.varying_walk`; the
        pooled engine's fused mode, in this process: no client, no ``fast_interior=False``)
    lights : light or sequence of BeamLight / DirectionalLight / PointLight
    options : MCOptions or None (the defaults: 1e5 photons per channel group, seed 0): photons, seed, time
        budget, batches, pool, engine (:class:`MCOptions`). Its former keyword arguments (``photons=``,
        ``seed=``...) are accepted with a DeprecationWarning.
    progress : False, True or the task named in the progress lines (default "mc"): photons emitted, as a bar on
        a terminal and as periodic lines otherwise (:class:`meshshade.progress.Progress`)
    client : a :class:`distributed.Client`: split the photons across its workers in tasks of whole entry chunks
        (:mod:`meshshade.montecarlo.distributed`). The split depends only on the photon count and the partial
        tallies are added in a fixed order, so the result is bitwise the same for any number of workers, and
        the same as without a client up to the order of the sums (~1e-15). Needs a photon count (no
        ``time_budget``) and the pooled engine. ``seconds`` is then the wall time of the split run.

    Returns
    -------
    MCResult

    Raises
    ------
    MeshshadeError
        A time budget or ``fast_interior=False`` with a client.
        An argument outside its domain (:func:`check_mc_options`), checked before any work, including a photon
        count that cannot finish (more than ``MAX_PHOTONS``, or, without a time budget, a run estimated at more
        than ``MAX_RUN_SECONDS``).
    LightError
        No light, a beam that misses, no light reaching the mesh (as the bake: :class:`Emitter`).
    """
    options = mc_options_from_keywords(options, deprecated, "simulate", stacklevel=3)
    varying = is_varying(material)
    if not varying and not isinstance(material, Material):
        raise MaterialError(f"Monte Carlo needs a Material, PaintedMaterial or PartedMaterial, got "
                            f"{type(material).__name__}")
    o = options
    if varying:
        material.check_mesh(mesh)
        groups = painted_groups(material) if isinstance(material, PaintedMaterial) else part_groups(material)
        if client is not None or not o.fast_interior:
            raise MeshshadeError("a painted or parted material walks in the pooled engine in this process only: "
                                 "no Dask client, no fast_interior=False")
    else:
        groups = channel_groups(material)
    photons, seed, time_budget, n_batches, pool = check_mc_options(   # the run's estimate needs the groups
        o.photons, seed=o.seed, time_budget=o.time_budget, n_batches=o.n_batches, pool=o.pool, engine=o.engine,
        groups=len(groups))
    engine, fast_interior, keep_beam_exits, beam_distances = o.engine, o.fast_interior, o.keep_beam_exits, \
        o.beam_distances
    if client is not None:
        if time_budget is not None:
            raise MeshshadeError("a time budget cannot be split across Dask workers (the split needs a photon "
                                 "count); give photons without time_budget")
        if not fast_interior:
            raise MeshshadeError("fast_interior=False (the baseline wavefront) runs in one process only; drop the "
                                 "client or use the pooled engine")
    t_start = time.perf_counter()
    n_photons = int(photons) if photons is not None else 1 << 62
    # photons emitted: a bar on a terminal, periodic lines otherwise (meshshade.progress)
    bar = Progress(progress if isinstance(progress, str) else "mc",
                   None if photons is None else n_photons * len(groups), "photons", enabled=bool(progress))
    try:
        # the medium's boundary (MCOptions.inside): the bake's inside {w > 1/2}, or the faces alone
        # (parts: each part wound outward, so that a nested part is medium, not a cavity)
        wmesh = walk_mesh(material, mesh) if varying else mesh
        surface = walk_surface(wmesh) if o.inside == "winding" else WalkSurface.of_faces(wmesh)
        if client is not None:
            # the lights are checked here, before any task (a beam that misses is one line, as in one process)
            emitter = make_emitter(mesh, surface, lights, material.eta, make_scene(surface.vertices, surface.faces))
            t0, c0 = time.perf_counter(), time.process_time()
            tallies = walk_on_client(client, mesh, material, lights, n_photons, seed=seed, n_batches=n_batches,
                                     pool=pool, keep_beam=keep_beam_exits, engine=engine, progress=bar,
                                     surface=surface)
        else:
            if varying:
                setup = prepare_varying_walks(wmesh, material, lights, surface, engine=engine,
                                              half_space_certificates=time_budget is None)
            else:
                setup = prepare_walks(mesh, material, lights, engine=engine, fast_interior=fast_interior,
                                      half_space_certificates=time_budget is None, surface=surface)
            emitter = setup.emitter
            children = np.random.SeedSequence(seed).spawn(len(groups))
            t0, c0 = time.perf_counter(), time.process_time()
            tallies = []
            for gi in range(len(groups)):
                budget = None
                if time_budget is not None:  # what is left, shared by the remaining groups, never below a floor
                    left = max(time_budget - (time.perf_counter() - t_start), 0.0) / (len(groups) - gi)
                    budget = max(left, MIN_GROUP_SHARE * time_budget / len(groups))
                if varying:
                    tallies.append(walk_varying_group(setup, gi, n_photons, seed=seed, n_batches=n_batches,
                                                      pool=pool, keep_beam=keep_beam_exits, time_budget=budget,
                                                      progress=bar))
                    continue
                tallies.append(walk_group(setup, gi, n_photons, seed=seed, n_batches=n_batches, pool=pool,
                                          keep_beam=keep_beam_exits, time_budget=budget, progress=bar,
                                          rng=np.random.default_rng(children[gi])))
    finally:  # also on KeyboardInterrupt: the bar clears its line before the error message is printed
        bar.close()
    V, F = mesh.vertices, mesh.faces
    n = V.shape[0]
    face_p = np.zeros((F.shape[0], 3)); face_se = np.zeros_like(face_p)
    vert_p = np.zeros((n, 3)); vert_se = np.zeros_like(vert_p)
    lid_p = np.zeros(3); lid_se = np.zeros(3)
    lid = surface.lid
    tot = np.zeros((7, 3)); tot_se = np.zeros((7, 3))
    frac = np.zeros((5, 3)); frac_se = np.zeros((5, 3))
    events = boundary = rays = 0
    per_channel = np.zeros(3, dtype=np.int64)
    exits = [None] * 3
    for (_key, chans), walk in zip(groups, tallies):
        emitted = walk.emitted
        rays += walk.rays
        per_channel[chans] = emitted
        scale = n_photons / emitted if emitted else 1.0
        # photon weights were P/n_photons: each group's tallies are normalised by its own count (a time budget
        # stops each group's emission on its own)
        # on the mesh's faces and vertices, batch by batch (the walk surface's lids and parts of split faces)
        face_t = walk.face if surface.identity else surface.mesh_face_tally(walk.face)
        vert_t = walk.face_vert if surface.identity else surface.mesh_vertex_tally(walk.face_vert)
        fp, fse = batch_stats(face_t * scale)
        vp, vse = batch_stats(vert_t * scale)
        lp, lse = batch_stats(walk.face[:, lid].sum(axis=1) * scale)
        tt, tse = batch_stats(walk.tot * scale)
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
            # on the mesh's faces (exits through a lid are on none: left out of the beam's tallies)
            group_exits["face"], group_exits["bary"] = surface.mesh_bary(group_exits["face"], group_exits["bary"])
            on = group_exits["face"] >= 0
            if not np.all(on):
                group_exits = {k: v[on] for k, v in group_exits.items()}
        for c in chans:
            face_p[:, c], face_se[:, c], vert_p[:, c], vert_se[:, c] = fp, fse, vp, vse
            lid_p[c], lid_se[c] = lp, lse
            tot[:, c], tot_se[:, c], frac[:, c], frac_se[:, c] = tt, tse, fr, fse_tot
            if group_exits is not None:
                exits[c] = group_exits   # channels of one group share the (read-only) arrays
        events += walk.events
        boundary += walk.boundary
    seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    va = mesh.vertex_areas if surface.identity else surface.vertex_areas()   # the boundary's, eq. (129)
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
        f_mesh, b_mesh = surface.mesh_bary(np.array([int(b[1])]), np.asarray(b[2]))
        beam_entry = (int(f_mesh[0]), b_mesh[0]) if f_mesh[0] >= 0 else None   # None: the beam enters a lid
        if beam_entry is not None and surface.identity:
            beam_entry = (int(b[1]), np.asarray(b[2]))
        if beam_entry is not None and beam_distances:
            beam_distance = GeodesicNeighbourhoods(V, F).distances_from(face=beam_entry[0], bary=beam_entry[1])
    check_exitance(radiance, lights)  # finite and >= 0, or a one-line error naming the lights' strengths
    return MCResult(material=material, face_power=face_p, face_power_stderr=face_se, vertex_power=vert_p,
                    radiance=radiance, radiance_stderr=radiance_se, totals=totals, lost=frac[4],
                    incident_power=tot[5], entering_power=tot[6], photons=int(per_channel.min()),
                    photons_per_channel=per_channel, events=events,
                    boundary_events=boundary, seconds=seconds, n_batches=n_batches, boundary_tests=rays,
                    cpu_seconds=cpu_seconds,
                    beam_exits=exits if keep_beam_exits else [], beam_entry=beam_entry,
                    beam_distance=beam_distance, surface=surface, lid_power=lid_p, lid_power_stderr=lid_se,
                    null_collisions=int(sum(getattr(t, "nulls", 0) for t in tallies)))

