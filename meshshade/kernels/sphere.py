"""Exact diffusion reflectance of a sphere (docs/physics.md §5), in optical units.

The medium is the ball ``r < R0``; the fluence vanishes on the extrapolated sphere ``r = R = R0 + z_b``; a
point source sits on the axis at depth ``delta`` below the entry point, ``r' = R0 - delta`` (``delta = z_r``
unless the sphere is smaller than one transport length, see below). The reflectance is the outward diffusion
flux on the *physical* sphere ``r = R0`` (docs/physics.md eqs. (23)-(24)):

    R_sph(theta) = alpha'/(4 pi) [ g(d) (delta + 2 r' sin^2(theta/2))  +  sum_m c_m P_m(cos theta) ],
    d^2 = delta^2 + 4 R0 r' sin^2(theta/2),
    c_m = (2m+1) I_nu(mu r') K_nu(mu R) / (I_nu(mu R) sqrt(r' R0)) [mu I_{nu+1}(mu R0) + m I_nu(mu R0)/R0],

with ``nu = m + 1/2`` and ``g(d) = (mu d + 1) e^{-mu d}/d^3``. Every length is in transport mean free paths
(times sigma_t'), so ``z_r = 1`` and the only material inputs are ``albedo_prime`` and ``eta``.

Evaluation (docs/physics.md §5.4, in a form that is also exact at mu = 0)
-------------------------------------------------------------------------
I and K are never formed. With ``x1 = mu r'``, ``x0 = mu R0``, ``xR = mu R`` the kernel uses the *scaled*
ratios

    tt_m(x) = I_{nu+1}(x) / (x I_nu(x))      backward:  tt_{m-1} = 1 / ((2m+1) + x^2 tt_m)
    uu_m(x) = x K_{nu+1}(x) / K_nu(x)        forward:   uu_m = x^2 / uu_{m-1} + (2m+1),  uu_0 = 1 + x

(``t = x tt`` and ``u = uu/x`` are the ``t_nu``, ``u_nu`` of docs/physics.md eq. (26)).
Their x -> 0 limits are finite and are
reached by the same recurrences without a branch: ``tt_m -> 1/(2m+3)``, ``uu_m -> 2m+1``. The coefficients
are then

    c_m = (2m+1) P_m W_m B_m,
    P_m = Q_m / sqrt(r' R0):  P_0 = e^{-mu (delta + 2 z_b)} f(x1) f(x0) / (R f(xR)^2),
                              P_{m+1} = P_m q tt_m(x1) tt_m(x0) / tt_m(xR)^2,     q = r' R0 / R^2,
    W_m = I_nu(xR) K_nu(xR): W_0 = f(xR),  W_{m+1} = W_m tt_m(xR) uu_m(xR),
    B_m = mu t_m(x0) + m/R0 = mu^2 R0 tt_m(x0) + m/R0,

with ``f(x) = (1 - e^{-2x})/(2x)`` (``f(0) = 1``). At mu = 0 this gives ``c_m = m q^m / (R0 R)``, the Kelvin
image of Laplace's equation, and ``c_0 = 0``: there is no 0/0 anywhere. The ``tt`` tables are built once per
call by backward recurrence from ``max(M, ceil(xR)) + 64`` (``M`` the term budget), where the error of the
start guess is damped by at least ``t^2 <= (sqrt 2 - 1)^2 ~ 0.17`` per step, i.e. 1e-49 after 64 steps (a
tighter start than the ``M + 60 + 2x`` of docs/physics.md §5.4, checked against mpmath).
The tables are streamed in blocks
from checkpoints, so memory stays O(M/512) even for 10^7 terms. Legendre polynomials come from the forward
recurrence rewritten for ``D_m = P_m - P_{m-1}`` with ``y = 2 sin^2(theta/2)``
(``D_{m+1} = (m D_m - (2m+1) y P_m)/(m+1)``), so angles near 0 are not rounded through ``cos theta``
(for theta > pi/2 the reflection ``P_m(-x) = (-1)^m P_m(x)`` is used).

Truncation rule
---------------
All c_m are positive and ``|P_m| <= 1``, so the truncation error at every theta is at most the tail of the
theta = 0 sum, and ``R_sph(0) * 4 pi / alpha' = g(delta) delta + sum c_m`` is the natural scale. The ratio
``c_{m+1}/c_m`` decreases monotonically towards ``q = r' R0/R^2 ~ 1 - z_v/R0`` (Gaussian-like decay
``exp(-nu^2 z_v/(2 mu R0^2))`` while nu < mu R0, geometric beyond). The sum stops after term m as soon as,
for 3 successive m, the geometric tail bound ``c_m rho/(1 - rho)`` with ``rho = max(c_m/c_{m-1}, q)`` is at
most ``rtol`` times the running theta = 0 sum. So ``rtol`` bounds the truncation error relative to the peak
``R_sph(0)``, uniformly in theta. The term budget is predicted as

    M = 1.3 (ln(1/rtol) + 3) / (-ln q) + 0.6 mu R + 64        (~ (R0/z_v) ln(1/rtol) + O(mu R))

(the ``mu R/2`` term covers the Gaussian regime: ``L/z_v + mu/2 >= sqrt(2 mu L/z_v)``); if the tail test
has not passed within M terms the budget is doubled and the sum restarted (never observed: over random
parameters N/M stays below 0.75, median 0.5).

Accuracy, domain and policies
-----------------------------
* Against 38-193 digit mpmath references (tests/data/sphere_reference.csv) at rtol = 1e-15, the error is
  essentially *absolute*, a fraction of the peak R_sph(0): measured 5e-16 at R0 = 2, 2-3e-15 at R0 = 200-1000,
  1.2e-14 at R0 = 1e4 (rounding grows like sqrt(N)); hence relative errors <= 3e-14 (R0 <= 1000) and
  1.2e-13 (R0 = 1e4) wherever ``R_sph >= 1e-3 R_sph(0)``. Far from the entry point the value comes from
  cancellation in the Legendre sum and only the absolute bound holds, plus the truncation error
  ``<= rtol R_sph(0)``. Where the true value is below that level (e.g. theta ~ pi on a sphere much larger than
  1/mu), the result is noise of that size, and negative noise is returned as 0 (the exact value is positive).
* ``mu -> 0`` (alpha' = 1): exact, through the scaled ratios above; continuous in mu.
* ``R0 < z_r`` (sphere smaller than one transport length): the source cannot sit at depth z_r. It is placed
  at the centre, ``r' = max(R0 - z_r, 0)``, i.e. ``delta = min(z_r, R0)``, and the same exact Green's function
  is used (only the m = 0 term survives at r' = 0). This keeps the source inside the medium, is continuous at
  R0 = z_r, and conserves energy (``sphere_total_reflectance`` uses the same delta). Diffusion theory is not
  accurate at such sizes; the policy only guarantees a finite, non-negative, energy-consistent answer.
* The cost is O(N (1 + n_theta)) with N ~ (R0/z_v) ln(1/rtol) + mu R/2: about 5e3 terms at R0 = 1000 mm of
  skin and rtol = 1e-10, 5e4 at 1e4 mm. For R0/z_v >~ 50, docs/physics.md §5.5 recommends the first-order curvature
  kernel as a cheaper approximation.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from meshshade.errors import MaterialError
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.optics import check_material, diffusion_params, g_func

_BLOCK = 512  # m-block for the streamed ratio tables and the theta loop
_RUN = 3  # successive passing tail tests before stopping
_RTOL_MIN = 1e-16


# --------------------------------------------------------------------------------------------------
# compiled core
# --------------------------------------------------------------------------------------------------
@njit(cache=True)
def _tt_checkpoints(x1, xe, xR, m_top, n_blocks):
    """tt_m at m = (k+1)*_BLOCK, k < n_blocks, for the three arguments, by backward recurrence from m_top.

    The three independent recurrences share one loop so that their division latencies overlap.
    """
    a2, b2, c2 = x1 * x1, xe * xe, xR * xR
    cp = np.empty((n_blocks, 3))
    a = m_top + 1.5  # nu + 1 at nu = m_top + 1/2
    t1 = 1.0 / (a + math.sqrt(a * a + a2))
    te = 1.0 / (a + math.sqrt(a * a + b2))
    tR = 1.0 / (a + math.sqrt(a * a + c2))
    for m in range(m_top, 0, -1):
        if m % _BLOCK == 0:
            k = m // _BLOCK - 1
            if k < n_blocks:
                cp[k, 0] = t1
                cp[k, 1] = te
                cp[k, 2] = tR
        w = 2 * m + 1.0
        t1 = 1.0 / (w + a2 * t1)
        te = 1.0 / (w + b2 * te)
        tR = 1.0 / (w + c2 * tR)
    return cp


@njit(cache=True)
def _tt_block(a2, b2, c2, k, cp, buf):
    """buf[j, :] = tt_{k*_BLOCK + j} from the checkpoints tt_{(k+1)*_BLOCK} (same arithmetic as the first pass)."""
    t1, te, tR = cp[k, 0], cp[k, 1], cp[k, 2]
    lo = k * _BLOCK
    for m in range((k + 1) * _BLOCK, lo, -1):
        w = 2 * m + 1.0
        t1 = 1.0 / (w + a2 * t1)
        te = 1.0 / (w + b2 * te)
        tR = 1.0 / (w + c2 * tR)
        buf[m - 1 - lo, 0] = t1
        buf[m - 1 - lo, 1] = te
        buf[m - 1 - lo, 2] = tR


@njit(cache=True)
def _series_core(y, n_plain, x1, xe, xR, p0, w0, q, mu2re, inv_re, flux, scale0, rtol, m_budget, out):
    """Sum_m c_m P_m(cos theta_i) into out[i]; returns the number of terms used, or -1 if m_budget is too small.

    y[i] = 2 sin^2(theta_i/2) for i < n_plain (theta <= pi/2) and 2 cos^2(theta_i/2) beyond (theta > pi/2,
    summed with (-1)^m). Coefficients c_m = (2m+1) P_m W_m B_m with B_m = mu2re tt_m(xe) + m inv_re if flux
    else 1 (fluence). scale0 (> 0) is the free-space part of the theta = 0 value, where the running sum of the
    tail test starts.
    """
    n_th = y.shape[0]
    n_blocks = (m_budget + _BLOCK - 1) // _BLOCK
    m_top = max(n_blocks * _BLOCK, int(math.ceil(xR))) + 64
    cp = _tt_checkpoints(x1, xe, xR, m_top, n_blocks)
    tb = np.empty((_BLOCK, 3))
    cb = np.empty(_BLOCK)
    ca = np.empty(_BLOCK)  # m/(m+1)
    cc = np.empty(_BLOCK)  # (2m+1)/(m+1)
    Pm = np.ones(n_th)  # P_m(x_i)
    Dm = np.zeros(n_th)  # P_m - P_{m-1}
    for i in range(n_th):
        out[i] = 0.0
    a2, b2, c2 = x1 * x1, xe * xe, xR * xR
    P = p0
    W = w0
    uu = 1.0 + xR
    S = scale0
    c_prev = 0.0
    run = 0
    n_used = -1
    for k in range(n_blocks):
        _tt_block(a2, b2, c2, k, cp, tb)
        nb = _BLOCK
        for j in range(_BLOCK):
            m = k * _BLOCK + j
            if flux:
                c = (2 * m + 1) * P * W * (mu2re * tb[j, 1] + m * inv_re)
            else:
                c = (2 * m + 1) * P * W
            cb[j] = c
            ca[j] = m / (m + 1.0)
            cc[j] = (2 * m + 1.0) / (m + 1.0)
            S += c
            if m == 0:
                if q == 0.0:  # source at the centre: only m = 0 is non-zero
                    n_used = 1
            else:
                if c_prev > 0.0:
                    rho = c / c_prev
                elif c == 0.0:
                    rho = 0.0
                else:
                    rho = np.inf
                if rho < q:
                    rho = q
                if rho < 1.0 and c * rho / (1.0 - rho) <= rtol * S:
                    run += 1
                else:
                    run = 0
                if run >= _RUN:
                    n_used = m + 1
            if n_used > 0:
                nb = j + 1
                break
            c_prev = c
            tR = tb[j, 2]
            P = P * q * (tb[j, 0] * tb[j, 1]) / (tR * tR)
            W = W * tR * uu
            uu = c2 / uu + (2 * m + 3)
        # Legendre recurrence D_{m+1} = (m D_m - (2m+1) y P_m)/(m+1), P_{m+1} = P_m + D_{m+1}, for every angle;
        # the inner loop runs over independent angles (vectorisable, no division)
        for j in range(nb):
            c = cb[j]
            cs = -c if (k * _BLOCK + j) & 1 else c
            aj = ca[j]
            bj = cc[j]
            for i in range(n_plain):
                p = Pm[i]
                out[i] += c * p
                d = aj * Dm[i] - bj * y[i] * p
                Dm[i] = d
                Pm[i] = p + d
            for i in range(n_plain, n_th):
                p = Pm[i]
                out[i] += cs * p
                d = aj * Dm[i] - bj * y[i] * p
                Dm[i] = d
                Pm[i] = p + d
        if n_used > 0:
            return n_used
    return -1


# --------------------------------------------------------------------------------------------------
# set-up shared by the public functions
# --------------------------------------------------------------------------------------------------
def _f(x):
    """(1 - e^{-2x})/(2x), with f(0) = 1 (scalar)."""
    return 1.0 if x == 0.0 else -math.expm1(-2.0 * x) / (2.0 * x)


def _check_scalar(name, value, *, lo=None, hi=None, lo_open=False, err=ValueError):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise err(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and v > hi):
        rng = f"{'(' if lo_open else '['}{lo}, {hi if hi is not None else 'inf'}]"
        raise err(f"{name} must be finite and in {rng}, got {value!r}")
    return v


def _material(albedo_prime, eta):
    a = _check_scalar("albedo_prime", albedo_prime, lo=0.0, hi=1.0, err=MaterialError)
    e = _check_scalar("eta", eta, lo=0.0, lo_open=True, err=MaterialError)
    p = diffusion_params(a, e)
    return a, float(p.mu), float(p.z_r), float(p.z_b)


def _geometry(R0_opt, z_r):
    """(R0, delta, r') with the small-sphere policy delta = min(z_r, R0) (source at the centre if R0 <= z_r)."""
    R0 = _check_scalar("R0_opt", R0_opt, lo=0.0, lo_open=True)
    delta = min(z_r, R0)
    return R0, delta, R0 - delta


def _angles(theta):
    """(shape, sin^2(theta/2), (y, n_plain, order)) for _series_core: angles <= pi/2 first, then the others."""
    th = np.asarray(theta, dtype=np.float64)
    flat = th.ravel()
    if not np.all((flat >= 0.0) & (flat <= np.pi)):  # also rejects NaN
        raise ValueError("theta must lie in [0, pi] (polar angle from the entry point)")
    half = 0.5 * flat
    flip = flat > 0.5 * np.pi
    y = np.where(flip, 2.0 * np.cos(half) ** 2, 2.0 * np.sin(half) ** 2)
    order = np.argsort(flip, kind="stable")  # theta <= pi/2 first (see _series_core)
    return th.shape, np.sin(half) ** 2, (y[order], int(np.count_nonzero(~flip)), order)


def _series(yy, *, R0, r_src, r_e, gape, delta, z_b, mu, flux, scale0, rtol):
    """Run the compiled sum with a predicted term budget, doubling it if the tail test has not passed.

    ``r_e`` is the evaluation radius and ``gape = R - r_e`` (passed separately to avoid cancellation).
    """
    rtol = _check_scalar("rtol", rtol, lo=_RTOL_MIN, hi=0.5)
    R = R0 + z_b
    gap1 = delta + z_b  # R - r'
    x1, xe, xR = mu * r_src, mu * r_e, mu * R
    p0 = math.exp(-mu * (gap1 + gape)) * _f(x1) * _f(xe) / (R * _f(xR) ** 2)
    w0 = _f(xR)
    q = r_src * r_e / (R * R)
    if q > 0.0:
        neg_ln_q = math.log1p((R * gap1 + r_src * gape) / (r_src * r_e))  # ln(R^2/(r' r_e)), R^2 - r' r_e exact
        budget = 1.3 * (math.log(1.0 / rtol) + 3.0) / neg_ln_q + 0.6 * xR + 64.0
    else:
        budget = 1.0
    m_budget = int(min(budget, 2.0**40))
    y, n_plain, order = yy
    tmp = np.empty(y.shape[0])
    while True:
        n = _series_core(y, n_plain, x1, xe, xR, p0, w0, q, mu * mu * r_e, 1.0 / r_e, flux, scale0, rtol, m_budget,
                         tmp)
        if n > 0:
            out = np.empty_like(tmp)
            out[order] = tmp
            return out, n
        m_budget *= 2


def _flux_profile(theta, R0, delta, z_b, mu, rtol):
    """4 pi R_sph/alpha' (S = 1 flux), any delta in (0, R0] and z_b >= 0; also returns the number of terms."""
    shape, s2, yy = _angles(theta)
    r_src = R0 - delta
    d = np.sqrt(delta * delta + 4.0 * R0 * r_src * s2)
    with np.errstate(under="ignore"):
        free = g_func(d, mu) * (delta + 2.0 * r_src * s2)
        scale0 = float(g_func(delta, mu)) * delta
    series, n = _series(yy, R0=R0, r_src=r_src, r_e=R0, gape=z_b, delta=delta, z_b=z_b, mu=mu, flux=True,
                        scale0=scale0, rtol=rtol)
    return np.maximum(free + series, 0.0).reshape(shape), n


# --------------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------------
def sphere_series_profile(theta, *, R0_opt, albedo_prime, eta, rtol=1e-10):
    """Exact-sphere diffuse reflectance R_sph(theta) in optical units (docs/physics.md eq. (23), stable recipe of §5.4).

    Defined as ``alpha'/(4 pi) [g(d)(delta + 2 r' sin^2(theta/2)) + sum_m c_m P_m(cos theta)]`` (see the
    module docstring): the outward diffusion flux on the physical sphere r = R0 for a source of strength
    alpha' (Jensen normalisation) at depth ``delta = min(z_r, R0)`` below the entry point, Dirichlet condition
    on r = R0 + z_b.

    Parameters
    ----------
    theta : array_like of float in [0, pi]
        Polar angle between the entry and exit points, seen from the centre (geodesic distance s = R0 theta).
    R0_opt : float > 0
        Sphere radius times sigma_t'. Below z_r = 1 the source is placed at the centre (module docstring).
    albedo_prime : float in [0, 1]
        Reduced albedo sigma_s'/sigma_t'; 1 (mu = 0) is handled exactly.
    eta : float in [1, 2.5] (:func:`meshshade.kernels.optics.check_eta`)
        Relative index of refraction.
    rtol : float in [1e-16, 0.5]
        Truncation tolerance relative to the peak R_sph(0), uniform in theta (module docstring).

    Returns
    -------
    ndarray of float64, shape of ``theta``
        ``R_sph / sigma_t'**2`` (dimensionless), >= 0. Multiply by sigma_t'^2 [mm^-2] for reflectance per
        unit incident power per mm^2.

    Raises
    ------
    MaterialError for albedo_prime or eta out of range; ValueError for R0_opt, theta or rtol out of range.
    """
    a, mu, z_r, z_b = _material(albedo_prime, eta)
    R0, delta, _ = _geometry(R0_opt, z_r)
    val, _ = _flux_profile(theta, R0, delta, z_b, mu, rtol)
    return a / (4.0 * np.pi) * val


def sphere_series_terms(*, R0_opt, albedo_prime, eta, rtol=1e-10):
    """Number of series terms N (m = 0 .. N-1) that :func:`sphere_series_profile` sums for these parameters.

    Independent of theta. Grows like ``(R0/z_v) ln(1/rtol) + O(mu R)`` (docs/physics.md eq. (31)); for example about
    5.2e3 for skin (alpha' = 1/1.01, eta = 1.3) at R0 = 1000 mm (R0_opt = 1010) and rtol = 1e-10.
    """
    _, mu, z_r, z_b = _material(albedo_prime, eta)
    R0, delta, _ = _geometry(R0_opt, z_r)
    return _flux_profile(np.zeros(0), R0, delta, z_b, mu, rtol)[1]


def _energy_T(R0, delta, z_b, mu):
    """T of docs/physics.md eq. (33), exp-scaled; broadcasting arrays. int R_sph dA = alpha' T."""
    R0, delta, z_b, mu = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (R0, delta, z_b, mu)))
    a = mu * (R0 - delta)  # mu r'
    b = mu * R0
    c = mu * (R0 + z_b)
    with np.errstate(divide="ignore", invalid="ignore", under="ignore"):
        fa = np.where(a > 0, -np.expm1(-2.0 * a) / (2.0 * a), 1.0)  # e^{-a} sinh(a)/a
        # h(b) = e^{-b} (b cosh b - sinh b): series sum_k 2k b^{2k+1}/(2k+1)! below b = 1 (cancellation)
        bs = np.minimum(b, 1.0)  # the series branch is only used below 1
        hs = np.zeros_like(b)
        term = bs.copy()
        for k in range(1, 14):
            term = term * bs * bs / ((2 * k) * (2 * k + 1))
            hs = hs + 2 * k * term
        hs = hs * np.exp(-bs)
        hd = 0.5 * (b * (1.0 + np.exp(-2.0 * b)) + np.expm1(-2.0 * b))
        h = np.where(b < 1.0, hs, hd)
        sh = -0.5 * np.expm1(-2.0 * c)  # e^{-c} sinh(c)
        ratio = np.where(c > 0, h / sh, 0.0)  # -> b^3/(3c) -> 0 as mu -> 0
        t1 = (b + 1.0) * fa * np.exp(-mu * delta)
        t2 = np.exp(-mu * (delta + 2.0 * z_b)) * fa * ratio
    return t1 + t2


