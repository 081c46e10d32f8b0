"""`meshshade bench`: what accuracy costs in time.

For a fixed set of scenes (spheres of R0 = 5, 20 and 100 mm, a long cylinder, a torus, and two real meshes of
../shared/meshes at realistic sizes) under a beam or a directional light, every model of
:data:`meshshade.transport.bake.MODELS` (read at run time) and every knob is measured against the best available
reference (bench_reference.py: the exact sphere or cylinder where they exist, otherwise Monte Carlo with its
standard errors): max and mean relative error, relative error of the exitant energy, and wall time.

Knobs (one varied at a time, the others at ``bake``'s defaults, rows ``knob="default"`` are the baseline):

* ``rtol``: the series tolerance of ``bake`` (only models that sum a series: not ``dipole`` or ``curved``);
* ``cutoff_tol``: the neighbourhood cutoff tolerance;
* ``resolution``: mesh refinement level of the procedural scenes (icosphere level; cylinder and torus
  segments 2^(level+2));
* ``geodesic``: the other geodesic method (beams default to ``exact``; directional lights to ``arc``, because
  exact neighbourhoods of every lit vertex cost minutes even on 10k vertices);
* ``render``: per-vertex vs per-pixel rendering of a baked beam (exact references only). Time: the bake plus
  the ``render_radiance`` call (per-pixel includes building the :class:`~meshshade.output.render.PixelGather`); error:
  exitance at the pixel centres' surface points of the same orthographic camera against the exact reference;
* ``photons``: the Monte Carlo photon count (model ``mc``; against an exact reference, or against the
  reference MC run with another seed).

Time is the wall time of the bake (render, simulate) call alone, by ``time.perf_counter``, after a warm-up of
every model on a tiny scene so that numba compilation is excluded. Material: the skin-like grey medium of
physics.md (sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3); errors on channel 0.

API: ``plan = bench_plan(quick=...)`` (a list of :class:`Run`), ``result = run_bench(plan, seed=...)``
(:class:`BenchResult` with ``rows`` and ``metadata``), ``bench_report.write_bench(result, out_dir)``.
"""
from __future__ import annotations

import inspect
import os
import platform
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.materials import Material

MATERIAL = Material(1.0, 0.01, 1.3, name="skin-like")
KNOBS = ("default", "rtol", "cutoff_tol", "resolution", "geodesic", "render", "photons")
#: models for which bake's rtol (series tolerance) changes nothing
NO_SERIES = ("dipole", "curved")
COLUMNS = ("scene", "model", "knob", "value", "error_max", "error_mean", "error_energy", "time_s", "ref_kind",
           "ref_stderr", "resolved_frac", "n_eval", "n_vertices", "light")


def bake_defaults() -> dict:
    """``rtol``, ``cutoff_tol`` and ``geodesic`` defaults of :func:`meshshade.transport.bake.bake` (kept in sync)."""
    from meshshade.transport.bake import bake  # noqa: PLC0415

    p = inspect.signature(bake).parameters
    return {k: p[k].default for k in ("rtol", "cutoff_tol", "geodesic")}


def shared_meshes_dir() -> Path:
    """../shared/meshes next to the project (or $MESHSHADE_SHARED/meshes), as tests/conftest.py finds it."""
    root = Path(__file__).resolve().parents[2] / "shared"
    return Path(os.environ.get("MESHSHADE_SHARED", root)) / "meshes"


