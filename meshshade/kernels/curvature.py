"""First-order curvature kernel (physics.md e.3 (ii)), in optical units (lengths x sigma_t', curvatures / sigma_t').

The reflectance of a slightly curved surface, expanded at the entry point, with the exit point at geodesic
distance ``rho`` in direction ``phi`` from the first principal direction (principal curvatures k1, k2; k > 0
convex, i.e. outward normals, physics.md f):

    R(rho, phi) = R_d(rho) + alpha' [ k_n(phi) A(rho) + k_n(phi + pi/2) B(rho) ] + O(k^2),
    k_n(phi) = k1 cos^2 phi + k2 sin^2 phi,

    4 pi (A+B) = (rho^2/2) [ g(d_r) + z_r^2 p(d_r) - g(d_v) - z_v^2 p(d_v) ]
               + a [ mu^2 I(rho,z_v) - z_v g(d_v) + z_v rho^2 p(d_v)
                     - z_b (mu^2 e^{-mu d_v}/d_v + g(d_v) - z_v^2 p(d_v)) ],
    4 pi B     = a [ (1/rho) dI/drho (rho, z_v) + z_b g(d_v) ],        a = z_r + z_b,

with ``g(d) = (mu d + 1) e^{-mu d}/d^3``, ``p(d) = (mu^2 d^2 + 3 mu d + 3) e^{-mu d}/d^5``,
``d_r = sqrt(rho^2 + z_r^2)``, ``d_v = sqrt(rho^2 + z_v^2)`` and the auxiliary integral of physics.md e.2

    I(rho, h) = int_h^inf e^{-mu s}/s dt = int_0^inf exp(-mu (d cosh v + h sinh v)) dv,    s = sqrt(rho^2 + t^2),
    (1/rho) dI/drho = -int_h^inf g(s) dt = -int_0^inf (mu s + 1) e^{-mu s}/s^2 dv,          d = sqrt(rho^2 + h^2).

The v-forms come from ``t = rho sinh u`` shifted by ``u0 = asinh(h/rho)`` (``rho cosh(u0 + v) = d cosh v +
h sinh v``): they have no 1/rho, so rho = 0 is an ordinary point (``I(0, h) = E1(mu h)``), h = 0 gives
``K0(mu rho)`` and ``-mu K1(mu rho)/rho``, and ``s - d = 2 d sinh^2(v/2) + h sinh v`` is formed without
cancellation, so ``I e^{mu d}`` never under- or overflows. Quadrature: 16-point Gauss-Legendre on
``max(3, ceil(v_end/2))`` equal panels up to ``v_end``, where both integrands have fallen below ``e^{-40}`` of
their value at v = 0 (they are monotone and decay super-exponentially). Against 40-digit mpmath quadrature of
the t-integrals (tests/data/curvature_aux_reference.csv, 264 points, rho 0..300, h 0..12.4, mu 1e-5..3) the
error is <= 3e-15 plus the conditioning of ``e^{-mu d}`` (``~mu d eps``: 2e-14 at mu d = 60).

Domain edges of the auxiliary integrals
---------------------------------------
* rho = h = 0: ``I = +inf`` and ``(1/rho) dI/drho = -inf`` (the log and 1/rho^2 singularities of the h = 0
  case); for h > 0 both are finite at rho = 0.
* mu -> 0 (sigma_a -> 0): ``I = -gamma - ln(mu (d + h)/2) + O(mu d)`` diverges logarithmically; below
  ``mu (d + h) = 1e-20`` this closed form is used, and at mu = 0 :func:`aux_integral` returns ``+inf``.
  ``(1/rho) dI/drho`` stays finite, ``-1/(d (d + h))`` at mu = 0. Only ``mu^2 I ~ mu^2 ln(1/mu) -> 0`` enters
  A + B, so the coefficients take the limit ``mu^2 I = 0`` at mu = 0 (alpha' = 1) and are continuous there
  (difference O(mu^2 (rho^2 + z_v^2)), checked at mu = 1.7e-7). In the appendix setting (z_b = 0) this limit
  reproduces the Laplace/Poisson-kernel result ``4 pi (A0 + B0) = a^2 (2 rho^2 - a^2)/d^5`` exactly.
* large mu d: unscaled values underflow to 0 (never NaN); the coefficients and ratios are computed from
  quantities scaled by ``e^{mu rho}`` and do not underflow.

Validity policy (what :func:`curvature_profile` returns)
--------------------------------------------------------
Write ``R = R_d (1 + delta)`` with ``delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho)``, ``a = alpha' A/R_d``,
``b = alpha' B/R_d`` (optical lengths; a ~ C(rho) grows about linearly with rho, |b| << a beyond rho ~ 1). The
first-order sum ``1 + delta`` turns negative on concave surfaces once ``delta < -1`` and grows without bound on
convex ones. The default policy ``"exp"`` returns

    R = min( R_d(rho) exp(delta),  R_d(0) exp(max(delta_0, 0)) ),      delta_0 = (k1 + k2) a(0),

i.e. the first-order correction is exponentiated (ln R = ln R_d + delta: identical to first order, so the
1/R0^2 convergence to the exact solutions is kept) and the result never exceeds the kernel's own value at the
entry point of a convex surface (the exact sphere's profile is largest at theta = 0). It is positive,
monotone in delta, finite for every finite input (delta is clipped at 700), and R_d itself when
k1 = k2 = 0. ``"clamp"`` returns ``R_d max(1 + delta, 0)`` under the same cap (the raw first order wherever
it is positive). The validity measure is

    nu = max(|k1|, |k2|) (|a(rho)| + |b(rho)| + z_r),     z_r = 1 (one transport length),

which bounds |delta| in every direction and adds the ``|k| z_r`` that governs the second-order error near
the entry point (where a and b are small). Measured maximum relative errors against the exact sphere
(convex; physics.md c) and the exact spherical cavity (concave, medium outside a sphere; the exterior K-type
series in tests/test_curvature_kernel.py) over 5 materials (skin eta 1.3 and 1.0, marble R, potato B,
ketchup G), radii 3-1000 mm and geodesic distances 0.25-30 mm (1550 pairs):

    nu <=          0.05            0.1             0.25            0.5             1
    "exp"    sph   2.6e-4          1.3e-3          8.5e-3          2.4e-2          9.4e-2
             cav   2.7e-4          1.5e-3          1.1e-2          4.3e-2          0.30
    "clamp"  sph   9.4e-4          3.3e-3          2.1e-2          7.6e-2          0.24
             cav   9.9e-4          3.7e-3          2.8e-2          0.13            0.67
    dipole   sph   4.0e-2          8.4e-2          0.20            0.36            0.60    (R_d at geodesic rho)
             cav   4.1e-2          9.5e-2          0.27            0.66            2.2

The exact R/R_d grows faster than linearly in delta on both sides (``1 + delta + beta delta^2``, beta ~
0.1-0.35), which is why the exponentiated form beats the clamped sum everywhere. :func:`curvature_validity`
(default tol 0.25, ~1 % error) flags where nu exceeds tol; there the kernel is a smooth, bounded
extrapolation, not physics: callers should blend to the exact sphere where the surface is locally spherical.

Performance
-----------
:class:`CurvatureTable` tabulates the smooth ratios ``a(rho)``, ``b(rho)`` per material as piecewise
Chebyshev interpolants of degree 7 in ``u = sqrt(rho)`` on intervals of width 1/16 (fixed node positions, so a
value does not depend on the table's extent; 115 intervals, 15 kB for 50 transport lengths), evaluated by
Estrin's scheme. Interpolation error against direct quadrature, relative to ``|a| + |b|``: 1e-12 .. 3e-11
over the materials tested (:meth:`CurvatureTable.max_interpolation_error`). Beyond the table the coefficients
are computed directly (exact, about 3 us each). R_d is the closed form with ``e^delta`` folded into its two
exponentials (no exponential more than the dipole), and cos(2 phi) is a branch-free polynomial (within 2e-16
of libm). :func:`curvature_profile` builds a table per call (about 2 ms for 50 transport lengths).
Measured by tools/bench_curvature.py (1e6 pairs, skin, rho <= 50 mm, |k| <= 0.1/mm): 22-26 ns per pair for
curvature_profile with phi, 20-24 ns with cos2phi, against 29-34 ns for the numpy ``dipole_profile``
(ratio 0.7-0.9) and 9-11 ns for the same dipole in a bare compiled loop (ratio 2.0-2.9). The floor of the
latter ratio is the table lookup: its 16 gathered coefficients do not vectorise (about 6 ns per pair).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from meshshade.kernels.optics import diffusion_params

__all__ = [
    "POLICIES",
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

#: positivity policies of :func:`curvature_profile` (module docstring)
POLICIES = ("soft", "exp", "clamp")
_POLICY_ID = {"exp": 0, "clamp": 1, "soft": 2}
#: "soft" policy: delta saturates smoothly as delta / sqrt(1 + (delta / DELTA_SAT)^2) before exponentiation, so
#: that far outside first-order range (nu >> tol, e.g. 20 mm from a 10 mm feature) the correction stays within
#: e^{+-DELTA_SAT} of the dipole instead of growing like e^{k C(rho)}; identical to "exp" up to -delta^3/8.
#: (An algebraic sigmoid rather than tanh: tanh cost 34 ns per pair in the compiled loop, this ~3 ns.)
DELTA_SAT = 2.0
_INV_SAT = 1.0 / DELTA_SAT

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_GL_X = 0.5 * (_GL_X + 1.0)  # nodes on [0, 1]
_GL_W = 0.5 * _GL_W
_LOG_CUT = 40.0  # integrands are integrated until they fall below e^-40 of their value at v = 0
_PANEL = 2.0  # panel width in v
_MIN_PANELS = 3
_MU_SMALL = 1e-20  # below mu (d + h) = 1e-20 the integrals take their small-mu closed forms
_EULER_GAMMA = 0.5772156649015329
_DELTA_MAX = 700.0  # exp(700) ~ 1e304: keeps R_d exp(delta) finite before the cap
_MU_RHO_ZERO = 1500.0  # beyond the table and mu rho >= 1500 the kernel is 0 in float64 whatever delta is
_RHO_TABLE_MAX = 4096.0  # tables built by curvature_profile stop here (1025 intervals); beyond: direct
_VALIDITY_TOL = 0.25

# table layout: piecewise Chebyshev (degree _DEG) in u = sqrt(rho) on intervals of width 1/_PER_UNIT
_DEG = 7
_PER_UNIT = 16
_MAX_TABLES_PER_CALL = 8


# ---------------------------------------------------------------------------------------------------------
# compiled core: auxiliary integrals
# ---------------------------------------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------------------------------------
# compiled core: coefficients A, B and the dipole, scaled by e^{mu rho}
# ---------------------------------------------------------------------------------------------------------

@numba.njit(cache=True, error_model="numpy")
def _coeffs_scaled(rho, mu, z_r, z_b):
    """``4 pi e^{mu rho} (A, B, R_d/alpha')`` at distance rho (physics.md e.3 (ii); z_b = 0 gives (i))."""
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
def _ratios_direct(rho, mu, z_r, z_b):
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


# ---------------------------------------------------------------------------------------------------------
# compiled core: Chebyshev table and the fused profile loop
# ---------------------------------------------------------------------------------------------------------

@numba.njit(cache=True, error_model="numpy")
def _build_table(n_int, mu, z_r, z_b, cheb_t, to_mono, out):
    """out[i, 2 j + c]: coefficient of t^j (t in [-1, 1]) of a (c = 0) and b (c = 1) on interval i."""
    npt = cheb_t.size
    du = 1.0 / _PER_UNIT
    vals = np.empty((npt, 2))
    for i in range(n_int):
        for q in range(npt):
            u = (i + 0.5 * (cheb_t[q] + 1.0)) * du
            ra, rb = _ratios_direct(u * u, mu, z_r, z_b)
            vals[q, 0] = ra
            vals[q, 1] = rb
        for j in range(npt):
            for c in range(2):
                acc = 0.0
                for q in range(npt):
                    acc += to_mono[j, q] * vals[q, c]
                out[i, 2 * j + c] = acc


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def _table_eval(u, coef):
    """(a, b) from the piece containing u = 16 sqrt(rho), 0 <= u < n_int (Estrin's scheme, degree 7)."""
    iu = np.uint64(u)  # unsigned: no negative-index wraparound code
    t = 2.0 * (u - iu) - 1.0
    t2 = t * t
    t4 = t2 * t2
    c = coef[iu]
    ra = ((c[0] + c[2] * t) + t2 * (c[4] + c[6] * t)) + t4 * ((c[8] + c[10] * t) + t2 * (c[12] + c[14] * t))
    rb = ((c[1] + c[3] * t) + t2 * (c[5] + c[7] * t)) + t4 * ((c[9] + c[11] * t) + t2 * (c[13] + c[15] * t))
    return ra, rb


@numba.njit(cache=True, error_model="numpy", inline="always")
def _table_ratios(rho, coef, n_int, mu, z_r, z_b):
    """Tabulated (a, b) at rho; direct quadrature beyond the table."""
    u = math.sqrt(rho) * _PER_UNIT
    if u >= n_int:
        return _ratios_direct(rho, mu, z_r, z_b)
    return _table_eval(u, coef)


# cos(x) for the kernel's cos(2 phi): fdlibm-style reduction by pi/2 (33 + 53 bit split of pi/2, exact products
# for |n| < 2^20) and Taylor polynomials on |r| <= pi/4 (truncation < 3e-18); within 1e-16 of libm's cos and,
# being branch- and call-free, about 2x cheaper on random angles. Domain |x| < 2^19 pi/2 (the caller checks).
_PIO2_HI = 1.57079632673412561417e+00
_PIO2_LO = 6.07710050650619224932e-11
_COS_C = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(1, 9))  # r^2 .. r^16
_SIN_C = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(1, 9))  # r^3 .. r^17
_TWO_OVER_PI = 2.0 / math.pi
_QUAD_COS = np.array([1.0, 0.0, -1.0, 0.0])  # cos(r + q pi/2) = QUAD_COS[q] cos r + QUAD_SIN[q] sin r
_QUAD_SIN = np.array([0.0, -1.0, 0.0, 1.0])
_PHI_MAX = 4.0e5  # |phi| bound of the kernel (2 phi < 2^19 pi/2); angles are meant to be in [-pi, pi]


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def _cos(x):
    n = math.floor(x * _TWO_OVER_PI + 0.5)
    r = (x - n * _PIO2_HI) - n * _PIO2_LO
    z = r * r
    z2 = z * z
    z4 = z2 * z2
    C, S = _COS_C, _SIN_C  # Estrin's scheme: short dependency chains
    c = 1.0 + z * (((C[0] + C[1] * z) + z2 * (C[2] + C[3] * z)) + z4 * ((C[4] + C[5] * z) + z2 * (C[6] + C[7] * z)))
    sn = r + (r * z) * (((S[0] + S[1] * z) + z2 * (S[2] + S[3] * z))
                        + z4 * ((S[4] + S[5] * z) + z2 * (S[6] + S[7] * z)))
    q = n & 3  # quadrant; branch-free selection (random angles would mispredict branches)
    return c * _QUAD_COS[q] + sn * _QUAD_SIN[q]


