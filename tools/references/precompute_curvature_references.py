#!/usr/bin/env python
"""Offline mpmath references for the first-order curvature kernel (physics.md e.2, e.3 (ii)).

Writes two CSV files:

* ``tests/data/curvature_aux_reference.csv``: the auxiliary integral and its companion,

      I(rho, h)       = int_h^inf exp(-mu s)/s dt,            s = sqrt(rho^2 + t^2),
      J(rho, h)       = (1/rho) dI/drho = -int_h^inf g(s) dt,  g(s) = (mu s + 1) exp(-mu s)/s^3,

  by mpmath tanh-sinh quadrature of these *t-integrals* (an independent route: the package integrates the
  shifted ``t = rho sinh u`` form with Gauss-Legendre panels). The integrands are normalised by their value at
  t = h (mpmath's convergence test is absolute) and the t-axis is split at ``h + x0 2^k`` up to the point
  where ``mu (s - d) = 1`` and then at ``mu (s - d) = 1, 2, ..., 100`` (``d = sqrt(rho^2 + h^2)``); beyond
  that the tail is integrated to infinity separately. Every value is computed twice, at ``DPS`` digits and at
  ``DPS + 10`` digits with half-width steps; ``rel_err_est`` is their relative difference (the script aborts
  above 1e-25). Closed forms are used only as checks (abort above 1e-30): ``I(rho, 0) = K0(mu rho)``,
  ``J(rho, 0) = -mu K1(mu rho)/rho``, ``I(0, h) = E1(mu h)``, ``J(0, h) = -(mu E2(mu h)/h + E3(mu h)/h^2)``.

* ``tests/data/curvature_coefficients_reference.csv``: A, B (unit source, physics.md e.3 (ii)) and the
  ratios ``a = alpha' A/R_d``, ``b = alpha' B/R_d`` in optical units, from the formulas of physics.md e.3 (ii)
  evaluated in mpmath with the quadrature values of I and J above:

      4 pi (A+B) = (rho^2/2) [g(d_r) + z_r^2 p(d_r) - g(d_v) - z_v^2 p(d_v)]
                 + a [mu^2 I(rho,z_v) - z_v g(d_v) + z_v rho^2 p(d_v) - z_b (mu^2 e^{-mu d_v}/d_v + g(d_v) - z_v^2 p(d_v))],
      4 pi B     = a [J(rho, z_v) + z_b g(d_v)],     a = z_r + z_b,
      R_d        = alpha'/(4 pi) [z_r g(d_r) + z_v g(d_v)],

  with z_r = 1, z_b = 2A/3, z_v = 1 + 4A/3, A = (1 + F_dr)/(1 - F_dr) (Groenhuis F_dr), mu = sqrt(3(1 - alpha')).
  At alpha' = 1 (mu = 0) the term ``mu^2 I`` is its limit 0 (I diverges only logarithmically).

This script imports nothing from meshshade. Inputs are the doubles the tests pass (``repr`` round-trips),
converted exactly to mpmath.

Usage:  python tools/references/precompute_curvature_references.py [--jobs 2]
"""
from __future__ import annotations

import argparse
import sys
import time
from multiprocessing import Pool
from pathlib import Path

from mpmath import mp, mpf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _refheader import write_reference_csv  # noqa: E402  (tools/ is not a package)

DPS = 40
ROOT = Path(__file__).resolve().parents[2]
OUT_AUX = ROOT / "tests" / "data" / "curvature_aux_reference.csv"
OUT_COEF = ROOT / "tests" / "data" / "curvature_coefficients_reference.csv"

AUX_RHO = (0.0, 1e-6, 1e-3, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)
AUX_RHO_FAR = (300.0,)  # only with mu >= 1: mu d = 300..900, the last underflows float64
#: h: 0 (K0 case, rho > 0 only), small, and z_v (optical units) for eta = 1.0, 1.3, 2.0 (z_v depends on eta only)
AUX_MU = (1e-5, 0.17, 1.0, 3.0)

