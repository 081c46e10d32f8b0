"""The near-field model in the bake (``near_field="beam"``; docs/physics.md §13.2, eq. (80)).

Every kernel of the bake answers a point source at depth z_r. With ``near_field="beam"`` each pair's value is
multiplied by the ratio of the half-space's near-field model (:mod:`meshshade.kernels.near_field`, eq. (76): exact
single scattering plus the beam's fitted diffusion sources) to the planar dipole, so that every model carries the
same near field as the factor of eq. (79):

* a pair at distance s from a point: ``N(s) = R_near(s) / R_d(s)``;
* a pair within PATCH_AVERAGE_RADII patch radii of a source patch of radius a (vertex samples; and, for beams, the
  receiver's own patch, since a vertex's exitance is the average over the patch it stands for):
  ``G(s, a) = <R_near>_a(s) / <R_d>_a(s)``, the ratio of the two kernels' averages over the disc (the same
  quadrature as the dipole's patch average, pair_kernel.py), on top of the dipole's patch factor;
* the far field (pairs beyond the near radius r, summed by clusters of the planar dipole): the ratio of the two
  kernels' tails ``T_near(r) / T_d(r)``, so that the energy it carries is the near-field model's;
* the direction the light travels inside (docs/physics.md eq. (81)): an entry sample whose light enters at
  incidence theta_i refracts to theta_t, and the near-field model's sources then lie at depths cos(theta_t) t_k;
  the sample's power is scaled by ``W(cos theta_t) = T_near(0; cos theta_t) / T_near(0; 1)``, the ratio of the
  model's totals (its profile keeps the normal-incidence shape).

Tables per channel: N in log-log on a grid of r sigma_t' in [1e-4, 1e3] (beyond, its end values), G as a bicubic
spline of ln G over (s/a, ln(a sigma_t')) on [0, PATCH_AVERAGE_RADII] x [1e-3, 8] (beyond: N(s) below 1e-3, the
quadrature above 8). Built once per material (:func:`near_field_factors`, ~1 s).

Pure array work; no I/O.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from meshshade.errors import ParameterError
from meshshade.kernels.dipole import dipole_profile, dipole_tail_reflectance
from meshshade.kernels.near_field import near_field_profile, near_field_ring, near_field_sources, near_field_total
from meshshade.materials import Material
from meshshade.transport.pair_kernel import PATCH_AVERAGE_RADII, _disc_average

#: what enters the medium in the bake: the kernels' own point source at z_r, or the near-field model
NEAR_FIELDS = ("point", "beam")
_N_LOG_R = np.linspace(math.log(1e-4), math.log(1e3), 701)
_G_U = np.linspace(0.0, PATCH_AVERAGE_RADII, 129)
_G_LOG_A = np.arange(math.log(1e-3), math.log(8.0) + 0.1, 0.2)
#: cos(theta_t) grid of the incidence scale (linear interpolation; below its first node the first node's value)
_COS_T = np.linspace(0.05, 1.0, 96)


def check_near_field(near_field) -> str:
    """``near_field`` lower-cased if it is one of :data:`NEAR_FIELDS`; ParameterError (one line) otherwise."""
    if not isinstance(near_field, str) or near_field.lower() not in NEAR_FIELDS:
        raise ParameterError(f"near field must be one of {', '.join(NEAR_FIELDS)}, got {near_field!r}")
    return near_field.lower()


class _Channel:
    """The factor tables of one (alpha', eta, g), optical units."""

    def __init__(self, albedo_prime: float, eta: float, g: float):
        self.kw = {"albedo_prime": albedo_prime, "eta": eta}
        self.g = g
        self.clamped = near_field_sources(albedo_prime, eta, g)[2]
        self.total = near_field_total(g=g, **self.kw)
        r = np.exp(_N_LOG_R)
        with np.errstate(under="ignore", divide="ignore", invalid="ignore"):
            log_n = np.log(near_field_profile(r, g=g, **self.kw) / dipole_profile(r, **self.kw))
        ok = np.isfinite(log_n)   # far out both kernels underflow: the last finite ratio from there on
        last = int(np.flatnonzero(ok)[-1])
        log_n[last + 1:] = log_n[last]
        self.log_n = log_n
        self._spline = None
        self.incidence = np.array([near_field_total(g=g, cos_t=c, **self.kw) for c in _COS_T]) / self.total

    # kernels and tails
    def near(self, r):
        return near_field_profile(r, g=self.g, **self.kw)

    def near_tail(self, r):
        """int_r^inf R_near 2 pi r dr (arrays)."""
        r = np.asarray(r, dtype=np.float64)
        out = np.full(r.shape, self.total)
        pos = r > 0
        if np.any(pos):
            rp = r[pos]
            out[pos] = self.total - np.pi * rp * rp * near_field_ring(0.0 * rp, rp, g=self.g, **self.kw)
        return np.maximum(out, 0.0)

    def point(self, r):
        """N(r) at optical distances r > 0."""
        lr = np.log(np.clip(r, np.exp(_N_LOG_R[0]), np.exp(_N_LOG_R[-1])))
        return np.exp(np.interp(lr, _N_LOG_R, self.log_n))

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
        for c in range(3):
            key = (float(material.albedo_prime[c]), float(material.eta), float(material.g))
            if key not in self._channels:
                self._channels[key] = _Channel(*key)
        self._key = [(float(material.albedo_prime[c]), float(material.eta), float(material.g)) for c in range(3)]

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

    def far_scale(self, c: int, r_mm: float) -> float:
        """T_near(r) / T_d(r): the energy of the near-field model beyond r over the dipole's (channel c)."""
        st = float(self.material.sigma_t_prime[c])
        ch = self._channels[self._key[c]]
        r = float(r_mm) * st
        flat = float(dipole_tail_reflectance(r, **ch.kw))
        return float(ch.near_tail(np.array([r]))[0] / flat) if flat > 0 else 1.0


@lru_cache(maxsize=16)
def near_field_factors(material: Material) -> NearFieldFactors:
    """:class:`NearFieldFactors` of ``material``, built once per material (Material is hashable)."""
    return NearFieldFactors(material)
