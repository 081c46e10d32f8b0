"""Embree called from numba threads: a ctypes binding of ``rtcIntersect1`` for the pooled Monte Carlo engine.

embreex's ``run`` holds the GIL, so one process gets at most one core of Embree (measured ~3-7 M rays/s), while
the near-surface walks of the benchmarks need a boundary test for ~35-40 % of their scattering events. Here the
Embree 4 library that ships inside the embreex wheel is bound with ctypes (``rtcNewDevice`` ... ``rtcIntersect1``)
and ``rtcIntersect1`` is called from a ``prange`` loop (no GIL; the walk loop
:func:`meshshade.montecarlo.fused_walk.walk_parallel` calls :func:`trace`), so every core traces its own photons'
rays.

Conventions are those of :class:`meshshade.raycast.embree.EmbreeScene`: the scene is built in float32 relative to
the bounding-box centre, in Embree's robust (watertight) mode; Embree only *selects* the face, the distance and the
barycentrics are recomputed in float64 on that face (:func:`meshshade.montecarlo.loops.surface_event`). Each ray
is limited to ``tfar = free path + margin`` (margin ``TFAR_MARGIN_REL * scale``, far above the ~1e-7 scale float32
error), which lets Embree stop early; a miss within tfar is an interior event.

RTCRayHit layout (Embree 4, rtcore_ray.h, 16-byte aligned): ray org_x..z, tnear, dir_x..z, time, tfar, mask, id,
flags (12 x 4 bytes), then hit Ng_x..z, u, v, primID (word 17), geomID (word 18), instID...; 32 words are
reserved per ray (the hit part is 32 or 48 bytes depending on the build).
"""
from __future__ import annotations

import ctypes
import glob
import os

import numpy as np
from numba import njit, prange

__all__ = ["TFAR_MARGIN_REL", "DirectEmbreeScene", "rayhit_buffer", "trace", "occlusion_rows", "distance_rows"]

#: tfar margin of a boundary test, relative to the scene's scale (bbox diagonal): ``tfar = free path + margin``
TFAR_MARGIN_REL = 1e-5
_NUMBA_OPTS = dict(cache=True, error_model="numpy")
_INVALID = np.uint32(0xFFFFFFFF)
_SCENE_FLAG_ROBUST = 1 << 2
_GEOMETRY_TRIANGLE, _BUFFER_INDEX, _BUFFER_VERTEX = 0, 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_PROPERTY_VERSION_MAJOR = 1
_LIB = None
_DEVICE = None


def _library():
    """The Embree 4 shared library bundled with embreex (None if it cannot be found)."""
    global _LIB
    if _LIB is None:
        import embreex  # lazy: loads Embree; needed only to find the library in its wheel

        root = os.path.dirname(os.path.dirname(embreex.__file__))
        pats = ["embreex.libs/libembree4*.so*", "embreex/.dylibs/libembree4*.dylib", "embreex/embree4*.dll",
                "embreex.libs/embree4*.dll", "embreex/libembree4*"]
        found = [p for pat in pats for p in sorted(glob.glob(os.path.join(root, pat)))]
        if not found:
            return None
        lib = ctypes.CDLL(found[0])
        vp, u32, sz, i32 = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t, ctypes.c_int
        for name, res, args in (("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcNewScene", vp, [vp]),
                                ("rtcSetSceneFlags", None, [vp, i32]), ("rtcNewGeometry", vp, [vp, i32]),
                                ("rtcSetNewGeometryBuffer", vp, [vp, i32, u32, i32, sz, sz]),
                                ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", u32, [vp, vp]),
                                ("rtcReleaseGeometry", None, [vp]), ("rtcCommitScene", None, [vp]),
                                ("rtcReleaseScene", None, [vp]), ("rtcGetDeviceError", i32, [vp]),
                                ("rtcGetDeviceProperty", ctypes.c_ssize_t, [vp, i32])):
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
        _LIB = lib
    return _LIB


