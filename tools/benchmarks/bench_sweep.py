"""The accuracy sweep (issue 47): the default bake against an in-mesh Monte Carlo reference on 20 pairs of scene and
material, beside a 2e6-photon Monte Carlo; JSON lines on stdout.

Pairs: the materials skin1, marble, wholemilk, ketchup, apple (``Material.preset``) x the scenes spot50, blub80,
head200 (``bench_volume.py``'s: spot.obj at 50 mm, blub.obj at 80 mm, the head scan at 200 mm, the sun along
(0.3, -0.4, -0.866)) and hand190 (``bench_defects.py``'s: hand.obj at 190 mm, the sun from the wrist, WRIST_SUN).
Per pair (one ``pair`` row):

* ``bake``: the default bake as ``meshshade bake`` runs it (the CLI parser's default options,
  ``bake_options_from_args``), in this process after a warm-up (``real_models.warm_up``: numba's kernels loaded
  outside the timing), its wall seconds, model and transport; its exitance averaged over each vertex's patch
  (``BakeResult.patch_averaged``, eq. (104)) as the Monte Carlo tallies it;
* ``mc``: ``simulate`` with ``--photons`` (default 2e6) and ``--seed`` (default 202);
* ``reference``: ``simulate`` with ``--reference-photons`` (default 1e7) and ``--reference-seed`` (default 101),
  and the mean relative standard error of its lit vertices (``noise_lit``: its own noise, part of every error);
* errors as ``bench_volume.py`` computes them (``bench_volume.errors``: mean |M / ref - 1| per channel r, g, b over
  the *lit* vertices, an unshadowed entry sample of positive power, ``bench_volume.lit_vertices``, and over the
  *unlit* ones whose reference is above 1e-2 of the channel's peak), for the bake and the 2e6 run; the bake's over
  the 2e6 run's (``ratio``); the total exitant power sum_v M_v A_v (A_v: the vertex's area) over the
  reference's, minus 1 (``power``);
* ``targets`` (issue 47; measured, nothing is tuned to them): lit ratio <= 0.8 and unlit ratio <= 1.2 on every
  channel, the bake's power within 1 % of the reference's on every channel.

The ``summary`` row: means over the sweep (per channel) of each error, the lit ratio of the means (the bake's mean
lit error over the 2e6 run's, pairs and channels pooled; target <= 0.6) and the mean of the pairs' lit ratios, the
pairs that meet their targets and those that do not, the bake's seconds.

The Monte Carlo runs are kept in the asset cache (``meshshade/asset_cache.py``, kind ``bench-sweep-<scene>``)
under a key of the material (name and coefficients), photons, seed, the mesh's geometry (sha256 of its vertices
and faces), the lights and the Monte Carlo's code version (:func:`mc_code_version`: sha256 of the sources the
Monte Carlo imports, found by reading their import statements). A change to the bake does not invalidate them; a
change to the Monte Carlo does (``--allow-other-mc-version`` takes a cached run of another code version, and the
row says which).

The references take long on 2 cores (1e7 photons: minutes per pair, tens of minutes for the milks): a many-core
machine without trimesh or libigl makes them from the scenes as arrays:

    python tools/benchmarks/bench_sweep.py --export DIR                 # here: DIR/<scene>.npz (V, F, the lights)
    python tools/benchmarks/bench_sweep.py --references-only --scenes-from DIR --out DIR2 [--pairs ...]
                                                 # there: DIR2/<scene>_<material>_<photons>_<seed>.npz
    python tools/benchmarks/bench_sweep.py --import-references DIR2     # here: into the asset cache
    python tools/benchmarks/bench_sweep.py [--pairs spot50:skin1,...] [--scenes ..] [--materials ..]

``--references-only`` makes every reference first (in ``--pairs``' order), then every ``--photons`` run (not with
``--runs reference``: the sweep then makes them here and caches them), skips the files already in
DIR2, writes each file whole (a temporary name renamed) and starts no run after ``--stop-after`` seconds.
``--rates`` measures the Monte Carlo's photons per second of walk on each pair at ``--rate-photons`` on each of
``--rate-threads`` and estimates a reference's seconds on 16 threads (1 thread's rate times ``--ceiling``, the
16-core machine's measured 8.5x, plus the run's set-up).
"""
from __future__ import annotations

