"""Compiled loops of the pooled Monte Carlo engine (:mod:`meshshade.montecarlo.engine`).

Every photon owns a counter-based random stream (below), so its path depends only on (seed, channel group,
photon index): never on the thread count, the scheduling or the pool size. Loops that run over the pool in
parallel (``prange``) write only to their own photon's slot; every sum over photons is done afterwards by
:func:`reduce_round`, in parallel over batches and in slot order within a batch, so the tallies are also bitwise
independent of the thread count.

Random numbers: photon ``i`` runs its own SplitMix64 generator (Steele, Lea & Flood 2014, OOPSLA; passes
BigCrush): draw ``k`` is ``u_k = mix(key + k * golden) / 2**64`` (top 53 bits), with the photon's key
``key = mix(base + (i + 1) * golden)`` and ``base`` derived from (seed, group) the same way. ``mix`` (the SplitMix64
finaliser) is a bijection of 64-bit words, so distinct photons have distinct keys. Two photons' streams are
shifted copies of one Weyl sequence; they share draws only if their keys lie within (draws per photon) x golden
of each other, a chance of ~N**2 L / 2**64 (N photons of L draws: ~1e-6 for 1e6 photons of 1e4 draws), and then
only as an uncorrelated-looking reuse of numbers at different points of two different paths.

Physics is that of :mod:`meshshade.montecarlo.simulation` (MCML conventions); the resolution of a boundary test
repeats the float64 ray-triangle reconstruction of :meth:`meshshade.raycast.scene._SceneBase._hits_on_faces`
(Moller & Trumbore 1997, barycentrics clipped onto the triangle) and the ray offsets of
:meth:`~meshshade.raycast.scene._SceneBase.offset_epsilon`. The fused walk of the ``fused`` mode, which calls
Embree from these threads, is :mod:`meshshade.montecarlo.fused_walk`.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_ONE = np.uint64(1)
_INV53 = 1.0 / 9007199254740992.0
FREE, ALIVE = np.int8(0), np.int8(1)
SCATTER, REFLECT, EXIT, LEAK = 0, 1, 2, 3
_OPTS = dict(cache=True, error_model="numpy")


@njit(inline="always", **_OPTS)
def _mix(z):
    """SplitMix64 finaliser (a bijection of uint64)."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(inline="always", **_OPTS)
def _uniform(key, ctr):
    """(u in [0, 1), next counter) of the stream ``key`` at counter ``ctr`` (SplitMix64 seeded with ``key``)."""
    ctr = ctr + _ONE
    z = _mix(key + ctr * _GOLDEN)
    return float(z >> _S11) * _INV53, ctr


@njit(**_OPTS)
def stream_base(seed, group):
    """uint64 base of the photon keys of channel group ``group`` (seed: uint64)."""
    return _mix(_mix(seed + _GOLDEN) + np.uint64(group + 1) * _GOLDEN)


@njit(**_OPTS)
def photon_key(base, index):
    return _mix(base + np.uint64(index + 1) * _GOLDEN)


@njit(**_OPTS)
def uniform_stream(key, n):
    """First ``n`` uniforms of stream ``key`` (for tests)."""
    out = np.empty(n)
    c = np.uint64(0)
    for k in range(n):
        out[k], c = _uniform(key, c)
    return out


@njit(inline="always", **_OPTS)
def certified(safe, geo, planes, pidx, x, y, z, dx, dy, dz, s):
    """Whether the free path from (x, y, z) along (dx, dy, dz) of length ``s`` provably stays inside the mesh.

    First the distance bound (safe: (nx, ny, nz) uint8 in units of geo[4], rounded down), then the voxel's
    half-space certificate (pidx: plane index or -1; planes: (n, c); both ends in {n . y < c} and the end within
    sqrt(geo[6]) of the voxel centre); see :mod:`meshshade.montecarlo.interior`. Whether a path is certified
    never changes the walk, only its cost.
    geo = (origin x, y, z, 1/h, bound unit, h, certificate radius**2).
    """
    fa = math.floor((x - geo[0]) * geo[3])
    fb = math.floor((y - geo[1]) * geo[3])
    fc = math.floor((z - geo[2]) * geo[3])
    if fa < 0 or fb < 0 or fc < 0 or fa >= safe.shape[0] or fb >= safe.shape[1] or fc >= safe.shape[2]:
        return False
    a, b, c = int(fa), int(fb), int(fc)
    if s < safe[a, b, c] * geo[4]:
        return True
    j = pidx[a, b, c]
    if j < 0:
        return False
    ex, ey, ez = x + s * dx, y + s * dy, z + s * dz
    rx = ex - (geo[0] + (a + 0.5) * geo[5])
    ry = ey - (geo[1] + (b + 0.5) * geo[5])
    rz = ez - (geo[2] + (c + 0.5) * geo[5])
    if rx * rx + ry * ry + rz * rz >= geo[6]:
        return False
    nx, ny, nz, cc = planes[j, 0], planes[j, 1], planes[j, 2], planes[j, 3]
    return nx * x + ny * y + nz * z < cc and nx * ex + ny * ey + nz * ez < cc


