"""The near-field model in the bake (the source model ``source_model="beam"``; docs/physics.md §13.2, eq. (80)).

Every kernel of the bake answers a point source at depth z_r. With ``source_model="beam"`` each pair's value is
multiplied by the ratio of the half-space's near-field model (:mod:`meshshade.kernels.near_field`, eq. (76): exact
single scattering plus the beam's fitted diffusion sources) to the planar dipole, so that every model carries the
same near field as the factor of eq. (79):

* a pair at distance s from a point: ``N(s) = R_near(s) / R_d(s)``;
* a pair within PATCH_AVERAGE_RADII patch radii of a source patch of radius a (vertex samples; and, for beams, the
  receiver's own patch, since a vertex's exitance is the average over the patch it stands for):
  ``G(s, a) = <R_near>_a(s) / <R_d>_a(s)``, the ratio of the two kernels' averages over the disc (the same
  quadrature as the dipole's patch average, pair_kernel.py), on top of the dipole's patch factor;
* the far field (pairs beyond the near radius r, summed by source clusters of the planar dipole): N(s) per pair (per
  cluster at its centroid distance), from the same table;
* the direction the light travels inside (docs/physics.md eq. (81)): an entry sample whose light enters at
  incidence theta_i refracts to theta_t, and the near-field model's sources then lie at depths cos(theta_t) t_k;
  the sample's power is scaled by the half-space's gain in total reflectance at that angle, W(cos theta_t) of
  eq. (86) (kernels.near_field.incidence_gain: the ratio of eq. (81)'s totals, corrected towards exact transport;
  the profile keeps its normal-incidence shape);
* the sideways drift of the light inside (docs/physics.md §13.4, eqs. (87)-(88)): light refracted at theta_t
  drifts on average one transport length 1/sigma_t' along the refracted ray before it has forgotten its
  direction, so its diffusion sources sit sin(theta_t)/sigma_t' *sideways* of the entry point, towards where
  the light was heading. A pair in direction psi from that drift (cos psi = 1 straight ahead) is multiplied by
  ``exp(A (cos psi - 1)) / i0e(A)`` with ``A = d lambda(s~) s / s~`` (d = sin(theta_t), optical units): to first
  order in the drift the kernel shifted by it (lambda = -d ln R_near/dr, the slope of the near-field model, taken
  at s~ = sqrt(s^2 + a^2 + d^2), i.e. of the kernel smoothed over a patch of radius a and over the drift),
  normalised so that every ring around the source keeps its energy: the drift moves light, it does not make or
  absorb any (:meth:`NearFieldFactors.drift_factor`).

Tables per channel: N and the slope lambda in log-log on a grid of r sigma_t' in [1e-4, 1e3] (beyond, its end
values), G as a bicubic spline of ln G over (s/a, ln(a sigma_t')) on [0, PATCH_AVERAGE_RADII] x [1e-3, 8]
(beyond: N(s) below 1e-3, the quadrature above 8). Built once per material (:func:`near_field_factors`, ~1 s).

Pure array work; no I/O.
"""
from __future__ import annotations

import math
import warnings
from functools import lru_cache

import numpy as np

from meshshade.errors import ParameterError
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.near_field import NearFieldModel
from meshshade.materials import Material
from meshshade.surface.patch_average import PATCH_AVERAGE_RADII, _disc_average

#: the source models: what enters the medium at an entry sample, the kernels' own point source at z_r ("point") or
#: the near-field model ("beam")
SOURCE_MODELS = ("point", "beam")
_N_LOG_R = np.linspace(math.log(1e-4), math.log(1e3), 701)
_G_U = np.linspace(0.0, PATCH_AVERAGE_RADII, 129)
_G_LOG_A = np.arange(math.log(1e-3), math.log(8.0) + 0.1, 0.2)
#: cos(theta_t) grid of the incidence scale (linear interpolation; below its first node the first node's value)
_COS_T = np.linspace(0.05, 1.0, 96)


def check_source_model(source_model) -> str:
    """``source_model`` lower-cased if it is one of :data:`SOURCE_MODELS`; ParameterError (one line) otherwise."""
    if not isinstance(source_model, str) or source_model.lower() not in SOURCE_MODELS:
        raise ParameterError(f"source model must be one of {', '.join(SOURCE_MODELS)}, got {source_model!r}")
    return source_model.lower()


def source_model_keyword(source_model, near_field, stacklevel: int = 3):
    """The source model a function was given: ``source_model``, or the value of the keyword it replaces,
    ``near_field`` (deprecated: a DeprecationWarning attributed to the function's caller; ``stacklevel`` 3 when
    called from the function itself). Both given and different: ParameterError."""
    if near_field is None:
        return source_model
    warnings.warn("near_field= is deprecated; use source_model=", DeprecationWarning, stacklevel=stacklevel)
    if source_model is not None and source_model != near_field:
        raise ParameterError(f"source_model={source_model!r} and the deprecated near_field={near_field!r} disagree; "
                             "give source_model only")
    return near_field


