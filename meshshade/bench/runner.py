"""The runner of `meshshade bench`: execute a plan, time each run, compare it with the scene's reference.

Every run of :func:`meshshade.bench.plan.bench_plan` is measured against the best available reference
(:mod:`meshshade.bench.references`: the exact sphere or cylinder where they exist, otherwise Monte Carlo with
its standard errors): max and mean relative error, relative error of the exitant energy, and wall time.

Time is the wall time of the bake (render, simulate) call alone, by ``time.perf_counter``, after a warm-up of
every model on a tiny scene so that numba compilation is excluded.

API: ``plan = bench_plan(quick=...)`` (a list of :class:`~meshshade.bench.plan.Run`),
``result = run_bench(plan, seed=...)`` (:class:`BenchResult` with ``rows`` and ``metadata``),
``write_bench(result, out_dir)`` (:mod:`meshshade.bench.report`).
"""
from __future__ import annotations

import os
import platform
import sys
import time
import warnings
from dataclasses import asdict, dataclass

import numba
import numpy as np
import scipy

from meshshade import __version__
from meshshade.bench.plan import FULL, QUICK, Run, bake_defaults
from meshshade.bench.references import (EXACT_FLOOR, MC_FLOOR, MC_MAX_REL_STDERR, REFERENCE_RTOL,
                                        exact_cylinder_reference, exact_sphere_reference, mc_reference,
                                        pixel_errors, sphere_beam_exitance, vertex_errors)
from meshshade.bench.scenes import MATERIAL
from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import BeamLight, DirectionalLight
from meshshade.montecarlo import MCOptions, simulate
from meshshade.output.render import Camera, PixelGather, render_radiance
from meshshade.raycast import make_scene
from meshshade.transport import BakeOptions, SurfaceOptions, bake

#: columns of the rows (and of accuracy_vs_time.csv)
COLUMNS = ("scene", "model", "knob", "value", "error_max", "error_mean", "error_energy", "time_s", "ref_kind",
           "ref_stderr", "resolved_frac", "n_eval", "n_vertices", "light")


@dataclass
class BenchResult:
    """What :func:`run_bench` measured: ``rows`` (dicts with :data:`COLUMNS`) and ``metadata``."""

    rows: list
    metadata: dict


def _warm_up(models, log):
    """Compile (or load from cache) every compiled loop on a tiny scene, so no timed call pays for it."""
    t = time.perf_counter()
    mesh = Mesh.from_arrays(*icosphere(5.0, 2))
    beam = BeamLight((0.06, 0.04, 15.0), (0, 0, -1))
    for m in models:
        for light in (beam, DirectionalLight((0, 0, -1))):
            for geo in ("exact", "arc"):
                options = BakeOptions(model=m, surface=SurfaceOptions(geodesic=geo))
                res = _failsafe(lambda: bake(mesh, MATERIAL, [light], options), log, f"warm-up {m}")
        if res is not None:
            cam = Camera("orthographic", (0, 0, 20), (0, 0, 0), ortho_height=4.0)
            render_radiance(mesh, res.radiance, cam, 8, 8, spp=1, eta=MATERIAL.eta, exitance_at=PixelGather(mesh, res))
    simulate(mesh, MATERIAL, [beam], MCOptions(photons=2000, seed=0, keep_beam_exits=False, beam_distances=False))
    _failsafe(lambda: sphere_beam_exitance(np.array([0.1]), R_mm=5.0, material=MATERIAL), log, "warm-up reference")
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
    e = res.samples.positions[0]
    n = res.samples.normals[0]
    up = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    h = min(12.0, 1.6 * sc.size_mm)
    return Camera("orthographic", tuple(e + 3.0 * sc.size_mm * n), tuple(e), tuple(up), ortho_height=h)


def _pixel_hits(mesh, camera, width):
    jj, ii = np.meshgrid(np.arange(width), np.arange(width), indexing="xy")
    x = (2 * (jj + 0.5) / width - 1).reshape(-1)
    y = (1 - 2 * (ii + 0.5) / width).reshape(-1)
    o, d = camera.rays(x, y, 1.0)
    hits = make_scene(mesh.vertices, mesh.faces).first_hit(o, d)
    h = hits.hit
    return hits.points[h], hits.face[h], hits.bary[h]


