"""Transport: integrate a diffusion kernel over geodesic neighbourhoods of the light's entry samples.

Modules: :mod:`~meshshade.transport.baking` (``bake``, ``BakeResult``: the stages in order),
:mod:`~meshshade.surface.models` (``MODELS``, the model names), :mod:`~meshshade.surface.pair_kernel` (the
kernel of each model for (source, vertex) pairs), :mod:`~meshshade.surface.gather` (cutoff radii, the chunked
pair iteration and the sum per vertex), :mod:`~meshshade.surface.zones` (how each sample's pairs are found),
:mod:`~meshshade.surface.auto` (which kernel and geodesics each sample needs),
:mod:`~meshshade.surface.sample_groups` (far-zone geodesics shared between samples),
:mod:`~meshshade.surface.farfield` with :mod:`~meshshade.surface.farfield_loops` (the far tail of flat
surroundings by a bounded Taylor expansion). The bake's files are written by
:func:`meshshade.output.bake_file.write_bake` (tone-mapped colours are an output concern).
"""
from meshshade.surface.auto import AutoPlan
from meshshade.transport.baking import BakeResult, bake, describe_result, describe_scale
from meshshade.surface.gather import cutoff_radii
from meshshade.surface.models import MODELS
from meshshade.surface.pair_kernel import PairKernel, SourceFrames, source_frames

__all__ = ["bake", "BakeResult", "MODELS", "describe_result", "describe_scale", "cutoff_radii",
           "PairKernel", "SourceFrames", "source_frames", "AutoPlan"]