class _Channel:
    """The factor tables of one medium channel (its :class:`~meshshade.kernels.near_field.NearFieldModel`),
    optical units."""

    def __init__(self, model: NearFieldModel):
        self.model = model
        self.kw = {"albedo_prime": model.albedo_prime, "eta": model.eta}
        self.g = model.g
        self.clamped = model.clamped
        self.total = model.total()
        r = np.exp(_N_LOG_R)
        with np.errstate(under="ignore", divide="ignore", invalid="ignore"):
            log_n = np.log(model.profile(r) / dipole_profile(r, **self.kw))
        ok = np.isfinite(log_n)   # far out both kernels underflow: the last finite ratio from there on
        last = int(np.flatnonzero(ok)[-1])
        log_n[last + 1:] = log_n[last]
        self.log_n = log_n
        # the near-field model's logarithmic slope -d ln R_near / d ln r (eq. (88)); where R_near underflows its
        # exponential tail continues the slope in proportion to r
        with np.errstate(under="ignore", divide="ignore"):
            log_near = np.log(model.profile(r))
        fin = np.isfinite(log_near)
        lastn = int(np.flatnonzero(fin)[-1])
        slope = -np.gradient(log_near[:lastn + 1], _N_LOG_R[:lastn + 1])
        self.slope = np.concatenate([slope, slope[-1] * r[lastn + 1:] / r[lastn]])
        self._spline = None
        self.incidence = np.array([model.incidence_gain(c) for c in _COS_T])

    # kernels and tails
    def near(self, r):
        return self.model.profile(r)

    def near_tail(self, r):
        """int_r^inf R_near 2 pi r dr (arrays)."""
        r = np.asarray(r, dtype=np.float64)
        out = np.full(r.shape, self.total)
        pos = r > 0
        if np.any(pos):
            rp = r[pos]
            out[pos] = self.total - np.pi * rp * rp * self.model.ring(0.0 * rp, rp)
        return np.maximum(out, 0.0)

    def point(self, r):
        """N(r) at optical distances r > 0."""
        lr = np.log(np.clip(r, np.exp(_N_LOG_R[0]), np.exp(_N_LOG_R[-1])))
        return np.exp(np.interp(lr, _N_LOG_R, self.log_n))

    def drift_slope(self, r):
        """lambda(r) = -d ln R_near/dr at optical distances r > 0 (per optical length)."""
        lr = np.log(np.clip(r, np.exp(_N_LOG_R[0]), np.exp(_N_LOG_R[-1])))
        return np.interp(lr, _N_LOG_R, self.slope) / r

    def disc_ratio_direct(self, s, a):
        """G(s, a) by quadrature (optical units, arrays, a > 0)."""
        near = _disc_average(s, a, profile=self.near, tail=self.near_tail, **self.kw)
        flat = _disc_average(s, a, **self.kw)
        return near / flat

    def disc(self, s, a):
        """G(s, a) for pairs with s < PATCH_AVERAGE_RADII a, a > 0 (optical units)."""
        out = np.empty(s.shape)
        small = a < math.exp(_G_LOG_A[0])
        big = a > math.exp(_G_LOG_A[-1])
        mid = ~(small | big)
        if np.any(small):   # the patch is far narrower than the kernel: the point value (at s > 0)
            out[small] = self.point(np.maximum(s[small], 1e-300))
        if np.any(big):
            out[big] = self.disc_ratio_direct(s[big], a[big])
        if np.any(mid):
            if self._spline is None:
                from scipy.interpolate import RectBivariateSpline  # lazy, as pair_kernel's tables

                u, la = np.meshgrid(_G_U, _G_LOG_A, indexing="ij")
                aa = np.exp(la).ravel()
                with np.errstate(under="ignore"):
                    f = np.log(self.disc_ratio_direct(u.ravel() * aa, aa)).reshape(u.shape)
                self._spline = RectBivariateSpline(_G_U, _G_LOG_A, f, kx=3, ky=3, s=0)
            out[mid] = np.exp(self._spline.ev(np.clip(s[mid] / a[mid], 0.0, PATCH_AVERAGE_RADII), np.log(a[mid])))
        return out


