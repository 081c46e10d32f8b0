"""Environment maps: which direction each pixel of an equirectangular map covers, and directions drawn in
proportion to its luminance.

Axis convention (the one Blender's Cycles and three.js use; docs/usage.md, "Lights")
    A direction w (unit, from the surface towards the sky) in the mesh's frame is first put in the map's frame,
    Z up, ``t = R_z(rotation) B w``: ``B`` is the identity for ``up = "z"`` (Blender's world, what the add-on
    passes) and ``(x, y, z) -> (x, -z, y)`` for ``up = "y"`` (glTF, OBJ, the meshes of meshshade and of
    ../shared: Blender's importers make the same conversion, so a Y-up mesh imported into Blender and lit by
    this map there is lit as here); ``R_z`` is the right-handed rotation about the up axis by ``rotation_deg``,
    what Blender's Mapping node (type Point, rotation Z) does to the World's texture vector. Then, as Cycles'
    ``direction_to_equirectangular``::

        u = 0.5 - atan2(t_y, t_x) / (2 pi)   (mod 1; the column, 0 at the image's left)
        s = acos(t_z) / pi                   (the row from the top: 0 at the zenith, 1 at the nadir)

    so the image's centre column looks along +X, u = 0.75 along +Z (Y up) or -Y (Z up), and its top row is the
    zenith. A feature at map direction t is seen from direction ``B^T R_z(-rotation) t``: rotating by +90 degrees
    moves what was along +X to -Y in Blender's frame, that is to +Z in a Y-up mesh.

Radiance and sampling
    The map is piecewise constant over its pixels: pixel (r, c) covers the solid angle
    ``Omega_r = (2 pi / W) (cos(pi r / H) - cos(pi (r + 1) / H))`` (the sin(theta) of the equirectangular
    Jacobian, integrated over the row), and a direction is drawn by picking a row from the marginal of
    ``Y Omega`` (Y the luminance per unit strength), a column from the row's conditional of Y, then a point
    uniform in solid angle inside the pixel (phi uniform, cos theta uniform). Its density is then exactly
    proportional to the radiance: ``p(w) = Y(w) / S`` with ``S = sum Y Omega`` (docs/physics.md eq. (121)).
    :meth:`MapSampler.sample` takes points of the unit square, so stratified or quasi-random points stay
    stratified on the sphere.

The map's colour: meshshade's lights are white (one power for the three channels), so an RGB map is reduced to
its Rec. 709 luminance ``0.2126 R + 0.7152 G + 0.0722 B`` (:func:`luminance`), with a warning when it is coloured.
"""
from __future__ import annotations

import functools
import math
import warnings

import numpy as np

from meshshade.light.sources import EnvironmentLight

__all__ = ["MapSampler", "map_sampler", "luminance", "environment_from_rgb", "map_frame", "REC709"]

#: Rec. 709 / sRGB luminance weights of linear R, G, B (sum 1: a grey map keeps its value)
REC709 = np.array([0.2126, 0.7152, 0.0722])
#: a map whose channels differ from their luminance by more than this share (luminance-weighted) is "coloured"
COLOUR_TOLERANCE = 1e-3


def luminance(rgb) -> np.ndarray:
    """(H, W) Rec. 709 luminance of an (H, W, 3) linear RGB image."""
    return np.asarray(rgb, dtype=np.float64) @ REC709


def environment_from_rgb(rgb, *, path=None, **kwargs) -> EnvironmentLight:
    """An :class:`~meshshade.light.sources.EnvironmentLight` of the (H, 2H, 3) linear RGB map ``rgb`` (its
    luminance, with a ``UserWarning`` when the channels differ: the colour is not used); ``kwargs``: the light's
    other fields (strength, rotation_deg, up, error, ...)."""
    rgb = np.asarray(rgb, dtype=np.float64)
    Y = luminance(rgb)
    spread = np.abs(rgb - Y[..., None]).max(axis=-1)
    if float(spread.sum()) > COLOUR_TOLERANCE * max(float(Y.sum()), 1e-300):
        name = f"environment map {str(path)!r}" if path is not None else "the environment map"
        warnings.warn(f"{name} is coloured: meshshade's lights are white, so its luminance (Rec. 709) is used",
                      UserWarning, stacklevel=2)
    return EnvironmentLight(Y, path=None if path is None else str(path), **kwargs)


def map_frame(up: str, rotation_deg: float) -> np.ndarray:
    """(3, 3) float64 M with ``t = M w``: a mesh-frame direction w in the map's Z-up frame (module docstring)."""
    B = np.eye(3) if up == "z" else np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    a = math.radians(rotation_deg)
    c, s = math.cos(a), math.sin(a)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return R @ B


