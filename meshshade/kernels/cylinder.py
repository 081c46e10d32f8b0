"""Exact diffusion reflectance of an infinite circular cylinder (reference solution), in optical units.

Geometry and boundary treatment are those of the exact sphere (docs/physics.md §5), transplanted to a cylinder:

* the medium is ``r < R0`` (cylinder radius ``R0``, axis along ``z``);
* the fluence vanishes on the **extrapolated** cylinder ``r = R = R0 + z_b``;
* the source sits at depth ``z_r`` below the entry point on the inward normal:
  ``r' = R0 - z_r``, angle 0, axial position 0 (for ``R0 < z_r`` it lies past the axis, at radius
  ``|r'|`` and angle pi);
* ``Lap Psi - mu^2 Psi = -(1/D) delta``, and the reflectance is ``alpha' (-D dPsi/dr)`` on the **physical**
  surface ``r = R0`` (Jensen normalisation, docs/physics.md eq. (9)).

Method (free-space term minus a regular part)::

    e^{-mu|x-x'|}/|x-x'| = (2/pi) int_0^inf dq cos(q z) sum_n eps_n cos(n theta) I_n(k r_<) K_n(k r_>),
    k = sqrt(mu^2 + q^2),   eps_0 = 1, eps_n = 2,

    Psi = 1/(4 pi D) [ e^{-mu d}/d - (2/pi) int_0^inf dq cos(q z) sum_n eps_n cos(n theta)
                                       I_n(k r') K_n(k R) I_n(k r) / I_n(k R) ],

    R_cyl(theta, z) = alpha'/(4 pi) [ g(d) (z_r + 2 r' sin^2(theta/2))
                                       + (2/pi) int_0^inf dq cos(q z) sum_n eps_n cos(n theta) G_n(k) ],
    d^2 = z_r^2 + 4 R0 r' sin^2(theta/2) + z^2,
    G_n(k) = Q_n W_n (k t_n(k R0) + n/R0)     (= I_n(k r') K_n(k R) k I_n'(k R0) / I_n(k R)),

with ``Q_n = I_n(k r') I_n(k R0)/I_n(k R)^2``, ``W_n = I_n(k R) K_n(k R)``, ``t_n = I_{n+1}/I_n``. As in
docs/physics.md §5.4 no I or K is ever formed: ``t_n`` comes from backward recurrence started from the Amos (1974)
bounds, ``K_{n+1}/K_n`` from forward recurrence, and ``Q_0, W_0`` from ``scipy.special.ive/kve`` with the
exponent ``-k((R - r') + (R - R0)) = -k z_v`` written without cancellation.

The q-integrand is analytic off the cut ``q in i[mu, inf)`` (``I_n(k R)`` vanishes only for imaginary k)
and decays like ``e^{-q z_v}`` (``Q_n ~ e^{-k (z_r + 2 z_b)}``). It is integrated with 20-point
Gauss-Legendre panels, graded geometrically from ``mu/2`` (the branch point at ``q = i mu``) up to a maximum
width ``min(2, 8/z_v, 16/max|z|)`` (so that ``cos(q z)`` is resolved), and continued until the tail bound
``F(q_end) * 2/z_v`` of the absolute integrand ``F = sum_n eps_n |G_n|`` is below ``eps`` times its running
integral. The n-series at each node is summed until the geometric tail bound ``2 |G_N| rho/(1 - rho)``,
``rho = max(|G_N/G_{N-1}|, r' R0/R^2)`` (the term ratios decrease towards ``r' R0/R^2`` from above), is below
``eps`` times the running absolute sum. The count is ``~ (R0/z_v) ln(1/eps)`` at small k (the sphere's rule,
docs/physics.md eq. (31)) and ``~ R0 sqrt(2 k ln(1/eps)/z_v)`` at large k,
where the terms are Gaussian in n. The angular
sum uses ``e^{i n theta}`` by rotation, re-synchronised with exact cos/sin every 32 orders.
``eps = 1e-4 rtol`` (clipped to [1e-16, 1e-3]).

Accuracy
--------
Against 34-digit mpmath (tests/data/cylinder_reference.csv: 22 points, R0_opt 0.6-5, theta 0-pi,
z 0-8, values 3e-3..1 of R(0)): max relative error 1.3e-15 with ``rtol=1e-14`` and 3.4e-12 with the default
``rtol=1e-8``. Also checked: ``Psi = 0`` on ``r = R`` to 1e-15 of the cancelling terms, the PDE by finite
differences, the flux against ``-D dPsi/dr`` of the fluence, and the total reflectance against its closed
form ``alpha' R0 mu I0(mu r') [K1(mu R0) + K0(mu R) I1(mu R0)/I0(mu R)]`` to 1e-15 (tests/test_cylinder.py).

The error is **absolute**, relative to the scale ``S = alpha'/(4 pi) (2/pi) int F dq`` (comparable to
``R(0)``): ``|error| <~ (eps + 1e-14) S`` plus the rounding of the free-space term. Where the true reflectance
is below ~1e-14 R(0) (e.g. ``mu x distance >~ 30``: the cosine/Fourier synthesis cannot resolve an
exponentially small result from O(1) coefficients) the value is rounding noise and can be a tiny negative
number; ``full_output=True`` returns this bound per point. This is a reference for moderate distances, not a
tail evaluator.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from scipy import special

from meshshade.errors import MaterialError, MeshshadeError, ParameterError
from meshshade.kernels.optics import check_material, diffusion_params, g_func

__all__ = ["cylinder_exact_profile", "cylinder_exact_profile_geodesic", "cylinder_point_source_exitance"]

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(20)
_MAX_TERMS = 2_000_000
_ROUNDING = 1e-14  # rounding allowance relative to the absolute series scale (measured: <~1e-15)


# ---------------------------------------------------------------------------------------------------------
# compiled core
# ---------------------------------------------------------------------------------------------------------

@numba.njit(cache=True)
def _ratio_start(nu, x):
    """Midpoint of the Amos (1974) bounds for I_{nu+1}(x)/I_nu(x), nu >= 0, x > 0."""
    lo = x / (nu + 0.5 + math.sqrt((nu + 1.5) ** 2 + x * x))
    hi = x / (nu + 0.5 + math.sqrt((nu + 0.5) ** 2 + x * x))
    return 0.5 * (lo + hi)


@numba.njit(cache=True)
def _ratios_backward(x, n_need, out):
    """out[n] = I_{n+1}(x)/I_n(x) for n = 0..n_need-1 by backward recurrence (t_{n-1} = 1/(2n/x + t_n))."""
    if x == 0.0:
        for n in range(n_need):
            out[n] = 0.0
        return
    extra = 40 + int(10.0 * math.sqrt(x))
    top = n_need + extra
    t = _ratio_start(float(top), x)
    for nu in range(top, n_need, -1):
        t = 1.0 / (2.0 * nu / x + t)
    # now t = t_{n_need}; continue storing
    for nu in range(n_need, 0, -1):
        t = 1.0 / (2.0 * nu / x + t)
        out[nu - 1] = t


@numba.njit(cache=True)
def _node_terms(kappa, x1, xe, xR, r_e, flux, Q0, W0, u0, q_lim, eps, terms, t1, te, tR):
    """Fill terms[0..N) with G_n (flux) or Q_n W_n (fluence) at one q node; return N (or -1: need more room)."""
    n_cap = terms.shape[0]
    _ratios_backward(x1, n_cap, t1)
    _ratios_backward(xe, n_cap, te)
    _ratios_backward(xR, n_cap, tR)
    Q = Q0
    W = W0
    u = u0
    s_abs = 0.0
    prev = 0.0
    for n in range(n_cap):
        if flux:
            g = Q * W * (kappa * te[n] + n / r_e)
        else:
            g = Q * W
        terms[n] = g
        a = abs(g)
        s_abs += a if n == 0 else 2.0 * a
        if a == 0.0 and n > 0:
            return n + 1
        if n >= 2 and prev > 0.0:
            rho = a / prev
            if rho < q_lim:
                rho = q_lim
            if rho < 1.0 and 2.0 * a * rho / (1.0 - rho) <= eps * s_abs:
                return n + 1
        prev = a
        # advance to n + 1
        tr = tR[n]
        Q = Q * (t1[n] / tr) * (te[n] / tr)
        W = W * tr * u
        u = 1.0 / u + 2.0 * (n + 1) / xR
    return -1


@numba.njit(cache=True)
def _accumulate(kappas, weights, qs, z, Q0s, W0s, u0s, ar1, r_e, R, flux, q_lim, eps, n_guess,
                theta, out, fabs, nused):
    """out[p] += sum_j w_j cos(q_j z_p) sum_n eps_n cos(n theta_p) G_n(q_j); fabs[j] = sum_n eps_n |G_n|."""
    n_pts = out.shape[0]
    cth = np.cos(theta)
    sth = np.sin(theta)
    c = np.empty(n_pts)
    s = np.empty(n_pts)
    acc = np.empty(n_pts)
    for j in range(kappas.shape[0]):
        k = kappas[j]
        cap = int(n_guess[j])
        while True:
            terms = np.empty(cap)
            t1 = np.empty(cap)
            te = np.empty(cap)
            tR = np.empty(cap)
            N = _node_terms(k, k * ar1, k * r_e, k * R, r_e, flux, Q0s[j], W0s[j], u0s[j], q_lim, eps,
                            terms, t1, te, tR)
            if N > 0:
                break
            cap *= 2
            if cap > 2_000_000:
                N = -1
                break
        nused[j] = N
        if N < 0:
            return
        fa = abs(terms[0])
        for n in range(1, N):
            fa += 2.0 * abs(terms[n])
        fabs[j] = fa
        for p in range(n_pts):
            c[p] = 1.0
            s[p] = 0.0
            acc[p] = terms[0]
        for n in range(1, N):
            g2 = 2.0 * terms[n]
            if n % 32 == 0:
                for p in range(n_pts):
                    # resynchronise the rotation with exact cos/sin (rounding stays ~32 eps)
                    c[p] = math.cos(n * theta[p])
                    s[p] = math.sin(n * theta[p])
                    acc[p] += g2 * c[p]
            else:
                for p in range(n_pts):
                    cn = c[p] * cth[p] - s[p] * sth[p]
                    s[p] = s[p] * cth[p] + c[p] * sth[p]
                    c[p] = cn
                    acc[p] += g2 * cn
        w = weights[j]
        q = qs[j]
        for p in range(n_pts):
            out[p] += w * math.cos(q * z[p]) * acc[p]


# ---------------------------------------------------------------------------------------------------------
# python driver
# ---------------------------------------------------------------------------------------------------------

def _panels(dq_max, q_start, q_stop, geometric_from):
    """Panel breakpoints from q_start to at least q_stop: geometric doubling from `geometric_from`, capped."""
    edges = [q_start]
    q = q_start
    while q < q_stop:
        width = min(dq_max, max(q, geometric_from)) if q > 0 else min(dq_max, geometric_from)
        q = q + width
        edges.append(q)
    return np.asarray(edges)


def _regular_part(theta, z, *, r_src, r_e, R, mu, flux, eps):
    """(2/pi) int_0^inf dq cos(q z) sum_n eps_n cos(n theta) T_n, for the flux (G_n) or fluence (Q_n W_n) terms.

    ``theta``, ``z`` are 1-D float arrays (angle measured from the source direction); ``r_src >= 0``.
    Returns (values, abs_scale) where abs_scale = (2/pi) int sum_n eps_n |T_n| dq (the rounding-floor scale).
    """
    a_decay = (R - r_src) + (R - r_e)  # integrand ~ exp(-k a_decay) at large k
    zmax = float(np.max(np.abs(z))) if z.size else 0.0
    dq_max = min(2.0, 16.0 / zmax) if zmax > 0 else 2.0
    dq_max = min(dq_max, 8.0 / a_decay)
    geometric_from = 0.5 * mu if mu > 0 else 1e-6 / R
    geometric_from = min(geometric_from, dq_max)
    q_lim = r_src * r_e / R**2
    ln_eps = math.log(1.0 / eps)
    n_geom = ln_eps / (-math.log(q_lim)) if 0.0 < q_lim < 1.0 else 0.0

    out = np.zeros(theta.shape[0])
    total_abs = 0.0
    q_lo = 0.0
    q_hi = (ln_eps + 10.0) / a_decay
    while True:
        edges = _panels(dq_max, q_lo, q_hi, geometric_from)
        a, b = edges[:-1, None], edges[1:, None]
        q = (0.5 * (b - a) * _GL_NODES[None, :] + 0.5 * (a + b)).ravel()
        w = (0.5 * (b - a) * _GL_WEIGHTS[None, :]).ravel()
        k = np.hypot(q, mu)
        x1, xe, xR = k * r_src, k * r_e, k * R
        with np.errstate(under="ignore"):
            Q0 = (special.ive(0, x1) * special.ive(0, xe) / special.ive(0, xR) ** 2) * np.exp(-k * a_decay)
        W0 = special.ive(0, xR) * special.kve(0, xR)
        u0 = special.kve(1, xR) / special.kve(0, xR)
        gauss_w = 1.0 / k * (1.0 / max(r_src, 1e-300) + 1.0 / r_e - 2.0 / R) if r_src > 0 else 0.0
        n_gauss = np.sqrt(2.0 * (ln_eps + 5.0) / np.maximum(gauss_w, 1e-300)) if r_src > 0 else np.zeros_like(k)
        n_guess = np.clip(1.3 * np.maximum(n_geom, np.minimum(n_gauss, 1e7)) + 64, 64, _MAX_TERMS).astype(np.int64)
        fabs = np.zeros(q.shape[0])
        nused = np.zeros(q.shape[0], dtype=np.int64)
        _accumulate(k, w, q, z, Q0, W0, u0, r_src, r_e, R, flux, q_lim, eps, n_guess,
                    theta, out, fabs, nused)
        if np.any(nused < 0):
            raise ParameterError("cylinder series did not converge within %d terms" % _MAX_TERMS)
        total_abs += float(np.dot(w, fabs))
        tail = float(np.max(fabs[-len(_GL_NODES):])) * 2.0 / a_decay
        if tail <= eps * total_abs or total_abs == 0.0:
            break
        q_lo, q_hi = float(edges[-1]), float(edges[-1]) + 10.0 / a_decay
    return (2.0 / np.pi) * out, (2.0 / np.pi) * total_abs


def _source_geometry(th, zz, R0, depth):
    """(d, geo, theta from the source) for a source at ``depth`` below the entry point: the distance d to the
    surface points (theta, z), and ``geo`` = R0 - r' cos(theta) (the free-space flux's geometric factor), both
    without cancellation (docs/physics.md §5.2); a source past the axis (depth > R0) sits at radius depth - R0 and
    angle pi, and angles are measured from there."""
    r_src = R0 - depth
    if r_src >= 0.0:
        sin2 = np.sin(0.5 * th) ** 2
        return (np.sqrt(depth * depth + 4.0 * R0 * r_src * sin2 + zz**2), depth + 2.0 * r_src * sin2, th)
    cos2 = np.cos(0.5 * th) ** 2
    far = 2.0 * R0 - depth
    return np.sqrt(far * far + 4.0 * R0 * (-r_src) * cos2 + zz**2), far + 2.0 * (-r_src) * cos2, th - np.pi


def _truncation_eps(rtol):
    """Series/q-range truncation level, relative to the absolute scale of the series (~R(0))."""
    rtol = _check_scalar("rtol", rtol, 0.0)
    return float(np.clip(rtol * 1e-4, 1e-16, 1e-3))


def _check_scalar(name, value, lo=None, err=MeshshadeError):
    """``value`` as a float; raises ``err`` unless it is a finite scalar (and > lo)."""
    v = np.asarray(value, dtype=np.float64)
    if v.ndim != 0 or not np.isfinite(v):
        raise err(f"{name} must be a finite scalar, got {value!r}")
    v = float(v)
    if lo is not None and not v > lo:
        raise err(f"{name} must be > {lo}, got {v}")
    return v


def _geometry(R0_opt, albedo_prime, eta):
    R0 = _check_scalar("R0_opt", R0_opt, 0.5)  # z_r/2: for R0 <= z_r/2 the source is not inside the medium
    check_material(albedo_prime, eta)  # the kernels' common material check, then this kernel's own limits
    alb = _check_scalar("albedo_prime", albedo_prime, err=MaterialError)
    if not 0.0 < alb <= 1.0:
        raise MaterialError(f"albedo_prime must lie in (0, 1], got {alb}")
    eta = _check_scalar("eta", eta, 0.0, err=MaterialError)
    p = diffusion_params(alb, eta)
    z_r, z_b, mu = float(p.z_r), float(p.z_b), float(p.mu)
    return R0, alb, mu, z_r, z_b


def cylinder_exact_profile(theta, z, *, R0_opt, albedo_prime, eta, rtol=1e-8, full_output=False):
    """Exact diffuse reflectance of an infinite cylinder, in optical units (reference solution).

    Defined as ``alpha' (-D dPsi/dr)`` at the physical surface ``r = R0`` for the source at depth ``z_r`` under
    the entry point, with ``Psi = 0`` on ``r = R0 + z_b`` (module docstring; docs/physics.md §5 for the sphere).

    Parameters
    ----------
    theta : array_like of float
        Angle around the axis from the entry point [rad]; the kernel is even and 2 pi-periodic in theta.
    z : array_like of float
        Axial offset of the exit point from the entry point, times sigma_t' (dimensionless); even in z.
    R0_opt : float > z_r/2 = 0.5
        Cylinder radius times sigma_t'. For ``0.5 < R0_opt < z_r = 1`` the source (z_r along the inward normal)
        lies past the axis, at radius ``z_r - R0`` on the far side; for ``R0_opt <= 0.5`` it would be outside the
        medium and MeshshadeError is raised. (Diffusion theory itself is poor for radii of ~1 mean free path.)
    albedo_prime : float in (0, 1]
        Reduced albedo sigma_s'/sigma_t'.
    eta : float in [1, 2.5] (:func:`meshshade.kernels.optics.check_eta`)
        Relative index of refraction.
    rtol : float > 0
        Accuracy target. The n-series and the q-range are truncated at ``eps = 1e-4 rtol`` (clipped to
        [1e-16, 1e-3]) of the absolute scale S (~R(0), module docstring), so the relative error is below
        rtol wherever ``R >~ 1e-4 R(0)``, and below ``(eps + 1e-14) S/R`` elsewhere. The quadrature itself is
        accurate to rounding (measured 1.3e-15 with rtol = 1e-14).
    full_output : bool
        If True, also return an absolute error bound (see Returns).

    Returns
    -------
    ndarray of float64, broadcast shape of (theta, z)
        ``R / sigma_t'**2``, Jensen normalisation (includes alpha'). Values below ~1e-14 R(0) carry no relative
        accuracy (absolute floor, module docstring).
    abs_error : ndarray of float64, same shape (only with ``full_output=True``)
        Absolute error bound ``S (eps + 1e-14) + 1e-14 alpha'/(4 pi) |free-space term|``: the truncation
        tolerance plus a rounding allowance relative to the absolute scale S of the series (module docstring).
        Where ``|value| < abs_error`` not even the sign of the result is resolved.
    """
    R0, alb, mu, z_r, z_b = _geometry(R0_opt, albedo_prime, eta)
    eps = _truncation_eps(rtol)
    th, zz = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(z, dtype=np.float64))
    shape = th.shape
    th = th.ravel()
    zz = np.abs(zz.ravel())
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(zz))):
        raise ParameterError("theta and z must be finite")
    R = R0 + z_b
    r_src = R0 - z_r
    d, geo, th_src = _source_geometry(th, zz, R0, z_r)
    with np.errstate(under="ignore"):
        free = g_func(d, mu) * geo
    reg, scale = _regular_part(th_src, zz, r_src=abs(r_src), r_e=R0, R=R, mu=mu, flux=True, eps=eps)
    value = (alb / (4.0 * np.pi) * (free + reg)).reshape(shape)
    if not full_output:
        return value
    err = alb / (4.0 * np.pi) * (scale * (eps + _ROUNDING) + _ROUNDING * np.abs(free))
    return value, err.reshape(shape)


def cylinder_exact_profile_geodesic(rho, phi, *, R0_opt, albedo_prime, eta, rtol=1e-8):
    """:func:`cylinder_exact_profile` at geodesic distance ``rho`` in direction ``phi`` on the cylinder surface.

    ``phi`` is the angle from the first principal direction at the entry point: ``phi = 0`` runs around the
    circumference (normal curvature ``k1 = 1/R0``), ``phi = pi/2`` along the axis (``k2 = 0``). The geodesic
    leaving the entry point in direction phi is a helix; unrolling the cylinder onto the plane makes it a
    straight line, so the exit point lies at arc length ``rho cos(phi)`` around (``theta = rho cos(phi)/R0``)
    and ``z = rho sin(phi)`` along the axis. (For ``|rho cos phi| > pi R0`` the helix has wrapped past the
    antipodal line and is no longer the shortest path; theta is then simply taken modulo 2 pi.)

    Parameters
    ----------
    rho : array_like of float >= 0
        Geodesic distance times sigma_t'.
    phi : array_like of float
        Direction angle [rad] from the circumferential principal direction.
    R0_opt, albedo_prime, eta, rtol
        As in :func:`cylinder_exact_profile`.

    Returns
    -------
    ndarray of float64, broadcast shape of (rho, phi); R / sigma_t'**2.
    """
    R0 = _check_scalar("R0_opt", R0_opt, 0.0)
    rho, phi = np.broadcast_arrays(np.asarray(rho, dtype=np.float64), np.asarray(phi, dtype=np.float64))
    theta = rho * np.cos(phi) / R0
    z = rho * np.sin(phi)
    return cylinder_exact_profile(theta, z, R0_opt=R0, albedo_prime=albedo_prime, eta=eta, rtol=rtol)


def _cylinder_fluence(r, theta, z, *, R0_opt, albedo_prime, eta, rtol=1e-10):
    """Private: Green's function Psi (S = 1) at interior points ``0 < r <= R0 + z_b`` (for tests).

    Defined as ``1/(4 pi D) [e^{-mu d}/d - regular part]`` with the same pieces as the reflectance; ``r``
    must be a scalar (the radial argument enters the Bessel ratios), theta and z arrays.
    """
    R0, alb, mu, z_r, z_b = _geometry(R0_opt, albedo_prime, eta)
    eps = _truncation_eps(rtol)
    r = _check_scalar("r", r, 0.0)
    th, zz = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(z, dtype=np.float64))
    shape = th.shape
    th = th.ravel()
    zz = np.abs(zz.ravel())
    R = R0 + z_b
    r_src = R0 - z_r
    d = np.sqrt((r - r_src) ** 2 + 4.0 * r * r_src * np.sin(0.5 * th) ** 2 + zz**2)
    free = np.exp(-mu * d) / d
    th_src = th if r_src >= 0 else th - np.pi
    reg, _ = _regular_part(th_src, zz, r_src=abs(r_src), r_e=r, R=R, mu=mu, flux=False, eps=eps)
    D = 1.0 / 3.0
    return ((free - reg) / (4.0 * np.pi * D)).reshape(shape)


def cylinder_point_source_exitance(theta, z, *, R0_opt, depth_opt, mu, D, z_b, c_phi, c_E, rtol=1e-8):
    """Exitance ``C_phi Psi + C_E (-D dPsi/dr)`` on the physical cylinder r = R0 of a unit isotropic point source
    at depth ``t`` under the entry point (docs/physics.md eq. (77)), Psi = 0 on r = R0 + z_b.

    The cylinder's exact Green's function (module docstring) for any source depth and dipole variant (``mu``,
    ``D``, ``z_b``, ``c_phi``, ``c_E`` as in :class:`meshshade.kernels.beam_diffusion.DipoleVariant`; Jensen's
    :func:`cylinder_exact_profile` is ``alpha'`` times this with ``c_phi = 0``, ``c_E = 1``, ``t = z_r``). A source
    past the axis (R0 < t < 2 R0) sits at radius t - R0 on the far side; one at t >= 2 R0 is outside and gives 0.
    theta (angle around the axis), z (axial offset, optical units) broadcast; returns float64 of their shape.
    """
    R0 = _check_scalar("R0_opt", R0_opt, 0.0)
    t = _check_scalar("depth_opt", depth_opt, 0.0)
    mu = _check_scalar("mu", mu)
    D = _check_scalar("D", D, 0.0)
    z_b = _check_scalar("z_b", z_b)
    if mu < 0 or z_b < 0:
        raise ParameterError(f"mu and z_b must be >= 0, got {mu}, {z_b}")
    eps = _truncation_eps(rtol)
    th, zz = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(z, dtype=np.float64))
    shape = th.shape
    th = th.ravel()
    zz = np.abs(zz.ravel())
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(zz))):
        raise ParameterError("theta and z must be finite")
    if t >= 2.0 * R0:
        return np.zeros(shape)
    R = R0 + z_b
    r_src = R0 - t
    d, geo, th_src = _source_geometry(th, zz, R0, t)
    out = np.zeros(th.shape)
    if c_E:
        with np.errstate(under="ignore"):
            free = g_func(d, mu) * geo
        reg, _ = _regular_part(th_src, zz, r_src=abs(r_src), r_e=R0, R=R, mu=mu, flux=True, eps=eps)
        out += float(c_E) / (4.0 * np.pi) * (free + reg)
    if c_phi:
        with np.errstate(under="ignore"):
            free = np.exp(-mu * d) / d
        reg, _ = _regular_part(th_src, zz, r_src=abs(r_src), r_e=R0, R=R, mu=mu, flux=False, eps=eps)
        out += float(c_phi) / (4.0 * np.pi * D) * (free - reg)
    return np.maximum(out, 0.0).reshape(shape)
