"""The kernel R(x_o; x_i) of one model evaluated for arrays of (entry sample, exit vertex) pairs.

The kernel is expanded at the entry point x_i (docs/physics.md §1.3): rho is the geodesic distance from x_i to x_o,
phi the direction of x_o in x_i's tangent plane from x_i's first principal direction, and k1, k2 are x_i's
principal curvatures (:class:`SourceFrames`). :class:`PairKernel` evaluates the models of
:data:`meshshade.transport.models.MODELS` per channel; :func:`patch_average_factor` averages the dipole over the
patch a vertex sample stands for.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from meshshade.errors import ParameterError
from meshshade.kernels.curvature import CurvatureTable
from meshshade.kernels.dipole import dipole_profile, dipole_tail_reflectance
from meshshade.kernels.fitted_curvature import chord_curvature, fitted_dipole_pairs, matched_table, normal_curvatures
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.materials import Material
from meshshade.transport.models import KERNEL_NAMES, MODELS

#: source patches are averaged over (ring average) for pairs closer than this many patch radii
PATCH_AVERAGE_RADII = 4.0


@dataclass(frozen=True)
class SourceFrames:
    """Entry-sample geometry the kernel needs, (k,) or (k, 3) float64: curvatures in 1/mm, unit frames."""

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normals: np.ndarray


def source_frames(samples, curv, faces) -> SourceFrames:
    """Principal curvatures and frames at entry samples: vertex values for vertex samples, barycentric
    interpolation (directions sign-aligned, re-orthogonalised to the sample's normal) inside a triangle.

    samples : EntrySamples (k samples); curv : per-vertex ``k1``, ``k2`` (n,) 1/mm and ``d1`` (n, 3);
    faces : (m, 3) int. Returns (k,) / (k, 3) float64 frames with ``d2 = normal x d1``.
    """
    k = len(samples)
    k1, k2 = np.empty(k), np.empty(k)
    d1 = np.empty((k, 3))
    at_v = samples.vertex >= 0
    iv = samples.vertex[at_v]
    k1[at_v], k2[at_v], d1[at_v] = curv.k1[iv], curv.k2[iv], curv.d1[iv]
    tri = ~at_v
    if np.any(tri):
        F = faces[samples.face[tri]]
        b = samples.bary[tri]
        k1[tri] = np.einsum("ij,ij->i", b, curv.k1[F])
        k2[tri] = np.einsum("ij,ij->i", b, curv.k2[F])
        D = curv.d1[F]  # (t, 3, 3): principal directions are defined up to sign: align to corner 0
        sign = np.sign(np.einsum("ijk,ik->ij", D, D[:, 0]))
        sign[sign == 0] = 1.0
        d1[tri] = np.einsum("ij,ijk->ik", b * sign, D)
    # an unreferenced vertex (no face: zero area, zero normal, no power) gets the frame of +z: any will do
    length = np.linalg.norm(samples.normals, axis=1, keepdims=True)
    n = np.where(length > 0, samples.normals / np.where(length > 0, length, 1.0), [[0.0, 0.0, 1.0]])
    d1 = d1 - np.einsum("ij,ij->i", d1, n)[:, None] * n
    norm = np.linalg.norm(d1, axis=1)
    bad = norm < 1e-12
    if np.any(bad):  # umbilic or failed frame: any tangent direction will do (k1 = k2 there)
        alt = np.where(np.abs(n[bad, 0:1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        d1[bad] = np.cross(n[bad], alt)
        norm[bad] = np.linalg.norm(d1[bad], axis=1)
    d1 /= norm[:, None]
    d2 = np.cross(n, d1)
    return SourceFrames(k1, k2, d1, d2, n)


class PairKernel:
    """Evaluates R [mm^-2] of one model and material for arrays of (source, exit) pairs.

    Channels with equal parameters are computed once. For ``exact-sphere`` the series is tabulated once per
    distinct local radius (radii rounded to ``sphere_radius_rtol``) on a fine angle grid and interpolated.
    ``plan`` (meshshade.transport.auto.AutoPlan) gives the kernel of each source for ``model="auto"``.
    """

    def __init__(self, model: str, material: Material, frames: SourceFrames, *, rtol: float = 1e-10,
                 sphere_radius_rtol: float = 1e-3, plan=None, near=None):
        if model not in MODELS:
            raise ParameterError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
        #: the near-field factors (transport.near_field.NearFieldFactors) the gather multiplies pairs by, or None
        #: for the kernels' own point source at z_r; with them, ``source_scale`` (k, 3): each source's incidence
        #: scale per channel (NearFieldFactors.incidence_scale), or None
        self.near_factors = near
        self.source_scale = None
        #: with the near-field factors, each source's sideways drift (sin theta_t (k,), its azimuth psi (k,) in the
        #: source frame; transport.near_field.drift_angles), or None: the gather multiplies pairs by
        #: NearFieldFactors.drift_factor (docs/physics.md eq. (88))
        self.source_drift = None
        if model == "auto" and plan is None:
            raise ValueError("model 'auto' needs the per-sample plan (meshshade.transport.auto.plan_sources)")
        self.model, self.material, self.frames, self.plan = model, material, frames, plan
        self.channels: list[tuple[int, list[int]]] = []  # (representative channel, channels it stands for)
        seen: dict = {}
        for c in range(3):
            key = (material.albedo_prime[c], material.sigma_t_prime[c])
            if key in seen:
                self.channels[seen[key]][1].append(c)
            else:
                seen[key] = len(self.channels)
                self.channels.append((c, [c]))
        self.stats: dict = {}
        self._tables: dict = {}  # curved: one CurvatureTable per channel
        self._matched: dict = {}  # fitted: the channel's table with a matched boundary (eta = 1)
        #: (source positions (k, 3) mm, receiver positions (n, 3) mm, receiver unit normals (n, 3), receiver
        #: principal curvatures k1, k2 (n,) 1/mm and first principal directions (n, 3)), or None: with them the
        #: fitted model measures each pair's curvatures between its two points (:meth:`_pair_curvatures`) when
        #: :meth:`evaluate` is given the receivers
        self.pair_points = None
        if model in ("exact-sphere", "auto"):
            H = 0.5 * (frames.k1 + frames.k2)
            convex = H > 0
            radius = np.where(convex, 1.0 / np.where(convex, H, 1.0), 1.0)  # local radius 2/(k1 + k2)
            q = np.where(convex, np.round(np.log(radius) / np.log1p(
                sphere_radius_rtol)), -1).astype(np.int64)
            self._radius_bin = q
            self._sphere_tables: dict = {}
            if model == "exact-sphere":
                self.stats["exact_sphere_fallback_dipole"] = int((~convex).sum())
                self.stats["exact_sphere_radius_bins"] = int(np.unique(q[convex]).size)
        self.rtol = rtol
        self.sphere_radius_rtol = sphere_radius_rtol

    def evaluate(self, c: int, src, s, chord, phi, vtx=None) -> np.ndarray:
        """R [mm^-2] of channel ``c`` for pairs with source indices ``src`` (into the frames), geodesic distance
        ``s`` [mm], chord [mm] and azimuth ``phi`` [rad]; all (p,), returns (p,) float64. ``vtx`` (p,): the
        receivers' indices into ``pair_points``, or None."""
        if self.model != "auto":
            return self._evaluate(self.model, c, src, s, chord, phi, vtx)
        out = np.empty(s.shape)
        kind = self.plan.kernel[src]
        for i, name in enumerate(KERNEL_NAMES):
            m = kind == i
            if np.any(m):  # "dipole" in auto: the planar dipole of the geodesic distance (curved at k = 0)
                out[m] = self._evaluate("dipole-geodesic" if name == "dipole" else name, c, src[m], s[m],
                                        chord[m], phi[m], None if vtx is None else vtx[m])
        return out

    def _evaluate(self, model, c, src, s, chord, phi, vtx=None):
        ch = self.material.channel(c)
        st, par = ch["sigma_t_prime"], {"albedo_prime": ch["albedo_prime"], "eta": ch["eta"]}
        if model == "dipole":
            return dipole_profile(chord * st, **par) * st * st
        if model == "dipole-geodesic":
            return dipole_profile(s * st, **par) * st * st
        if model == "fitted":
            table = self._curvature_table(c, st, par, float(s.max()) if s.size else 0.0)
            matched = self._matched.get(c)
            if matched is None or matched.rho_max_opt != table.rho_max_opt:
                matched = self._matched[c] = matched_table(table)
            f = self.frames
            ka, kc, t2 = normal_curvatures(phi, f.k1[src], f.k2[src])
            if vtx is not None and self.pair_points is not None:
                ka, kc, t2 = self._pair_curvatures(src, vtx, ka, kc, t2)
            return fitted_dipole_pairs(table, s * st, ka / st, kc / st, t2 / (st * st), matched=matched) * st * st
        if model == "curved":
            table = self._curvature_table(c, st, par, float(s.max()) if s.size else 0.0)
            f = self.frames
            R, valid = table.profile(s * st, phi, k1_opt=f.k1[src] / st, k2_opt=f.k2[src] / st,
                                     return_validity=True)
            self.stats["curved_pairs_out_of_first_order_range"] = (
                self.stats.get("curved_pairs_out_of_first_order_range", 0) + int((~valid).sum()))
            return R * st * st
        return self._exact_sphere(c, st, par, src, s, chord)

    def _pair_curvatures(self, src, vtx, ka, kc, t2):
        """The fitted model's curvatures of pairs whose receivers are known (docs/physics.md eq. (85)): along the pair
        the normal-section curvature between its two points; across it and the squared twist, the mean of the
        source's and the receiver's (the receiver's normal curvature across the pair's direction in its tangent
        plane). A surface that bends differently away from the entry point is then seen as it is, not as the
        entry point's osculating quadric extrapolated (on spheres, cylinders around their axis and cavities the
        two agree)."""
        xs, xr, nr, rk1, rk2, rd1 = self.pair_points
        ka = chord_curvature(xs[src], self.frames.normals[src], xr[vtx], nr[vtx], ka)
        v = xr[vtx] - xs[src]
        n = nr[vtx]
        tv = v - np.einsum("ij,ij->i", v, n)[:, None] * n
        across = np.cross(n, tv)
        norm = np.linalg.norm(across, axis=1)
        ok = norm > 0.0
        c2 = np.where(ok, np.einsum("ij,ij->i", rd1[vtx], across) / np.where(ok, norm, 1.0), 0.0) ** 2
        kc = np.where(ok, 0.5 * (kc + rk1[vtx] * c2 + rk2[vtx] * (1.0 - c2)), kc)
        t2 = np.where(ok, 0.5 * (t2 + (rk1[vtx] - rk2[vtx]) ** 2 * c2 * (1.0 - c2)), t2)
        return ka, kc, t2

    def _curvature_table(self, c, st, par, s_max):
        """One Chebyshev table of the curvature coefficients per channel, grown when a longer distance shows up."""
        t = self._tables.get(c)
        if t is None or t.rho_max_opt < s_max * st:
            t = self._tables[c] = CurvatureTable(par["albedo_prime"], par["eta"], max(s_max * st * 1.25, 10.0))
        return t

    def _exact_sphere(self, c, st, par, src, s, chord):
        out = np.empty(s.shape)
        bins = self._radius_bin[src]
        flat = bins < 0
        out[flat] = dipole_profile(chord[flat] * st, **par) * st * st
        for b in np.unique(bins[~flat]):
            sel = bins == b
            key = (c, int(b))
            if key not in self._sphere_tables:
                R0 = float(np.exp(b * np.log1p(self.sphere_radius_rtol)))
                theta = np.linspace(0.0, np.pi, 4097)
                vals = sphere_series_profile(theta, R0_opt=R0 * st, rtol=self.rtol, **par) * st * st
                self._sphere_tables[key] = (R0, theta, vals)
            R0, theta, vals = self._sphere_tables[key]
            th = np.clip(s[sel] / R0, 0.0, np.pi)
            if th.size <= theta.size:  # few pairs (a beam): evaluate the series exactly
                out[sel] = sphere_series_profile(th, R0_opt=R0 * st, rtol=self.rtol, **par) * st * st
            else:  # log-linear interpolation; relative error < 1e-5 for R0 >= 1 transport length
                out[sel] = np.exp(np.interp(th, theta, np.log(np.maximum(vals, 1e-300))))
        return out


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