class NearFieldFactors:
    """The bake's near-field factors for one material (module docstring), per channel; lengths in mm."""

    def __init__(self, material: Material):
        self.material = material
        self._channels = {}
        self._key = [(float(material.albedo_prime[c]), float(material.eta), float(material.g)) for c in range(3)]
        for c, key in enumerate(self._key):   # a channel like an earlier one shares its tables
            if key not in self._channels:
                self._channels[key] = _Channel(material.medium.near_field(c))

    @property
    def clamped(self) -> bool:
        """Whether any channel's medium lies outside the near-field model's fitted domain (nearest node used)."""
        return any(ch.clamped for ch in self._channels.values())

    def pair_factor(self, c: int, s_mm, a_mm) -> np.ndarray:
        """(p,) factor of pairs at distances ``s_mm`` from sources of patch radius ``a_mm`` (0: a point) in channel
        ``c``: G(s, a) within PATCH_AVERAGE_RADII a, N(s) beyond."""
        st = float(self.material.sigma_t_prime[c])
        ch = self._channels[self._key[c]]
        s = np.asarray(s_mm, dtype=np.float64) * st
        a = np.broadcast_to(np.asarray(a_mm, dtype=np.float64) * st, s.shape)
        out = np.empty(s.shape)
        close = (a > 0) & (s < PATCH_AVERAGE_RADII * a)
        if np.any(close):
            out[close] = ch.disc(s[close], a[close])
        far = ~close
        if np.any(far):
            out[far] = ch.point(np.maximum(s[far], 1e-300))
        return out

    def incidence_scale(self, cos_incidence, eta: float | None = None) -> np.ndarray:
        """(k, 3): per entry sample and channel, W(cos theta_t) of the light entering at ``cos_incidence`` (k,) (from
        the outside normal; refracted with the material's eta)."""
        ci = np.clip(np.asarray(cos_incidence, dtype=np.float64), 0.0, 1.0)
        eta = float(self.material.eta if eta is None else eta)
        ct = np.sqrt(np.maximum(0.0, 1.0 - (1.0 - ci * ci) / (eta * eta)))
        return np.stack([np.interp(ct, _COS_T, self._channels[self._key[c]].incidence) for c in range(3)], axis=1)

    def drift_factor(self, c: int, s_mm, a_mm, sin_t, cos_psi) -> np.ndarray:
        """(p,) factor of pairs at distances ``s_mm`` from sources of patch radius ``a_mm`` (0: a point) whose
        light drifts sideways by ``sin_t`` / sigma_t' (sin theta_t, (p,)), the receiver lying at angle psi from the
        drift (``cos_psi`` (p,)), channel ``c`` (eq. (88)): exp(A (cos psi - 1)) / i0e(A),
        A = d lambda(s~) s / s~ with d = sin_t and s~ = sqrt(s^2 + a^2 + d^2) (optical): the slope of the kernel
        smoothed over the patch and over the drift itself, so that A stays bounded where s << d and vanishes at
        s = 0. Averages to 1 over every ring."""
        from scipy.special import i0e   # lazy, as the disc spline

        st = float(self.material.sigma_t_prime[c])
        ch = self._channels[self._key[c]]
        s = np.asarray(s_mm, dtype=np.float64) * st
        a = np.broadcast_to(np.asarray(a_mm, dtype=np.float64) * st, s.shape)
        d = np.broadcast_to(np.asarray(sin_t, dtype=np.float64), s.shape)   # the drift, optical units
        st2 = np.sqrt(s * s + a * a + d * d)
        pos = (st2 > 0.0) & (d > 0.0)
        A = np.zeros(s.shape)
        A[pos] = d[pos] * ch.drift_slope(st2[pos]) * s[pos] / st2[pos]
        return np.exp(A * (np.clip(cos_psi, -1.0, 1.0) - 1.0)) / i0e(A)

    def log_ratio_table(self) -> np.ndarray:
        """(3, m): ln N(r) per channel on the slope table's grid of ln(r sigma_t') (the compiled far field's
        per-pair near-field factor, eq. (80))."""
        return np.ascontiguousarray(np.stack([self._channels[self._key[c]].log_n for c in range(3)]))

    def slope_table(self, c: int) -> tuple[np.ndarray, float, float]:
        """(g (m,), ln r0, step): channel ``c``'s slope g = -d ln R_near / d ln r on the uniform grid ln r0 + i step
        of ln(r sigma_t') (lambda(r) = g / r), for the compiled far field."""
        ch = self._channels[self._key[c]]
        return np.ascontiguousarray(ch.slope), float(_N_LOG_R[0]), float(_N_LOG_R[1] - _N_LOG_R[0])

def refracted_drift(normals, directions, eta: float) -> np.ndarray:
    """(k, 3): the tangential part of the refracted direction of light travelling along ``directions`` (k, 3) unit
    into a surface of outward unit ``normals`` (k, 3) with relative index ``eta``: (d - (d.n) n) / eta, of length
    sin(theta_t) (Snell's law keeps the tangential component over eta). The light's sideways drift inside is
    this over sigma_t' (eq. (87))."""
    d = np.asarray(directions, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    return (d - np.einsum("ij,ij->i", d, n)[:, None] * n) / float(eta)


def drift_angles(drift, d1, d2) -> tuple[np.ndarray, np.ndarray]:
    """(sin theta_t (k,), psi (k,)): the length of each source's drift ``drift`` (k, 3) and its azimuth in the
    source's tangent frame (``d1``, ``d2`` (k, 3)), measured as the pairs' azimuth phi is."""
    sin_t = np.linalg.norm(drift, axis=1)
    psi = np.arctan2(np.einsum("ij,ij->i", drift, d2), np.einsum("ij,ij->i", drift, d1))
    return sin_t, psi


@lru_cache(maxsize=16)
def near_field_factors(material: Material) -> NearFieldFactors:
    """:class:`NearFieldFactors` of ``material``, built once per material (Material is hashable)."""
    return NearFieldFactors(material)
