"""Per-material Chebyshev table of the curvature ratios a(rho), b(rho) and the compiled profile loop over it.

:class:`CurvatureTable` tabulates the smooth ratios ``a = alpha' A/R_d`` and ``b = alpha' B/R_d``
(:mod:`meshshade.kernels.curvature.coefficients`; optical length units) per material as piecewise Chebyshev
interpolants of degree 7 in ``u = sqrt(rho)`` on intervals of width 1/16 (fixed node positions, so a value does
not depend on the table's extent; 115 intervals, 15 kB for 50 transport lengths), evaluated by Estrin's scheme.
Interpolation error against direct quadrature, relative to ``|a| + |b|``: 1e-12 .. 3e-11 over the materials
tested (:meth:`CurvatureTable.max_interpolation_error`). Beyond the table the coefficients are computed directly
(exact, about 3 us each).

:meth:`CurvatureTable.profile` evaluates the curved kernel ``R = R_d(rho) f(delta)`` (policies:
:mod:`meshshade.kernels.curvature.policies`) in one compiled loop: R_d is
:func:`~meshshade.kernels.dipole.dipole_diffuse_reflectance` with ``e^delta`` folded into its two exponentials
(no exponential more than the dipole), and cos(2 phi) is a branch-free polynomial (within 2e-16 of libm).

Performance, measured by tools/benchmarks/bench_curvature.py (1e6 pairs, skin, rho <= 50 mm, |k| <= 0.1/mm): 22-26 ns
per pair for curvature_profile with phi, 20-24 ns with cos2phi, against 9-11 ns for the dipole in a bare compiled
loop (ratio 2.0-2.9). The floor of that ratio is the table lookup: its 16 gathered coefficients do not vectorise
(about 6 ns per pair). (When the numpy ``dipole_profile`` was a numpy expression it took 29-34 ns, ratio
0.7-0.9; it now runs the same compiled closed form as the bare loop, within ~1.3x of its time on a loaded
machine.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from meshshade.errors import MaterialError
from meshshade.kernels.curvature.auxiliary import _check_nonneg_finite
from meshshade.kernels.curvature.coefficients import VALIDITY_TOL, ratios_direct, curvature_ratios
from meshshade.kernels.curvature.policies import CLAMP, DELTA_MAX, check_policy, entry_point_cap, policy_exponent
from meshshade.kernels.dipole import dipole_diffuse_reflectance
from meshshade.kernels.optics import check_material, diffusion_params

__all__ = ["CurvatureTable", "curved_dipole", "first_order_delta", "kernel_ratios"]

# table layout: piecewise Chebyshev (degree _DEG) in u = sqrt(rho) on intervals of width 1/PER_UNIT
_DEG = 7
PER_UNIT = 16
MU_RHO_ZERO = 1500.0  # beyond the table and mu rho >= 1500 the kernel is 0 in float64 whatever delta is


# ---------------------------------------------------------------------------------------------------------
# compiled core: Chebyshev table
# ---------------------------------------------------------------------------------------------------------

@numba.njit(cache=True, error_model="numpy")
def _build_table(n_int, mu, z_r, z_b, cheb_t, to_mono, out):
    """out[i, 2 j + c]: coefficient of t^j (t in [-1, 1]) of a (c = 0) and b (c = 1) on interval i."""
    npt = cheb_t.size
    du = 1.0 / PER_UNIT
    vals = np.empty((npt, 2))
    for i in range(n_int):
        for q in range(npt):
            u = (i + 0.5 * (cheb_t[q] + 1.0)) * du
            ra, rb = ratios_direct(u * u, mu, z_r, z_b)
            vals[q, 0] = ra
            vals[q, 1] = rb
        for j in range(npt):
            for c in range(2):
                acc = 0.0
                for q in range(npt):
                    acc += to_mono[j, q] * vals[q, c]
                out[i, 2 * j + c] = acc


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def piece_pair(c, o, t, t2, t4):
    """(a, b) of the interleaved degree-7 piece at ``c[o:o + 16]`` at t in [-1, 1] (Estrin's scheme)."""
    ra = (((c[o] + c[o + 2] * t) + t2 * (c[o + 4] + c[o + 6] * t))
          + t4 * ((c[o + 8] + c[o + 10] * t) + t2 * (c[o + 12] + c[o + 14] * t)))
    rb = (((c[o + 1] + c[o + 3] * t) + t2 * (c[o + 5] + c[o + 7] * t))
          + t4 * ((c[o + 9] + c[o + 11] * t) + t2 * (c[o + 13] + c[o + 15] * t)))
    return ra, rb


@numba.njit(cache=True, error_model="numpy", inline="always", fastmath={"contract"})
def _table_eval(u, coef):
    """(a, b) from the piece containing u = 16 sqrt(rho), 0 <= u < n_int (Estrin's scheme, degree 7)."""
    iu = np.uint64(u)  # unsigned: no negative-index wraparound code
    t = 2.0 * (u - iu) - 1.0
    t2 = t * t
    return piece_pair(coef[iu], 0, t, t2, t2 * t2)


@numba.njit(cache=True, error_model="numpy", inline="always")
def _table_ratios(rho, coef, n_int, mu, z_r, z_b):
    """Tabulated (a, b) at rho; direct quadrature beyond the table."""
    u = math.sqrt(rho) * PER_UNIT
    if u >= n_int:
        return ratios_direct(rho, mu, z_r, z_b)
    return _table_eval(u, coef)


@numba.njit(cache=True, error_model="numpy", inline="always")
def kernel_ratios(rho, coef, n_int, mu, z_r, z_b):
    """(a, b) as the kernel needs them at rho (optical units): tabulated (``coef``, ``n_int`` intervals of a
    :class:`CurvatureTable`), by direct quadrature beyond the table, and 0 where ``mu rho >= 1500`` (the kernel
    ``R_d e^delta <= e^(700 - mu rho)`` underflows to 0 whatever they are)."""
    u = math.sqrt(rho) * PER_UNIT
    if u < n_int:
        return _table_eval(u, coef)
    if rho * mu >= MU_RHO_ZERO:
        return 0.0, 0.0
    return ratios_direct(rho, mu, z_r, z_b)


@numba.njit(cache=True, error_model="numpy", inline="always")
def first_order_delta(k_along, k_across, ra, rb):
    """The first-order relative correction of docs/physics.md eq. (51), ``delta = k_n(phi) a + k_n(phi + pi/2) b``,
    from the normal curvatures along and across the pair's direction (optical units) and the ratios a, b."""
    return k_along * ra + k_across * rb


@numba.njit(cache=True, error_model="numpy", inline="always")
def curved_dipole(rho, k_along, k_across, coef, n_int, alb, mu, z_r, z_b, z_v, a0, rd0, policy):
    """The curved kernel of one pair, ``R_d(rho) f(delta)`` capped at its entry-point value (optical units): the
    one scalar evaluation of docs/physics.md eqs. (49)-(53) with a positivity policy
    (:mod:`~meshshade.kernels.curvature.policies`). ``k_along``, ``k_across``: the source's normal curvatures
    towards the receiver and across (optical units); ``coef``, ``n_int``, ``a0``: a :class:`CurvatureTable`'s
    coefficients, interval count and a(0); ``alb``, ``mu``, ``z_r``, ``z_b``, ``z_v``: the material's diffusion
    parameters; ``rd0`` the dipole's R_d(0)."""
    if k_along == 0.0 and k_across == 0.0:
        return dipole_diffuse_reflectance(rho, alb, mu, z_r, z_v)
    ra, rb = kernel_ratios(rho, coef, n_int, mu, z_r, z_b)
    delta = first_order_delta(k_along, k_across, ra, rb)
    if policy == CLAMP:
        out = dipole_diffuse_reflectance(rho, alb, mu, z_r, z_v) * max(1.0 + delta, 0.0)
    else:
        out = dipole_diffuse_reflectance(rho, alb, mu, z_r, z_v, min(policy_exponent(delta, policy), DELTA_MAX))
    return entry_point_cap(out, rd0, k_along + k_across, a0, policy)


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
PHI_MAX = 4.0e5  # |phi| bound of the kernel (2 phi < 2^19 pi/2); angles are meant to be in [-pi, pi]


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
def dipole_exp_block(rho, dl, out, alb, mu, z_r, z_v):
    """Pass 2 of :func:`_profile_loop`, "exp" and "soft": the dipole with e^delta folded into its exponentials.

    A separate, non-inlined, branch-free loop over views: as lean as the bare dipole loop."""
    for j in range(rho.size):
        out[j] = dipole_diffuse_reflectance(rho[j], alb, mu, z_r, z_v, min(dl[j], DELTA_MAX))


@numba.njit(cache=True, error_model="numpy")
def _dipole_clamp_block(rho, dl, out, alb, mu, z_r, z_v):
    """Pass 2 of :func:`_profile_loop`, "clamp": the dipole times max(1 + delta, 0)."""
    for j in range(rho.size):
        out[j] = dipole_diffuse_reflectance(rho[j], alb, mu, z_r, z_v) * max(1.0 + dl[j], 0.0)


@numba.njit(cache=True, error_model="numpy", fastmath={"contract"})
def _profile_loop(rho, ang, k1, k2, ang_is_cos2, policy, coef, n_int, alb, mu, z_r, z_b, a0, tol, valid, out):
    """Compiled kernel: R_d (closed form) times the policy factor of delta (tabulated a, b).

    Per block of pairs: (0) the input checks and cos(2 phi) (branch- and call-free, SIMD); (1) delta from the
    table (scalar: the gathers do not vectorise), the validity mask and the rare direct evaluations beyond
    the table; (2) :func:`dipole_exp_block`, i.e. ``alpha'/(4 pi) sum_i z_i (mu d_i + 1) e^{delta - mu d_i}/d_i^3``
    for "exp" and "soft": no exponential more than the dipole (:func:`_dipole_clamp_block` for "clamp"); (3) the
    entry-point cap (rarely active). ``valid`` (size of rho, or 0 to skip) receives
    ``max(|k1|, |k2|) (|a| + |b| + z_r) <= tol``. Returns True (the caller raises) on a negative or non-finite
    rho, a non-finite phi or |phi| > PHI_MAX, or a non-finite delta (non-finite k or cos2phi).
    """
    z_v = z_r + 2.0 * z_b
    rd0 = dipole_diffuse_reflectance(0.0, alb, mu, z_r, z_v)
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
                ok &= abs(a) <= PHI_MAX
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
            ra, rb = kernel_ratios(r, coef, n_int, mu, z_r, z_b)
            h, d = 0.5 * (c1 + c2), 0.5 * (c1 - c2) * cs[j]   # Euler: k_n(phi) = H + (k1 - k2)/2 cos 2 phi
            delta = first_order_delta(h + d, h - d, ra, rb)
            if not (abs(delta) < math.inf):
                return True
            dl[j] = policy_exponent(delta, policy)
            if want_valid:
                valid[k] = max(abs(c1), abs(c2)) * (abs(ra) + abs(rb) + z_r) <= tol
        # pass 2: the dipole with e^delta (or times max(1 + delta, 0))
        if policy != CLAMP:
            dipole_exp_block(rho[start:start + m], dl[:m], out[start:start + m], alb, mu, z_r, z_v)
        else:
            _dipole_clamp_block(rho[start:start + m], dl[:m], out[start:start + m], alb, mu, z_r, z_v)
        # pass 3: cap at the kernel's entry-point value (reachable only where delta is large)
        for j in range(m):
            k = start + j
            out[k] = entry_point_cap(out[k], rd0, k1[k] + k2[k], a0, policy)
    return False


# ---------------------------------------------------------------------------------------------------------
# the table
# ---------------------------------------------------------------------------------------------------------

def cheb_to_monomial(deg):
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


_CHEB_T, _TO_MONO = cheb_to_monomial(_DEG)


def _material_scalars(albedo_prime, eta):
    p = diffusion_params(albedo_prime, eta)
    return (float(p.albedo_prime), float(p.mu), float(p.z_r), float(p.z_b))


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
        check_material(self.albedo_prime, self.eta)
        if np.ndim(self.albedo_prime) or np.ndim(self.eta):
            raise MaterialError("CurvatureTable takes a single material (scalar albedo_prime and eta)")
        rmax = float(self.rho_max_opt)
        if not (math.isfinite(rmax) and rmax >= 0):
            raise ValueError(f"rho_max_opt must be finite and >= 0, got {self.rho_max_opt!r}")
        alb, mu, z_r, z_b = _material_scalars(self.albedo_prime, self.eta)
        n_int = int(math.ceil(math.sqrt(rmax) * PER_UNIT)) + 1
        coef = np.empty((n_int, 2 * (_DEG + 1)))
        _build_table(n_int, mu, z_r, z_b, _CHEB_T, _TO_MONO, coef)
        coef.flags.writeable = False
        a0, _ = ratios_direct(0.0, mu, z_r, z_b)
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

    def validity(self, rho_opt, k_opt, tol=VALIDITY_TOL):
        """:func:`~meshshade.kernels.curvature.coefficients.curvature_validity` from the table;
        ``k_opt = max(|k1|, |k2|)/sigma_t'``."""
        a, b = self.ratios(rho_opt)
        return np.abs(np.asarray(k_opt, dtype=np.float64)) * (np.abs(a) + np.abs(b) + self.z_r) <= tol

    def profile(self, rho_opt, phi=None, *, k1_opt, k2_opt, cos2phi=None, policy="soft", return_validity=False,
                tol=VALIDITY_TOL):
        """Curved kernel R (optical units) as :func:`~meshshade.kernels.curvature.profile.curvature_profile`, from
        this table (same arguments)."""
        policy_id = check_policy(policy)
        if (phi is None) == (cos2phi is None):
            raise ValueError("give exactly one of phi and cos2phi")
        ang = phi if cos2phi is None else cos2phi
        arrs = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (rho_opt, ang, k1_opt, k2_opt)))
        shape = arrs[0].shape
        r, ang, c1, c2 = (np.ascontiguousarray(x).ravel() for x in arrs)
        out = np.empty(r.size)
        valid = np.empty(r.size if return_validity else 0, dtype=np.bool_)
        bad = _profile_loop(r, ang, c1, c2, cos2phi is not None, policy_id, self.coef, self.n_intervals,
                            self.albedo_prime, self.mu, self.z_r, self.z_b, self.a0, float(tol), valid, out)
        if bad:
            raise ValueError("rho_opt must be finite and >= 0; k1_opt, k2_opt and cos2phi must be finite; "
                             f"phi must be finite with |phi| <= {PHI_MAX:g} (reduce angles modulo 2 pi)")
        if return_validity:
            return out.reshape(shape), valid.reshape(shape)
        return out.reshape(shape)

    def max_interpolation_error(self, n=4000, seed=0):
        """Max over ``n`` random points in [0, rho_max] (uniform in sqrt(rho)) plus the interval ends of
        ``max(|a_tab - a|, |b_tab - b|)/(|a| + |b|)`` against direct quadrature."""
        rng = np.random.default_rng(seed)
        u = np.concatenate([rng.random(n) * math.sqrt(self.rho_max_opt),
                            np.arange(self.n_intervals) / PER_UNIT])
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
