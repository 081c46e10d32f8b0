"""The patch average of the kernel: a vertex sample stands for its dual patch, not a point (docs/physics.md §8.2).

:func:`patch_average_factor` (eq. (58)) is the ratio of the dipole averaged over the source's patch to its point
value, for pairs within :data:`PATCH_AVERAGE_RADII` patch radii; :func:`source_patch_radius` the patch radius of
each entry sample.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from meshshade.kernels.dipole import dipole_profile, dipole_tail_reflectance

#: source patches are averaged over (ring average) for pairs closer than this many patch radii
PATCH_AVERAGE_RADII = 4.0


def source_patch_radius(samples, vertex_areas) -> np.ndarray:
    """(k,) mm: radius ``sqrt(area/pi)`` of the patch each entry sample stands for: its vertex's dual area
    (``vertex_areas`` (n,) mm^2) for vertex samples of directional and point lights, 0 for point samples (beams)."""
    return np.where(samples.vertex >= 0, np.sqrt(vertex_areas[np.maximum(samples.vertex, 0)] / np.pi), 0.0)


def patch_average_factor(s_mm, a_mm, *, albedo_prime, eta, sigma_t_prime):
    """Ratio of the dipole averaged over a source patch to its point value, for pairs at distance ``s_mm``.

    A vertex sample stands for a patch of radius ``a = sqrt(area/pi)`` lit uniformly; the exitance it causes at
    distance s is the kernel averaged over that patch. Point sampling over-counts badly when the kernel's width
    (~z_r) is below the edge length (the self term alone can exceed the power entering). Two rules
    (docs/physics.md §8.2, eq. (58)):

    * a pair at distance s > 0: the exact average of the dipole over the disc of radius a centred at distance s,

          R_bar(s) = [T(0) - T(a - s)]_{s < a} + int_0^pi 2 s a sin(t) acos((r^2 + s^2 - a^2)/(2 r s)) R_d(r) dt
                     --------------------------------------------------------------------------------------------,
                                                          pi a^2

      r^2 = (s - a)^2 + 4 s a sin^2(t/2) (polar coordinates about the receiver: full circles up to a - s in
      closed form with the dipole's tail T(r) = int_r^inf R_d 2 pi r dr, the arcs inside the disc beyond by
      Gauss-Legendre panels in t graded towards t = 0, where R_d peaks when the receiver lies in the disc);
    * the self pair (s = 0): the value that makes a uniformly lit regular triangular lattice of the same vertex
      density (cell area pi a^2) return the dipole's closed-form total T(0) at its vertices, with every other
      pair weighted as the bake weights it (the disc rule within ``PATCH_AVERAGE_RADII`` a, point values beyond):
      the discrete form of the singular subtraction M(x) = E(x) int R dA + int (E(y) - E(x)) R dA. The bare disc
      average of the self patch leaves the gaps and overlaps between neighbouring discs uncorrected (measured
      -0.5 % on a sphere with edges 1.5 z_r, -1.7 % at 3 z_r; the former ring average over |r - s| <= a, -2.5 %
      and -3.8 %). The ratio to the disc average is tabulated once per material on a log grid of a sigma_t'.

    Other models are multiplied by the same ratio (curvature changes little across one patch). ``s_mm``,
    ``a_mm`` : (k,) mm. Returns (k,) float64 > 0; 1 where a = 0 (point samples, beams).
    """
    s = np.asarray(s_mm, dtype=np.float64) * sigma_t_prime
    a = np.asarray(a_mm, dtype=np.float64) * sigma_t_prime
    s, a = np.broadcast_arrays(s, a)
    out = np.ones(s.shape)
    m = np.flatnonzero(a.reshape(-1) >= DISC_TABLE_A[0])   # below, the patch average is the point value to 1e-6
    if not m.size:
        return out
    sm, am = s.reshape(-1)[m], a.reshape(-1)[m]
    kw = {"albedo_prime": float(albedo_prime), "eta": float(eta)}
    f = np.ones(m.size)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        u, la = sm / am, np.log(am)
        tab = (u <= PATCH_AVERAGE_RADII) & (am <= DISC_TABLE_A[1])
        if np.any(tab):
            f[tab] = np.exp(_disc_table(**kw).ev(u[tab], la[tab]))
        direct = ~tab
        if np.any(direct):  # patches wider than DISC_TABLE_A[1] transport lengths, or pairs beyond the table
            f[direct] = _disc_average(sm[direct], am[direct], **kw) / dipole_profile(sm[direct], **kw)
        self_pair = sm <= SELF_PAIR_RTOL * am
        if np.any(self_pair):
            f[self_pair] *= _self_term_ratio(am[self_pair], **kw)
    f = np.where(np.isfinite(f) & (f > 0), f, 1.0)
    out.reshape(-1)[m] = f
    return out


#: a pair closer than this fraction of the patch radius is the self pair (source vertex = receiver vertex)
SELF_PAIR_RTOL = 1e-9
#: range of a sigma_t' over which the disc rule is tabulated (bicubic in s/a and ln a: within 1e-4 of the
#: quadrature); below it the factor is 1 (the patch is far narrower than the kernel), above it the quadrature runs
DISC_TABLE_A = (1e-3, 8.0)
_DISC_TABLE_U = np.linspace(0.0, PATCH_AVERAGE_RADII, 257)
_DISC_TABLE_LOG_A = np.arange(np.log(DISC_TABLE_A[0]), np.log(DISC_TABLE_A[1]) + 0.1, 0.1)
#: Gauss-Legendre panels in the polar angle t about the receiver (fractions of pi) and nodes per panel
_DISC_T_PANELS = np.array([0.0, 1.0 / 256, 1.0 / 64, 1.0 / 16, 0.25, 1.0]) * np.pi
_DISC_T_NODES = 12


def _disc_nodes():
    x, w = np.polynomial.legendre.leggauss(_DISC_T_NODES)
    lo, hi = _DISC_T_PANELS[:-1, None], _DISC_T_PANELS[1:, None]
    return (lo + 0.5 * (hi - lo) * (x + 1.0)).ravel(), (0.5 * (hi - lo) * w).ravel()


_DISC_T, _DISC_W = _disc_nodes()


def _disc_average(s, a, *, albedo_prime, eta, profile=None, tail=None):
    """Average of the dipole R_d over the disc of radius ``a`` centred at distance ``s`` from the receiver (optical
    units, (k,) arrays, a > 0; within 1e-7 of a brute-force 2-D quadrature for a up to 30); see
    :func:`patch_average_factor`. Returns (k,) in units of R_d/sigma_t'^2. ``profile(r)`` and its tail
    ``tail(r) = int_r^inf profile 2 pi r dr`` replace the dipole's when given (any radial kernel)."""
    kw = {"albedo_prime": albedo_prime, "eta": eta}
    if profile is None:
        profile = lambda r: dipole_profile(r, **kw)   # noqa: E731
        tail = lambda r: dipole_tail_reflectance(r, **kw)   # noqa: E731
    inside = s < a
    full = np.where(inside, tail(0.0) - tail(np.where(inside, a - s, 0.0)), 0.0)
    out = np.empty(s.shape)
    for b in range(0, s.size, 65536):   # blocks of pairs: (block, 60) temporaries
        sc, ac, t = s[b:b + 65536, None], a[b:b + 65536, None], _DISC_T[None, :]
        r2 = (sc - ac) ** 2 + 4.0 * sc * ac * np.sin(0.5 * t) ** 2
        r = np.sqrt(r2)
        with np.errstate(invalid="ignore", divide="ignore"):
            arc = np.arccos(np.clip((r2 + sc * sc - ac * ac) / (2.0 * r * sc), -1.0, 1.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            integrand = np.where(sc > 0, 2.0 * sc * ac * np.sin(t) * arc * profile(r), 0.0)
        out[b:b + 65536] = integrand @ _DISC_W
    return (full + out) / (np.pi * a * a)


@lru_cache(maxsize=64)
def _disc_table(*, albedo_prime: float, eta: float):
    """Bicubic spline of ln(disc average / point value) over (s/a, ln(a sigma_t')), once per material (~0.1 s)."""
    from scipy.interpolate import RectBivariateSpline  # lazy: scipy.interpolate costs ~0.1 s at import

    kw = {"albedo_prime": albedo_prime, "eta": eta}
    u, la = np.meshgrid(_DISC_TABLE_U, _DISC_TABLE_LOG_A, indexing="ij")
    a = np.exp(la).ravel()
    s = u.ravel() * a
    with np.errstate(under="ignore"):
        f = np.log(_disc_average(s, a, **kw) / dipole_profile(s, **kw)).reshape(u.shape)
    return RectBivariateSpline(_DISC_TABLE_U, _DISC_TABLE_LOG_A, f, kx=3, ky=3, s=0)


#: ln(a sigma_t') grid of the self-term ratio (outside it the ratio is 1: below, the self term holds less than
#: 1e-3 of the kernel's total and the ratio is within 1 % of 1; above, the neighbours' share underflows)
_SELF_LOG_A = np.linspace(np.log(0.02), np.log(1e3), 55)
#: width of the smooth hand-over from the lattice sum to the integral, in lattice spacings
_SELF_WIDTH_H = 16.0


@lru_cache(maxsize=64)
def _self_term_table(*, albedo_prime: float, eta: float):
    """Cubic spline in ln(a sigma_t') of the ratio of the lattice-calibrated self term to the self disc average
    (docstring of :func:`patch_average_factor`), once per material (~0.2 s).

    Per grid value a: the regular triangular lattice of cell area pi a^2 (spacing h = a sqrt(2 pi/sqrt 3)), the
    receiver on a site. Sites within rho_c = PATCH_AVERAGE_RADII a + 2 h are summed exactly with the bake's
    weights; a C-infinity step chi from 1 to 0 over [rho_c, rho_c + 16 h] hands the rest to the integral (the
    lattice sum of R_d (1 - chi), analytic in a strip wider than rho_c and smooth on the scale 16 h, equals its
    integral to ~1e-7: doubling the width moves the ratio by < 3e-7); the self term is what is left of T(0)."""
    from scipy.interpolate import CubicSpline  # lazy, as above

    kw = {"albedo_prime": albedo_prime, "eta": eta}
    total = float(dipole_tail_reflectance(0.0, **kw))
    xg, wg = np.polynomial.legendre.leggauss(48)
    out = np.ones(_SELF_LOG_A.size)
    for j, la in enumerate(_SELF_LOG_A):   # a loop over the table's nodes, once per material
        a = float(np.exp(la))
        h = a * np.sqrt(2.0 * np.pi / np.sqrt(3.0))
        area = np.pi * a * a
        rho_c = PATCH_AVERAGE_RADII * a + 2.0 * h
        width = _SELF_WIDTH_H * h
        n = int(np.ceil((rho_c + width) / h)) + 2       # rows k reach |y| = 0.87 h |k|, columns |x| >= h (|i| - |k|/2)
        nk = int(np.ceil(n / (0.5 * np.sqrt(3.0))))
        i, k = np.meshgrid(np.arange(-n - nk, n + nk + 1), np.arange(-nk, nk + 1))
        r = np.hypot(h * (i + 0.5 * k), h * (0.5 * np.sqrt(3.0)) * k).ravel()
        r = r[(r > 0) & (r < rho_c + width)]
        kern = dipole_profile(r, **kw)                  # the bake's weight of each site: point value, or
        close = r < PATCH_AVERAGE_RADII * a               # the disc average within PATCH_AVERAGE_RADII a
        kern[close] = _disc_average(r[close], np.full(int(close.sum()), a), **kw)
        near_sum = area * float(np.sum(kern * _smooth_step((r - rho_c) / width)))
        rr = rho_c + 0.5 * width * (xg + 1.0)
        far = float(np.sum(0.5 * width * wg * dipole_profile(rr, **kw) * (1.0 - _smooth_step((rr - rho_c) / width))
                           * 2.0 * np.pi * rr)) + float(dipole_tail_reflectance(rho_c + width, **kw))
        self_disc = float(_disc_average(np.zeros(1), np.array([a]), **kw)[0])
        ratio = (total - near_sum - far) / (area * self_disc)
        out[j] = ratio if np.isfinite(ratio) and ratio > 0 else 1.0
    return CubicSpline(_SELF_LOG_A, out)


def _smooth_step(t):
    """C-infinity step: 1 for t <= 0, 0 for t >= 1."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore", over="ignore"):
        up = np.where(t > 0, np.exp(-1.0 / np.where(t > 0, t, 1.0)), 0.0)
        down = np.where(t < 1, np.exp(-1.0 / np.where(t < 1, 1.0 - t, 1.0)), 0.0)
    return down / (up + down)


def _self_term_ratio(a, *, albedo_prime: float, eta: float):
    """(k,) ratio of the calibrated self term to the self disc average at patch radii ``a`` (optical units)."""
    la = np.log(a)
    inside = (la >= _SELF_LOG_A[0]) & (la <= _SELF_LOG_A[-1])
    out = np.ones(la.shape)
    if np.any(inside):
        out[inside] = _self_term_table(albedo_prime=albedo_prime, eta=eta)(la[inside])
    return out