# ------------------------------------------------------------------------------------------------ scenes
@dataclass(frozen=True)
class Scene:
    """A benchmark scene as data: geometry, size, light, reference kind and default resolution.

    shape : "sphere" (radius ``size_mm``) | "cylinder" (radius ``size_mm``, length ``length_mm``, along z) |
        "torus" (tube radius ``size_mm``, major radius 3 x size) | "mesh" (``mesh_file`` in ../shared/meshes,
        centred, largest extent scaled to ``size_mm``)
    light : "beam" | "directional"; reference : "exact" | "mc"; level : default refinement;
    geodesic : the scene's baseline geodesic method; patch_mm : MC comparison patch size
    """

    name: str
    shape: str
    size_mm: float
    light: str
    reference: str
    level: int = 4
    length_mm: float = 100.0
    mesh_file: str | None = None
    geodesic: str = "exact"
    patch_mm: float = 2.0

    def build(self, level: int | None = None):
        from meshshade.geometry.mesh import Mesh  # noqa: PLC0415
        from meshshade.geometry.procedural import capped_cylinder, icosphere, torus  # noqa: PLC0415

        L = self.level if level is None else int(level)
        R = self.size_mm
        if self.shape == "sphere":
            V, F = icosphere(R, L)
        elif self.shape == "cylinder":
            seg = 2 ** (L + 2)
            V, F = capped_cylinder(R, self.length_mm, seg, int(round(self.length_mm / (2 * np.pi * R / seg))))
        elif self.shape == "torus":
            V, F = torus(3.0 * R, R, 3 * 2 ** (L + 2), 2 ** (L + 2))
        elif self.shape == "mesh":
            from meshshade.io import read_mesh_arrays  # noqa: PLC0415

            path = shared_meshes_dir() / self.mesh_file
            if not path.exists():
                raise MeshshadeError(f"scene {self.name}: {path} not found (../shared/meshes is only in the "
                                     "developers' workspace)")
            V, F = read_mesh_arrays(path)
            V = (V - 0.5 * (V.min(axis=0) + V.max(axis=0))) * (self.size_mm / np.ptp(V, axis=0).max())
        else:
            raise MeshshadeError(f"unknown scene shape {self.shape!r}")
        return Mesh.from_arrays(V, F, source=f"bench:{self.name}:L{L}")

    def make_light(self, mesh):
        """The scene's light, aimed from outside: beams with small offsets so they never hit a vertex."""
        from meshshade.light.samples import BeamLight, DirectionalLight  # noqa: PLC0415

        R = self.size_mm
        if self.light == "directional":
            d = (0.0, 0.0, -1.0) if self.shape == "sphere" else (0.3, -0.4, -0.866)
            return DirectionalLight(d, 1.0)
        if self.shape == "sphere":
            return BeamLight((0.0123 * R, 0.0071 * R, 3.0 * R), (0.0, 0.0, -1.0))
        if self.shape == "cylinder":
            return BeamLight((3.0 * R, 0.0131 * R, 0.0213 * R), (-1.0, 0.0, 0.0))
        if self.shape == "torus":  # from the hole's centre outwards: enters at the inner equator, a saddle
            return BeamLight((0.0, 0.0131, 0.0213), (1.0, 0.0, 0.0))
        c = mesh.bbox.mean(axis=0)
        return BeamLight((c[0] + 0.0131, c[1] + 0.0213, mesh.bbox[1, 2] + 0.5 * self.size_mm), (0.0, 0.0, -1.0))

    @property
    def procedural(self) -> bool:
        return self.shape != "mesh"


def _s(name, shape, size, light, ref, **kw):
    return Scene(name, shape, size, light, ref, **kw)


#: every scene of the full run (quick mode picks some and coarsens them, see bench_plan)
SCENES = {s.name: s for s in (
    _s("sphere_r5_beam", "sphere", 5.0, "beam", "exact", level=5),
    _s("sphere_r20_beam", "sphere", 20.0, "beam", "exact", level=5),
    _s("sphere_r100_beam", "sphere", 100.0, "beam", "exact", level=6),
    _s("sphere_r5_directional", "sphere", 5.0, "directional", "exact", level=3, geodesic="arc"),
    _s("sphere_r20_directional", "sphere", 20.0, "directional", "exact", level=4, geodesic="arc"),
    _s("sphere_r100_directional", "sphere", 100.0, "directional", "exact", level=4, geodesic="arc"),
    _s("cylinder_r10_beam", "cylinder", 10.0, "beam", "exact", level=4, length_mm=100.0),
    _s("torus_beam", "torus", 10.0, "beam", "mc", level=4, patch_mm=1.5),
    _s("torus_directional", "torus", 10.0, "directional", "mc", level=3, geodesic="arc", patch_mm=3.0),
    _s("spot_50mm_beam", "mesh", 50.0, "beam", "mc", mesh_file="spot.obj", patch_mm=1.5),
    _s("head_200mm_beam", "mesh", 200.0, "beam", "mc", mesh_file="lee_perry_smith_head.obj", patch_mm=2.0),
    _s("head_200mm_directional", "mesh", 200.0, "directional", "mc", mesh_file="lee_perry_smith_head.obj",
       patch_mm=6.0),
    _s("spot_50mm_directional", "mesh", 50.0, "directional", "mc", mesh_file="spot.obj", patch_mm=2.0),
)}


