"""Error of the dipole and the first-order curved kernel against the exact sphere and cylinder, per radius.

Skin-like case of docs/physics.md §11 (sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3).
Relative errors (model - exact)/exact
at geodesic distances s = 1, 2, 5, 10 mm; "dipole" is Jensen's chord dipole on the curved shape, "curved" the
first-order k1/k2 kernel with its default positivity policy. Prints a markdown table (for README) and, with
--json, the raw numbers.

    python tools/studies/accuracy_table.py [--json]
"""
from __future__ import annotations

import json
import sys

import numpy as np

from meshshade.materials import Material
from meshshade.profiles import Shape, reflectance_profile

S = np.array([1.0, 2.0, 5.0, 10.0])
RADII = (10.0, 20.0, 50.0, 100.0, 1000.0)
CASES = (("sphere", 0.0), ("cylinder", 0.0), ("cylinder", 90.0))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    m = Material(1.0, 0.01, 1.3, name="skin-like")
    rows = []
    for kind, az in CASES:
        for R in RADII:
            shape = Shape.make(kind, R)
            ex = reflectance_profile(m, S, model="exact", shape=shape, azimuth_deg=az, rtol=1e-12)[0]
            for model in ("dipole", "curved"):
                v = reflectance_profile(m, S, model=model, shape=shape, azimuth_deg=az)[0]
                rows.append({"shape": kind, "azimuth_deg": az, "radius_mm": R, "model": model,
                             "rel_error": ((v - ex) / ex).tolist()})
    if "--json" in argv:
        print(json.dumps({"s_mm": S.tolist(), "rows": rows}, indent=1))
        return rows
    head = "| shape | R0 (mm) | model | " + " | ".join(f"s = {s:g} mm" for s in S) + " |"
    print(head)
    print("|" + "---|" * (3 + S.size))
    for r in rows:
        where = r["shape"] + ("" if r["shape"] == "sphere" else (" around" if r["azimuth_deg"] == 0 else " along"))
        print(f"| {where} | {r['radius_mm']:g} | {r['model']} | " +
              " | ".join(f"{e:+.2e}" for e in r["rel_error"]) + " |")
    return rows


if __name__ == "__main__":
    main()
