"""First-order curvature kernel (docs/physics.md eqs. (49)-(50)),
in optical units (lengths x sigma_t', curvatures / sigma_t').

One concept per module, each importing only the ones above it:

* :mod:`~meshshade.kernels.curvature.auxiliary`: the auxiliary integral I(rho, h) of docs/physics.md §7.2 and
  ``(1/rho) dI/drho`` (compiled Gauss-Legendre quadrature);
* :mod:`~meshshade.kernels.curvature.coefficients`: the coefficients A, B, the ratios a, b to R_d, C(rho) and
  the validity measure (``VALIDITY_TOL``);
* :mod:`~meshshade.kernels.curvature.policies`: the positivity policies "soft", "exp", "clamp" (``R/R_d = f(delta)``);
* :mod:`~meshshade.kernels.curvature.table`: :class:`CurvatureTable`, the per-material Chebyshev table of a, b
  and the compiled profile loop over it;
* :mod:`~meshshade.kernels.curvature.profile`: :func:`curvature_profile`, the kernel itself, and its validity
  policy with the measured errors.

The names below are re-exported here: ``from meshshade.kernels.curvature import curvature_profile``.
"""
from meshshade.kernels.curvature.auxiliary import aux_integral, aux_integral_drho_over_rho
from meshshade.kernels.curvature.coefficients import (VALIDITY_TOL, _coeffs_scaled, curvature_coefficients,
                                                      curvature_ratios, curvature_relative_coefficient,
                                                      curvature_validity)
from meshshade.kernels.curvature.policies import DELTA_SAT, POLICIES, curvature_factor
from meshshade.kernels.curvature.profile import curvature_profile
from meshshade.kernels.curvature.table import CurvatureTable, _cos_many

__all__ = [
    "DELTA_SAT",
    "POLICIES",
    "VALIDITY_TOL",
    "CurvatureTable",
    "aux_integral",
    "aux_integral_drho_over_rho",
    "curvature_coefficients",
    "curvature_factor",
    "curvature_profile",
    "curvature_ratios",
    "curvature_relative_coefficient",
    "curvature_validity",
]
# _coeffs_scaled and _cos_many (compiled internals) are re-exported for tests/kernels/test_curvature_kernel.py,
# which reaches them as attributes of this package.
