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
cavity     (-1/R, -1/R)        R_d(s)                                 (none)                     k1/k2 kernel
bore       (0, -1/R)           R_d(s)                                 (none)                     k1/k2 kernel
point      (--k1, --k2)        R_d(s)                                 (none)                     k1/k2 kernel
=========  ==================  =====================================  =========================  ===========

``fitted`` is the curvature model fitted to Monte Carlo (:mod:`meshshade.kernels.fitted_curvature`, docs/physics.md
§14) on every shape: R_d(s) times its curvature factor, or with ``source_model="beam"`` the near-field base R_near(s)
times it (eq. (82)). A cavity is the medium outside a ball, a bore the medium outside a cylinder (its first
principal direction, k1 = 0, runs along the axis).

``source_model`` says what enters the medium (docs/physics.md §13): ``"point"`` is every model's own point source
at depth z_r; ``"beam"`` replaces it by the near-field model (exact single scattering plus the beam's fitted diffusion
sources, :mod:`meshshade.kernels.near_field`), composed with each model's geometry:

=========  ========================================================================================================
dipole     the half-space near field at the dipole's distance (the chord on the sphere and cylinder, s elsewhere)
exact      each of the beam's sources with the exact sphere's or cylinder's Green's function (eq. (78)); single
           scattering at the chord
curved     the half-space near field at s times the k1/k2 kernel's curvature factor R_curved(s) / R_d(s) (eq. (79))
=========  ========================================================================================================

