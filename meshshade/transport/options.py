"""The bake's options: one frozen record, checked where it is made (a one-line
:class:`~meshshade.errors.MeshshadeError` naming the option, its value and what is allowed), that the CLI, batches,
the Blender add-on, ``render``, ``compare`` and the benchmark build alike.

:class:`BakeOptions` holds the choice of transport (``model``), the volume's options
(:class:`~meshshade.volume.options.VolumeOptions`: its lattice's resolution and the solve's precision), the surface
models' (:class:`~meshshade.surface.options.SurfaceOptions`: geodesics, cutoff, far field, how vertex samples are
summed, the source model), the ray backend and the progress report. A caller of the default needs none of it:
``bake(mesh, material, lights)``.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

from meshshade.errors import MeshshadeError, ParameterError
from meshshade.names import DEFAULT_MODEL, MODELS
from meshshade.surface.options import KEYWORDS as SURFACE_KEYWORDS
from meshshade.surface.options import SurfaceOptions, options_from_keywords
from meshshade.volume.options import VolumeOptions

__all__ = ["BakeOptions", "BACKENDS", "bake_options_from_keywords"]

#: the ray-casting backends (:func:`meshshade.raycast.make_scene`)
BACKENDS = ("embree", "numpy")


@dataclass(frozen=True)
class BakeOptions:
    """How :func:`meshshade.transport.bake` bakes.

    model : str
        One of :data:`meshshade.names.MODELS`: "volume" (the default: diffusion inside the object's volume), or a
        surface model ("dipole", "curved", "exact-sphere", "fitted", "auto").
    volume : VolumeOptions
        The volume's lattice resolution (``h0`` or ``budget``) and solve tolerance.
    surface : SurfaceOptions
        The surface models' options (geodesics, cutoff, far field, transport, source model); with
        ``model="volume"`` those of its fallback on a mesh that encloses nothing, where only the defaults of the
        source model (the volume's "beam"), the transport and the far field are allowed.
    backend : "embree" (default) or "numpy": the ray casts.
    progress : bool or str
        False (default), True or the task named in the progress lines (``render`` and ``compare`` pass their own).
    """

    model: str = DEFAULT_MODEL
    volume: VolumeOptions = field(default_factory=VolumeOptions)
    surface: SurfaceOptions = field(default_factory=SurfaceOptions)
    backend: str = "embree"
    progress: bool | str = False

    def __post_init__(self):
        if self.model not in MODELS:
            raise MeshshadeError(f"unknown model {self.model!r}; choose one of {', '.join(MODELS)}")
        if not isinstance(self.volume, VolumeOptions):
            raise ParameterError(f"volume options must be VolumeOptions, got {type(self.volume).__name__}")
        if not isinstance(self.surface, SurfaceOptions):
            raise ParameterError(f"surface options must be SurfaceOptions, got {type(self.surface).__name__}")
        if self.backend not in BACKENDS:
            raise MeshshadeError(f"unknown ray backend {self.backend!r}; choose embree or numpy")
        if not isinstance(self.progress, (bool, str)):
            raise ParameterError(f"progress must be True, False or a task name, got {self.progress!r}")
        s = self.surface
        if self.model == "volume":   # options of the surface models that the volume model cannot honour
            if s.source_model is not None and s.source_model != "beam":
                raise ParameterError("the volume model takes the beam source model; source model 'point' applies to "
                                     "the surface models (dipole, curved, exact-sphere, fitted, auto)")
            if s.transport != "auto":
                raise ParameterError(f"transport {s.transport!r} applies to the surface models; the volume model has "
                                     "its own")
            if s.far_field is not None:
                raise ParameterError("the far-field option applies to the surface models; the volume model solves "
                                     "the far field inside the volume")

    @property
    def far_field(self) -> str:
        """The surface models' far-field method with its default for the model resolved."""
        return self.surface.far_field_of(self.model)


#: the former keyword arguments of bake that are fields of BakeOptions itself
_OWN = ("model", "backend", "progress")


def bake_options_from_keywords(options: BakeOptions | None, keywords: dict, where: str = "bake",
                               stacklevel: int = 3) -> BakeOptions:
    """``options`` (default ones for None) with the former keyword arguments ``keywords`` of ``where`` applied
    (``model``, ``backend``, ``progress`` and the surface models' options: :data:`meshshade.surface.options.KEYWORDS`),
    with one DeprecationWarning attributed ``stacklevel`` frames up naming the records to use instead."""
    options = BakeOptions() if options is None else options
    if not isinstance(options, BakeOptions):
        raise ParameterError(f"{where}: options must be BakeOptions or None, got {type(options).__name__}")
    if not keywords:
        return options
    unknown = sorted(set(keywords) - set(_OWN) - set(SURFACE_KEYWORDS))
    if unknown:
        raise TypeError(f"{where}() got an unexpected keyword argument {unknown[0]!r}")
    own = {k: keywords[k] for k in _OWN if k in keywords}
    rest = {k: v for k, v in keywords.items() if k not in own}
    names = ", ".join(f"{k}=" for k in keywords)
    warnings.warn(f"{where}({names}...) is deprecated; pass options=BakeOptions(model=..., surface=SurfaceOptions"
                  "(...), volume=VolumeOptions(...)) (meshshade.transport.options)", DeprecationWarning,
                  stacklevel=stacklevel)
    with warnings.catch_warnings():   # one warning for the call, not a second one from the surface's keywords
        warnings.filterwarnings("ignore", r".*is deprecated; pass options=SurfaceOptions", DeprecationWarning)
        surface = options_from_keywords(options.surface, rest, where)
    return replace(options, surface=surface, **own)
