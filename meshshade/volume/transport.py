"""The volume transport: diffusion inside the object's volume on a graded lattice, plus the near field (docs/physics.md
§15): the bake's default model.

:class:`VolumeTransport` is built once per mesh and material and reused for every light:

1. the surface it samples (:mod:`meshshade.volume.surface`: the mesh, or the mesh refined on its facets where
   it is coarser than the lattice);
2. the inside (:mod:`meshshade.volume.inside`: the winding number, so open and overlapping meshes have one);
3. the lattice (:mod:`meshshade.volume.lattice`) at the material's resolution (:mod:`meshshade.volume.resolution`);
4. the cut-cell matrices (:mod:`meshshade.volume.cutfem`) and the channels' multigrid solver
   (:mod:`meshshade.volume.multigrid`);
5. the correction's tables (:mod:`meshshade.volume.remainder`).

:meth:`VolumeTransport.exitance` takes the entry samples of the lights on the sampling surface and returns the
exitance at the mesh's vertices:

    M = phi / (2A)                       [the lattice's solution for the smoothed line sources, eqs. (99)-(100)]
        + M_f                            [the near field less what the lattice carries, eqs. (102)-(103)]

at the sampling surface's vertices, P1 between them; a vertex of the mesh takes it at its own point (as texels and
pixels do, :mod:`meshshade.volume.surface`). Each stage is timed.
"""
from __future__ import annotations

import math
import time

import numpy as np
from scipy.spatial import cKDTree

from meshshade import memo
from meshshade.errors import MeshshadeError
from meshshade.kernels.fresnel import refract_in
from meshshade.progress import kernel_interrupts
from meshshade.raycast import make_scene
from meshshade.volume.cutfem import assemble
from meshshade.volume.inside import SurfaceVolume
from meshshade.volume.lattice import build_lattice
from meshshade.volume.long_range import ewald_weight, lattice_loads, line_rule
from meshshade.volume.media import NEAR_FIELD_NODES, varying_medium
from meshshade.volume.multigrid import ChannelOperator, Multigrid, solve_channels
from meshshade.volume.remainder import RemainderTables, longest_edges, remainder_exitance
from meshshade.volume.options import VolumeOptions
from meshshade.volume.resolution import THIN_PROBE_OVER_H0, volume_resolution
from meshshade.volume.surface import SamplingSurface
from meshshade.volume.thickness import surface_thickness
from meshshade.volume.uncollided import DEPTH_POINTS, FLOOR, PREFILTER_MARGIN, face_entries, uncollided_exitance

__all__ = ["VolumeTransport", "thin_parts", "SAMPLE_SPACING_OVER_H0", "NEAR_FIELD_NODES"]

#: the sampling surface's longest edge, in units of the lattice's spacing h0: the entries' sources are spread
#: sideways by h0 / 2 (eq. (100)), and entries up to 2 h0 apart (4 spreads) left a ripple at the entries, where the
#: surface is read; at h0 (2 spreads) the accuracy sweep's lit ratio of the means is 0.71 against 0.80 at 2 h0, at
#: 1.4 times its bakes' time (a mesh finer than h0 is not split and costs nothing more; docs/benchmarks.md)
SAMPLE_SPACING_OVER_H0 = 1.0
#: a surface point farther than this many lattice spacings outside the lattice's own surface is read on it
OUTSIDE_READ = 0.1
#: a vertex is buried when the winding number this far outside it (mm; at most a tenth of the mean edge) is > 1/2
BURIED_OFFSET_MM = 0.05


def _lap(timings, name, t, on_stage):
    timings[name] = time.perf_counter() - t
    if on_stage is not None:
        on_stage(name)


