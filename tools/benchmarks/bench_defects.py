"""Defect invariance of the default bake on real scans (issue 41): harmless defects must not change the answer
away from them.

For each scene (a clean, closed scan from ../shared/meshes at a real size, skin1, a sun) the default bake
``meshshade.transport.bake(mesh, Material.preset("skin1"), [DirectionalLight(...)])`` of the clean mesh and of
the same mesh made imperfect by tools/benchmarks/mesh_defects.py (every bake in a fresh subprocess, numba's
kernels loaded first on two small spheres, closed and open, outside the timing; the asset cache off):

* ``holes6``: six holes, the 2-ring faces around six vertices removed (seeded, centres >= 10 % of the mesh's
  size apart);
* ``dup5``: five faces duplicated;
* ``ball6``: a ball 6 mm across (radius 3 mm, an icosphere of 162 vertices) centred on the vertex farthest
  along the light's direction (the hand: a fingertip, lit from the wrist's side, so the ball shadows nothing);
* ``fin``: one triangle standing on an edge (a non-manifold edge);
* ``stray10``: ten unreferenced vertices within 1 mm of the surface;
* ``flip10``: ten faces with reversed winding (repaired by the mesh validation: should change nothing).

Peak memory is the bake's own: the process's peak is reset (``/proc/self/clear_refs``) after the mesh is built and
the kernels are warm.

One JSON row per scene and defect: the defective mesh's size, ``result.model`` and ``stats["transport"]``,
seconds (wall, and CPU: user + system) and peak resident memory of the bake's process (MB = 1e6 bytes), and for
every distance D (0, 10, 15, 25 mm): over the original vertices farther than D from every defect location (D = 0:
all of them) that still have a face, and whose clean exitance is above 1e-3 of the channel's peak, the mean, p99
and max of |M_defect / M_clean - 1| per channel (r, g, b). ``meets_targets`` (issue 41, D = 10, 15, 25): mean
<= 2 %, p99 <= 6 % in every channel, and the volume model. The first row of each scene is the clean bake.

Scenes: ``hand190`` (hand.obj, 190 mm long, the sun travelling from the wrist towards the fingers),
``head200`` (lee_perry_smith_head.obj at 200 mm, the sun of bench_volume.py); also ``bunny155`` and
``armadillo200`` (the issue's 30k and 14.6k scans). Without ../shared/meshes each scene is a row "skipped".

    python tools/benchmarks/bench_defects.py [--scenes hand190,head200] [--defects holes6,dup5,ball6]

About 2-4 minutes per scene on the volume model; a defect that sends the bake to the surface transport costs
10-20x that (today: most of them), so a full run takes 20-40 minutes on 2 cores.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package: mesh_defects.py beside this

import mesh_defects as md  # noqa: E402
import real_models  # noqa: E402

SHARED = Path(os.environ.get("MESHSHADE_SHARED", Path(__file__).resolve().parents[3] / "shared")) / "meshes"
SUN = (0.3, -0.4, -0.866)
WRIST_SUN = (0.2, 0.9, -0.4)
#: scene -> (file in ../shared/meshes, longest side in mm, the sun's direction of travel)
SCENES = {"hand190": ("hand.obj", 190.0, WRIST_SUN), "head200": ("lee_perry_smith_head.obj", 200.0, SUN),
          "bunny155": ("bunny.ply", 155.0, SUN), "armadillo200": ("armadillo.obj", 200.0, SUN)}
DEFECTS = ("holes6", "dup5", "ball6", "fin", "stray10", "flip10")
DISTANCES = (0.0, 10.0, 15.0, 25.0)
SEED = 41
TARGET_MEAN, TARGET_P99 = 0.02, 0.06


def scene_arrays(name: str):
    """(vertices in mm centred on the bounding box, faces, sun direction) of a scene, or None without its file."""
    from meshshade.io import read_mesh_arrays

    if name not in SCENES:
        raise SystemExit(f"unknown scene {name!r}; choose among {', '.join(SCENES)}")
    file, size, sun = SCENES[name]
    if not (SHARED / file).exists():
        return None
    V, F = read_mesh_arrays(SHARED / file)
    V = V - 0.5 * (V.min(axis=0) + V.max(axis=0))
    return V * (size / float(np.ptp(V, axis=0).max())), F, sun


def defective(defect: str, V, F, sun) -> md.Defected:
    """The scene's mesh with one defect (deterministic); ``"clean"``: unchanged."""
    if defect == "clean":
        return md.Defected(V, F, np.zeros((0, 3)), {"kind": "clean"})
    if defect == "holes6":
        return md.punch_holes(V, F, 6, seed=SEED)
    if defect == "dup5":
        return md.duplicate_faces(V, F, 5, seed=SEED)
    if defect == "ball6":
        d = np.asarray(sun, dtype=np.float64) / np.linalg.norm(sun)
        return md.add_ball(V, F, V[int(np.argmax(V @ d))], 3.0)
    if defect == "fin":
        return md.add_fin(V, F, seed=SEED)
    if defect == "stray10":
        return md.add_stray_vertices(V, F, 10, seed=SEED, spread=1.0)
    if defect == "flip10":
        return md.flip_faces(V, F, 10, seed=SEED)
    raise SystemExit(f"unknown defect {defect!r}; choose among {', '.join(DEFECTS)}")