@numba.njit(cache=True, error_model="numpy")
def _cos_many(x, out):
    for k in range(x.size):
        out[k] = _cos(x[k])


_BLOCK = 512  # pairs per block of the profile loop (its scratch arrays stay in L1)


@numba.njit(cache=True, error_model="numpy")
def _dipole_exp_block(rho, dl, out, pre, mu, z_r, z_v):
    """Pass 2 of :func:`_profile_loop`, "exp": the dipole's closed form with e^delta folded into its exponentials.

    A separate, non-inlined, branch-free loop over views: as lean as the bare dipole loop."""
    for j in range(rho.size):
        r2 = rho[j] * rho[j]
        d_r = math.sqrt(r2 + z_r * z_r)
        d_v = math.sqrt(r2 + z_v * z_v)
        x = min(dl[j], _DELTA_MAX)
        out[j] = pre * (z_r * ((mu * d_r + 1.0) * math.exp(x - mu * d_r) / (d_r * d_r * d_r))
                        + z_v * ((mu * d_v + 1.0) * math.exp(x - mu * d_v) / (d_v * d_v * d_v)))


@numba.njit(cache=True, error_model="numpy")
def _dipole_clamp_block(rho, dl, out, pre, mu, z_r, z_v):
    """Pass 2 of :func:`_profile_loop`, "clamp": the dipole times max(1 + delta, 0)."""
    for j in range(rho.size):
        r2 = rho[j] * rho[j]
        d_r = math.sqrt(r2 + z_r * z_r)
        d_v = math.sqrt(r2 + z_v * z_v)
        out[j] = pre * (z_r * ((mu * d_r + 1.0) * math.exp(-mu * d_r) / (d_r * d_r * d_r))
                        + z_v * ((mu * d_v + 1.0) * math.exp(-mu * d_v) / (d_v * d_v * d_v))) * max(1.0 + dl[j], 0.0)


