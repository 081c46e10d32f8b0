"""Transport: integrate a diffusion kernel over geodesic neighbourhoods of the light's entry samples.

Modules: :mod:`~meshshade.transport.baking` (``bake``, ``BakeResult``: the stages in order),
:mod:`~meshshade.transport.models` (``MODELS``, the model names), :mod:`~meshshade.transport.pair_kernel` (the
kernel of each model for (source, vertex) pairs), :mod:`~meshshade.transport.gather` (cutoff radii, the chunked
pair iteration and the sum per vertex), :mod:`~meshshade.transport.zones` (how each sample's pairs are found),
:mod:`~meshshade.transport.auto` (which kernel and geodesics each sample needs),
:mod:`~meshshade.transport.sample_groups` (far-zone geodesics shared between samples),
:mod:`~meshshade.transport.farfield` with :mod:`~meshshade.transport.farfield_loops` (the far tail of flat
surroundings by a bounded Taylor expansion). The bake's files are written by
:func:`meshshade.output.bake_file.write_bake` (tone-mapped colours are an output concern).
"""
from meshshade.transport.auto import AutoPlan
from meshshade.transport.baking import BakeResult, bake, describe_result, describe_scale
from meshshade.transport.gather import cutoff_radii
from meshshade.transport.models import MODELS
from meshshade.transport.pair_kernel import PairKernel, SourceFrames, source_frames

__all__ = ["bake", "BakeResult", "MODELS", "describe_result", "describe_scale", "cutoff_radii",
           "PairKernel", "SourceFrames", "source_frames", "AutoPlan"]