#: case -> (sigma_s' [1/mm], sigma_a [1/mm], eta)
COEF_CASES = {
    "skin_test_eta1.3": (1.0, 0.01, 1.3),  # physics.md a test case
    "skin_test_eta1.0": (1.0, 0.01, 1.0),
    "marble_R": (2.19, 0.0021, 1.3),
    "potato_B": (0.55, 0.12, 1.3),
    "ketchup_B": (0.03, 1.45, 1.3),  # alpha' ~ 0.02: outside diffusion validity, still a function
    "near_conservative": (1.0, 1e-10, 1.5),
    "albedo1": (1.0, 0.0, 1.3),  # mu = 0
}
COEF_RHO = (0.0, 1e-3, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 200.0)


def z_v_of_eta(eta: mpf) -> mpf:
    F_dr = -mpf("1.440") / eta**2 + mpf("0.710") / eta + mpf("0.668") + mpf("0.0636") * eta
    A = (1 + F_dr) / (1 - F_dr)
    return 1 + 4 * A / 3


def _split_points(rho: mpf, h: mpf, mu: mpf, w_step: mpf) -> list:
    d = mp.sqrt(rho**2 + h**2)
    scales = [x for x in (rho, h) if x > 0]
    x0 = min(scales) / 64

    def t_of_w(w):
        s = d + w / mu
        return mp.sqrt(s * s - rho * rho)

    t_w1 = t_of_w(1) if mu > 0 else mpf(10) ** 15
    pts = [h]
    x = x0
    while h + x < t_w1:
        pts.append(h + x)
        x *= 2
    if mu > 0:
        w = mpf(1)
        while w <= 100:
            pts.append(t_of_w(w))
            w += w_step
    return pts


def _quad_normalised(f, pts):
    val = mp.quad(f, pts) + mp.quad(f, [pts[-1], mp.inf])
    mp._tanh_sinh.clear()  # mpmath caches transformed nodes per interval: unbounded memory otherwise
    return val


def aux_I(rho: mpf, h: mpf, mu: mpf, w_step=mpf(1)) -> mpf:
    """I(rho, h) by quadrature of the t-integral; +inf at mu = 0."""
    if mu == 0:
        return mp.inf
    d = mp.sqrt(rho**2 + h**2)

    def f(t):
        s = mp.sqrt(rho**2 + t**2)
        return mp.exp(-mu * (s - d)) * d / s

    return _quad_normalised(f, _split_points(rho, h, mu, w_step)) * mp.exp(-mu * d) / d


def aux_J(rho: mpf, h: mpf, mu: mpf, w_step=mpf(1)) -> mpf:
    """(1/rho) dI/drho = -int_h^inf g(s) dt by quadrature."""
    d = mp.sqrt(rho**2 + h**2)

    def f(t):
        s = mp.sqrt(rho**2 + t**2)
        return (mu * s + 1) / (mu * d + 1) * mp.exp(-mu * (s - d)) * (d / s) ** 3

    return -_quad_normalised(f, _split_points(rho, h, mu, w_step)) * (mu * d + 1) * mp.exp(-mu * d) / d**3


def _both_precisions(fn, make_args):
    """fn(*make_args()) at DPS and at DPS + 10 with half-width steps; returns (value, relative difference)."""
    with mp.workdps(DPS):
        v1 = fn(*make_args())
    with mp.workdps(DPS + 10):
        v2 = fn(*make_args(), w_step=mpf(1) / 2)
        err = abs(v1 - v2) / abs(v2) if mp.isfinite(v2) and v2 != 0 else mpf(0)
    if err > mpf("1e-25"):
        raise SystemExit(f"{fn.__name__}{make_args()}: precision check failed, rel diff {err}")
    return v2, err


