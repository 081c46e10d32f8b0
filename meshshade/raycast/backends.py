"""Backend choice of the ray-casting API: :func:`make_scene` builds an Embree scene or its numpy twin."""
from __future__ import annotations

from meshshade.raycast.embree import EmbreeScene
from meshshade.raycast.numpy_twin import NumpyScene

__all__ = ["make_scene"]


def make_scene(vertices, faces, backend: str = "embree") -> EmbreeScene | NumpyScene:
    """Build a ray-casting scene: ``backend`` is ``"embree"`` (default) or ``"numpy"`` (reference, tiny meshes).

    vertices : (n, 3) float64 mm; faces : (m, 3) int.
    """
    if backend == "embree":
        return EmbreeScene(vertices, faces)
    if backend == "numpy":
        return NumpyScene(vertices, faces)
    raise ValueError(f"unknown ray-casting backend {backend!r} (expected 'embree' or 'numpy')")
