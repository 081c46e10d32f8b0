"""Specular Fresnel reflectance of a smooth dielectric interface (unpolarised light).

Pure array functions, float64, broadcasting like ufuncs. The diffuse (hemispherical) counterpart F_dr used by
the dipole boundary condition lives in :mod:`meshshade.kernels.optics`.

Equations (the Fresnel formulae, Born & Wolf, *Principles of Optics*, 7th ed., section 1.5.2; pbrt-v4
``FrDielectric``): with relative index ``eta = eta_t / eta_i``, Snell's law ``sin(theta_t) = sin(theta_i)/eta``,
``cos_t = sqrt(1 - (1 - cos_i**2)/eta**2)`` and

    r_perp = (cos_i - eta cos_t) / (cos_i + eta cos_t)        (s, TE)
    r_parl = (eta cos_i - cos_t) / (eta cos_i + cos_t)        (p, TM)
    F      = (r_perp**2 + r_parl**2) / 2.

The numerators are evaluated in the cancellation-free forms obtained by multiplying through by the conjugate
and using ``eta**2 cos_t**2 = eta**2 - 1 + cos_i**2`` (with ``eta**2 - 1`` formed as ``(eta - 1)(eta + 1)``):

    cos_i - eta cos_t   = (1 - eta**2) / (cos_i + eta cos_t)
    eta cos_i - cos_t   = (eta**2 - 1) (cos_i**2 (eta**2 + 1) - 1) / (eta**2 (eta cos_i + cos_t))

so that F is exactly 0 at ``eta = 1`` and keeps full relative accuracy for index-matched media.
"""
from __future__ import annotations

import numpy as np


def fresnel_reflectance(cos_i, eta_i, eta_t):
    """Unpolarised specular reflectance F of a smooth interface, light going from index ``eta_i`` into ``eta_t``.

    Parameters
    ----------
    cos_i : array_like of float in [0, 1]
        Cosine of the angle of incidence, measured from the normal on the incident side. Values are clipped to
        [0, 1] (the caller orients the normal); NaN propagates.
    eta_i, eta_t : array_like of float > 0
        Refractive indices of the incident and transmitting media (dimensionless).

    Returns
    -------
    ndarray of float64 in [0, 1], broadcast shape of the inputs.

    Domain edges
    ------------
    * normal incidence (cos_i = 1): ``((eta_i - eta_t)/(eta_i + eta_t))**2``;
    * grazing incidence (cos_i = 0): 1, for any mismatched pair of indices;
    * total internal reflection (eta_i > eta_t and sin_i >= eta_t/eta_i): 1;
    * matched indices (eta_i == eta_t): 0 at every angle, including cos_i = 0 (there is no interface; this is
      the limit cos_i -> 0 at eta = 1, and takes precedence over the grazing rule).

    F is non-decreasing in the angle of incidence for eta_t/eta_i below about 3.7 (checked numerically; above
    it the unpolarised F dips slightly away from normal incidence before rising to 1).
    """
    cos_i = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    eta = np.asarray(eta_t, dtype=np.float64) / np.asarray(eta_i, dtype=np.float64)
    cos_i, eta = np.broadcast_arrays(cos_i, eta)
    eta2 = eta * eta
    d = (eta - 1.0) * (eta + 1.0)                  # eta**2 - 1, exact-ish near eta = 1 (Sterbenz)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos2_t = (d + cos_i * cos_i) / eta2        # = 1 - sin_i**2 / eta**2 without cancellation
        tir = cos2_t <= 0.0
        cos_t = np.sqrt(np.clip(cos2_t, 0.0, None))
        den_perp = cos_i + eta * cos_t
        den_parl = eta * cos_i + cos_t
        r_perp = -d / (den_perp * den_perp)
        r_parl = d * (cos_i * cos_i * (d + 2.0) - 1.0) / (eta2 * den_parl * den_parl)
        F = 0.5 * (r_perp * r_perp + r_parl * r_parl)
    F = np.where(tir | (cos_i == 0.0), 1.0, F)
    F = np.where(eta == 1.0, 0.0, F)
    F = np.where(np.isnan(cos_i) | np.isnan(eta), np.nan, F)
    return np.clip(F, 0.0, 1.0)[()]


def fresnel_transmittance_entry(cos_i, eta):
    """Fraction ``F_t = 1 - F`` of incident power transmitted from outside (index 1) into a medium of index ``eta``.

    Parameters
    ----------
    cos_i : array_like of float in [0, 1]
        Cosine of the angle between the incoming light's reversed direction and the outward surface normal.
    eta : array_like of float > 0
        Relative index of the medium (dimensionless); eta = 1 gives F_t = 1.

    Returns
    -------
    ndarray of float64 in [0, 1], broadcast shape; 0 at grazing incidence (cos_i = 0) unless eta = 1.
    """
    return (1.0 - fresnel_reflectance(cos_i, 1.0, eta))[()]


def refract_in(d, n, eta: float) -> np.ndarray:
    """Refract unit directions ``d`` (n, 3) arriving from outside (index 1) through outward unit normals ``n`` (n, 3)
    into ``eta`` (Snell): the Monte Carlo entry and the volume transport's line sources."""
    cos_i = np.clip(-np.einsum("ij,ij->i", d, n), 0.0, 1.0)
    sin2_t = (1.0 - cos_i ** 2) / eta ** 2
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    out = d / eta + (cos_i / eta - cos_t)[:, None] * n
    return out / np.linalg.norm(out, axis=1, keepdims=True)
