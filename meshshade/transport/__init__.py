"""Transport: the one place that chooses how light travels inside the object, the volume (:mod:`meshshade.volume`,
the default) or a surface model (:mod:`meshshade.surface`), and the record every choice answers with.

Modules: :mod:`~meshshade.transport.baking` (:func:`bake`: the choice and its run),
:mod:`~meshshade.transport.options` (:class:`BakeOptions`: the model, the volume's and the surface models' options
records) and :mod:`~meshshade.transport.result` (:class:`BakeResult` and the one-line descriptions). The bake's
files are written by :func:`meshshade.output.bake_file.write_bake`.
"""
from meshshade.names import MODELS
from meshshade.surface.options import AutoTolerances, SurfaceOptions
from meshshade.transport.baking import bake
from meshshade.transport.options import BakeOptions
from meshshade.transport.result import BakeResult, describe_result, describe_scale, mesh_note
from meshshade.volume.options import VolumeOptions

__all__ = ["bake", "BakeOptions", "VolumeOptions", "SurfaceOptions", "AutoTolerances", "BakeResult", "MODELS",
           "describe_result", "describe_scale", "mesh_note"]
