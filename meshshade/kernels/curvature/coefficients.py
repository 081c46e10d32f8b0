"""First-order curvature coefficients (docs/physics.md eqs. (49)-(50)),
optical units (lengths x sigma_t', curvatures / sigma_t').

The reflectance of a slightly curved surface, expanded at the entry point, with the exit point at geodesic
distance ``rho`` in direction ``phi`` from the first principal direction (principal curvatures k1, k2; k > 0
convex, i.e. outward normals, docs/physics.md §1.3):

    R(rho, phi) = R_d(rho) + alpha' [ k_n(phi) A(rho) + k_n(phi + pi/2) B(rho) ] + O(k^2),
    k_n(phi) = k1 cos^2 phi + k2 sin^2 phi,

    4 pi (A+B) = (rho^2/2) [ g(d_r) + z_r^2 p(d_r) - g(d_v) - z_v^2 p(d_v) ]
               + a [ mu^2 I(rho,z_v) - z_v g(d_v) + z_v rho^2 p(d_v)
                     - z_b (mu^2 e^{-mu d_v}/d_v + g(d_v) - z_v^2 p(d_v)) ],
    4 pi B     = a [ (1/rho) dI/drho (rho, z_v) + z_b g(d_v) ],        a = z_r + z_b,

with ``g(d) = (mu d + 1) e^{-mu d}/d^3``, ``p(d) = (mu^2 d^2 + 3 mu d + 3) e^{-mu d}/d^5``,
``d_r = sqrt(rho^2 + z_r^2)``, ``d_v = sqrt(rho^2 + z_v^2)`` and the auxiliary integral I of docs/physics.md §7.2
(:mod:`meshshade.kernels.curvature.auxiliary`).

Domain edges: only ``mu^2 I ~ mu^2 ln(1/mu) -> 0`` enters A + B, so the coefficients take the limit
``mu^2 I = 0`` at mu = 0 (alpha' = 1) and are continuous there (difference O(mu^2 (rho^2 + z_v^2)), checked at
mu = 1.7e-7). In the appendix setting (z_b = 0) this limit reproduces the Laplace/Poisson-kernel result
``4 pi (A0 + B0) = a^2 (2 rho^2 - a^2)/d^5`` exactly. For large mu rho, A and B underflow to 0 (never NaN); the
ratios ``a = alpha' A/R_d`` and ``b = alpha' B/R_d`` are computed from quantities scaled by ``e^{mu rho}`` (the
scaled R_d below is the dipole's closed form with ``e^{-mu (d - rho)}`` formed without cancellation) and do not
underflow.

The validity measure ``nu = max(|k1|, |k2|) (|a| + |b| + z_r)`` and the errors it predicts are documented in
:mod:`meshshade.kernels.curvature.profile`. A material outside its domain (albedo_prime outside [0, 1], eta not
finite and > 0) raises MaterialError; a negative or non-finite rho_opt raises ValueError.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from meshshade.kernels.curvature.auxiliary import _aux_scaled, _check_nonneg_finite
from meshshade.kernels.optics import check_material, diffusion_params

__all__ = [
    "VALIDITY_TOL",
    "curvature_coefficients",
    "curvature_ratios",
    "curvature_relative_coefficient",
    "curvature_validity",
]

#: default threshold of the validity measure nu (the "exp" policy is then within ~1 % of the exact sphere and
#: cavity; :mod:`meshshade.kernels.curvature.profile`)
VALIDITY_TOL = 0.25


@numba.njit(cache=True, error_model="numpy")
def _coeffs_scaled(rho, mu, z_r, z_b):
    """``4 pi e^{mu rho} (A, B, R_d/alpha')`` at distance rho (docs/physics.md eq. (50); z_b = 0 gives eq. (48))."""
    z_v = z_r + 2.0 * z_b
    a = z_r + z_b
    r2 = rho * rho
    d_r = math.sqrt(r2 + z_r * z_r)
    d_v = math.sqrt(r2 + z_v * z_v)
    e_r = math.exp(-mu * (z_r * z_r / (d_r + rho)))  # e^{-mu (d_r - rho)}
    e_v = math.exp(-mu * (z_v * z_v / (d_v + rho)))
    g_r = (mu * d_r + 1.0) * e_r / (d_r * d_r * d_r)
    g_v = (mu * d_v + 1.0) * e_v / (d_v * d_v * d_v)
    m_r = mu * d_r
    m_v = mu * d_v
    p_r = (m_r * m_r + 3.0 * m_r + 3.0) * e_r / (d_r * d_r * d_r * d_r * d_r)
    p_v = (m_v * m_v + 3.0 * m_v + 3.0) * e_v / (d_v * d_v * d_v * d_v * d_v)
    si, sj = _aux_scaled(rho, z_v, mu)
    mu2_i = mu * mu * (si * e_v) if mu > 0.0 else 0.0  # the mu -> 0 limit of mu^2 I is 0 (I ~ ln(1/mu))
    a_plus_b = (0.5 * r2 * (g_r + z_r * z_r * p_r - g_v - z_v * z_v * p_v)
                + a * (mu2_i - z_v * g_v + z_v * r2 * p_v
                       - z_b * (mu * mu * e_v / d_v + g_v - z_v * z_v * p_v)))
    b = a * (sj * e_v + z_b * g_v)
    rd = z_r * g_r + z_v * g_v
    return a_plus_b - b, b, rd


@numba.njit(cache=True, error_model="numpy")
def ratios_direct(rho, mu, z_r, z_b):
    """``(a, b) = (alpha' A/R_d, alpha' B/R_d)`` by direct quadrature."""
    cA, cB, rd = _coeffs_scaled(rho, mu, z_r, z_b)
    return cA / rd, cB / rd


@numba.njit(cache=True, error_model="numpy")
def _coeffs_many(rho, mu, z_r, z_b, alb, out_a, out_b, out_ra, out_rb):
    inv4pi = 0.25 / math.pi
    for k in range(rho.size):
        cA, cB, rd = _coeffs_scaled(rho[k], mu[k], z_r[k], z_b[k])
        e = math.exp(-mu[k] * rho[k])
        out_a[k] = inv4pi * cA * e
        out_b[k] = inv4pi * cB * e
        out_ra[k] = cA / rd
        out_rb[k] = cB / rd


def _coeff_arrays(rho_opt, albedo_prime, eta):
    rho = np.asarray(rho_opt, dtype=np.float64)
    _check_nonneg_finite("rho_opt", rho)
    p = diffusion_params(*check_material(albedo_prime, eta))
    r, alb, mu, z_r, zb = np.broadcast_arrays(rho, p.albedo_prime, p.mu, p.z_r, p.z_b)
    shape = r.shape
    r, alb, mu, z_r, zb = (np.ascontiguousarray(x, dtype=np.float64).ravel() for x in (r, alb, mu, z_r, zb))
    outs = [np.empty(r.size) for _ in range(4)]
    with np.errstate(under="ignore"):
        _coeffs_many(r, mu, z_r, zb, alb, *outs)
    return [o.reshape(shape) for o in outs]


def curvature_coefficients(rho_opt, *, albedo_prime, eta):
    """First-order curvature coefficients ``(A, B)`` of docs/physics.md eqs. (49)-(50), optical units.

    Defined by ``R = R_d + alpha' [k_n(phi) A + k_n(phi + pi/2) B]`` (module docstring): A multiplies the normal
    curvature along the entry-to-exit direction, B the one across it. Unit-source normalisation (the alpha'
    is outside), lengths times sigma_t', so ``alpha' k A`` is ``R/sigma_t'^2`` when k is curvature/sigma_t'.

    Parameters
    ----------
    rho_opt : array_like of float, finite and >= 0
        Geodesic distance from the entry point times sigma_t'.
    albedo_prime : array_like of float in [0, 1]
        Reduced albedo (1 is handled as the mu -> 0 limit).
    eta : array_like of float > 0
        Relative index of refraction.

    Returns
    -------
    (A, B) : tuple of ndarray of float64, broadcast shape
        ``A(0) = B(0)``. Both underflow to 0 like e^{-mu rho}; use :func:`curvature_ratios` for the
        underflow-free ratios to R_d.
    """
    A, B, _, _ = _coeff_arrays(rho_opt, albedo_prime, eta)
    return A, B


def curvature_ratios(rho_opt, *, albedo_prime, eta):
    """``(a, b) = (alpha' A/R_d, alpha' B/R_d)``, optical length units (multiply by a curvature/sigma_t').

    Computed from quantities scaled by ``e^{mu rho}``, so finite for every finite rho. The first-order
    relative correction is ``delta = k_n(phi) a + k_n(phi + pi/2) b``.
    """
    _, _, a, b = _coeff_arrays(rho_opt, albedo_prime, eta)
    return a, b


def curvature_relative_coefficient(rho_opt, *, albedo_prime, eta):
    """``C(rho) = alpha' (A + B)/R_d`` (docs/physics.md eq. (51)), optical length units.

    For a sphere of radius R0 (k1 = k2 = 1/R0) the first-order kernel is ``R_d (1 + C/R0)``. In mm:
    ``C_mm = C_opt / sigma_t'`` (skin test case: 1.127 mm at s = 1 mm, 15.89 mm at 20 mm).
    """
    a, b = curvature_ratios(rho_opt, albedo_prime=albedo_prime, eta=eta)
    return a + b


def curvature_validity(rho_opt, k_opt, *, albedo_prime, eta, tol=VALIDITY_TOL):
    """True where the first-order kernel is inside its validity range: ``|k| (|a| + |b| + z_r) <= tol``.

    ``k_opt`` is the largest absolute principal curvature, ``max(|k1|, |k2|)/sigma_t'``. The measure bounds
    ``|delta|`` in every direction (``|a| + |b|``) and adds ``|k| z_r`` (z_r = 1: curvature radius against
    one transport length), which governs the second-order error near the entry point, where a and b are
    small. Measured maximum errors of the "exp" policy by tol: :mod:`meshshade.kernels.curvature.profile`
    (0.1 -> 0.14 %, 0.25 -> 1.1 %).
    """
    a, b = curvature_ratios(rho_opt, albedo_prime=albedo_prime, eta=eta)
    k = np.abs(np.asarray(k_opt, dtype=np.float64))
    return k * (np.abs(a) + np.abs(b) + 1.0) <= tol
