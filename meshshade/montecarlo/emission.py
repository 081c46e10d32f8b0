"""Photon emission of the pooled engine, compiled and parallel: each photon's entry drawn from its own stream.

The physics is that of :class:`meshshade.montecarlo.emitter.Emitter` (which keeps the numpy version, the twin
that the baseline wavefront uses and the tests compare against): a light is chosen in proportion to its power;
a pencil beam enters at its precomputed first hit; a wide beam starts uniformly on the clipped square of its disc
and enters where its ray first hits (photons outside the disc or beside the mesh carry nothing); directional and
point lights pick a face in proportion to the centroid estimate of its incident power, a uniform point on it and
(point lights) an importance weight; environment and area lights pick a face from the bake's estimate, a point on
it and a direction (:mod:`meshshade.light.sky_loops`); a shadow ray towards the light decides whether the
point is lit. At entry
the Fresnel reflectance F(cos) from index 1 into ``eta`` is split off as specular power and the direction is
refracted (Snell).

Three steps, so that the ray casts can be Embree's from the numba threads (``fused``) or one embreex call
(``batched``) with the same sampling:

1. :func:`sample_entries` (``prange`` over photons): the light, face and point of every photon, and the ray it
   needs (none, the first hit of a wide beam's ray, or a shadow ray);
2. the casts: :func:`cast_direct` (``prange``, ``rtcIntersect1``), or ``EmitterKernel.cast`` through embreex;
3. :func:`enter_slots` (``prange``): the hit's float64 barycentrics, the shadow, Fresnel and refraction, written
   straight into the pool's free slots.

Photon ``pid`` of channel group ``k`` draws its entry from the counter-based stream keyed by (seed, k, pid) on an
emission base separate from its walk's (:func:`emission_base`), so the entry of a photon, like its path, does not
depend on the thread count, the pool size or which process walks it.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from meshshade.light import AreaLight, BeamLight, DirectionalLight, EnvironmentLight, PointLight
from meshshade.montecarlo import loops as K
from meshshade.light.sky_loops import (A_AREA, A_N, A_RADIANCE, E_STRENGTH, E_TOTAL, area_point,
                                       cosine_direction, env_direction, env_pixel, fresnel_in, pack_sky)
from meshshade.raycast.embree_direct import rayhit_buffer, trace

__all__ = ["EmitterKernel", "emission_base", "fresnel_in", "spot_falloff", "sample_entries", "cast_direct",
           "enter_slots"]

_OPTS = K._OPTS
#: light kinds of the compiled emitter
PENCIL, DISC, DIRECTIONAL, POINT, ENVIRONMENT, AREA = 0, 1, 2, 3, 4, 5
#: rays an entry needs
NO_RAY, FIRST_HIT, SHADOW = 0, 1, 2
#: the emission streams' group offset: group k's entries draw from stream_base(seed, k + EMISSION_GROUPS)
EMISSION_GROUPS = 1 << 20
# columns of the per-light parameter rows (L, 24)
_O, _D, _U, _V, _LO, _HI, _R2 = 0, 3, 6, 9, 12, 14, 16       # disc beam: origin, direction, basis, rect, R^2
_P, _I, _SPOT, _AX, _SC, _SW = 0, 3, 4, 5, 8, 9             # point light: position, intensity, spot, axis, c, width


def emission_base(seed: int, group: int) -> np.uint64:
    """uint64 base of the entry streams of channel group ``group`` (distinct from the walks' bases)."""
    return np.uint64(K.stream_base(np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF), int(group) + EMISSION_GROUPS))


@njit(inline="always", **_OPTS)
def spot_falloff(cos_theta, c, width):
    """Scalar twin of :meth:`meshshade.light.Spot.falloff`: c = cos(angle / 2), width = (1 - c) * blend."""
    if not width > 0.0:
        return 1.0 if cos_theta >= c else 0.0
    t = min(1.0, max(0.0, (cos_theta - c) / width))
    return t * t * (3.0 - 2.0 * t)