def sphere_total_reflectance(*, R0_opt, albedo_prime, eta):
    """Total diffuse reflectance of the exact sphere, ``int R_sph dA = alpha' T`` (docs/physics.md eq. (33)).

    Defined as ``alpha' sinh(mu r')/(mu r') [(mu R0 + 1) e^{-mu R0} + e^{-mu R}(mu R0 cosh mu R0 - sinh mu R0)
    / sinh mu R]`` with ``r' = R0 - delta``, ``R = R0 + z_b``, evaluated in exp-scaled form (no overflow at any
    R0; the bracket's small-mu R0 cancellation is summed as a series). Tends to the planar value
    ``(alpha'/2)(e^{-mu z_r} + e^{-mu z_v})`` as R0 -> inf and to alpha' as mu -> 0; always <= alpha'.
    Broadcasts like a ufunc over its (array_like) arguments; dimensionless.
    """
    a, e = check_material(albedo_prime, eta)
    R0 = np.asarray(R0_opt, dtype=np.float64)
    if not np.all(np.isfinite(R0) & (R0 > 0)):
        raise ValueError("R0_opt must be finite and > 0")
    p = diffusion_params(a, e)
    delta = np.minimum(p.z_r, R0)
    return p.albedo_prime * _energy_T(R0, delta, p.z_b, p.mu)


