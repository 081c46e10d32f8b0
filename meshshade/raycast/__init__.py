"""Ray casting: the only Embree users.

Modules: ``scene`` (the shared API: :class:`Hits`, ray offsets, the float64 brute force and hit reconstruction),
``embree`` (:class:`EmbreeScene`, the embreex adapter), ``numpy_twin`` (:class:`NumpyScene`, its pure-numpy
reference), ``backends`` (:func:`make_scene`), ``embree_direct`` (Embree 4 bound with ctypes so that numba
threads call ``rtcIntersect1``, for the Monte Carlo engine).
"""
from meshshade.raycast.backends import make_scene
from meshshade.raycast.embree import EmbreeScene
from meshshade.raycast.numpy_twin import NumpyScene
from meshshade.raycast.scene import OFFSET_ABS, OFFSET_REL, Hits

__all__ = ["make_scene", "EmbreeScene", "NumpyScene", "Hits", "OFFSET_REL", "OFFSET_ABS"]
