#!/usr/bin/env python
"""Benchmark the reflectance kernels; prints JSON on stdout.

* evaluations/second of ``dipole_profile`` and ``sphere_series_profile`` (skin test case of docs/physics.md §11.1:
  sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3) by radius R0 in mm and by rtol;
* the sphere's terms-vs-accuracy-vs-time table: terms N, achieved error against an rtol = 1e-16 run
  (max over theta relative to the peak R_sph(0), and max relative error where R_sph >= 1e-6 R_sph(0)),
  seconds per call;
* the ratio of sphere to dipole cost per evaluation, measured in the same run.

Timings are the best of ``--repeat`` calls after a warm-up call (numba compilation excluded).

Usage:  python tools/benchmarks/bench_kernels.py [--n-theta 1000] [--repeat 5] [--out bench.json]
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.sphere import sphere_series_profile, sphere_series_terms

SIGMA_S, SIGMA_A, ETA = 1.0, 0.01, 1.3
ST = SIGMA_S + SIGMA_A
PAR = {"albedo_prime": SIGMA_S / ST, "eta": ETA}
RADII_MM = (1.0, 10.0, 100.0, 1000.0, 10000.0)
RTOLS = (1e-6, 1e-10, 1e-14)
TABLE_RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14)


def best_time(fn, repeat):
    fn()  # warm-up (compilation, caches)
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def thetas(R0_mm, n):
    """n angles covering geodesic distances 0..min(50 mm, pi R0) (where the reflectance matters)."""
    return np.linspace(0.0, min(50.0 / R0_mm, np.pi), n)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-theta", type=int, default=1000, help="angles per sphere call")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", type=Path, help="also write the JSON here")
    args = ap.parse_args(argv)
    n = args.n_theta

    r = np.linspace(0.0, 50.0 * ST, 1_000_000)
    t_dip = best_time(lambda: dipole_profile(r, **PAR), args.repeat)
    dip_eps = r.size / t_dip

    by_radius = []
    for R0_mm in RADII_MM:
        th = thetas(R0_mm, n)
        kw = {"R0_opt": R0_mm * ST, **PAR, "rtol": 1e-10}
        t_many = best_time(lambda: sphere_series_profile(th, **kw), args.repeat)
        t_one = best_time(lambda: sphere_series_profile(th[:1], **kw), args.repeat)
        by_radius.append({"R0_mm": R0_mm, "rtol": 1e-10, "terms": sphere_series_terms(**kw), "n_theta": n,
                          "seconds_per_call": t_many, "evals_per_second": n / t_many,
                          "seconds_single_theta": t_one,
                          "cost_ratio_vs_dipole": (t_many / n) / (1.0 / dip_eps)})

    by_rtol = []
    R0_mm = 100.0
    th = thetas(R0_mm, n)
    for rtol in RTOLS:
        kw = {"R0_opt": R0_mm * ST, **PAR, "rtol": rtol}
        t = best_time(lambda: sphere_series_profile(th, **kw), args.repeat)
        by_rtol.append({"R0_mm": R0_mm, "rtol": rtol, "terms": sphere_series_terms(**kw), "n_theta": n,
                        "seconds_per_call": t, "evals_per_second": n / t,
                        "cost_ratio_vs_dipole": (t / n) / (1.0 / dip_eps)})

    table = []
    for R0_mm in (10.0, 100.0, 1000.0, 10000.0):
        th = thetas(R0_mm, n)
        ref = sphere_series_profile(th, R0_opt=R0_mm * ST, **PAR, rtol=1e-16)
        near = ref >= 1e-6 * ref[0]
        for rtol in TABLE_RTOLS:
            kw = {"R0_opt": R0_mm * ST, **PAR, "rtol": rtol}
            v = sphere_series_profile(th, **kw)
            t = best_time(lambda: sphere_series_profile(th, **kw), args.repeat)
            table.append({"R0_mm": R0_mm, "rtol": rtol, "terms": sphere_series_terms(**kw),
                          "max_abs_err_over_peak": float(np.max(np.abs(v - ref)) / ref[0]),
                          "max_rel_err_where_ge_1e-6_peak": float(np.max(np.abs(v[near] / ref[near] - 1))),
                          "seconds_per_call": t, "n_theta": n})

    out = {
        "case": {"sigma_s_prime_per_mm": SIGMA_S, "sigma_a_per_mm": SIGMA_A, "eta": ETA},
        "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine(),
                    "numpy": np.__version__},
        "dipole": {"n": r.size, "seconds": t_dip, "evals_per_second": dip_eps},
        "sphere_by_radius": by_radius,
        "sphere_by_rtol": by_rtol,
        "sphere_terms_accuracy_time": table,
    }
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
