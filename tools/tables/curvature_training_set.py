"""Generate the training set of the fitted curvature model (meshshade.kernels.fitted_curvature, docs/physics.md
§14): Monte Carlo reflectance profiles on exact curved shapes, each with the half-space profile of the same
medium and the same rings, so that their ratio is the curvature factor the model fits.

Shapes (meshshade.montecarlo.shapes, exact boundaries and exact geodesic exit distances, pencil beam at normal
incidence): sphere (k1 = k2 = 1/R), spherical cavity (the medium outside a ball, k1 = k2 = -1/R), cylinder
(around the axis k = 1/R) and cylindrical bore (the medium outside a cylinder, around the axis k = -1/R), the last
two tallied in azimuth sectors of half-width 10 deg about 0, 45 and 90 deg from the direction around the axis.
Radii R = c / sigma_tr for c in RADII_TR (curvature radii from twice the diffusion length down to half of it).
Media: sigma_s' = 1 /mm (so millimetres are transport lengths) and the (alpha', eta, g) of MEDIA. Rings at
distances x / sigma_tr, x in X_GRID, half-width max(0.1 s, 0.05 mm), those that do not exist on the shape dropped.

One Dask task per (medium, shape, radius): the project's distributed engine; ``--scheduler ADDRESS`` runs them
on a cluster, by default on a local one with one worker per core. Deterministic for a given ``--seed`` (every
run's photon streams are keyed by it). Writes a CSV with a provenance header.

    python tools/tables/curvature_training_set.py [--photons 1000000] [--seed 2026]
        [--out tools/tables/data/curvature_training.csv]

About 20 min on 2 cores with the defaults.
"""
from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
#: (alpha', eta, g) of the media; sigma_s' = 1 /mm
MEDIA = ((0.8, 1.3, 0.0), (0.9, 1.3, 0.0), (0.97, 1.3, 0.0), (0.99, 1.3, 0.0), (0.998, 1.3, 0.0),
         (0.9, 1.0, 0.0), (0.99, 1.0, 0.0), (0.9, 1.5, 0.0), (0.99, 1.5, 0.0), (0.9, 1.3, 0.8), (0.99, 1.3, 0.8),
         (0.95, 1.4, 0.0),
         # a fuller (alpha', eta) grid, so that the fit interpolates in the medium rather than extrapolating
         (0.8, 1.0, 0.0), (0.97, 1.0, 0.0), (0.998, 1.0, 0.0), (0.9, 1.15, 0.0), (0.97, 1.15, 0.0), (0.99, 1.15, 0.0),
         (0.9, 1.4, 0.0), (0.99, 1.4, 0.0), (0.8, 1.5, 0.0), (0.97, 1.5, 0.0), (0.998, 1.5, 0.0), (0.95, 1.2, 0.8))
#: curvature radii in units of the diffusion length 1/sigma_tr
RADII_TR = (0.5, 1.0, 2.0, 4.0)
#: (shape, azimuth deg) tallies; one Monte Carlo run per shape serves all its azimuths
TALLIES = (("sphere", 0.0), ("cavity", 0.0), ("cylinder", 0.0), ("cylinder", 45.0), ("cylinder", 90.0),
           ("bore", 0.0), ("bore", 45.0), ("bore", 90.0))
#: ring distances times sigma_tr
X_GRID = np.geomspace(0.03, 6.0, 18)
SECTOR_DEG = 10.0
COLUMNS = ("albedo_prime", "eta", "g", "sigma_tr", "shape", "radius_mm", "k1", "k2", "azimuth_deg", "s_mm", "lo_mm",
           "hi_mm", "R_shape", "R_shape_err", "R_plane", "R_plane_err")


def _material(albedo, eta, g):
    from meshshade.materials import Material
    sa = (1.0 - albedo) / albedo
    return Material(sigma_s_prime=np.full(3, 1.0), sigma_a=np.full(3, sa), eta=eta, g=g)


def _distances(medium, shape, radius):
    m = _material(*medium)
    s = X_GRID / float(m.sigma_tr[0])
    s = s[s >= 0.1]
    if shape in ("sphere", "cavity"):
        s = s[s * 1.1 + 0.05 < np.pi * radius]
    return s


def photons_for(albedo, photons):
    """Photons of one run: the budget, halved for alpha' > 0.95 and quartered for alpha' > 0.99 (long walks; their
    profiles are broad, so the rings hold more photons each)."""
    return photons if albedo <= 0.95 else photons // 2 if albedo <= 0.99 else photons // 4


