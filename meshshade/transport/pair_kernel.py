"""The kernel R(x_o; x_i) of one model evaluated for arrays of (entry sample, exit vertex) pairs.

The kernel is expanded at the entry point x_i (docs/physics.md §1.3): rho is the geodesic distance from x_i to x_o,
phi the direction of x_o in x_i's tangent plane from x_i's first principal direction, and k1, k2 are x_i's
principal curvatures (:class:`SourceFrames`). :class:`PairKernel` evaluates the models of
:data:`meshshade.transport.models.MODELS` per channel; :func:`patch_average_factor` averages the dipole over the
patch a vertex sample stands for.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshshade.errors import ParameterError
from meshshade.kernels.curvature import CurvatureTable
from meshshade.kernels.dipole import dipole_profile, dipole_tail_reflectance
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
    n = samples.normals / np.linalg.norm(samples.normals, axis=1, keepdims=True)
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
                 sphere_radius_rtol: float = 1e-3, plan=None):
        if model not in MODELS:
            raise ParameterError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
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

    def evaluate(self, c: int, src, s, chord, phi) -> np.ndarray:
        """R [mm^-2] of channel ``c`` for pairs with source indices ``src`` (into the frames), geodesic distance
        ``s`` [mm], chord [mm] and azimuth ``phi`` [rad]; all (p,), returns (p,) float64."""
        if self.model != "auto":
            return self._evaluate(self.model, c, src, s, chord, phi)
        out = np.empty(s.shape)
        kind = self.plan.kernel[src]
        for i, name in enumerate(KERNEL_NAMES):
            m = kind == i
            if np.any(m):  # "dipole" in auto: the planar dipole of the geodesic distance (curved at k = 0)
                out[m] = self._evaluate("dipole-geodesic" if name == "dipole" else name, c, src[m], s[m],
                                        chord[m], phi[m])
        return out

    def _evaluate(self, model, c, src, s, chord, phi):
        ch = self.material.channel(c)
        st, par = ch["sigma_t_prime"], {"albedo_prime": ch["albedo_prime"], "eta": ch["eta"]}
        if model == "dipole":
            return dipole_profile(chord * st, **par) * st * st
        if model == "dipole-geodesic":
            return dipole_profile(s * st, **par) * st * st
        if model == "curved":
            table = self._curvature_table(c, st, par, float(s.max()) if s.size else 0.0)
            f = self.frames
            R, valid = table.profile(s * st, phi, k1_opt=f.k1[src] / st, k2_opt=f.k2[src] / st,
                                     return_validity=True)
            self.stats["curved_pairs_out_of_first_order_range"] = (
                self.stats.get("curved_pairs_out_of_first_order_range", 0) + int((~valid).sum()))
            return R * st * st
        return self._exact_sphere(c, st, par, src, s, chord)

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
    (~z_r) is below the edge length (the self term alone can exceed the power entering). The average is taken
    over the ring |r - s| <= a with the dipole's closed-form tail T(r) = int_r^inf R_d 2 pi r dr:

        R_bar(s) = [T(max(s - a, 0)) - T(s + a)] / (pi ((s + a)^2 - max(s - a, 0)^2))

    (the exact disc average at s = 0, -> R_d(s) for s >> a). Other models are multiplied by the same ratio
    (curvature changes little across one patch). ``s_mm``, ``a_mm`` : (k,) mm. Returns (k,) float64 > 0.
    """
    s = np.asarray(s_mm, dtype=np.float64) * sigma_t_prime
    a = np.asarray(a_mm, dtype=np.float64) * sigma_t_prime
    lo = np.maximum(s - a, 0.0)
    hi = s + a
    kw = {"albedo_prime": albedo_prime, "eta": eta}
    ring = np.pi * (hi * hi - lo * lo)
    with np.errstate(invalid="ignore", divide="ignore"):
        avg = (dipole_tail_reflectance(lo, **kw) - dipole_tail_reflectance(hi, **kw)) / ring
        f = avg / dipole_profile(s, **kw)
    return np.where((a > 0) & np.isfinite(f) & (f > 0), f, 1.0)
