"""The shared ray-casting API: first hits (:class:`Hits`), occlusion, scale-aware ray offsets (:class:`_SceneBase`).

Two backends implement it (trimesh/ray style), built with :func:`meshshade.raycast.backends.make_scene`:

* :class:`meshshade.raycast.embree.EmbreeScene`, the only embreex user in meshshade and the only place that
  casts to float32;
* :class:`meshshade.raycast.numpy_twin.NumpyScene`, a pure-numpy float64 twin (Moller & Trumbore 1997), chunked
  over rays x triangles, used by the tests as the reference and fine for tiny meshes.

Both report hits in float64 computed from the float64 triangle: Embree only *selects* the triangle, then the
distance ``t``, the barycentrics ``(u, v)`` and the hit point are recomputed in float64 (see
:meth:`_SceneBase._hits_on_faces`), so no float32 value leaks into the physics.

Conventions
-----------
* Directions need not be unit length; they are normalised in float64, and ``t`` is the distance in mm along
  the unit direction.
* Barycentrics follow Embree: ``(u, v)`` weight vertices 1 and 2 of the face, ``1 - u - v`` vertex 0, so the
  hit point is ``(1-u-v) V[f,0] + u V[f,1] + v V[f,2]``.
* Rays start at ``t = 0`` exactly (Embree's ``tnear`` is fixed at 0 by embreex); a ray leaving a surface must
  first be moved off it with :meth:`offset_origins`.
* Faces are two-sided (no back-face culling).

Float32 precision (why the offsets below are enough)
----------------------------------------------------
Before casting to float32 the scene is translated to its bounding-box centre ``c``, and every ray origin outside
the bounding sphere (centre ``c``, radius half the bbox diagonal) is first advanced in float64 to just before
that sphere (radius x 1.01). Hence every float32 coordinate Embree sees is at most ~0.51 x scale in magnitude,
its rounding error is below ``2**-24 * 0.51 * scale ~ 3e-8 scale``, and this holds wherever the mesh sits in
space and however far the light is. :meth:`offset_origins` moves points by

    eps(p) = 1e-6 * (scale + |p - c|) + 1e-12 * |p|        [mm]

* ``1e-6 * scale`` is about 30x that float32 error (and 1e-10 scale would be plenty for the float64 twin);
* ``1e-6 * |p - c|`` makes it grow for points away from the mesh (the rounding of an origin relative to c);
* ``1e-12 * |p|`` covers the float64 rounding of the world coordinates themselves (~1e4 ulps): it only matters
  for a mesh many orders of magnitude smaller than its distance from the world origin (1e-3 mm at 1e3 mm
  away: 1e-9 mm, comparable to the first term).

Unlike trimesh's ``tol.merge``-style absolute epsilons, nothing here depends on the unit. At 1e-6 of the mesh size
the offset is far below any physical length in the shading (a mean free path, an edge length).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshshade.errors import MeshValidationError

#: Relative ray offset: offset_origins moves a point by OFFSET_REL * (scale + |p - centre|) + OFFSET_ABS * |p| mm.
OFFSET_REL = 1e-6

#: Absolute float64 term of the offset: OFFSET_ABS * |p| mm covers ~1e4 ulps of the point's own coordinates.
OFFSET_ABS = 1e-12

_EDGE_WIDEN = 1e-12       # brute force: barycentric slack so rays through shared edges/vertices cannot slip through


@dataclass(frozen=True)
class Hits:
    """First hits of a batch of ``n`` rays (float64 throughout).

    Attributes
    ----------
    face : (n,) int64
        Index of the hit face, -1 for a miss.
    t : (n,) float64
        Distance in mm from the ray origin along the unit direction; ``inf`` for a miss.
    uv : (n, 2) float64
        Barycentrics ``(u, v)`` of vertices 1 and 2 of the hit face (Embree convention), clipped onto the
        triangle; NaN for a miss.
    points : (n, 3) float64
        Hit points in mm, ``(1-u-v) V0 + u V1 + v V2`` of the hit face; NaN for a miss.
    """

    face: np.ndarray
    t: np.ndarray
    uv: np.ndarray
    points: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """(n,) bool, True where the ray hit the mesh."""
        return self.face >= 0

    @property
    def bary(self) -> np.ndarray:
        """(n, 3) float64 barycentric weights of vertices 0, 1, 2 of the hit face (NaN for misses)."""
        u, v = self.uv[:, 0], self.uv[:, 1]
        return np.stack([1.0 - u - v, u, v], axis=1)

    def __len__(self) -> int:
        return int(self.face.shape[0])

    def __repr__(self) -> str:
        return f"Hits(n={len(self)}, hit={int(np.count_nonzero(self.hit))})"


def _as_mesh_arrays(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    V = np.array(vertices, dtype=np.float64, copy=True)
    F = np.array(faces, copy=True)
    if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] == 0:
        raise MeshValidationError(f"vertices must be a non-empty (n, 3) array, got shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or F.shape[0] == 0:
        raise MeshValidationError(f"faces must be a non-empty (m, 3) array, got shape {F.shape}")
    if not np.issubdtype(F.dtype, np.integer):
        raise MeshValidationError(f"faces must be integer indices, got dtype {F.dtype}")
    F = F.astype(np.int64)
    if F.min() < 0 or F.max() >= V.shape[0]:
        raise MeshValidationError(f"face indices must lie in [0, {V.shape[0] - 1}], got [{F.min()}, {F.max()}]")
    if not np.all(np.isfinite(V)):
        raise MeshValidationError("vertices contain non-finite coordinates")
    V.setflags(write=False)
    F.setflags(write=False)
    return V, F


def _as_rays(origins, directions) -> tuple[np.ndarray, np.ndarray]:
    """Broadcast to (n, 3) float64 origins and unit directions; zero or non-finite directions raise ValueError."""
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    if o.shape[-1:] != (3,) or d.shape[-1:] != (3,) or o.ndim > 2 or d.ndim > 2:
        raise ValueError(f"origins and directions must be (n, 3) or (3,), got {o.shape} and {d.shape}")
    o, d = np.broadcast_arrays(np.atleast_2d(o), np.atleast_2d(d))
    norm = np.linalg.norm(d, axis=1)
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(norm)) and np.all(norm > 0.0)):
        raise ValueError("ray origins must be finite and directions finite and non-zero")
    return np.ascontiguousarray(o), d / norm[:, None]


class _SceneBase:
    """Shared state and float64 geometry of both backends (subclasses implement the two backend hooks).

    vertices : (n, 3) float64 mm (copied, read-only); faces : (m, 3) int (copied as int64, read-only).
    """

    backend = "base"

    def __init__(self, vertices, faces):
        self.vertices, self.faces = _as_mesh_arrays(vertices, faces)
        self.chunk = 1 << 18  # ray-triangle pairs held in memory at once by the float64 brute force
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        #: (3,) float64 bounding-box centre in mm (float32 coordinates are taken relative to it)
        self.center = 0.5 * (lo + hi)
        #: bounding-box diagonal in mm
        self.scale = float(np.linalg.norm(hi - lo))
        if not self.scale > 0.0:
            raise MeshValidationError("mesh has zero extent (all vertices coincide)")
        tri = self.vertices[self.faces]
        self._v0 = tri[:, 0]
        self._e1 = tri[:, 1] - tri[:, 0]
        self._e2 = tri[:, 2] - tri[:, 0]

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(vertices={len(self.vertices)}, faces={len(self.faces)}, "
                f"scale={self.scale:.6g} mm)")

    # --- offsets -------------------------------------------------------------------------------------------
    def offset_epsilon(self, points) -> np.ndarray:
        """Offset distance in mm for each point: ``OFFSET_REL * (scale + |p - center|) + OFFSET_ABS * |p|``.

        points : (n, 3) float64 mm  ->  (n,) float64 mm. See the module docstring for the justification.
        """
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return (OFFSET_REL * (self.scale + np.linalg.norm(p - self.center, axis=1))
                + OFFSET_ABS * np.linalg.norm(p, axis=1))

    def offset_origins(self, points, normals, sign=1.0) -> np.ndarray:
        """Move surface points off the surface along their normals so that rays leaving them miss that surface.

        Parameters
        ----------
        points : (n, 3) float64, mm
        normals : (n, 3) or (3,) float64, any length (normalised here; a zero normal gives no offset)
        sign : float or (n,) float
            +1 to move along the normal (rays leaving on the normal's side), -1 against it.

        Returns
        -------
        (n, 3) float64: ``points + sign * offset_epsilon(points) * normals / |normals|``.
        """
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        n = np.broadcast_to(np.asarray(normals, dtype=np.float64), p.shape)
        length = np.linalg.norm(n, axis=1)
        unit = np.divide(n, length[:, None], out=np.zeros_like(p), where=length[:, None] > 0.0)
        s = np.sign(np.broadcast_to(np.asarray(sign, dtype=np.float64), p.shape[:1]))
        return p + (s * self.offset_epsilon(p))[:, None] * unit

    # --- queries ---------------------------------------------------------------------------------------------
    def first_hit(self, origins, directions, *, exact: bool = False) -> Hits:
        """Nearest intersection (t > 0) of each ray with the mesh.

        origins : (n, 3) or (3,) float64 mm; directions : (n, 3) or (3,) float64, non-zero (broadcast together).
        exact : select the faces with the float64 brute force (O(n x faces)) whatever the backend. Meant for a
            handful of rays whose answer must not depend on float32, e.g. a beam: Embree's robust mode can let a
            ray aimed exactly at a vertex slip through (RenderKit/embree issues 174, 181, 188; measured here at
            ~0.1-0.2 % of rays aimed exactly at non-silhouette vertices, never through edges).
        Returns :class:`Hits` with n entries.
        """
        o, d = _as_rays(origins, directions)
        face = self._brute_first_hit_faces(o, d) if exact else self._first_hit_faces(o, d)
        return self._hits_on_faces(o, d, face)

    def first_hit_distances(self, origins, directions) -> np.ndarray:
        """(n,) float64 mm: the distance along each ray (unit ``directions``) to the first face it meets, inf where
        it meets none. The Embree scene casts them on the worker threads in float32 (about 1e-6 of the scene's
        size); here the float64 :meth:`first_hit`."""
        hits = self.first_hit(origins, directions)
        return np.where(hits.hit, hits.t, np.inf)

    def occluded(self, origins, directions, t_max=np.inf) -> np.ndarray:
        """Whether each ray hits the mesh at a distance ``0 < t < t_max`` (mm along the unit direction).

        origins, directions : as in :meth:`first_hit`; t_max : float or (n,) float64 mm (inf allowed).
        Returns (n,) bool.
        """
        o, d = _as_rays(origins, directions)
        t_max = np.broadcast_to(np.asarray(t_max, dtype=np.float64), o.shape[:1])
        if np.any(np.isnan(t_max)):
            raise ValueError("t_max must not be NaN")
        return self._occluded(o, d, t_max)

    # --- backend hooks -------------------------------------------------------------------------------------
    def _first_hit_faces(self, o, d) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _occluded(self, o, d, t_max) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    # --- float64 brute force (NumpyScene, and EmbreeScene.first_hit(..., exact=True)) ----------------------
    def _pair_t(self, o, d, fs):
        """(r, k) float64 distances of rays (o, d) to faces slice ``fs``; inf where there is no hit with t > 0."""
        e1, e2, v0 = self._e1[fs].T, self._e2[fs].T, self._v0[fs].T          # (3, k) each
        ox, oy, oz = (o[:, i, None] for i in range(3))                       # (r, 1) each
        dx, dy, dz = (d[:, i, None] for i in range(3))
        # p = d x e2, det = e1 . p
        px, py, pz = dy * e2[2] - dz * e2[1], dz * e2[0] - dx * e2[2], dx * e2[1] - dy * e2[0]
        det = e1[0] * px + e1[1] * py + e1[2] * pz
        sx, sy, sz = ox - v0[0], oy - v0[1], oz - v0[2]
        # q = s x e1
        qx, qy, qz = sy * e1[2] - sz * e1[1], sz * e1[0] - sx * e1[2], sx * e1[1] - sy * e1[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            u = (sx * px + sy * py + sz * pz) * inv
            v = (dx * qx + dy * qy + dz * qz) * inv
            t = (e2[0] * qx + e2[1] * qy + e2[2] * qz) * inv
            w = _EDGE_WIDEN
            ok = (u >= -w) & (v >= -w) & (u + v <= 1.0 + w) & (t > 0.0) & np.isfinite(t)
        return np.where(ok, t, np.inf)

    def _chunks(self, n):
        m = self.faces.shape[0]
        fstep = max(1, min(m, self.chunk))
        rstep = max(1, self.chunk // fstep)
        for r0 in range(0, n, rstep):
            for f0 in range(0, m, fstep):
                yield slice(r0, min(n, r0 + rstep)), slice(f0, min(m, f0 + fstep))

    def _brute_first_hit_faces(self, o, d):
        n = o.shape[0]
        best_t = np.full(n, np.inf)
        best_f = np.full(n, -1, dtype=np.int64)
        for rs, fs in self._chunks(n):
            t = self._pair_t(o[rs], d[rs], fs)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(t.shape[0]), j]
            better = tj < best_t[rs]
            best_t[rs] = np.where(better, tj, best_t[rs])
            best_f[rs] = np.where(better, j + fs.start, best_f[rs])
        return best_f

    # --- float64 hit reconstruction ------------------------------------------------------------------------
    def _hits_on_faces(self, o, d, face) -> Hits:
        """Recompute t, (u, v) and the point in float64 on the selected faces (Moller-Trumbore on one triangle).

        ``t`` is the float64 distance to the face's plane. ``(u, v)`` is clipped onto the triangle (Embree may pick
        a neighbour of the exact face when the hit is within float32 rounding of a shared edge; then the
        unclipped value is off by ~1e-7) and the point is interpolated from the clipped barycentrics, so it
        always lies on the mesh. A ray (numerically) parallel to the selected face keeps the nearest point.
        """
        n = o.shape[0]
        face = np.asarray(face, dtype=np.int64)
        t = np.full(n, np.inf)
        uv = np.full((n, 2), np.nan)
        points = np.full((n, 3), np.nan)
        idx = np.flatnonzero(face >= 0)
        if idx.size:
            f = face[idx]
            oi, di = o[idx], d[idx]
            e1, e2, v0 = self._e1[f], self._e2[f], self._v0[f]
            p = np.cross(di, e2)
            det = np.einsum("ij,ij->i", e1, p)
            s = oi - v0
            q = np.cross(s, e1)
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = 1.0 / det
                u = np.einsum("ij,ij->i", s, p) * inv
                v = np.einsum("ij,ij->i", di, q) * inv
                tt = np.einsum("ij,ij->i", e2, q) * inv
            bad = ~(np.isfinite(u) & np.isfinite(v) & np.isfinite(tt))
            if np.any(bad):  # grazing ray in the plane of its face: use the closest vertex
                u[bad], v[bad] = 0.0, 0.0
                tt[bad] = np.einsum("ij,ij->i", v0[bad] - oi[bad], di[bad])
            u = np.clip(u, 0.0, None)
            v = np.clip(v, 0.0, None)
            total = u + v
            over = total > 1.0
            u[over] /= total[over]
            v[over] /= total[over]
            t[idx] = tt
            uv[idx, 0], uv[idx, 1] = u, v
            points[idx] = v0 + u[:, None] * e1 + v[:, None] * e2
        return Hits(face=face, t=t, uv=uv, points=points)