``mc`` is Monte Carlo on the exact plane, sphere, cylinder, cavity or bore
(:func:`meshshade.montecarlo.shapes.shape_mc_profile`:
exact exit distances, rings of half-width max(0.1 s, 0.05 / min sigma_t'), a pencil beam at normal incidence,
``photons`` per channel, reproducible for a ``seed``); its rows carry the standard error.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from meshshade.errors import ParameterError
from meshshade.kernels.curvature import curvature_profile
from meshshade.kernels.cylinder import cylinder_exact_profile
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.fitted_curvature import fitted_curvature_factor, helix_chord_curvature
from meshshade.kernels.near_field import near_field_cylinder_profile, near_field_profile, near_field_sphere_profile
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.materials import CHANNELS, Material
from meshshade.montecarlo.shapes import shape_mc_profile
from meshshade.names import PROFILE_MC_PHOTONS as MC_PHOTONS, PROFILE_SHAPES as SHAPES  # the CLI's too
from meshshade.surface.options import RTOL_RANGE
from meshshade.surface.source_factors import check_source_model, source_model_keyword

MODELS = ("dipole", "exact", "curved", "fitted", "mc")
#: the shapes with an exact Monte Carlo (meshshade.montecarlo.shapes)
MC_SHAPES = ("plane", "sphere", "cylinder", "cavity", "bore")


def _real(value) -> float:
    """``value`` as a float; NaN when it is not a real number (every range check below then refuses it)."""
    try:
        return float(value) if not isinstance(value, (bool, str)) else math.nan
    except (TypeError, ValueError):
        return math.nan


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
            raise ParameterError(f"unknown shape {kind!r}; choose one of {', '.join(SHAPES)}")
        if kind == "plane":
            return cls("plane")
        if kind == "point":
            if k1 is None or k2 is None:
                raise ParameterError("a curvature point needs both --k1 and --k2 (1/mm)")
            if not (math.isfinite(_real(k1)) and math.isfinite(_real(k2))):
                raise ParameterError(f"curvatures k1, k2 must be finite numbers [1/mm], got k1={k1!r}, k2={k2!r}")
            k1, k2 = _real(k1), _real(k2)
            return cls("point", None, max(k1, k2), min(k1, k2))
        if radius_mm is None:
            raise ParameterError(f"--shape {kind} needs --radius MM")
        R = _real(radius_mm)
        if not 0.0 < R < math.inf:
            raise ParameterError(f"radius must be finite and > 0 mm, got {radius_mm!r}")
        k = {"sphere": (1 / R, 1 / R), "cylinder": (1 / R, 0.0), "saddle": (1 / R, -1 / R), "cavity": (-1 / R, -1 / R),
             "bore": (0.0, -1 / R)}[kind]
        return cls(kind, R, *k)


def _check_distances(distances_mm) -> np.ndarray:
    """(n,) float64 geodesic distances, at least one, each finite and >= 0 mm; MeshshadeError otherwise."""
    try:
        s = np.asarray(distances_mm, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError(f"distances must be numbers (mm), got {distances_mm!r}") from None
    if s.size == 0:
        raise ParameterError("distances: give at least one distance (mm)")
    bad = ~((s >= 0.0) & (s < np.inf))
    if np.any(bad):
        raise ParameterError(f"distances must be finite and >= 0 mm, got {float(s[bad][0])!r}")
    return s


def _check_azimuth(azimuth_deg) -> float:
    phi = _real(azimuth_deg)
    if not math.isfinite(phi):
        raise ParameterError(f"azimuth must be a finite number of degrees, got {azimuth_deg!r}")
    return phi


def _check_rtol(rtol) -> float:
    x = _real(rtol)
    if not RTOL_RANGE[0] <= x <= RTOL_RANGE[1]:
        raise ParameterError(f"rtol (relative tolerance of the exact series) must lie in [{RTOL_RANGE[0]:g}, "
                             f"{RTOL_RANGE[1]:g}], got {rtol!r}")
    return x


def _check_models(models) -> list[str]:
    """A non-empty list of distinct known model names (lower-cased); MeshshadeError otherwise."""
    if isinstance(models, str):
        models = [models]
    models = [str(m).strip().lower() for m in models]
    if not models:
        raise ParameterError(f"models: give at least one of {', '.join(MODELS)}")
    for m in models:
        if m == "beam":
            raise ParameterError("the near-field model is a source model, not a model: --source-model beam "
                                 "(source_model='beam') with --models dipole, exact or curved")
        if m not in MODELS:
            raise ParameterError(f"unknown model {m!r}; choose among {', '.join(MODELS)}")
    dup = sorted({m for m in models if models.count(m) > 1})
    if dup:
        raise ParameterError(f"models: {', '.join(dup)} given twice; each model once")
    return models


#: most distances of one profile (a CSV line and a kernel evaluation each)
MAX_PROFILE_SAMPLES = 1_000_000


def profile_distances(max_distance_mm=20.0, samples=41) -> np.ndarray:
    """``samples`` evenly spaced geodesic distances from 0 to ``max_distance_mm`` (the CLI's ``--max-distance``
    and ``--samples``): ``max_distance_mm`` finite and > 0, ``samples`` an integer in [2, ``MAX_PROFILE_SAMPLES``]
    (MeshshadeError otherwise)."""
    top = _real(max_distance_mm)
    if not 0.0 < top < math.inf:
        raise ParameterError(f"max distance must be finite and > 0 mm, got {max_distance_mm!r}")
    ok = not isinstance(samples, (bool, str)) and isinstance(samples, (int, float, np.integer, np.floating))
    if ok and not isinstance(samples, (int, np.integer)):
        ok = math.isfinite(samples) and float(samples).is_integer()
    if not ok or not 2 <= int(samples) <= MAX_PROFILE_SAMPLES:
        raise ParameterError(f"samples must be an integer in [2, {MAX_PROFILE_SAMPLES}], got {samples!r}")
    return np.linspace(0.0, top, int(samples))


def _mc(material, s, shape, azimuth_deg, photons, seed):
    if shape.kind not in MC_SHAPES:
        raise ParameterError(f"Monte Carlo profiles are exact on a {', '.join(MC_SHAPES[:-1])} or {MC_SHAPES[-1]}, "
                             f"not a {shape.kind}")
    # the Monte Carlo's azimuth runs from the direction around the axis; a bore's first principal direction
    # (k1 = 0) runs along it
    az = 90.0 - float(azimuth_deg) if shape.kind == "bore" else azimuth_deg
    return shape_mc_profile(material, s, shape=shape.kind, radius_mm=shape.radius_mm, azimuth_deg=az,
                            photons=photons, seed=seed)


def reflectance_profile(material: Material, distances_mm, *, model: str = "dipole", shape: Shape | None = None,
                        azimuth_deg: float = 0.0, rtol: float = 1e-10, photons: int = MC_PHOTONS,
                        seed: int = 0, source_model: str | None = None, near_field: str | None = None) -> np.ndarray:
    """Diffuse reflectance per unit power entering the medium [mm^-2], shape (3, n): channels r, g, b.

    Parameters
    ----------
    material : Material
    distances_mm : (n,) float, finite and >= 0 — geodesic distance from the entry point [mm] (at least one)
    model : "dipole" | "exact" | "curved" | "fitted" | "mc" (see the module table)
    shape : Shape (default: plane)
    azimuth_deg : angle of the exit direction from the first principal direction [degrees], finite
    rtol : relative tolerance of the exact series, in [1e-15, 0.1] (``RTOL_RANGE``)
    photons, seed : Monte Carlo photons per channel and seed (``model="mc"``)
    source_model : "point" (default) | "beam" — the models' point source at z_r or the near-field model (module
        docstring); Monte Carlo is exact either way
    near_field : the former name of ``source_model`` (deprecated: a DeprecationWarning)

    Every argument is checked first (MeshshadeError, one line naming it, its value and the allowed range).
    """
    shape = shape or Shape("plane")
    if not isinstance(shape, Shape):
        raise ParameterError(f"shape must be a Shape (Shape.make), got {type(shape).__name__}")
    if not isinstance(material, Material):
        raise ParameterError(f"material must be a Material, got {type(material).__name__}")
    s = _check_distances(distances_mm)
    (model,) = _check_models([model])
    phi = np.deg2rad(_check_azimuth(azimuth_deg))
    rtol = _check_rtol(rtol)
    source_model = check_source_model(source_model_keyword(source_model, near_field) or "point")
    if model == "mc":
        return _mc(material, s, shape, azimuth_deg, photons, seed).reflectance
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
        if source_model == "beam":
            out[c] = _beam_profile_opt(s * st, model, shape, phi, st, par, material.g, rtol) * st * st
        else:
            out[c] = _profile_opt(s * st, model, shape, phi, st, par, rtol) * st * st
    return out


def _flat_distance(r, shape, phi, st):
    """The distance (optical units) at which a half-space model is evaluated: the chord on the sphere and the
    cylinder (as the dipole), the geodesic distance elsewhere."""
    if shape.kind == "sphere":
        R0 = shape.radius_mm * st
        return 2.0 * R0 * np.sin(0.5 * np.minimum(r / R0, np.pi))
    if shape.kind == "cylinder":
        R0 = shape.radius_mm * st
        around, along = r * np.cos(phi), r * np.sin(phi)
        return np.hypot(2.0 * R0 * np.sin(0.5 * around / R0), along)
    return r


def _fitted_factor(r, shape, phi, st, par):
    """The fitted model's curvature factor on ``shape``, with the curvature along the exit direction measured
    between the entry and exit points as in the bake (docs/physics.md eq. (85)): the helix's on a cylinder or bore,
    the entry point's normal curvature elsewhere (where the two agree, or no second point exists)."""
    along = None
    if shape.kind in ("cylinder", "bore"):
        around = phi if shape.kind == "cylinder" else np.pi / 2 - phi   # a bore's k1 = 0 runs along its axis
        sign = 1.0 if shape.kind == "cylinder" else -1.0
        along = sign * helix_chord_curvature(r, around, shape.radius_mm * st)
    return fitted_curvature_factor(r, phi, shape.k1 / st, shape.k2 / st, k_along_opt=along, **par)


def _beam_profile_opt(r, model, shape, phi, st, par, g, rtol):
    """The near-field model composed with ``model`` on ``shape`` (module docstring), optical units."""
    if shape.kind == "plane" or model == "dipole":
        return near_field_profile(_flat_distance(r, shape, phi, st), g=g, **par)
    if model == "fitted":
        return near_field_profile(r, g=g, **par) * _fitted_factor(r, shape, phi, st, par)
    if model == "curved":
        flat = dipole_profile(r, **par)
        curved = _profile_opt(r, "curved", shape, phi, st, par, rtol)
        with np.errstate(invalid="ignore", divide="ignore"):
            factor = np.where(flat > 0, curved / np.where(flat > 0, flat, 1.0), 1.0)
        return near_field_profile(r, g=g, **par) * factor
    R0 = shape.radius_mm * st
    if shape.kind == "sphere":
        _profile_opt(r, "dipole", shape, phi, st, par, rtol)   # the same checks as the point source's
        return near_field_sphere_profile(np.minimum(r / R0, np.pi), R0_opt=R0, g=g, rtol=rtol, **par)
    if shape.kind == "cylinder":
        around, along = r * np.cos(phi), r * np.sin(phi)
        theta = np.abs(np.mod(around / R0 + np.pi, 2 * np.pi) - np.pi)
        return near_field_cylinder_profile(theta, np.abs(along), R0_opt=R0, g=g, rtol=max(rtol, 1e-13), **par)
    raise ParameterError(f"no exact solution for shape {shape.kind!r}; use --models dipole,curved")


def _profile_opt(r, model, shape, phi, st, par, rtol):
    if shape.kind == "plane" or (model == "dipole" and shape.kind in ("saddle", "cavity", "bore", "point")):
        return dipole_profile(r, **par)
    if model == "fitted":
        return dipole_profile(r, **par) * _fitted_factor(r, shape, phi, st, par)
    if model == "curved":
        return curvature_profile(r, phi, k1_opt=shape.k1 / st, k2_opt=shape.k2 / st, **par)
    R0 = shape.radius_mm * st
    if shape.kind == "sphere":
        theta = r / R0
        if np.any(theta > np.pi):
            raise ParameterError(f"distances beyond half the circumference ({np.pi * shape.radius_mm:.6g} mm) "
                                 "do not exist on this sphere")
        if model == "dipole":
            return dipole_profile(_flat_distance(r, shape, phi, st), **par)
        return sphere_series_profile(theta, R0_opt=R0, rtol=rtol, **par)
    if shape.kind == "cylinder":
        around, along = r * np.cos(phi), r * np.sin(phi)
        if model == "dipole":
            return dipole_profile(_flat_distance(r, shape, phi, st), **par)
        theta = np.mod(around / R0 + np.pi, 2 * np.pi) - np.pi
        # far out (mu s > ~30) the series' absolute error (~1e-14 R(0)) exceeds the value: clamp that noise at 0
        return np.maximum(cylinder_exact_profile(np.abs(theta), np.abs(along), R0_opt=R0, rtol=max(rtol, 1e-13),
                                                 **par), 0.0)
    raise ParameterError(f"no exact solution for shape {shape.kind!r}; use --models dipole,curved")


def profile_rows(material: Material, distances_mm, *, models, shapes, azimuths_deg=(0.0,), rtol=1e-10,
                 photons: int = MC_PHOTONS, seed: int = 0, source_model="point", near_field=None):
    """All (model, radius, azimuth, channel) curves as rows of dicts, for the CSV, table and plot; Monte Carlo
    rows (``mc``, ``photons`` per channel, ``seed``) also hold ``stderr_per_mm2``.

    ``models``: a non-empty list of distinct names among ``MODELS``; ``shapes``: a non-empty list of
    :class:`Shape`; ``azimuths_deg``: a non-empty list of finite angles; ``distances_mm`` and ``rtol`` as
    :func:`reflectance_profile`; ``source_model``: "point", "beam" or a list of both (each model's curve for each;
    curves with the beam are named ``model+beam``; Monte Carlo once; ``near_field``: its former name, deprecated).
    All checked before any curve is computed (MeshshadeError, one line).
    """
    s_all = _check_distances(distances_mm)
    models = _check_models(models)
    shapes = list(shapes) if not isinstance(shapes, Shape) else [shapes]
    if not shapes or not all(isinstance(sh, Shape) for sh in shapes):
        raise ParameterError(f"shapes must be a non-empty list of Shape (Shape.make), got {shapes!r}")
    azimuths_deg = [_check_azimuth(a) for a in np.atleast_1d(np.asarray(azimuths_deg, dtype=object))]
    if not azimuths_deg:
        raise ParameterError("azimuths: give at least one angle in degrees")
    rtol = _check_rtol(rtol)
    if near_field is not None:
        source_model = source_model_keyword(None, near_field)
    source_models = [source_model] if isinstance(source_model, str) else list(source_model)
    source_models = list(dict.fromkeys(check_source_model(x) for x in source_models))
    if not source_models:
        raise ParameterError("source model: give point, beam or both")
    if not isinstance(material, Material):
        raise ParameterError(f"material must be a Material, got {type(material).__name__}")
    rows = []
    for shape in shapes:
        s = s_all
        if shape.kind in ("sphere", "cavity") and np.any(s_all > np.pi * shape.radius_mm):
            s = s_all[s_all <= np.pi * shape.radius_mm]  # no point on a sphere is further than half its girth
            warnings.warn(f"{shape.kind} of radius {shape.radius_mm:g} mm: "
                          f"distances beyond {np.pi * shape.radius_mm:.4g} mm "
                          "(half the circumference) are left out of its curves", stacklevel=2)
            if s.size == 0:
                raise ParameterError(f"no requested distance lies on the {shape.kind} of radius {shape.radius_mm:g} mm")
        for az in azimuths_deg:
            for model in models:
                for sm in (source_models if model != "mc" else source_models[:1]):
                    err = None
                    if model == "mc":
                        res = _mc(material, s, shape, az, photons, seed)
                        R, err = res.reflectance, res.stderr
                    else:
                        R = reflectance_profile(material, s, model=model, shape=shape, azimuth_deg=az, rtol=rtol,
                                                source_model=sm)
                    label = model + ("+beam" if sm == "beam" and model != "mc" and len(source_models) > 1 else "")
                    for c, ch in enumerate(CHANNELS):
                        rows.append({"model": label, "channel": ch, "radius_mm": shape.radius_mm,
                                     "azimuth_deg": az, "distance_mm": s, "reflectance_per_mm2": R[c],
                                     "stderr_per_mm2": None if err is None else err[c]})
    return rows
