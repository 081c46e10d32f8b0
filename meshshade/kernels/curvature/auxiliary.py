"""Auxiliary integral of docs/physics.md §7.2 and its rho-derivative, in optical units (lengths x sigma_t').

The first-order curvature coefficients (:mod:`meshshade.kernels.curvature.coefficients`) need

    I(rho, h) = int_h^inf e^{-mu s}/s dt = int_0^inf exp(-mu (d cosh v + h sinh v)) dv,    s = sqrt(rho^2 + t^2),
    (1/rho) dI/drho = -int_h^inf g(s) dt = -int_0^inf (mu s + 1) e^{-mu s}/s^2 dv,          d = sqrt(rho^2 + h^2),

with ``g(d) = (mu d + 1) e^{-mu d}/d^3``. The v-forms come from ``t = rho sinh u`` shifted by
``u0 = asinh(h/rho)`` (``rho cosh(u0 + v) = d cosh v + h sinh v``): they have no 1/rho, so rho = 0 is an ordinary
point (``I(0, h) = E1(mu h)``), h = 0 gives ``K0(mu rho)`` and ``-mu K1(mu rho)/rho``, and
``s - d = 2 d sinh^2(v/2) + h sinh v`` is formed without cancellation, so ``I e^{mu d}`` never under- or
overflows. Quadrature: 16-point Gauss-Legendre on ``max(3, ceil(v_end/2))`` equal panels up to ``v_end``, where
both integrands have fallen below ``e^{-40}`` of their value at v = 0 (they are monotone and decay
super-exponentially). Against 40-digit mpmath quadrature of the t-integrals
(tests/data/curvature_aux_reference.csv, 264 points, rho 0..300, h 0..12.4, mu 1e-5..3) the error is
<= 3e-15 plus the conditioning of ``e^{-mu d}`` (``~mu d eps``: 2e-14 at mu d = 60).

Domain edges
------------
* rho = h = 0: ``I = +inf`` and ``(1/rho) dI/drho = -inf`` (the log and 1/rho^2 singularities of the h = 0
  case); for h > 0 both are finite at rho = 0.
* mu -> 0 (sigma_a -> 0): ``I = -gamma - ln(mu (d + h)/2) + O(mu d)`` diverges logarithmically; below
  ``mu (d + h) = 1e-20`` this closed form is used, and at mu = 0 :func:`aux_integral` returns ``+inf``.
  ``(1/rho) dI/drho`` stays finite, ``-1/(d (d + h))`` at mu = 0.
* large mu d: unscaled values underflow to 0 (never NaN).

Negative or non-finite rho, h or mu raise ValueError (they are distances and a decay rate, not material
parameters).
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["aux_integral", "aux_integral_drho_over_rho"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_GL_X = 0.5 * (_GL_X + 1.0)  # nodes on [0, 1]
_GL_W = 0.5 * _GL_W
_LOG_CUT = 40.0  # integrands are integrated until they fall below e^-40 of their value at v = 0
_PANEL = 2.0  # panel width in v
_MIN_PANELS = 3
_MU_SMALL = 1e-20  # below mu (d + h) = 1e-20 the integrals take their small-mu closed forms
_EULER_GAMMA = 0.5772156649015329


@numba.njit(cache=True, error_model="numpy")
def _aux_scaled(rho, h, mu):
    """``(I e^{mu d}, (1/rho) dI/drho e^{mu d})`` for rho, h, mu >= 0 (module docstring)."""
    d = math.hypot(rho, h)
    if d == 0.0:
        return math.inf, -math.inf
    if mu * (d + h) < _MU_SMALL:
        # I = E1(mu (d+h)/2) + O(mu d) = -gamma - ln(mu (d+h)/2) and J = -1/(d (d+h)) + O(mu d), both to
        # relative O(1e-20); also keeps the panel count bounded (it grows like ln(1/(mu d)))
        j = -1.0 / (d * (d + h))
        if mu == 0.0:
            return math.inf, j
        return -_EULER_GAMMA - math.log(0.5 * mu) - math.log(d + h), j  # no underflow in mu (d + h)
    # v_end: the smaller of the roots of 2 d sinh^2(v/2) = T and h sinh v = T, with T = _LOG_CUT/mu
    # (there s - d >= T, so both integrands are below e^-40 of their start; the J-integrand relative to its
    # start is (mu s + 1)/(mu d + 1) (d/s)^2 e^{-mu (s-d)} <= e^{-mu (s-d)}); at most ~50 panels
    T = _LOG_CUT / mu
    v_end = 2.0 * math.asinh(math.sqrt(0.5 * T / d))
    if h > 0.0:
        v2 = math.asinh(T / h)
        if v2 < v_end:
            v_end = v2
    n = int(math.ceil(v_end / _PANEL))
    if n < _MIN_PANELS:
        n = _MIN_PANELS
    dv = v_end / n
    acc_i = 0.0
    acc_j = 0.0
    for p in range(n):
        v0 = p * dv
        for j in range(16):
            v = v0 + _GL_X[j] * dv
            sh = math.sinh(0.5 * v)
            sd = 2.0 * d * sh * sh + h * math.sinh(v)  # s - d
            s = d + sd
            e = math.exp(-mu * sd)
            acc_i += _GL_W[j] * e
            acc_j += _GL_W[j] * (mu * s + 1.0) * e / (s * s)
    return acc_i * dv, -acc_j * dv


@numba.njit(cache=True, error_model="numpy")
def _aux_many(rho, h, mu, out_i, out_j):
    for k in range(rho.size):
        r, hh, m = rho[k], h[k], mu[k]
        si, sj = _aux_scaled(r, hh, m)
        e = math.exp(-m * math.hypot(r, hh))  # the same d as inside _aux_scaled
        out_i[k] = si * e if si != math.inf else math.inf
        out_j[k] = sj * e if sj != -math.inf else -math.inf


def _check_nonneg_finite(name, arr):
    """Raise ValueError unless every element of ``arr`` is finite and >= 0 (distances; not material errors)."""
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be finite and >= 0")


def aux_integral(rho, h, mu):
    """Auxiliary integral I(rho, h) of docs/physics.md §7.2 (optical units).

    Defined as ``int_h^inf exp(-mu s)/s dt`` with ``s = sqrt(rho^2 + t^2)``; equal to
    ``int_0^inf J0(q rho) e^{-h sqrt(q^2+mu^2)} q dq/(q^2+mu^2)``, to ``K0(mu rho)`` at h = 0 and to
    ``E1(mu h)`` at rho = 0.

    Parameters
    ----------
    rho, h, mu : array_like of float, finite and >= 0
        Lateral distance, height (z + zeta in docs/physics.md eq. (44); the kernel uses h = z_v) and
        mu = sigma_tr/sigma_t'. Broadcast together.

    Returns
    -------
    ndarray of float64, broadcast shape
        ``+inf`` where rho = h = 0 or mu = 0 (the integral diverges there); underflows to 0 for large mu d.
        Relative error ~1e-15 + mu d eps (module docstring).
    """
    i, _ = _aux_arrays(rho, h, mu)
    return i


def aux_integral_drho_over_rho(rho, h, mu):
    """``(1/rho) dI/drho`` of docs/physics.md §7.2 (optical units), computed without cancellation.

    Defined as ``-int_h^inf g(s) dt``, ``g(s) = (mu s + 1) e^{-mu s}/s^3``, ``s = sqrt(rho^2 + t^2)``; equal to
    ``-mu K1(mu rho)/rho`` at h = 0 and to ``-1/(d (d + h))`` at mu = 0 (d = sqrt(rho^2 + h^2)).

    Parameters
    ----------
    rho, h, mu : array_like of float, finite and >= 0 (broadcast together)

    Returns
    -------
    ndarray of float64, broadcast shape, <= 0
        ``-inf`` where rho = h = 0; finite at mu = 0; underflows to -0 for large mu d.
    """
    _, j = _aux_arrays(rho, h, mu)
    return j


def _aux_arrays(rho, h, mu):
    rho, h, mu = (np.asarray(x, dtype=np.float64) for x in (rho, h, mu))
    for name, arr in (("rho", rho), ("h", h), ("mu", mu)):
        _check_nonneg_finite(name, arr)
    r, hh, m = np.broadcast_arrays(rho, h, mu)
    shape = r.shape
    r, hh, m = (np.ascontiguousarray(x).ravel() for x in (r, hh, m))
    out_i = np.empty(r.size)
    out_j = np.empty(r.size)
    with np.errstate(under="ignore"):
        _aux_many(r, hh, m, out_i, out_j)
    return out_i.reshape(shape), out_j.reshape(shape)

