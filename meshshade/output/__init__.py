"""Outputs: per-pixel rendering of baked radiance, tone mapping, model comparison, profile reports, the bake's files.

Modules: :mod:`~meshshade.output.render` (camera, primary rays, exit radiance, per-pixel gather),
:mod:`~meshshade.output.tonemap` (Drago 2003, exposure, sRGB), :mod:`~meshshade.output.compare` (two models'
statistics, split image, heat map), :mod:`~meshshade.output.report` (profile tables, CSV text, plots),
:mod:`~meshshade.output.bake_file` (the bake's PLY and NPZ). Nothing is re-exported here: import the modules.
"""