def _sample(pid0, k, base, w_photon, light_cdf, kinds, params, rows, cdfs, wfaces, V, F, N, A, center, scale,
            off_rel, off_abs, light, face, bary, weight, query, ray_o, ray_d, ray_t, sky_rows, sky_flat, sky_lum,
            sky_edges):
    """Step 1 for photons pid0 .. pid0 + k - 1 (outputs indexed by j = pid - pid0); see the module docstring."""
    m = F.shape[0]
    for j in prange(k):
        key = K.photon_key(base, pid0 + j)
        c = np.uint64(0)
        u, c = K._uniform(key, c)
        li = min(np.searchsorted(light_cdf, u, side="right"), light_cdf.shape[0] - 1)
        light[j] = li
        kind = kinds[li]
        w = w_photon
        query[j] = NO_RAY
        face[j] = 0
        bary[j, 0], bary[j, 1], bary[j, 2] = 1.0, 0.0, 0.0
        if kind == DISC:
            p = params[li]
            u1, c = K._uniform(key, c)
            u2, c = K._uniform(key, c)
            a = p[_LO] + (p[_HI] - p[_LO]) * u1
            b = p[_LO + 1] + (p[_HI + 1] - p[_LO + 1]) * u2
            if a * a + b * b <= p[_R2]:
                query[j] = FIRST_HIT
                for q in range(3):
                    ray_o[j, q] = p[_O + q] + a * p[_U + q] + b * p[_V + q]
                    ray_d[j, q] = p[_D + q]
                ray_t[j] = math.inf
            else:
                w = 0.0
        elif kind == DIRECTIONAL or kind == POINT or kind == ENVIRONMENT or kind == AREA:
            row = rows[li]
            u, c = K._uniform(key, c)
            f = min(np.searchsorted(cdfs[row], u, side="right"), m - 1)
            u1, c = K._uniform(key, c)
            u2, c = K._uniform(key, c)
            r1 = math.sqrt(u1)
            b0, b1, b2 = 1.0 - r1, r1 * (1.0 - u2), r1 * u2
            face[j] = f
            bary[j, 0], bary[j, 1], bary[j, 2] = b0, b1, b2
            i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
            px = b0 * V[i0, 0] + b1 * V[i1, 0] + b2 * V[i2, 0]
            py = b0 * V[i0, 1] + b1 * V[i1, 1] + b2 * V[i2, 1]
            pz = b0 * V[i0, 2] + b1 * V[i1, 2] + b2 * V[i2, 2]
            p = params[li]
            if kind == DIRECTIONAL:
                dx, dy, dz = p[0], p[1], p[2]
                t = math.inf
            elif kind == ENVIRONMENT:   # one-sample MIS of the map and the cosine (light.sky_loops)
                us, c = K._uniform(key, c)
                ux, c = K._uniform(key, c)
                uy, c = K._uniform(key, c)
                if us < 0.5:
                    wx, wy, wz = env_direction(p, sky_rows, sky_flat, sky_edges, ux, uy)
                else:
                    wx, wy, wz = cosine_direction(N[f, 0], N[f, 1], N[f, 2], ux, uy)
                cos = max(0.0, wx * N[f, 0] + wy * N[f, 1] + wz * N[f, 2])
                lum = sky_lum[env_pixel(p, wx, wy, wz)]
                pdf = 0.5 * lum / p[E_TOTAL] + 0.5 * cos / math.pi
                w *= p[E_STRENGTH] * lum * cos / pdf * A[f] / wfaces[row, f] if pdf > 0.0 else 0.0
                dx, dy, dz = -wx, -wy, -wz
                t = math.inf
            elif kind == AREA:          # a point uniform on the emitter
                ux, c = K._uniform(key, c)
                uy, c = K._uniform(key, c)
                qx, qy, qz = area_point(p, ux, uy)
                ex, ey, ez = px - qx, py - qy, pz - qz
                t = math.sqrt(ex * ex + ey * ey + ez * ez)
                dx, dy, dz = ex / t, ey / t, ez / t
                cos = max(0.0, -(N[f, 0] * dx + N[f, 1] * dy + N[f, 2] * dz))
                cos_e = max(0.0, dx * p[A_N] + dy * p[A_N + 1] + dz * p[A_N + 2])
                w *= p[A_AREA] * p[A_RADIANCE] * cos * cos_e / (t * t) * A[f] / wfaces[row, f]
            else:
                ex, ey, ez = px - p[_P], py - p[_P + 1], pz - p[_P + 2]
                t = math.sqrt(ex * ex + ey * ey + ez * ez)
                dx, dy, dz = ex / t, ey / t, ez / t
                emit = p[_I]
                if p[_SPOT] != 0.0:
                    emit *= spot_falloff(dx * p[_AX] + dy * p[_AX + 1] + dz * p[_AX + 2], p[_SC], p[_SW])
                cos = max(0.0, -(N[f, 0] * dx + N[f, 1] * dy + N[f, 2] * dz))
                # importance weight: true irradiance at the point over the face-centroid value used for sampling
                w *= emit * cos / (t * t) * A[f] / wfaces[row, f]
            eps = K.ray_offset(px, py, pz, center, scale, off_rel, off_abs)
            query[j] = SHADOW
            ray_o[j, 0], ray_o[j, 1], ray_o[j, 2] = px + eps * N[f, 0], py + eps * N[f, 1], pz + eps * N[f, 2]
            ray_d[j, 0], ray_d[j, 1], ray_d[j, 2] = -dx, -dy, -dz
            ray_t[j] = t
        weight[j] = w