@njit(inline="always", **_OPTS)
def _hg_scatter(dx, dy, dz, g, key, c):
    """Henyey-Greenstein scattering of unit (dx, dy, dz): (nx, ny, nz, counter).

    cos(theta) by inversion, the azimuth by Marsaglia's (1972) disc rejection, the frame by Duff et al. (2017).
    """
    u, c = _uniform(key, c)
    if abs(g) < 1e-6:
        ct = 1.0 - 2.0 * u
    else:
        tmp = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
        ct = min(1.0, max(-1.0, (1.0 + g * g - tmp * tmp) / (2.0 * g)))
    st = math.sqrt(max(0.0, 1.0 - ct * ct))
    while True:  # uniform azimuth without trigonometry: (p, q) uniform in the unit disc, angle doubled
        u, c = _uniform(key, c)
        p = 2.0 * u - 1.0
        u, c = _uniform(key, c)
        q = 2.0 * u - 1.0
        r2 = p * p + q * q
        if 0.0 < r2 <= 1.0:
            break
    sign = 1.0 if dz >= 0.0 else -1.0
    a = -1.0 / (sign + dz)
    bb = dx * dy * a
    f = st / r2
    cp, sp = (p * p - q * q) * f, 2.0 * p * q * f
    nx = cp * (1.0 + sign * dx * dx * a) + sp * bb + ct * dx
    ny = cp * (sign * bb) + sp * (sign + dy * dy * a) + ct * dy
    nz = cp * (-sign * dx) + sp * (-dy) + ct * dz
    inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx * inv, ny * inv, nz * inv, c


@njit(inline="always", **_OPTS)
def fresnel_out(cos_i, eta):
    """Unpolarised Fresnel reflectance from index ``eta`` into 1 (scalar twin of kernels.fresnel, eta_i=eta)."""
    if eta == 1.0:
        return 0.0
    cos_i = min(1.0, max(0.0, cos_i))
    e = 1.0 / eta
    e2 = e * e
    d = (e - 1.0) * (e + 1.0)
    cos2_t = (d + cos_i * cos_i) / e2
    if cos2_t <= 0.0 or cos_i == 0.0:
        return 1.0
    cos_t = math.sqrt(cos2_t)
    dp = cos_i + e * cos_t
    dl = e * cos_i + cos_t
    rp = -d / (dp * dp)
    rl = d * (cos_i * cos_i * (d + 2.0) - 1.0) / (e2 * dl * dl)
    return min(1.0, max(0.0, 0.5 * (rp * rp + rl * rl)))


@njit(inline="always", **_OPTS)
def scatter_s(x, y, z, dx, dy, dz, wi, s, k, c, thr, albedo, g, boost):
    """Fly ``s`` mm, deposit (1 - albedo) of the weight, scatter (HG), Russian roulette below ``thr``.

    Returns (x, y, z, dx, dy, dz, weight, counter, absorbed, alive); ``absorbed`` includes the roulette's net
    weight change (exact balance, unbiased).
    """
    x += s * dx
    y += s * dy
    z += s * dz
    ab = wi * (1.0 - albedo)
    wi *= albedo
    dx, dy, dz, c = _hg_scatter(dx, dy, dz, g, k, c)
    alive = True
    if wi < thr:
        u, c = _uniform(k, c)
        if u * boost < 1.0:
            ab -= (boost - 1.0) * wi
            wi *= boost
        else:
            ab += wi
            wi = 0.0
            alive = False
    return x, y, z, dx, dy, dz, wi, c, ab, alive


