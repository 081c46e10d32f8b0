"""Light: sources (beam, directional, point, environment, area), their text specs, entry samples with Fresnel entry,
shadows.

Modules: :mod:`~meshshade.light.sources` (the light classes and their validation), :mod:`~meshshade.light.spec`
(``--light`` text specs), :mod:`~meshshade.light.samples` (entry points and transmitted power),
:mod:`~meshshade.light.shadows` (shadow rays and their culling), :mod:`~meshshade.light.environment` (equirectangular
maps: directions and importance sampling), :mod:`~meshshade.light.area` (rectangle and disc emitters),
:mod:`~meshshade.light.incidence` (what an environment or area light delivers at each vertex).
"""
from meshshade.light.samples import EntrySamples, entry_samples
from meshshade.light.sources import AreaLight, BeamLight, DirectionalLight, EnvironmentLight, Light, PointLight
from meshshade.light.spec import parse_light_spec

__all__ = ["BeamLight", "DirectionalLight", "PointLight", "EnvironmentLight", "AreaLight", "Light", "parse_light_spec",
           "EntrySamples", "entry_samples"]