# ------------------------------------------------------------------------------------------------ plan
@dataclass(frozen=True)
class Run:
    """One measurement: ``scene`` with ``model`` at ``level``; ``knob``/``value`` name what differs from the
    defaults. ``settings``: bake keywords (rtol, cutoff_tol, geodesic), or ``render`` / ``photons``."""

    scene: Scene
    model: str
    knob: str
    value: str
    level: int
    settings: dict = field(default_factory=dict)


@dataclass
class BenchConfig:
    """Knob values and sizes of one bench mode; ``bench_plan`` expands it into runs."""

    scenes: tuple
    levels: dict                 # scene name -> default level (overrides the scene's)
    rtol: tuple = ()
    rtol_scenes: tuple = ()
    cutoff: tuple = ()
    cutoff_scenes: tuple = ()
    resolution: dict = field(default_factory=dict)   # scene name -> levels
    geodesic_scenes: tuple = ()
    render_scenes: tuple = ()
    render_width: int = 128
    photons: tuple = ()
    photon_scenes: tuple = ()
    mc_photons: int = 1_000_000  # photons of the MC references


QUICK = BenchConfig(
    scenes=("sphere_r5_beam", "sphere_r20_beam", "sphere_r100_beam", "sphere_r5_directional",
            "sphere_r20_directional", "sphere_r100_directional", "cylinder_r10_beam", "torus_beam",
            "torus_directional", "spot_50mm_beam", "head_200mm_beam"),
    levels={"sphere_r5_beam": 4, "sphere_r20_beam": 4, "sphere_r100_beam": 5, "sphere_r5_directional": 3,
            "sphere_r20_directional": 3, "sphere_r100_directional": 3, "cylinder_r10_beam": 3, "torus_beam": 3,
            "torus_directional": 2},
    rtol=(1e-2, 1e-4, 1e-6, 1e-13), rtol_scenes=("sphere_r20_beam",),
    cutoff=(1e-2, 1e-3, 1e-5), cutoff_scenes=("sphere_r20_directional",),
    resolution={"sphere_r20_beam": (3, 5), "sphere_r20_directional": (2,), "sphere_r100_beam": (4,)},
    geodesic_scenes=("sphere_r20_beam",),
    render_scenes=("sphere_r20_beam",), render_width=64,
    photons=(10_000, 100_000), photon_scenes=("sphere_r20_beam", "torus_beam"),
    mc_photons=1_000_000,
)

FULL = BenchConfig(
    scenes=tuple(SCENES),
    levels={},
    rtol=(1e-2, 1e-4, 1e-6, 1e-8, 1e-12, 1e-14), rtol_scenes=("sphere_r5_beam", "sphere_r20_beam",
                                                               "sphere_r100_beam", "sphere_r20_directional"),
    cutoff=(1e-2, 1e-3, 1e-5, 1e-6), cutoff_scenes=("sphere_r20_beam", "sphere_r20_directional",
                                                      "sphere_r100_directional", "torus_directional"),
    resolution={"sphere_r5_beam": (3, 4, 6), "sphere_r20_beam": (3, 4, 6), "sphere_r20_directional": (2, 3),
                "sphere_r100_directional": (3,), "cylinder_r10_beam": (3, 5), "torus_beam": (3, 5)},
    geodesic_scenes=("sphere_r5_beam", "sphere_r20_beam", "sphere_r100_beam", "cylinder_r10_beam", "torus_beam",
                     "spot_50mm_beam", "head_200mm_beam", "sphere_r5_directional", "head_200mm_directional",
                     "spot_50mm_directional"),
    render_scenes=("sphere_r5_beam", "sphere_r20_beam", "sphere_r100_beam", "cylinder_r10_beam"),
    render_width=192,
    photons=(10_000, 100_000, 1_000_000), photon_scenes=("sphere_r5_beam", "sphere_r20_beam",
                                                         "sphere_r20_directional", "torus_beam", "spot_50mm_beam"),
    mc_photons=4_000_000,
)