import argparse
import ast
import functools
import hashlib
import json
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package: the benchmarks beside this

import bench_volume  # noqa: E402

from meshshade.asset_cache import AssetCache, cache_dir  # noqa: E402
from meshshade.geometry.mesh import Mesh  # noqa: E402
from meshshade.light import DirectionalLight  # noqa: E402
from meshshade.materials import Material  # noqa: E402
from meshshade.montecarlo import MCOptions, simulate  # noqa: E402

#: the sweep's scenes and materials (issue 47)
SCENES = ("spot50", "blub80", "hand190", "head200")
MATERIALS = ("skin1", "marble", "wholemilk", "ketchup", "apple")
#: seeds of the reference and of the smaller run (different streams)
REFERENCE_SEED, MC_SEED = 101, 202
#: issue 47's targets: per pair lit and unlit error over the 2e6 run's, over the sweep the lit one, the power
TARGET_LIT, TARGET_UNLIT, TARGET_LIT_SWEEP, TARGET_POWER = 0.8, 1.2, 0.6, 0.01
#: the 16-core machine's speed-up of pure arithmetic from 1 to 16 threads (bench_mc_scaling.py's ceiling, issue 46)
CEILING_16 = 8.5
#: a run measured there (docs/benchmarks.md, issue 46: ``simulate(2e6)`` on head200 x skin1, 16 threads, 2.65 s)
CALIBRATION = ("head200", "skin1", 2_000_000, 2.65)


