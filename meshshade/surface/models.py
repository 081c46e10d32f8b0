"""The bake's kernel models; their names (the CLI's choices, the benchmark's models) are in :mod:`meshshade.names`.

* ``dipole``: Jensen's planar dipole of the chord distance;
* ``curved``: the first-order k1/k2 kernel (kernels/curvature.py);
* ``exact-sphere``: the exact sphere series with the local radius 2/(k1 + k2);
* ``fitted``: the curvature model fitted to Monte Carlo beyond first order (kernels/fitted_curvature.py);
* ``auto``: per entry sample the cheapest of the three that the scene calls for (surface/auto.py);
* ``volume`` (the default): diffusion inside the object's volume with the analytic near field on top
  (meshshade/volume, docs/physics.md §15); open, many-part and coarse meshes included; on a mesh that encloses no
  volume (a flat sheet) the bake says so and uses ``auto`` with the beam near field.
"""
from __future__ import annotations

from enum import IntEnum

from meshshade.names import DEFAULT_MODEL, KERNEL_NAMES, MODELS  # noqa: F401 (the one list; no numpy there)


class Kernel(IntEnum):
    """The kernel a source's pairs take: the one enumeration of kernels, used by the auto plans
    (``AutoPlan.kernel``, the NPZ's ``auto_kernel``), the hierarchical transport's sources and the compiled
    evaluation (:func:`meshshade.surface.kernel_evaluation.kernel_value`)."""

    #: the planar dipole of the surface distance (what ``auto`` calls "dipole")
    DIPOLE_SURFACE = 0
    #: the first-order k1/k2 kernel with its soft positivity policy
    CURVED = 1
    #: the exact sphere series of the source's local radius 2/(k1 + k2) (the chord dipole where it is not convex)
    EXACT_SPHERE = 2
    #: the fitted curvature model on the dipole
    FITTED = 3
    #: the planar dipole of the chord distance: the model "dipole"
    DIPOLE_CHORD = 4


#: the kernel of every source of a single-kernel model (``auto`` plans one per source; ``volume`` has none)
MODEL_KERNEL = {"dipole": Kernel.DIPOLE_CHORD, "curved": Kernel.CURVED, "exact-sphere": Kernel.EXACT_SPHERE,
                "fitted": Kernel.FITTED}
