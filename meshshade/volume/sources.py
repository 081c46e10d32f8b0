"""Where the entering light becomes diffuse: sources along the refracted rays (docs/physics.md §15, eq. (95)).

Light that enters with power P along the refracted unit direction w is scattered for the first time at depth t
along w with density sigma_s' P exp(-sigma_t' t) (W/mm): in all alpha' P, at mean distance 1/sigma_t' (the
similarity-reduced medium, as the dipole's source at z_r = 1/sigma_t'). The line source is replaced by an
n-point Gauss-Laguerre rule: points t_j = x_j / sigma_t' carrying alpha' P w_j, exact for the power and for
every polynomial moment of t up to degree 2n - 1. A single point at 1/sigma_t' (n = 1) is the classic dipole's.
The refracted directions come from :func:`meshshade.kernels.fresnel.refract_in`.
"""
from __future__ import annotations

import numpy as np
from numpy.polynomial.laguerre import laggauss

from meshshade.errors import MeshshadeError

__all__ = ["line_sources", "line_source_rule", "SOURCE_POINTS"]

#: points per entry sample and channel (eq. (97): exact for the power and the moments of t up to degree 7)
SOURCE_POINTS = 4


def line_source_rule(albedo_prime: float, n: int = SOURCE_POINTS):
    """(distances (n,), strengths (n,)), optical units: the line density alpha' exp(-t) as its n-point
    Gauss-Laguerre rule (eq. (97)): the same total alpha' and the same moments of t up to degree 2n - 1."""
    x, w = laggauss(int(n))
    return x, float(albedo_prime) * w


def line_sources(positions, refracted, power, *, sigma_t_prime, albedo_prime, n_points=SOURCE_POINTS):
    """Point sources ``(points (k n, 3) mm, powers (k n,) W)`` of eq. (95) for entries at ``positions`` (k, 3)
    with ``refracted`` unit directions (k, 3) and entering ``power`` (k,) W, in a medium of sigma_t' (1/mm) and
    reduced albedo alpha'. Every entry's points sum to alpha' P."""
    if not (sigma_t_prime > 0 and 0.0 <= albedo_prime <= 1.0 and int(n_points) >= 1):
        raise MeshshadeError("line sources need sigma_t' > 0, alpha' in [0, 1] and at least one point")
    x, w = line_source_rule(albedo_prime, n_points)
    t = x / sigma_t_prime                                            # (n,) mm
    pos = np.asarray(positions, dtype=np.float64)
    pts = pos[:, None, :] + t[None, :, None] * np.asarray(refracted, dtype=np.float64)[:, None, :]
    pw = np.asarray(power, dtype=np.float64)[:, None] * w[None, :]
    return pts.reshape(-1, 3), pw.reshape(-1)
