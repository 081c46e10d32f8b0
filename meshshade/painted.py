"""A painted material: a base material whose colour an artist painted over the surface (docs/physics.md §17).

:class:`PaintedMaterial` keeps the base material's index and anisotropy, and its mean free path 1/sigma_t' per
channel unless a radius map scales it (eq. (132)), and takes the reduced albedo from the painted colour, the diffuse
reflectance the medium under the paint must have (:func:`meshshade.kernels.painted_reflectance.albedo_for_reflectance`,
eq. (106); a scale-free inversion, so it holds for any mean free path). The colour is given on the input mesh: per
vertex (``colour`` (n_vertices, 3), linear) or as an image over its UV map (``image`` (H, W, 3) linear, ``uv``
(m, 3, 2) per face corner), read bilinearly at any surface point (:meth:`PaintedMaterial.colour_at`); the radius map
likewise (``radius`` per vertex or ``radius_image`` over the same UVs: a factor on the base's mean free path,
:meth:`PaintedMaterial.radius_at`). The painted medium reaches through the whole object, each point of the volume
taking the medium of the nearest sampled surface point (§17); the bake reads it there
(:mod:`meshshade.volume.transport`).
"""
from __future__ import annotations

import hashlib
import warnings

import numpy as np

from meshshade.errors import DiffusionValidityWarning, MaterialError
from meshshade.kernels.painted_reflectance import albedo_for_reflectance, model_total_reflectance, reflectance_range
from meshshade.materials import LOW_ALBEDO_WARNING, Material

__all__ = ["PaintedMaterial", "CLAMP_MARGIN"]

#: a clamped colour lies this fraction of the reachable range inside its ends (eq. (106) has a root there)
CLAMP_MARGIN = 1e-3


