"""``meshshade profile``: its one-line help and its arguments (what it does: :mod:`meshshade.cli.profile`)."""
from __future__ import annotations

import argparse

from meshshade.cli.arguments.common import add_deprecated_alias, add_material_args, integer, number
from meshshade.names import PROFILE_MC_PHOTONS as MC_PHOTONS, PROFILE_SHAPES as SHAPES

HELP = "reflectance vs geodesic distance on a plane, sphere, cylinder, saddle, cavity, bore or curvature pair"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_material_args(p)
    p.add_argument("--shape", default="plane", choices=[s for s in SHAPES if s != "point"],
                   help="surface the profile lives on (default plane; cavity: the medium outside a ball, bore: "
                        "outside a cylinder); --k1/--k2 give any curvature pair")
    p.add_argument("--radius", metavar="MM", help="radius of sphere/cylinder/saddle/cavity/bore [mm]; several: 5,10,50")
    p.add_argument("--k1", type=number, help="first principal curvature at the entry point [1/mm] (with --k2)")
    p.add_argument("--k2", type=number, help="second principal curvature [1/mm]; k > 0 is convex")
    p.add_argument("--azimuth", default="0", metavar="DEG",
                   help="exit direction from the first principal direction [deg]; several: 0,45,90")
    p.add_argument("--models", default="dipole,exact",
                   help="comma list among dipole,exact,curved,fitted,mc (default dipole,exact); fitted: the "
                        "curvature model fitted to Monte Carlo; mc: Monte Carlo on the exact plane, sphere, "
                        "cylinder, cavity or bore, with error bars")
    p.add_argument("--source-model", default="point", metavar="SM[,SM]",
                   help="what enters the medium: point (each model's point source at z_r; default), beam (the "
                        "near-field model: single scattering plus the fitted beam sources, composed with the model's "
                        "geometry, docs/physics.md §13), or point,beam for both curves (named model+beam)")
    add_deprecated_alias(p, "--near-field", "--source-model", metavar="SM[,SM]")
    p.add_argument("--distances", metavar="LIST", help="geodesic distances [mm], e.g. 0.1,0.5,1")
    p.add_argument("--max-distance", type=number, default=None, metavar="MM",
                   help="with --samples: evenly spaced distances 0..MM (default 20 mm)")
    p.add_argument("--samples", type=integer(2), default=41, metavar="N", help="number of distances (default 41)")
    p.add_argument("--rtol", type=number, default=1e-10, help="relative tolerance of the exact series")
    p.add_argument("--photons", type=integer(16), default=MC_PHOTONS, metavar="N",
                   help=f"Monte Carlo photons per channel for --models mc (default {MC_PHOTONS:.0e})")
    p.add_argument("--seed", type=integer(0), default=0, help="Monte Carlo seed (default 0)")
    p.add_argument("--csv", metavar="FILE", help="write model,channel,distance_mm,reflectance_per_mm2 rows "
                                                 "(and stderr_per_mm2 with mc)")
    p.add_argument("--plot", metavar="FILE.png", help="plot log reflectance vs geodesic distance")
