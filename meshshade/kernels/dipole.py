"""Planar dipole (Jensen, Marschner, Levoy & Hanrahan 2001; docs/physics.md §4), in optical units.

:func:`dipole_diffuse_reflectance` is the one implementation of the closed form ``R_d(r)``: a compiled scalar
function that the numpy :func:`dipole_profile` (through a compiled ufunc), the curvature kernel's profile loop
and the far-field sum (meshshade.surface.farfield_loops) all call. numba's on-disk cache (cache=True) checks
only the file of the function it caches, so alone it would keep those callers in other files on the old code
after an edit here; meshshade keys the whole cache on a hash of all its sources (meshshade.compiled_cache), and
every caller is compiled again.

The public numpy functions validate the material (:func:`~meshshade.kernels.optics.check_material`) and raise
MaterialError outside its domain; the compiled scalar function does not.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from meshshade.kernels.optics import check_material, diffusion_params


# fastmath=False is given explicitly: a numba function without it inherits the fastmath flags of whichever
# caller compiles it first (the curvature profile loop has {"contract"}), so its rounding would depend on call
# order. Without contraction the closed form rounds the same in every caller and on every machine.
@numba.njit(cache=True, error_model="numpy", fastmath=False)
def dipole_diffuse_reflectance(r, albedo_prime, mu, z_r, z_v, log_gain=0.0):
    """Planar-dipole diffuse reflectance ``R_d(r) e^log_gain`` for one distance (compiled scalar, optical units).

    Defined as ``alpha'/(4 pi) [z_r g(d_r) + z_v g(d_v)]`` with ``g(d) = (mu d + 1) e^{-mu d}/d^3``,
    ``d_r = sqrt(r^2 + z_r^2)``, ``d_v = sqrt(r^2 + z_v^2)`` (docs/physics.md eq. (15), Jensen et al. 2001 eq. 4 with
    S = alpha'), times ``e^log_gain``, which is folded into the two exponentials (``e^{log_gain - mu d}``): the
    curvature kernel's "exp" policy multiplies R_d by ``e^delta`` without an exponential more and without
    overflow of ``e^delta`` alone. ``log_gain = 0`` gives R_d itself, bit for bit.

    Parameters
    ----------
    r : float, >= 0
        Distance from the entry point times sigma_t' (dimensionless).
    albedo_prime, mu, z_r, z_v : float
        Reduced albedo, sigma_tr/sigma_t', real-source depth and image-source height in optical units
        (:func:`~meshshade.kernels.optics.diffusion_params`); not validated (callers check the material).
    log_gain : float
        Natural log of a factor applied to R_d (0: none).

    Returns
    -------
    float
        ``R_d e^log_gain / sigma_t'**2``: multiply by sigma_t'^2 [mm^-2] for reflectance per unit incident power
        per mm^2. Finite and positive for every r >= 0 when z_r > 0; underflows to 0 for large mu r.
    """
    r2 = r * r
    d_r = math.sqrt(r2 + z_r * z_r)
    d_v = math.sqrt(r2 + z_v * z_v)
    return albedo_prime / (4.0 * math.pi) * (
        z_r * ((mu * d_r + 1.0) * math.exp(log_gain - mu * d_r) / (d_r * d_r * d_r))
        + z_v * ((mu * d_v + 1.0) * math.exp(log_gain - mu * d_v) / (d_v * d_v * d_v)))


@numba.vectorize(cache=True)
def _dipole_ufunc(r, albedo_prime, mu, z_r, z_v):
    """:func:`dipole_diffuse_reflectance` as a numpy ufunc (broadcasting, any shapes)."""
    return dipole_diffuse_reflectance(r, albedo_prime, mu, z_r, z_v)


def dipole_profile(r_opt, *, albedo_prime, eta):
    """Planar-dipole diffuse reflectance R_d in optical units.

    Defined as ``alpha'/(4 pi) [z_r g(d_r) + z_v g(d_v)]`` with ``d_r = sqrt(r^2 + z_r^2)``,
    ``d_v = sqrt(r^2 + z_v^2)`` (docs/physics.md eq. (15), Jensen et al. 2001 eq. 4 with S = alpha'), evaluated by
    :func:`dipole_diffuse_reflectance` elementwise.

    Parameters
    ----------
    r_opt : array_like of float, >= 0
        Distance from the entry point times sigma_t' (dimensionless).
    albedo_prime : array_like of float in [0, 1]
        Reduced albedo sigma_s'/sigma_t'.
    eta : array_like of float in [1, 2.5] (:func:`meshshade.kernels.optics.check_eta`)
        Relative index of refraction.

    Returns
    -------
    ndarray of float64, broadcast shape
        ``R_d / sigma_t'**2``: multiply by sigma_t'^2 [mm^-2] for reflectance per unit incident power per mm^2.
        Finite and positive for every r_opt >= 0 (d_r >= z_r > 0); underflows to 0 for large mu r.

    Raises
    ------
    MaterialError
        If albedo_prime is not finite and in [0, 1] or eta is not finite and > 0.
    """
    p = diffusion_params(*check_material(albedo_prime, eta))
    with np.errstate(under="ignore"):
        return _dipole_ufunc(np.asarray(r_opt, dtype=np.float64), p.albedo_prime, p.mu, p.z_r, p.z_v)


def dipole_total_reflectance(*, albedo_prime, eta):
    """Closed-form total diffuse reflectance of the planar dipole, ``int R_d 2 pi r dr``.

    Defined as ``(alpha'/2) (exp(-mu z_r) + exp(-mu z_v))`` (docs/physics.md eq. (16)), dimensionless and
    independent of units. Equals 0.6458266279762992 for alpha' = 1/1.01, eta = 1.3.
    """
    return _total_reflectance(diffusion_params(*check_material(albedo_prime, eta)))


def dipole_tail_reflectance(r_opt, *, albedo_prime, eta):
    """Reflectance of the planar dipole beyond distance ``r_opt``: ``int_r^inf R_d 2 pi r' dr'``.

    Defined as ``(alpha'/2) [z_r exp(-mu d_r)/d_r + z_v exp(-mu d_v)/d_v]`` with ``d = sqrt(r^2 + z^2)``,
    from ``d/dr [exp(-mu d)/d] = -r g(d)`` (docs/physics.md §4.2, eq. (16)).
    Equals :func:`dipole_total_reflectance` at r = 0.
    """
    return _tail_reflectance(r_opt, diffusion_params(*check_material(albedo_prime, eta)))


def dipole_cutoff_radius(tol, *, albedo_prime, eta, r_max_opt=1e12):
    """Smallest ``r_opt`` whose tail :func:`dipole_tail_reflectance` is below ``tol`` times the total.

    Bisection in log space (the tail is monotonic in r). With sigma_a = 0 (mu = 0) the tail falls only like
    1/r, so the result can be huge: callers clip it to the mesh size. Returns ``r_max_opt`` if not reached.
    """
    p = diffusion_params(*check_material(albedo_prime, eta))
    target = float(tol) * float(_total_reflectance(p))
    f = lambda r: float(_tail_reflectance(r, p)) - target  # noqa: E731
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


def dipole_cutoff_radii(tol, *, sigma_t_prime, albedo_prime, eta) -> np.ndarray:
    """(c,) mm: per channel of reduced extinction ``sigma_t_prime`` (1/mm) and reduced albedo ``albedo_prime``
    ((c,) each; ``eta`` a scalar), the radius beyond which the dipole's reflectance is below ``tol`` of its total:
    :func:`dipole_cutoff_radius` over ``sigma_t_prime``."""
    st = np.atleast_1d(np.asarray(sigma_t_prime, dtype=np.float64))
    al = np.broadcast_to(np.asarray(albedo_prime, dtype=np.float64), st.shape)
    return np.array([dipole_cutoff_radius(tol, albedo_prime=float(a), eta=float(eta)) / float(s)
                     for a, s in zip(al, st)])


def _total_reflectance(p):
    """:func:`dipole_total_reflectance` from :class:`~meshshade.kernels.optics.DiffusionParams` ``p``."""
    return 0.5 * p.albedo_prime * (np.exp(-p.mu * p.z_r) + np.exp(-p.mu * p.z_v))


def _tail_reflectance(r_opt, p):
    """:func:`dipole_tail_reflectance` from :class:`~meshshade.kernels.optics.DiffusionParams` ``p``."""
    r2 = np.asarray(r_opt, dtype=np.float64) ** 2
    d_r = np.sqrt(r2 + p.z_r**2)
    d_v = np.sqrt(r2 + p.z_v**2)
    with np.errstate(under="ignore"):
        return 0.5 * p.albedo_prime * (p.z_r * np.exp(-p.mu * d_r) / d_r + p.z_v * np.exp(-p.mu * d_v) / d_v)