@njit(inline="always", **_OPTS)
def ray_offset(px, py, pz, center, scale, off_rel, off_abs):
    """The scene's ray offset at p in mm, as :meth:`meshshade.raycast.scene._SceneBase.offset_epsilon`:
    off_rel (scale + |p - center|) + off_abs |p|."""
    rc = math.sqrt((px - center[0]) ** 2 + (py - center[1]) ** 2 + (pz - center[2]) ** 2)
    return off_rel * (scale + rc) + off_abs * math.sqrt(px * px + py * py + pz * pz)


@njit(inline="always", **_OPTS)
def face_ray(f, x, y, z, dx, dy, dz, v0, e1, e2):
    """(t, u, v): the float64 Moller-Trumbore distance and barycentrics of the ray from (x, y, z) along (dx, dy, dz)
    on face f (v0, e1, e2: its first vertex and edges); a grazing ray (no finite solution) takes the first vertex
    (u = v = 0) at the distance of its projection on the ray."""
    a0, a1, a2 = e1[f, 0], e1[f, 1], e1[f, 2]
    b0, b1, b2 = e2[f, 0], e2[f, 1], e2[f, 2]
    px, py, pz = dy * b2 - dz * b1, dz * b0 - dx * b2, dx * b1 - dy * b0
    det = a0 * px + a1 * py + a2 * pz
    sx, sy, sz = x - v0[f, 0], y - v0[f, 1], z - v0[f, 2]
    qx, qy, qz = sy * a2 - sz * a1, sz * a0 - sx * a2, sx * a1 - sy * a0
    inv = 1.0 / det
    u = (sx * px + sy * py + sz * pz) * inv
    v = (dx * qx + dy * qy + dz * qz) * inv
    t = (b0 * qx + b1 * qy + b2 * qz) * inv
    if not (math.isfinite(u) and math.isfinite(v) and math.isfinite(t)):  # grazing: nearest vertex
        u, v = 0.0, 0.0
        t = -(sx * dx + sy * dy + sz * dz)
    return t, u, v


@njit(inline="always", **_OPTS)
def clip_onto_face(u, v):
    """Barycentrics (u, v) moved onto the triangle: negatives to 0, a sum above 1 scaled back to 1."""
    u = max(u, 0.0)
    v = max(v, 0.0)
    if u + v > 1.0:
        tot = u + v
        u /= tot
        v /= tot
    return u, v


def face_records(V, F, normals):
    """(v0, e1, e2, normals) (m, 3) each: views of one 96-byte record per face (a boundary test touches 1-2 cache
    lines, not 4), as :func:`face_ray` and :func:`surface_s` read them."""
    tri = V[F]
    packed = np.ascontiguousarray(np.concatenate([tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0],
                                                  np.asarray(normals, dtype=np.float64)], axis=1))
    return tuple(packed[:, 3 * j:3 * j + 3] for j in range(4))


@njit(inline="always", **_OPTS)
def surface_s(f, x, y, z, dx, dy, dz, s, k, c, v0, e1, e2, normals, center, scale, off_rel, off_abs, eta):
    """Outcome of a boundary test whose Embree hit within tfar = free path + margin is face f (-1: none).

    Returns (kind, x, y, z, dx, dy, dz, counter, u, v): kind SCATTER (the free path ends before the surface:
    the caller scatters), REFLECT (position moved back inside by the scene's ray offset, direction mirrored),
    EXIT (leaves through f at barycentrics (1-u-v, u, v)) or LEAK (no or front-facing hit from inside).
    The distance and barycentrics are recomputed in float64 on face f (Moller-Trumbore, clipped).
    """
    if f < 0:
        return (SCATTER if s < math.inf else LEAK), x, y, z, dx, dy, dz, c, 0.0, 0.0
    nxf, nyf, nzf = normals[f, 0], normals[f, 1], normals[f, 2]
    cos_i = dx * nxf + dy * nyf + dz * nzf
    if not cos_i > 0.0:  # a ray from inside must hit the back of a face
        return LEAK, x, y, z, dx, dy, dz, c, 0.0, 0.0
    t, u, v = face_ray(f, x, y, z, dx, dy, dz, v0, e1, e2)
    if s < max(t, 0.0):
        return SCATTER, x, y, z, dx, dy, dz, c, 0.0, 0.0
    u, v = clip_onto_face(u, v)
    hx = v0[f, 0] + u * e1[f, 0] + v * e2[f, 0]
    hy = v0[f, 1] + u * e1[f, 1] + v * e2[f, 1]
    hz = v0[f, 2] + u * e1[f, 2] + v * e2[f, 2]
    uu, c = _uniform(k, c)
    if uu < fresnel_out(cos_i, eta):
        eps = ray_offset(hx, hy, hz, center, scale, off_rel, off_abs) / math.sqrt(nxf * nxf + nyf * nyf + nzf * nzf)
        return (REFLECT, hx - eps * nxf, hy - eps * nyf, hz - eps * nzf, dx - 2.0 * cos_i * nxf,
                dy - 2.0 * cos_i * nyf, dz - 2.0 * cos_i * nzf, c, u, v)
    return EXIT, hx, hy, hz, dx, dy, dz, c, u, v


