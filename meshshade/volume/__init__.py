"""The far field as diffusion inside the object's own volume, with the analytic near field on top (docs/physics.md
§15, §15.1): the bake's default model.

The diffusion equation -div(D grad phi) + sigma_a phi = Q with the extrapolated (Robin) boundary, solved with P1
finite elements on a tetrahedral mesh of the object: :mod:`meshshade.volume.fem` (assembly, point loads, exitance,
pure array functions), :mod:`meshshade.volume.tetmesh` (the tetrahedral mesh of a closed surface, keeping its
vertices; graded boxes and balls by construction), :mod:`meshshade.volume.sources` (the entering light's sources
along the refracted rays), :mod:`meshshade.volume.locate` (point location, a compiled neighbour walk),
:mod:`meshshade.volume.operator` (the channels' assembled operators on one sparsity pattern),
:mod:`meshshade.volume.solve` (conjugate gradients over all channels at once), :mod:`meshshade.volume.near_field`
(the near-field model less the Robin half-space's response to the same sources, eq. (98)) and
:mod:`meshshade.volume.transport` (:class:`VolumeTransport`: the stage the bake calls, built once per mesh and
material and reused for every light).
"""
from meshshade.volume.fem import (assemble_channels, assemble_diffusion, boundary_faces, exitance_from_fluence,
                                  locate_points, point_source_vector, tet_geometry)
from meshshade.volume.near_field import NearFieldCorrection
from meshshade.volume.operator import DiffusionOperator
from meshshade.volume.solve import pcg_jacobi
from meshshade.volume.sources import line_source_rule, line_sources
from meshshade.volume.tetmesh import SurfaceTetrahedra, graded_box, surface_tetrahedra
from meshshade.volume.transport import VolumeTransport

__all__ = ["assemble_channels", "assemble_diffusion", "boundary_faces", "exitance_from_fluence", "locate_points",
           "point_source_vector", "tet_geometry", "NearFieldCorrection", "DiffusionOperator", "pcg_jacobi",
           "line_source_rule", "line_sources", "SurfaceTetrahedra", "graded_box", "surface_tetrahedra",
           "VolumeTransport"]
