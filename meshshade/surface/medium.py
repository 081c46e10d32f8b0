"""What the surface models read of a material, made once per bake: :class:`SurfaceMedium`.

The surface family (the dipole, the curved kernel, the exact sphere, the fitted and auto models: docs/physics.md
§2-§13) reads, per colour channel, the material's coefficients and Jensen's dipole (from the material's
:class:`~meshshade.medium.Medium`), and three things derived from them that every stage of a bake needs:

* the neighbourhood's cutoff radii (:func:`~meshshade.surface.gather.cutoff_radii`: the dipole's reflectance
  beyond them is below ``cutoff_tol`` of its total), read by the hierarchical transport, the direct sum and the
  bake's result; the radii within which the far field's distance check compares (:data:`CHECK_CUTOFF_TOL`); the
  far field's radius (:func:`~meshshade.surface.farfield.far_field_radius` at ``far_tol``);
* the near field's factors (:class:`~meshshade.surface.source_factors.NearFieldFactors`, eqs. (80)-(88)) with the
  ``beam`` source model (None with ``point``), read by the sources' incidence scale, the drift, the gather and the
  far field;
* the exact sphere's tables (:class:`~meshshade.surface.kernel_evaluation.SphereTables`, eq. (40)), whose radius
  bins grow as sources ask for them and are shared by every kernel of the bake.

:func:`surface_medium` makes the record where a surface bake starts (:func:`meshshade.surface.baking.surface_bake`);
the transport, the direct sum and the kernels take it in place of the material, so that no stage computes these
again. It answers to the attributes the kernels' parameter builders read of a material (``sigma_t_prime``,
``albedo_prime``, ``eta``, ``g``, ``medium``, :meth:`SurfaceMedium.channel`, :meth:`SurfaceMedium.describe`), so a
:class:`~meshshade.materials.Material` may still be given to the surface family's public functions directly.
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import ParameterError
from meshshade.materials import Material
from meshshade.kernels.dipole import dipole_cutoff_radii
from meshshade.surface.farfield import DEFAULT_FAR_TOL, check_far_tol
from meshshade.surface.kernel_evaluation import SphereTables
from meshshade.surface.options import SurfaceOptions
from meshshade.surface.source_factors import NearFieldFactors, near_field_factors

__all__ = ["SurfaceMedium", "surface_medium", "CHECK_CUTOFF_TOL"]

#: the far field's distance check (surface/hierarchical.py) compares the pairs within the radius holding all but
#: this fraction of the dipole's total
CHECK_CUTOFF_TOL = 1e-2


class SurfaceMedium:
    """The surface models' record of one material for one bake (module docstring).

    material : the :class:`~meshshade.materials.Material`; medium : its :class:`~meshshade.medium.Medium`
    sigma_t_prime, albedo_prime : (3,) 1/mm and reduced albedo per channel; eta, g : floats
    cutoff_tol : the cutoff's tolerance; cutoff_mm : (3,) mm, the cutoff radii at it (not yet capped by a mesh's
    scale: the bake caps them); check_cutoff_mm : (3,) mm, those at CHECK_CUTOFF_TOL
    far_tol : the far field's tail share; far_mm : (3,) mm, the far field's radius at it
    source_model : "point" or "beam"; near : NearFieldFactors with "beam", else None
    sphere : SphereTables at ``rtol`` (shared, grown on demand)
    """

    def __init__(self, material: Material, *, cutoff_tol: float, source_model: str = "point",
                 rtol: float = 1e-10, far_tol: float = DEFAULT_FAR_TOL):
        if source_model not in ("point", "beam"):
            raise ValueError(f"source_model must be 'point' or 'beam', got {source_model!r}")
        self.material = material
        self.medium = material.medium
        self.sigma_t_prime = self.medium.sigma_t_prime
        self.albedo_prime = self.medium.albedo_prime
        self.eta = float(self.medium.eta)
        self.g = float(self.medium.g)
        self.cutoff_tol = float(cutoff_tol)
        self.far_tol = check_far_tol(far_tol)
        # the three radii of the dipole's tail (gather.cutoff_radii, farfield.far_field_radius), in one pass
        self.cutoff_mm, self.check_cutoff_mm, self.far_mm = (
            dipole_cutoff_radii(tol, sigma_t_prime=self.sigma_t_prime, albedo_prime=self.albedo_prime, eta=self.eta)
            for tol in (self.cutoff_tol, CHECK_CUTOFF_TOL, self.far_tol))
        for a in (self.cutoff_mm, self.check_cutoff_mm, self.far_mm):
            a.flags.writeable = False
        self.source_model = source_model
        self.near: NearFieldFactors | None = near_field_factors(material) if source_model == "beam" else None
        self.rtol = float(rtol)
        self.sphere = SphereTables(material, self.rtol)

    def channel(self, c: int) -> dict:
        """Channel ``c``'s coefficients, as :meth:`Material.channel <meshshade.materials.Material.channel>`."""
        return self.material.channel(c)

    def describe(self) -> str:
        """The material's one-line description (what the bake's caches are keyed on)."""
        return self.material.describe()

    def __repr__(self) -> str:
        cut = "/".join(f"{x:.3g}" for x in np.asarray(self.cutoff_mm))
        return (f"<SurfaceMedium of {self.describe()}: cutoff {cut} mm at {self.cutoff_tol:g}, "
                f"source model {self.source_model}>")


def surface_medium(material, options: SurfaceOptions | None = None, source_model: str | None = None
                   ) -> SurfaceMedium:
    """The :class:`SurfaceMedium` of ``material`` under the surface ``options`` (default ones for None) and
    ``source_model`` (None: the options', else "point"). A SurfaceMedium given as ``material`` is returned as it is
    when it was made for these options (ParameterError otherwise: its radii and tables would not be theirs)."""
    options = options if options is not None else SurfaceOptions()
    source_model = source_model or options.source_model or "point"
    if isinstance(material, SurfaceMedium):
        made = (material.cutoff_tol, material.source_model, material.rtol, material.far_tol)
        if made != (options.cutoff_tol, source_model, options.rtol, options.far_tol):
            raise ParameterError(f"{material!r} was made for other options than these (cutoff_tol "
                                 f"{options.cutoff_tol:g}, source model {source_model}, rtol {options.rtol:g}, "
                                 f"far_tol {options.far_tol:g})")
        return material
    return SurfaceMedium(material, cutoff_tol=options.cutoff_tol, source_model=source_model, rtol=options.rtol,
                         far_tol=options.far_tol)
