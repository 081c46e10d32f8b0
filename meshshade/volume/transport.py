"""The volume transport: diffusion inside the object's own volume plus the analytic near field (§15, §15.1).

:class:`VolumeTransport` is a stage of its own, built once per mesh and material and reused for every light: the
tetrahedral mesh of the surface (its vertices kept as nodes), the assembled operator of each channel with its
solver, the point-location structures and the near-field correction's tables. :meth:`exitance` takes
the bake's entry samples (where light enters, with shadows and Fresnel already applied) and returns the exitance at
the mesh's vertices:

    M = phi / (2A)  [the volume's solution for the near-field model's diffusion sources along the refracted rays]
        + sum over pairs of Delta R  [the near field minus the Robin half-space's response to the same sources]

(docs/physics.md eqs. (89)-(98)). The diffusion theory is d'Eon's (D = (2 - alpha') / (3 sigma_t'), A of eq.
(74)), the near-field model's own, so that on a flat surface the two parts add up to the near-field model.
Sources past where the refracted ray leaves the body are dropped: that light leaves unscattered.
"""
from __future__ import annotations

import hashlib
import math
import time

import igl
import numpy as np
from scipy.spatial import cKDTree

from meshshade.errors import MeshshadeError
from meshshade.kernels.beam_diffusion import dipole_variant
from meshshade.kernels.fresnel import refract_in
from meshshade.progress import kernel_interrupts
from meshshade.volume.fem import boundary_faces, locate_points, point_source_vector
from meshshade.volume.locate import tet_neighbours
from meshshade.volume.near_field import NearFieldCorrection
from meshshade.volume.operator import DiffusionOperator
from meshshade.volume.sources import line_sources
from meshshade.volume.tetmesh import SurfaceTetrahedra, surface_tetrahedra

__all__ = ["VolumeTransport", "diffusion_constants", "tetra_key"]

#: the tetrahedral mesher's settings as they enter the cache key (bump when surface_tetrahedra changes its output)
MESHER_VERSION = "surface_tetrahedra/2"


#: the grading from the material: layers every NORMAL_SPACING x the shortest material length (1/sigma_t' or
#: 1/sigma_tr of any channel) below the surface, down to LAYERED_DEPTH x that length, in columns no closer than
#: COLUMN_SPACING x the layers' spacing (a finer surface keeps all its vertices but not a column under each);
#: inside, lattices no coarser than INTERIOR_SPACING x the longest diffusion length (1/sigma_tr of the channel that
#: reaches farthest) within INTERIOR_REACH x that length of the surface (light that crosses the body travels
#: there), coarser beyond
NORMAL_SPACING, LAYERED_DEPTH, INTERIOR_SPACING, INTERIOR_REACH, COLUMN_SPACING = 0.45, 2.0, 0.5, 2.0, 1.5


def grading(material) -> tuple[float, float, float, float, float]:
    """(normal spacing, layered depth, interior spacing, interior reach, column spacing), mm, of the tetrahedral
    mesh for ``material`` (:data:`NORMAL_SPACING`)."""
    short = float(min(np.min(1.0 / np.asarray(material.sigma_t_prime)), np.min(1.0 / np.asarray(material.sigma_tr))))
    long = float(np.max(1.0 / np.asarray(material.sigma_tr)))
    normal = NORMAL_SPACING * short
    return normal, LAYERED_DEPTH * short, INTERIOR_SPACING * long, INTERIOR_REACH * long, COLUMN_SPACING * normal


def tetra_key(mesh, spacing) -> str:
    """Hex digest naming the tetrahedral mesh of ``mesh`` in an asset cache: its vertices (mm) and faces, the
    grading ``spacing`` (:func:`grading`) and the mesher's version."""
    h = hashlib.sha256(f"{MESHER_VERSION} {' '.join(repr(float(x)) for x in spacing)}".encode())
    for a in (np.ascontiguousarray(mesh.vertices, dtype=np.float64), np.ascontiguousarray(mesh.faces, dtype=np.int64)):
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:32]


