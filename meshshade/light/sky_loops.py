"""Compiled loops of the environment and area lights: the scalar twins of :mod:`meshshade.light.environment` and
:mod:`meshshade.light.area`, the rows of the bake's quadrature (:mod:`meshshade.light.incidence`), its shadow rays
through Embree from the worker threads, and the packing of the lights for the Monte Carlo emission
(:mod:`meshshade.montecarlo.emission`).

The quadrature's rows (:func:`quadrature_rows`): for point j and replicate r, m points of its shifted lattice per
strategy; an environment's first strategy draws from the map (:func:`env_direction`, the twin of
``MapSampler.sample``), its second cosine-weighted about the normal (:func:`cosine_direction`), each row's value
``L cos / (m (p_map + cos / pi))`` (docs/physics.md eq. (123)); an area light's rows are points uniform on the
emitter (:func:`area_point`), each ``A_e L_e cos_e cos_x / (m d^2)`` (eq. (122)). A Monte Carlo photon of such a light
draws one direction the same way (one-sample balance heuristic: the map with probability 1/2, ``p = (p_map +
cos/pi)/2``; eq. (125)). :func:`env_pixel` is the twin of ``MapSampler.pixels``; the twins are tested against the
numpy versions.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from meshshade.light.area import emitter_frame
from meshshade.light.environment import map_sampler
from meshshade.light.sources import AreaLight, EnvironmentLight
from meshshade.raycast.embree_direct import rayhit_buffer, trace

__all__ = ["SkyTables", "pack_sky", "env_direction", "env_pixel", "cosine_direction", "area_point", "quadrature_rows",
           "shadow_rows", "row_moments", "fresnel_in", "MOMENTS", "ENVIRONMENT_ROWS", "AREA_ROWS", "SUPPORT_COS",
           "E_ROW", "E_PIX", "E_EDGE", "E_H", "E_W", "E_STRENGTH", "E_TOTAL", "E_FRAME",
           "A_C", "A_U", "A_V", "A_N", "A_SIZE", "A_DISC", "A_RADIANCE", "A_AREA"]

_OPTS = dict(cache=True, error_model="numpy")
#: a direction more than this cosine above one of a convex mesh's faces at the vertex cannot be shadowed
SUPPORT_COS = 1e-6
#: what quadrature_rows draws: an environment's two strategies (map, cosine) or an area light's emitter points
ENVIRONMENT_ROWS, AREA_ROWS = 0, 1
#: columns of a point's moments (row_moments): entering and incident power (W), then entering-power-weighted sums
#: of the refracted direction's cos theta_t, its tangential components a1, a2 (along the point's tangents t1, t2)
#: and their products a1^2, a2^2, a1 a2
MOMENTS = 8
# columns of an environment light's parameter row: offsets into the packed tables, size, strength, S, frame (3x3)
E_ROW, E_PIX, E_EDGE, E_H, E_W, E_STRENGTH, E_TOTAL, E_FRAME = 0, 1, 2, 3, 4, 5, 6, 7
# columns of an area light's: centre, axes u and v, normal, size (2), disc (0/1), radiance, area
A_C, A_U, A_V, A_N, A_SIZE, A_DISC, A_RADIANCE, A_AREA = 0, 3, 6, 9, 12, 14, 15, 16


class SkyTables:
    """The environment maps of a light list packed end to end (float64, contiguous): ``row_cdf``, ``flat_cdf``
    (each row's column CDF offset by twice its row index, :class:`~meshshade.light.environment.MapSampler`),
    ``lum`` (luminance per unit strength, row-major) and ``cos_edges``; empty arrays without an environment."""

    def __init__(self, row_cdf, flat_cdf, lum, cos_edges):
        self.row_cdf = np.ascontiguousarray(row_cdf, dtype=np.float64)
        self.flat_cdf = np.ascontiguousarray(flat_cdf, dtype=np.float64)
        self.lum = np.ascontiguousarray(lum, dtype=np.float64)
        self.cos_edges = np.ascontiguousarray(cos_edges, dtype=np.float64)


def pack_sky(lights, params) -> SkyTables:
    """Fill the rows of ``params`` (L, >= 17) of the environment and area lights among ``lights`` (see the column
    constants) and return the packed map tables."""
    rows, flats, lums, edges = [], [], [], []
    off = np.zeros(3, dtype=np.int64)
    for i, light in enumerate(lights):
        p = params[i]
        if isinstance(light, EnvironmentLight):
            s = map_sampler(light)
            p[E_ROW], p[E_PIX], p[E_EDGE], p[E_H], p[E_W] = off[0], off[1], off[2], s.H, s.W
            p[E_STRENGTH], p[E_TOTAL] = s.strength, s.total
            p[E_FRAME:E_FRAME + 9] = s.frame.ravel()
            rows.append(s.row_cdf)
            flats.append((s.col_cdf + 2.0 * np.arange(s.H)[:, None]).ravel())
            lums.append(s.lum.ravel())
            edges.append(s.cos_edges)
            off += [s.H, s.H * s.W, s.H + 1]
        elif isinstance(light, AreaLight):
            c, u, v, n = emitter_frame(light)
            p[A_C:A_C + 3], p[A_U:A_U + 3], p[A_V:A_V + 3], p[A_N:A_N + 3] = c, u, v, n
            p[A_SIZE:A_SIZE + 2] = light.size
            p[A_DISC] = 1.0 if light.shape == "disc" else 0.0
            p[A_RADIANCE], p[A_AREA] = light.radiance, light.area

    def cat(parts):
        return np.concatenate(parts) if parts else np.zeros(1)
    return SkyTables(cat(rows), cat(flats), cat(lums), cat(edges))


@njit(inline="always", **_OPTS)
def env_pixel(p, wx, wy, wz):
    """Flat index (into ``SkyTables.lum``) of the pixel of environment row ``p`` holding unit direction w."""
    f = E_FRAME
    tx = p[f] * wx + p[f + 1] * wy + p[f + 2] * wz
    ty = p[f + 3] * wx + p[f + 4] * wy + p[f + 5] * wz
    tz = p[f + 6] * wx + p[f + 7] * wy + p[f + 8] * wz
    H, W = int(p[E_H]), int(p[E_W])
    u = 0.5 - math.atan2(ty, tx) / (2.0 * math.pi)
    u -= math.floor(u)
    s = math.acos(min(1.0, max(-1.0, tz))) / math.pi
    col = min(int(u * W), W - 1)
    row = min(int(s * H), H - 1)
    return int(p[E_PIX]) + row * W + col


@njit(inline="always", **_OPTS)
def env_direction(p, row_cdf, flat_cdf, cos_edges, x, y):
    """Unit direction (mesh frame) of environment row ``p`` for the point (x, y) of [0, 1)^2 (scalar twin of
    ``MapSampler.sample``)."""
    H, W = int(p[E_H]), int(p[E_W])
    r0, p0, e0 = int(p[E_ROW]), int(p[E_PIX]), int(p[E_EDGE])
    row = min(np.searchsorted(row_cdf[r0:r0 + H], x, side="right"), H - 1)
    lo = row_cdf[r0 + row - 1] if row > 0 else 0.0
    a = min(1.0, max(0.0, (x - lo) / (row_cdf[r0 + row] - lo)))
    flat = flat_cdf[p0 + row * W:p0 + (row + 1) * W]      # the row's column CDF, offset by 2 row
    base = 2.0 * row
    col = max(0, min(np.searchsorted(flat, y + base, side="right"), W - 1))
    clo = flat[col - 1] - base if col > 0 else 0.0
    b = min(1.0, max(0.0, (y - clo) / (flat[col] - base - clo)))
    c0, c1 = cos_edges[e0 + row], cos_edges[e0 + row + 1]
    cos_t = c0 + a * (c1 - c0)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    phi = math.pi - 2.0 * math.pi * (col + b) / W
    tx, ty, tz = sin_t * math.cos(phi), sin_t * math.sin(phi), cos_t
    f = E_FRAME
    return (p[f] * tx + p[f + 3] * ty + p[f + 6] * tz, p[f + 1] * tx + p[f + 4] * ty + p[f + 7] * tz,
            p[f + 2] * tx + p[f + 5] * ty + p[f + 8] * tz)


@njit(inline="always", **_OPTS)
def cosine_direction(nx, ny, nz, x, y):
    """Cosine-weighted unit direction about the unit normal n for (x, y) of [0, 1)^2 (Malley's method in the frame
    of Duff et al. 2017, as :mod:`meshshade.light.incidence`)."""
    s = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (s + nz)
    b = nx * ny * a
    t1x, t1y, t1z = 1.0 + s * nx * nx * a, s * b, -s * nx
    t2x, t2y, t2z = b, s + ny * ny * a, -ny
    r = math.sqrt(x)
    phi = 2.0 * math.pi * y
    c, d, z = r * math.cos(phi), r * math.sin(phi), math.sqrt(max(0.0, 1.0 - x))
    return c * t1x + d * t2x + z * nx, c * t1y + d * t2y + z * ny, c * t1z + d * t2z + z * nz


@njit(inline="always", **_OPTS)
def area_point(p, x, y):
    """Point (mm) of area light row ``p`` for (x, y) of [0, 1)^2, uniform over the emitter (as
    :func:`~meshshade.light.area.emitter_points`)."""
    if p[A_DISC] != 0.0:
        r = math.sqrt(x)
        phi = 2.0 * math.pi * y
        s, t = p[A_SIZE] * r * math.cos(phi), p[A_SIZE + 1] * r * math.sin(phi)
    else:
        s, t = (x - 0.5) * p[A_SIZE], (y - 0.5) * p[A_SIZE + 1]
    return (p[A_C] + s * p[A_U] + t * p[A_V], p[A_C + 1] + s * p[A_U + 1] + t * p[A_V + 1],
            p[A_C + 2] + s * p[A_U + 2] + t * p[A_V + 2])


@njit(nogil=True, **_OPTS)
def quadrature_rows(a, b, kind, P, Nrm, shifts, lx, ly, prm, sky_rows, sky_flat, sky_lum, sky_edges, adjacent,
                    face_normals, w_out, value_out, cos_out, tmax_out, sure_out):
    """Rows of points a .. b - 1 (module docstring): point j's K = R S m rows start at j K, ordered by replicate,
    strategy and lattice point; ``value_out`` 0 for a row that brings nothing (below the horizon, behind the
    emitter). ``shifts`` (n, R, S, 2), ``lx``/``ly`` (m,) the lattice, ``prm`` the light's parameter row.
    ``adjacent`` (n, deg) the faces of each point's vertex on a mesh certified convex (padded with a face whose
    ``face_normals`` row is 0; zero columns otherwise): ``sure_out`` marks the rows above one of them, which no
    shadow ray needs (light.incidence.SupportingPlanes)."""
    R, S, m = shifts.shape[1], shifts.shape[2], lx.shape[0]
    K = R * S * m
    deg = adjacent.shape[1]
    for j in range(a, b):
        nx, ny, nz = Nrm[j, 0], Nrm[j, 1], Nrm[j, 2]
        for r in range(R):
            for s in range(S):
                for i in range(m):
                    row = j * K + (r * S + s) * m + i
                    x = lx[i] + shifts[j, r, s, 0]
                    x -= math.floor(x)
                    y = ly[i] + shifts[j, r, s, 1]
                    y -= math.floor(y)
                    value = 0.0
                    if kind == ENVIRONMENT_ROWS:
                        if s == 0:
                            wx, wy, wz = env_direction(prm, sky_rows, sky_flat, sky_edges, x, y)
                        else:
                            wx, wy, wz = cosine_direction(nx, ny, nz, x, y)
                        cos = wx * nx + wy * ny + wz * nz
                        if cos > 0.0:
                            lum = sky_lum[env_pixel(prm, wx, wy, wz)]
                            value = prm[E_STRENGTH] * lum * cos / (m * (lum / prm[E_TOTAL] + cos / math.pi))
                        tmax_out[row] = math.inf
                    else:
                        qx, qy, qz = area_point(prm, x, y)
                        ex, ey, ez = qx - P[j, 0], qy - P[j, 1], qz - P[j, 2]
                        d = math.sqrt(ex * ex + ey * ey + ez * ez)
                        wx, wy, wz = (ex / d, ey / d, ez / d) if d > 0.0 else (nx, ny, nz)
                        cos = wx * nx + wy * ny + wz * nz
                        cos_e = -(wx * prm[A_N] + wy * prm[A_N + 1] + wz * prm[A_N + 2])
                        if d > 0.0 and cos > 0.0 and cos_e > 0.0:
                            value = prm[A_AREA] * prm[A_RADIANCE] * cos * cos_e / (m * d * d)
                        tmax_out[row] = d
                    w_out[row, 0], w_out[row, 1], w_out[row, 2] = wx, wy, wz
                    value_out[row] = value
                    cos_out[row] = cos
                    sure = False
                    if value > 0.0:
                        for q in range(deg):
                            f = adjacent[j, q]
                            if (face_normals[f, 0] * wx + face_normals[f, 1] * wy
                                    + face_normals[f, 2] * wz) > SUPPORT_COS:
                                sure = True
                                break
                    sure_out[row] = sure


@njit(nogil=True, **_OPTS)
def shadow_rows(a, b, origins, dirs, tmax, center, intersect, scene, occluded_out):
    """Shadow rays a .. b - 1 through Embree from this thread (:func:`meshshade.raycast.embree_direct.trace`, float32
    relative to ``center``): ``occluded_out[j]`` whether ray j meets the mesh within ``tmax[j]`` mm. The origins lie
    on the mesh (offset off it), inside Embree's bounding sphere, so no ray needs advancing first."""
    rh, rhi = rayhit_buffer()
    for j in range(a, b):
        t = min(tmax[j], 1e37)
        hit = trace(intersect, scene, rh, rhi, origins[j, 0] - center[0], origins[j, 1] - center[1],
                    origins[j, 2] - center[2], dirs[j, 0], dirs[j, 1], dirs[j, 2], t)
        occluded_out[j] = hit >= 0