def sphere_chord_dipole_profile(theta, *, R0_opt, albedo_prime, eta):
    """Jensen's usage on a sphere: the planar dipole at the chord, ``R_d(2 R0 sin(theta/2))``
    (docs/physics.md eq. (18)).

    theta in [0, pi] as for :func:`sphere_series_profile`; returns ``R_d / sigma_t'**2``, shape of theta.
    """
    th = np.asarray(theta, dtype=np.float64)
    return dipole_profile(2.0 * float(R0_opt) * np.sin(0.5 * th), albedo_prime=albedo_prime, eta=eta)


def _sphere_fluence(r_opt, theta, *, R0_opt, albedo_prime, eta, rtol=1e-14):
    """Fluence Psi(r, theta) per unit source (S = 1) in optical units, for r' < r <= R (private; for tests).

    ``Psi = 1/(4 pi D) [e^{-mu d}/d - sum_m (2m+1) I_nu(mu r') I_nu(mu r) K_nu(mu R)/(I_nu(mu R) sqrt(r r'))
    P_m]``, ``d^2 = (r - r')^2 + 4 r r' sin^2(theta/2)`` (docs/physics.md eq. (22)),
    with the same ratio recurrences as the reflectance. Vanishes on r = R = R0 + z_b. D = 1/3 in optical units.
    """
    _, mu, z_r, z_b = _material(albedo_prime, eta)
    R0, delta, r_src = _geometry(R0_opt, z_r)
    r = float(r_opt)
    R = R0 + z_b
    if not r_src < r <= R:
        raise ValueError(f"r_opt must lie in (r', R] = ({r_src}, {R}]")
    shape, s2, yy = _angles(theta)
    gap = r - r_src
    d = np.sqrt(gap * gap + 4.0 * r * r_src * s2)
    free = np.exp(-mu * d) / d
    series, _ = _series(yy, R0=R0, r_src=r_src, r_e=r, gape=R - r, delta=delta, z_b=z_b, mu=mu, flux=False,
                        scale0=math.exp(-mu * gap) / gap, rtol=rtol)
    return (3.0 / (4.0 * np.pi) * (free - series)).reshape(shape)


