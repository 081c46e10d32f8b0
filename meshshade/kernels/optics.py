"""Diffusion parameters of docs/physics.md §2, in optical units (sigma_t' = 1).

Every length below is in units of the transport mean free path 1/sigma_t'; multiply by 1/sigma_t' [mm]
to get millimetres. The only material inputs the kernels need are the reduced albedo alpha' and eta.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from meshshade.errors import MaterialError


def fresnel_diffuse_reflectance(eta):
    """F_dr, the diffuse Fresnel reflectance (Groenhuis et al. 1983 fit, as in Jensen et al. 2001 eq. 5).

    Defined as ``-1.440/eta**2 + 0.710/eta + 0.668 + 0.0636*eta``. Domain eta > 0 (fit made for eta >= 1);
    at eta = 1 it gives 0.0016, not 0 (docs/physics.md eq. (6)).
    """
    eta = np.asarray(eta, dtype=np.float64)
    return -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta


def check_material(albedo_prime, eta):
    """Validate the material inputs of every kernel; return them as float64 arrays ``(albedo_prime, eta)``.

    Raises :class:`~meshshade.errors.MaterialError` unless every ``albedo_prime`` is finite and in [0, 1] and every
    ``eta`` is finite and > 0 (array_like, any shapes; the arrays are returned unbroadcast).
    """
    try:
        a = np.asarray(albedo_prime, dtype=np.float64)
        e = np.asarray(eta, dtype=np.float64)
    except (TypeError, ValueError):
        raise MaterialError(f"albedo_prime and eta must be real numbers, got {albedo_prime!r}, {eta!r}") from None
    if a.ndim == 0 and e.ndim == 0:  # the common case, without numpy reductions (NaN fails every comparison)
        ok_a = 0.0 <= float(a) <= 1.0
        ok_e = 0.0 < float(e) < math.inf
    else:
        ok_a = bool(np.all((a >= 0.0) & (a <= 1.0)))
        ok_e = bool(np.all((e > 0.0) & (e < np.inf)))
    if not ok_a:
        bad = a[~((a >= 0.0) & (a <= 1.0))].flat[0] if a.ndim else a
        raise MaterialError(f"albedo_prime must be finite and lie in [0, 1], got {float(bad)!r}")
    if not ok_e:
        bad = e[~((e > 0.0) & (e < np.inf))].flat[0] if e.ndim else e
        raise MaterialError(f"eta must be finite and > 0, got {float(bad)!r}")
    return a, e


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
    The inputs are not validated here: the public kernels call :func:`check_material` first.
    """
    a = np.asarray(albedo_prime, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
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