@numba.njit(cache=True, error_model="numpy", fastmath={"contract"})
def _profile_loop(rho, ang, k1, k2, ang_is_cos2, policy, coef, n_int, alb, mu, z_r, z_b, a0, tol, valid, out):
    """Compiled kernel: R_d (closed form) times the policy factor of delta (tabulated a, b).

    Per block of pairs: (0) the input checks and cos(2 phi) (branch- and call-free, SIMD); (1) delta from the
    table (scalar: the gathers do not vectorise), the validity mask and the rare direct evaluations beyond
    the table; (2) :func:`_dipole_exp_block`, i.e. ``alpha'/(4 pi) sum_i z_i (mu d_i + 1) e^{delta - mu d_i}/d_i^3``
    for "exp": no exponential more than the dipole; (3) the entry-point cap (rarely active). ``valid`` (size
    of rho, or 0 to skip) receives ``max(|k1|, |k2|) (|a| + |b| + z_r) <= tol``. Returns True (the caller
    raises) on a negative or non-finite rho, a non-finite phi or |phi| > _PHI_MAX, or a non-finite delta
    (non-finite k or cos2phi).
    """
    z_v = z_r + 2.0 * z_b
    pre = alb / (4.0 * math.pi)
    rd0 = pre * (z_r * ((mu * z_r + 1.0) * math.exp(-mu * z_r) / (z_r * z_r * z_r))
                 + z_v * ((mu * z_v + 1.0) * math.exp(-mu * z_v) / (z_v * z_v * z_v)))
    want_valid = valid.size == rho.size
    n = rho.size
    cs = np.empty(_BLOCK)
    dl = np.empty(_BLOCK)
    for start in range(0, n, _BLOCK):
        m = min(_BLOCK, n - start)
        # pass 0: checks and cos(2 phi)
        ok = True
        for j in range(m):
            r = rho[start + j]
            ok &= (r >= 0.0) & (r < math.inf)
        if ang_is_cos2:
            for j in range(m):
                cs[j] = ang[start + j]
        else:
            for j in range(m):
                a = ang[start + j]
                ok &= abs(a) <= _PHI_MAX
                cs[j] = _cos(2.0 * a)
        if not ok:
            return True
        # pass 1: delta
        for j in range(m):
            k = start + j
            c1 = k1[k]
            c2 = k2[k]
            if c1 == 0.0 and c2 == 0.0:
                dl[j] = 0.0
                if want_valid:
                    valid[k] = True
                continue
            r = rho[k]
            u = math.sqrt(r) * _PER_UNIT
            if u < n_int:
                ra, rb = _table_eval(u, coef)
            elif r * mu >= _MU_RHO_ZERO:
                ra = 0.0  # R_d e^delta <= e^{700 - mu rho} underflows to 0 whatever a, b are
                rb = 0.0
            else:
                ra, rb = _ratios_direct(r, mu, z_r, z_b)
            delta = 0.5 * (c1 + c2) * (ra + rb) + 0.5 * (c1 - c2) * cs[j] * (ra - rb)
            if not (abs(delta) < math.inf):
                return True
            if policy == 2:
                delta = delta / math.sqrt(1.0 + (delta * _INV_SAT) * (delta * _INV_SAT))
            dl[j] = delta
            if want_valid:
                valid[k] = max(abs(c1), abs(c2)) * (abs(ra) + abs(rb) + z_r) <= tol
        # pass 2: the dipole with e^delta (or times max(1 + delta, 0))
        if policy != 1:
            _dipole_exp_block(rho[start:start + m], dl[:m], out[start:start + m], pre, mu, z_r, z_v)
        else:
            _dipole_clamp_block(rho[start:start + m], dl[:m], out[start:start + m], pre, mu, z_r, z_v)
        # pass 3: cap at the kernel's entry-point value (reachable only where delta is large)
        for j in range(m):
            k = start + j
            if out[k] > rd0:
                d0 = max((k1[k] + k2[k]) * a0, 0.0)
                if policy == 2:
                    d0 = d0 / math.sqrt(1.0 + (d0 * _INV_SAT) * (d0 * _INV_SAT))
                cap = rd0 * (math.exp(min(d0, _DELTA_MAX)) if policy != 1 else 1.0 + d0)
                if out[k] > cap:
                    out[k] = cap
    return False


