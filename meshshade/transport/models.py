"""The bake's kernel models: the one list of their names (the CLI's choices, the benchmark's models).

* ``dipole``: Jensen's planar dipole of the chord distance;
* ``curved``: the first-order k1/k2 kernel (kernels/curvature.py);
* ``exact-sphere``: the exact sphere series with the local radius 2/(k1 + k2);
* ``fitted``: the curvature model fitted to Monte Carlo beyond first order (kernels/fitted_curvature.py);
* ``auto``: per entry sample the cheapest of the three that the scene calls for (transport/auto.py);
* ``volume`` (the default): diffusion inside the object's volume with the analytic near field on top
  (meshshade/volume, docs/physics.md §15); on a mesh that encloses no volume (open, or not tetrahedralisable)
  the bake says so and uses ``auto`` with the beam near field.
"""
from __future__ import annotations

#: the kernels ``auto`` chooses between per entry sample, in the order of its plan codes (``AutoPlan.kernel``,
#: the NPZ's ``auto_kernel``: 0 dipole, 1 curved, 2 exact-sphere, 3 fitted)
KERNEL_NAMES = ("dipole", "curved", "exact-sphere", "fitted")
#: every model :func:`meshshade.transport.baking.bake` accepts
MODELS = KERNEL_NAMES + ("auto", "volume")
#: the default model of the bake, the CLI, batches, the Blender add-on and compare's first model
DEFAULT_MODEL = "volume"