@njit(inline="always", **_OPTS)
def surface_event(i, f, pos, d, w, w0, pend, key, ctr, absorbed, lost, status, exit_face, exit_bary, exit_w,
                  v0, e1, e2, normals, center, scale, off_rel, off_abs, eta, albedo, g, thresh, boost):
    """:func:`surface_s` (then scattering, reflection, exit or leak) on photon i's slot; (events, boundary)."""
    s, k = pend[i], key[i]
    kind, x, y, z, dx, dy, dz, c, u, v = surface_s(f, pos[i, 0], pos[i, 1], pos[i, 2], d[i, 0], d[i, 1], d[i, 2],
                                                   s, k, ctr[i], v0, e1, e2, normals, center, scale, off_rel,
                                                   off_abs, eta)
    ev = 0
    bd = 0
    pend[i] = -1.0
    if kind == SCATTER:
        x, y, z, dx, dy, dz, wi, c, ab, alive = scatter_s(x, y, z, dx, dy, dz, w[i], s, k, c, thresh * w0[i],
                                                          albedo, g, boost)
        absorbed[i] += ab
        w[i] = wi
        if not alive:
            status[i] = FREE
        ev = 1
    elif kind == LEAK:
        lost[i] += w[i]
        w[i] = 0.0
        status[i] = FREE
    elif kind == EXIT:
        exit_face[i] = f
        exit_bary[i, 0], exit_bary[i, 1], exit_bary[i, 2] = 1.0 - u - v, u, v
        exit_w[i] = w[i]
        w[i] = 0.0
        status[i] = FREE
        bd = 1
    else:
        bd = 1
    pos[i, 0], pos[i, 1], pos[i, 2] = x, y, z
    d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
    ctr[i] = c
    return ev, bd


@njit(inline="always", **_OPTS)
def interior_run(i, pos, d, w, w0, pend, key, ctr, absorbed, status, safe, geo, planes, pidx, sigma_t, albedo, g,
                 thresh, boost, max_steps):
    """Photon i scatters while its free path is certified by the safe-distance bound, at most ``max_steps`` times.

    Returns (events, need): ``need`` is True when the pending free path (kept in ``pend``) may reach the surface.
    """
    x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
    dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
    wi, s, k, c = w[i], pend[i], key[i], ctr[i]
    thr = thresh * w0[i]
    ab_sum = 0.0
    ev = 0
    need = False
    alive = True
    while True:
        if s < 0.0:
            u, c = _uniform(k, c)
            s = -math.log(1.0 - u) / sigma_t
        if not certified(safe, geo, planes, pidx, x, y, z, dx, dy, dz, s):
            need = True
            break
        if ev >= max_steps:
            break
        x, y, z, dx, dy, dz, wi, c, ab, alive = scatter_s(x, y, z, dx, dy, dz, wi, s, k, c, thr, albedo, g, boost)
        ab_sum += ab
        s = -1.0
        ev += 1
        if not alive:
            break
    pos[i, 0], pos[i, 1], pos[i, 2] = x, y, z
    d[i, 0], d[i, 1], d[i, 2] = dx, dy, dz
    w[i], pend[i], ctr[i] = wi, s, c
    absorbed[i] += ab_sum
    if not alive:
        status[i] = FREE
    return ev, need