sample_entries = njit(parallel=True, nogil=True, **_OPTS)(_sample)


def _cast(query, ray_o, ray_d, ray_t, center, radius, intersect, scene, hit):
    """Step 2 with Embree from the numba threads: ``hit[j]`` the first-hit face (-1: none within ray_t[j]) of
    every photon with a ray; origins outside the bounding sphere (1.01 x radius) are first advanced to it, as
    :meth:`meshshade.raycast.embree.EmbreeScene` does, so float32 keeps its precision."""
    r2 = (1.01 * radius) ** 2
    for j in prange(query.shape[0]):
        hit[j] = -1
        if query[j] == NO_RAY:
            continue
        rh, rhi = rayhit_buffer()
        ox, oy, oz = ray_o[j, 0] - center[0], ray_o[j, 1] - center[1], ray_o[j, 2] - center[2]
        dx, dy, dz = ray_d[j, 0], ray_d[j, 1], ray_d[j, 2]
        b = ox * dx + oy * dy + oz * dz
        cc = ox * ox + oy * oy + oz * oz - r2
        t0 = 0.0
        if cc > 0.0:
            disc = b * b - cc
            if disc < 0.0 or b > 0.0:   # outside the sphere and not reaching it: no hit
                continue
            t0 = max(0.0, -b - math.sqrt(disc))
        tfar = ray_t[j] - t0
        if not tfar > 0.0:
            continue
        hit[j] = trace(intersect, scene, rh, rhi, ox + t0 * dx, oy + t0 * dy, oz + t0 * dz, dx, dy, dz,
                       min(tfar, 1e37))


cast_direct = njit(parallel=True, nogil=True, **_OPTS)(_cast)