class DirectEmbreeScene:
    """A robust Embree 4 triangle scene (float32, relative to ``center``) whose rtcIntersect1 numba can call.

    Raises RuntimeError if the library cannot be loaded or the build fails (the caller then uses embreex).
    """

    def __init__(self, vertices, faces, center):
        global _DEVICE
        lib = _library()
        if lib is None:
            raise RuntimeError("libembree4 not found next to embreex")
        if _DEVICE is None:
            _DEVICE = lib.rtcNewDevice(None)
        major = lib.rtcGetDeviceProperty(_DEVICE, _PROPERTY_VERSION_MAJOR)
        if major != 4:  # the RTCRayHit layout and rtcIntersect1's signature below are Embree 4's
            raise RuntimeError(f"Embree {major} found next to embreex, the direct binding needs Embree 4")
        self._lib = lib
        V = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64) - center, dtype=np.float32)
        F = np.ascontiguousarray(faces, dtype=np.uint32)
        self.scene = lib.rtcNewScene(_DEVICE)
        lib.rtcSetSceneFlags(self.scene, _SCENE_FLAG_ROBUST)
        geo = lib.rtcNewGeometry(_DEVICE, _GEOMETRY_TRIANGLE)
        vb = lib.rtcSetNewGeometryBuffer(geo, _BUFFER_VERTEX, 0, _FORMAT_FLOAT3, 12, V.shape[0])
        ib = lib.rtcSetNewGeometryBuffer(geo, _BUFFER_INDEX, 0, _FORMAT_UINT3, 12, F.shape[0])
        if not vb or not ib:
            raise RuntimeError("Embree could not allocate the geometry buffers")
        ctypes.memmove(vb, V.ctypes.data, V.nbytes)   # V and F stay referenced until the copies are done
        ctypes.memmove(ib, F.ctypes.data, F.nbytes)
        lib.rtcCommitGeometry(geo)
        lib.rtcAttachGeometry(self.scene, geo)
        lib.rtcReleaseGeometry(geo)
        lib.rtcCommitScene(self.scene)
        err = lib.rtcGetDeviceError(_DEVICE)
        if err != 0:
            raise RuntimeError(f"Embree error {err} while building the scene")
        proto = ctypes.CFUNCTYPE(None, ctypes.c_uint64, ctypes.c_uint64, ctypes.c_uint64)
        self.intersect = proto(ctypes.cast(lib.rtcIntersect1, ctypes.c_void_p).value)
        self.handle = np.uint64(self.scene)

    def close(self):
        if self.scene:
            self._lib.rtcReleaseScene(self.scene)
            self.scene = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def first_hit_faces(self, o32, d32):
        """(k,) int64 first-hit faces (-1 miss) of float32 rays relative to the centre (tests, not the walk)."""
        return _cast(self.intersect, self.handle, np.ascontiguousarray(o32, dtype=np.float32),
                     np.ascontiguousarray(d32, dtype=np.float32))


@njit(inline="always", **_NUMBA_OPTS)
def rayhit_buffer():
    """A 16-byte aligned 32-word RTCRayHit buffer: (float32 view (32,), uint32 view (32,)) of the same memory."""
    raw = np.empty(40, dtype=np.float32)
    off = ((16 - raw.ctypes.data % 16) % 16) // 4
    rh = raw[off:off + 32]
    return rh, rh.view(np.uint32)


@njit(inline="always", **_NUMBA_OPTS)
def trace(intersect, scene, rh, rhi, ox, oy, oz, dx, dy, dz, tfar):
    """First-hit face (int64, -1: none within ``tfar``) of one float32 ray relative to the scene's centre (mm).

    intersect, scene : ``DirectEmbreeScene.intersect`` and ``.handle``; rh, rhi : a :func:`rayhit_buffer`.
    """
    rh[0], rh[1], rh[2], rh[3] = ox, oy, oz, 0.0
    rh[4], rh[5], rh[6], rh[7] = dx, dy, dz, 0.0
    rh[8] = tfar
    rhi[9], rhi[10], rhi[11] = _INVALID, 0, 0
    rhi[17], rhi[18] = _INVALID, _INVALID
    intersect(scene, rh.ctypes.data, 0)
    return -1 if rhi[18] == _INVALID else np.int64(rhi[17])


@njit(parallel=True, nogil=True, **_NUMBA_OPTS)
def _cast(intersect, scene, o32, d32):
    """(k,) int64 first-hit faces of float32 rays (k, 3) relative to the centre, in parallel."""
    out = np.empty(o32.shape[0], dtype=np.int64)
    for j in prange(o32.shape[0]):
        rh, rhi = rayhit_buffer()
        out[j] = trace(intersect, scene, rh, rhi, o32[j, 0], o32[j, 1], o32[j, 2], d32[j, 0], d32[j, 1],
                        d32[j, 2], np.float32(1e37))
    return out


@njit(nogil=True, **_NUMBA_OPTS)
def occlusion_rows(intersect, scene, o32, d32, tfar, out, a, b):
    """out[j] = whether the float32 ray j (relative to the scene's centre) meets the mesh within tfar[j], for rays
    a .. b - 1, from this thread (blocks of rays run on the worker threads)."""
    rh, rhi = rayhit_buffer()
    for j in range(a, b):
        out[j] = trace(intersect, scene, rh, rhi, o32[j, 0], o32[j, 1], o32[j, 2], d32[j, 0], d32[j, 1], d32[j, 2],
                       tfar[j]) >= 0


@njit(nogil=True, **_NUMBA_OPTS)
def distance_rows(intersect, scene, o32, d32, out, a, b):
    """out[j] = the distance (mm) along the float32 ray j (relative to the scene's centre, unit direction) to the
    first face it meets, inf where it meets none, for rays a .. b - 1, from this thread."""
    rh, rhi = rayhit_buffer()
    for j in range(a, b):
        f = trace(intersect, scene, rh, rhi, o32[j, 0], o32[j, 1], o32[j, 2], d32[j, 0], d32[j, 1], d32[j, 2],
                  np.float32(1e37))
        out[j] = np.float64(rh[8]) if f >= 0 else np.inf
