"""The paper's surface transports: a diffusion kernel integrated over geodesic neighbourhoods of the light's entry
samples (the models ``dipole``, ``curved``, ``exact-sphere``, ``fitted`` and ``auto``; kept for comparison and for
what the volume cannot serve).

Modules: :mod:`~meshshade.surface.models` (the kernels' enumeration), :mod:`~meshshade.surface.pair_kernel` (the
kernel of each model for (source, vertex) pairs), :mod:`~meshshade.surface.kernel_evaluation` (its compiled
evaluation), :mod:`~meshshade.surface.patch_average` (a vertex sample stands for its patch),
:mod:`~meshshade.surface.source_factors` (the near-field model as a factor on every kernel),
:mod:`~meshshade.surface.gather` (cutoff radii, the chunked pair iteration and the sum per vertex),
:mod:`~meshshade.surface.zones` (how each sample's pairs are found), :mod:`~meshshade.surface.auto` (which kernel and
geodesics each sample needs), :mod:`~meshshade.surface.sample_groups` (far-zone geodesics shared between samples),
:mod:`~meshshade.surface.farfield` with :mod:`~meshshade.surface.farfield_loops` (the far tail of flat surroundings
by a bounded Taylor expansion), :mod:`~meshshade.surface.direct_sum` (every pair within the cutoff) and
:mod:`~meshshade.surface.hierarchical` with :mod:`~meshshade.surface.hierarchy_loops` (source clusters beyond a near
zone). :func:`meshshade.transport.bake` chooses between them and the volume (:mod:`meshshade.volume`).
"""
from meshshade.surface.auto import AutoPlan
from meshshade.surface.gather import cutoff_radii
from meshshade.surface.hierarchical import SurfaceTransport
from meshshade.surface.pair_kernel import PairKernel, SourceFrames, source_frames

__all__ = ["AutoPlan", "cutoff_radii", "SurfaceTransport", "PairKernel", "SourceFrames", "source_frames"]
