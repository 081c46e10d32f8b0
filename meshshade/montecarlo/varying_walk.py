"""The pooled engine's walk in a varying medium: a painted material or a material of parts (docs/physics.md §17,
"The Monte Carlo in a varying medium").

The walk of :mod:`meshshade.montecarlo.fused_walk` (the same pool, entry, random streams, safe-distance grid,
Embree calls from the numba threads, boundary physics and tallies), with the medium read where a photon collides
(:func:`meshshade.montecarlo.media.medium_at`):

* *delta tracking* (Woodcock et al. 1965; Coleman 1968): free paths are drawn at the majorant sigma_bar of the
  channel group's medium, s = -ln(u) / sigma_bar; at the tentative collision x the collision is real with
  probability sigma_t(x) / sigma_bar (one more uniform of the photon's stream), else null: the photon goes on from x
  in the same direction with the same weight. A real collision is the homogeneous walk's: the weight times the
  local single-scattering albedo, Henyey-Greenstein with the local g, the same Russian roulette. The majorant
  bounds sigma_t everywhere, so the tracking is unbiased; a boundary nearer than the tentative free path is met as
  in the homogeneous walk (Fresnel, with the one index of the object's boundary) and a new free path drawn after
  it (the free path is memoryless).
* where sigma_t equals the majorant everywhere (a painted material with g = 0, whose sigma_t is the base's
  sigma_t'; parts of equal sigma_t) no collision is null and no uniform is drawn to decide: the walk is then the
  homogeneous walk with the weight taking the local albedo at each collision, and for parts of one material it is
  bitwise the homogeneous walk.

Its properties are the engine's: photon ``i``'s path depends only on (seed, channel group, i), every sum runs in
a fixed order (bitwise the same for any thread count), time budget and progress as the pooled engine
(:class:`meshshade.montecarlo.engine.PoolWalk`, whose rounds this walk replaces). It needs the Embree library bound
from numba (the ``fused`` mode); the ``batched`` mode, the baseline wavefront and Dask workers walk homogeneous
media only.
"""
from __future__ import annotations

import math
import warnings

import numba
import numpy as np
from numba import njit, prange

from meshshade.errors import MeshshadeError
from meshshade.geometry.mesh import MeshDefectWarning
from meshshade.montecarlo import loops as K
from meshshade.montecarlo.engine import CHUNK, CHUNKS_PER_THREAD, PoolWalk
from meshshade.montecarlo.interior import SafeDistanceGrid
from meshshade.montecarlo.media import MediumField, common_eta, medium_at, medium_fields
from meshshade.montecarlo.sampling import ROULETTE_BOOST as K_BOOST, ROULETTE_THRESHOLD as K_THRESH, GroupMedium
from meshshade.montecarlo.walks import GroupTally, WalkSetup, check_engine, make_emitter, surface_note
from meshshade.raycast import make_scene
from meshshade.raycast.embree_direct import DirectEmbreeScene, rayhit_buffer, trace
from meshshade.raycast.scene import OFFSET_ABS, OFFSET_REL

__all__ = ["walk_varying_parallel", "VaryingPoolWalk", "prepare_varying_walks", "walk_varying_group"]


