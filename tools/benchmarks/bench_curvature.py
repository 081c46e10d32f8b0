#!/usr/bin/env python
"""Benchmark the first-order curvature kernel against the planar dipole; prints JSON on stdout.

Per-evaluation cost on the same N random pairs (skin test case of docs/physics.md §11.1, optical units): distances
uniform in [0, 50 mm], directions uniform, principal curvatures uniform in [-0.1, 0.1] /mm. Every variant is
timed in the same run, interleaved (round-robin over ``--repeat`` rounds, best time kept), so load from other
processes affects all of them alike. Variants:

* ``dipole_numpy``: ``meshshade.kernels.dipole.dipole_profile`` (what transport.py calls for the dipole model);
* ``dipole_compiled``: the same closed form in a bare numba loop (the fastest dipole we have);
* ``curved_api``: ``curvature_profile`` with phi (builds its CurvatureTable per call, included in the time);
* ``curved_api_cos2phi``: the same with ``cos2phi=`` (callers with tangent-plane x, y: (x^2 - y^2)/rho^2);
* ``curved_table_phi``: ``CurvatureTable.profile`` with phi (one cosine per pair);
* ``curved_table_cos2phi``: ``CurvatureTable.profile(..., cos2phi=...)``;
* ``fitted_table_phi`` / ``fitted_table_cos2phi``: the fitted curvature model on the dipole
  (``fitted_dipole_profile``, physics §14: numpy turns k1, k2, phi into each pair's curvatures, then the compiled
  loop) from the same table and its matched-boundary table;
* ``fitted_pairs``: ``fitted_dipole_pairs``, the bake's form (curvatures along and across and the twist given per
  pair; the compiled loop alone).

Ratios are curved time / dipole time per evaluation, and fitted time / curved time (the issue's budget: 1.5).
Also reports the table build time and its measured interpolation error.

Usage:  python tools/benchmarks/bench_curvature.py [--n 1000000] [--repeat 7] [--out bench.json]
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import time
from pathlib import Path

import numba
import numpy as np

from meshshade.kernels.curvature import CurvatureTable, curvature_profile
from meshshade.kernels.dipole import dipole_diffuse_reflectance, dipole_profile
from meshshade.kernels.fitted_curvature import (fitted_dipole_pairs, fitted_dipole_profile, matched_table,
                                                normal_curvatures)
from meshshade.kernels.optics import diffusion_params

SIGMA_S, SIGMA_A, ETA = 1.0, 0.01, 1.3
ST = SIGMA_S + SIGMA_A
ALB = SIGMA_S / ST
RHO_MAX_MM = 50.0
K_MAX_MM = 0.1


@numba.njit(cache=True, error_model="numpy")
def _dipole_loop(rho, alb, mu, z_r, z_v, out):
    for k in range(rho.size):
        out[k] = dipole_diffuse_reflectance(rho[k], alb, mu, z_r, z_v)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="pairs per call")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--seed", type=int, default=20261121)
    ap.add_argument("--out", type=Path, help="also write the JSON here")
    args = ap.parse_args(argv)
    n = args.n
    rng = np.random.default_rng(args.seed)
    rho = rng.random(n) * RHO_MAX_MM * ST
    phi = rng.random(n) * 2 * np.pi
    cos2 = np.cos(2 * phi)
    k1 = rng.uniform(-K_MAX_MM, K_MAX_MM, n) / ST
    k2 = rng.uniform(-K_MAX_MM, K_MAX_MM, n) / ST
    par = {"albedo_prime": ALB, "eta": ETA}
    p = diffusion_params(ALB, ETA)
    out = np.empty(n)

    t0 = time.perf_counter()
    table = CurvatureTable(ALB, ETA, float(rho.max()))
    t_build_first = time.perf_counter() - t0  # includes numba compilation or cache load
    t0 = time.perf_counter()
    table = CurvatureTable(ALB, ETA, float(rho.max()))
    t_build = time.perf_counter() - t0
    matched = matched_table(table)
    ka, kc, t2 = normal_curvatures(phi, k1, k2)

    variants = {
        "dipole_numpy": lambda: dipole_profile(rho, **par),
        "dipole_compiled": lambda: _dipole_loop(rho, float(p.albedo_prime), float(p.mu), float(p.z_r),
                                                float(p.z_v), out),
        "curved_api": lambda: curvature_profile(rho, phi, k1_opt=k1, k2_opt=k2, **par),
        "curved_api_cos2phi": lambda: curvature_profile(rho, cos2phi=cos2, k1_opt=k1, k2_opt=k2, **par),
        "curved_table_phi": lambda: table.profile(rho, phi, k1_opt=k1, k2_opt=k2),
        "curved_table_cos2phi": lambda: table.profile(rho, cos2phi=cos2, k1_opt=k1, k2_opt=k2),
        "fitted_table_phi": lambda: fitted_dipole_profile(table, rho, phi, k1_opt=k1, k2_opt=k2, matched=matched),
        "fitted_table_cos2phi": lambda: fitted_dipole_profile(table, rho, cos2phi=cos2, k1_opt=k1, k2_opt=k2,
                                                              matched=matched),
        "fitted_pairs": lambda: fitted_dipole_pairs(table, rho, ka, kc, t2, matched=matched),
    }
    for fn in variants.values():  # warm-up: compilation, caches
        fn()
    best = {k: math.inf for k in variants}
    for _ in range(args.repeat):
        for name, fn in variants.items():
            t0 = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t0)

    ns = {k: v / n * 1e9 for k, v in best.items()}
    ratios = {}
    for c in ("curved_api", "curved_api_cos2phi", "curved_table_phi", "curved_table_cos2phi"):
        for d in ("dipole_numpy", "dipole_compiled"):
            ratios[f"{c}/{d}"] = round(best[c] / best[d], 3)
    for f, c in (("fitted_table_phi", "curved_table_phi"), ("fitted_table_cos2phi", "curved_table_cos2phi"),
                 ("fitted_pairs", "curved_table_cos2phi")):
        ratios[f"{f}/{c}"] = round(best[f] / best[c], 3)
    report = {
        "case": {"sigma_s_prime_per_mm": SIGMA_S, "sigma_a_per_mm": SIGMA_A, "eta": ETA,
                 "rho_mm": [0.0, RHO_MAX_MM], "k_per_mm": [-K_MAX_MM, K_MAX_MM], "n_pairs": n},
        "ns_per_eval": {k: round(v, 2) for k, v in ns.items()},
        "evals_per_s": {k: round(1e9 / v) for k, v in ns.items()},
        "ratio": ratios,
        "table": {"intervals": table.n_intervals, "bytes": int(table.coef.nbytes),
                  "build_s": round(t_build, 5), "first_build_s_incl_jit_or_cache_load": round(t_build_first, 3),
                  "max_interpolation_error": table.max_interpolation_error(n=4000)},
        "repeat": args.repeat,
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
                    "processor": platform.processor() or platform.machine()},
    }
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