def thin_parts(samples, resolution, scene):
    """(thickness (n_s,) mm, thin (n_s,) bool, the thin share of the area) of the sampling surface ``samples`` (a
    :class:`~meshshade.geometry.mesh.Mesh`) with its ray ``scene``: its shape diameter cast from one vertex per cube
    of THIN_PROBE_OVER_H0 h0 (:func:`~meshshade.volume.thickness.surface_thickness`), thin below the
    ``resolution``'s ``thin_below`` (physics §15.2, eq. (135)). What the bake refines and ``meshshade check``
    reports."""
    thickness = surface_thickness(scene, samples.vertices, samples.vertex_normals,
                                  THIN_PROBE_OVER_H0 * resolution.h0)
    thin = thickness < resolution.thin_below
    area = samples.vertex_areas
    return thickness, thin, float(area[thin].sum() / max(float(area.sum()), 1e-300))


class VolumeTransport:
    """The volume transport of one mesh and material (module docstring). Build with :meth:`build`; the lattice
    itself is made for the first light set it is given (finer at that light's edges) and remade only for a light
    set with edges elsewhere."""

    def __init__(self, mesh, material, resolution, surface, inside, tables, timings, medium=None):
        self.mesh, self.material, self.resolution = mesh, material, resolution
        self.surface, self.inside, self.tables = surface, inside, tables
        self.timings = timings
        # a medium varying over the object (painted, parts: :mod:`meshshade.volume.media`), or None: one medium
        # (attached to ``surface``: :meth:`build`)
        self.medium = medium
        varying = medium is not None
        m = medium.boundary.medium if varying else material.medium   # d'Eon's D [mm], A, sigma_a (eq. (74))
        self.A = np.array(m.A, dtype=np.float64)
        if varying and not getattr(self.medium, "single", False):
            # D and sigma_a per cube inside the matrices (eq. (107)); the boundary's 1/(2A) here (one index)
            self.coef = np.stack([np.ones(3), 1.0 / (2.0 * m.A), np.ones(3)], axis=1)
        else:
            self.coef = np.stack([m.D, 1.0 / (2.0 * m.A), m.sigma_a], axis=1)
        self._lattice_key = None
        self._spacing = None          # each sampling vertex's longest edge (eq. (103)'s subtracted radius)
        self.on_stage = None          # called with each stage's name as it ends (progress), or None
        self.options = VolumeOptions()   # the resolution's and the solve's (build sets the ones it was given)
        self.lattice = self.assembly = self.operator = self.multigrid = None
        self.buried = self._buried_vertices()
        self.scene = None             # the sampling surface's ray scene (:meth:`build` makes it for the thickness)
        self.thin = np.zeros(surface.samples.n_vertices, dtype=bool)   # sampling vertices in thin parts
        self.stats = {
            "volume_resolution_mm": round(resolution.h0, 5), "volume_resolution_limited_by": resolution.limited_by,
            "volume_resolution_reason": resolution.reason,
            "volume_spread_mm": round(resolution.spread, 5),
            "volume_samples": int(surface.samples.n_vertices), "volume_samples_split": bool(surface.split),
            "volume_lattice_fraction": [round(float(x), 4) for x in self.tables.long_fraction],
            "near_field_radius_mm": [round(float(r), 4) for r in self.tables.radius_mm],
            "volume_parts": int(mesh.defects.n_components), "volume_closed": bool(mesh.defects.is_closed),
            "volume_buried_vertices": int(self.buried.sum()),
        }

    @classmethod
    def build(cls, mesh, material, options: VolumeOptions | None = None, *, sample_spacing: float | None = None,
              on_stage=None):
        """Sample ``mesh``, find its inside and tabulate the correction (module docstring); ``options``
        (:class:`~meshshade.volume.options.VolumeOptions`, default ones for None): the lattice's surface spacing or
        its budget of surface cubes (:mod:`meshshade.volume.resolution`) and the solve's tolerance;
        ``on_stage(name)`` is called as each stage ends (progress)."""
        options = VolumeOptions() if options is None else options
        timings = {}
        t = time.perf_counter()
        medium = varying_medium(material)
        # a varying medium: the lattice resolves its fastest-decaying media (and reaches as deep as its slowest)
        res_material = medium.resolution_material() if medium is not None else material
        res = volume_resolution(res_material, float(mesh.total_area), mesh.bbox_size_mm, h0=options.h0,
                                budget=options.budget)
        if medium is not None:               # each medium's own resolution: where its edges need refining
            medium.note_resolution(res, lambda m: volume_resolution(m, float(mesh.total_area), mesh.bbox_size_mm,
                                                                    h0=options.h0, budget=options.budget))
        surface = SamplingSurface(mesh, SAMPLE_SPACING_OVER_H0 * res.h0 if sample_spacing is None else sample_spacing)
        inside = SurfaceVolume(mesh.vertices, mesh.nondegenerate_faces, surface.samples.vertices,
                               surface.spacing)
        S = surface.samples
        scene = memo.cached("scene", (id(S), "embree"), lambda: make_scene(S.vertices, S.faces), pins=(S,))
        thin = thin_parts(S, res, scene)
        _lap(timings, "volume sampling", t, on_stage)
        t = time.perf_counter()
        # a varying medium: read on the sampling surface, its near field tabulated per medium node
        tables = RemainderTables(material, res.spread) if medium is None else medium.attach(mesh, surface, res.spread)
        _lap(timings, "near-field tables", t, on_stage)
        vt = cls(mesh, material, res, surface, inside, tables, timings, medium)
        vt._note_thin(*thin, scene)
        vt.on_stage = on_stage
        vt.options = options
        return vt

    def _note_thin(self, thickness, thin, fraction, scene):
        """The sampling surface's :func:`thin_parts`: they are resolved at h0 / 2 (:meth:`_refinement`)."""
        self.scene, self.thin = scene, thin
        finite = np.isfinite(thickness)
        self.stats.update({
            "volume_thin_below_mm": round(float(self.resolution.thin_below), 4),
            "volume_thin_fraction": round(fraction, 4),
            "volume_thinnest_mm": round(float(np.min(thickness[finite])), 4) if finite.any() else None})
        self._lattice_key = None

    def _buried_vertices(self):
        """(n,) bool: the mesh's vertices buried in another of its parts (only a mesh of several parts has them),
        whose exitance is reported as 0 (docs/limitations.md)."""
        mesh = self.mesh
        if mesh.defects.n_components < 2:
            return np.zeros(mesh.n_vertices, dtype=bool)
        offset = min(BURIED_OFFSET_MM, 0.1 * float(mesh.mean_edge_length))
        return self.inside.buried(mesh.vertices, mesh.vertex_normals, offset)

    def to_vertices(self, sample_values):
        """(n, 3) values at the sampling surface's vertices read at the mesh's vertices (the same points), 0 at
        buried vertices."""
        out = np.array(self.surface.to_vertices(sample_values), dtype=np.float64)
        out[self.buried] = 0.0
        return out

    def edges_of_light(self, samples):
        """(m, 3) points of the sampling surface where the light changes sharply (an edge of the sampling mesh
        whose irradiance falls below a quarter from one end to the other) and the beams' entries."""
        surf = self.surface.samples
        at_v = samples.vertex >= 0
        E = np.bincount(samples.vertex[at_v], weights=samples.power[at_v], minlength=surf.n_vertices)
        E = np.where(surf.vertex_areas > 0, E / np.where(surf.vertex_areas > 0, surf.vertex_areas, 1.0), 0.0)
        F = surf.faces
        e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        hi = np.maximum(E[e[:, 0]], E[e[:, 1]])
        lo = np.minimum(E[e[:, 0]], E[e[:, 1]])
        sharp = (hi > 0) & (lo < 0.25 * hi)
        pts = np.unique(e[sharp].ravel())
        return np.concatenate([surf.vertices[pts], samples.positions[~at_v]])

    def _refinement(self, pts):
        """The lattice's ``refine`` (cube centres (p, 3) -> bool (p,): level 0, h0 / 2, there): within the reach of
        the edges of light ``pts`` (the resolution's ``refine_radius``, or each edge's medium's) and in the thin
        parts (:func:`thin_parts`: within half the thin parts' threshold of their sampling vertices, so across
        them); level 1 elsewhere. (Until stop 58 a light with no edge left the whole surface at level 0.)"""
        h1 = 2.0 * self.resolution.grading.h0
        r1 = 0.5 * math.sqrt(3.0) * h1
        reaches = self.medium.edge_reach(pts) if self.medium is not None and len(pts) else None
        if not len(pts):
            groups = []
        elif reaches is None:
            reach = self.resolution.refine_radius
            groups = [(cKDTree(pts), reach)] if reach > 0 else []
        else:                                     # a varying medium: each edge its own medium's reach
            groups = [(cKDTree(pts[reaches == r]), float(r)) for r in np.unique(reaches) if r > 0]
        if self.thin.any():
            groups.append((cKDTree(self.surface.samples.vertices[self.thin]), 0.5 * self.resolution.thin_below))

        def refine(centres):
            out = np.zeros(len(centres), dtype=bool)
            for tree, r in groups:
                todo = np.flatnonzero(~out)
                d, _ = tree.query(centres[todo], distance_upper_bound=r + r1)
                out[todo] = np.isfinite(d)
            return out
        return refine

    def prepare(self, samples):
        """Build the lattice, its matrices and multigrid for ``samples``' light unless the current one fits."""
        pts = self.edges_of_light(samples)
        h1 = 2.0 * self.resolution.grading.h0
        key = np.unique(np.floor(pts / h1).astype(np.int64), axis=0).tobytes() if len(pts) else b""
        if key == self._lattice_key:
            return {}
        timings = {}
        on_stage = self.on_stage
        t = time.perf_counter()
        refine = self._refinement(pts)
        lo, hi = self.mesh.bbox
        lattice = build_lattice(self.inside.depth, lo, hi, self.resolution.grading, refine=refine)
        _lap(timings, "volume lattice", t, on_stage)
        t = time.perf_counter()
        media = None
        if self.medium is not None:          # each cube's medium at its centre (eq. (107); §17)
            centres = (lattice.ijk + 0.5) * lattice.cell_size[:, None]
            media = self.medium.cube_media(centres)
            _lap(timings, "volume media", t, None)
            t = time.perf_counter()
        asm = assemble(lattice, media=media)
        op = ChannelOperator(asm, self.coef)
        _lap(timings, "volume operator", t, on_stage)
        t = time.perf_counter()
        mg = Multigrid(lattice, op)
        _lap(timings, "volume multigrid", t, on_stage)
        self.lattice, self.assembly, self.operator, self.multigrid = lattice, asm, op, mg
        self._lattice_key = key
        self.stats.update({"volume_cells_per_level": lattice.stats["volume_cells_per_level"],
                           "volume_unknowns": int(asm.n), "volume_multigrid_levels": mg.sizes,
                           "volume_mm3": round(asm.volume, 3), "volume_surface_mm2": round(asm.area, 3),
                           "volume_edge_points": int(len(pts))})
        return timings

    def exitance(self, samples):
        """(M (n, 3) W/mm^2 at the mesh's vertices, stats with ``timings``) for ``samples``, the lights' entry
        samples on ``self.surface.samples``: :meth:`sample_exitance` at the mesh's vertices."""
        Ms, stats = self.sample_exitance(samples)
        return self.to_vertices(Ms), stats

    def sample_exitance(self, samples, scene=None):
        """(M (n_s, 3) W/mm^2 at the sampling surface's vertices, stats with ``timings``): the solution itself,
        P1 on the sampling surface: the mesh's vertices read it at their points (:meth:`to_vertices`), textures and
        per-pixel renders between them (:meth:`meshshade.volume.surface.SamplingSurface.locate`). ``scene``: the
        sampling surface's ray scene (made here if None) for the light crossing thin parts."""
        mat, surf = self.material, self.surface.samples
        stats = {}
        if len(samples) == 0:
            return np.zeros((surf.n_vertices, 3)), {"timings": {}}
        timings = self.prepare(samples)
        on_stage = self.on_stage
        t = time.perf_counter()
        w = refract_in(samples.directions, samples.normals, float(mat.eta))
        cos_t = np.clip(-np.einsum("ij,ij->i", w, samples.normals), 0.0, 1.0)
        if self.medium is not None:          # each entry's sources in the medium where it enters (eq. (107))
            loads, dropped = self.medium.entry_loads(self.lattice, samples, w, self.resolution.spread)
        else:
            depths, strengths = np.zeros((3, 6)), np.zeros((3, 6))
            for c in range(3):
                x, q = line_rule(float(mat.albedo_prime[c]))
                depths[c] = x / float(mat.sigma_t_prime[c])
                strengths[c] = q * ewald_weight(self.resolution.kappa[c], self.resolution.spread)
            loads, dropped = lattice_loads(self.lattice, samples.positions, w, samples.normals, samples.power,
                                           depths, strengths, self.resolution.spread)
        b = self.assembly.to_unknowns(loads)
        _lap(timings, "volume sources", t, on_stage)
        t = time.perf_counter()
        with kernel_interrupts():
            x, its = solve_channels(self.operator, self.multigrid, b, rtol=self.options.solve_rtol)
        phi = self.assembly.to_nodes(x)
        M, outside = self._read(phi, surf.vertices, surf.vertex_normals)
        _lap(timings, "volume solve", t, on_stage)
        t = time.perf_counter()
        if self.medium is not None:
            Mf, pairs = self.medium.near_field(*self._remainder_inputs(samples, cos_t), self._mean_spacing())
        else:
            Mf, pairs = remainder_exitance(self.tables, *self._remainder_inputs(samples, cos_t),
                                           spacing_mm=self._mean_spacing())
        M += Mf
        _lap(timings, "near field", t, on_stage)
        if not np.all(np.isfinite(M)):
            raise MeshshadeError("the volume transport produced a non-finite exitance")
        peak = np.maximum(M.max(axis=0), 1e-300)
        neg = M < 0
        stats["volume_negative_clamped"] = neg.sum(axis=0).tolist()
        stats["volume_negative_worst"] = [float(max(0.0, -M[:, c].min()) / peak[c]) for c in range(3)]
        M[neg] = 0.0
        if self.options.uncollided:
            t = time.perf_counter()
            Mu, ustats = self.uncollided(samples, scene)
            M += Mu
            stats.update(ustats)
            _lap(timings, "uncollided", t, on_stage)
        elif on_stage is not None:           # not asked for: the stage is over at once (progress reaches its end)
            on_stage("uncollided")
        total = np.maximum(samples.power.sum(), 1e-300)
        stats.update({"volume_dropped_source_power": [round(float(d / total), 6) for d in dropped],
                      "near_field_pairs": int(pairs), "volume_solve_iterations": its.tolist(),
                      "volume_outside_lattice": int(outside), "timings": timings})
        return M, stats

    def uncollided(self, samples, scene=None):
        """(M_u (n_s, 3) W/mm^2 at the sampling surface's vertices, stats): the light entering at ``samples`` that
        leaves unscattered (eqs. (130)-(131), :mod:`meshshade.volume.uncollided`), each vertex's entry split over
        its faces as the Monte Carlo's photons enter (:func:`~meshshade.volume.uncollided.face_entries`)."""
        surf = self.surface.samples
        if scene is None:
            scene = self.scene if self.scene is not None else make_scene(surf.vertices, surf.faces)
        ext = self.medium.extinction() if self.medium is not None else np.asarray(self.material.sigma_t_prime)
        depth = None
        if ext is None:                      # a varying extinction: a midpoint rule along each segment
            medium = self.medium

            def depth(o, d, L):
                u = (np.arange(DEPTH_POINTS) + 0.5) / DEPTH_POINTS
                pts = o[:, None, :] + (L[:, None] * u[None, :])[:, :, None] * d[:, None, :]
                sig = medium.extinction_at(pts.reshape(-1, 3)).reshape(len(o), DEPTH_POINTS, 3)
                return sig.mean(axis=1) * L[:, None]
            depth.sigma_min = medium.least_extinction()
        closed = bool(self.mesh.defects.is_closed) and self.mesh.defects.n_components == 1
        sides = None if closed else (lambda p: self.inside.winding(p) > 0.5)
        eta = float(self.material.eta)
        # only the entries whose own ray can carry light across (a lower bound of its extinction, a margin of
        # PREFILTER_MARGIN below the floor) are split over their faces and followed: most end in a thick part
        w = refract_in(samples.directions, samples.normals, eta)
        first = scene.first_hit(scene.offset_origins(samples.positions, samples.normals, sign=-1.0), w)
        sig_min = ext if ext is not None else depth.sigma_min
        reach = first.hit & (np.exp(-np.where(first.hit, first.t, np.inf) * float(np.min(sig_min)))
                             >= PREFILTER_MARGIN * FLOOR)
        sel = np.flatnonzero(reach)
        pos, nrm, win, pw = face_entries(surf.vertices, surf.faces, samples.vertex[sel], samples.positions[sel],
                                         samples.directions[sel], samples.normals[sel], samples.power[sel], eta)
        M, st = uncollided_exitance(scene, surf.vertex_areas, pos, nrm, win, pw, eta, sigma_t_prime=ext,
                                    optical_depth=depth, sides=sides)
        total = np.maximum(samples.power.sum(), 1e-300)
        return M, {"volume_uncollided_power": [round(float(x / total), 6) for x in st["left"]],
                   "volume_uncollided_lost": [round(float(x / total), 6) for x in st["lost"]],
                   "volume_uncollided_rays": int(st["rays"] + len(samples)),
                   "volume_uncollided_entries": int(sel.size)}

    def point_entries_correction(self, samples, index, points, normals, radius):
        """(p, 3) W/mm^2: eq. (103) of the point entries ``index`` of ``samples`` (beams) at ``points`` (p, 3) with
        ``normals`` and patch ``radius`` (p,) mm: what a per-pixel render adds to the interpolated solution so that
        a pencil beam's peak is as sharp as the pixels."""
        points = np.asarray(points, dtype=np.float64)
        if len(index) == 0 or len(points) == 0:
            return np.zeros((len(points), 3))
        w = refract_in(samples.directions[index], samples.normals[index], float(self.material.eta))
        cos_t = np.clip(-np.einsum("ij,ij->i", w, samples.normals[index]), 0.0, 1.0)
        src = {"pos": samples.positions[index], "normal": samples.normals[index], "power": samples.power[index],
               "area": np.zeros(len(index)), "cos_t": cos_t, "light": np.zeros(len(index), dtype=np.int64)}
        rec = {"pos": points, "normal": np.asarray(normals, dtype=np.float64), "radius": np.asarray(radius),
               "E": np.zeros((len(points), 1)), "cos_t": np.ones((len(points), 1))}
        if self.medium is None:
            M, _ = remainder_exitance(self.tables, src, rec)
            return M
        return self.medium.point_near_field(src, rec, points)

    def _read(self, phi, points, normals):
        """(M (p, 3) = phi / (2A) at ``points``, how many lay outside the lattice). A point farther outside the
        lattice's surface (the zero of its interpolated depth) than OUTSIDE_READ h0 (a sharp corner or edge finer
        than the lattice, where the cut surface passes well inside the mesh's) is moved in along its normal to that
        surface, not read from the P1 functions' extension outside, which a sliver's corner can make large; nearer
        ones (a smooth surface's chords: h^2 / 8R) read the extension, the Robin solution's own continuation. A
        point in no kept cube is moved in along its normal: first by a hair (1e-3 h0: a face on a lattice plane or
        a hair off it, whose cube outside was dropped; moved half a cube in, it read a box's lit face 10 % too
        bright), then by steps of half a cube to four cubes (a part thinner than the lattice resolves), else read
        at the nearest node that holds an unknown."""
        points = np.array(points, dtype=np.float64)
        h = self.resolution.grading.h0
        cells, bary, nodes = self.lattice.locate(points)
        for _ in range(4):
            ok = np.flatnonzero(cells >= 0)
            d = np.einsum("pk,pk->p", bary[ok], self.lattice.depth[nodes[ok]])
            far = d < -OUTSIDE_READ * h
            out = ok[far]
            if out.size == 0:
                break
            points[out] += d[far][:, None] * normals[out]
            cells[out], bary[out], nodes[out] = self.lattice.locate(points[out])
        miss = np.flatnonzero(cells < 0)
        for step in (1e-3, 0.5, 1.0, 2.0, 3.0, 4.0):
            if miss.size == 0:
                break
            c2, b2, n2 = self.lattice.locate(points[miss] - step * h * normals[miss])
            hit = c2 >= 0
            cells[miss[hit]], bary[miss[hit]], nodes[miss[hit]] = c2[hit], b2[hit], n2[hit]
            miss = miss[~hit]
        if miss.size:
            have = self.assembly.free
            _, near = cKDTree(self.lattice.nodes[have]).query(points[miss])
            bary[miss] = 0.0
            bary[miss, 0] = 1.0
            nodes[miss, 0] = have[near]
        M = np.einsum("pk,pkc->pc", bary, phi[nodes]) / (2.0 * self.A[None, :])
        return M, int(np.sum(cells < 0))

    def _mean_spacing(self) -> float:
        """The sampling surface's mean edge (mm) as a regular triangulation of its area and faces would have it,
        sqrt(4 area / (sqrt 3 faces)): the scale of the near field's local reach (no pass over the edges)."""
        surf = self.surface.samples
        return math.sqrt(4.0 * float(surf.total_area) / (math.sqrt(3.0) * max(1, surf.n_faces)))

    def _remainder_inputs(self, samples, cos_t):
        """The entries and receivers of eq. (103) on the sampling surface: one entry per sampling vertex (every
        one, lit or not: the subtraction needs the whole neighbourhood) with the power of all lights entering
        there and their power-weighted cos theta_t, and the beams' point entries."""
        surf = self.surface.samples
        nv = surf.n_vertices
        at_v = samples.vertex >= 0
        v, p, c = samples.vertex[at_v], samples.power[at_v], cos_t[at_v]
        P = np.bincount(v, weights=p, minlength=nv)
        pc = np.bincount(v, weights=p * c, minlength=nv)
        cos_v = np.where(P > 0, pc / np.where(P > 0, P, 1.0), 1.0)
        area = surf.vertex_areas
        E = np.where(area > 0, P / np.where(area > 0, area, 1.0), 0.0)
        pt = ~at_v
        src = {"pos": np.concatenate([surf.vertices, samples.positions[pt]]),
               "normal": np.concatenate([surf.vertex_normals, samples.normals[pt]]),
               "power": np.concatenate([P, samples.power[pt]]),
               "area": np.concatenate([area, np.zeros(int(pt.sum()))]),
               "cos_t": np.concatenate([cos_v, cos_t[pt]]),
               "light": np.zeros(nv + int(pt.sum()), dtype=np.int64)}
        if self._spacing is None:
            self._spacing = longest_edges(surf.vertices, surf.faces)
        rec = {"pos": surf.vertices, "normal": surf.vertex_normals, "radius": np.sqrt(area / math.pi),
               "E": E[:, None], "cos_t": cos_v[:, None], "spacing": self._spacing}
        return src, rec