def _closed_form_check(rho, h, mu, I, J):
    with mp.workdps(DPS + 10):
        rho, h, mu = mpf(rho), mpf(h), mpf(mu)
        checks = []
        if h == 0:
            checks += [("K0", I, mp.besselk(0, mu * rho)), ("-mu K1/rho", J, -mu * mp.besselk(1, mu * rho) / rho)]
        if rho == 0:
            checks += [("E1", I, mp.e1(mu * h)),
                       ("E2/E3", J, -(mu * mp.expint(2, mu * h) / h + mp.expint(3, mu * h) / h**2))]
        for name, got, want in checks:
            if abs(got - want) > mpf("1e-30") * abs(want):
                raise SystemExit(f"closed form {name} at rho={rho}, h={h}, mu={mu}: {got} != {want}")
        return ",".join(name for name, _, _ in checks)


def aux_row(args):
    rho, h, mu = args
    args_ = lambda: (mpf(rho), mpf(h), mpf(mu))  # noqa: E731
    I, eI = _both_precisions(aux_I, args_)
    J, eJ = _both_precisions(aux_J, args_)
    checked = _closed_form_check(rho, h, mu, I, J)
    with mp.workdps(DPS + 10):
        return {"rho": repr(rho), "h": repr(h), "mu": repr(mu), "I": mp.nstr(I, 30, min_fixed=0, max_fixed=0),
                "J": mp.nstr(J, 30, min_fixed=0, max_fixed=0), "rel_err_est": mp.nstr(max(eI, eJ), 2),
                "closed_form_checked": checked}


def coef_row(args):
    case, (s_p, s_a, eta_f), rho_f = args
    albedo_f = s_p / (s_p + s_a)  # float64, as meshshade.materials computes it
    with mp.workdps(DPS + 10):
        alb, eta, rho = mpf(albedo_f), mpf(eta_f), mpf(rho_f)
        z_r = mpf(1)
        z_v = z_v_of_eta(eta)
        z_b = (z_v - z_r) / 2
        a = z_r + z_b
        mu = mp.sqrt(3 * (1 - alb))

        def g(d):
            return (mu * d + 1) * mp.exp(-mu * d) / d**3

        def p(d):
            return (mu**2 * d**2 + 3 * mu * d + 3) * mp.exp(-mu * d) / d**5

    args_ = lambda: (mpf(rho_f), z_v_of_eta(mpf(eta_f)), mp.sqrt(3 * (1 - mpf(albedo_f))))  # noqa: E731
    I, eI = (mpf(0), mpf(0)) if albedo_f == 1.0 else _both_precisions(aux_I, args_)
    J, eJ = _both_precisions(aux_J, args_)
    with mp.workdps(DPS + 10):
        if mu == 0:
            d = mp.sqrt(rho**2 + z_v**2)
            want = -1 / (d * (d + z_v))
            if abs(J - want) > mpf("1e-30") * abs(want):
                raise SystemExit(f"mu = 0 closed form of J failed at rho={rho}: {J} != {want}")
        d_r = mp.sqrt(rho**2 + z_r**2)
        d_v = mp.sqrt(rho**2 + z_v**2)
        mu2I = mu**2 * I if mu > 0 else mpf(0)
        ApB = (rho**2 / 2 * (g(d_r) + z_r**2 * p(d_r) - g(d_v) - z_v**2 * p(d_v))
               + a * (mu2I - z_v * g(d_v) + z_v * rho**2 * p(d_v)
                      - z_b * (mu**2 * mp.exp(-mu * d_v) / d_v + g(d_v) - z_v**2 * p(d_v)))) / (4 * mp.pi)
        B = a * (J + z_b * g(d_v)) / (4 * mp.pi)
        A = ApB - B
        Rd = alb / (4 * mp.pi) * (z_r * g(d_r) + z_v * g(d_v))
        fmt = lambda x: mp.nstr(x, 30, min_fixed=0, max_fixed=0)  # noqa: E731
        return {"case": case, "sigma_s_prime": repr(s_p), "sigma_a": repr(s_a), "albedo_prime": repr(albedo_f),
                "eta": repr(eta_f), "rho_opt": repr(rho_f), "A": fmt(A), "B": fmt(B), "R_d": fmt(Rd),
                "a_ratio": fmt(alb * A / Rd), "b_ratio": fmt(alb * B / Rd), "rel_err_est": mp.nstr(max(eI, eJ), 2)}