class _Runner:
    def __init__(self, seed, mc_photons, log, client=None):
        self.seed, self.mc_photons, self.log, self.client = seed, mc_photons, log, client
        self.meshes, self.refs, self.mc = {}, {}, {}
        self.ref_seconds = {}

    def mesh(self, sc, level):
        key = (sc.name, level)
        if key not in self.meshes:
            self.meshes[key] = sc.build(level)
        return self.meshes[key]

    def reference(self, sc, level):
        key = (sc.name, level)
        if key in self.refs:
            return self.refs[key]
        mesh = self.mesh(sc, level)
        light = sc.make_light(mesh)
        t = time.perf_counter()
        if sc.reference == "mc":
            # the reference may be split across Dask workers (the same tallies); timed runs below stay here
            mc = self.simulate(mesh, light, self.mc_photons, self.seed, client=self.client)[0]
            ref = mc_reference(mesh, light, mc, patch_mm=sc.patch_mm)
        elif sc.shape == "sphere":
            ref = exact_sphere_reference(mesh, light, R_mm=sc.size_mm, material=MATERIAL)
        else:
            ref = exact_cylinder_reference(mesh, light, R_mm=sc.size_mm, length_mm=sc.length_mm,
                                           material=MATERIAL)
        ref.seconds = time.perf_counter() - t
        self.ref_seconds[f"{sc.name}:L{level}"] = ref.seconds
        self.log(f"reference {sc.name} (L{level}, {mesh.n_vertices} vertices): {sc.reference} in {ref.seconds:.1f} s"
                 + (f", median MC rel. stderr {ref.stderr_median:.3g} over {int(ref.patch_mask.sum())} patches"
                    if ref.kind == "mc" and ref.stderr_median is not None else ""))
        self.refs[key] = ref
        return ref

    def simulate(self, mesh, light, photons, seed, client=None):
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = simulate(mesh, MATERIAL, [light], MCOptions(photons=int(photons), seed=int(seed),
                                                              keep_beam_exits=False, beam_distances=False),
                           client=client)
        return res, time.perf_counter() - t

    def run(self, r: Run) -> dict | None:
        sc = r.scene
        mesh = self.mesh(sc, r.level)
        ref = self.reference(sc, r.level)
        light = sc.make_light(mesh)
        st = r.settings
        if r.knob == "photons":
            seed = self.seed + 1 + int(st["photons"]) % 9973  # never the reference's stream
            mc, dt = self.simulate(mesh, light, st["photons"], seed)
            err = vertex_errors(mesh, mc.radiance[:, 0], ref)
        else:
            kw = {k: st[k] for k in ("rtol", "cutoff_tol", "geodesic")}
            kw["source_model"] = st.get("source_model", "point")
            options = BakeOptions(model=r.model, surface=SurfaceOptions(**kw))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = time.perf_counter()
                res = _failsafe(lambda: bake(mesh, MATERIAL, [light], options), self.log,
                                f"{sc.name} {r.model} {r.knob}={r.value}")
                dt = time.perf_counter() - t
            if res is None:
                return None
            if "render" in st:  # the cost of the image: bake + render
                err, dt_render = self._render(sc, mesh, res, ref, light, st["render"], st["width"])
                dt += dt_render
            else:
                err = vertex_errors(mesh, res.radiance[:, 0], ref)
        return {"scene": sc.name, "model": r.model, "knob": r.knob, "value": r.value, **err, "time_s": dt,
                "ref_kind": sc.reference, "ref_stderr": ref.stderr_median if ref.kind == "mc" else None,
                "n_vertices": mesh.n_vertices, "light": sc.light}

    def _render(self, sc, mesh, res, ref, light, mode, width):
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
        return pixel_errors(M, ref.point(points), ref.peak), dt


def machine_info() -> dict:
    """Platform, CPU count and the versions of Python, meshshade, numpy, scipy and numba (bench metadata)."""
    return {"platform": platform.platform(), "machine": platform.machine(), "processor": platform.processor(),
            "cpu_count": os.cpu_count(), "python": sys.version.split()[0], "meshshade": __version__,
            "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__}


def run_bench(plan, *, seed: int = 0, mc_photons: int | None = None, quick: bool = False, progress=None,
              client=None) -> BenchResult:
    """Execute ``plan`` (from :func:`~meshshade.bench.plan.bench_plan`); ``progress(str)`` receives one line
    per step (or None).

    ``client``: a :class:`distributed.Client` on which the Monte Carlo *references* are split
    (:mod:`meshshade.montecarlo.distributed`; the same tallies as in one process up to the order of the sums);
    every timed run (bakes, and Monte Carlo as a model) stays in this process so its time means the same.

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
    runner = _Runner(seed, cfg.mc_photons if mc_photons is None else mc_photons, log_fail, client=client)
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

    meta = {"command": "meshshade bench" + (" --quick" if quick else ""), "seed": seed,
            "wall_time_s": time.perf_counter() - t0, "warm_up_s": warm,
            "load_average_before": list(load0), "load_average_after": list(os.getloadavg()),
            "machine": machine_info(), "material": MATERIAL.to_dict(), "channel": 0,
            "bake_defaults": bake_defaults(), "mc_reference_photons": runner.mc_photons,
            "masks": {"exact_floor": EXACT_FLOOR, "mc_floor": MC_FLOOR,
                      "mc_max_rel_stderr": MC_MAX_REL_STDERR, "reference_rtol": REFERENCE_RTOL},
            "scenes": {r.scene.name: asdict(r.scene) for r in plan},
            "reference_seconds": runner.ref_seconds, "failures": failures, "runs_planned": len(plan),
            "mc_reference_workers": (len(client.scheduler_info().get("workers", {})) if client is not None else 0),
            "rows": len(rows)}
    return BenchResult(rows, meta)
