#!/usr/bin/env python
"""Offline mpmath references for the unpolarised Fresnel reflectance: writes tests/data/fresnel_reference.csv.

This is an *independent* implementation (it imports nothing from meshshade) and uses a different form of the
Fresnel equations than ``meshshade/kernels/fresnel.py``: Fresnel's sine and tangent laws in terms of the angles
(Born & Wolf, *Principles of Optics*, section 1.5.2),

    theta_t = asin(eta_i sin(theta_i) / eta_t)
    R_s = (sin(theta_i - theta_t) / sin(theta_i + theta_t))**2
    R_p = (tan(theta_i - theta_t) / tan(theta_i + theta_t))**2
    F   = (R_s + R_p) / 2,

evaluated in mpmath at 50 digits. At normal incidence (0/0 in the angle form) it writes the closed form
((eta_i - eta_t)/(eta_i + eta_t))**2; beyond the critical angle it writes 1 (total internal reflection).
Inputs ``cos_i``, ``eta_i``, ``eta_t`` are doubles (stored as ``repr``) converted to mpmath exactly, so the
reference is the exact function value at the double inputs.

Usage:  python tools/references/precompute_fresnel_references.py [--out tests/data/fresnel_reference.csv]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mpmath
from mpmath import mp, mpf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _refheader import write_reference_csv  # noqa: E402  (tools/ is not a package)

DPS = 50
ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = ROOT / "tests" / "data" / "fresnel_reference.csv"

# (eta_i, eta_t): nearly index-matched, air into tissue/glass/diamond, glass/water out into air (TIR rows)
PAIRS = [(1.0, 1.0001), (1.0, 1.3), (1.0, 1.5), (1.0, 2.4), (1.5, 1.0), (1.33, 1.0)]
COS_I = [1.0, 0.999, 0.99, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1, 0.05, 0.01, 0.001]


def reference(cos_i: float, eta_i: float, eta_t: float) -> mpf:
    c, n1, n2 = mpf(cos_i), mpf(eta_i), mpf(eta_t)
    if c == 1:
        return ((n1 - n2) / (n1 + n2)) ** 2
    theta_i = mpmath.acos(c)
    s_t = n1 * mpmath.sin(theta_i) / n2
    if s_t >= 1:
        return mpf(1)
    theta_t = mpmath.asin(s_t)
    R_s = (mpmath.sin(theta_i - theta_t) / mpmath.sin(theta_i + theta_t)) ** 2
    R_p = (mpmath.tan(theta_i - theta_t) / mpmath.tan(theta_i + theta_t)) ** 2
    return (R_s + R_p) / 2


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    rows = []
    with mp.workdps(DPS):
        for eta_i, eta_t in PAIRS:
            cos_list = list(COS_I)
            if eta_t > eta_i:  # Brewster angle, where R_p = 0: cos = eta_i / sqrt(eta_i^2 + eta_t^2)
                cos_list.append(float(mpf(eta_i) / mpmath.sqrt(mpf(eta_i) ** 2 + mpf(eta_t) ** 2)))
            for c in cos_list:
                rows.append((repr(c), repr(eta_i), repr(eta_t), mpmath.nstr(reference(c, eta_i, eta_t), 30)))
    write_reference_csv(
        args.out, ["cos_i", "eta_i", "eta_t", "F"], rows, script=Path(__file__),
        title="Unpolarised Fresnel reflectance references (meshshade.kernels.fresnel.fresnel_reflectance)",
        params={
            "function": "F = (R_s + R_p)/2 by Fresnel's sine/tangent laws in the angles (Born & Wolf 1.5.2);"
                        " normal incidence ((n1-n2)/(n1+n2))^2; total internal reflection 1",
            "inputs": "cos_i, eta_i, eta_t are exact doubles (repr) converted exactly to mpmath",
            "parameters": f"pairs {PAIRS}; cos_i {COS_I} plus the Brewster cosine where eta_t > eta_i",
            "dps": f"{DPS} (mp.workdps); values printed to 30 significant digits",
        })
    print(f"wrote {len(rows)} rows to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