def aux_grid():
    with mp.workdps(DPS):
        zvs = [float(z_v_of_eta(mpf(e))) for e in (1.0, 1.3, 2.0)]
    hs = [0.0, 1e-3, 0.3] + zvs
    grid = [(r, h, m) for m in AUX_MU for h in hs for r in AUX_RHO if not (r == 0 and h == 0)]
    grid += [(r, h, m) for m in AUX_MU if m >= 1 for h in (0.0, zvs[1]) for r in AUX_RHO_FAR]
    return grid, hs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out-aux", type=Path, default=OUT_AUX)
    ap.add_argument("--out-coef", type=Path, default=OUT_COEF)
    args = ap.parse_args(argv)
    t0 = time.time()
    grid, hs = aux_grid()
    coef_grid = [(c, v, r) for c, v in COEF_CASES.items() for r in COEF_RHO]
    with Pool(args.jobs) as pool:
        aux_rows = pool.map(aux_row, grid, chunksize=1)
        coef_rows = pool.map(coef_row, coef_grid, chunksize=1)
    runtime = time.time() - t0
    dps = f"{DPS} (value), checked against {DPS + 10} digits with a finer split (rel_err_est)"

    write_reference_csv(
        args.out_aux, list(aux_rows[0]), aux_rows, script=Path(__file__),
        title="Auxiliary integral of the curvature kernel (physics.md e.2), optical units",
        params={
            "function": "I = int_h^inf exp(-mu s)/s dt, J = (1/rho) dI/drho = -int_h^inf (mu s+1) exp(-mu s)/s^3 dt,"
                        " s = sqrt(rho^2+t^2)",
            "method": "mpmath tanh-sinh quadrature of the t-integrals (normalised integrands, split points in"
                      " mu (s - d)); closed forms K0, K1, E1, E2, E3 only as checks (column closed_form_checked,"
                      " to 1e-30)",
            "parameters": f"rho {list(AUX_RHO)} (+ {list(AUX_RHO_FAR)} for mu >= 1, h in {{0, z_v(1.3)}});"
                          f" h {hs} (z_v for eta 1.0, 1.3, 2.0); mu {list(AUX_MU)}",
            "inputs": "rho, h, mu are exact doubles (repr) converted exactly to mpmath; values to 30 digits",
            "dps": dps,
            "runtime": f"{runtime:.0f} s on {args.jobs} processes (both files)",
        })
    write_reference_csv(
        args.out_coef, list(coef_rows[0]), coef_rows, script=Path(__file__),
        title="First-order curvature coefficients (physics.md e.3 (ii)), optical units (lengths x sigma_t')",
        params={
            "function": "A, B (unit source) with R = R_d + alpha' [k_n(phi) A + k_n(phi+pi/2) B];"
                        " a_ratio = alpha' A/R_d, b_ratio = alpha' B/R_d; R_d = alpha'/(4 pi)[z_r g(d_r) + z_v g(d_v)]"
                        " (see the generator docstring)",
            "method": "formulas of physics.md e.3 (ii) in mpmath with I(rho, z_v), J(rho, z_v) from the quadrature"
                      " of curvature_aux_reference.csv; mu^2 I = 0 at mu = 0",
            "parameters": "cases " + ", ".join(f"{k}=(sigma_s_prime={v[0]}, sigma_a={v[1]}, eta={v[2]})"
                                               for k, v in COEF_CASES.items()) + f"; rho_opt {list(COEF_RHO)}",
            "inputs": "albedo_prime = sigma_s'/(sigma_s'+sigma_a) as float64, eta, rho_opt: exact doubles (repr)",
            "dps": dps,
            "runtime": f"{runtime:.0f} s on {args.jobs} processes (both files)",
        })
    print(f"wrote {len(aux_rows)} rows to {args.out_aux} and {len(coef_rows)} rows to {args.out_coef} "
          f"in {runtime:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
