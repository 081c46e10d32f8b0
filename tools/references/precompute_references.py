#!/usr/bin/env python
"""Offline mpmath references for the exact sphere (physics.md c): writes tests/data/sphere_reference.csv.

Independent of meshshade (imports nothing from it). The dipole parameters come from
tools/references/precompute_dipole_references.py (``params``), which also writes tests/data/dipole_reference.csv; the
planar-dipole references are *not* duplicated here.

Method, in optical units (sigma_t' = 1), at the float64 inputs converted exactly to mpmath:

* geometry: source depth ``delta = min(z_r, R0)`` (meshshade's small-sphere policy), ``r' = R0 - delta``,
  ``R = R0 + z_b``;
* the series in its ORIGINAL form (physics.md c)

      c_m = (2m+1) I_nu(mu r') K_nu(mu R) / (I_nu(mu R) sqrt(r' R0)) [mu I_{nu+1}(mu R0) + m I_nu(mu R0)/R0]

  with I_nu, K_nu themselves (no ratio recurrences): I_nu from exact top values ``mp.besseli`` at the two
  highest orders plus backward recurrence (adds positive terms: no cancellation), K_nu from the closed forms
  K_{1/2}, K_{3/2} plus forward recurrence; the tables are checked at a few orders against ``mp.besseli``, the
  closed form of I_{1/2} and the finite sum for K_{m+1/2} (A&S 10.2.15). At r' = 0 only m = 0 survives, with
  ``lim I_{1/2}(mu r')/sqrt(r') = sqrt(2 mu/pi)``;
* free-space term in the textbook form ``g(d) (R0 - r' cos theta)``, ``d^2 = R0^2 + r'^2 - 2 R0 r' cos theta``;
* Legendre polynomials by the three-term recurrence at ``x = cos theta`` (in mpmath);
* mu = 0 (alpha' = 1): the series is ``c_m = m q^m/(R0 R)``, summed in closed form with the Legendre generating
  function: ``sum m q^m P_m(x) = q (x - q)/(1 - 2 q x + q^2)^{3/2}`` (method ``kelvin_closed_form``).

Precision control per (case, radius, group of angles): the number of terms N makes the geometric tail bound
``c_{N-1} rho/(1 - rho)`` (rho the last ratio; the ratios are checked to be non-increasing) smaller than
``TAIL`` times the smallest value of the group, and the working precision covers the cancellation between the
peak and that smallest value. Every group is computed twice, at ``dps`` and ``dps + 15`` with the same N; the
column ``rel_err_est`` is (tail bound + |difference|)/|value| and the script aborts if any exceeds 1e-20.

Usage:  python tools/references/precompute_references.py [--out tests/data/sphere_reference.csv] [--jobs 2]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from multiprocessing import Pool
from pathlib import Path

from mpmath import mp, mpf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _refheader import write_reference_csv  # noqa: E402  (tools/ is not a package)
from precompute_dipole_references import params  # noqa: E402  (alpha', eta -> z_r, z_b, z_v, mu in mpmath)

DIPOLE_SCRIPT = Path(__file__).resolve().parent / "precompute_dipole_references.py"  # hashed as a dependency

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = ROOT / "tests" / "data" / "sphere_reference.csv"
TAIL = mpf("1e-25")  # tail bound relative to the smallest value of a group
MAX_REL_ERR = mpf("1e-20")

#: polar angles for spheres of a few transport lengths to a few hundred (theta up to pi)
THETA_FULL = (0.0, 1e-6, 1e-3, 0.01, 0.05, 0.1, 0.3, 0.6, 1.0, 1.5, 2.0, 2.5, 3.0, math.pi)

SKIN = (1.0, 0.01)  # physics.md a test case [1/mm]

#: (case, sigma_s' [1/mm], sigma_a [1/mm], eta, [(R0 [mm], theta group name), ...]); presets: Jensen et al. 2001
CASES = [
    ("skin_eta1.3", *SKIN, 1.3, [(0.5, "full"), (2.0, "full"), (10.0, "full"), (100.0, "full"),
                                 (1000.0, "near"), (1000.0, "far"), (10000.0, "near")]),
    ("skin_eta1.0", *SKIN, 1.0, [(1.5, "full"), (5.0, "full"), (50.0, "full")]),
    ("skin_eta2.0", *SKIN, 2.0, [(20.0, "full")]),
    ("marble_R", 2.19, 0.0021, 1.3, [(10.0, "full"), (100.0, "full")]),
    ("potato_B", 0.55, 0.12, 1.3, [(5.0, "full"), (50.0, "full")]),
    ("ketchup_B", 0.03, 1.45, 1.3, [(20.0, "full")]),          # albedo ~0.02, mu ~ 1.7
    ("near_conservative", 1.0, 1e-10, 1.5, [(3.0, "full"), (30.0, "full")]),  # mu ~ 1.7e-5
    ("albedo1", 1.0, 0.0, 1.3, [(0.5, "full"), (5.0, "full"), (50.0, "full"), (500.0, "full")]),  # mu = 0
]


def theta_group(name: str, R0_mm: float) -> list[float]:
    """Angles of a group; 'near' is by geodesic distance s [mm] = R0 theta, 'far' covers the rest up to pi."""
    if name == "full":
        return list(THETA_FULL)
    if name == "near":
        s_mm = (0.0, 0.1, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)
        return [s / R0_mm for s in s_mm]
    if name == "far":
        return [0.0, 0.3, 1.0, 2.0, math.pi]
    raise ValueError(name)


def legendre_sum(c, x):
    """sum_m c[m] P_m(x) by the three-term recurrence."""
    p_prev, p = mpf(1), x
    acc = c[0] + (c[1] * x if len(c) > 1 else 0)
    for m in range(1, len(c) - 1):
        p_prev, p = p, ((2 * m + 1) * x * p - m * p_prev) / (m + 1)
        acc += c[m + 1] * p
    return acc


def i_table(x, n):
    """[I_{m+1/2}(x) for m = 0..n] by backward recurrence from exact mp.besseli at the two top orders."""
    tab = [mpf(0)] * (n + 1)
    tab[n] = mp.besseli(n + mpf(1) / 2, x)
    tab[n - 1] = mp.besseli(n - mpf(1) / 2, x)
    for m in range(n - 1, 0, -1):  # I_{nu-1} = I_{nu+1} + (2 nu/x) I_nu, nu = m + 1/2
        tab[m - 1] = tab[m + 1] + (2 * m + 1) / x * tab[m]
    return tab


def k_table(x, n):
    """[K_{m+1/2}(x) for m = 0..n] by forward recurrence from the closed forms of K_{1/2}, K_{3/2}."""
    tab = [mpf(0)] * (n + 1)
    tab[0] = mp.sqrt(mp.pi / (2 * x)) * mp.exp(-x)
    tab[1] = tab[0] * (1 + 1 / x)
    for m in range(1, n):  # K_{nu+1} = K_{nu-1} + (2 nu/x) K_nu
        tab[m + 1] = tab[m - 1] + (2 * m + 1) / x * tab[m]
    return tab


def check_tables(I, K, x_i, x_k, tol):
    """Spot checks of the recurrences against mpmath's own Bessel functions and the closed form of I_{1/2}."""
    n = len(I) - 1
    closed = mp.sqrt(2 / (mp.pi * x_i)) * mp.sinh(x_i)
    assert abs(I[0] / closed - 1) < tol, ("I_1/2", I[0], closed)
    for m in {1, n // 2, n - 2}:
        ref = mp.besseli(m + mpf(1) / 2, x_i)
        assert abs(I[m] / ref - 1) < tol, ("I", m, I[m], ref)
    # K_{m+1/2} of half-integer order is a finite sum of positive terms (A&S 10.2.15, no cancellation);
    # mp.besselk's asymptotic series does not converge at high precision for x ~ 1e3
    for m in {1, n // 2, n}:
        term, acc = mpf(1), mpf(1)
        for k in range(1, m + 1):
            term *= mpf((m + k) * (m - k + 1)) / (k * 2 * x_k)  # (m+k)!/(k!(m-k)!(2x)^k)
            acc += term
        ref = mp.sqrt(mp.pi / (2 * x_k)) * mp.exp(-x_k) * acc
        assert abs(K[m] / ref - 1) < tol, ("K", m, K[m], ref)


def sphere_values(albedo, eta, R0_f, thetas, dps, n_terms, *, check=False):
    """R_sph(theta)/sigma_t'^2 (Jensen normalisation) at each theta, the tail bound, and the terms used."""
    with mp.workdps(dps):
        p = params(mpf(albedo), mpf(eta))
        mu, z_b = p["mu"], p["z_b"]
        R0 = mpf(R0_f)
        delta = min(p["z_r"], R0)
        rs = R0 - delta
        R = R0 + z_b
        cos = [mp.cos(mpf(t)) for t in thetas]
        free = []
        for x in cos:
            d = mp.sqrt(R0**2 + rs**2 - 2 * R0 * rs * x)
            free.append((mu * d + 1) * mp.exp(-mu * d) / d**3 * (R0 - rs * x))
        pref = p["albedo"] / (4 * mp.pi)
        if mu == 0:  # Kelvin image of Laplace's equation, closed form
            q = rs * R0 / R**2
            vals = [pref * (f + q * (x - q) / (R0 * R * (1 - 2 * q * x + q * q) ** mpf(1.5)))
                    for f, x in zip(free, cos)]
            return vals, mpf(0), 0, "kelvin_closed_form"
        x1, x0, xR = mu * rs, mu * R0, mu * R
        if rs == 0:  # source at the centre: only m = 0
            half = mpf(1) / 2
            c0 = (mp.sqrt(2 * mu / mp.pi) * mp.besselk(half, xR) / (mp.besseli(half, xR) * mp.sqrt(R0))
                  * mu * mp.besseli(half + 1, x0))
            return [pref * (f + c0) for f in free], mpf(0), 1, "series_r'=0"
        n = n_terms
        I1, I0, IR, K = i_table(x1, n + 1), i_table(x0, n + 1), i_table(xR, n + 1), k_table(xR, n + 1)
        if check:
            tol = mpf(10) ** (-(dps - 10))
            check_tables(I0, K, x0, xR, tol)
            check_tables(I1, K, x1, xR, tol)
        sq = mp.sqrt(rs * R0)
        c = [(2 * m + 1) * I1[m] * K[m] / (IR[m] * sq) * (mu * I0[m + 1] + m * I0[m] / R0) for m in range(n)]
        ratios = [c[m] / c[m - 1] for m in range(n - 20, n)]
        assert all(a >= b for a, b in zip(ratios, ratios[1:])), "ratios not non-increasing at the tail"
        rho = ratios[-1]
        assert rho < 1
        tail = pref * c[-1] * rho / (1 - rho)
        vals = [pref * (f + legendre_sum(c, x)) for f, x in zip(free, cos)]
        return vals, tail, n, "series"


def plan(albedo, eta, R0_f, thetas):
    """(dps, N) for a group: N from the geometric rate q and an estimate of the smallest value (free-space term)."""
    with mp.workdps(30):
        p = params(mpf(albedo), mpf(eta))
        mu, z_b = p["mu"], p["z_b"]
        R0 = mpf(R0_f)
        delta = min(p["z_r"], R0)
        rs = R0 - delta
        R = R0 + z_b

        def free(t):
            x = mp.cos(mpf(t))
            d = mp.sqrt(R0**2 + rs**2 - 2 * R0 * rs * x)
            return (mu * d + 1) * mp.exp(-mu * d) / d**3 * (R0 - rs * x)

        # smallest value ~ free-space term times a power-law image factor (margin 1e-3)
        ratio = min(free(t) for t in thetas) / free(0) * mpf("1e-3")
        digits = max(0, int(-mp.log10(ratio)))
        dps = 30 + digits + 5
        L = -mp.log(TAIL * ratio)
        q = rs * R0 / R**2
        n = 1 if q == 0 else int(1.5 * L / -mp.log(q) + mu * R + 100)
    return dps, n


def run_group(job):
    case, s, a, eta, R0_mm, group = job
    t0 = time.time()
    albedo = s / (s + a)  # float64, as meshshade.materials.Material.albedo_prime
    st = s + a
    R0_f = R0_mm * st  # the double the tests pass as R0_opt
    thetas = theta_group(group, R0_mm)
    dps, n = plan(albedo, eta, R0_f, thetas)
    while True:
        v1, tail, used, method = sphere_values(albedo, eta, R0_f, thetas, dps, n, check=True)
        with mp.workdps(dps):
            vmin = min(abs(v) for v in v1)
            if used <= 1 or tail <= TAIL * vmin:
                break
        n = int(n * 1.5)
    v2, _, _, _ = sphere_values(albedo, eta, R0_f, thetas, dps + 15, n)
    rows = []
    with mp.workdps(dps + 15):
        for t, a1, a2 in zip(thetas, v1, v2):
            err = (tail + abs(a1 - a2)) / abs(a2)
            if not err <= MAX_REL_ERR:
                raise RuntimeError(f"{case} R0={R0_mm} theta={t}: rel_err_est {err} > {MAX_REL_ERR}")
            rows.append({"case": case, "sigma_s_prime": repr(s), "sigma_a": repr(a), "albedo_prime": repr(albedo),
                         "eta": repr(eta), "R0_mm": repr(R0_mm), "R0_opt": repr(R0_f), "theta": repr(t),
                         "value": mp.nstr(a2, 25, min_fixed=0, max_fixed=0),
                         "rel_err_est": mp.nstr(err, 2, min_fixed=0, max_fixed=0),
                         "n_terms": used, "dps": dps, "method": method})
    print(f"{case:18s} R0={R0_mm:8g} mm ({group:4s}) N={used:7d} dps={dps:4d} "
          f"max rel_err_est={max(float(r['rel_err_est']) for r in rows):.1e}  {time.time() - t0:6.1f} s", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    jobs = [(case, s, a, eta, R0_mm, grp) for case, s, a, eta, radii in CASES for R0_mm, grp in radii]
    longest_first = sorted(range(len(jobs)), key=lambda i: -jobs[i][4])
    t0 = time.time()
    with Pool(args.jobs) as pool:
        results = dict(zip(longest_first, pool.map(run_group, [jobs[i] for i in longest_first], chunksize=1)))
    rows = [row for i in range(len(jobs)) for row in results[i]]  # CASES order
    elapsed = time.time() - t0
    cases_txt = "; ".join(f"{c}=(sigma_s_prime={s}, sigma_a={a}, eta={e}, R0_mm={[r for r, _ in rr]})"
                          for c, s, a, e, rr in CASES)
    fields = ["case", "sigma_s_prime", "sigma_a", "albedo_prime", "eta", "R0_mm", "R0_opt", "theta", "value",
              "rel_err_est", "n_terms", "dps", "method"]
    write_reference_csv(
        args.out, fields, rows, script=Path(__file__), depends=[DIPOLE_SCRIPT],
        title="Exact-sphere references (physics.md c), optical units: R_sph(theta) / sigma_t'^2, Jensen normalisation",
        params={
            "function": "alpha'/(4 pi) [g(d)(R0 - r' cos theta) + sum_m c_m P_m(cos theta)], original c_m form with"
                        " I_nu, K_nu in mpmath (see tools/references/precompute_references.py docstring);"
                        " r' = R0 - min(z_r, R0),"
                        " R = R0 + z_b",
            "inputs": "albedo_prime = sigma_s'/(sigma_s'+sigma_a) as float64, R0_opt = R0_mm*(sigma_s'+sigma_a) as"
                      " float64, eta, theta: exact doubles (repr) converted exactly to mpmath",
            "parameters": cases_txt,
            "theta groups": f"full={list(THETA_FULL)}; near = s/R0 for s in (0, 0.1, 1, 2, 5, 10, 20, 50) mm;"
                            " far = (0, 0.3, 1, 2, pi)",
            "dps": f"per group (column dps), each group recomputed at dps+15; tail bound < {mp.nstr(TAIL, 2)} x"
                   f" smallest value; rel_err_est = (tail + |diff|)/|value| <= {mp.nstr(MAX_REL_ERR, 2)};"
                   " values to 25 digits",
            "runtime": f"{elapsed:.0f} s on {args.jobs} processes",
        })
    print(f"wrote {len(rows)} rows to {args.out} in {elapsed:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