def _advance(status, pos, d, w, w0, pend, key, ctr, absorbed, need, safe, geo, planes, pidx, sigma_t, albedo, g,
             thresh, boost, max_steps):
    """:func:`interior_run` for every live photon (``need`` marks the photons waiting for a boundary test).

    Photons stopped by ``max_steps`` continue next round. Returns the number of scattering events.
    """
    n = status.shape[0]
    events = 0
    for i in prange(n):
        need[i] = False
        if status[i] == ALIVE:
            ev, nd = interior_run(i, pos, d, w, w0, pend, key, ctr, absorbed, status, safe, geo, planes, pidx,
                                  sigma_t, albedo, g, thresh, boost, max_steps)
            need[i] = nd
            events += ev
    return events


def _resolve(idx, prim, status, pos, d, w, w0, pend, key, ctr, absorbed, lost, exit_face, exit_bary, exit_w,
             v0, e1, e2, normals, center, scale, off_rel, off_abs, eta, albedo, g, thresh, boost):
    """:func:`surface_event` for photons ``idx`` with Embree first-hit faces ``prim``; (events, boundary events)."""
    m = idx.shape[0]
    events = 0
    boundary = 0
    for j in prange(m):
        ev, bd = surface_event(idx[j], prim[j], pos, d, w, w0, pend, key, ctr, absorbed, lost, status, exit_face,
                               exit_bary, exit_w, v0, e1, e2, normals, center, scale, off_rel, off_abs, eta,
                               albedo, g, thresh, boost)
        events += ev
        boundary += bd
    return events, boundary


advance_parallel = njit(parallel=True, nogil=True, **_OPTS)(_advance)
resolve_parallel = njit(parallel=True, nogil=True, **_OPTS)(_resolve)


@njit(nogil=True, **_OPTS)
def gather_rays(need, pos, d, pend, center, margin):
    """Slots needing a boundary test (ascending), their float32 rays relative to the scene centre and their
    float32 tfar = free path + ``margin`` (the margin covers Embree's float32 error, so a hit within the free path
    is never missed)."""
    idx = np.flatnonzero(need)
    o32 = np.empty((idx.size, 3), dtype=np.float32)
    d32 = np.empty((idx.size, 3), dtype=np.float32)
    tfar = np.empty(idx.size, dtype=np.float32)
    for j in range(idx.size):
        i = idx[j]
        for a in range(3):
            o32[j, a] = pos[i, a] - center[a]
            d32[j, a] = d[i, a]
        tfar[j] = min(pend[i] + margin, 1e37)
    return idx, o32, d32, tfar


def _reduce(batch, light, absorbed, lost, exit_face, exit_bary, exit_w, F, facing, tot, face, face_vert):
    """One round's absorbed/lost/exit weights into the per-batch tallies, in parallel over batches: batch ``b``'s
    thread adds the slots of batch ``b`` in slot order, so the sums are bitwise independent of the thread count
    and no two threads write the same tally row.

    tot[:, 1] diffuse (exit on a face facing the photon's light), 2 transmitted, 3 absorbed, 4 lost.
    """
    n_batches = tot.shape[0]
    for b in prange(n_batches):
        for i in range(batch.shape[0]):
            if batch[i] != b:
                continue
            if absorbed[i] != 0.0:
                tot[b, 3] += absorbed[i]
                absorbed[i] = 0.0
            if lost[i] != 0.0:
                tot[b, 4] += lost[i]
                lost[i] = 0.0
            f = exit_face[i]
            if f < 0:
                continue
            exit_face[i] = -1
            we = exit_w[i]
            face[b, f] += we
            for a in range(3):
                face_vert[b, F[f, a]] += we * exit_bary[i, a]
            tot[b, 1 if facing[light[i], f] else 2] += we


reduce_round = njit(parallel=True, nogil=True, **_OPTS)(_reduce)


@njit(nogil=True, **_OPTS)
def cut_off(status, w, batch, tot):
    """Hard time limit: the weight still in flight is booked as lost (tot[:, 4]); all slots freed."""
    for i in range(status.shape[0]):
        if status[i] == ALIVE:
            tot[batch[i], 4] += w[i]
            w[i] = 0.0
            status[i] = FREE