def one(scene: str, defect: str, out: str) -> dict:
    """Child process: bake one mesh, write its radiance to ``out`` (.npy); returns the bake's row."""
    from meshshade.geometry.mesh import Mesh
    from meshshade.light import DirectionalLight
    from meshshade.materials import Material
    from meshshade.transport import bake

    os.environ["MESHSHADE_ASSET_CACHE"] = "off"
    V, F, sun = scene_arrays(scene)
    d = defective(defect, V, F, sun)
    material, light = Material.preset("skin1"), DirectionalLight(sun, 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = Mesh.from_arrays(d.vertices, d.faces, source=f"{scene}+{defect}")
    real_models.warm_up(material, [light])   # numba's kernels compiled or loaded, outside the timing
    reset = real_models.reset_peak_rss()     # the peak below is the bake's, not the warm-up's
    t, cpu = time.perf_counter(), real_models.cpu_seconds()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = bake(mesh, material, [light])
        except Exception as exc:  # noqa: BLE001 - the row says what failed
            return {"seconds": round(time.perf_counter() - t, 2),
                    "error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"}
    sec = time.perf_counter() - t
    np.save(out, np.asarray(res.radiance))
    return {"seconds": round(sec, 2), "cpu_seconds": round(real_models.cpu_seconds() - cpu, 2),
            "peak_rss_mb": round(real_models.peak_rss_mb()), "peak_reset": reset,
            "model": res.model, "transport": res.stats.get("transport"),
            "load_average": [round(x, 2) for x in os.getloadavg()],
            "warnings": sorted({str(w.message).splitlines()[0][:160] for w in caught})[:6]}


def _bake(scene, defect, folder, timeout):
    out = str(Path(folder) / f"{defect}.npy")
    cmd = [sys.executable, __file__, "--one", f"{scene}:{defect}:{out}"]
    try:
        got = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"failed": f"no result within {timeout} s (killed)"}, None
    if got.returncode:
        lines = [x for x in got.stderr.strip().splitlines() if "Error" in x or "error" in x]
        why = lines[-1] if lines else "no message (killed for memory?)"
        return {"failed": f"exit {got.returncode}: {why}"}, None
    info = json.loads(got.stdout.strip().splitlines()[-1])
    return info, (np.load(out) if "error" not in info else None)


def _rounded(stats):
    return {k: ([None if x is None else round(x, 4) for x in v] if k in ("mean", "p99", "max") else v)
            for k, v in stats.items()}


def rows(scene: str, defects, args):
    got = scene_arrays(scene)
    if got is None:
        yield {"row": "defect", "scene": scene, "skipped": f"{SHARED / SCENES[scene][0]} not found"}
        return
    V, F, sun = got
    n = V.shape[0]
    with tempfile.TemporaryDirectory() as tmp:
        clean_info, clean = _bake(scene, "clean", tmp, args.timeout)
        yield {"row": "defect", "scene": scene, "defect": "clean", "vertices": n, "faces": int(F.shape[0]),
               "sun": list(sun), **clean_info}
        if clean is None:
            return
        for defect in defects:
            d = defective(defect, V, F, sun)
            info, M = _bake(scene, defect, tmp, args.timeout)
            base = {"row": "defect", "scene": scene, "defect": defect, "vertices": int(d.vertices.shape[0]),
                    "faces": int(d.faces.shape[0]), "defect_points": int(d.points.shape[0]), **info}
            if M is None:
                yield base
                continue
            referenced = np.zeros(d.vertices.shape[0], dtype=bool)
            referenced[d.faces.reshape(-1)] = True
            by_distance, ok = {}, info.get("model") == "volume" and info.get("transport") == "volume"
            for D in DISTANCES:
                keep = md.far_from(V, d.points, D) & referenced[:n]
                stats = md.relative_change(M[:n], clean, keep)
                by_distance[f"{D:g}mm"] = _rounded(stats)
                if D > 0:
                    ok = ok and all(m is not None and m <= TARGET_MEAN for m in stats["mean"]) and all(
                        p is not None and p <= TARGET_P99 for p in stats["p99"])
            yield {**base, "seconds_over_clean": round(info["seconds"] / clean_info["seconds"], 2),
                   "relative_change": by_distance, "meets_targets": bool(ok)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default="hand190,head200")
    ap.add_argument("--defects", default=",".join(DEFECTS))
    ap.add_argument("--timeout", type=float, default=1200.0, help="seconds before one bake is killed")
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one is not None:
        scene, defect, out = args.one.split(":", 2)
        print(json.dumps(one(scene, defect, out)), flush=True)
        return
    defects = [x for x in args.defects.split(",") if x]
    for name in defects:
        if name not in DEFECTS:
            raise SystemExit(f"unknown defect {name!r}; choose among {', '.join(DEFECTS)}")
    for scene in [s for s in args.scenes.split(",") if s]:
        for r in rows(scene, defects, args):
            print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