def bench_plan(*, quick: bool = False, scenes=None, models=None, config: BenchConfig | None = None) -> list:
    """The runs of a bench mode (``config`` overrides ``quick``); ``scenes`` (names of :data:`SCENES`, or
    :class:`Scene` objects) and ``models`` restrict it.

    Models default to :data:`meshshade.transport.bake.MODELS` as it is now, so a model added there is benchmarked
    without a change here.
    """
    from meshshade.transport.bake import MODELS  # noqa: PLC0415

    cfg = config or (QUICK if quick else FULL)
    models = tuple(MODELS) if models is None else tuple(models)
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise MeshshadeError(f"unknown model {bad[0]!r}; choose among {', '.join(MODELS)}")
    picked = cfg.scenes if scenes is None else tuple(scenes)
    for n in picked:
        if not isinstance(n, Scene) and n not in SCENES:
            raise MeshshadeError(f"unknown scene {n!r}; choose among {', '.join(SCENES)}")
    if not picked:
        raise MeshshadeError("no scene chosen")
    d = bake_defaults()
    runs = []
    for sc in (n if isinstance(n, Scene) else SCENES[n] for n in picked):
        n = sc.name
        L = cfg.levels.get(n, sc.level)
        base = {"rtol": d["rtol"], "cutoff_tol": d["cutoff_tol"], "geodesic": sc.geodesic}
        for m in models:
            runs.append(Run(sc, m, "default", "", L, dict(base)))
            if n in cfg.rtol_scenes and m not in NO_SERIES:
                runs += [Run(sc, m, "rtol", f"{v:g}", L, {**base, "rtol": v}) for v in cfg.rtol]
            if n in cfg.cutoff_scenes:
                runs += [Run(sc, m, "cutoff_tol", f"{v:g}", L, {**base, "cutoff_tol": v}) for v in cfg.cutoff]
            runs += [Run(sc, m, "resolution", str(v), v, dict(base)) for v in cfg.resolution.get(n, ()) if v != L]
            if n in cfg.geodesic_scenes and m != "auto":  # auto chooses its geodesics per entry sample
                other = "arc" if sc.geodesic == "exact" else "exact"
                runs.append(Run(sc, m, "geodesic", other, L, {**base, "geodesic": other}))
            if n in cfg.render_scenes and sc.reference == "exact" and sc.light == "beam":
                runs += [Run(sc, m, "render", mode, L, {**base, "render": mode, "width": cfg.render_width})
                         for mode in ("per-vertex", "per-pixel")]
        if n in cfg.photon_scenes:
            runs += [Run(sc, "mc", "photons", str(p), L, {"photons": p}) for p in cfg.photons]
    return runs


# ------------------------------------------------------------------------------------------------ execution
@dataclass
class BenchResult:
    rows: list
    metadata: dict


def _warm_up(models, log):
    """Compile (or load from cache) every numba kernel on a tiny scene, so no timed call pays for it."""
    from meshshade.geometry.mesh import Mesh  # noqa: PLC0415
    from meshshade.geometry.procedural import icosphere  # noqa: PLC0415
    from meshshade.light.samples import BeamLight, DirectionalLight  # noqa: PLC0415
    from meshshade.montecarlo.simulate import simulate  # noqa: PLC0415
    from meshshade.output.render import Camera, PixelGather, render_radiance  # noqa: PLC0415
    from meshshade.transport.bake import bake  # noqa: PLC0415

    t = time.perf_counter()
    mesh = Mesh.from_arrays(*icosphere(5.0, 2))
    beam = BeamLight((0.06, 0.04, 15.0), (0, 0, -1))
    for m in models:
        for light in (beam, DirectionalLight((0, 0, -1))):
            for geo in ("exact", "arc"):
                res = _failsafe(lambda: bake(mesh, MATERIAL, [light], model=m, geodesic=geo), log, f"warm-up {m}")
        if res is not None:
            cam = Camera("orthographic", (0, 0, 20), (0, 0, 0), ortho_height=4.0)
            render_radiance(mesh, res.radiance, cam, 8, 8, spp=1, eta=MATERIAL.eta, exitance_at=PixelGather(mesh, res))
    simulate(mesh, MATERIAL, [beam], photons=2000, seed=0, keep_beam_exits=False, beam_distances=False)
    _failsafe(lambda: __import__("meshshade.bench.references", fromlist=["_"]).sphere_beam_exitance(
        np.array([0.1]), R_mm=5.0, material=MATERIAL), log, "warm-up reference")
    return time.perf_counter() - t


