"""Diffusion inside the object's own volume, with the analytic near field on top (docs/physics.md §15): the bake's
default model.

The pipeline, one module per stage: :mod:`meshshade.volume.surface` (the surface it samples: the mesh, its long
edges split), :mod:`meshshade.volume.inside` (what is inside: the generalised winding number, so open, overlapping
and defective meshes have an inside), :mod:`meshshade.volume.resolution` (how fine, from the material and a cell
budget), :mod:`meshshade.volume.lattice` (a graded octree of cubes anchored in world coordinates, finer at edges
of light), :mod:`meshshade.volume.cutfem` (P1 finite elements on the cubes cut by the surface),
:mod:`meshshade.volume.multigrid` (the channels' operators and their multigrid conjugate gradients),
:mod:`meshshade.volume.long_range` (the light's sources along the refracted rays, the share the lattice carries),
:mod:`meshshade.volume.options` (:class:`VolumeOptions`: the lattice's resolution and the solve's precision),
:mod:`meshshade.volume.remainder` (the near field less that share, summed in the local half-space) and
:mod:`meshshade.volume.transport` (:class:`VolumeTransport`: the stage the bake calls).
"""
from meshshade.volume.cutfem import Assembly, assemble, cut_tetrahedron
from meshshade.volume.inside import SurfaceVolume
from meshshade.volume.lattice import Grading, Lattice, build_lattice, coarser_lattice
from meshshade.volume.long_range import ewald_weight, lattice_loads, line_rule
from meshshade.volume.multigrid import ChannelOperator, Multigrid, solve_channels
from meshshade.volume.options import VolumeOptions
from meshshade.volume.remainder import RemainderTables, remainder_exitance
from meshshade.volume.resolution import VolumeResolution, volume_resolution
from meshshade.volume.surface import SamplingSurface, split_long_edges
from meshshade.volume.transport import VolumeTransport

__all__ = ["Assembly", "assemble", "cut_tetrahedron", "SurfaceVolume", "Grading", "Lattice", "build_lattice",
           "coarser_lattice", "ewald_weight", "lattice_loads", "line_rule", "ChannelOperator", "Multigrid",
           "solve_channels", "VolumeOptions", "RemainderTables", "remainder_exitance", "VolumeResolution", "volume_resolution",
           "SamplingSurface", "split_long_edges", "VolumeTransport"]
