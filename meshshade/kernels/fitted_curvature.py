"""The fitted curvature model (docs/physics.md §14, eqs. (82)-(84)), in optical units (lengths x sigma_t',
curvatures / sigma_t').

The first-order k1/k2 kernel (§7) is a diffusion result for a point source: it holds where the curvature radius is
large against both the transport length and the distance travelled, ``nu <= 0.25`` (eq. (55)). Beyond, and near
the entry point at any curvature, Monte Carlo on curved shapes departs from it. This model keeps what is known
exactly and fits only the rest to Monte Carlo:

    R_fit(r, phi) = R_near(r) exp(S(delta(r, phi) + Q(r, phi))),                                  (82)

* ``R_near`` is the near-field base of the half-space (:mod:`meshshade.kernels.near_field`): at k1 = k2 = 0 the
  model *is* the base, exactly (every term of Q vanishes there);
* ``delta = k_n(phi) a(r) + k_n(phi + pi/2) b(r)`` is the first-order kernel's relative correction (eq. (51)), so
  ``R_fit = R_near (1 + delta) + O(k^2)`` wherever diffusion holds (r beyond a few transport lengths, where the
  near-source terms below have decayed);
* ``Q = sum_j theta_j f_j`` is linear in fitted coefficients over the features of :func:`fitted_features`
  (eq. (83)): four near-source terms of first order in k that decay within a few transport lengths (transport,
  not diffusion: Monte Carlo's response to curvature near the source is two to three times the diffusion
  kernel's there); nine terms of second order and beyond (delta^2-like, delta times k where a curvature radius near
  the transport length makes diffusion itself fail, and the twist tau of the shape operator in the direction of
  travel, which first order cannot see); three terms that move delta towards its value for a matched boundary
  (eta = 1) where |delta| or |U| is large (Monte Carlo's curvature response hardly depends on eta, the diffusion
  kernel's grows with the extrapolation distance; the switches U^2/(1 + U^2) and delta^2/(D^2 + delta^2) are of
  second order, and the fit gives the second a coefficient near 1: where |delta| >> D = 1/2 the exponent is the
  matched boundary's delta_1); and the thirteen
  base terms again times A - 1 (A the boundary mismatch of eq. (7), 0 for eta = 1), so that every coefficient may
  depend on the boundary. Per material the last group folds into the first: 16 effective coefficients;
* ``S`` is the identity for |E| <= E_LIN and saturates smoothly (C^2) towards +-E_SAT beyond it (eq. (84)), so the
  model is positive, bounded by ``R_near e^{+-E_SAT}`` and smooth for every input.

The coefficients are fitted by ``tools/tables/fit_curvature_model.py`` to the exact-shape Monte Carlo training set
(``tools/tables/curvature_training_set.py``) and stored with their provenance and held-out errors in
:mod:`meshshade.kernels.fitted_curvature_table`.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from meshshade.kernels import fitted_curvature_table as table
from meshshade.kernels.curvature import CurvatureTable
from meshshade.kernels.curvature.coefficients import ratios_direct
from meshshade.kernels.curvature.table import (MU_RHO_ZERO, PER_UNIT, PHI_MAX, cheb_to_monomial,
                                               dipole_exp_block, piece_pair)
from meshshade.kernels.dipole import dipole_diffuse_reflectance
from meshshade.kernels.near_field import near_field_profile
from meshshade.kernels.optics import diffusion_params

__all__ = ["FEATURES", "E_LIN", "E_SAT", "N_BASE", "N_SWITCH", "DELTA_SWITCH", "fitted_features", "fitted_saturation",
           "fitted_exponent", "effective_coefficients", "fitted_row_table", "near_source_functions",
           "fitted_curvature_factor", "fitted_curvature_profile", "fitted_dipole_profile", "fitted_dipole_pairs",
           "chord_curvature", "helix_chord_curvature", "matched_table", "normal_curvatures", "pair_exponent",
           "shipped_coefficients"]

#: decay lengths (transport lengths) of the near-source terms; the compiled kernel reads them from its table
#: (:func:`fitted_row_table`)
NEAR_LENGTHS = (0.3, 1.0, 3.0)
_BASE = ("H e1", "H e2", "H e3", "(ka - kc) e2", "u^2", "u v", "v^2", "u ka", "u kc", "H^2 e2", "w^2", "tau^2 e2",
         "w^2 H a")
#: number of base features (those that appear again times A - 1)
N_BASE = len(_BASE)
#: names of the features f_j of eq. (83), in the order of the coefficients
_SWITCH = ("(d1 - d) U^2/(1 + U^2)", "(d1 - d) U^3/(1 + U^2)", "(d1 - d) d^2/(D^2 + d^2)")
#: number of matched-boundary terms (between the base terms and their boundary copies)
N_SWITCH = len(_SWITCH)
FEATURES = _BASE + _SWITCH + tuple(f"(A - 1) {f}" for f in _BASE)
#: the scale D of |delta| beyond which Monte Carlo's curvature response is that of the matched boundary
DELTA_SWITCH = 0.5
#: the saturation S of eq. (84): identity up to E_LIN, then towards +-E_SAT
E_LIN = 4.0
E_SAT = 6.0


def normal_curvatures(phi, k1, k2):
    """(k_along, k_across, tau^2): the normal curvatures along the direction phi from the first principal direction
    and across it (Euler's formula, k_n(phi) and k_n(phi + pi/2)), and the square of the twist
    tau = (k1 - k2) sin(phi) cos(phi), the off-diagonal of the shape operator in the (along, across) frame.
    Arrays broadcast; each value by :func:`euler_curvatures`."""
    phi, k1, k2 = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (phi, k1, k2)))
    flat = [np.ascontiguousarray(x).ravel() for x in (phi, k1, k2)]
    out = [np.empty(flat[0].size) for _ in range(3)]
    _normal_curvatures_loop(*flat, *out)
    return tuple(x.reshape(phi.shape) if phi.ndim else x[0] for x in out)


@numba.njit(cache=True, error_model="numpy", inline="always")
def euler_curvatures(phi, k1, k2):
    """(k_along, k_across, tau^2) of one direction (:func:`normal_curvatures`): docs/physics.md eq. (3),
    ``k_n(phi) = H + dk cos 2 phi`` with ``H = (k1 + k2)/2``, ``dk = (k1 - k2)/2``, and ``tau = dk sin 2 phi``."""
    H, dk = 0.5 * (k1 + k2), 0.5 * (k1 - k2)
    c = dk * math.cos(2.0 * phi)
    tau = dk * math.sin(2.0 * phi)
    return H + c, H - c, tau * tau


@numba.njit(cache=True, error_model="numpy")
def _normal_curvatures_loop(phi, k1, k2, ka, kc, t2):
    for j in range(phi.size):
        ka[j], kc[j], t2[j] = euler_curvatures(phi[j], k1[j], k2[j])


def fitted_features(r_opt, k_along, k_across, tau2, a_opt, b_opt, a1_opt, b1_opt, A_minus_1):
    """The features f_j of eq. (83), (..., len(FEATURES)) float64 (arrays broadcast).

    a, b are the first-order ratios of the material, a1, b1 those of the same albedo with eta = 1, A - 1 the
    material's boundary mismatch minus one. With H = (ka + kc)/2, e_j = exp(-r / l_j) (l_j in NEAR_LENGTHS),
    u = ka a, v = kc a, w^2 = tau^2 a^2 (the ratio a scales every direction: it is the kernel's own length),
    delta = ka a + kc b, delta_1 = ka a1 + kc b1 and U = H a:

    ``H e1, H e2, H e3, (ka - kc) e2`` (first order, near the source); ``u^2, u v, v^2, u ka, u kc, H^2 e2, w^2,
    tau^2 e2, w^2 H a`` (second order and beyond; the twist enters squared, as symmetry requires);
    ``(delta_1 - delta) U^2/(1 + U^2)``, ``(delta_1 - delta) U^3/(1 + U^2)`` and
    ``(delta_1 - delta) delta^2/(D^2 + delta^2)`` (D = DELTA_SWITCH; third order at small k: the matched-boundary
    switches); and the first thirteen again times A - 1. Every feature is 0 at k = 0."""
    r, ka, kc, t2, a, b, a1, b1, Am1 = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (
        r_opt, k_along, k_across, tau2, a_opt, b_opt, a1_opt, b1_opt, A_minus_1)))
    H = 0.5 * (ka + kc)
    e1, e2, e3 = (np.exp(-r / length) for length in NEAR_LENGTHS)
    u, v, w2 = ka * a, kc * a, t2 * a * a
    base = [H * e1, H * e2, H * e3, (ka - kc) * e2, u * u, u * v, v * v, u * ka, u * kc, H * H * e2, w2, t2 * e2,
            w2 * H * a]
    U = H * a
    sw = U * U / (1.0 + U * U)
    delta = ka * a + kc * b
    dd = (ka * a1 + kc * b1) - delta
    d2 = delta * delta
    return np.stack(base + [dd * sw, dd * sw * U, dd * d2 / (DELTA_SWITCH ** 2 + d2)] + [Am1 * f for f in base],
                    axis=-1)


def effective_coefficients(coef, A_minus_1) -> np.ndarray:
    """The 16 per-material coefficients of the compiled kernel: the base thirteen plus (A - 1) times their
    boundary terms, then the three matched-boundary terms."""
    th = np.asarray(coef, dtype=np.float64)
    _check_coef(th)
    return np.ascontiguousarray(np.concatenate([th[:N_BASE] + float(A_minus_1) * th[N_BASE + N_SWITCH:],
                                                th[N_BASE:N_BASE + N_SWITCH]]))


def fitted_saturation(E):
    """S(E) of eq. (84): E for |E| <= E_LIN, else sign(E) (E_LIN + w tanh((|E| - E_LIN)/w)), w = E_SAT - E_LIN
    (value, slope and curvature continuous at E_LIN; |S| < E_SAT, = E_SAT once tanh rounds to 1)."""
    E = np.asarray(E, dtype=np.float64)
    w = E_SAT - E_LIN
    m = np.abs(E)
    return np.where(m <= E_LIN, E, np.sign(E) * (E_LIN + w * np.tanh((m - E_LIN) / w)))


def fitted_exponent(r_opt, k_along, k_across, tau2, a_opt, b_opt, a1_opt, b1_opt, A_minus_1, coef=None):
    """``S(delta + Q)`` of eq. (82) from the first-order ratios (optical units; arrays broadcast; arguments as
    :func:`fitted_features`); ``coef`` the theta_j (default: the shipped fit).

    The model as the fit sees it: linear in the features (tools/tables/fit_curvature_model.py fits theta with it).
    Every kernel evaluates the exponent compiled, by :func:`fitted_pair_exponent`; this numpy form is the fit's
    and the tests' oracle of that one evaluation."""
    theta = shipped_coefficients() if coef is None else np.asarray(coef, dtype=np.float64)
    _check_coef(theta)
    ka, kc, a, b = (np.asarray(x, dtype=np.float64) for x in (k_along, k_across, a_opt, b_opt))
    delta = ka * a + kc * b
    X = fitted_features(r_opt, ka, kc, tau2, a, b, a1_opt, b1_opt, A_minus_1)
    return fitted_saturation(delta + X @ theta)


def _boundary(albedo_prime, eta) -> float:
    return float(diffusion_params(albedo_prime, eta).A) - 1.0


def fitted_curvature_factor(r_opt, phi, k1_opt, k2_opt, *, albedo_prime, eta, coef=None, k_along_opt=None):
    """``R_fit / R_near = exp(S(delta + Q))`` at distance r, azimuth phi from the first principal direction and
    principal curvatures k1, k2 (optical units; arrays broadcast; scalar material). 1 exactly at k1 = k2 = 0.
    ``k_along_opt``: the curvature along the pair measured between its points (eq. (85)) instead of the entry
    point's k_n(phi). Evaluated by :func:`fitted_pair_exponent`, as every kernel of the bake."""
    r = np.asarray(r_opt, dtype=np.float64)
    ka, kc, t2 = normal_curvatures(phi, k1_opt, k2_opt)
    if k_along_opt is not None:
        ka = np.broadcast_to(np.asarray(k_along_opt, dtype=np.float64), np.broadcast(ka, k_along_opt).shape)
    r, ka, kc, t2 = np.broadcast_arrays(r, ka, kc, t2)
    if not np.all(np.isfinite(r) & (r >= 0)):
        raise ValueError("r_opt must be finite and >= 0")
    tab = CurvatureTable(albedo_prime, eta, max(float(r.max(initial=0.0)) * 1.25, 10.0))
    m1 = matched_table(tab)
    th = effective_coefficients(shipped_coefficients() if coef is None else coef, _boundary(albedo_prime, eta))
    flat = [np.ascontiguousarray(x, dtype=np.float64).ravel() for x in (r, ka, kc, t2)]
    E = np.empty(flat[0].size)
    _fitted_exponents(*flat, fitted_row_table(tab, m1, th), tab.n_intervals, tab.mu, tab.z_r, tab.z_b, m1.z_b,
                      tuple(float(x) for x in th), E)
    return np.exp(E).reshape(r.shape)


@numba.njit(cache=True, error_model="numpy")
def _fitted_exponents(rho, ka, kc, t2, row, n_int, mu, z_r, z_b, z_b1, th, out):
    for k in range(rho.size):
        out[k] = fitted_pair_exponent(rho[k], ka[k], kc[k], t2[k], row, n_int, mu, z_r, z_b, z_b1, th)


def fitted_curvature_profile(r_opt, phi, k1_opt, k2_opt, *, albedo_prime, eta, g=0.0):
    """R_fit(r, phi) of eq. (82) per unit entering power, optical units (times sigma_t'^2 for mm^-2)."""
    base = near_field_profile(r_opt, albedo_prime=albedo_prime, eta=eta, g=g)
    return base * fitted_curvature_factor(r_opt, phi, k1_opt, k2_opt, albedo_prime=albedo_prime, eta=eta)


def near_source_functions(r_opt, th):
    """The two near-source functions of the compiled kernel (optical units; ``th`` the effective coefficients):
    ``g(r) = th0 e1 + th1 e2 + th2 e3`` (the coefficient of H) and ``e2(r)``, e_j = exp(-r / l_j) (NEAR_LENGTHS)."""
    r = np.asarray(r_opt, dtype=np.float64)
    e1, e2, e3 = (np.exp(-r / length) for length in NEAR_LENGTHS)
    return th[0] * e1 + th[1] * e2 + th[2] * e3, e2


#: degree of the pieces of the matched boundary's ratios and the near-source functions in the compiled kernel's
#: table (cubic: their interpolation errors, below 1e-8 and 2e-6 of their largest values, enter the exponent only
#: through second-order switches and decaying near-source terms)
_NEAR_DEG = 3
_NEAR_T, _NEAR_TO_MONO = cheb_to_monomial(_NEAR_DEG)


def fitted_row_table(tab: CurvatureTable, matched: CurvatureTable, th) -> np.ndarray:
    """The compiled kernel's per-material table, (n_int, 32), on the curvature table's intervals (u = sqrt(r) in
    [i/16, (i+1)/16]): the material's a, b (the curvature table's degree-7 row, exact to ~1e-11) and, as cubic
    pieces, its matched boundary's a1, b1 and the near-source functions g, e2 of :func:`near_source_functions`
    (coefficient j of the four at 16 + 4 j .. 19 + 4 j). A pair reads one row (32 float64, 256 bytes) and
    evaluates no exponential beyond the dipole's."""
    if matched.n_intervals != tab.n_intervals or matched.albedo_prime != tab.albedo_prime:
        raise ValueError("the matched-boundary table must have the material's albedo and extent")
    n = tab.n_intervals
    u = (np.arange(n)[:, None] + 0.5 * (_NEAR_T[None, :] + 1.0)) / PER_UNIT        # (n, 4) Chebyshev nodes
    g, e2 = near_source_functions(u * u, th)
    # a1, b1 at the cubic's nodes from the matched table's own degree-7 pieces (t the nodes' position in a piece)
    powers = _NEAR_T[:, None] ** np.arange(matched.coef.shape[1] // 2)[None, :]      # (4, 8)
    a1, b1 = matched.coef[:, 0::2] @ powers.T, matched.coef[:, 1::2] @ powers.T
    near = np.empty((n, 4, 4))
    for f, vals in enumerate((a1, b1, g, e2)):
        near[:, :, f] = vals @ _NEAR_TO_MONO.T
    return np.ascontiguousarray(np.hstack([tab.coef, near.reshape(n, 16)]))


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def _row_at(r, row, n_int, mu, z_r, z_b, z_b1, th):
    """(a, b, a1, b1, g, e2) at r from :func:`fitted_row_table` (one row gathered: a degree-7 piece pair and four
    cubics); direct quadrature and exponentials beyond it."""
    u = math.sqrt(r) * PER_UNIT
    if u < n_int:
        iu = np.uint64(u)
        t = 2.0 * (u - iu) - 1.0
        t2 = t * t
        c = row[iu]
        ra, rb = piece_pair(c, 0, t, t2, t2 * t2)
        ra1 = (c[16] + c[20] * t) + t2 * (c[24] + c[28] * t)
        rb1 = (c[17] + c[21] * t) + t2 * (c[25] + c[29] * t)
        g = (c[18] + c[22] * t) + t2 * (c[26] + c[30] * t)
        e2 = (c[19] + c[23] * t) + t2 * (c[27] + c[31] * t)
        return ra, rb, ra1, rb1, g, e2
    if r * mu >= MU_RHO_ZERO:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    ra, rb = ratios_direct(r, mu, z_r, z_b)
    ra1, rb1 = ratios_direct(r, mu, z_r, z_b1)
    e2 = math.exp(-r / NEAR_LENGTHS[1])
    return ra, rb, ra1, rb1, th[0] * math.exp(-r / NEAR_LENGTHS[0]) + th[1] * e2 + th[2] * math.exp(
        -r / NEAR_LENGTHS[2]), e2


_D2 = DELTA_SWITCH ** 2


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def pair_exponent(ka, kc, t2, ra, rb, ra1, rb1, g, e2, th):
    """S(delta + Q) of eq. (82) for one pair (compiled; the loop below and the hierarchical far field): normal
    curvatures along and across ka, kc, squared twist t2, first-order ratios ra, rb of the material and ra1, rb1 of
    its matched boundary, the near-source functions g, e2 at the pair's distance (:func:`near_source_functions`),
    all optical units; ``th`` the 16 effective coefficients (:func:`effective_coefficients`; an array or a tuple).
    The two switches share one division. NaN in, NaN out."""
    H = 0.5 * (ka + kc)
    u = ka * ra
    v = kc * ra
    w2 = t2 * ra * ra
    delta = ka * ra + kc * rb
    U = H * ra
    dd = ka * ra1 + kc * rb1 - delta
    U2 = U * U
    d2 = delta * delta
    # dd (U^2/(1 + U^2) (th13 + th14 U) + th15 d^2/(D^2 + d^2)) over the common denominator
    sw = (U2 * (_D2 + d2) * (th[13] + th[14] * U) + th[15] * d2 * (1.0 + U2)) / ((1.0 + U2) * (_D2 + d2))
    q = (H * (g + th[9] * H * e2) + th[3] * (ka - kc) * e2
         + u * (th[4] * u + th[5] * v + th[7] * ka + th[8] * kc) + th[6] * v * v
         + w2 * (th[10] + th[12] * H * ra) + th[11] * t2 * e2 + dd * sw)
    E = delta + q
    if abs(E) > E_LIN:
        w = E_SAT - E_LIN
        E = math.copysign(E_LIN + w * math.tanh((abs(E) - E_LIN) / w), E)
    return E


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def fitted_pair_exponent(rho, ka, kc, t2, row, n_int, mu, z_r, z_b, z_b1, th):
    """S(delta + Q) of eq. (82) for one pair at distance ``rho`` with its curvatures along and across ``ka``,
    ``kc`` and squared twist ``t2`` (optical units), from one row of :func:`fitted_row_table` (``row``, ``n_int``
    intervals) and the effective coefficients ``th``; 0 for a flat pair. The one evaluation of the fitted model's
    exponent: the profile loop below and the bake's pairs (:func:`fitted_dipole`) call it."""
    if ka == 0.0 and kc == 0.0 and t2 == 0.0:
        return 0.0
    ra, rb, ra1, rb1, g, e2 = _row_at(rho, row, n_int, mu, z_r, z_b, z_b1, th)
    return pair_exponent(ka, kc, t2, ra, rb, ra1, rb1, g, e2, th)


@numba.njit(cache=True, error_model="numpy", inline="always")
def fitted_dipole(rho, ka, kc, t2, row, n_int, alb, mu, z_r, z_b, z_b1, z_v, th):
    """The fitted model on the point dipole for one pair, ``R_d(rho) exp(S(delta + Q))`` (eqs. (82)-(84),
    optical units; arguments as :func:`fitted_pair_exponent`, with the material's diffusion parameters)."""
    if rho * mu >= MU_RHO_ZERO:
        return 0.0
    E = fitted_pair_exponent(rho, ka, kc, t2, row, n_int, mu, z_r, z_b, z_b1, th)
    return dipole_diffuse_reflectance(rho, alb, mu, z_r, z_v, E)


@numba.njit(cache=True, error_model="numpy", fastmath={"contract"})
def _fitted_pairs_loop(rho, ka, kc, t2, row, n_int, alb, mu, z_r, z_b, z_b1, th, out):
    """Compiled R_d(rho) exp(S(delta + Q)) (eqs. (82)-(84) on the point dipole) over pairs with their curvatures along
    and across and squared twist, blockwise like the curved kernel's loop: (1) the exponent per pair
    (:func:`fitted_pair_exponent`); (2) the dipole with the exponent folded into its exponentials. Returns True (the
    caller raises) on a negative or non-finite rho or a non-finite exponent."""
    z_v = z_r + 2.0 * z_b
    n = rho.size
    blk = 512
    dl = np.empty(blk)
    for start in range(0, n, blk):
        m = min(blk, n - start)
        for j in range(m):
            k = start + j
            r = rho[k]
            if not ((r >= 0.0) & (r < math.inf)):
                return True
            E = fitted_pair_exponent(r, ka[k], kc[k], t2[k], row, n_int, mu, z_r, z_b, z_b1, th)
            if not (abs(E) < math.inf):
                return True
            dl[j] = E
        dipole_exp_block(rho[start:start + m], dl[:m], out[start:start + m], alb, mu, z_r, z_v)
    return False


def chord_curvature(x_src, n_src, x_rcv, n_rcv, fallback):
    """The normal-section curvature between two surface points, ``(n_r - n_s).(x_r - x_s)/|x_r - x_s|^2``
    (docs/physics.md eq. (85); 1/R on a sphere of radius R at any distance, -1/R in a cavity); ``fallback`` where
    the points coincide. All (p, 3) / (p,) arrays, any length unit (curvature in its inverse)."""
    v = np.asarray(x_rcv, dtype=np.float64) - np.asarray(x_src, dtype=np.float64)
    dn = np.asarray(n_rcv, dtype=np.float64) - np.asarray(n_src, dtype=np.float64)
    c2 = np.einsum("ij,ij->i", v, v)
    ok = c2 > 0.0
    return np.where(ok, np.einsum("ij,ij->i", dn, v) / np.where(ok, c2, 1.0), fallback)


def helix_chord_curvature(r, phi, R):
    """:func:`chord_curvature` on a cylinder of radius R between the entry point and the point at geodesic distance
    r in direction phi from the direction around the axis (all optical units or all mm): the helix's
    ``2 R (1 - cos t) / (2 R^2 (1 - cos t) + z^2)``, t = r cos(phi)/R, z = r sin(phi); k cos^2(phi) near the
    entry point (Euler's formula), less far along a helix; 1/R at r = 0."""
    r, phi, R = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (r, phi, R)))
    th = r * np.cos(phi) / R
    z = r * np.sin(phi)
    one_c = 2.0 * np.sin(0.5 * th) ** 2
    den = 2.0 * R * R * one_c + z * z
    near = np.cos(phi) ** 2 / R
    return np.where(den > 0.0, 2.0 * R * one_c / np.where(den > 0.0, den, 1.0), near)


def fitted_dipole_pairs(tab: CurvatureTable, rho_opt, k_along_opt, k_across_opt, tau2_opt, *, coef=None,
                        matched: CurvatureTable | None = None):
    """:func:`fitted_dipole_profile` with each pair's curvatures along and across and squared twist given (optical
    units; (p,) arrays): the bake's form, where the curvature along a pair is measured between its two points."""
    th = effective_coefficients(shipped_coefficients() if coef is None else coef, _boundary(tab.albedo_prime, tab.eta))
    m1 = matched_table(tab) if matched is None else matched
    r, ka, kc, t2 = (np.ascontiguousarray(x, dtype=np.float64).ravel()
                     for x in np.broadcast_arrays(rho_opt, k_along_opt, k_across_opt, tau2_opt))
    out = np.empty(r.size)
    with np.errstate(under="ignore"):
        bad = _fitted_pairs_loop(r, ka, kc, t2, fitted_row_table(tab, m1, th), tab.n_intervals, tab.albedo_prime,
                                 tab.mu, tab.z_r, tab.z_b, m1.z_b, tuple(float(x) for x in th), out)
    # the coefficients as a tuple: compiled as constants of the loop, not reloaded per pair (2 ns of ~29)
    if bad:
        raise ValueError("rho_opt must be finite and >= 0 and the curvatures finite")
    return out


def matched_table(tab: CurvatureTable) -> CurvatureTable:
    """The curvature table of ``tab``'s albedo with a matched boundary (eta = 1), over the same distances."""
    return CurvatureTable(tab.albedo_prime, 1.0, tab.rho_max_opt)


def fitted_dipole_profile(tab: CurvatureTable, rho_opt, phi=None, *, k1_opt, k2_opt, cos2phi=None, coef=None,
                          matched: CurvatureTable | None = None):
    """The fitted curvature factor on the planar dipole, ``R_d(rho) exp(S(delta + Q))`` (optical units), with the
    entry point's curvatures k1, k2 and the direction ``phi`` from the first principal direction (or ``cos2phi``),
    from ``tab``'s tabulated a, b and those of ``matched`` (:func:`matched_table`, built when not given); arguments
    as :meth:`CurvatureTable.profile`, ``coef`` the theta_j (default: the shipped fit). The bake measures each
    pair's curvatures between its points instead and calls :func:`fitted_dipole_pairs`; with the near field, as
    every model, it multiplies this by R_near/R_d (docs/physics.md eq. (80))."""
    if (phi is None) == (cos2phi is None):
        raise ValueError("give exactly one of phi and cos2phi")
    arrs = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64)
                                 for x in (rho_opt, phi if cos2phi is None else cos2phi, k1_opt, k2_opt)))
    r, ang, k1, k2 = arrs
    if cos2phi is None:
        if not np.all(np.abs(ang) <= PHI_MAX):
            raise ValueError(f"phi must be finite with |phi| <= {PHI_MAX:g}")
        ang = np.cos(2.0 * ang)
    # Euler's formula with cos 2 phi: k_n(phi) = H + (k1 - k2)/2 cos 2 phi, tau^2 = ((k1 - k2)/2)^2 (1 - cos^2 2 phi)
    H, dk = 0.5 * (k1 + k2), 0.5 * (k1 - k2)
    t2 = dk * dk * np.maximum(1.0 - ang * ang, 0.0)
    out = fitted_dipole_pairs(tab, r, H + dk * ang, H - dk * ang, t2, coef=coef, matched=matched)
    return out.reshape(r.shape)


def shipped_coefficients() -> np.ndarray:
    """The shipped coefficients, after checking they were fitted for these features."""
    if tuple(getattr(table, "FEATURES", ())) != FEATURES:
        raise ValueError("the table was fitted for other features: rerun tools/tables/fit_curvature_model.py")
    return np.asarray(table.COEF, dtype=np.float64)


def _check_coef(theta) -> None:
    if not (theta.shape == (len(FEATURES),) and np.all(np.isfinite(theta))):
        raise ValueError(f"fitted curvature coefficients must be {len(FEATURES)} finite numbers")
