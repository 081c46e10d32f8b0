"""Reflectance profiles R(s) in physical units for a material on a simple shape (the `meshshade profile` job).

Converts once between millimetres and the kernels' optical units: ``r_opt = s * sigma_t'``,
``R0_opt = R0 * sigma_t'``, ``k_opt = k / sigma_t'`` and back ``R = R_opt * sigma_t'^2`` [mm^-2].

Shapes and what each model means on them (distances are geodesic, in mm; azimuth phi is measured from the
first principal direction, k1 >= k2):

=========  ==================  =====================================  =========================  ===========
shape      (k1, k2)            dipole                                 exact                      curved
=========  ==================  =====================================  =========================  ===========
plane      (0, 0)              R_d(s)                                 R_d(s) (exact for a plane)  R_d(s)
sphere     (1/R, 1/R)          R_d(chord), chord = 2R sin(s/2R)       docs/physics.md eq. (23)   k1/k2 kernel
cylinder   (1/R, 0)            R_d(chord of the helix)                exact infinite cylinder    k1/k2 kernel
saddle     (1/R, -1/R)         R_d(s)                                 (none)                     k1/k2 kernel
point      (--k1, --k2)        R_d(s)                                 (none)                     k1/k2 kernel
=========  ==================  =====================================  =========================  ===========
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from meshshade.errors import MeshshadeError
from meshshade.kernels.curvature import curvature_profile
from meshshade.kernels.cylinder import cylinder_exact_profile
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.materials import CHANNELS, Material
from meshshade.montecarlo import mc_profile

SHAPES = ("plane", "sphere", "cylinder", "saddle", "point")
MODELS = ("dipole", "exact", "curved", "mc")


@dataclass(frozen=True)
class Shape:
    """A surface point with principal curvatures (1/mm): the geometry a profile is evaluated on."""

    kind: str
    radius_mm: float | None = None
    k1: float = 0.0
    k2: float = 0.0

    @classmethod
    def make(cls, kind: str, radius_mm: float | None = None, k1: float | None = None, k2: float | None = None):
        kind = kind.lower()
        if kind not in SHAPES:
            raise MeshshadeError(f"unknown shape {kind!r}; choose one of {', '.join(SHAPES)}")
        if kind == "plane":
            return cls("plane")
        if kind == "point":
            if k1 is None or k2 is None:
                raise MeshshadeError("a curvature point needs both --k1 and --k2 (1/mm)")
            if not (np.isfinite(k1) and np.isfinite(k2)):
                raise MeshshadeError(f"curvatures must be finite, got k1={k1}, k2={k2}")
            return cls("point", None, float(max(k1, k2)), float(min(k1, k2)))
        if radius_mm is None:
            raise MeshshadeError(f"--shape {kind} needs --radius MM")
        if not np.isfinite(radius_mm) or radius_mm <= 0:
            raise MeshshadeError(f"radius must be finite and > 0 mm, got {radius_mm}")
        R = float(radius_mm)
        k = {"sphere": (1 / R, 1 / R), "cylinder": (1 / R, 0.0), "saddle": (1 / R, -1 / R)}[kind]
        return cls(kind, R, *k)


def _check_distances(distances_mm) -> np.ndarray:
    s = np.asarray(distances_mm, dtype=np.float64).reshape(-1)
    if s.size == 0 or not np.all(np.isfinite(s)) or np.any(s < 0):
        raise MeshshadeError("distances must be finite and >= 0 mm")
    return s


def reflectance_profile(material: Material, distances_mm, *, model: str = "dipole", shape: Shape | None = None,
                        azimuth_deg: float = 0.0, rtol: float = 1e-10) -> np.ndarray:
    """Diffuse reflectance per unit power entering the medium [mm^-2], shape (3, n): channels r, g, b.

    Parameters
    ----------
    material : Material
    distances_mm : (n,) float, >= 0 — geodesic distance from the entry point [mm]
    model : "dipole" | "exact" | "curved" | "mc" (see the module table)
    shape : Shape (default: plane)
    azimuth_deg : angle of the exit direction from the first principal direction [degrees]
    rtol : relative tolerance of the exact series
    """
    shape = shape or Shape("plane")
    s = _check_distances(distances_mm)
    model = model.lower()
    if model not in MODELS:
        raise MeshshadeError(f"unknown model {model!r}; choose among {', '.join(MODELS)}")
    if model == "mc":
        return mc_profile(material, s, shape=shape)
    phi = np.deg2rad(float(azimuth_deg))
    out = np.empty((3, s.size))
    done: dict = {}
    for c in range(3):
        key = (material.albedo_prime[c], material.sigma_t_prime[c])
        if key in done:  # channels with equal parameters computed once
            out[c] = out[done[key]]
            continue
        done[key] = c
        st = float(material.sigma_t_prime[c])
        par = {"albedo_prime": float(material.albedo_prime[c]), "eta": material.eta}
        out[c] = _profile_opt(s * st, model, shape, phi, st, par, rtol) * st * st
    return out


def _profile_opt(r, model, shape, phi, st, par, rtol):
    if shape.kind == "plane" or (model == "dipole" and shape.kind in ("saddle", "point")):
        return dipole_profile(r, **par)
    if model == "curved":
        return curvature_profile(r, phi, k1_opt=shape.k1 / st, k2_opt=shape.k2 / st, **par)
    R0 = shape.radius_mm * st
    if shape.kind == "sphere":
        theta = r / R0
        if np.any(theta > np.pi):
            raise MeshshadeError(f"distances beyond half the circumference ({np.pi * shape.radius_mm:.6g} mm) "
                                 "do not exist on this sphere")
        if model == "dipole":
            return dipole_profile(2.0 * R0 * np.sin(0.5 * theta), **par)
        return sphere_series_profile(theta, R0_opt=R0, rtol=rtol, **par)
    if shape.kind == "cylinder":
        around, along = r * np.cos(phi), r * np.sin(phi)
        if model == "dipole":
            chord = np.hypot(2.0 * R0 * np.sin(0.5 * around / R0), along)
            return dipole_profile(chord, **par)
        theta = np.mod(around / R0 + np.pi, 2 * np.pi) - np.pi
        # far out (mu s > ~30) the series' absolute error (~1e-14 R(0)) exceeds the value: clamp that noise at 0
        return np.maximum(cylinder_exact_profile(np.abs(theta), np.abs(along), R0_opt=R0, rtol=max(rtol, 1e-13),
                                                 **par), 0.0)
    raise MeshshadeError(f"no exact solution for shape {shape.kind!r}; use --models dipole,curved")


def profile_rows(material: Material, distances_mm, *, models, shapes, azimuths_deg=(0.0,), rtol=1e-10):
    """All (model, radius, azimuth, channel) curves as rows of dicts, for the CSV, table and plot."""
    s_all = _check_distances(distances_mm)
    rows = []
    for shape in shapes:
        s = s_all
        if shape.kind == "sphere" and np.any(s_all > np.pi * shape.radius_mm):
            s = s_all[s_all <= np.pi * shape.radius_mm]  # no point on a sphere is further than half its girth
            warnings.warn(f"sphere of radius {shape.radius_mm:g} mm: distances beyond {np.pi * shape.radius_mm:.4g} mm "
                          "(half the circumference) are left out of its curves", stacklevel=2)
            if s.size == 0:
                raise MeshshadeError(f"no requested distance lies on the sphere of radius {shape.radius_mm:g} mm")
        for az in azimuths_deg:
            for model in models:
                R = reflectance_profile(material, s, model=model, shape=shape, azimuth_deg=az, rtol=rtol)
                for c, ch in enumerate(CHANNELS):
                    rows.append({"model": model, "channel": ch, "radius_mm": shape.radius_mm,
                                 "azimuth_deg": az, "distance_mm": s, "reflectance_per_mm2": R[c]})
    return rows