def run_one(medium, shape, radius, photons, seed, cache_dir):
    """(rows, from_cache) of one (medium, shape, radius): every azimuth of the shape (one run tallies them all), with
    the plane on the same rings. Cached as JSON in ``cache_dir`` (a re-run resumes; ``from_cache`` says so)."""
    import json
    from meshshade.montecarlo.shapes import shape_mc_profile, shape_mc_profiles
    name = Path(cache_dir) / (f"{medium[0]:g}_{medium[1]:g}_{medium[2]:g}_{shape}_{radius:.9g}_{photons}_{seed}"
                              ".json")
    if name.exists():
        return json.loads(name.read_text()), True
    m = _material(*medium)
    s = _distances(medium, shape, radius)
    kw = dict(photons=photons_for(medium[0], photons), seed=seed, sector_deg=SECTOR_DEG)
    plane = shape_mc_profile(m, s, shape="plane", **kw)
    k = 1.0 / radius
    k1, k2 = {"sphere": (k, k), "cavity": (-k, -k), "cylinder": (k, 0.0), "bore": (0.0, -k)}[shape]
    rows = []
    azimuths = [az for tshape, az in TALLIES if tshape == shape]
    for az, p in zip(azimuths, shape_mc_profiles(m, s, shape=shape, radius_mm=radius, azimuths_deg=azimuths, **kw)):
        # the azimuth from the first principal direction (k1 >= k2): around the cylinder's axis for the cylinder,
        # along the bore's axis for the bore (there k1 = 0 is the direction along the axis)
        phi = 90.0 - az if shape == "bore" else az
        for j in range(s.size):
            if not np.isfinite(p.reflectance[0, j]):
                continue
            rows.append((*medium, float(m.sigma_tr[0]), shape, radius, k1, k2, phi, s[j], p.lo[j], p.hi[j],
                         p.reflectance[0, j], p.stderr[0, j], plane.reflectance[0, j], plane.stderr[0, j]))
    tmp = name.with_suffix(".tmp")
    tmp.write_text(json.dumps(rows))
    tmp.replace(name)
    return rows, False


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address (default: a local cluster)")
    ap.add_argument("--out", default=str(ROOT / "tools" / "tables" / "data" / "curvature_training.csv"))
    ap.add_argument("--cache", default=None, help="directory of per-run results, so that a re-run resumes "
                    "(default: a temporary directory)")
    args = ap.parse_args(argv)
    from dask.distributed import Client, LocalCluster, as_completed
    jobs = [(med, shape, c / float(_material(*med).sigma_tr[0]))
            for med in MEDIA for c in RADII_TR for shape in ("sphere", "cavity", "cylinder", "bore")]
    jobs.sort(key=lambda j: (-j[0][0], j[1] not in ("cavity", "bore")))   # the long runs first
    t0 = time.time()
    import tempfile
    cache = args.cache or tempfile.mkdtemp(prefix="meshshade-training-")
    Path(cache).mkdir(parents=True, exist_ok=True)
    cluster = None if args.scheduler else LocalCluster(threads_per_worker=1, processes=True)
    with Client(args.scheduler or cluster) as client:
        futs = [client.submit(run_one, *job, args.photons, args.seed, cache, pure=False) for job in jobs]
        rows, done, cached = [], 0, 0
        for f in as_completed(futs):
            got, hit = f.result()
            rows.extend(got)
            cached += hit
            done += 1
            print(f"{done}/{len(jobs)} runs, {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
    if cluster is not None:
        cluster.close()
    rows.sort(key=lambda r: (r[0], r[1], r[2], r[4], r[5], r[8], r[9]))
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip()
    out = Path(args.out)
    tmp = out.with_suffix(".tmp")
    with open(tmp, "w") as fh:
        fh.write(f"# meshshade curvature training set: exact-shape Monte Carlo (meshshade.montecarlo.shapes)\n"
                 f"# command: python tools/tables/curvature_training_set.py --photons {args.photons} "
                 f"--seed {args.seed}\n"
                 f"# photons per run: the budget for alpha' <= 0.95, half to 0.99, a quarter beyond\n"
                 f"# commit {rev}, {datetime.date.today().isoformat()}, {time.time() - t0:.0f} s for "
                 f"{len(jobs) - cached} runs ({cached} more read from --cache); sigma_s' = 1 /mm;\n"
                 f"# R_* per unit entering power [mm^-2], ring-averaged over [lo, hi], batch-mean standard errors\n")
        fh.write(",".join(COLUMNS) + "\n")
        for r in rows:
            fh.write(",".join(f"{v:.9g}" if isinstance(v, float) else str(v) for v in r) + "\n")
    tmp.replace(out)
    print(f"{len(rows)} rows -> {out}")


if __name__ == "__main__":
    main()
