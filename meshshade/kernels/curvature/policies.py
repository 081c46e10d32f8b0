"""Positivity policies of the first-order curvature kernel: the map ``R/R_d = f(delta)`` (docs/physics.md §7.6).

The first-order relative correction ``delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho)`` (dimensionless;
:mod:`meshshade.kernels.curvature.coefficients`) is turned into a positive factor of the planar dipole R_d:

* ``"exp"``: ``f = exp(min(delta, 700))``, identical to ``1 + delta`` to first order;
* ``"clamp"``: ``f = max(1 + delta, 0)``, the raw first order wherever it is positive;
* ``"soft"`` (the default of :func:`~meshshade.kernels.curvature.profile.curvature_profile`): delta saturates
  smoothly as ``delta / sqrt(1 + (delta / DELTA_SAT)^2)`` before exponentiation, so that far outside
  first-order range (e.g. 20 mm from a 10 mm feature) the correction stays within ``e^{+-DELTA_SAT}`` of the
  dipole instead of growing like ``e^{k C(rho)}``; identical to "exp" up to ``-delta^3/8``.

The compiled profile loop (:mod:`meshshade.kernels.curvature.table`) applies the same maps and caps the
result at the kernel's entry-point value; measured errors of each policy: :mod:`meshshade.kernels.curvature.profile`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["DELTA_SAT", "POLICIES", "curvature_factor"]

#: positivity policies of :func:`~meshshade.kernels.curvature.profile.curvature_profile`
POLICIES = ("soft", "exp", "clamp")
_POLICY_ID = {"exp": 0, "clamp": 1, "soft": 2}  # the policy argument of the compiled profile loop
#: "soft" policy: saturation level of delta (an algebraic sigmoid rather than tanh: tanh cost 34 ns per pair in the
#: compiled loop, this ~3 ns)
DELTA_SAT = 2.0
_INV_SAT = 1.0 / DELTA_SAT
_DELTA_MAX = 700.0  # exp(700) ~ 1e304: keeps R_d exp(delta) finite before the cap


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
    check_policy(policy)
    delta = np.asarray(delta, dtype=np.float64)
    if policy == "soft":
        return np.exp(delta / np.sqrt(1.0 + (delta / DELTA_SAT) ** 2))
    if policy == "exp":
        return np.exp(np.minimum(delta, _DELTA_MAX))
    return np.maximum(1.0 + delta, 0.0)
