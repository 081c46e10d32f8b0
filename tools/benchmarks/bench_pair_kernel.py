"""Cost per pair of PairKernel.evaluate (the near zone's and the direct sum's kernel evaluation) by model.

``python tools/benchmarks/bench_pair_kernel.py [--pairs 2000000] [--repeat 3]`` prints JSON: ns per pair of each
model (best of ``--repeat``) and, as the baseline measured in the same run, a bare compiled loop of the planar dipole
(kernels.dipole.dipole_diffuse_reflectance) over the same distances; ``ratio`` = model / baseline holds on a noisy
machine. 1000 sources with random principal curvatures (|k| <= 0.1 /mm), pairs at random distances up to 20 mm.
Exact-sphere sources here have 1000 different radii, about 1000 pairs each: below SPHERE_THETA_POINTS pairs a radius
bin takes the series at each pair (a beam's case), so that row measures the series, not the tables.
"""
from __future__ import annotations

import argparse
import json

import numba
import numpy as np

from meshshade.kernels.dipole import dipole_diffuse_reflectance
from meshshade.kernels.optics import diffusion_params
from meshshade.materials import Material
from meshshade.surface.auto import AutoPlan
from meshshade.surface.pair_kernel import PairKernel, SourceFrames

from bench_kernels import best_time  # noqa: E402  (tools/ is not a package: this script's folder is on sys.path)


@numba.njit(cache=True)
def _bare_dipole(s, st, al, mu, zr, zv, out):
    for j in range(s.size):
        out[j] = dipole_diffuse_reflectance(s[j] * st, al, mu, zr, zv) * st * st


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    mat = Material(1.0, 0.01, 1.3)
    n, p = 1000, a.pairs
    rng = np.random.default_rng(0)
    frames = SourceFrames(rng.uniform(0.0, 0.1, n), rng.uniform(-0.05, 0.1, n), np.tile([1.0, 0, 0], (n, 1)),
                          np.tile([0, 1.0, 0], (n, 1)), np.tile([0, 0, 1.0], (n, 1)))
    src, s, phi = rng.integers(0, n, p), rng.uniform(0.0, 20.0, p), rng.uniform(-3.0, 3.0, p)
    out = np.empty(p)
    d = diffusion_params(1.0 / 1.01, 1.3)
    base = best_time(lambda: _bare_dipole(s, 1.01, float(d.albedo_prime), float(d.mu), float(d.z_r), float(d.z_v), out),
                 a.repeat) / p * 1e9
    plan = AutoPlan(rng.integers(0, 4, n).astype(np.int8), np.ones(n, bool), np.zeros(n, bool))
    rows = {}
    for model in ("dipole", "curved", "fitted", "exact-sphere", "auto"):
        pk = PairKernel(model, mat, frames, plan=plan if model == "auto" else None, reach_mm=20.0)
        ns = best_time(lambda: pk.evaluate(0, src, s, s, phi), a.repeat) / p * 1e9
        rows[model] = {"ns_per_pair": round(ns, 1), "ratio": round(ns / base, 2)}
    print(json.dumps({"pairs": p, "baseline_bare_dipole_ns_per_pair": round(base, 1), "models": rows}, indent=1))


if __name__ == "__main__":
    main()
