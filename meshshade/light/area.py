"""Area lights: points drawn uniformly over a rectangle or disc emitter, and what a point sees of it.

A one-sided Lambertian emitter of area A_e and power P has radiance L_e = P / (pi A_e) towards every direction of
its front half-space. The irradiance it delivers at a surface point x of normal n is

    E(x) = integral over the emitter of L_e cos(theta_e) cos(theta_x) / d^2 V(x, y) dA(y)

(docs/physics.md eq. (122)); with points y_k uniform over the emitter (density 1 / A_e) the estimate is
``(A_e / K) sum_k L_e cos_e cos_x V / d^2``. :func:`emitter_points` maps points of the unit square to the
emitter so that stratified points stay stratified: a rectangle linearly, a disc (ellipse) by
``r = sqrt(x), phi = 2 pi y`` (uniform in area).
"""
from __future__ import annotations

import numpy as np

from meshshade.light.sources import AreaLight

__all__ = ["emitter_points", "emitter_frame"]


def emitter_frame(light: AreaLight) -> np.ndarray:
    """(4, 3) float64: the emitter's centre (mm), axes u and v, and normal, one per row."""
    u, v = light.axes()
    return np.stack([np.array(light.position), u, v, np.array(light.normal)])


def emitter_points(light: AreaLight, x, y) -> np.ndarray:
    """(k, 3) mm: points of the emitter for the points (x, y) of [0, 1)^2, uniform over its area."""
    c, u, v, _n = emitter_frame(light)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    a, b = light.size
    if light.shape == "rect":
        s, t = (x - 0.5) * a, (y - 0.5) * b
    else:
        r = np.sqrt(x)
        phi = 2.0 * np.pi * y
        s, t = a * r * np.cos(phi), b * r * np.sin(phi)
    return c + s[:, None] * u + t[:, None] * v