# ---------------------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------------------

def _cheb_to_monomial(deg):
    """Chebyshev nodes of the first kind on [-1, 1] and the matrix: node values -> monomial coefficients."""
    npt = deg + 1
    k = np.arange(npt)
    t = np.cos(np.pi * (k + 0.5) / npt)
    # values -> Chebyshev coefficients (discrete orthogonality), then Chebyshev -> monomial
    T = np.cos(np.outer(np.arange(npt), np.pi * (k + 0.5) / npt))  # T[j, q] = T_j(t_q)
    vals_to_cheb = (2.0 / npt) * T
    vals_to_cheb[0] *= 0.5
    cheb_to_mono = np.zeros((npt, npt))
    for j in range(npt):
        e = np.zeros(npt)
        e[j] = 1.0
        mono = np.polynomial.chebyshev.cheb2poly(e)
        cheb_to_mono[: mono.size, j] = mono
    return t, cheb_to_mono @ vals_to_cheb


_CHEB_T, _TO_MONO = _cheb_to_monomial(_DEG)


def _check_nonneg_finite(name, arr):
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be finite and >= 0")


def _material_scalars(albedo_prime, eta):
    p = diffusion_params(albedo_prime, eta)
    return (float(p.albedo_prime), float(p.mu), float(p.z_r), float(p.z_b))


