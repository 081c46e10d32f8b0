"""Planar dipole (Jensen, Marschner, Levoy & Hanrahan 2001; physics.md section b), in optical units."""
from __future__ import annotations

import numpy as np

from meshshade.kernels.optics import diffusion_params, g_func


def dipole_profile(r_opt, *, albedo_prime, eta):
    """Planar-dipole diffuse reflectance R_d in optical units.

    Defined as ``alpha'/(4 pi) [z_r g(d_r) + z_v g(d_v)]`` with ``d_r = sqrt(r^2 + z_r^2)``,
    ``d_v = sqrt(r^2 + z_v^2)`` (physics.md b, Jensen et al. 2001 eq. 4 with S = alpha').

    Parameters
    ----------
    r_opt : array_like of float, >= 0
        Distance from the entry point times sigma_t' (dimensionless).
    albedo_prime : array_like of float in [0, 1]
        Reduced albedo sigma_s'/sigma_t'.
    eta : array_like of float > 0
        Relative index of refraction.

    Returns
    -------
    ndarray of float64, broadcast shape
        ``R_d / sigma_t'**2``: multiply by sigma_t'^2 [mm^-2] for reflectance per unit incident power per mm^2.
        Finite and positive for every r_opt >= 0 (d_r >= z_r > 0); underflows to 0 for large mu r.
    """
    p = diffusion_params(albedo_prime, eta)
    r = np.asarray(r_opt, dtype=np.float64)
    r2 = r * r
    d_r = np.sqrt(r2 + p.z_r**2)
    d_v = np.sqrt(r2 + p.z_v**2)
    with np.errstate(under="ignore"):
        return p.albedo_prime / (4.0 * np.pi) * (p.z_r * g_func(d_r, p.mu) + p.z_v * g_func(d_v, p.mu))


def dipole_total_reflectance(*, albedo_prime, eta):
    """Closed-form total diffuse reflectance of the planar dipole, ``int R_d 2 pi r dr``.

    Defined as ``(alpha'/2) (exp(-mu z_r) + exp(-mu z_v))`` (physics.md b), dimensionless and
    independent of units. Equals 0.6458266279762992 for alpha' = 1/1.01, eta = 1.3.
    """
    p = diffusion_params(albedo_prime, eta)
    return 0.5 * p.albedo_prime * (np.exp(-p.mu * p.z_r) + np.exp(-p.mu * p.z_v))


def dipole_tail_reflectance(r_opt, *, albedo_prime, eta):
    """Reflectance of the planar dipole beyond distance ``r_opt``: ``int_r^inf R_d 2 pi r' dr'``.

    Defined as ``(alpha'/2) [z_r exp(-mu d_r)/d_r + z_v exp(-mu d_v)/d_v]`` with ``d = sqrt(r^2 + z^2)``,
    from ``d/dr [exp(-mu d)/d] = -r g(d)`` (physics.md b). Equals :func:`dipole_total_reflectance` at r = 0.
    """
    p = diffusion_params(albedo_prime, eta)
    r2 = np.asarray(r_opt, dtype=np.float64) ** 2
    d_r = np.sqrt(r2 + p.z_r**2)
    d_v = np.sqrt(r2 + p.z_v**2)
    with np.errstate(under="ignore"):
        return 0.5 * p.albedo_prime * (p.z_r * np.exp(-p.mu * d_r) / d_r + p.z_v * np.exp(-p.mu * d_v) / d_v)


def dipole_cutoff_radius(tol, *, albedo_prime, eta, r_max_opt=1e12):
    """Smallest ``r_opt`` whose tail :func:`dipole_tail_reflectance` is below ``tol`` times the total.

    Bisection in log space (the tail is monotonic in r). With sigma_a = 0 (mu = 0) the tail falls only like
    1/r, so the result can be huge: callers clip it to the mesh size. Returns ``r_max_opt`` if not reached.
    """
    tot = float(dipole_total_reflectance(albedo_prime=albedo_prime, eta=eta))
    target = float(tol) * tot
    f = lambda r: float(dipole_tail_reflectance(r, albedo_prime=albedo_prime, eta=eta)) - target  # noqa: E731
    if f(r_max_opt) > 0:
        return float(r_max_opt)
    lo, hi = 0.0, 1.0
    while f(hi) > 0:
        lo, hi = hi, hi * 2.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
        if hi - lo <= 1e-12 * hi:
            break
    return hi
