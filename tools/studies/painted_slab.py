"""A uniformly painted slab (issue 49's target, docs/physics.md §17): how far its reflectance in the middle is from
the painted colour C, and how much of that a flat slab's finite thickness explains.

For each C: the albedo of eq. (106) at skin1's mean free path; the diffusion part of the half-space's total under
normal incidence (the Robin Green's function of eq. (93) summed over eq. (97)'s sources) against the same for a
laterally infinite slab of thickness ``--thickness`` with the Robin condition on both faces (1-D closed form:
G(z, z') = u1(z<) u2(z>) / (D W), u1 = sinh(k z) + k l cosh(k z), u2 = the same from the far face, l = 2 A D,
W their Wronskian), printed as the slab's deficit in % of C. With ``--bake``: the bake of a box of 100 x 100 x
thickness mm (box(..., 25), moved by SHIFT off the lattice's planes) painted C under a sun at normal incidence, the mean exitance over the central
20 x 20 mm of its lit face over the entering irradiance 1 - F(0), in % off C (``--h0`` the lattice spacing, default
the material's). JSON lines on stdout.

    python tools/studies/painted_slab.py [--colours 0.05,0.2,0.5,0.8,0.95] [--thickness 20] [--bake] [--h0 MM]
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np
from numpy.polynomial.laguerre import laggauss

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import box
from meshshade.kernels.fresnel import fresnel_reflectance
from meshshade.kernels.painted_reflectance import albedo_for_reflectance
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.painted import PaintedMaterial
from meshshade.transport import bake
from meshshade.transport.options import BakeOptions
from meshshade.volume.long_range import SOURCE_POINTS
from meshshade.volume.options import VolumeOptions


#: the box's offset from the origin, mm (module docstring)
SHIFT = (0.37, 0.21, 0.37)


def diffusion_part(albedo, sigma_t, A, thickness=None):
    """The exitance through the lit face per unit entering power of eq. (97)'s sources in a half-space
    (``thickness`` None) or a slab, Robin condition phi = 2AD dphi/dn outside on every face (1-D: laterally
    uniform light)."""
    x, w = laggauss(SOURCE_POINTS)
    D = (2.0 - albedo) / (3.0 * sigma_t)
    k = np.sqrt((1.0 - albedo) * sigma_t / D)
    l = 2.0 * A * D
    z0, q = x / sigma_t, albedo * w
    if thickness is None:
        return float(np.sum(q * np.exp(-k * z0)) / (1.0 + l * k))
    L = float(thickness)
    u1 = lambda z: np.sinh(k * z) + k * l * np.cosh(k * z)                        # noqa: E731
    u1p = lambda z: k * np.cosh(k * z) + k * k * l * np.sinh(k * z)               # noqa: E731
    u2 = lambda z: np.sinh(k * (L - z)) + k * l * np.cosh(k * (L - z))            # noqa: E731
    u2p = lambda z: -k * np.cosh(k * (L - z)) - k * k * l * np.sinh(k * (L - z))  # noqa: E731
    W = u1p(0.0) * u2(0.0) - u1(0.0) * u2p(0.0)
    return float(np.sum(q * u1(0.0) * u2(z0)) / (D * W) / (2.0 * A))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--colours", default="0.05,0.2,0.5,0.8,0.95")
    ap.add_argument("--thickness", type=float, default=20.0)
    ap.add_argument("--bake", action="store_true")
    ap.add_argument("--h0", type=float, default=None)
    args = ap.parse_args(argv)
    base = Material.preset("skin1")
    A = float(base.medium.A[0])
    mesh = None
    if args.bake:
        V, F = box((100.0, 100.0, args.thickness), 25)
        # off the lattice's planes: a box centred at the origin has its faces on them, which the bake gets wrong
        # (tests/volume/test_grid_alignment.py)
        mesh = Mesh.from_arrays(V + np.array(SHIFT), F)
        top = 0.5 * args.thickness - 1e-6
        mid = (np.abs(V[:, 0]) <= 10) & (np.abs(V[:, 1]) <= 10) & (V[:, 2] > top)
        T0 = 1.0 - float(fresnel_reflectance(1.0, 1.0, base.eta))
    for C in (float(c) for c in args.colours.split(",")):
        a = albedo_for_reflectance(np.full(3, C), base.eta, base.g)
        row = {"C": C, "albedo_prime": a.tolist(),
               "slab_1d_deficit_pct": [round(100.0 * (diffusion_part(a[c], base.sigma_t_prime[c], A, args.thickness)
                                                      - diffusion_part(a[c], base.sigma_t_prime[c], A)) / C, 3)
                                       for c in range(3)]}
        if mesh is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                painted = PaintedMaterial(base, colour=np.full((mesh.n_vertices, 3), C))
                r = bake(mesh, painted, DirectionalLight([0, 0, -1.0], 1.0),
                         BakeOptions(volume=VolumeOptions(h0=args.h0)))
            got = r.radiance[mid].mean(axis=0) / T0
            row.update({"bake_off_pct": np.round(100.0 * (got / C - 1.0), 3).tolist(),
                        "h0_mm": r.stats["volume_resolution_mm"]})
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
