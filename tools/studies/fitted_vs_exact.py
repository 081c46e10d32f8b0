"""The fitted curvature model (docs/physics.md §14) against the exact diffusion solutions on the sphere and the
cylinder (§5, §6): max and mean |R_fit / R_exact - 1| over distances from 2 transport lengths to
min(0.8 pi R, 6 / sigma_tr), for radii R of 5-100 transport lengths, with the first-order kernel's for comparison.
Both sides are diffusion with the point source at z_r: the fitted factor on the planar dipole
(``fitted_curvature_factor``), the first-order kernel's ``curvature_profile``; the cylinder around its axis (phi = 0)
and along it (phi = 90 deg). Prints one JSON line per (medium, radius).

    python tools/studies/fitted_vs_exact.py
"""
from __future__ import annotations

import json

import numpy as np

from meshshade.kernels.curvature import curvature_profile
from meshshade.kernels.cylinder import cylinder_exact_profile_geodesic
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.fitted_curvature import fitted_curvature_factor
from meshshade.kernels.sphere import sphere_series_profile

MEDIA = ((0.99, 1.3), (0.99, 1.0), (0.95, 1.5), (0.9, 1.3))
RADII = (5.0, 10.0, 20.0, 50.0, 100.0)


def _err(model, exact):
    m = exact > 1e-300
    e = np.abs(model[m] / exact[m] - 1.0)
    return round(float(e.max()), 4), round(float(e.mean()), 4)


def main() -> int:
    for al, eta in MEDIA:
        mu = np.sqrt(3.0 * (1.0 - al))
        par = dict(albedo_prime=al, eta=eta)
        for R in RADII:
            r = np.linspace(2.0, min(0.8 * np.pi * R, 6.0 / mu), 25)
            Rd = dipole_profile(r, **par)
            row = {"albedo_prime": al, "eta": eta, "R_transport_lengths": R, "R_diffusion_lengths": round(R * mu, 2)}
            ex = sphere_series_profile(r / R, R0_opt=R, **par)
            row["sphere"] = {"fitted": _err(Rd * fitted_curvature_factor(r, 0.0, 1 / R, 1 / R, **par), ex),
                             "first": _err(curvature_profile(r, 0.0, k1_opt=1 / R, k2_opt=1 / R, **par), ex)}
            for name, phi in (("cylinder_around", 0.0), ("cylinder_along", np.pi / 2)):
                ex = cylinder_exact_profile_geodesic(r, phi, R0_opt=R, rtol=1e-8, **par)
                row[name] = {"fitted": _err(Rd * fitted_curvature_factor(r, phi, 1 / R, 0.0, **par), ex),
                             "first": _err(curvature_profile(r, phi, k1_opt=1 / R, k2_opt=0.0, **par), ex)}
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
