"""The far field as diffusion inside the object's own volume (docs/physics.md §15).

The diffusion equation -div(D grad phi) + sigma_a phi = Q with the extrapolated (Robin) boundary, solved with P1
finite elements on a tetrahedral mesh of the object: :mod:`meshshade.volume.fem` (assembly, sources, exitance,
pure array functions), :mod:`meshshade.volume.tetmesh` (tetrahedral meshes built by construction: graded boxes)
and :mod:`meshshade.volume.operator` (the assembled operator of one material channel, solved for any number of
source sets).
"""
from meshshade.volume.fem import (assemble_diffusion, boundary_faces, exitance_from_fluence, locate_points,
                                  point_source_vector, tet_geometry)
from meshshade.volume.operator import DiffusionOperator
from meshshade.volume.tetmesh import graded_box

__all__ = ["assemble_diffusion", "boundary_faces", "exitance_from_fluence", "locate_points", "point_source_vector",
           "tet_geometry", "DiffusionOperator", "graded_box"]