def _check_material(albedo_prime, eta):
    a = np.asarray(albedo_prime, dtype=np.float64)
    e = np.asarray(eta, dtype=np.float64)
    if not np.all(np.isfinite(a)) or np.any((a < 0) | (a > 1)):
        raise ValueError("albedo_prime must lie in [0, 1]")
    if not np.all(np.isfinite(e)) or np.any(e <= 0):
        raise ValueError("eta must be finite and > 0")
    return a, e


# ---------------------------------------------------------------------------------------------------------
# public API: auxiliary integral
# ---------------------------------------------------------------------------------------------------------

def aux_integral(rho, h, mu):
    """Auxiliary integral I(rho, h) of physics.md e.2 (optical units).

    Defined as ``int_h^inf exp(-mu s)/s dt`` with ``s = sqrt(rho^2 + t^2)``; equal to
    ``int_0^inf J0(q rho) e^{-h sqrt(q^2+mu^2)} q dq/(q^2+mu^2)``, to ``K0(mu rho)`` at h = 0 and to
    ``E1(mu h)`` at rho = 0.

    Parameters
    ----------
    rho, h, mu : array_like of float, finite and >= 0
        Lateral distance, height (z + a in physics.md e.1; the kernel uses h = z_v) and
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
    """``(1/rho) dI/drho`` of physics.md e.2 (optical units), computed without cancellation.

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


