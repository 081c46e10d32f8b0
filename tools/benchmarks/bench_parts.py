"""Parts of different media in the bake (issue 49): two scenes, their bakes, the time against one material, and
their errors against a Monte Carlo reference where one is given. One JSON line per scene on stdout.

Scenes (the sun along (0, 0, -1), 1 W/mm^2):

* ``split``: a sphere of radius ``--radius`` (20 mm) as two closed hemispheres, each with its flat cap, split by
  the plane x = 0 (which contains the sun's direction): skin1 on the +x side, marble on the other
  (:func:`meshshade.geometry.procedural.split_sphere`, ``--rings`` rings of latitude).
* ``nested``: an icosphere of radius ``--radius`` in skin1 with a closed icosphere of radius ``--inner`` (8 mm) of
  marble inside it (:func:`meshshade.geometry.procedural.nested_spheres`).

Per scene:

* ``time``: the default bake of the parts and of the same (part-oriented) mesh in skin1 alone, each once to warm
  (compiled kernels loaded) and then ``--repeats`` times (the least kept), in the same process: ``ratio`` =
  parts / one (issue 49's target: <= 1.5), ``ratio_to_marble`` = parts / the same mesh all marble (whose edges of
  light the lattice refines as far as a marble part's), and each bake's lattice unknowns.
* ``checks`` (independent of any reference): ``same_as_one``, the largest |M - M_one| / max M_one over vertices
  and channels of the parts all skin1 against skin1 alone (the parts' code path reduced to one medium);
  ``cubes_same_as_one``, the same with the per-cube matrices forced (the varying medium's code path, equal media);
  ``power``: the exitant power per channel of all skin1, the parts and all marble (the parts' between the two, to
  1e-5 relative: the solve's tolerance; the nested ball changes nothing in blue, 12 mm under skin1).
* ``accuracy`` (with ``--reference``): mean |M / ref - 1| per channel over *lit* vertices (an unshadowed entry
  sample of positive power) and over *unlit* vertices whose reference is above 1e-2 of the channel's peak,
  exactly as tools/benchmarks/bench_volume.py computes it, for the bake's patch-averaged exitance (eq. (104)),
  and for a Monte Carlo of ``--mc-photons`` (seed 202) where :func:`meshshade.montecarlo.simulate` takes a
  material of parts. ``--reference DIR`` holds ``<scene>.npz`` with ``radiance`` (n_vertices, 3) W/mm^2: the
  per-vertex exitance of a Monte Carlo of >= 1e7 photons in the same media (its ``photons`` and ``seed`` are
  reported when the file has them). Buried vertices (the nested ball's, the caps') are left out of both sets.

    python tools/benchmarks/bench_parts.py [--scenes split,nested] [--reference DIR] [--repeats 2]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import nested_spheres, split_sphere
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.parts import PartedMaterial
from meshshade.raycast import make_scene
from meshshade.transport import bake

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/ is not a package: the benchmarks beside this
from bench_volume import errors  # noqa: E402  (the errors every accuracy benchmark reports)

SUN = (0.0, 0.0, -1.0)


def scene(name, args):
    """(mesh, PartedMaterial, light) of scene ``name``."""
    skin, marble = Material.preset("skin1"), Material.preset("marble")
    if name == "split":
        V, F, part = split_sphere(args.radius, (1.0, 0.0, 0.0), args.rings)
        names = ("skin", "marble")
    elif name == "nested":
        V, F, part = nested_spheres(args.radius, args.inner, 5, 4)
        names = ("outer", "ball")
    else:
        raise SystemExit(f"unknown scene {name!r} (split, nested)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")              # two components, the repair's turn (undone by oriented)
        mesh = Mesh.from_arrays(V, F, source=name)
    parts = PartedMaterial([skin, marble], part, names)
    return parts.oriented(mesh), parts, DirectionalLight(SUN, 1.0)


def timed(fn, repeats):
    fn()                                                   # warm: compiled kernels, caches
    best, out = np.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def run(name, args):
    mesh, parts, light = scene(name, args)
    skin, marble = parts.materials
    t_one, one = timed(lambda: bake(mesh, skin, [light]), args.repeats)
    t_parts, got = timed(lambda: bake(mesh, parts, [light]), args.repeats)
    t_marble, all_marble = timed(lambda: bake(mesh, marble, [light]), args.repeats)
    row = {"scene": name, "vertices": int(mesh.n_vertices), "faces": int(mesh.n_faces),
           "parts": dict(zip(parts.names, (m.name for m in parts.materials))),
           "buried_vertices": int(got.stats["volume_buried_vertices"]),
           "time": {"one_s": round(t_one, 3), "parts_s": round(t_parts, 3), "ratio": round(t_parts / t_one, 3),
                    "marble_s": round(t_marble, 3), "ratio_to_marble": round(t_parts / t_marble, 3),
                    "unknowns": {"one": one.stats["volume_unknowns"], "parts": got.stats["volume_unknowns"],
                                 "marble": all_marble.stats["volume_unknowns"]},
                    "one": {k: round(v, 3) for k, v in one.timings.items()},
                    "parts": {k: round(v, 3) for k, v in got.timings.items()}}}
    same = bake(mesh, PartedMaterial([skin, skin], parts.face_part, parts.names), [light])
    peak = np.abs(one.radiance).max()
    checks = {"same_as_one": float(np.abs(same.radiance - one.radiance).max() / peak)}
    from meshshade.volume.media import PartsMedium
    PartsMedium.force_cubes = True
    try:
        forced = bake(mesh, PartedMaterial([skin, Material.preset("skin1")], parts.face_part, parts.names), [light])
    finally:
        PartsMedium.force_cubes = False
    checks["cubes_same_as_one"] = float(np.abs(forced.radiance - one.radiance).max() / peak)
    power = {"skin1": one.stats["exitant_power"], "parts": got.stats["exitant_power"],
             "marble": all_marble.stats["exitant_power"]}
    checks["power"] = {k: [round(x, 3) for x in v] for k, v in power.items()}
    checks["power_between"] = bool(all(min(a, b) * (1 - 1e-5) <= p <= max(a, b) * (1 + 1e-5)
                                       for a, p, b in zip(power["skin1"], power["parts"], power["marble"])))
    row["checks"] = checks
    if args.reference:
        row["accuracy"] = accuracy(name, mesh, parts, light, got, Path(args.reference), args)
    return row


def accuracy(name, mesh, parts, light, got, folder, args):
    path = folder / f"{name}.npz"
    if not path.exists():
        return {"skipped": f"no reference {path}"}
    data = np.load(path)
    ref = np.asarray(data["radiance"], dtype=np.float64)
    if ref.shape != (mesh.n_vertices, 3):
        return {"skipped": f"{path} holds {ref.shape[0]} vertices, the scene {mesh.n_vertices}"}
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas, [light],
                       make_scene(mesh.vertices, mesh.faces), parts.eta)
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    lit[es.vertex[(es.vertex >= 0) & (es.power > 0)]] = True
    keep = ~got.volume.buried
    ref = np.where(keep[:, None], ref, 0.0)                    # buried vertices: in neither set
    out = {"reference": {k: data[k].tolist() for k in ("photons", "seed") if k in data.files},
           "bake": errors(got.patch_averaged(), ref, lit & keep)}
    try:
        from meshshade.montecarlo import MCOptions, simulate
        mc = simulate(mesh, parts, [light], MCOptions(photons=int(args.mc_photons), seed=202, beam_distances=False))
        out["mc"] = {"photons": int(args.mc_photons), "seconds": round(mc.seconds, 2),
                     **errors(mc.radiance, ref, lit & keep)}
    except Exception as e:                                      # the Monte Carlo of parts may not be there yet
        out["mc"] = {"skipped": f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="split,nested")
    ap.add_argument("--radius", type=float, default=20.0)
    ap.add_argument("--inner", type=float, default=8.0)
    ap.add_argument("--rings", type=int, default=36)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--reference", default=None, help="folder of <scene>.npz references (radiance (n, 3))")
    ap.add_argument("--mc-photons", type=float, default=2e6)
    args = ap.parse_args()
    for name in [s for s in args.scenes.split(",") if s]:
        print(json.dumps(run(name, args)), flush=True)


if __name__ == "__main__":
    main()