def _walk(idx, status, pos, d, w, w0, pend, key, ctr, absorbed, lost, exit_face, exit_bary, exit_w, safe, geo,
          planes, pidx, v0, e1, e2, normals, center, scale, off_rel, off_abs, margin, eta, thresh, boost, max_steps,
          intersect, scene, kind, fp, paint, parts):
    """:func:`meshshade.montecarlo.fused_walk.walk_parallel` with delta tracking in the medium (kind, fp, paint,
    parts) (module docstring). Returns (real scattering events, boundary events, rays, null collisions)."""
    events = 0
    boundary = 0
    rays = 0
    nulls = 0
    sigma_bar = fp[0]
    constant = fp[1] > 0.0
    for j in prange(idx.shape[0]):
        i = idx[j]
        if status[i] != K.ALIVE:
            continue
        rh, rhi = rayhit_buffer()
        stack = np.empty(256, np.int64)
        x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        wi, s, k, c = w[i], pend[i], key[i], ctr[i]
        thr = thresh * w0[i]
        ab_sum = 0.0
        alive = True
        ev = 0
        bd = 0
        nr = 0
        nn = 0
        steps = 0
        while steps < max_steps:
            steps += 1
            if s < 0.0:
                u, c = K._uniform(k, c)
                s = -math.log(1.0 - u) / sigma_bar
            kind_s = K.SCATTER
            if not K.certified(safe, geo, planes, pidx, x, y, z, dx, dy, dz, s):
                f = trace(intersect, scene, rh, rhi, x - center[0], y - center[1], z - center[2], dx, dy, dz,
                          min(s + margin, 1e37))
                nr += 1
                kind_s, x, y, z, dx, dy, dz, c, u, v = K.surface_s(f, x, y, z, dx, dy, dz, s, k, c, v0, e1, e2,
                                                                   normals, center, scale, off_rel, off_abs, eta)
            if kind_s == K.SCATTER:
                px, py, pz = x + s * dx, y + s * dy, z + s * dz
                st, albedo, g = medium_at(px, py, pz, kind, fp, paint, parts, stack)
                real = True
                if not constant:
                    u, c = K._uniform(k, c)
                    real = u * sigma_bar < st
                if real:
                    x, y, z, dx, dy, dz, wi, c, ab, alive = K.scatter_s(x, y, z, dx, dy, dz, wi, s, k, c, thr,
                                                                        albedo, g, boost)
                    ab_sum += ab
                    ev += 1
                else:
                    x, y, z = px, py, pz
                    nn += 1
            elif kind_s == K.LEAK:
                lost[i] += wi
                wi = 0.0
                alive = False
            elif kind_s == K.EXIT:
                exit_face[i] = f
                exit_bary[i, 0], exit_bary[i, 1], exit_bary[i, 2] = 1.0 - u - v, u, v
                exit_w[i] = wi
                wi = 0.0
                alive = False
                bd += 1
            else:
                bd += 1
            s = -1.0
            if not alive:
                status[i] = K.FREE
                break
        pos[i, 0], pos[i, 1], pos[i, 2] = x, y, z
        d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
        w[i], pend[i], ctr[i] = wi, s, c
        absorbed[i] += ab_sum
        events += ev
        boundary += bd
        rays += nr
        nulls += nn
    return events, boundary, rays, nulls


walk_varying_parallel = njit(parallel=True, nogil=True, **K._OPTS)(_walk)


