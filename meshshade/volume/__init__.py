"""The far field as diffusion inside the object's own volume (docs/physics.md §15).

The diffusion equation -div(D grad phi) + sigma_a phi = Q with the extrapolated (Robin) boundary, solved with P1
finite elements on a tetrahedral mesh of the object: :mod:`meshshade.volume.fem` (assembly, point loads, exitance,
pure array functions), :mod:`meshshade.volume.tetmesh` (the tetrahedral mesh of a closed surface, keeping its
vertices; graded boxes and balls by construction), :mod:`meshshade.volume.sources` (the entering light's sources
along the refracted rays), :mod:`meshshade.volume.locate` (point location, a compiled neighbour walk) and
:mod:`meshshade.volume.operator` (the assembled operator of one material channel, solved for any number of
source sets). Not yet called by the bake (docs/physics.md §15 says what remains).
"""
from meshshade.volume.fem import (assemble_diffusion, boundary_faces, exitance_from_fluence, locate_points,
                                  point_source_vector, tet_geometry)
from meshshade.volume.operator import DiffusionOperator
from meshshade.volume.sources import line_sources
from meshshade.volume.tetmesh import SurfaceTetrahedra, graded_box, surface_tetrahedra

__all__ = ["assemble_diffusion", "boundary_faces", "exitance_from_fluence", "locate_points", "point_source_vector",
           "tet_geometry", "DiffusionOperator", "line_sources", "SurfaceTetrahedra",
           "graded_box", "surface_tetrahedra"]
