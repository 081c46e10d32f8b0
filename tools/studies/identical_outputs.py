"""Outputs of the bench's quick scenes, every model, for a before/after refactoring check.

``python tools/studies/identical_outputs.py save OUT.npz`` then, after a change,
``python tools/studies/identical_outputs.py compare OUT.npz``: prints, per output, the largest difference relative
to the output's largest finite value, and exits 1 if any exceeds 1e-12. Profiles of the beam near field are
infinite at r = 0: those entries must match exactly.
"""
from __future__ import annotations

import sys
import warnings

import numpy as np

from meshshade.bench.plan import QUICK
from meshshade.bench.scenes import MATERIAL, SCENES
from meshshade.montecarlo import MCOptions, simulate
from meshshade.profiles import Shape, profile_distances, reflectance_profile
from meshshade.transport import BakeOptions, MODELS, SurfaceOptions, bake

BAKE_SCENES = ("sphere_r5_beam", "sphere_r20_directional", "cylinder_r10_beam", "torus_beam", "torus_directional")
PROFILE_MODELS = ("dipole", "exact", "curved", "fitted")
SHAPES = (Shape("plane"), Shape.make("sphere", 10.0), Shape.make("cylinder", 10.0))


def outputs() -> dict:
    out = {}
    warnings.simplefilter("ignore")
    for name in BAKE_SCENES:
        sc = SCENES[name]
        mesh = sc.build(min(QUICK.levels.get(name, sc.level), 3))
        light = sc.make_light(mesh)
        for model in MODELS:
            for near in ((None,) if model == "volume" else ("point", "beam")):
                res = bake(mesh, MATERIAL, [light], BakeOptions(model=model, surface=SurfaceOptions(source_model=near)))
                out[f"bake/{name}/{model}/{near}"] = res.radiance
                print(f"bake {name} {model} {near}", flush=True)
        res = bake(mesh, MATERIAL, [light], BakeOptions(model="curved", surface=SurfaceOptions(transport="direct")))
        out[f"bake/{name}/curved/direct"] = res.radiance
        for model in ("dipole", "curved"):   # the arc geodesics (the demo's dipole bake takes them)
            res = bake(mesh, MATERIAL, [light], BakeOptions(model=model, surface=SurfaceOptions(geodesic="arc")))
            out[f"bake/{name}/{model}/arc"] = res.radiance
    s = profile_distances(20.0, 41)
    for shape in SHAPES:
        for model in PROFILE_MODELS:
            if model == "exact" and shape.kind == "plane":
                continue
            for near in ("point", "beam"):
                for az in (0.0, 60.0):
                    key = f"profile/{shape.kind}/{model}/{near}/{az}"
                    try:
                        out[key] = reflectance_profile(MATERIAL, s, model=model, shape=shape, source_model=near,
                                                       azimuth_deg=az)
                    except Exception as e:  # noqa: BLE001 - a refused combination is an output too
                        out[key] = np.array([np.nan])
                        print(key, "refused:", e)
    sc = SCENES["sphere_r20_beam"]
    mesh = sc.build(3)
    mc = simulate(mesh, MATERIAL, [sc.make_light(mesh)], MCOptions(photons=20_000, seed=3))
    out["mc/sphere_r20_beam/radiance"] = mc.radiance
    out["mc/profile/sphere"] = reflectance_profile(MATERIAL, s, model="mc", shape=Shape.make("sphere", 20.0),
                                                   photons=20_000, seed=3)
    return out


def main(argv):
    mode, path = argv
    out = outputs()
    if mode == "save":
        np.savez(path, **out)
        print(f"saved {len(out)} outputs to {path}")
        return 0
    ref = np.load(path)
    worst = 0.0
    for k in sorted(set(ref.files) | set(out)):
        if k not in ref.files or k not in out:
            print(f"{k}: missing on one side")
            worst = np.inf
            continue
        a, b = np.asarray(ref[k]), np.asarray(out[k])
        if a.shape != b.shape:
            print(f"{k}: shape {a.shape} vs {b.shape}")
            worst = np.inf
            continue
        fin = np.isfinite(a)
        if not np.array_equal(fin, np.isfinite(b)) or not np.array_equal(a[~fin], b[~fin], equal_nan=True):
            d = np.inf   # NaN or infinite (a beam's r = 0) in different places
        elif fin.any():
            peak = np.max(np.abs(a[fin]))
            d = np.max(np.abs(a[fin] - b[fin])) / (peak or 1.0)
        else:
            d = 0.0
        worst = max(worst, d)
        print(f"{k}: {'identical' if np.array_equal(a, b, equal_nan=True) else f'max diff / peak {d:.3g}'}")
    print(f"worst {worst:.3g} over {len(out)} outputs")
    return 0 if worst <= 1e-12 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