class VaryingPoolWalk(PoolWalk):
    """:class:`~meshshade.montecarlo.engine.PoolWalk` (its pool, emission, budget and tallies) whose rounds walk in
    the varying medium ``field`` (:class:`~meshshade.montecarlo.media.MediumField`); ``nulls`` counts the null
    collisions."""

    def __init__(self, V, F, normals, emitter, scene, grid, fld: MediumField, eta, *, direct, **kwargs):
        if direct is None:
            raise MeshshadeError("a varying medium walks only with Embree bound from the walk's threads (engine "
                                 "'fused'), which is not available here")
        # the majorant as the base walk's medium (its sigma_t is what the base class would sample with)
        super().__init__(V, F, normals, emitter, scene, grid, GroupMedium(fld.majorant, 0.0, 0.0, eta),
                         direct=direct, **kwargs)
        self.field = fld
        self.nulls = 0

    def _round(self, st, steps):
        grid, fld = self.grid, self.field
        idx = np.flatnonzero(st.status)
        chunk = int(min(CHUNK, max(1, idx.size // (CHUNKS_PER_THREAD * numba.get_num_threads()))))
        with numba.parallel_chunksize(chunk):
            ev, bd, nr, nn = walk_varying_parallel(
                idx, st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key, st.ctr, st.absorbed, st.lost,
                st.exit_face, st.exit_bary, st.exit_w, self._safe, self._geo, grid.planes, grid.plane_index,
                self._v0, self._e1, self._e2, self._N, self._center, self.scene.scale, OFFSET_REL, OFFSET_ABS,
                self._margin, self.eta, K_THRESH, K_BOOST, steps, self.direct.intersect, self.direct.handle,
                fld.kind, fld.fp, fld.paint, fld.parts)
        self.events += int(ev)
        self.boundary += int(bd)
        self.rays += int(nr)
        self.nulls += int(nn)
        if self.beam_light is not None and self.keep_beam:
            sel = np.flatnonzero((st.exit_face >= 0) & (st.light == self.beam_light))
            if sel.size:
                for k, arr in (("face", st.exit_face), ("bary", st.exit_bary), ("weight", st.exit_w),
                               ("batch", st.batch)):
                    self.exits[k].append(arr[sel].copy())
        K.reduce_round(st.batch, st.light, st.absorbed, st.lost, st.exit_face, st.exit_bary, st.exit_w, self._F,
                       self._facing, self.tot, self.face, self.face_vert)


def prepare_varying_walks(mesh, material, lights, surface, *, engine: str = "auto",
                          half_space_certificates: bool = True, stacklevel: int = 3) -> WalkSetup:
    """:func:`meshshade.montecarlo.walks.prepare_walks` for a painted or parted ``material`` on the walk surface
    ``surface``: the same scene, grid and emitter, plus the channel groups' medium fields (``setup.fields``)."""
    engine = check_engine(engine)
    if engine == "batched":
        raise MeshshadeError("a varying medium walks only in the engine's fused mode (engine 'auto' or 'fused')")
    eta = common_eta(material)
    if msg := surface_note(surface):
        warnings.warn(msg, MeshDefectWarning, stacklevel=stacklevel)
    medium = np.zeros(mesh.n_faces, dtype=bool)
    whole = (surface.face_of >= 0) if surface.split is None else (surface.face_of >= 0) & (surface.split < 0)
    medium[surface.face_of[whole]] = True
    groups, fields = medium_fields(material, mesh, medium)
    V, F = surface.vertices, surface.faces
    scene = make_scene(V, F)
    top = max(f.majorant for f in fields)
    use_planes = top > 0 and half_space_certificates
    grid = SafeDistanceGrid(V, F, mean_free_path=1.0 / top if use_planes else None)
    direct = None
    if getattr(scene, "backend", "") == "embree":
        try:
            direct = DirectEmbreeScene(V, F, scene.center)
        except (RuntimeError, OSError) as exc:
            raise MeshshadeError(f"a varying medium needs the engine's fused mode, not available here ({exc})") \
                from exc
    if direct is None:
        raise MeshshadeError("a varying medium needs the engine's fused mode (Embree), not available here")
    emitter = make_emitter(mesh, surface, lights, eta, scene)
    setup = WalkSetup(V, F, surface.normals, scene, grid, direct, emitter, material, groups, True, surface)
    setup.fields = fields
    setup.eta = eta
    return setup


def walk_varying_group(setup: WalkSetup, gi: int, n_photons: int, *, seed: int, n_batches: int, pool: int | None,
                       keep_beam: bool, time_budget: float | None = None, progress=None) -> GroupTally:
    """Walk channel group ``gi`` of a varying ``setup`` (:func:`prepare_varying_walks`) over ``n_photons``."""
    walk = VaryingPoolWalk(setup.V, setup.F, setup.normals, setup.emitter, setup.scene, setup.grid,
                           setup.fields[gi], setup.eta, direct=setup.direct, n_batches=n_batches,
                           keep_beam=keep_beam, seed=seed, group=gi)
    emitted = walk.run(n_photons, pool=pool, time_budget=time_budget, progress=progress)
    tally = GroupTally(walk.face, walk.face_vert, walk.tot, int(emitted), int(walk.events), int(walk.boundary),
                       int(walk.rays), {k: list(v) for k, v in walk.exits.items()})
    tally.nulls = walk.nulls
    return tally