def _failsafe(fn, log, what):
    """Run ``fn``; a failing model must not end a 30-minute benchmark: report the error in one line, return None.
    (MeshshadeError and the errors a model under development raises; anything else propagates.)"""
    try:
        return fn()
    except (MeshshadeError, ValueError, NotImplementedError, RuntimeError) as exc:
        log(f"{what}: failed: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
        return None


def _render_camera(sc, res):
    """Camera looking down the beam at its entry point (a window of 12 mm, or 1.6 R0 on small spheres)."""
    from meshshade.output.render import Camera  # noqa: PLC0415

    e = res.samples.positions[0]
    n = res.samples.normals[0]
    up = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    h = min(12.0, 1.6 * sc.size_mm)
    return Camera("orthographic", tuple(e + 3.0 * sc.size_mm * n), tuple(e), tuple(up), ortho_height=h)


def _pixel_hits(mesh, camera, width):
    from meshshade.raycast.scene import make_scene  # noqa: PLC0415

    jj, ii = np.meshgrid(np.arange(width), np.arange(width), indexing="xy")
    x = (2 * (jj + 0.5) / width - 1).reshape(-1)
    y = (1 - 2 * (ii + 0.5) / width).reshape(-1)
    o, d = camera.rays(x, y, 1.0)
    hits = make_scene(mesh.vertices, mesh.faces).first_hit(o, d)
    h = hits.hit
    return hits.points[h], hits.face[h], hits.bary[h]


class _Runner:
    def __init__(self, seed, mc_photons, log):
        self.seed, self.mc_photons, self.log = seed, mc_photons, log
        self.meshes, self.refs, self.mc = {}, {}, {}
        self.ref_seconds = {}

    def mesh(self, sc, level):
        key = (sc.name, level)
        if key not in self.meshes:
            self.meshes[key] = sc.build(level)
        return self.meshes[key]

    def reference(self, sc, level):
        from meshshade.bench import references as br  # noqa: PLC0415

        key = (sc.name, level)
        if key in self.refs:
            return self.refs[key]
        mesh = self.mesh(sc, level)
        light = sc.make_light(mesh)
        t = time.perf_counter()
        if sc.reference == "mc":
            mc = self.simulate(mesh, light, self.mc_photons, self.seed)[0]
            ref = br.mc_reference(mesh, light, mc, patch_mm=sc.patch_mm)
        elif sc.shape == "sphere":
            ref = br.exact_sphere_reference(mesh, light, R_mm=sc.size_mm, material=MATERIAL)
        else:
            ref = br.exact_cylinder_reference(mesh, light, R_mm=sc.size_mm, length_mm=sc.length_mm,
                                              material=MATERIAL)
        ref.seconds = time.perf_counter() - t
        self.ref_seconds[f"{sc.name}:L{level}"] = ref.seconds
        self.log(f"reference {sc.name} (L{level}, {mesh.n_vertices} vertices): {sc.reference} in {ref.seconds:.1f} s"
                 + (f", median MC rel. stderr {ref.stderr_median:.3g} over {int(ref.patch_mask.sum())} patches"
                    if ref.kind == "mc" and ref.stderr_median is not None else ""))
        self.refs[key] = ref
        return ref

    def simulate(self, mesh, light, photons, seed):
        from meshshade.montecarlo.simulate import simulate  # noqa: PLC0415

        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = simulate(mesh, MATERIAL, [light], photons=int(photons), seed=int(seed), keep_beam_exits=False,
                           beam_distances=False)
        return res, time.perf_counter() - t

    def run(self, r: Run) -> dict | None:
        from meshshade.bench import references as br  # noqa: PLC0415
        from meshshade.transport.bake import bake  # noqa: PLC0415

        sc = r.scene
        mesh = self.mesh(sc, r.level)
        ref = self.reference(sc, r.level)
        light = sc.make_light(mesh)
        st = r.settings
        if r.knob == "photons":
            seed = self.seed + 1 + int(st["photons"]) % 9973  # never the reference's stream
            mc, dt = self.simulate(mesh, light, st["photons"], seed)
            err = br.vertex_errors(mesh, mc.radiance[:, 0], ref)
        else:
            kw = {k: st[k] for k in ("rtol", "cutoff_tol", "geodesic")}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = time.perf_counter()
                res = _failsafe(lambda: bake(mesh, MATERIAL, [light], model=r.model, **kw), self.log,
                                f"{sc.name} {r.model} {r.knob}={r.value}")
                dt = time.perf_counter() - t
            if res is None:
                return None
            if "render" in st:  # the cost of the image: bake + render
                err, dt_render = self._render(sc, mesh, res, ref, light, st["render"], st["width"])
                dt += dt_render
            else:
                err = br.vertex_errors(mesh, res.radiance[:, 0], ref)
        return {"scene": sc.name, "model": r.model, "knob": r.knob, "value": r.value, **err, "time_s": dt,
                "ref_kind": sc.reference, "ref_stderr": ref.stderr_median if ref.kind == "mc" else None,
                "n_vertices": mesh.n_vertices, "light": sc.light}

    def _render(self, sc, mesh, res, ref, light, mode, width):
        from meshshade.bench import references as br  # noqa: PLC0415
        from meshshade.output.render import PixelGather, render_radiance  # noqa: PLC0415

        cam = _render_camera(sc, res)
        t = time.perf_counter()
        gather = PixelGather(mesh, res) if mode == "per-pixel" else None
        render_radiance(mesh, res.radiance, cam, width, width, spp=1, eta=MATERIAL.eta, exitance_at=gather)
        dt = time.perf_counter() - t
        points, face, bary = _pixel_hits(mesh, cam, width)
        if gather is None:
            M = np.einsum("ij,ij->i", bary, res.radiance[mesh.faces[face], 0])
        else:
            M = gather(points, face, bary)[:, 0]
        return br.pixel_errors(M, ref.point(points), ref.peak), dt


def machine_info() -> dict:
    import numba  # noqa: PLC0415
    import scipy  # noqa: PLC0415

    from meshshade import __version__  # noqa: PLC0415

    return {"platform": platform.platform(), "machine": platform.machine(), "processor": platform.processor(),
            "cpu_count": os.cpu_count(), "python": sys.version.split()[0], "meshshade": __version__,
            "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__}


def run_bench(plan, *, seed: int = 0, mc_photons: int | None = None, quick: bool = False, progress=None
              ) -> BenchResult:
    """Execute ``plan`` (from :func:`bench_plan`); ``progress(str)`` receives one line per step (or None).

    ``mc_photons``: photons of each MC reference (default: the mode's, 1M quick / 4M full).
    Returns a :class:`BenchResult`: ``rows`` (dicts with :data:`COLUMNS`) and ``metadata`` (machine, load
    average before and after, versions, seed, material, reference definitions and build times, failures).
    """
    log = progress or (lambda s: None)
    cfg = QUICK if quick else FULL
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    models = sorted({r.model for r in plan if r.model != "mc"})
    failures = []

    def log_fail(msg):
        if "failed" in msg:
            failures.append(msg)
        log(msg)

    warm = _warm_up(models, log_fail)
    log(f"warm-up {warm:.1f} s (numba compilation excluded from every timing)")
    runner = _Runner(seed, cfg.mc_photons if mc_photons is None else mc_photons, log_fail)
    rows = []
    for i, r in enumerate(plan):
        try:
            row = runner.run(r)
        except MeshshadeError as exc:  # e.g. a shared mesh that is absent: skip the run, say why
            log_fail(f"{r.scene.name}: failed: {exc}")
            row = None
        if row is None:
            continue
        rows.append(row)
        log(f"[{i + 1}/{len(plan)}] {row['scene']} {row['model']} {row['knob']}={row['value'] or '-'}: "
            f"max {row['error_max']:.3g}, mean {row['error_mean']:.3g}, energy {row['error_energy']:+.3g} "
            f"in {row['time_s']:.3g} s")
    from meshshade.bench import references as br  # noqa: PLC0415

    meta = {"command": "meshshade bench" + (" --quick" if quick else ""), "seed": seed,
            "wall_time_s": time.perf_counter() - t0, "warm_up_s": warm,
            "load_average_before": list(load0), "load_average_after": list(os.getloadavg()),
            "machine": machine_info(), "material": MATERIAL.to_dict(), "channel": 0,
            "bake_defaults": bake_defaults(), "mc_reference_photons": runner.mc_photons,
            "masks": {"exact_floor": br.EXACT_FLOOR, "mc_floor": br.MC_FLOOR,
                      "mc_max_rel_stderr": br.MC_MAX_REL_STDERR, "reference_rtol": br.REFERENCE_RTOL},
            "scenes": {r.scene.name: asdict(r.scene) for r in plan},
            "reference_seconds": runner.ref_seconds, "failures": failures, "runs_planned": len(plan),
            "rows": len(rows)}
    return BenchResult(rows, meta)