class MapSampler:
    """The sampling tables of one :class:`~meshshade.light.sources.EnvironmentLight` (float64 throughout).

    Attributes: ``frame`` (3, 3) (:func:`map_frame`), ``cos_edges`` (H + 1,) cos theta at the rows' edges (1 at the
    top, -1 at the bottom), ``row_cdf`` (H,), ``col_cdf`` (H, W) (rows without light: uniform), ``lum`` (H, W)
    luminance per unit strength, ``total`` = S = sum Y Omega (the integral of Y over all directions,
    W/mm^2 per unit strength), ``strength``.
    """

    def __init__(self, light: EnvironmentLight):
        Y = light.radiance
        H, W = Y.shape
        self.H, self.W = H, W
        self.lum = Y
        self.strength = float(light.strength)
        self.frame = map_frame(light.up, light.rotation_deg)
        ce = np.cos(np.pi * np.arange(H + 1) / H)
        ce[0], ce[-1] = 1.0, -1.0
        self.cos_edges = ce
        omega = (2.0 * np.pi / W) * (ce[:-1] - ce[1:])
        P = Y * omega[:, None]
        row = P.sum(axis=1)
        self.total = float(row.sum())
        self.row_cdf = np.cumsum(row) / self.total
        self.row_cdf[-1] = 1.0
        csum = np.cumsum(Y, axis=1)
        tot = csum[:, -1:]
        uniform = np.broadcast_to((np.arange(1, W + 1) / W)[None, :], (H, W))
        with np.errstate(invalid="ignore", divide="ignore"):
            self.col_cdf = np.where(tot > 0.0, csum / np.where(tot > 0.0, tot, 1.0), uniform)
        self.col_cdf[:, -1] = 1.0
        # every row's CDF offset by twice its index, flattened: one searchsorted finds a column in any row
        self._flat_cdf = (self.col_cdf + 2.0 * np.arange(H)[:, None]).ravel()

    # --- directions <-> pixels -----------------------------------------------------------------------
    def pixels(self, w) -> tuple[np.ndarray, np.ndarray]:
        """(row, column) int64 of the pixel that holds each unit direction ``w`` (k, 3) (mesh frame)."""
        t = np.asarray(w, dtype=np.float64) @ self.frame.T
        u = np.mod(0.5 - np.arctan2(t[:, 1], t[:, 0]) / (2.0 * np.pi), 1.0)
        s = np.arccos(np.clip(t[:, 2], -1.0, 1.0)) / np.pi
        col = np.minimum((u * self.W).astype(np.int64), self.W - 1)
        row = np.minimum((s * self.H).astype(np.int64), self.H - 1)
        return row, col

    def radiance(self, w) -> np.ndarray:
        """(k,) W/(mm^2 sr): the light's radiance arriving from the unit directions ``w`` (k, 3)."""
        row, col = self.pixels(w)
        return self.strength * self.lum[row, col]

    def pdf(self, w) -> np.ndarray:
        """(k,) 1/sr: the density of :meth:`sample` at the unit directions ``w`` (k, 3): Y(w) / S."""
        row, col = self.pixels(w)
        return self.lum[row, col] / self.total

    def sample(self, x, y) -> np.ndarray:
        """(k, 3) unit directions (mesh frame) for the points (x, y) of [0, 1)^2, drawn with density :meth:`pdf`
        (continuous inversion of the row and column distributions: strata of the square stay strata)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        row = np.minimum(np.searchsorted(self.row_cdf, x, side="right"), self.H - 1)
        lo = np.where(row > 0, self.row_cdf[np.maximum(row - 1, 0)], 0.0)
        a = np.clip((x - lo) / (self.row_cdf[row] - lo), 0.0, 1.0)
        col = np.minimum(np.searchsorted(self._flat_cdf, y + 2.0 * row, side="right") - row * self.W, self.W - 1)
        col = np.maximum(col, 0)
        cdf = self.col_cdf
        clo = np.where(col > 0, cdf[row, np.maximum(col - 1, 0)], 0.0)
        b = np.clip((y - clo) / (cdf[row, col] - clo), 0.0, 1.0)
        cos_t = self.cos_edges[row] + a * (self.cos_edges[row + 1] - self.cos_edges[row])
        sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
        phi = np.pi - 2.0 * np.pi * (col + b) / self.W
        t = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
        return t @ self.frame        # M^T t: back to the mesh's frame


@functools.lru_cache(maxsize=8)
def map_sampler(light: EnvironmentLight) -> MapSampler:
    """The :class:`MapSampler` of ``light`` (kept for the last few lights: the bake and Monte Carlo share it)."""
    return MapSampler(light)
