"""Sampling of the Monte Carlo random walk: Russian roulette constants, Henyey-Greenstein scattering, refraction.

Pure array functions on float64 unit directions (n, 3); random numbers come from a ``numpy.random.Generator``.
The pooled engine's compiled loops (:mod:`meshshade.montecarlo.loops`) implement the same physics per photon.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from meshshade.kernels.fresnel import refract_in  # noqa: F401 - part of the walk's sampling API

__all__ = ["ROULETTE_THRESHOLD", "ROULETTE_BOOST", "GroupMedium", "sample_hg_cos", "scatter_directions",
           "refract_in"]

#: Russian roulette starts below this fraction of the photon's initial weight
ROULETTE_THRESHOLD = 1e-4
#: a photon survives the roulette with probability 1/ROULETTE_BOOST, its weight multiplied by ROULETTE_BOOST
ROULETTE_BOOST = 10.0


class GroupMedium(NamedTuple):
    """The medium one channel group's photons walk in (both engines, :class:`~meshshade.montecarlo.engine.PoolWalk`
    and :class:`~meshshade.montecarlo.wavefront_oracle.WavefrontWalk`).

    Attributes
    ----------
    sigma_s, sigma_a : float, 1/mm
        Scattering and absorption coefficients (not reduced: the walk samples the phase function).
    g : float
        Henyey-Greenstein anisotropy.
    eta : float
        Relative index of refraction of the medium.
    """

    sigma_s: float
    sigma_a: float
    g: float
    eta: float

    @property
    def sigma_t(self) -> float:
        """Extinction coefficient sigma_s + sigma_a, 1/mm."""
        return self.sigma_s + self.sigma_a

    @property
    def albedo(self) -> float:
        """Single-scattering albedo sigma_s / sigma_t (0 where sigma_t is 0)."""
        return self.sigma_s / self.sigma_t if self.sigma_t > 0 else 0.0


def _orthonormal_basis(d):
    """(t, b) unit vectors orthogonal to unit ``d`` (n, 3) (Duff et al. 2017, branchless)."""
    sign = np.where(d[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + d[:, 2])
    b = d[:, 0] * d[:, 1] * a
    t = np.stack([1.0 + sign * d[:, 0] ** 2 * a, sign * b, -sign * d[:, 0]], axis=1)
    s = np.stack([b, sign + d[:, 1] ** 2 * a, -d[:, 1]], axis=1)
    return t, s


def sample_hg_cos(g: float, u) -> np.ndarray:
    """cos(theta) of the Henyey-Greenstein phase function with anisotropy ``g`` by inversion (u uniform in [0, 1))."""
    u = np.asarray(u, dtype=np.float64)
    if abs(g) < 1e-6:
        return 1.0 - 2.0 * u
    tmp = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - tmp * tmp) / (2.0 * g), -1.0, 1.0)


def scatter_directions(d, g: float, rng) -> np.ndarray:
    """New unit directions (n, 3) after HG scattering of unit directions ``d`` (n, 3)."""
    n = d.shape[0]
    cos_t = sample_hg_cos(g, rng.random(n))
    sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
    phi = 2.0 * np.pi * rng.random(n)
    t, b = _orthonormal_basis(d)
    out = (sin_t * np.cos(phi))[:, None] * t + (sin_t * np.sin(phi))[:, None] * b + cos_t[:, None] * d
    return out / np.linalg.norm(out, axis=1, keepdims=True)
