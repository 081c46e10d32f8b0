"""The default bake on real models as users download them (issue 41): what each mesh is, what the bake made of it,
how long it took and how much memory.

One JSON row per model of tools/benchmarks/real_models.toml (files in shared/models/ or ../shared/models/; a row
``"skipped"`` with the reason for each file not at hand): the mesh's counts (tools/benchmarks/real_models.py:
topology_counts: vertices, faces, parts, boundary, non-manifold edges and vertices, duplicated and degenerate faces,
unreferenced vertices, size and mean edge in mm), then the default ``meshshade.transport.bake(mesh,
Material.preset("skin1"), [DirectionalLight(SUN)])`` in a fresh subprocess per model, the asset cache off:

* numba's kernels are compiled or loaded first by baking two small spheres, closed and open (the volume model
  and its surface fallback), outside the timing; the process's peak memory is then reset
  (``/proc/self/clear_refs``) so that ``peak_rss_mb`` (``resource.getrusage``, MB = 1e6 bytes) is the bake's,
  with the mesh already loaded (``warm_up_peak_rss_mb``: the peak before the reset);
* ``seconds`` (wall) and ``cpu_seconds`` (user + system: less disturbed by a busy machine), ``result.model``,
  ``stats["transport"]`` (which says why the volume model was not used), whether the exitance is finite and >= 0,
  the exitant power per channel against the entering power, the load average;
* ``targets``: the volume model, <= 30 s, <= 3 GB, finite and >= 0, exitant <= entering; ``meets_targets``.

A bake that raises (meshshade refuses non-finite or negative exitance) is a row with its error; one that runs past
``--timeout`` or dies is a row ``failed``.

    python tools/benchmarks/bench_real_models.py [--models ogre,teapot] [--timeout 900] [--light 0.3,-0.4,-0.866]

About 15-25 minutes for the twelve models on the code of 2ded9bb (2 cores), most of it the surface transport's.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package: real_models.py beside this

import real_models  # noqa: E402

SUN = (0.3, -0.4, -0.866)
TARGET_SECONDS = 30.0
TARGET_MB = 3000.0


def one(name: str, light) -> dict:
    """Child process: bake one model; returns its row (printed as the last line of stdout)."""
    from meshshade.light import DirectionalLight
    from meshshade.materials import Material
    from meshshade.transport import bake

    os.environ["MESHSHADE_ASSET_CACHE"] = "off"
    entry = real_models.entries([name])[0]
    mesh = real_models.load_model(entry)
    material, sun = Material.preset("skin1"), DirectionalLight(light, 1.0)
    real_models.warm_up(material, [sun])   # numba's kernels compiled or loaded, outside the timing
    warm_peak = real_models.peak_rss_mb()
    reset = real_models.reset_peak_rss()
    t, cpu = time.perf_counter(), real_models.cpu_seconds()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = bake(mesh, material, [sun])
        except Exception as exc:  # noqa: BLE001 - the row says what failed
            return {"seconds": round(time.perf_counter() - t, 2), "peak_rss_mb": round(real_models.peak_rss_mb()),
                    "error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"}
    sec = time.perf_counter() - t
    M = np.asarray(res.radiance)
    ex = [float(x) for x in res.stats["exitant_power"]]
    ent = float(res.stats["entering_power"])
    return {"seconds": round(sec, 2), "cpu_seconds": round(real_models.cpu_seconds() - cpu, 2),
            "peak_rss_mb": round(real_models.peak_rss_mb()), "peak_reset": reset,
            "warm_up_peak_rss_mb": round(warm_peak),
            "model": res.model, "transport": res.stats.get("transport"),
            "finite": bool(np.isfinite(M).all()), "nonnegative": bool((M >= 0).all()),
            "min_exitance": float(np.nanmin(M)), "exitant_power": [round(x, 6) for x in ex],
            "entering_power": round(ent, 6), "exitant_over_entering": [round(x / ent, 4) if ent > 0 else None
                                                                       for x in ex],
            "load_average": [round(x, 2) for x in os.getloadavg()],
            "warnings": sorted({str(w.message).splitlines()[0][:160] for w in caught})[:8],
            "timings": {k: round(v, 2) for k, v in res.timings.items()}}


def row(entry: dict, args) -> dict:
    base = {"row": "real_model", "name": entry["name"], "file": entry["file"], "kind": entry["kind"]}
    if real_models.model_path(entry) is None:
        return {**base, "skipped": real_models.missing_reason()}
    V, F = real_models.load_arrays(entry)
    counts = real_models.topology_counts(V, F)
    counts["size_mm"] = round(counts.pop("size"), 1)
    counts["mean_edge_mm"] = round(counts.pop("mean_edge"), 2)
    cmd = [sys.executable, __file__, "--one", entry["name"], "--light", args.light]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return {**base, **counts, "failed": f"no result within {args.timeout} s (killed)"}
    if out.returncode:
        lines = [x for x in out.stderr.strip().splitlines() if "Error" in x or "error" in x]
        return {**base, **counts, "failed": f"exit {out.returncode}: "
                + (lines[-1] if lines else "no error message (killed for memory?)")}
    bake_row = json.loads(out.stdout.strip().splitlines()[-1])
    if "error" in bake_row:
        return {**base, **counts, **bake_row, "meets_targets": False}
    targets = {"volume_model": bake_row["model"] == "volume" and bake_row["transport"] == "volume",
               "seconds": bake_row["seconds"] <= TARGET_SECONDS, "memory": bake_row["peak_rss_mb"] <= TARGET_MB,
               "finite_nonnegative": bake_row["finite"] and bake_row["nonnegative"],
               "exitant_le_entering": max(bake_row["exitant_power"]) <= bake_row["entering_power"] * (1 + 1e-9)}
    return {**base, **counts, **bake_row, "targets": targets, "meets_targets": all(targets.values())}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="", help="comma list of names (default: every model of the list)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds before a model's bake is killed")
    ap.add_argument("--light", default=",".join(str(x) for x in SUN), help="the sun's direction of travel")
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    light = tuple(float(x) for x in args.light.split(","))
    if args.one is not None:
        print(json.dumps(one(args.one, light)), flush=True)
        return
    names = [n for n in args.models.split(",") if n] or None
    if real_models.models_dir() is None:
        print(json.dumps({"row": "real_model", "skipped": real_models.missing_reason()}), flush=True)
        return
    for entry in real_models.entries(names):
        print(json.dumps(row(entry, args)), flush=True)


if __name__ == "__main__":
    main()