def diffusion_constants(material, c: int) -> tuple[float, float, float]:
    """(D mm, sigma_a 1/mm, A) of channel ``c`` in d'Eon's diffusion theory (eq. (74)), the volume's."""
    s = float(material.sigma_t_prime[c])
    v = dipole_variant(float(material.albedo_prime[c]), float(material.eta), "better")
    return v.D / s, float(material.sigma_a[c]), v.z_b / (2.0 * v.D)


class VolumeTransport:
    """The volume transport of one mesh and material (module docstring). Build with :meth:`build`."""

    def __init__(self, mesh, material, tetra, operator, correction, timings, neighbours=None):
        self.mesh, self.material, self.tetra = mesh, material, tetra
        self.operator = operator
        self.correction = correction
        self.timings = timings
        #: the mesh's vertices that faces use: the tetrahedral mesh's first nodes, in this order (a vertex no face
        #: uses bounds no volume and gets no exitance, as in the surface models)
        self.surface_vertices = np.unique(mesh.faces)
        if self.surface_vertices.size != tetra.n_surface:
            raise MeshshadeError("the tetrahedral mesh was built for another surface")
        self._tree = cKDTree(tetra.nodes[tetra.tets].mean(axis=1))
        self._neighbours = tet_neighbours(tetra.tets) if neighbours is None else neighbours
        # surface vertices of no tetrahedron (a spike's tip, at most MAX_ORPHANS of them): read by interpolation
        # in the tetrahedron that holds them, or the nearest one
        in_tet = np.zeros(tetra.n_surface, dtype=bool)
        in_tet[tetra.tets[tetra.tets < tetra.n_surface]] = True
        self._orphans = np.flatnonzero(~in_tet)
        self._orphan_at = locate_points(tetra.nodes, tetra.tets, tetra.nodes[self._orphans], tree=self._tree,
                                        neighbours=self._neighbours)
        self.stats = {"volume_nodes": int(tetra.nodes.shape[0]), "volume_tetrahedra": int(tetra.tets.shape[0]),
                      "volume_faces_recovered": round(float(tetra.faces_recovered), 5),
                      "volume_vertices_interpolated": int(self._orphans.size),
                      "near_field_radius_mm": [round(float(r), 4) for r in correction.radius_mm]}

    @classmethod
    def build(cls, mesh, material, *, tetra=None, cache=None):
        """Tetrahedralise ``mesh`` (or take ``tetra``, a :class:`~meshshade.volume.tetmesh.SurfaceTetrahedra` of
        it) and assemble one operator per distinct channel. ``cache``: an object with ``read(key)`` and
        ``write(key, **arrays)`` (:class:`meshshade.asset_cache.AssetCache`) where the tetrahedral mesh is looked up and
        stored under :func:`tetra_key`; ``stats["volume_tetrahedra_cached"]`` says whether it was found there."""
        timings = {}
        t0 = time.perf_counter()
        cached = False
        spacing = grading(material)
        key = tetra_key(mesh, spacing) if cache is not None else None
        used = np.unique(mesh.faces)
        if tetra is None and cache is not None:
            got = cache.read(key)
            if got is not None and {"nodes", "tets", "n_surface", "surface_spacing", "faces_recovered"} <= set(got):
                tetra = SurfaceTetrahedra(got["nodes"], got["tets"], int(got["n_surface"]),
                                          float(got["surface_spacing"]), float(got["faces_recovered"]))
                cached = tetra.n_surface == used.size
                tetra = tetra if cached else None
        if tetra is None:
            faces = np.searchsorted(used, mesh.faces)
            tetra = surface_tetrahedra(mesh.vertices[used], faces, normal_spacing=spacing[0],
                                       layered_depth=spacing[1], interior_spacing=spacing[2],
                                       interior_reach=spacing[3], column_spacing=spacing[4])
            if cache is not None:
                cache.write(key, nodes=tetra.nodes, tets=tetra.tets, n_surface=tetra.n_surface,
                            surface_spacing=tetra.surface_spacing, faces_recovered=tetra.faces_recovered)
        timings["tetrahedra"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        D, sa, A = zip(*(diffusion_constants(material, c) for c in range(3)))
        neighbours = tet_neighbours(tetra.tets)
        operator = DiffusionOperator(tetra.nodes, tetra.tets, D=D, sigma_a=sa, A=A, lumped=True,
                                     faces=boundary_faces(tetra.tets, tetra.nodes, neighbours))
        timings["volume operator"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        correction = NearFieldCorrection(material)
        timings["near-field tables"] = time.perf_counter() - t0
        out = cls(mesh, material, tetra, operator, correction, timings, neighbours=neighbours)
        out.stats["volume_tetrahedra_cached"] = cached
        return out

    def exitance(self, samples):
        """(M (n, 3) W/mm^2 at the mesh's vertices, stats with ``timings``) for the bake's ``samples``."""
        mesh, mat, tm = self.mesh, self.material, self.tetra
        timings, stats = {}, {}
        n = mesh.n_vertices
        M = np.zeros((n, 3))
        if len(samples) == 0:
            return M, {"timings": timings}
        t0 = time.perf_counter()
        w = refract_in(samples.directions, samples.normals, float(mat.eta))
        cos_t = np.clip(-np.einsum("ij,ij->i", w, samples.normals), 0.0, 1.0)
        loads = np.zeros((tm.nodes.shape[0], 3))
        dropped = np.zeros(3)
        for c in range(3):
            pts, pw = line_sources(samples.positions, w, samples.power, sigma_t_prime=float(mat.sigma_t_prime[c]),
                                   albedo_prime=float(mat.albedo_prime[c]))
            keep = pw > 0
            inside = np.zeros(pts.shape[0], dtype=bool)
            inside[keep] = igl.fast_winding_number(mesh.vertices, mesh.faces, pts[keep]) > 0.5
            dropped[c] = float(pw[~inside].sum() / max(pw.sum(), 1e-300))
            tet, bary = locate_points(tm.nodes, tm.tets, pts[inside], tree=self._tree, neighbours=self._neighbours)
            loads[:, c] = point_source_vector(tm.nodes.shape[0], tm.tets, tet, bary, pw[inside])
        timings["volume sources"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        op = self.operator
        with kernel_interrupts():   # a Ctrl-C inside the compiled parallel loops is a KeyboardInterrupt
            phi = op.solve(loads)
        tet, bary = self._orphan_at
        phi[self._orphans] = np.einsum("ij,ijc->ic", bary, phi[tm.tets[tet]])
        M[self.surface_vertices] = phi[:tm.n_surface] / (2.0 * op.A[None, :])
        timings["volume solve"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        point = samples.vertex < 0
        src_radius = np.where(point, 0.0, np.sqrt(mesh.vertex_areas[np.maximum(samples.vertex, 0)] / math.pi))
        with kernel_interrupts():
            dM, pairs = self.correction.exitance(samples.positions, samples.normals, samples.power, cos_t,
                                                 src_radius, mesh.vertices, mesh.vertex_normals,
                                                 np.sqrt(mesh.vertex_areas / math.pi))
        M += dM
        timings["near field"] = time.perf_counter() - t0
        if not np.all(np.isfinite(M)):
            raise MeshshadeError("the volume transport produced a non-finite exitance")
        # P1 elements can undershoot where the fluence falls by orders of magnitude within an element (the blue
        # past a sun's terminator); exitance is >= 0, so such values are set to 0 and counted, with the deepest
        # undershoot relative to the channel's peak
        peak = np.maximum(M.max(axis=0), 1e-300)
        neg = M < 0
        stats["volume_negative_clamped"] = neg.sum(axis=0).tolist()
        stats["volume_negative_worst"] = [float(max(0.0, -M[:, c].min()) / peak[c]) for c in range(3)]
        M[neg] = 0.0
        stats.update({"volume_dropped_source_power": [round(float(x), 5) for x in dropped],
                      "near_field_pairs": pairs, "volume_solve_iterations": op.iterations.tolist(),
                      "timings": timings})
        return M, stats
