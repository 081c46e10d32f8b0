"""Curved-surface diffuse reflectance, first order in the principal curvatures (docs/physics.md eqs. (49)-(50)),
in optical units.

:func:`curvature_profile` returns ``R = R_d(rho) f(delta)``: the planar dipole at geodesic distance ``rho`` times a
positive function of the first-order relative correction

    delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho),     k_n(phi) = k1 cos^2 phi + k2 sin^2 phi,

with ``a = alpha' A/R_d``, ``b = alpha' B/R_d`` (optical lengths; :mod:`meshshade.kernels.curvature.coefficients`;
a ~ C(rho) grows about linearly with rho, |b| << a beyond rho ~ 1), evaluated through a
:class:`~meshshade.kernels.curvature.table.CurvatureTable`.

Validity policy (what :func:`curvature_profile` returns)
--------------------------------------------------------
The first-order sum ``1 + delta`` turns negative on concave surfaces once ``delta < -1`` and grows without
bound on convex ones. The policy ``"exp"`` returns

    R = min( R_d(rho) exp(delta),  R_d(0) exp(max(delta_0, 0)) ),      delta_0 = (k1 + k2) a(0),

i.e. the first-order correction is exponentiated (ln R = ln R_d + delta: identical to first order, so the
1/R0^2 convergence to the exact solutions is kept) and the result never exceeds the kernel's own value at the
entry point of a convex surface (the exact sphere's profile is largest at theta = 0). It is positive,
monotone in delta, finite for every finite input (delta is clipped at 700), and R_d itself when
k1 = k2 = 0. ``"clamp"`` returns ``R_d max(1 + delta, 0)`` under the same cap (the raw first order wherever
it is positive). ``"soft"``, the default, saturates delta before exponentiating it (same cap;
:mod:`meshshade.kernels.curvature.policies`). The validity measure is

    nu = max(|k1|, |k2|) (|a(rho)| + |b(rho)| + z_r),     z_r = 1 (one transport length),

which bounds |delta| in every direction and adds the ``|k| z_r`` that governs the second-order error near
the entry point (where a and b are small). Measured maximum relative errors against the exact sphere
(convex; docs/physics.md §5) and the exact spherical cavity (concave, medium outside a sphere; the exterior K-type
series in tests/kernels/test_curvature_kernel.py) over 5 materials (skin eta 1.3 and 1.0, marble R, potato B,
ketchup G), radii 3-1000 mm and geodesic distances 0.25-30 mm (1550 pairs):

    nu <=          0.05            0.1             0.25            0.5             1
    "exp"    sph   2.6e-4          1.3e-3          8.5e-3          2.4e-2          9.4e-2
             cav   2.7e-4          1.5e-3          1.1e-2          4.3e-2          0.30
    "clamp"  sph   9.4e-4          3.3e-3          2.1e-2          7.6e-2          0.24
             cav   9.9e-4          3.7e-3          2.8e-2          0.13            0.67
    dipole   sph   4.0e-2          8.4e-2          0.20            0.36            0.60    (R_d at geodesic rho)
             cav   4.1e-2          9.5e-2          0.27            0.66            2.2

The exact R/R_d grows faster than linearly in delta on both sides (``1 + delta + beta delta^2``, beta ~
0.1-0.35), which is why the exponentiated form beats the clamped sum everywhere.
:func:`~meshshade.kernels.curvature.coefficients.curvature_validity` (default tol VALIDITY_TOL = 0.25, ~1 %
error) flags where nu exceeds tol; there the kernel is a smooth, bounded extrapolation, not physics: callers
should blend to the exact sphere where the surface is locally spherical.

Errors: a material outside its domain raises MaterialError; other bad arguments (negative or non-finite rho,
non-finite curvatures or angles, an unknown policy) raise ValueError.
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.kernels.curvature.coefficients import VALIDITY_TOL
from meshshade.kernels.curvature.policies import check_policy
from meshshade.kernels.curvature.table import CurvatureTable
from meshshade.kernels.optics import check_material

__all__ = ["curvature_profile"]

_RHO_TABLE_MAX = 4096.0  # tables built by curvature_profile stop here (1025 intervals); beyond: direct
_MAX_TABLES_PER_CALL = 8


def curvature_profile(rho_opt, phi=None, *, k1_opt, k2_opt, albedo_prime, eta, cos2phi=None, policy="soft",
                      return_validity=False, tol=VALIDITY_TOL):
    """Curved-surface diffuse reflectance R in optical units (first order in k, docs/physics.md eqs. (49)-(50)).

    Defined as ``R_d(rho) f(delta)`` with ``delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho)``,
    ``k_n(phi) = k1 cos^2 phi + k2 sin^2 phi``, i.e. ``delta = H (a + b) + dk cos(2 phi) (a - b)`` with
    ``H = (k1 + k2)/2``, ``dk = (k1 - k2)/2``, and the positivity policy of the module docstring ("exp":
    ``f = exp``; "clamp": ``f = max(1 + delta, 0)``; "soft": exp of a saturated delta; all capped at the
    kernel's entry-point value). Equal to
    :func:`~meshshade.kernels.dipole.dipole_profile` (to rounding, <= 1e-15 relative) where k1 = k2 = 0.

    Parameters
    ----------
    rho_opt : array_like of float, finite, >= 0
        Geodesic distance from the entry point times sigma_t'.
    phi : array_like of float, finite
        Direction of the exit point in the entry point's tangent plane, from the first principal direction
        [rad]. Give either phi or ``cos2phi``.
    k1_opt, k2_opt : array_like of float, finite
        Principal curvatures at the entry point divided by sigma_t' (k > 0 convex).
    albedo_prime : array_like of float in [0, 1]
    eta : array_like of float > 0
    cos2phi : array_like of float in [-1, 1], optional
        ``cos(2 phi)`` instead of phi: callers with the exit point's tangent-plane coordinates (x, y) in the
        principal frame have it as ``(x^2 - y^2)/(x^2 + y^2)`` and save an arctan2 and a cosine per pair.
    policy : {"soft", "exp", "clamp"}
    return_validity : bool
        Also return the boolean mask ``max(|k1|, |k2|) (|a| + |b| + z_r) <= tol``
        (:func:`~meshshade.kernels.curvature.coefficients.curvature_validity`).
    tol : float
        Threshold of the mask (0.25: "exp" within ~1 % of the exact sphere and cavity, module docstring).

    Returns
    -------
    ndarray of float64, broadcast shape of all inputs (and the mask if requested)
        ``R / sigma_t'^2``; finite and >= 0 for every finite input.

    Notes
    -----
    Evaluated through a :class:`CurvatureTable` built for this call over ``[0, min(max rho, 4096)]`` per
    distinct (albedo_prime, eta) pair (at most 8 tables; with more distinct materials every coefficient is
    computed by direct quadrature). Node positions are fixed, so a value does not depend on the other
    elements of the call beyond the < 4e-11 interpolation error. For repeated calls with one material, hold a
    :class:`CurvatureTable`.
    """
    check_policy(policy)
    if (phi is None) == (cos2phi is None):
        raise ValueError("give exactly one of phi and cos2phi")
    alb, eta = check_material(albedo_prime, eta)
    ang = phi if cos2phi is None else cos2phi
    angle_kw = "phi" if cos2phi is None else "cos2phi"
    kw = {"policy": policy, "return_validity": return_validity, "tol": tol}
    rho = np.asarray(rho_opt, dtype=np.float64)
    rmax = float(np.max(rho)) if rho.size else 0.0
    if not (math.isfinite(rmax) and (rho.size == 0 or float(np.min(rho)) >= 0)):
        raise ValueError("rho_opt must be finite and >= 0")
    if alb.ndim == 0 and eta.ndim == 0:  # the common case: one material, no copies
        table = CurvatureTable(float(alb), float(eta), min(rmax, _RHO_TABLE_MAX))
        return table.profile(rho, k1_opt=k1_opt, k2_opt=k2_opt, **{angle_kw: ang}, **kw)
    arrs = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (rho, ang, k1_opt, k2_opt)), alb, eta)
    shape = arrs[0].shape
    flat = [np.ascontiguousarray(x).ravel() for x in arrs]
    out = np.empty(flat[0].size)
    valid = np.ones(flat[0].size, dtype=np.bool_)
    if out.size:
        uniq, inv = np.unique(np.stack([flat[4], flat[5]], axis=1), axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        for g, (a_g, e_g) in enumerate(uniq):
            sel = inv == g
            part = [x[sel] for x in flat[:4]]
            extent = min(float(part[0].max()), _RHO_TABLE_MAX) if len(uniq) <= _MAX_TABLES_PER_CALL else 0.0
            table = CurvatureTable(float(a_g), float(e_g), extent)
            res = table.profile(part[0], k1_opt=part[2], k2_opt=part[3], **{angle_kw: part[1]}, **kw)
            if return_validity:
                out[sel], valid[sel] = res
            else:
                out[sel] = res
    if return_validity:
        return out.reshape(shape), valid.reshape(shape)
    return out.reshape(shape)