@njit(inline="always", **_OPTS)
def fresnel_in(cos_i, eta):
    """Unpolarised Fresnel reflectance from index 1 into ``eta`` (scalar twin of kernels.fresnel, eta_i = 1)."""
    cos_i = min(1.0, max(0.0, cos_i))
    if eta == 1.0:
        return 0.0
    if cos_i == 0.0:
        return 1.0
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return min(1.0, max(0.0, 0.5 * (rs * rs + rp * rp)))


@njit(nogil=True, **_OPTS)
def row_moments(pt, rep, w, cos, value, areas, Nrm, T1, T2, eta, replicates, entering_out, moments, rep_sum):
    """Add the rows (point ``pt``, replicate ``rep``, unit direction ``w`` towards the light, ``cos`` on the normal,
    ``value`` W/mm^2) to their points: ``rep_sum[p, r]`` the replicates' irradiance estimates, ``moments[p]`` the
    :data:`MOMENTS` columns (the row's power ``value area / replicates``, after Fresnel ``F_t(cos)`` for the
    entering one; the refracted direction from Snell's law); ``entering_out[j]`` row j's entering power (W)."""
    for j in range(pt.shape[0]):
        p = pt[j]
        rep_sum[p, rep[j]] += value[j]
        inc = value[j] * areas[p] / replicates
        c = cos[j]
        e = inc * (1.0 - fresnel_in(c, eta))
        entering_out[j] = e
        cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - c * c) / (eta * eta)))
        # the refracted direction's tangential part: that of the travel direction -w, over eta
        tx = (-w[j, 0] + c * Nrm[p, 0]) / eta
        ty = (-w[j, 1] + c * Nrm[p, 1]) / eta
        tz = (-w[j, 2] + c * Nrm[p, 2]) / eta
        a1 = tx * T1[p, 0] + ty * T1[p, 1] + tz * T1[p, 2]
        a2 = tx * T2[p, 0] + ty * T2[p, 1] + tz * T2[p, 2]
        moments[p, 0] += e
        moments[p, 1] += inc
        moments[p, 2] += e * cos_t
        moments[p, 3] += e * a1
        moments[p, 4] += e * a2
        moments[p, 5] += e * a1 * a1
        moments[p, 6] += e * a2 * a2
        moments[p, 7] += e * a1 * a2