# ---------------------------------------------------------------------------------------------------------
# public API: coefficients
# ---------------------------------------------------------------------------------------------------------

def _coeff_arrays(rho_opt, albedo_prime, eta, z_b_override=None):
    rho = np.asarray(rho_opt, dtype=np.float64)
    _check_nonneg_finite("rho_opt", rho)
    albedo_prime, eta = _check_material(albedo_prime, eta)
    p = diffusion_params(albedo_prime, eta)
    z_b = p.z_b if z_b_override is None else np.asarray(z_b_override, dtype=np.float64)
    r, alb, mu, z_r, zb = np.broadcast_arrays(rho, p.albedo_prime, p.mu, p.z_r, z_b)
    shape = r.shape
    r, alb, mu, z_r, zb = (np.ascontiguousarray(x, dtype=np.float64).ravel() for x in (r, alb, mu, z_r, zb))
    outs = [np.empty(r.size) for _ in range(4)]
    with np.errstate(under="ignore"):
        _coeffs_many(r, mu, z_r, zb, alb, *outs)
    return [o.reshape(shape) for o in outs]


def curvature_coefficients(rho_opt, *, albedo_prime, eta):
    """First-order curvature coefficients ``(A, B)`` of physics.md e.3 (ii), optical units.

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
    """``C(rho) = alpha' (A + B)/R_d`` (physics.md e.3), optical length units.

    For a sphere of radius R0 (k1 = k2 = 1/R0) the first-order kernel is ``R_d (1 + C/R0)``. In mm:
    ``C_mm = C_opt / sigma_t'`` (skin test case: 1.127 mm at s = 1 mm, 15.89 mm at 20 mm).
    """
    a, b = curvature_ratios(rho_opt, albedo_prime=albedo_prime, eta=eta)
    return a + b


def curvature_validity(rho_opt, k_opt, *, albedo_prime, eta, tol=_VALIDITY_TOL):
    """True where the first-order kernel is inside its validity range: ``|k| (|a| + |b| + z_r) <= tol``.

    ``k_opt`` is the largest absolute principal curvature, ``max(|k1|, |k2|)/sigma_t'``. The measure bounds
    ``|delta|`` in every direction (``|a| + |b|``) and adds ``|k| z_r`` (z_r = 1: curvature radius against
    one transport length), which governs the second-order error near the entry point, where a and b are
    small. Measured maximum errors of the "exp" policy by tol: module docstring (0.1 -> 0.14 %,
    0.25 -> 1.1 %).
    """
    a, b = curvature_ratios(rho_opt, albedo_prime=albedo_prime, eta=eta)
    k = np.abs(np.asarray(k_opt, dtype=np.float64))
    return k * (np.abs(a) + np.abs(b) + 1.0) <= tol


def curvature_factor(delta, policy="exp"):
    """The positivity map ``R/R_d = f(delta)`` without the entry-point cap: ``exp(min(delta, 700))`` ("exp")
    or ``max(1 + delta, 0)`` ("clamp"). Identity to first order; f(0) = 1 exactly."""
    if policy not in _POLICY_ID:
        raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
    delta = np.asarray(delta, dtype=np.float64)
    if policy == "soft":
        return np.exp(delta / np.sqrt(1.0 + (delta / DELTA_SAT) ** 2))
    if policy == "exp":
        return np.exp(np.minimum(delta, _DELTA_MAX))
    return np.maximum(1.0 + delta, 0.0)


# ---------------------------------------------------------------------------------------------------------
# public API: table and profile
# ---------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, repr=False)
class CurvatureTable:
    """Per-material table of the ratios a(rho), b(rho) for fast evaluation of the curved kernel.

    Parameters
    ----------
    albedo_prime : float in [0, 1]
        Reduced albedo sigma_s'/sigma_t'.
    eta : float > 0
        Relative index of refraction.
    rho_max_opt : float, finite, >= 0
        Largest distance (times sigma_t') served from the table; larger distances are computed by direct
        quadrature (about 5 us each) or, where ``mu rho >= 1500``, need no coefficients (the kernel is 0).

    Notes
    -----
    The table holds ``ceil(16 sqrt(rho_max_opt)) + 1`` intervals of degree-7 polynomials in ``u = sqrt(rho)``
    (256 bytes per interval for a and b together) at fixed positions ``u in [i/16, (i+1)/16]``, built from
    Chebyshev nodes by direct quadrature (about 8 evaluations per interval: 4 ms for rho_max_opt = 50).
    """

    albedo_prime: float
    eta: float
    rho_max_opt: float
    coef: np.ndarray = field(init=False, compare=False)
    mu: float = field(init=False)
    z_r: float = field(init=False)
    z_b: float = field(init=False)
    a0: float = field(init=False)

    def __post_init__(self):
        _check_material(self.albedo_prime, self.eta)
        if np.ndim(self.albedo_prime) or np.ndim(self.eta):
            raise ValueError("CurvatureTable takes a single material (scalar albedo_prime and eta)")
        rmax = float(self.rho_max_opt)
        if not (math.isfinite(rmax) and rmax >= 0):
            raise ValueError(f"rho_max_opt must be finite and >= 0, got {self.rho_max_opt!r}")
        alb, mu, z_r, z_b = _material_scalars(self.albedo_prime, self.eta)
        n_int = int(math.ceil(math.sqrt(rmax) * _PER_UNIT)) + 1
        coef = np.empty((n_int, 2 * (_DEG + 1)))
        _build_table(n_int, mu, z_r, z_b, _CHEB_T, _TO_MONO, coef)
        coef.flags.writeable = False
        a0, _ = _ratios_direct(0.0, mu, z_r, z_b)
        for name, val in (("albedo_prime", alb), ("eta", float(self.eta)), ("rho_max_opt", rmax), ("coef", coef),
                          ("mu", mu), ("z_r", z_r), ("z_b", z_b), ("a0", float(a0))):
            object.__setattr__(self, name, val)

    def __repr__(self):
        return (f"CurvatureTable(albedo_prime={self.albedo_prime!r}, eta={self.eta!r}, "
                f"rho_max_opt={self.rho_max_opt!r}, intervals={self.n_intervals}, degree={_DEG}, mu={self.mu:.6g})")

    @property
    def n_intervals(self) -> int:
        """Number of polynomial pieces."""
        return self.coef.shape[0]

    def ratios(self, rho_opt):
        """Tabulated ``(a, b)`` of :func:`curvature_ratios` at rho_opt (direct quadrature beyond the table)."""
        rho = np.asarray(rho_opt, dtype=np.float64)
        _check_nonneg_finite("rho_opt", rho)
        flat = np.ascontiguousarray(rho).ravel()
        a = np.empty(flat.size)
        b = np.empty(flat.size)
        _ratios_table_many(flat, self.coef, self.n_intervals, self.mu, self.z_r, self.z_b, a, b)
        return a.reshape(rho.shape), b.reshape(rho.shape)

    def validity(self, rho_opt, k_opt, tol=_VALIDITY_TOL):
        """:func:`curvature_validity` from the table; ``k_opt = max(|k1|, |k2|)/sigma_t'``."""
        a, b = self.ratios(rho_opt)
        return np.abs(np.asarray(k_opt, dtype=np.float64)) * (np.abs(a) + np.abs(b) + self.z_r) <= tol

    def profile(self, rho_opt, phi=None, *, k1_opt, k2_opt, cos2phi=None, policy="soft", return_validity=False,
                tol=_VALIDITY_TOL):
        """Curved kernel R (optical units) as :func:`curvature_profile`, from this table (same arguments)."""
        if policy not in _POLICY_ID:
            raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
        if (phi is None) == (cos2phi is None):
            raise ValueError("give exactly one of phi and cos2phi")
        ang = phi if cos2phi is None else cos2phi
        arrs = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (rho_opt, ang, k1_opt, k2_opt)))
        shape = arrs[0].shape
        r, ang, c1, c2 = (np.ascontiguousarray(x).ravel() for x in arrs)
        out = np.empty(r.size)
        valid = np.empty(r.size if return_validity else 0, dtype=np.bool_)
        bad = _profile_loop(r, ang, c1, c2, cos2phi is not None, _POLICY_ID[policy], self.coef, self.n_intervals,
                            self.albedo_prime, self.mu, self.z_r, self.z_b, self.a0, float(tol), valid, out)
        if bad:
            raise ValueError("rho_opt must be finite and >= 0; k1_opt, k2_opt and cos2phi must be finite; "
                             f"phi must be finite with |phi| <= {_PHI_MAX:g} (reduce angles modulo 2 pi)")
        if return_validity:
            return out.reshape(shape), valid.reshape(shape)
        return out.reshape(shape)

    def max_interpolation_error(self, n=4000, seed=0):
        """Max over ``n`` random points in [0, rho_max] (uniform in sqrt(rho)) plus the interval ends of
        ``max(|a_tab - a|, |b_tab - b|)/(|a| + |b|)`` against direct quadrature."""
        rng = np.random.default_rng(seed)
        u = np.concatenate([rng.random(n) * math.sqrt(self.rho_max_opt),
                            np.arange(self.n_intervals) / _PER_UNIT])
        rho = u * u
        ta, tb = self.ratios(rho)
        da, db = curvature_ratios(rho, albedo_prime=self.albedo_prime, eta=self.eta)
        return float(np.max(np.maximum(np.abs(ta - da), np.abs(tb - db)) / (np.abs(da) + np.abs(db))))


