"""Diffusion parameters of docs/physics.md §2, in optical units (sigma_t' = 1).

Every length below is in units of the transport mean free path 1/sigma_t'; multiply by 1/sigma_t' [mm]
to get millimetres. The only material inputs the kernels need are the reduced albedo alpha' and eta.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from meshshade.errors import MaterialError


#: the documented domain of the relative index eta (inside/outside), [ETA_MIN, ETA_MAX]: see ``check_eta``
ETA_MIN = 1.0
ETA_MAX = 2.5
#: above this eta the fit's boundary mismatch A is more than 1 % off the exact Fresnel value (Material warns)
ETA_FIT_ACCURATE = 2.2


def fresnel_diffuse_reflectance(eta):
    """F_dr, the diffuse Fresnel reflectance (Groenhuis et al. 1983 fit, as in Jensen et al. 2001 eq. 5).

    Defined as ``-1.440/eta**2 + 0.710/eta + 0.668 + 0.0636*eta``; at eta = 1 it gives 0.0016, not 0
    (docs/physics.md eq. (6)). Meaningful on the domain ``[ETA_MIN, ETA_MAX]`` = [1, 2.5] only (``check_eta``):
    within 1.3e-3 of the exact hemispherical Fresnel reflectance for 1 <= eta <= 2.2, 5e-3 at 2.5; it is negative
    below eta = 1 and exceeds 1 above eta = 3.9 (A < 0: negative reflectance). Not validated here.
    """
    eta = np.asarray(eta, dtype=np.float64)
    return -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta


def _eta_ok(e) -> np.ndarray | bool:
    return (e >= ETA_MIN) & (e <= ETA_MAX)  # NaN fails both comparisons


def check_eta(eta) -> np.ndarray:
    """Validate the relative index of refraction ``eta`` (array_like); return it as a float64 array.

    Domain: finite and ``ETA_MIN <= eta <= ETA_MAX``, i.e. [1, 2.5] (docs/physics.md §2.1). The outside is air
    (index 1) everywhere in meshshade, so eta < 1 would be a medium optically thinner than air (and the F_dr fit
    is negative there); above 2.5 the Groenhuis fit of F_dr leaves the exact value by more than 0.5 % (4.6 % in
    A at 2.5, 26 % at 3) and exceeds 1 above 3.9, which makes A and every reflectance negative. Real translucent
    media lie well inside: water 1.33, tissue 1.35-1.45, wax 1.44, marble 1.49-1.66, jade 1.66, zirconia 2.2.

    Raises :class:`~meshshade.errors.MaterialError` (one line naming the value and the range) otherwise.
    """
    try:
        e = np.asarray(eta, dtype=np.float64)
    except (TypeError, ValueError):
        raise MaterialError(f"eta must be a real number, got {eta!r}") from None
    ok = bool(_eta_ok(float(e))) if e.ndim == 0 else bool(np.all(_eta_ok(e)))
    if not ok:
        bad = e[~_eta_ok(e)].flat[0] if e.ndim else e
        raise MaterialError(f"eta (relative index of refraction) must be finite and lie in [{ETA_MIN:g}, "
                            f"{ETA_MAX:g}], the range of the F_dr fit (docs/physics.md §2.1), got {float(bad)!r}")
    return e


def check_material(albedo_prime, eta):
    """Validate the material inputs of every kernel; return them as float64 arrays ``(albedo_prime, eta)``.

    Raises :class:`~meshshade.errors.MaterialError` unless every ``albedo_prime`` is finite and in [0, 1] and every
    ``eta`` is finite and in [1, 2.5] (:func:`check_eta`; array_like, any shapes; the arrays are returned
    unbroadcast).
    """
    try:
        a = np.asarray(albedo_prime, dtype=np.float64)
        np.asarray(eta, dtype=np.float64)
    except (TypeError, ValueError):
        raise MaterialError(f"albedo_prime and eta must be real numbers, got {albedo_prime!r}, {eta!r}") from None
    if a.ndim == 0:  # the common case, without numpy reductions (NaN fails every comparison)
        ok_a = 0.0 <= float(a) <= 1.0
    else:
        ok_a = bool(np.all((a >= 0.0) & (a <= 1.0)))
    if not ok_a:
        bad = a[~((a >= 0.0) & (a <= 1.0))].flat[0] if a.ndim else a
        raise MaterialError(f"albedo_prime must be finite and lie in [0, 1], got {float(bad)!r}")
    return a, check_eta(eta)


class DiffusionParams(NamedTuple):
    """Dipole parameters in optical units (docs/physics.md §2.3, eq. (10)).

    albedo_prime : alpha' = sigma_s'/sigma_t'
    D            : diffusion coefficient 1/3
    mu           : sigma_tr/sigma_t' = sqrt(3 (1 - alpha'))
    z_r          : depth of the real source, 1
    F_dr, A      : diffuse Fresnel reflectance and boundary mismatch (1 + F_dr)/(1 - F_dr)
    z_b          : extrapolation distance 2 A D
    z_v          : height of the image source above the surface, z_r + 2 z_b
    """

    albedo_prime: np.ndarray
    D: np.ndarray
    mu: np.ndarray
    z_r: np.ndarray
    F_dr: np.ndarray
    A: np.ndarray
    z_b: np.ndarray
    z_v: np.ndarray


def diffusion_params(albedo_prime, eta) -> DiffusionParams:
    """Return :class:`DiffusionParams` (broadcast arrays) for reduced albedo ``albedo_prime`` in [0, 1] and ``eta``.

    ``mu = sqrt(3 (1 - alpha'))`` is formed from ``1 - alpha'`` directly so it stays accurate as alpha' -> 1.
    The albedo is not validated here (the public kernels call :func:`check_material` first); ``eta`` is, always
    (:func:`check_eta`, MaterialError outside [1, 2.5]), so no path reaches the F_dr fit outside its domain.
    """
    a = np.asarray(albedo_prime, dtype=np.float64)
    eta = check_eta(eta)
    F_dr = fresnel_diffuse_reflectance(eta)
    A = (1.0 + F_dr) / (1.0 - F_dr)
    D = np.full(np.broadcast(a, eta).shape, 1.0 / 3.0)
    mu = np.sqrt(3.0 * np.clip(1.0 - a, 0.0, None)) + 0.0 * eta
    z_r = np.ones_like(D)
    z_b = 2.0 * A * D
    z_v = z_r + 2.0 * z_b
    return DiffusionParams(a + 0.0 * eta, D, mu, z_r, F_dr + 0.0 * a, A + 0.0 * a, z_b + 0.0 * a, z_v + 0.0 * a)


def g_func(d, mu):
    """g(d) = (mu d + 1) exp(-mu d) / d**3 (docs/physics.md eq. (10)); d > 0."""
    d = np.asarray(d, dtype=np.float64)
    return (mu * d + 1.0) * np.exp(-mu * d) / d**3