def _enter(pid0, k, slots, query, hit, light, face, bary, weight, ray_o, ray_d, kinds, params, beam_entry, V, F,
           N, v0, e1, e2, center, scale, off_rel, off_abs, eta, walk_base, n_batches, status, pos, d, w, w0, pend, key,
           ctr, batch, slot_light, pid, inc, spec, w_in):
    """Step 3: entry ``j`` (photon pid0 + j) goes into pool slot ``slots[j]`` (ALIVE when it carries power);
    ``inc``, ``spec``, ``w_in`` (k,) receive its incident, specular and entering power."""
    for j in prange(k):
        li = light[j]
        kind = kinds[li]
        wj = weight[j]
        f = face[j]
        b0, b1, b2 = bary[j, 0], bary[j, 1], bary[j, 2]
        if query[j] == SHADOW and hit[j] >= 0:
            wj = 0.0
        elif query[j] == FIRST_HIT:
            f = hit[j]
            dx, dy, dz = ray_d[j, 0], ray_d[j, 1], ray_d[j, 2]
            if f < 0 or N[f, 0] * dx + N[f, 1] * dy + N[f, 2] * dz >= 0.0:
                wj = 0.0
                f = 0
            else:   # float64 barycentrics of the hit on face f (Moller-Trumbore, clipped onto the face)
                _t, uu, vv = K.face_ray(f, ray_o[j, 0], ray_o[j, 1], ray_o[j, 2], dx, dy, dz, v0, e1, e2)
                uu, vv = K.clip_onto_face(uu, vv)
                b0, b1, b2 = 1.0 - uu - vv, uu, vv
        i = slots[j]
        pid_j = pid0 + j
        bt = pid_j % n_batches
        if kind == PENCIL:
            x, y, z = beam_entry[li, 0], beam_entry[li, 1], beam_entry[li, 2]
            ux, uy, uz = beam_entry[li, 3], beam_entry[li, 4], beam_entry[li, 5]
            fr = beam_entry[li, 6]
        elif wj > 0.0:
            i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
            x = b0 * V[i0, 0] + b1 * V[i1, 0] + b2 * V[i2, 0]
            y = b0 * V[i0, 1] + b1 * V[i1, 1] + b2 * V[i2, 1]
            z = b0 * V[i0, 2] + b1 * V[i1, 2] + b2 * V[i2, 2]
            nx, ny, nz = N[f, 0], N[f, 1], N[f, 2]
            if kind == DISC:
                ox, oy, oz = params[li, _D], params[li, _D + 1], params[li, _D + 2]
            elif kind == DIRECTIONAL:
                ox, oy, oz = params[li, 0], params[li, 1], params[li, 2]
            else:
                ox, oy, oz = -ray_d[j, 0], -ray_d[j, 1], -ray_d[j, 2]
            cos_i = min(1.0, max(0.0, -(ox * nx + oy * ny + oz * nz)))
            fr = fresnel_in(cos_i, eta)
            eps = K.ray_offset(x, y, z, center, scale, off_rel, off_abs)
            x, y, z = x - eps * nx, y - eps * ny, z - eps * nz
            cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - cos_i * cos_i) / (eta * eta)))
            cf = cos_i / eta - cos_t
            ux, uy, uz = ox / eta + cf * nx, oy / eta + cf * ny, oz / eta + cf * nz
            nrm = 1.0 / math.sqrt(ux * ux + uy * uy + uz * uz)
            ux, uy, uz = ux * nrm, uy * nrm, uz * nrm
        else:
            x = y = z = ux = uy = uz = fr = 0.0
        inc[j] = wj
        spec[j] = wj * fr
        w_in[j] = wj * (1.0 - fr)
        if w_in[j] > 0.0:
            status[i] = K.ALIVE
            pos[i, 0], pos[i, 1], pos[i, 2] = x, y, z
            d[i, 0], d[i, 1], d[i, 2] = ux, uy, uz
            w[i] = w0[i] = w_in[j]
            pend[i] = -1.0
            key[i] = K.photon_key(walk_base, pid_j)
            ctr[i] = np.uint64(0)
            batch[i], slot_light[i], pid[i] = bt, li, pid_j


enter_slots = njit(parallel=True, nogil=True, **_OPTS)(_enter)