def sphere_point_source_exitance(theta, *, R0_opt, depth_opt, mu, D, z_b, c_phi, c_E, rtol=1e-10):
    """Exitance ``C_phi Psi + C_E (-D dPsi/dr)`` on the physical sphere r = R0 of a unit isotropic point source
    at depth ``t`` on the axis under the entry point (docs/physics.md eq. (77)), Psi = 0 on r = R0 + z_b.

    The sphere's exact Green's function (docs/physics.md eqs. (22)-(23)) for any source depth and any dipole
    variant: ``mu``, ``D``, ``z_b``, ``c_phi``, ``c_E`` as in :class:`meshshade.kernels.beam_diffusion.DipoleVariant`
    (Jensen's reflectance is ``alpha'`` times this with ``c_phi = 0``, ``c_E = 1``, ``t = z_r``). The flux is
    :func:`sphere_series_profile`'s series, the fluence the same sum with the fluence coefficients. A source
    deeper than the centre (R0 < t < 2 R0) is the mirror case seen from the antipode; one at t >= 2 R0 lies
    outside the ball and gives 0. As R0 -> inf this tends to the half-space's
    :func:`meshshade.kernels.beam_diffusion.point_source_reflectance`.

    theta : polar angle(s) in [0, pi] from the entry point; R0_opt, depth_opt > 0 (optical units);
    rtol : truncation tolerance of each series relative to its theta = 0 scale. Returns float64, shape of theta.
    """
    R0 = _check_scalar("R0_opt", R0_opt, lo=0.0, lo_open=True)
    t = _check_scalar("depth_opt", depth_opt, lo=0.0, lo_open=True)
    mu = _check_scalar("mu", mu, lo=0.0)
    D = _check_scalar("D", D, lo=0.0, lo_open=True)
    z_b = _check_scalar("z_b", z_b, lo=0.0)
    th = np.asarray(theta, dtype=np.float64)
    if t >= 2.0 * R0:
        _angles(th)   # validates theta
        return np.zeros(th.shape)
    if t > R0:   # past the centre: the same problem seen from the antipode
        t, th = 2.0 * R0 - t, np.pi - th
    shape, s2, yy = _angles(th)
    out = np.zeros(th.size)
    if c_E:
        E, _ = _flux_profile(th, R0, t, z_b, mu, rtol)
        out += float(c_E) / (4.0 * np.pi) * E.ravel()
    if c_phi:
        r_src = R0 - t
        d = np.sqrt(t * t + 4.0 * R0 * r_src * s2)
        with np.errstate(under="ignore"):
            free = np.exp(-mu * d) / d
        series, _ = _series(yy, R0=R0, r_src=r_src, r_e=R0, gape=z_b, delta=t, z_b=z_b, mu=mu, flux=False,
                            scale0=math.exp(-mu * t) / t, rtol=rtol)
        out += float(c_phi) / (4.0 * np.pi * D) * (free - series)
    return np.maximum(out, 0.0).reshape(shape)
