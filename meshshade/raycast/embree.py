"""The Embree backend of the ray-casting API: :class:`EmbreeScene` (embreex; float64 in and out, float32 inside)."""
from __future__ import annotations

import numpy as np

from meshshade.pacing import run_in_blocks
from meshshade.raycast.embree_direct import DirectEmbreeScene, distance_rows, occlusion_rows
from meshshade.raycast.scene import _SceneBase, _as_rays

__all__ = ["EmbreeScene"]

_FLOAT32_TFAR_MAX = 1e37  # embreex's own "infinite" tfar


class EmbreeScene(_SceneBase):
    """Embree (embreex) triangle scene; float64 in and out, float32 only inside.

    Parameters
    ----------
    vertices : (n, 3) float64, mm
    faces : (m, 3) int

    Notes
    -----
    On embreex (4.x) this adapter handles:

    * ``EmbreeScene.run`` takes float32 (n, 3) arrays only (float64 raises "Buffer dtype mismatch");
    * ``tnear`` is always 0 and ``tfar`` defaults to 1e37; a ``dists`` array is used *and overwritten* as tfar;
    * ``output=1`` with ``query='OCCLUDED'`` returns uninitialised arrays, so occlusion uses the plain query,
      which returns the geomID (0) for occluded rays and -1 otherwise;
    * ``t`` is in units of the direction's length; directions are normalised before the cast;
    * scenes are built with ``robust=True`` (Embree's watertight mode: no cracks along shared edges). Rays aimed
      *exactly* at a vertex can still slip through (a known Embree limitation, RenderKit/embree issues 174 and
      188; about 0.1-0.2 % of such rays in the tests, none through edges): use ``first_hit(..., exact=True)``
      for the few rays whose answer must be exact (beams).

    Occlusion (shadow rays, the many rays of a bake) goes through Embree called from the worker threads
    (:attr:`direct`, :class:`~meshshade.raycast.embree_direct.DirectEmbreeScene`: embreex's ``run`` holds the
    interpreter, so it uses one core) where the library beside embreex loads, else through embreex. Each of the two
    is built when first needed, so a bake that only casts shadow rays builds one.
    """

    backend = "embree"

    def __init__(self, vertices, faces):
        super().__init__(vertices, faces)
        try:
            # lazy: loading embreex loads the Embree library, which a NumpyScene-only user never needs
            import embreex  # noqa: F401
        except ImportError as exc:  # pragma: no cover - embreex is a required dependency
            raise ImportError("meshshade needs embreex for EmbreeScene; use NumpyScene or install embreex") from exc
        self._embreex = None
        self._direct = False          # not tried yet
        self._radius = 0.5 * self.scale

    @property
    def _scene(self):
        """embreex's scene (built at the first call that needs it)."""
        if self._embreex is None:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh

            self._embreex = rtcore_scene.EmbreeScene(robust=True)
            local = np.ascontiguousarray(self.vertices - self.center, dtype=np.float32)
            self._mesh = TriangleMesh(self._embreex, local, np.ascontiguousarray(self.faces, dtype=np.int32))
        return self._embreex

    @property
    def direct(self):
        """The scene as a :class:`~meshshade.raycast.embree_direct.DirectEmbreeScene` (Embree from the worker
        threads), built at the first call; None where the Embree 4 library beside embreex does not load."""
        if self._direct is False:
            try:
                self._direct = DirectEmbreeScene(self.vertices, self.faces, self.center)
            except (RuntimeError, OSError):
                self._direct = None
        return self._direct

    def _local_rays(self, o, d):
        """Float64 origins advanced to just before the bounding sphere, relative to the centre.

        Returns (keep, origins32, directions32, t0): ``keep`` marks rays that can reach the bounding sphere;
        the rest cannot hit the mesh. ``t0`` is the float64 distance the origin was advanced.
        """
        rel = o - self.center
        b = np.einsum("ij,ij->i", rel, d)
        c = np.einsum("ij,ij->i", rel, rel) - (1.01 * self._radius) ** 2
        disc = b * b - c
        # outside the (slightly enlarged) sphere and not reaching it -> cannot hit
        keep = (c <= 0.0) | ((disc >= 0.0) & (b <= 0.0))
        t0 = np.where(c > 0.0, np.clip(-b - np.sqrt(np.clip(disc, 0.0, None)), 0.0, None), 0.0)
        local = rel + t0[:, None] * d
        return (keep, np.ascontiguousarray(local[keep], dtype=np.float32),
                np.ascontiguousarray(d[keep], dtype=np.float32), t0)

    def first_hit_faces_local(self, o32, d32, tfar):
        """(k,) int32 face of the first hit within ``tfar`` (-1: none) of float32 rays given relative to
        ``self.center`` (one batched call, no float64 round trip; ``tfar`` (k,) float32 is overwritten)."""
        return self._scene.run(o32, d32, dists=tfar)

    def _first_hit_faces(self, o, d):
        face = np.full(o.shape[0], -1, dtype=np.int64)
        keep, o32, d32, _ = self._local_rays(o, d)
        if o32.shape[0]:
            out = self._scene.run(o32, d32, query="INTERSECT", output=1)
            face[keep] = out["primID"].astype(np.int64)
        face[face < 0] = -1
        return face

    def first_hit_distances(self, origins, directions):
        o, d = _as_rays(origins, directions)
        d = d / np.linalg.norm(d, axis=1)[:, None]
        out = np.full(o.shape[0], np.inf)
        keep, o32, d32, t0 = self._local_rays(o, d)
        if not o32.shape[0]:
            return out
        direct = self.direct
        sub = np.empty(o32.shape[0])
        if direct is not None:
            run_in_blocks(lambda a, b: distance_rows(direct.intersect, direct.handle, o32, d32, sub, a, b),
                          o32.shape[0], min_block=8192)
        else:
            tfar = np.full(o32.shape[0], 1e37, dtype=np.float32)
            face = self._scene.run(o32, d32, dists=tfar)
            sub = np.where(face >= 0, tfar.astype(np.float64), np.inf)
        out[keep] = sub + t0[keep]
        return out

    def _occluded(self, o, d, t_max):
        result = np.zeros(o.shape[0], dtype=bool)
        keep, o32, d32, t0 = self._local_rays(o, d)
        tfar = (t_max - t0)[keep]
        live = tfar > 0.0
        if np.any(live):
            dists = np.ascontiguousarray(np.minimum(tfar[live], _FLOAT32_TFAR_MAX), dtype=np.float32)
            o_live, d_live = np.ascontiguousarray(o32[live]), np.ascontiguousarray(d32[live])
            direct = self.direct
            if direct is not None:
                hit = np.zeros(o_live.shape[0], dtype=np.bool_)
                run_in_blocks(lambda a, b: occlusion_rows(direct.intersect, direct.handle, o_live, d_live, dists,
                                                          hit, a, b), o_live.shape[0], min_block=8192)
            else:
                hit = self._scene.run(o_live, d_live, dists=dists, query="OCCLUDED") >= 0
            sub = np.zeros(keep.sum(), dtype=bool)
            sub[live] = hit
            result[keep] = sub
        return result