@numba.njit(cache=True, error_model="numpy")
def _ratios_table_many(rho, coef, n_int, mu, z_r, z_b, out_a, out_b):
    for k in range(rho.size):
        ra, rb = _table_ratios(rho[k], coef, n_int, mu, z_r, z_b)
        out_a[k] = ra
        out_b[k] = rb


def curvature_profile(rho_opt, phi=None, *, k1_opt, k2_opt, albedo_prime, eta, cos2phi=None, policy="soft",
                      return_validity=False, tol=_VALIDITY_TOL):
    """Curved-surface diffuse reflectance R in optical units (first order in k, physics.md e.3 (ii)).

    Defined as ``R_d(rho) f(delta)`` with ``delta = k_n(phi) a(rho) + k_n(phi + pi/2) b(rho)``,
    ``k_n(phi) = k1 cos^2 phi + k2 sin^2 phi``, i.e. ``delta = H (a + b) + dk cos(2 phi) (a - b)`` with
    ``H = (k1 + k2)/2``, ``dk = (k1 - k2)/2``, and the positivity policy of the module docstring ("exp":
    ``f = exp``; "clamp": ``f = max(1 + delta, 0)``; both capped at the kernel's entry-point value). Equal to
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
    policy : {"exp", "clamp"}
    return_validity : bool
        Also return the boolean mask ``max(|k1|, |k2|) (|a| + |b| + z_r) <= tol`` (:func:`curvature_validity`).
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
    if policy not in _POLICY_ID:
        raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
    if (phi is None) == (cos2phi is None):
        raise ValueError("give exactly one of phi and cos2phi")
    alb, eta = _check_material(albedo_prime, eta)
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
