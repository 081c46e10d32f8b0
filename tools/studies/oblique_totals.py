"""Oblique light on the half-space: the total diffuse reflectance of the near-field model against exact transport.

For five media and the incidence angles 45, 70 and 85 degrees, the exact half-space Monte Carlo entering at that
angle (meshshade.montecarlo.shapes, ``--photons`` per run, seeds the incidence table never used) against

* eq. (86), the bake's incidence scale: the near-field total at normal incidence times ``incidence_gain``;
* eq. (81), the depth projection of the beam's sources alone;
* the normal-incidence model (the near-field total, no angle at all).

Prints one JSON line per (medium, angle) and a markdown table of the errors in % (docs/validation.md "Oblique
light").

    python tools/studies/oblique_totals.py [--photons 600000] [--seed 41]
"""
from __future__ import annotations

import argparse
import json
import math
import sys

from meshshade.kernels.near_field import incidence_gain, near_field_total
from meshshade.materials import Material
from meshshade.montecarlo.shapes import shape_mc_profile

MEDIA = [("alpha' = 0.99, eta 1.3, g 0", Material(1.0, 0.01, 1.3, 0.0)),
         ("alpha' = 0.91, eta 1.3, g 0", Material(1.0, 0.1, 1.3, 0.0)),
         ("alpha' = 0.91, eta 1.0, g 0.8", Material(1.0, 0.1, 1.0, 0.8)),
         ("alpha' = 0.68, eta 1.3, g 0", Material(1.0, 0.47, 1.3, 0.0)),
         ("alpha' = 0.99, eta 1.3, g 0.8", Material(1.0, 0.01, 1.3, 0.8))]
ANGLES = (45.0, 70.0, 85.0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photons", type=int, default=600_000)
    ap.add_argument("--seed", type=int, default=41)
    args = ap.parse_args(argv)
    table = []
    for name, m in MEDIA:
        a, eta, g = float(m.albedo_prime[0]), m.eta, m.g
        t0 = near_field_total(albedo_prime=a, eta=eta, g=g)
        cells = []
        for ang in ANGLES:
            mc = shape_mc_profile(m, [1.0], shape="plane", photons=args.photons, seed=args.seed, incidence_deg=ang)
            T, e = float(mc.total[0]), float(mc.total_stderr[0])
            cos_t = math.sqrt(1.0 - (math.sin(math.radians(ang)) / eta) ** 2)
            eq86 = t0 * incidence_gain(albedo_prime=a, eta=eta, g=g, cos_t=cos_t) / T - 1.0
            eq81 = near_field_total(albedo_prime=a, eta=eta, g=g, cos_t=cos_t) / T - 1.0
            normal = t0 / T - 1.0
            print(json.dumps({"medium": name, "incidence_deg": ang, "mc_total": round(T, 5),
                              "mc_rel_stderr": round(e / T, 5), "eq86": round(eq86, 4), "eq81": round(eq81, 4),
                              "normal": round(normal, 4)}), flush=True)
            cells.append(f"{100 * eq86:+.1f} / {100 * eq81:+.1f} / {100 * normal:+.0f}")
        table.append(f"| {name} | " + " | ".join(cells) + " |")
    print("\n| medium | " + " | ".join(f"{a:g}°" for a in ANGLES) + " |")
    print("|---|" + "---|" * len(ANGLES))
    print("\n".join(table))
    return 0


if __name__ == "__main__":
    sys.exit(main())
