"""Light: sources (beam, directional, point), their text specs, entry samples with Fresnel entry, shadows.

Modules: :mod:`~meshshade.light.sources` (the light classes and their validation), :mod:`~meshshade.light.spec`
(``--light`` text specs), :mod:`~meshshade.light.samples` (entry points and transmitted power),
:mod:`~meshshade.light.shadows` (shadow rays and their culling).
"""
from meshshade.light.samples import EntrySamples, entry_samples
from meshshade.light.sources import BeamLight, DirectionalLight, Light, PointLight
from meshshade.light.spec import parse_light_spec

__all__ = ["BeamLight", "DirectionalLight", "PointLight", "Light", "parse_light_spec", "EntrySamples",
           "entry_samples"]