def _fail(message: str):
    print(f"bench_sweep.py: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _say(args, message: str) -> None:
    if not getattr(args, "quiet", False):
        print(f"[bench_sweep {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------------ scenes
@dataclass(frozen=True)
class Scene:
    """A scene as arrays: vertices (n, 3) mm, faces (m, 3), its directional lights."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    lights: tuple

    def mesh(self) -> Mesh:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return Mesh.from_arrays(np.asarray(self.vertices, dtype=np.float64),
                                    np.asarray(self.faces, dtype=np.int64), source=self.name)


def local_scene(name: str) -> Scene | None:
    """The scene of the benchmarks that define it (bench_volume.py, bench_defects.py), or None without its mesh."""
    if name not in SCENES:
        _fail(f"unknown scene {name!r}; choose among {', '.join(SCENES)}")
    if name == "hand190":
        import bench_defects

        got = bench_defects.scene_arrays(name)
        if got is None:
            return None
        V, F, sun = got
        return Scene(name, np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64),
                     (DirectionalLight(sun, 1.0),))
    got = bench_volume.scene(name)
    if got is None:
        return None
    mesh, _, light = got
    return Scene(name, np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64), (light,))


def export_scene(scene: Scene, folder: Path) -> Path:
    """Write ``folder/<scene>.npz``: V, F and the lights (directions (k, 3), irradiances (k,)), whole."""
    for light in scene.lights:
        if not isinstance(light, DirectionalLight):
            _fail(f"{scene.name}: only directional lights are exported, got {type(light).__name__}")
    folder.mkdir(parents=True, exist_ok=True)
    return _write_npz(folder / f"{scene.name}.npz", V=scene.vertices, F=scene.faces,
                      light_directions=np.array([lt.direction for lt in scene.lights], dtype=np.float64),
                      light_irradiance=np.array([lt.irradiance for lt in scene.lights], dtype=np.float64),
                      name=np.array(scene.name))


def load_scene(folder: Path, name: str) -> Scene:
    path = Path(folder) / f"{name}.npz"
    try:
        with np.load(path, allow_pickle=False) as d:
            V, F = np.asarray(d["V"], dtype=np.float64), np.asarray(d["F"], dtype=np.int64)
            dirs, irr = d["light_directions"], d["light_irradiance"]
    except (OSError, KeyError, ValueError) as exc:
        _fail(f"cannot read the scene {path}: {exc}")
    return Scene(name, V, F, tuple(DirectionalLight(tuple(map(float, x)), float(e)) for x, e in zip(dirs, irr)))


def _write_npz(path: Path, **arrays) -> Path:
    """np.savez under a temporary name in the same folder, then renamed: no partial file."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


# ------------------------------------------------------------------------------------------------ cache keys
def geometry_hash(mesh: Mesh) -> str:
    h = hashlib.sha256(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    return h.hexdigest()


def lights_key(lights) -> str:
    text = ";".join(f"{type(lt).__name__}:{','.join(f'{x:.9f}' for x in lt.direction)}:{lt.irradiance:.9g}"
                    for lt in lights)
    return hashlib.sha256(text.encode()).hexdigest()


def material_key(mat: Material) -> str:
    text = f"{mat.name}:{mat.sigma_s_prime.tolist()}:{mat.sigma_a.tolist()}:{mat.eta!r}:{mat.g!r}"
    return hashlib.sha256(text.encode()).hexdigest()


def _module_file(root: Path, name: str) -> list[Path]:
    """The file of the meshshade module or package ``name`` ([] for a name that is neither: an attribute)."""
    base = root.joinpath(*name.split(".")[1:])
    return [p for p in (base.with_suffix(".py"), base / "__init__.py") if p.is_file()][:1]


def mc_code_version(root: Path | None = None) -> str:
    """sha256 (hex) of the Monte Carlo's code: every ``.py`` file of ``meshshade/montecarlo/`` and, transitively,
    every meshshade module they name in an import statement (the ones inside functions too; a package's
    ``__init__`` only where the package itself is imported from, not for a module inside it: importing
    ``meshshade.volume.inside`` runs ``volume/__init__.py``, which imports the bake's volume transport, but the
    walk calls none of it), over their paths relative to the package and their bytes. So a change to the bake
    keeps the cached runs, one to any code the walk names drops them."""
    if root is None:
        return _mc_code_version_here()
    root = Path(root)
    todo = sorted((root / "montecarlo").glob("*.py"))
    seen: set[Path] = set()
    while todo:
        f = todo.pop()
        if f in seen or not f.is_file():
            continue
        seen.add(f)
        package = ".".join(("meshshade",) + f.relative_to(root).parent.parts).rstrip(".")
        for node in ast.walk(ast.parse(f.read_bytes())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join(up + ([base] if base else []))
                names = [base] + [f"{base}.{a.name}" for a in node.names]
            todo += [p for n in names if n == "meshshade" or n.startswith("meshshade.")
                     for p in _module_file(root, n)]
    h = hashlib.sha256()
    for f in sorted(seen):
        h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def _mc_code_version_here() -> str:
    import meshshade

    return mc_code_version(Path(meshshade.__file__).resolve().parent)


def run_key(material: str, photons: int, seed: int, geometry: str, lights: str, mat_key: str,
            version: str | None) -> str:
    """The asset-cache key of one Monte Carlo run; ``version`` None: the prefix shared by every code version."""
    prefix = f"{material}-{int(photons)}-seed{int(seed)}-g{geometry[:16]}-l{lights[:10]}-m{mat_key[:10]}-mc"
    return prefix if version is None else prefix + version[:16]


# ------------------------------------------------------------------------------------------------ Monte Carlo runs
def mc_run(mesh: Mesh, mat: Material, lights, photons: int, seed: int) -> dict:
    """One ``simulate`` as the arrays and metadata the cache and the device's files hold."""
    import numba

    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(mesh, mat, list(lights), MCOptions(photons=int(photons), seed=int(seed), beam_distances=False))
    return {"radiance": np.asarray(r.radiance, dtype=np.float64),
            "radiance_stderr": np.asarray(r.radiance_stderr, dtype=np.float32),
            "photons": np.array(int(photons)), "seed": np.array(int(seed)), "seconds": np.array(float(r.seconds)),
            "wall_seconds": np.array(time.perf_counter() - t), "cpu_seconds": np.array(float(r.cpu_seconds)),
            "threads": np.array(int(numba.get_num_threads())), "cpus": np.array(int(os.cpu_count() or 0)),
            "lost": np.asarray(r.lost, dtype=np.float64), "events": np.array(int(r.events)),
            "mc_version": np.array(mc_code_version()), "geometry": np.array(geometry_hash(mesh)),
            "lights": np.array(lights_key(lights)), "material": np.array(mat.name),
            "material_key": np.array(material_key(mat)), "numba": np.array(numba.__version__),
            "numpy": np.array(np.__version__), "python": np.array(sys.version.split()[0])}


def _meta(run: dict) -> dict:
    """The run's metadata as plain values (what a row reports)."""
    out = {}
    for k in ("photons", "seed", "seconds", "wall_seconds", "threads", "cpus", "mc_version"):
        if k in run:
            v = np.asarray(run[k]).item()
            out[k] = round(v, 2) if isinstance(v, float) else (v[:16] if k == "mc_version" else v)
    return out


def cached_run(scene: str, mesh: Mesh, mat: Material, lights, photons: int, seed: int, *, allow_other=False,
               compute=True, say=lambda m: None) -> tuple[dict | None, str]:
    """(run, where): the cached run of this key, else (``allow_other``) one of another Monte Carlo code version,
    else (``compute``) a new run written into the cache; (None, why) when none."""
    cache = AssetCache(f"bench-sweep-{scene}")
    parts = (mat.name, photons, seed, geometry_hash(mesh), lights_key(lights), material_key(mat))
    key = run_key(*parts, mc_code_version())
    got = cache.read(key)
    if got is not None and got.get("radiance", np.zeros(0)).shape == (mesh.n_vertices, 3):
        return got, "cache"
    if allow_other:
        for path in sorted(cache_dir(cache.kind).glob(run_key(*parts, None) + "*.npz"),
                           key=lambda p: p.stat().st_mtime, reverse=True):
            other = cache.read(path.stem)
            if other is not None and other["radiance"].shape == (mesh.n_vertices, 3):
                return other, "cache, another Monte Carlo code version"
    if not compute:
        return None, f"no cached run {key} (kind {cache.kind})"
    say(f"{scene} {mat.name}: simulate {photons:.3g} photons, seed {seed} (not cached)")
    run = mc_run(mesh, mat, lights, photons, seed)
    cache.write(key, **run)
    return run, "computed here"


def import_references(folder: Path, args) -> list[dict]:
    """Put the device's files ``folder/<scene>_<material>_<photons>_<seed>.npz`` into the asset cache under the
    keys their metadata give (the geometry, lights and code version they were made with); one row per file."""
    rows, here = [], mc_code_version()
    files = sorted(p for p in Path(folder).glob("*_*_*_*.npz") if not p.name.startswith("."))
    if not files:
        _fail(f"no <scene>_<material>_<photons>_<seed>.npz files in {folder}")
    for path in files:
        scene = path.stem.split("_")[0]
        try:
            with np.load(path, allow_pickle=False) as d:
                run = {k: d[k] for k in d.files}
            meta = {k: str(run[k]) for k in ("material", "geometry", "lights", "material_key", "mc_version")}
            photons, seed = int(run["photons"]), int(run["seed"])
            ok = run["radiance"].ndim == 2 and run["radiance"].shape[1] == 3 and np.all(np.isfinite(run["radiance"]))
        except (OSError, KeyError, ValueError) as exc:
            rows.append({"row": "import", "file": path.name, "skipped": f"unreadable: {exc}"})
            continue
        if not ok:
            rows.append({"row": "import", "file": path.name, "skipped": "radiance not (n, 3) finite"})
            continue
        key = run_key(meta["material"], photons, seed, meta["geometry"], meta["lights"], meta["material_key"],
                      meta["mc_version"])
        written = AssetCache(f"bench-sweep-{scene}").write(key, **run)
        rows.append({"row": "import", "file": path.name, "scene": scene, "key": key, "written": written,
                     "same_mc_version_as_here": meta["mc_version"] == here, **_meta(run)})
    return rows


# ------------------------------------------------------------------------------------------------ errors
def total_power(M: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """(3,) W: sum over vertices of exitance times the vertex's area (its patch's third of each face)."""
    return np.sum(np.asarray(M, dtype=np.float64) * np.asarray(areas, dtype=np.float64)[:, None], axis=0)


def _ratio(a, b):
    return [None if x is None or y is None or y == 0 else round(x / y, 3) for x, y in zip(a, b)]


def pair_metrics(bake_M, mc_M, ref_M, lit, areas) -> dict:
    """Errors of the bake and of the smaller run against the reference (``bench_volume.errors``), their ratios,
    the bake's and the run's total power over the reference's minus 1, and issue 47's per-pair targets."""
    eb, em = bench_volume.errors(bake_M, ref_M, lit), bench_volume.errors(mc_M, ref_M, lit)
    p_ref = total_power(ref_M, areas)
    power_bake = total_power(bake_M, areas) / p_ref - 1.0
    power_mc = total_power(mc_M, areas) / p_ref - 1.0
    ratio = {"lit": _ratio(eb["lit"], em["lit"]), "unlit": _ratio(eb["unlit"], em["unlit"])}
    lit_ok = all(r is not None and r <= TARGET_LIT for r in ratio["lit"])
    unlit_ok = all(r <= TARGET_UNLIT for r in ratio["unlit"] if r is not None)   # no unlit vertex: nothing to miss
    power_ok = bool(np.all(np.abs(power_bake) <= TARGET_POWER))
    return {"bake": {**eb, "power": [round(float(x), 4) for x in power_bake]},
            "mc": {**em, "power": [round(float(x), 4) for x in power_mc]},
            "ratio": ratio,
            "targets": {f"lit<={TARGET_LIT}": lit_ok, f"unlit<={TARGET_UNLIT}": unlit_ok,
                        f"power<={TARGET_POWER:.0%}": power_ok},
            "meets_targets": bool(lit_ok and unlit_ok and power_ok)}


def _mean(rows, side, key):
    vals = np.array([[np.nan if x is None else x for x in r[side][key]] for r in rows], dtype=np.float64)
    if vals.size == 0 or np.all(np.isnan(vals)):
        return None
    return [None if np.all(np.isnan(c)) else round(float(np.nanmean(c)), 4) for c in vals.T]


def summary(rows: list[dict]) -> dict:
    """Means over the sweep's pair rows (per channel), the lit ratio of the means (pairs and channels pooled) and
    the mean of the pairs' lit ratios, the pairs meeting their targets, the bake's seconds."""
    done = [r for r in rows if r.get("row") == "pair" and "bake" in r]
    if not done:
        return {"row": "summary", "pairs": 0}
    means = {f"{side}_{key}": _mean(done, side, key) for side in ("bake", "mc") for key in ("lit", "unlit", "power")}
    bake_lit = np.array([r["bake"]["lit"] for r in done], dtype=np.float64)
    mc_lit = np.array([r["mc"]["lit"] for r in done], dtype=np.float64)
    lit_ratio = float(np.mean(bake_lit) / np.mean(mc_lit))
    pair_ratios = np.array([[np.nan if x is None else x for x in r["ratio"]["lit"]] for r in done])
    seconds = [r["bake"]["seconds"] for r in done if "seconds" in r["bake"]]
    return {"row": "summary", "pairs": len(done), "means": means,
            "lit_ratio_of_means": round(lit_ratio, 3),
            "mean_of_pair_lit_ratios": round(float(np.nanmean(pair_ratios)), 3),
            f"lit_sweep<={TARGET_LIT_SWEEP}": bool(lit_ratio <= TARGET_LIT_SWEEP),
            "pairs_meeting_targets": [f"{r['scene']}:{r['material']}" for r in done if r["meets_targets"]],
            "pairs_missing_targets": {f"{r['scene']}:{r['material']}": [k for k, v in r["targets"].items() if not v]
                                      for r in done if not r["meets_targets"]},
            "bake_seconds": {"total": round(float(np.sum(seconds)), 2), "mean": round(float(np.mean(seconds)), 2),
                             "max": round(float(np.max(seconds)), 2)} if seconds else None,
            "reference_photons": sorted({r["reference"]["photons"] for r in done}),
            "mc_photons": sorted({r["mc"]["photons"] for r in done})}


# ------------------------------------------------------------------------------------------------ the sweep
def bake_timed(mesh: Mesh, mat: Material, lights):
    """The default bake with ``meshshade bake``'s options, timed after a warm-up in this process."""
    import real_models

    from meshshade.cli.main import build_parser
    from meshshade.cli.options import bake_options_from_args
    from meshshade.transport import bake

    options = bake_options_from_args(build_parser().parse_args(["bake", "mesh.obj", "--out", "out.ply", "-q"]),
                                     progress=False)
    real_models.warm_up(mat, list(lights))
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = bake(mesh, mat, list(lights), options)
    return res, time.perf_counter() - t


def pair_row(scene: Scene, material: str, args) -> dict:
    mesh, lights = scene.mesh(), scene.lights
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mat = Material.preset(material)
    base = {"row": "pair", "scene": scene.name, "material": material, "vertices": int(mesh.n_vertices)}
    say = lambda m: _say(args, m)  # noqa: E731
    runs = {}
    for name, photons, seed in (("reference", args.reference_photons, args.reference_seed),
                                ("mc", args.photons, args.seed)):
        run, where = cached_run(scene.name, mesh, mat, lights, photons, seed, allow_other=args.allow_other_mc_version,
                                compute=not args.cached_only, say=say)
        if run is None:
            return {**base, "skipped": where}
        runs[name] = (run, where)
    say(f"{scene.name} {material}: bake")
    res, seconds = bake_timed(mesh, mat, lights)
    lit = bench_volume.lit_vertices(mesh, mat, lights)
    ref, mc = runs["reference"][0], runs["mc"][0]
    m = pair_metrics(res.patch_averaged(), mc["radiance"], ref["radiance"], lit, mesh.vertex_areas)
    sel = lit[:, None] & (ref["radiance"] > 0)
    noise = [round(float(np.mean(ref["radiance_stderr"][sel[:, c], c] / ref["radiance"][sel[:, c], c])), 4)
             for c in range(3)]
    return {**base, "lit_vertices": int(lit.sum()),
            "bake": {"seconds": round(seconds, 2), "model": res.model, "transport": res.stats.get("transport"),
                     **m["bake"]},
            "mc": {**_meta(mc), "from": runs["mc"][1], **m["mc"]},
            "reference": {**_meta(ref), "from": runs["reference"][1], "noise_lit": noise},
            "ratio": m["ratio"], "targets": m["targets"], "meets_targets": m["meets_targets"],
            "load_average": [round(x, 2) for x in os.getloadavg()]}


def pairs_of(args) -> list[tuple[str, str]]:
    if args.pairs:
        out = []
        for item in [p for p in args.pairs.split(",") if p]:
            scene, _, mat = item.partition(":")
            if not mat:
                _fail(f"--pairs: {item!r} is not SCENE:MATERIAL")
            out.append((scene, mat))
    else:
        out = [(s, m) for s in args.scenes.split(",") if s for m in args.materials.split(",") if m]
    for scene, mat in out:
        if scene not in SCENES:
            _fail(f"unknown scene {scene!r}; choose among {', '.join(SCENES)}")
        if mat not in MATERIALS:
            _fail(f"unknown material {mat!r}; choose among {', '.join(MATERIALS)}")
    return out


def _scenes(names, args) -> dict:
    out = {}
    for name in dict.fromkeys(names):
        out[name] = load_scene(args.scenes_from, name) if args.scenes_from else local_scene(name)
    return out


def _warm_mc():
    from meshshade.geometry.procedural import icosphere

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sphere = Mesh.from_arrays(*icosphere(5.0, 1))
        for name in ("skin1", "wholemilk", "ketchup"):   # every code path compiled before a timed run
            simulate(sphere, Material.preset(name), [DirectionalLight((0, 0, -1))],
                     MCOptions(photons=4096, seed=1, beam_distances=False))


def references_only(args) -> None:
    """The device's mode: every reference, then every smaller run, each written to ``args.out`` whole."""
    import signal

    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # `timeout`: the file being written is removed
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pairs = pairs_of(args)
    scenes = _scenes([s for s, _ in pairs], args)
    t0 = time.perf_counter()
    _warm_mc()
    print(json.dumps({"row": "device", "warm_up_s": round(time.perf_counter() - t0, 1), "cpus": os.cpu_count(),
                      "mc_version": mc_code_version()[:16]}), flush=True)
    todo = [(args.reference_photons, args.reference_seed)]
    if args.runs == "both":
        todo.append((args.photons, args.seed))
    for photons, seed in todo:
        for scene_name, material in pairs:
            path = out / f"{scene_name}_{material}_{int(photons)}_{int(seed)}.npz"
            row = {"row": "device-run", "file": path.name}
            if path.exists():
                print(json.dumps({**row, "skipped": "exists"}), flush=True)
                continue
            if args.stop_after is not None and time.perf_counter() - t0 > args.stop_after:
                print(json.dumps({**row, "skipped": f"--stop-after {args.stop_after:g} s passed"}), flush=True)
                continue
            scene = scenes[scene_name]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mat = Material.preset(material)
            run = mc_run(scene.mesh(), mat, scene.lights, photons, seed)
            _write_npz(path, **run)
            print(json.dumps({**row, **_meta(run), "photons_per_s": round(int(photons) / float(run["seconds"])),
                              "elapsed_s": round(time.perf_counter() - t0, 1)}), flush=True)


def rates(args) -> None:
    """The Monte Carlo's cost on each pair at ``--rate-photons`` on each of ``--rate-threads``, and three estimates
    of a ``--reference-photons`` and a ``--photons`` run on the 16-core machine, each the pair's figure scaled:
    ``calibrated``: :data:`CALIBRATION`'s seconds (head200 x skin1 measured there) times the photons' ratio times
    head200 x skin1's photons per CPU second of walk here over the pair's (CPU seconds on 1 thread: robust to other
    processes on this machine); ``by_cpu``: photons per CPU second here times ``--ceiling`` (16 threads of this
    machine's cores), plus the set-up here; ``by_events``: like ``calibrated`` with the walk's events per photon.
    None counts the first run's compilation there (1-2 minutes on a fresh machine, once)."""
    import numba

    pairs = pairs_of(args)
    c_scene, c_mat, c_photons, c_seconds = CALIBRATION
    scenes = _scenes([c_scene] + [s for s, _ in pairs], args)
    _warm_mc()
    counts = [int(t) for t in args.rate_threads.split(",")]
    total: dict = {}
    calib = None
    for scene_name, material in [(c_scene, c_mat)] + pairs:
        scene = scenes[scene_name]
        mesh = scene.mesh()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mat = Material.preset(material)
        row = {"row": "rate", "scene": scene_name, "material": material, "photons": int(args.rate_photons)}
        for t in counts:
            numba.set_num_threads(t)
            run = mc_run(mesh, mat, scene.lights, int(args.rate_photons), 7)
            walk, wall, cpu = float(run["seconds"]), float(run["wall_seconds"]), float(run["cpu_seconds"])
            row[f"threads{t}"] = {"walk_s": round(walk, 2), "walk_cpu_s": round(cpu, 2),
                                  "setup_s": round(wall - walk, 2),
                                  "photons_per_s": round(args.rate_photons / walk),
                                  "photons_per_cpu_s": round(args.rate_photons / cpu),
                                  "events_per_photon": round(int(run["events"]) / args.rate_photons, 1)}
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        one = row["threads1"]
        if calib is None:      # the calibration pair, first and not printed: what CALIBRATION's seconds bought
            calib = one
            continue
        for name, photons in (("reference", args.reference_photons), ("mc", args.photons)):
            est = {"calibrated": c_seconds * (photons / c_photons) * calib["photons_per_cpu_s"]
                   / one["photons_per_cpu_s"],
                   "by_cpu": one["setup_s"] + photons / one["photons_per_cpu_s"] / args.ceiling,
                   "by_events": c_seconds * (photons / c_photons) * one["events_per_photon"]
                   / calib["events_per_photon"]}
            row[f"estimate_16_threads_{name}_s"] = {k: round(v, 1) for k, v in est.items()}
            for k, v in est.items():
                total[f"{name}_{k}"] = total.get(f"{name}_{k}", 0.0) + v
        row["cumulative_estimate_s"] = {k: round(v, 1) for k, v in total.items()}
        row["load_average"] = [round(x, 2) for x in os.getloadavg()]
        print(json.dumps(row), flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--materials", default=",".join(MATERIALS))
    ap.add_argument("--pairs", default=None, help="SCENE:MATERIAL,... (instead of --scenes x --materials)")
    ap.add_argument("--reference-photons", type=float, default=1e7)
    ap.add_argument("--reference-seed", type=int, default=REFERENCE_SEED)
    ap.add_argument("--photons", type=float, default=2e6, help="the smaller Monte Carlo run's photons")
    ap.add_argument("--seed", type=int, default=MC_SEED, help="the smaller Monte Carlo run's seed")
    ap.add_argument("--allow-other-mc-version", action="store_true",
                    help="use a cached Monte Carlo run made by another version of its code")
    ap.add_argument("--cached-only", action="store_true", help="skip a pair whose runs are not cached")
    ap.add_argument("--export", metavar="DIR", default=None, help="write each scene's arrays to DIR/<scene>.npz")
    ap.add_argument("--references-only", action="store_true", help="make the Monte Carlo runs into --out (device)")
    ap.add_argument("--scenes-from", metavar="DIR", default=None, help="read the scenes from DIR/<scene>.npz")
    ap.add_argument("--out", metavar="DIR2", default=None)
    ap.add_argument("--runs", choices=("both", "reference"), default="both",
                    help="--references-only: the references and the --photons runs, or the references alone")
    ap.add_argument("--stop-after", type=float, default=None, help="--references-only: start no run after S s")
    ap.add_argument("--import-references", metavar="DIR2", default=None, help="put DIR2's runs into the asset cache")
    ap.add_argument("--rates", action="store_true", help="the Monte Carlo's rate per pair and 16-thread estimates")
    ap.add_argument("--rate-photons", type=float, default=2e4)
    ap.add_argument("--rate-threads", default="1,2")
    ap.add_argument("--ceiling", type=float, default=CEILING_16, help="16 threads' speed-up over 1 (measured 8.5)")
    ap.add_argument("-q", "--quiet", action="store_true")
    args = ap.parse_args(argv)
    for name in ("reference_photons", "photons", "rate_photons"):
        if not 1 <= getattr(args, name) <= 1e10:
            _fail(f"--{name.replace('_', '-')} must lie in [1, 1e10], got {getattr(args, name):g}")
        setattr(args, name, int(getattr(args, name)))
    if args.seed == args.reference_seed:
        _fail(f"--seed {args.seed} is the reference's (--reference-seed): the smaller run must draw other numbers")
    if "1" not in args.rate_threads.split(","):
        _fail(f"--rate-threads must include 1 (the estimates scale 1 thread's rate), got {args.rate_threads!r}")
    if args.export:
        for name in dict.fromkeys(s for s, _ in pairs_of(args)):
            scene = local_scene(name)
            if scene is None:
                print(json.dumps({"row": "export", "scene": name, "skipped": "mesh not found"}), flush=True)
                continue
            path = export_scene(scene, Path(args.export))
            print(json.dumps({"row": "export", "scene": name, "file": str(path), "vertices": len(scene.vertices),
                              "bytes": path.stat().st_size, "geometry": geometry_hash(scene.mesh())[:16]}), flush=True)
        return 0
    if args.references_only:
        if not args.out:
            _fail("--references-only needs --out DIR2")
        references_only(args)
        return 0
    if args.import_references:
        for row in import_references(Path(args.import_references), args):
            print(json.dumps(row), flush=True)
        return 0
    if args.rates:
        rates(args)
        return 0
    pairs = pairs_of(args)
    rows = []
    scenes = _scenes([s for s, _ in pairs], args)
    for scene_name, material in pairs:
        scene = scenes[scene_name]
        if scene is None:
            row = {"row": "pair", "scene": scene_name, "material": material, "skipped": "mesh not found"}
        else:
            row = pair_row(scene, material, args)
        rows.append(row)
        print(json.dumps(row), flush=True)
    print(json.dumps(summary(rows)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