class PaintedMaterial:
    """``base`` (a :class:`~meshshade.materials.Material`) painted with ``colour`` (n_vertices, 3) per vertex, or
    ``image`` (H, W, 3) over the mesh's per-corner ``uv`` (m, 3, 2); colours linear, per channel in the range the
    model reaches (a MaterialError naming it otherwise, :func:`albedo_for_reflectance`), or with ``clamp`` moved
    into it (a stated clamp: ``clamped`` counts the values moved, ``clamp_range`` the range).

    A radius map scales the base's mean free path per point (eq. (132)): ``radius`` per vertex, (n_vertices,) or
    (n_vertices, 3), or ``radius_image`` (H', W') or (H', W', 3) over the same ``uv``; finite factors above 0 (a
    MaterialError otherwise: no medium has a mean free path of 0), one value for the three channels or one per
    channel. With a radius map and no colour, the colour is the base's own total diffuse reflectance everywhere
    (eq. (105)): only the mean free path varies."""

    def __init__(self, base: Material, *, colour=None, image=None, uv=None, name: str | None = None,
                 clamp: bool = False, radius=None, radius_image=None):
        if not isinstance(base, Material):
            raise MaterialError(f"a painted material needs a base Material, got {type(base).__name__}")
        if colour is not None and image is not None:
            raise MaterialError("a painted material takes either per-vertex colours or an image over the UVs")
        if radius is not None and radius_image is not None:
            raise MaterialError("a radius map is either per vertex or an image over the UVs, not both")
        if colour is None and image is None:
            if radius is None and radius_image is None:
                raise MaterialError("a painted material needs a colour (per vertex or a map) or a radius map")
            own = model_total_reflectance(base.albedo_prime, base.eta, base.g)      # the base's own colour
            if radius is not None:
                colour = np.tile(own, (np.asarray(radius).shape[0], 1))
            else:
                image = own.reshape(1, 1, 3)
        self.base = base
        self.name = name or f"{base.name} painted"
        lo, hi = reflectance_range(base.eta, base.g)
        self.clamp_range = (lo + CLAMP_MARGIN * (hi - lo), hi - CLAMP_MARGIN * (hi - lo))
        self.clamped = 0
        if clamp:
            def clamp_(v):
                v = np.asarray(v, dtype=np.float64)
                out = np.clip(v, *self.clamp_range)
                self.clamped += int(np.sum(out != v))
                return out
            colour = None if colour is None else clamp_(colour)
            image = None if image is None else clamp_(image)
        if colour is not None:
            colour = np.asarray(colour, dtype=np.float64)
            if colour.ndim != 2 or colour.shape[1] != 3:
                raise MaterialError(f"vertex colours must be (n, 3), got shape {colour.shape}")
            self._check(colour)
            self.colour, self.image = colour, None
        else:
            image = np.asarray(image, dtype=np.float64)
            if image.ndim != 3 or image.shape[2] != 3:
                raise MaterialError(f"a colour map must be (H, W, 3), got shape {image.shape}")
            self._check(image)
            self.colour, self.image = None, image
        if (image is not None or radius_image is not None) and uv is None:
            raise MaterialError("a colour map needs the mesh's texture coordinates (UVs); the mesh has none"
                                if radius_image is None else
                                "a radius map needs the mesh's texture coordinates (UVs); the mesh has none")
        self.uv = None if uv is None or (image is None and radius_image is None) else np.asarray(uv, dtype=np.float64)
        self.radius, self.radius_image = _radius_values(radius, 1), _radius_values(radius_image, 2)
        if self.radius is not None and self.colour is not None and self.radius.shape[0] != self.colour.shape[0]:
            raise MaterialError(f"the radius map has {self.radius.shape[0]} vertex values and the paint "
                                f"{self.colour.shape[0]} vertex colours")
        rad = self.radius if self.radius is not None else self.radius_image
        self._radius_range = ((np.ones(3), np.ones(3)) if rad is None else
                              (rad.reshape(-1, 3).min(axis=0), rad.reshape(-1, 3).max(axis=0)))
        low = self.albedo_range()[0] < LOW_ALBEDO_WARNING
        if np.any(low):
            warnings.warn(f"painted material {self.name!r}: the paint's darkest colours need a reduced albedo below "
                          f"{LOW_ALBEDO_WARNING} in channel(s) {','.join(c for c, f in zip('rgb', low) if f)}, where "
                          "diffusion theory is inaccurate", DiffusionValidityWarning, stacklevel=2)
        data = self.colour if self.colour is not None else self.image
        digest = hashlib.sha1(np.ascontiguousarray(data).tobytes())
        if rad is not None:
            digest.update(np.ascontiguousarray(rad).tobytes())
        self._digest = digest.hexdigest()[:12]

    def _check(self, colours):
        """Every painted value's albedo (eq. (106); a MaterialError for one no medium has), kept as its range."""
        alb = albedo_for_reflectance(colours.reshape(-1, 3), self.base.eta, self.base.g)
        self._albedo_range = (alb.min(axis=0), alb.max(axis=0))

    # --- the base's constants -----------------------------------------------------------------------------
    @property
    def eta(self) -> float:
        return self.base.eta

    @property
    def g(self) -> float:
        return self.base.g

    @property
    def sigma_t_prime(self) -> np.ndarray:
        """(3,) 1/mm: the base's reduced extinction (the paint's where no radius map scales it:
        :meth:`sigma_t_prime_range`)."""
        return self.base.sigma_t_prime

    @property
    def has_radius(self) -> bool:
        """Whether a radius map scales the mean free path (eq. (132))."""
        return self.radius is not None or self.radius_image is not None

    def describe(self) -> str:
        kind = "vertex colours" if self.colour is not None else f"a {self.image.shape[1]}x{self.image.shape[0]} map"
        if self.radius is not None:
            kind += " and a radius per vertex"
        elif self.radius_image is not None:
            kind += f" and a {self.radius_image.shape[1]}x{self.radius_image.shape[0]} radius map"
        return f"{self.base.describe()}, painted with {kind} ({self._digest})"

    def to_dict(self) -> dict:
        return {**self.base.to_dict(), "name": self.name, "painted": self.describe()}

    def check_mesh(self, mesh) -> None:
        """MaterialError unless the paint fits ``mesh``: a colour (and radius) per vertex, or a UV map per face."""
        if self.colour is not None and self.colour.shape[0] != mesh.n_vertices:
            raise MaterialError(f"the painted material has {self.colour.shape[0]} vertex colours for a mesh of "
                                f"{mesh.n_vertices} vertices")
        if self.radius is not None and self.radius.shape[0] != mesh.n_vertices:
            raise MaterialError(f"the painted material has {self.radius.shape[0]} vertex radius factors for a mesh of "
                                f"{mesh.n_vertices} vertices")
        if self.uv is not None and self.uv.shape[:2] != (mesh.n_faces, 3):
            raise MaterialError(f"the painted material's UV map is for {self.uv.shape[0]} faces, the mesh has "
                                f"{mesh.n_faces}")

    # --- the paint ---------------------------------------------------------------------------------------------
    def colour_at(self, faces, faces_of_mesh, bary) -> np.ndarray:
        """(k, 3) the painted colour at points given by their input ``faces`` (k,), the mesh's face array
        ``faces_of_mesh`` (m, 3) and barycentrics ``bary`` (k, 3): vertex colours interpolated, or the image read
        bilinearly at the interpolated UV (wrapped, v up)."""
        return self._read(self.colour, self.image, faces, faces_of_mesh, bary)

    def radius_at(self, faces, faces_of_mesh, bary) -> np.ndarray:
        """(k, 3): the radius map's factor on the base's mean free path at points given as for :meth:`colour_at`
        (read the same way; 1 without a radius map)."""
        if not self.has_radius:
            return np.ones((len(faces), 3))
        return self._read(self.radius, self.radius_image, faces, faces_of_mesh, bary)

    def sigma_t_prime_at(self, faces, faces_of_mesh, bary) -> np.ndarray:
        """(k, 3) 1/mm: the reduced extinction at points given as for :meth:`colour_at` (eq. (132))."""
        return self.base.sigma_t_prime / self.radius_at(faces, faces_of_mesh, bary)

    def _read(self, per_vertex, image, faces, faces_of_mesh, bary) -> np.ndarray:
        faces = np.asarray(faces, dtype=np.int64)
        bary = np.asarray(bary, dtype=np.float64)
        if per_vertex is not None:
            return np.einsum("km,kmc->kc", bary, per_vertex[np.asarray(faces_of_mesh)[faces]])
        uv = np.einsum("km,kmd->kd", bary, self.uv[faces])
        H, W = image.shape[:2]
        x = np.mod(uv[:, 0], 1.0) * W - 0.5
        y = (1.0 - np.mod(uv[:, 1], 1.0)) * H - 0.5
        x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        xa, xb = np.mod(x0, W), np.mod(x0 + 1, W)
        ya, yb = np.clip(y0, 0, H - 1), np.clip(y0 + 1, 0, H - 1)
        im = image
        return ((1 - fy) * ((1 - fx) * im[ya, xa] + fx * im[ya, xb]) + fy * ((1 - fx) * im[yb, xa] + fx * im[yb, xb]))

    def albedo_range(self) -> tuple[np.ndarray, np.ndarray]:
        """((3,), (3,)): the least and the largest reduced albedo per channel over the whole paint (every vertex
        or texel)."""
        return self._albedo_range

    def radius_range(self) -> tuple[np.ndarray, np.ndarray]:
        """((3,), (3,)): the least and the largest factor of the radius map per channel (1, 1 without one)."""
        return self._radius_range

    def sigma_t_prime_range(self) -> tuple[np.ndarray, np.ndarray]:
        """((3,), (3,)) 1/mm: the least and the largest reduced extinction per channel over the paint."""
        lo, hi = self._radius_range
        st = np.asarray(self.base.sigma_t_prime, dtype=np.float64)
        return st / hi, st / lo

    def material_of(self, albedo_prime, name: str = "painted", sigma_t_prime=None) -> Material:
        """A homogeneous Material of reduced albedo ``albedo_prime`` (3,) at ``sigma_t_prime`` (3,) (the base's by
        default), and the base's eta and g."""
        a = np.asarray(albedo_prime, dtype=np.float64)
        st = self.base.sigma_t_prime if sigma_t_prime is None else np.asarray(sigma_t_prime, dtype=np.float64)
        with warnings.catch_warnings():       # the paint's low albedos are said once, where it is made
            warnings.simplefilter("ignore", DiffusionValidityWarning)
            return Material(a * st, (1.0 - a) * st, self.base.eta, self.base.g, name)


def _radius_values(values, point_axes: int):
    """A radius map's factors as (n, 3) (``point_axes`` 1: per vertex) or (H, W, 3) (2: an image), a single
    channel repeated; None for None. A MaterialError for a shape that is neither or a factor that is not finite
    and above 0 (eq. (132))."""
    if values is None:
        return None
    v = np.asarray(values, dtype=np.float64)
    what = "per-vertex radius factors" if point_axes == 1 else "a radius map"
    if v.ndim == point_axes:
        v = np.repeat(v[..., None], 3, axis=-1)
    if v.ndim != point_axes + 1 or v.shape[-1] != 3 or v.size == 0:
        shape = "(n,) or (n, 3)" if point_axes == 1 else "(H, W) or (H, W, 3)"
        raise MaterialError(f"{what} must be {shape}, got shape {np.shape(values)}")
    bad = ~(np.isfinite(v) & (v > 0.0))
    if bad.any():
        raise MaterialError(f"{what} holds {int(bad.any(axis=-1).sum())} value(s) that are not a finite factor above "
                            "0 (no medium has a mean free path of 0)")
    return np.ascontiguousarray(v)