@njit(parallel=True, nogil=True, **_OPTS)
def book_entries(pid0, k, n_batches, inc, spec, w_in, tot):
    """Add the incident, specular and entering power of entries 0 .. k - 1 (photon pid0 + j, batch
    (pid0 + j) % n_batches) to ``tot[:, 5]``, ``tot[:, 0]``, ``tot[:, 6]``: in parallel over batches, each in
    photon order (bitwise independent of the thread count)."""
    for b in prange(n_batches):
        j = (b - pid0 % n_batches) % n_batches
        s_inc = 0.0
        s_spec = 0.0
        s_in = 0.0
        while j < k:
            s_inc += inc[j]
            s_spec += spec[j]
            s_in += w_in[j]
            j += n_batches
        tot[b, 5] += s_inc
        tot[b, 0] += s_spec
        tot[b, 6] += s_in


class EmitterKernel:
    """The lights of an :class:`~meshshade.montecarlo.emitter.Emitter` packed for the compiled emission.

    ``emit_into(pool, slots, pid0, base, walk_base, n_total, n_batches, tot)`` writes photons pid0 .. pid0 + k - 1
    (k = len(slots)) into the pool's ``slots``; the casts go through ``direct`` (a
    :class:`~meshshade.raycast.embree_direct.DirectEmbreeScene`) when given, else through the emitter's scene.
    """

    def __init__(self, emitter, direct=None):
        em = self.em = emitter
        self.direct = direct
        L = len(em.lights)
        self.kinds = np.zeros(L, dtype=np.int64)
        self.params = np.zeros((L, 24))
        self.rows = np.full(L, -1, dtype=np.int64)
        self.beam_entry = np.zeros((L, 7))
        cdfs, wfaces = [], []
        for i, (light, part) in enumerate(zip(em.lights, em.parts)):
            p = self.params[i]
            if part[0] == "beam":
                _, f, b, d = part
                p1, d1, F1 = em._enter(np.array([f]), np.asarray(b, dtype=np.float64)[None], np.asarray(d)[None])
                self.kinds[i] = PENCIL
                self.beam_entry[i] = [*p1[0], *d1[0], F1[0]]
            elif part[0] == "disc":
                _, _, _, d, lt, (u, v, lo, hi, _area) = part
                self.kinds[i] = DISC
                p[_O:_O + 3], p[_D:_D + 3], p[_U:_U + 3], p[_V:_V + 3] = lt.origin, d, u, v
                p[_LO:_LO + 2], p[_HI:_HI + 2], p[_R2] = lo, hi, lt.radius ** 2
            else:
                _, cdf, w_face, lt = part
                self.rows[i] = len(cdfs)
                cdfs.append(cdf)
                wfaces.append(w_face)
                if isinstance(lt, EnvironmentLight):
                    self.kinds[i] = ENVIRONMENT
                elif isinstance(lt, AreaLight):
                    self.kinds[i] = AREA
                elif isinstance(lt, DirectionalLight):
                    self.kinds[i] = DIRECTIONAL
                    p[0:3] = lt.direction
                else:
                    assert isinstance(lt, PointLight)
                    self.kinds[i] = POINT
                    p[_P:_P + 3], p[_I] = lt.position, lt.intensity
                    if lt.spot is not None:
                        c = math.cos(0.5 * lt.spot.angle)
                        p[_SPOT], p[_AX:_AX + 3], p[_SC], p[_SW] = 1.0, lt.spot.axis, c, (1.0 - c) * lt.spot.blend
            assert isinstance(light, (BeamLight, DirectionalLight, PointLight, EnvironmentLight, AreaLight))
        self.sky = pack_sky(em.lights, self.params)
        m = em.F.shape[0]
        self.cdfs = np.ascontiguousarray(np.array(cdfs) if cdfs else np.zeros((0, m)))
        self.wfaces = np.ascontiguousarray(np.array(wfaces) if wfaces else np.zeros((0, m)))
        self.light_cdf = np.ascontiguousarray(em.light_cdf, dtype=np.float64)
        self.V = np.ascontiguousarray(em.V, dtype=np.float64)
        self.F = np.ascontiguousarray(em.F, dtype=np.int64)
        self.N = np.ascontiguousarray(em.N, dtype=np.float64)
        self.A = np.ascontiguousarray(em.A, dtype=np.float64)
        self.v0, self.e1, self.e2, _ = K.face_records(self.V, self.F, self.N)
        sc = em.scene
        self.center = np.ascontiguousarray(sc.center, dtype=np.float64)
        self.scale = float(sc.scale)
        self.radius = float(getattr(sc, "_radius", 0.5 * sc.scale))
        self._buf = None

    def _buffers(self, k):
        if self._buf is None or self._buf["light"].shape[0] < k:
            n = max(k, 1024)
            self._buf = {"light": np.zeros(n, dtype=np.int64), "face": np.zeros(n, dtype=np.int64),
                         "bary": np.zeros((n, 3)), "weight": np.zeros(n), "query": np.zeros(n, dtype=np.int8),
                         "ray_o": np.zeros((n, 3)), "ray_d": np.zeros((n, 3)), "ray_t": np.zeros(n),
                         "hit": np.zeros(n, dtype=np.int64), "inc": np.zeros(n), "spec": np.zeros(n),
                         "w_in": np.zeros(n)}
        return {name: a[:k] for name, a in self._buf.items()}

    def _cast(self, b):
        if self.direct is not None:
            cast_direct(b["query"], b["ray_o"], b["ray_d"], b["ray_t"], self.center, self.radius,
                        self.direct.intersect, self.direct.handle, b["hit"])
            return
        b["hit"][:] = -1
        sc = self.em.scene
        first = np.flatnonzero(b["query"] == FIRST_HIT)
        if first.size:
            b["hit"][first] = sc.first_hit(b["ray_o"][first], b["ray_d"][first]).face
        shadow = np.flatnonzero(b["query"] == SHADOW)
        if shadow.size:
            occ = sc.occluded(b["ray_o"][shadow], b["ray_d"][shadow], b["ray_t"][shadow])
            b["hit"][shadow[occ]] = 0

    def emit_into(self, st, slots, pid0, base, walk_base, n_total, n_batches, tot, off_rel, off_abs):
        """Photons pid0 .. pid0 + len(slots) - 1 into pool ``st``'s ``slots``; books their powers in ``tot``.
        Returns the number that carry power (the slots made ALIVE)."""
        k = slots.shape[0]
        if k == 0:
            return 0
        b = self._buffers(k)
        sample_entries(pid0, k, base, self.em.total_power / n_total, self.light_cdf, self.kinds, self.params,
                       self.rows, self.cdfs, self.wfaces, self.V, self.F, self.N, self.A, self.center, self.scale,
                       off_rel, off_abs, b["light"], b["face"], b["bary"], b["weight"], b["query"], b["ray_o"],
                       b["ray_d"], b["ray_t"], self.sky.row_cdf, self.sky.flat_cdf, self.sky.lum, self.sky.cos_edges)
        self._cast(b)
        enter_slots(pid0, k, slots, b["query"], b["hit"], b["light"], b["face"], b["bary"], b["weight"],
                    b["ray_o"], b["ray_d"], self.kinds, self.params, self.beam_entry, self.V, self.F, self.N,
                    self.v0, self.e1, self.e2, self.center, self.scale, off_rel, off_abs, self.em.eta, walk_base,
                    n_batches, st.status, st.pos, st.d, st.w, st.w0, st.pend, st.key, st.ctr, st.batch, st.light,
                    st.pid, b["inc"], b["spec"], b["w_in"])
        book_entries(pid0, k, n_batches, b["inc"], b["spec"], b["w_in"], tot)
        return int(np.count_nonzero(b["w_in"]))
