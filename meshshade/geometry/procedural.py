"""Deterministic procedural meshes: ``(vertices, faces)`` arrays, outward oriented, lengths in the caller's unit.

Every generator returns ``vertices`` (n, 3) float64 and ``faces`` (m, 3) int64 with counter-clockwise winding seen
from outside (positive signed volume for the closed shapes), no duplicate vertices (neighbouring faces share
their vertices) and no degenerate faces. The same arguments always give bitwise the same arrays. Closed-form
curvatures (convex = positive with outward normals) are given in each docstring for tests.
"""
from __future__ import annotations

import numpy as np

__all__ = ["icosahedron", "icosphere", "uv_sphere", "capped_cylinder", "torus", "box", "saddle_patch",
           "pebble", "apple", "spherical_uv"]


def _check_positive(**kwargs):
    for name, value in kwargs.items():
        if not (np.all(np.isfinite(value)) and np.all(np.asarray(value) > 0)):
            raise ValueError(f"{name} must be positive, got {value!r}")


def _check_count(name: str, value, minimum: int) -> int:
    if int(value) != value or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def icosahedron():
    """The regular icosahedron inscribed in the unit sphere: (12, 3) vertices, (20, 3) faces."""
    p = (1.0 + 5.0 ** 0.5) / 2.0
    V = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p], [0, -1, -p],
                  [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], dtype=np.float64)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                  [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    return V / np.linalg.norm(V, axis=1, keepdims=True), F


def _subdivide(V, F):
    """Split every triangle into four at its edge midpoints (midpoints shared between neighbours)."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    lo, hi = e.min(axis=1), e.max(axis=1)
    keys, first, inv = np.unique(lo * np.int64(V.shape[0]) + hi, return_index=True, return_inverse=True)
    mids = 0.5 * (V[lo[first]] + V[hi[first]])
    m = F.shape[0]
    ab, bc, ca = (V.shape[0] + inv.reshape(3, m))
    a, b, c = F.T
    F2 = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1), np.stack([c, ca, bc], 1),
                         np.stack([ab, bc, ca], 1)])
    return np.concatenate([V, mids]), F2


def icosphere(radius: float = 1.0, subdivisions: int = 3):
    """Icosphere: the icosahedron split ``subdivisions`` times, every vertex projected exactly onto the sphere.

    10 * 4**s + 2 vertices, 20 * 4**s faces; mean edge length about ``1.1 * radius / 2**s``.
    Curvature: k1 = k2 = 1/radius everywhere.
    """
    _check_positive(radius=radius)
    s = _check_count("subdivisions", subdivisions, 0)
    V, F = icosahedron()
    for _ in range(s):
        V, F = _subdivide(V, F)
        V = V / np.linalg.norm(V, axis=1, keepdims=True)
    return V * float(radius), F


def spherical_uv(vertices, faces, centre=(0.0, 0.0, 0.0)):
    """A procedural UV map of a closed, star-shaped mesh around ``centre``: per-corner (m, 3, 2) longitude-latitude
    coordinates, u = 1/2 + atan2(y, x) / 2 pi, v = 1/2 + asin(z / |p|) / pi, in [0, 1].

    Faces that straddle the date line (u jumping by more than 1/2 within a face) are shifted to one side and then
    cut back into [0, 1] by squeezing (u of their corners beyond 1 moved to 1: those few faces lose their texels
    beyond the seam, which the neighbours across it do not need); a corner at a pole takes the mean u of the
    face's other corners. Deterministic.
    """
    P = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)] - np.asarray(centre, dtype=np.float64)
    r = np.linalg.norm(P, axis=2)
    u = 0.5 + np.arctan2(P[..., 1], P[..., 0]) / (2.0 * np.pi)
    v = 0.5 + np.arcsin(np.clip(P[..., 2] / np.where(r > 0, r, 1.0), -1.0, 1.0)) / np.pi
    pole = np.hypot(P[..., 0], P[..., 1]) <= 1e-12 * np.maximum(r, 1e-300)
    seam = (np.where(pole, -np.inf, u).max(axis=1) - np.where(pole, np.inf, u).min(axis=1)) > 0.5
    u = np.where(seam[:, None] & (u < 0.5), u + 1.0, u)
    if pole.any():
        others = np.where(pole, 0.0, u).sum(axis=1) / np.maximum((~pole).sum(axis=1), 1)
        u = np.where(pole, others[:, None], u)
    return np.stack([np.clip(u, 0.0, 1.0), v], axis=2)


def uv_sphere(radius: float = 1.0, n_lat: int = 16, n_lon: int = 32):
    """Latitude-longitude sphere, z axis through the poles: 2 + (n_lat - 1) * n_lon vertices.

    Vertices lie exactly on the sphere; triangles are thin near the poles. k1 = k2 = 1/radius.
    """
    _check_positive(radius=radius)
    n_lat, n_lon = _check_count("n_lat", n_lat, 2), _check_count("n_lon", n_lon, 3)
    theta = np.pi * np.arange(1, n_lat) / n_lat
    phi = 2 * np.pi * np.arange(n_lon) / n_lon
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (n_lat - 1, n_lon))], -1)
    V = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]]) * float(radius)
    south = V.shape[0] - 1
    j, j1 = np.arange(n_lon), (np.arange(n_lon) + 1) % n_lon
    idx = lambda i, k: 1 + i * n_lon + k  # noqa: E731 - ring i (0-based), column k
    faces = [np.stack([np.zeros(n_lon, np.int64), idx(0, j), idx(0, j1)], 1)]
    for i in range(n_lat - 2):
        faces += [np.stack([idx(i, j), idx(i + 1, j), idx(i + 1, j1)], 1),
                  np.stack([idx(i, j), idx(i + 1, j1), idx(i, j1)], 1)]
    faces.append(np.stack([np.full(n_lon, south), idx(n_lat - 2, j1), idx(n_lat - 2, j)], 1))
    return V, np.concatenate(faces).astype(np.int64)


def capped_cylinder(radius: float = 1.0, length: float = 4.0, segments: int = 64, rings: int = 64,
                    cap_rings: int | None = None):
    """Cylinder along z from ``-length/2`` to ``length/2`` closed by flat discs.

    The side has ``rings + 1`` circles of ``segments`` vertices; each cap has ``cap_rings`` concentric circles
    (default ``round(segments / 2 pi)``, for triangles about as wide as the side's) and a centre vertex.
    Curvature on the side: k1 = 1/radius around the axis, k2 = 0 along it; 0 on the caps (the rims are edges).
    """
    _check_positive(radius=radius, length=length)
    segments, rings = _check_count("segments", segments, 3), _check_count("rings", rings, 1)
    if cap_rings is None:
        cap_rings = max(1, int(round(segments / (2 * np.pi))))
    cap_rings = _check_count("cap_rings", cap_rings, 1)
    phi = 2 * np.pi * np.arange(segments) / segments
    circle = np.stack([np.cos(phi), np.sin(phi)], 1)
    z = np.linspace(-length / 2, length / 2, rings + 1)
    side = np.concatenate([np.column_stack([radius * circle, np.full(segments, zi)]) for zi in z])
    j, j1 = np.arange(segments), (np.arange(segments) + 1) % segments
    faces = []
    for i in range(rings):
        a, b = i * segments, (i + 1) * segments
        faces += [np.stack([a + j, a + j1, b + j1], 1), np.stack([a + j, b + j1, b + j], 1)]
    verts = [side]
    n = side.shape[0]
    for top in (False, True):
        zc = z[-1] if top else z[0]
        rim = (rings * segments) if top else 0
        inner = [rim]  # first vertex index of each circle, from the rim inwards
        for c in range(1, cap_rings):
            rr = radius * (1 - c / cap_rings)
            verts.append(np.column_stack([rr * circle, np.full(segments, zc)]))
            inner.append(n)
            n += segments
        verts.append(np.array([[0.0, 0.0, zc]]))
        centre = n
        n += 1
        for a, b in zip(inner[:-1], inner[1:]):
            quad = [np.stack([a + j, b + j1, a + j1], 1), np.stack([a + j, b + j, b + j1], 1)]
            faces += [q[:, ::-1] for q in quad] if top else quad
        fan = np.stack([inner[-1] + j, np.full(segments, centre), inner[-1] + j1], 1)
        faces.append(fan[:, ::-1] if top else fan)
    return np.concatenate(verts), np.concatenate(faces).astype(np.int64)


def torus(R: float = 2.0, r: float = 0.5, n_major: int = 96, n_minor: int = 48):
    """Ring torus around the z axis, major radius ``R`` > minor radius ``r``.

    ``x = (R + r cos v) cos u, y = (R + r cos v) sin u, z = r sin v``. Curvature: 1/r around the tube and
    ``cos v / (R + r cos v)`` along the parallels, so on the outer equator (v = 0) k1 = 1/r, k2 = 1/(R + r), and
    on the inner equator (v = pi) k1 = 1/r, k2 = -1/(R - r).
    """
    _check_positive(R=R, r=r)
    if r >= R:
        raise ValueError(f"need r < R for a ring torus, got R={R!r}, r={r!r}")
    nu, nv = _check_count("n_major", n_major, 3), _check_count("n_minor", n_minor, 3)
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    U, Vv = np.meshgrid(u, v, indexing="ij")
    rho = R + r * np.cos(Vv)
    V = np.stack([rho * np.cos(U), rho * np.sin(U), r * np.sin(Vv)], -1).reshape(-1, 3)
    i, k = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    i1, k1 = (i + 1) % nu, (k + 1) % nv
    a, b, c, d = i * nv + k, i1 * nv + k, i1 * nv + k1, i * nv + k1
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F.astype(np.int64)


def box(size=1.0, subdivisions: int = 1):
    """Axis-aligned box centred at the origin, each side a grid of ``subdivisions**2`` squares (two triangles).

    ``size`` is a number or (3,) extents. Vertices on the box's edges and corners are shared by the sides, so the
    surface is closed: ``6 s**2 + 2`` vertices. Curvature 0 on the sides (edges and corners are singular).
    """
    ext = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,)).copy()
    _check_positive(size=ext)
    s = _check_count("subdivisions", subdivisions, 1)
    lattice = np.full((s + 1,) * 3, -1, np.int64)
    g = np.arange(s + 1)
    I, J, K = np.meshgrid(g, g, g, indexing="ij")
    surface = (I == 0) | (I == s) | (J == 0) | (J == s) | (K == 0) | (K == s)
    lattice[surface] = np.arange(int(surface.sum()))
    V = (np.stack([I[surface], J[surface], K[surface]], 1) / s - 0.5) * ext
    faces = []
    for axis in range(3):
        for side in (0, s):
            sl = [slice(None)] * 3
            sl[axis] = side
            grid = lattice[tuple(sl)]  # (s+1, s+1) over the two other axes, in increasing axis order
            a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
            quad = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
            # (u, v, axis) is right-handed for axis = 0 and 2 and left-handed for axis = 1
            outward = (side == s) == (axis != 1)
            faces.append(quad if outward else quad[:, ::-1])
    return V, np.concatenate(faces).astype(np.int64)


def saddle_patch(k: float = 0.1, half_width: float = 1.0, n: int = 33):
    """Open saddle ``z = k (x**2 - y**2) / 2`` over the square ``|x|, |y| <= half_width``, an n x n grid.

    Normals point to +z. With the convex-positive convention (the surface bending away from its normal is
    positive) the curvature at the centre is +k along y (k1) and -k along x (k2).
    """
    _check_positive(half_width=half_width)
    if not np.isfinite(k):
        raise ValueError(f"k must be finite, got {k!r}")
    n = _check_count("n", n, 2)
    t = np.linspace(-half_width, half_width, n)
    X, Y = np.meshgrid(t, t, indexing="ij")
    V = np.stack([X, Y, 0.5 * k * (X**2 - Y**2)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F.astype(np.int64)


def _radial(subdivisions: int, radius_fn):
    """Icosphere whose unit directions ``u`` are moved to ``u * radius_fn(u)`` (star-shaped, so no fold)."""
    U, F = icosphere(1.0, subdivisions)
    r = radius_fn(U)
    if not np.all(r > 0):
        raise ValueError("radial displacement must stay positive")
    return U * r[:, None], F


def pebble(size=(40.0, 30.0, 20.0), subdivisions: int = 5, *, bumpiness: float = 0.06, seed: int = 7):
    """A smooth river-pebble: an ellipsoid with ``size`` extents and a few low-frequency radial bumps.

    The bumps are ``1 + bumpiness * sum_j a_j cos(w_j u.d_j + p_j)`` over eight directions ``d_j`` with
    frequencies 1-3, drawn once from ``numpy.random.default_rng(seed)`` (deterministic). Star-shaped, closed,
    genus 0, smooth (curvatures of order 2/size).
    """
    ext = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    _check_positive(size=ext)
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(8, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    w, ph, amp = rng.uniform(1.0, 3.0, 8), rng.uniform(0, 2 * np.pi, 8), rng.uniform(0.3, 1.0, 8)
    V, F = _radial(subdivisions,
                   lambda U: 1.0 + bumpiness * (amp * np.cos((U @ d.T) * w + ph)).sum(axis=1) / amp.sum() * 2)
    return V * (ext / 2.0), F


def apple(radius: float = 40.0, subdivisions: int = 5):
    """A stylised apple about ``2 * radius`` wide: a sphere slightly wider at the top, with a stem dimple at
    the top pole and a shallower calyx dimple at the bottom, and five faint lobes. Star-shaped, closed, genus 0.
    """
    _check_positive(radius=radius)

    def shape(U):
        theta = np.arccos(np.clip(U[:, 2], -1, 1))  # 0 at the top
        phi = np.arctan2(U[:, 1], U[:, 0])
        r = 1.0 + 0.06 * np.cos(theta) - 0.04 * np.cos(theta) ** 2
        r -= 0.22 * np.exp(-(theta / 0.38) ** 2) + 0.10 * np.exp(-((np.pi - theta) / 0.32) ** 2)
        return r * (1.0 + 0.015 * np.cos(5 * phi) * np.sin(theta) ** 2)

    V, F = _radial(subdivisions, shape)
    return V * float(radius), F


# ------------------------------------------------------------------------------------------------ parts
def _zipper(A, B):
    """(k, 3) triangles between two closed rings of vertex ids ``A`` (a,) and ``B`` (b,), both starting at angle 0
    and running the same way: the rings' advances merged by angle (a ring of one vertex is a pole: a fan)."""
    a, b = len(A), len(B)
    fa = (np.arange(a) + 0.5) / a
    fb = (np.arange(b) + 0.5) / b
    order = np.argsort(np.concatenate([fa, fb]), kind="stable")
    from_a = order < a
    i = np.cumsum(from_a) - from_a                 # A's position before each advance
    j = np.cumsum(~from_a) - (~from_a)
    tri_a = np.stack([A[i % a], A[(i + 1) % a], B[j % b]], axis=1)[from_a]
    tri_b = np.stack([A[i % a], B[(j + 1) % b], B[j % b]], axis=1)[~from_a]
    out = [tri_b] if a == 1 else [tri_a, tri_b]
    if b == 1:
        out = [tri_a]
    return np.concatenate(out)


def _orient_convex(V, F, centre):
    """``F`` with every face turned to face away from ``centre`` (a point inside a convex shape)."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    c = V[F].mean(axis=1) - np.asarray(centre, dtype=np.float64)
    flip = np.einsum("ij,ij->i", n, c) < 0
    F = F.copy()
    F[flip] = F[flip][:, [0, 2, 1]]
    return F


def _hemisphere(radius, axis, u, v, rings):
    """A closed hemisphere (dome and flat cap) of a sphere of ``radius`` about the origin on the side of ``axis``:
    ``rings`` rings of latitude, the cap's rings at the dome's spacing, the rim on the plane through the origin."""
    ring_ids, pts = [], []
    count = 0

    def ring(points):
        nonlocal count
        ring_ids.append(np.arange(count, count + len(points)))
        pts.append(points)
        count += len(points)

    def circle(m, r, h):
        phi = 2.0 * np.pi * np.arange(m) / m
        return (h * axis[None, :] + r * (np.cos(phi)[:, None] * u[None, :] + np.sin(phi)[:, None] * v[None, :]))

    theta = 0.5 * np.pi * np.arange(rings + 1) / rings
    for k, t in enumerate(theta):                       # the dome: the pole, then rings down to the rim
        m = 1 if k == 0 else max(6, int(round(4 * rings * np.sin(t))))
        ring(circle(m, radius * np.sin(t), radius * np.cos(t)))
    dome = list(ring_ids)
    n_c = max(1, int(round(2.0 * rings / np.pi)))
    cap = [dome[-1]]                                    # the cap shares the rim
    for j in range(n_c - 1, -1, -1):
        rho = radius * j / n_c
        m = 1 if j == 0 else max(6, int(round(4 * rings * rho / radius)))
        ring(circle(m, rho, 0.0))
        cap.append(ring_ids[-1])
    V = np.concatenate(pts)
    F = np.concatenate([_zipper(x, y) for x, y in zip(dome[:-1], dome[1:])] +
                       [_zipper(y, x) for x, y in zip(cap[1:], cap[:-1])])
    return V, _orient_convex(V, F, 0.375 * radius * axis)


def split_sphere(radius: float = 20.0, normal=(1.0, 0.0, 0.0), rings: int = 24):
    """A sphere of ``radius`` about the origin as two closed hemispheres, split by the plane through the origin
    normal to ``normal``: ``(vertices, faces, face_part)``, part 0 on the side of ``normal``, part 1 the other.
    Each hemisphere is a dome of ``rings`` rings of latitude and a flat cap; the two caps lie on each other with
    opposite orientations and the rims' vertices coincide (two closed parts: vertices are not shared between
    them). A mesh of parts (:class:`meshshade.parts.PartedMaterial`)."""
    _check_positive(radius=radius)
    rings = _check_count("rings", rings, 2)
    a = np.asarray(normal, dtype=np.float64)
    a = a / np.linalg.norm(a)
    u = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    V0, F0 = _hemisphere(float(radius), a, u, v, rings)
    V1, F1 = _hemisphere(float(radius), -a, u, -v, rings)
    V = np.concatenate([V0, V1])
    F = np.concatenate([F0, F1 + V0.shape[0]])
    part = np.concatenate([np.zeros(len(F0), np.int64), np.ones(len(F1), np.int64)])
    return V, F, part


def nested_spheres(radius: float = 20.0, inner_radius: float = 8.0, subdivisions: int = 5,
                   inner_subdivisions: int = 4):
    """An icosphere of ``radius`` with a closed icosphere of ``inner_radius`` inside it, both about the origin and
    outward oriented: ``(vertices, faces, face_part)``, part 0 the outer surface, part 1 the inner ball (a mesh of
    parts: the ball is a part nested in the outer one, :class:`meshshade.parts.PartedMaterial`)."""
    _check_positive(radius=radius, inner_radius=inner_radius)
    if not inner_radius < radius:
        raise ValueError(f"the inner radius must be below the outer, got {inner_radius!r} >= {radius!r}")
    V0, F0 = icosphere(radius, subdivisions)
    V1, F1 = icosphere(inner_radius, inner_subdivisions)
    part = np.concatenate([np.zeros(len(F0), np.int64), np.ones(len(F1), np.int64)])
    return np.concatenate([V0, V1]), np.concatenate([F0, F1 + V0.shape[0]]), part
