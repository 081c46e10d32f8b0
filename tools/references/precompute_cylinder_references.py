"""Reference values of the exact infinite-cylinder reflectance, computed with mpmath (offline).

Writes ``tests/data/cylinder_reference.csv`` (or the path given as the first argument), with a ``#``
provenance header. Independent of ``meshshade.kernels.cylinder``: Bessel functions come from
``mp.besseli`` for every order and ``mp.besselk`` for orders 0 and 1 (higher K orders by the upward
recurrence ``K_{n+1} = K_{n-1} + (2n/x) K_n``, which is stable and exact to working precision); the q-integral is
``mp.quad`` (Gauss-Legendre, with its error estimate) over fixed sub-intervals. No ratios, no scaling, no
double precision.

    R(theta, z) = alpha'/(4 pi) [ g(d) (z_r + 2 r' sin^2(theta/2))
                  + (2/pi) int_0^qmax dq cos(q z) sum_n eps_n cos(n theta)
                    I_n(k r') K_n(k R) / I_n(k R) * k I_n'(k R0) ],   k = sqrt(mu^2 + q^2),

with r' = R0 - z_r, R = R0 + z_b, I_n'(x) = I_{n+1}(x) + (n/x) I_n(x), all in optical units (sigma_t' = 1).
Run: ``python tools/references/precompute_cylinder_references.py`` (about 7 minutes on one core).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import mpmath as mp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _refheader import write_reference_csv  # noqa: E402  (tools/ is not a package)

DPS = 34
TAIL = mp.mpf(10) ** -24      # n-series: stop when the last term and the geometric tail bound are below this (relative)
QTAIL = 56                    # q-range: k z_v up to QTAIL (exp(-56) = 5e-25)

# (albedo_prime, eta, R0_opt, [(theta, z), ...])
CASES = [
    ("1/1.01", "1.3", "1.5", [("0", "0"), ("0.5", "0"), ("0", "1"), ("1", "2.5"), ("pi", "0"), ("0.2", "6")]),
    ("1/1.01", "1.3", "5", [("0", "0"), ("0.2", "0"), ("0", "1.5"), ("0.4", "1"), ("pi", "0"), ("0", "8")]),
    ("0.9", "1.0", "0.6", [("0", "0"), ("1", "0"), ("pi", "0"), ("0", "1"), ("2", "0.5")]),
    ("0.9", "1.0", "3", [("0", "0"), ("0.3", "0"), ("0", "0.5"), ("0.7", "2"), ("pi", "3")]),
]


def _number(text):
    """'1/1.01' -> mpf(1)/mpf('1.01'); '0.9' -> mpf('0.9') (exact decimal strings, no float round trip)."""
    num, _, den = text.partition("/")
    return mp.mpf(num) / mp.mpf(den) if den else mp.mpf(num)


def params(alb, eta):
    alb, eta = _number(alb), _number(eta)
    F_dr = -mp.mpf("1.440") / eta**2 + mp.mpf("0.710") / eta + mp.mpf("0.668") + mp.mpf("0.0636") * eta
    A = (1 + F_dr) / (1 - F_dr)
    D = mp.mpf(1) / 3
    mu = mp.sqrt(3 * (1 - alb))
    z_r = mp.mpf(1)
    z_b = 2 * A * D
    return alb, mu, z_r, z_b


def g(d, mu):
    return (mu * d + 1) * mp.exp(-mu * d) / d**3


class Coefficients:
    """G_n(q) for one cylinder, cached by q (mp.quad reuses its nodes for every exit point)."""

    def __init__(self, mu, r_src, R0, R):
        self.mu, self.r_src, self.R0, self.R = mu, r_src, R0, R
        self.cache = {}

    def __call__(self, q):
        key = mp.nstr(q, DPS)
        if key in self.cache:
            return self.cache[key]
        k = mp.sqrt(self.mu**2 + q**2)
        x1, x0, xR = k * abs(self.r_src), k * self.R0, k * self.R
        K_prev, K_cur = mp.besselk(0, xR), mp.besselk(1, xR)    # K_0, K_1
        I0_next = mp.besseli(0, x0)
        terms = []
        s_abs = mp.mpf(0)
        n = 0
        prev = None
        while True:
            I0_n, I0_next = I0_next, mp.besseli(n + 1, x0)
            K_n = K_prev
            G = mp.besseli(n, x1) * K_n / mp.besseli(n, xR) * k * (I0_next + n / x0 * I0_n)
            terms.append(G)
            s_abs += abs(G) * (1 if n == 0 else 2)
            if n >= 3 and prev is not None and prev != 0:
                rho = abs(G / prev)
                if rho < 1 and abs(G) * rho / (1 - rho) < TAIL * s_abs:
                    break
            if G == 0 and n > 0:
                break
            prev = G
            K_prev, K_cur = K_cur, K_prev + 2 * (n + 1) / xR * K_cur
            n += 1
        self.cache[key] = terms
        return terms


def reflectance(alb, mu, z_r, z_b, R0, theta, z, coef):
    r_src = R0 - z_r
    R = R0 + z_b
    sin2 = mp.sin(theta / 2) ** 2
    d = mp.sqrt(z_r**2 + 4 * R0 * r_src * sin2 + z**2)
    free = g(d, mu) * (z_r + 2 * r_src * sin2)
    th = theta if r_src >= 0 else theta - mp.pi

    def integrand(q):
        terms = coef(q)
        s = terms[0] + 2 * mp.fsum(t * mp.cos(n * th) for n, t in enumerate(terms) if n > 0)
        return mp.cos(q * z) * s

    z_v = z_r + 2 * z_b
    q_max = QTAIL / z_v
    width = min(mp.mpf(1), 4 / (z + 1))
    edges = [mp.mpf(0)]
    e = mu / 2
    while e < min(width, q_max):       # geometric grading towards the branch point q = i mu
        edges.append(e)
        e *= 2
    e = edges[-1] + width
    while e < q_max:
        edges.append(e)
        e += width
    edges.append(q_max)
    val, err = mp.quad(integrand, edges, method="gauss-legendre", error=True)
    reg = 2 / mp.pi * val
    return alb / (4 * mp.pi) * (free + reg), alb / (4 * mp.pi) * 2 / mp.pi * err


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0]) if argv else Path(__file__).resolve().parents[2] / "tests" / "data" / "cylinder_reference.csv"
    mp.mp.dps = DPS
    rows = []
    t0 = time.time()
    for alb_s, eta_s, R0_s, pts in CASES:
        alb, mu, z_r, z_b = params(alb_s, eta_s)
        R0 = mp.mpf(R0_s)
        coef = Coefficients(mu, R0 - z_r, R0, R0 + z_b)
        for th_s, z_s in pts:
            theta = mp.pi if th_s == "pi" else mp.mpf(th_s)
            z = mp.mpf(z_s)
            val, err = reflectance(alb, mu, z_r, z_b, R0, theta, z, coef)
            rows.append((alb, eta_s, R0, theta, z, val, err))
            print(f"alb={alb_s} eta={eta_s} R0={R0_s} theta={th_s} z={z_s}: {mp.nstr(val, 25)} "
                  f"(quad err {mp.nstr(err, 3)}, {time.time() - t0:.0f} s)", flush=True)
    write_reference_csv(
        out, ["albedo_prime", "eta", "R0_opt", "theta", "z", "R", "quad_error"],
        [(mp.nstr(alb, 20), eta_s, mp.nstr(R0, 20), mp.nstr(theta, 20), mp.nstr(z, 20), mp.nstr(val, 25),
          mp.nstr(err, 3)) for alb, eta_s, R0, theta, z, val, err in rows],
        script=Path(__file__),
        title="Exact infinite-cylinder diffusion reflectance R/sigma_t'^2 (Jensen normalisation, includes alpha'),"
              " optical units (sigma_t' = 1, z_r = 1, D = 1/3); meshshade.kernels.cylinder.cylinder_exact_profile",
        params={
            "function": "alpha'(-D dPsi/dr) at r = R0, Psi = 0 on r = R0 + z_b, source at r' = R0 - z_r"
                        " (physics.md c, d)",
            "method": f"mp.besseli all orders, mp.besselk orders 0,1 + upward recurrence; mp.quad gauss-legendre in"
                      f" q up to q z_v = {QTAIL}; n-series tail < 1e-24 relative",
            "columns": "albedo_prime, eta, R0_opt, theta, z, R (25 digits), quad_error (mp.quad's error estimate)",
            "dps": f"{DPS}",
            "runtime": f"{time.time() - t0:.0f} s",
        })
    print(f"wrote {out} ({len(rows)} rows, {time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
