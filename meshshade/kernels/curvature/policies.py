"""Positivity policies of the first-order curvature kernel: the map ``R/R_d = f(delta)`` (docs/physics.md §7.6).

The first-order relative correction ``delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho)`` (dimensionless;
:mod:`meshshade.kernels.curvature.coefficients`) is turned into a positive factor of the planar dipole R_d:

* ``"exp"``: ``f = exp(min(delta, 700))``, identical to ``1 + delta`` to first order;
* ``"clamp"``: ``f = max(1 + delta, 0)``, the raw first order wherever it is positive;
* ``"soft"`` (the default of :func:`~meshshade.kernels.curvature.profile.curvature_profile`): delta saturates
  smoothly as ``delta / sqrt(1 + (delta / DELTA_SAT)^2)`` before exponentiation, so that far outside
  first-order range (e.g. 20 mm from a 10 mm feature) the correction stays within ``e^{+-DELTA_SAT}`` of the
  dipole instead of growing like ``e^{k C(rho)}``; identical to "exp" up to ``-delta^3/8``.

Each map and the entry-point cap is defined once, as a compiled scalar function (:func:`policy_exponent`,
:func:`policy_factor`, :func:`entry_point_cap`); every evaluation of the curved kernel calls them: the profile
loop of :mod:`meshshade.kernels.curvature.table`, the bake's pair evaluation
(:func:`~meshshade.kernels.curvature.table.curved_dipole`) and :func:`curvature_factor`. Measured errors of each
policy: :mod:`meshshade.kernels.curvature.profile`.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["DELTA_SAT", "POLICIES", "curvature_factor", "entry_point_cap", "policy_exponent", "policy_factor"]

#: positivity policies of :func:`~meshshade.kernels.curvature.profile.curvature_profile`
POLICIES = ("soft", "exp", "clamp")
#: the policies' ids in the compiled functions
EXP, CLAMP, SOFT = 0, 1, 2
_POLICY_ID = {"exp": EXP, "clamp": CLAMP, "soft": SOFT}
#: "soft" policy: saturation level of delta (an algebraic sigmoid rather than tanh: tanh cost 34 ns per pair in the
#: compiled loop, this ~3 ns)
DELTA_SAT = 2.0
INV_SAT = 1.0 / DELTA_SAT
#: exp(700) ~ 1e304: the exponent's ceiling, which keeps R_d exp(delta) finite before the cap
DELTA_MAX = 700.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def policy_exponent(delta, policy):
    """The first-order correction as the policy uses it: for "soft" ``delta / sqrt(1 + (delta / DELTA_SAT)^2)``
    (the exponent), for "exp" and "clamp" delta itself (their factors are ``exp(min(., DELTA_MAX))`` and
    ``max(1 + ., 0)``)."""
    if policy == SOFT:
        return delta / math.sqrt(1.0 + (delta * INV_SAT) * (delta * INV_SAT))
    return delta


@numba.njit(cache=True, error_model="numpy", inline="always")
def policy_factor(delta, policy):
    """The positivity map ``R/R_d = f(delta)`` of one value (module docstring)."""
    if policy == CLAMP:
        return max(1.0 + delta, 0.0)
    return math.exp(min(policy_exponent(delta, policy), DELTA_MAX))


@numba.njit(cache=True, error_model="numpy", inline="always")
def entry_point_cap(value, rd0, k_sum, a0, policy):
    """``value`` (the curved kernel of one pair, any unit) capped at the kernel's entry-point value
    ``rd0 f(max((k1 + k2) a(0), 0))`` (docs/physics.md §7.6): ``rd0`` the dipole's R_d(0) in the unit of
    ``value``, ``k_sum = k1 + k2`` and ``a0 = a(0)`` in optical units. Reachable only where delta is large."""
    if value > rd0:
        cap = rd0 * policy_factor(max(k_sum * a0, 0.0), policy)
        if value > cap:
            return cap
    return value


@numba.njit(cache=True, error_model="numpy")
def _factor_many(delta, policy, out):
    for k in range(delta.size):
        out[k] = policy_factor(delta[k], policy)


def check_policy(policy):
    """Raise ValueError unless ``policy`` is one of :data:`POLICIES`; return its id in the compiled loop."""
    if policy not in _POLICY_ID:
        raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
    return _POLICY_ID[policy]


def curvature_factor(delta, policy="exp"):
    """The positivity map ``R/R_d = f(delta)`` without the entry-point cap (module docstring).

    ``exp(min(delta, 700))`` ("exp"), ``max(1 + delta, 0)`` ("clamp") or
    ``exp(delta / sqrt(1 + (delta / DELTA_SAT)^2))`` ("soft"). Identity to first order; f(0) = 1 exactly.

    Parameters
    ----------
    delta : array_like of float
        First-order relative correction (dimensionless).
    policy : {"exp", "clamp", "soft"}

    Returns
    -------
    ndarray of float64, shape of delta, >= 0.
    """
    policy_id = check_policy(policy)
    delta = np.asarray(delta, dtype=np.float64)
    out = np.empty(delta.size)
    _factor_many(np.ascontiguousarray(delta).ravel(), policy_id, out)
    return out.reshape(delta.shape) if delta.ndim else out[0]
