"""Near the light, on meshes: the bake's mean error against a long Monte Carlo run, point source vs near field.

For each scene (a bench scene, or the 20 mm sphere under a sun) and each channel of the material (default skin1):
a long Monte Carlo run is the reference (bench patch metrics: meshshade.bench.references.mc_reference and
vertex_errors); against it, bakes of ``--models`` with ``source_model="point"`` and ``"beam"``, and a short Monte
Carlo run with another seed (``--short-photons``, the issue's yardstick). Prints one JSON line per (scene, channel,
run) with the mean and max patch error and the wall time.

    python tools/studies/near_field_bakes.py [--scenes sphere_r20_sun,spot_50mm_directional] [--photons 20000000]
        [--short-photons 2000000] [--material skin1] [--models curved,auto] [--near-fields point,beam]

``--material bench`` is the bench's skin-like medium (meshshade.bench.scenes.MATERIAL); ``--short-photons 0``
skips the short run. The fitted curvature model's real-mesh figures (docs/validation.md) come from
``--scenes head_200mm_beam,head_200mm_directional,spot_50mm_beam,spot_50mm_directional,torus_beam,torus_directional
--material bench --photons 4000000 --short-photons 0 --models dipole,curved,fitted,auto``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

from meshshade.bench.references import mc_reference, vertex_errors
from meshshade.bench.scenes import MATERIAL, SCENES, Scene
from meshshade.materials import Material
from meshshade.montecarlo.simulation import simulate
from meshshade.transport import BakeOptions, SurfaceOptions, bake
from meshshade.montecarlo import MCOptions

EXTRA = {"sphere_r20_sun": Scene("sphere_r20_sun", "sphere", 20.0, "directional", "mc", level=4, geodesic="arc",
                                 patch_mm=3.0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="sphere_r20_sun,spot_50mm_directional")
    ap.add_argument("--photons", type=int, default=20_000_000)
    ap.add_argument("--short-photons", type=int, default=2_000_000)
    ap.add_argument("--material", default="skin1")
    ap.add_argument("--models", default="curved,auto")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--near-fields", default="point,beam")
    args = ap.parse_args(argv)
    mat = MATERIAL if args.material == "bench" else Material.preset(args.material)
    channels = (0,) if mat.is_grey else (0, 1, 2)
    scenes = {**SCENES, **EXTRA}
    for name in args.scenes.split(","):
        sc = scenes[name]
        mesh = sc.build()
        light = sc.make_light(mesh)
        runs = {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = time.perf_counter()
            long = simulate(mesh, mat, [light], MCOptions(
                photons=args.photons, seed=args.seed, keep_beam_exits=False, beam_distances=False))
            t_long = time.perf_counter() - t
            if args.short_photons:
                t = time.perf_counter()
                short = simulate(mesh, mat, [light], MCOptions(
                    photons=args.short_photons, seed=args.seed + 1000, keep_beam_exits=False, beam_distances=False))
                runs[f"mc {args.short_photons:.0e}"] = (short.radiance, time.perf_counter() - t)
            for model in args.models.split(","):
                for nf in args.near_fields.split(","):
                    t = time.perf_counter()
                    res = bake(mesh, mat, [light], BakeOptions(
                        model=model, surface=SurfaceOptions(geodesic=sc.geodesic, source_model=nf)))
                    runs[f"{model} {nf}"] = (res.radiance, time.perf_counter() - t)
        for ch in channels:
            ref = mc_reference(mesh, light, long, patch_mm=sc.patch_mm, channel=ch)
            for run, (M, secs) in runs.items():
                err = vertex_errors(mesh, M[:, ch], ref)
                print(json.dumps({"scene": name, "vertices": mesh.n_vertices, "channel": "rgb"[ch], "run": run,
                                  "error_mean": round(err["error_mean"], 4), "error_max": round(err["error_max"], 4),
                                  "error_energy": round(err["error_energy"], 4), "seconds": round(secs, 2),
                                  "reference_photons": args.photons, "reference_seconds": round(t_long, 1),
                                  "reference_median_rel_stderr": round(ref.stderr_median or 0.0, 4)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
