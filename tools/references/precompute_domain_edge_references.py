#!/usr/bin/env python
"""Offline mpmath values of every material kernel at one point, for alpha' = 0.9 and eta on the edges and inside
of the documented domain [1, 2.5]: writes tests/data/domain_edge_reference.csv.

tests/kernels/test_kernel_errors.py calls each kernel that takes a material at eta = 1.0, 1.3, 1.7 and 2.5 (the
ends of the F_dr fit's domain and two points inside) and compares the value with this file, so that a kernel
that accepts an edge value but returns NaN, 0 or a wrong branch there fails. Imports nothing from meshshade; it
reuses the independent mpmath routes of the other generators (each hashed as a dependency):

* ``dipole_R_d`` at r = 0 and 1: the closed form of physics.md b (``precompute_dipole_references.R_d``);
  ``dipole_total``: tanh-sinh quadrature of 2 pi r R_d (``total_by_quadrature``), checked against the closed form
  (abort above 1e-30); ``dipole_tail`` at r = 1: quadrature of 2 pi r R_d from 1 to infinity, checked against
  ``(alpha'/2) [z_r e^{-mu d_r}/d_r + z_v e^{-mu d_v}/d_v]`` (abort above 1e-30);
* ``curv_A``, ``curv_B``, ``curv_a``, ``curv_b`` at rho = 0 and 1: ``precompute_curvature_references.coef_row``
  (quadrature of the t-integrals at DPS and DPS + 10 digits; aborts above 1e-25);
* ``sphere_series`` at R0 = 10, theta = 0.1: ``precompute_references.sphere_values`` (the Bessel series in its
  original form) with that script's term and precision plan, computed twice (dps and dps + 15);
* ``sphere_total`` at R0 = 10: 2 pi R0^2 alpha'/(4 pi) [int_0^pi free(theta) sin theta dtheta + 2 c_0], the
  free-space term by tanh-sinh quadrature and c_0 (the only Legendre term with a non-zero integral) from
  mp.besseli/mp.besselk at orders 1/2 and 3/2; checked against physics.md eq. (33) (abort above 1e-25);
* ``sphere_chord`` at R0 = 10, theta = 0.1: R_d(2 R0 sin(theta/2));
* ``cylinder`` at R0 = 3, (theta, z) = (0.1, 0) and (cos 0.3/3, sin 0.3) (the geodesic rho = 1, phi = 0.3):
  ``precompute_cylinder_references.reflectance`` (mp.besseli/besselk, Gauss-Legendre in q) at 30 digits;
  rel_err_est is mp.quad's error estimate over the value.

Inputs are the doubles the test passes (0.9, 1.0, 1.3, 1.7, 2.5, 0.1, 0.3), converted exactly to mpmath.

Usage:  python tools/references/precompute_domain_edge_references.py   (about 6 minutes, the cylinder at eta = 1
the longest)
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from mpmath import mp, mpf

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _refheader import write_reference_csv  # noqa: E402  (tools/ is not a package)
import precompute_curvature_references as curvature  # noqa: E402
import precompute_cylinder_references as cylinder  # noqa: E402
import precompute_dipole_references as dipole  # noqa: E402
import precompute_references as sphere  # noqa: E402

ROOT = HERE.parents[1]
OUT = ROOT / "tests" / "data" / "domain_edge_reference.csv"
DPS = 50
ALBEDO = 0.9
ETAS = (1.0, 1.3, 1.7, 2.5)
SPHERE_R0, SPHERE_THETA = 10.0, 0.1
CYL_R0, CYL_THETA, CYL_RHO, CYL_PHI = 3.0, 0.1, 1.0, 0.3
CYL_DPS = 30


def _fmt(x) -> str:
    return mp.nstr(x, 25, min_fixed=0, max_fixed=0)


def dipole_rows(eta: float) -> list[tuple]:
    rows = []
    with mp.workdps(DPS):
        p = dipole.params(mpf(ALBEDO), mpf(eta))
        for r in (0.0, 1.0):
            rows.append(("dipole_R_d", r, "", dipole.R_d(mpf(r), p), 0, "closed form"))
        tot, _ = dipole.total_by_quadrature(p)
        closed = dipole.total_closed_form(p)
        if abs(tot - closed) > mpf("1e-30") * closed:
            raise SystemExit(f"eta {eta}: total by quadrature {tot} != closed form {closed}")
        rows.append(("dipole_total", "", "", tot, abs(tot - closed) / closed, "tanh-sinh quadrature"))
        pts = [mpf(1), p["z_v"] + 1, mpf(10), mpf(30), mpf(100), mpf(1000), mp.inf]
        tail = mp.quad(lambda r: 2 * mp.pi * r * dipole.R_d(r, p), pts, maxdegree=10)
        d_r, d_v = mp.sqrt(1 + p["z_r"] ** 2), mp.sqrt(1 + p["z_v"] ** 2)
        closed = p["albedo"] / 2 * (p["z_r"] * mp.exp(-p["mu"] * d_r) / d_r + p["z_v"] * mp.exp(-p["mu"] * d_v) / d_v)
        if abs(tail - closed) > mpf("1e-30") * closed:
            raise SystemExit(f"eta {eta}: tail by quadrature {tail} != closed form {closed}")
        rows.append(("dipole_tail", 1.0, "", tail, abs(tail - closed) / closed, "tanh-sinh quadrature"))
        chord = 2 * mpf(SPHERE_R0) * mp.sin(mpf(SPHERE_THETA) / 2)
        rows.append(("sphere_chord", SPHERE_R0, SPHERE_THETA, dipole.R_d(chord, p), 0, "closed form at the chord"))
    return rows


def curvature_rows(eta: float) -> list[tuple]:
    rows = []
    # coef_row takes (sigma_s', sigma_a): 9/10 is the double 0.9 (9.0 / (9.0 + 1.0) == 0.9)
    assert 9.0 / (9.0 + 1.0) == ALBEDO
    for rho in (0.0, 1.0):
        row = curvature.coef_row(("edge", (9.0, 1.0, eta), rho))
        for q, key in (("curv_A", "A"), ("curv_B", "B"), ("curv_a", "a_ratio"), ("curv_b", "b_ratio")):
            rows.append((q, rho, "", mpf(row[key]), mpf(row["rel_err_est"]), "t-integral quadrature"))
    return rows


def sphere_rows(eta: float) -> list[tuple]:
    dps, n = sphere.plan(ALBEDO, eta, SPHERE_R0, [SPHERE_THETA])
    v1, tail, used, method = sphere.sphere_values(ALBEDO, eta, SPHERE_R0, [SPHERE_THETA], dps, n, check=True)
    v2, _, _, _ = sphere.sphere_values(ALBEDO, eta, SPHERE_R0, [SPHERE_THETA], dps + 15, n)
    with mp.workdps(dps + 15):
        err = (tail + abs(v1[0] - v2[0])) / abs(v2[0])
        if err > mpf("1e-20"):
            raise SystemExit(f"eta {eta}: sphere series rel_err_est {err}")
        rows = [("sphere_series", SPHERE_R0, SPHERE_THETA, v2[0], err, f"{method}, {used} terms, dps {dps}")]
    with mp.workdps(DPS):
        p = dipole.params(mpf(ALBEDO), mpf(eta))
        mu, z_b = p["mu"], p["z_b"]
        R0 = mpf(SPHERE_R0)
        rs = R0 - min(p["z_r"], R0)
        R = R0 + z_b

        def free(t):
            x = mp.cos(t)
            d = mp.sqrt(R0**2 + rs**2 - 2 * R0 * rs * x)
            return (mu * d + 1) * mp.exp(-mu * d) / d**3 * (R0 - rs * x) * mp.sin(t)

        half = mpf(1) / 2
        x1, x0, xR = mu * rs, mu * R0, mu * R
        c0 = (mp.besseli(half, x1) * mp.besselk(half, xR) / (mp.besseli(half, xR) * mp.sqrt(rs * R0))
              * (mu * mp.besseli(half + 1, x0)))
        total = 2 * mp.pi * R0**2 * p["albedo"] / (4 * mp.pi) * (mp.quad(free, [0, mpf(1) / 10, 1, mp.pi]) + 2 * c0)
        closed = p["albedo"] * mp.sinh(mu * rs) / (mu * rs) * (
            (mu * R0 + 1) * mp.exp(-mu * R0) + mp.exp(-mu * R) * (mu * R0 * mp.cosh(mu * R0) - mp.sinh(mu * R0))
            / mp.sinh(mu * R))
        err = abs(total - closed) / closed
        if err > mpf("1e-25"):
            raise SystemExit(f"eta {eta}: sphere total {total} != eq. (33) {closed}")
        rows.append(("sphere_total", SPHERE_R0, "", total, err, "quadrature of the free term + 2 c_0"))
    return rows


def cylinder_rows(eta: float) -> list[tuple]:
    rows = []
    with mp.workdps(CYL_DPS):
        alb, mu, z_r, z_b = cylinder.params(repr(ALBEDO), repr(eta))
        R0 = mpf(CYL_R0)
        coef = cylinder.Coefficients(mu, R0 - z_r, R0, R0 + z_b)
        rho, phi = mpf(CYL_RHO), mpf(CYL_PHI)
        for label, theta, z in ((f"theta={CYL_THETA!r} z=0", mpf(CYL_THETA), mpf(0)),
                                (f"rho={CYL_RHO!r} phi={CYL_PHI!r}", rho * mp.cos(phi) / R0, rho * mp.sin(phi))):
            val, err = cylinder.reflectance(alb, mu, z_r, z_b, R0, theta, z, coef)
            rows.append(("cylinder", CYL_R0, label, val, abs(err / val), "mp.quad gauss-legendre in q"))
    return rows


def main() -> int:
    t0 = time.time()
    rows = []
    for eta in ETAS:
        for part in (dipole_rows, curvature_rows, sphere_rows, cylinder_rows):
            for quantity, x, y, value, err, method in part(eta):
                rows.append({"albedo_prime": repr(ALBEDO), "eta": repr(eta), "quantity": quantity, "x": repr(x) if
                             x != "" else "", "y": y if isinstance(y, str) else repr(y), "value": _fmt(value),
                             "rel_err_est": mp.nstr(err, 2, min_fixed=0, max_fixed=0), "method": method})
            print(f"eta {eta}: {part.__name__} done ({time.time() - t0:.0f} s)", flush=True)
    write_reference_csv(
        OUT, ["albedo_prime", "eta", "quantity", "x", "y", "value", "rel_err_est", "method"], rows,
        script=Path(__file__),
        depends=[HERE / "precompute_dipole_references.py", HERE / "precompute_curvature_references.py",
                 HERE / "precompute_references.py", HERE / "precompute_cylinder_references.py"],
        title="Every material kernel at one point for alpha' = 0.9 and eta = 1.0, 1.3, 1.7, 2.5 (optical units, "
              "Jensen normalisation, R/sigma_t'^2)",
        params={
            "function": "dipole_R_d(r=x), dipole_total, dipole_tail(r=x), curv_A/B/a/b(rho=x) (physics.md e.3),"
                        " sphere_series(R0=x, theta=y), sphere_total(R0=x), sphere_chord(R0=x, theta=y),"
                        " cylinder(R0=x, at y)",
            "method": "module docstring of the generator; rel_err_est per row",
            "dps": f"{DPS} (curvature {curvature.DPS}+10, sphere series by plan, cylinder {CYL_DPS})",
            "runtime": f"{time.time() - t0:.0f} s",
        })
    print(f"wrote {OUT} ({len(rows)} rows, {time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
