"""Quick looks for notebooks: a mesh coloured by its exitance, drawn with matplotlib (``BakeResult.plot``,
``MCResult.plot``).

A preview, not a render: faces are flat-coloured by the mean of their vertices' display colours and drawn as a
matplotlib 3-D polygon collection (painter's order, no lighting), and the display colour is a plain exposure that
puts the 99th percentile of the luminance at 1, sRGB-encoded. The pictures of ``meshshade render`` (ray traced,
Drago tone mapping: :mod:`meshshade.output.tonemap`) are what to show anyone else. Meshes above ``max_faces`` faces
are drawn from an even subset of their faces (matplotlib draws ~1e5 polygons in seconds), and the title says so.
"""
from __future__ import annotations

import numpy as np

from meshshade.errors import ParameterError

__all__ = ["preview_colours", "mesh_preview"]

#: Rec. 709 luminance weights (as meshshade.output.tonemap)
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def preview_colours(radiance) -> np.ndarray:
    """(n, 3) linear radiance -> (n, 3) sRGB-encoded display colours in [0, 1] (99th-percentile exposure)."""
    rad = np.nan_to_num(np.asarray(radiance, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0).clip(min=0.0)
    lum = rad @ _LUMA
    top = np.percentile(lum[lum > 0], 99.0) if np.any(lum > 0) else 1.0
    x = np.clip(rad / top, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def mesh_preview(vertices, faces, radiance, *, title: str = "", elev: float = 20.0, azim: float = -60.0,
                 ax=None, max_faces: int = 100_000):
    """A matplotlib figure of the mesh coloured by ``radiance`` (module docstring). ``vertices`` (n, 3) mm,
    ``faces`` (m, 3), ``radiance`` (n, 3); ``ax``: an existing 3-D axes to draw into. Returns the figure."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # lazy: plotting is needed only for figures

    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    R = np.asarray(radiance, dtype=np.float64)
    if R.shape != (V.shape[0], 3):
        raise ParameterError(f"radiance must be (n, 3) for the mesh's {V.shape[0]} vertices, got {R.shape}; "
                             "pass the mesh that was baked")
    colours = preview_colours(R)
    shown = F
    if F.shape[0] > max_faces:
        shown = F[np.linspace(0, F.shape[0] - 1, max_faces).astype(np.int64)]
        title = f"{title} ({max_faces} of {F.shape[0]} faces)".strip()
    if ax is None:
        import matplotlib.pyplot as plt   # the session's backend: inline in Jupyter, Agg without a display

        fig = plt.figure(figsize=(5.5, 5.0))
        ax = fig.add_subplot(projection="3d")
    fig = ax.figure
    ax.add_collection3d(Poly3DCollection(V[shown], facecolors=colours[shown].mean(axis=1), linewidths=0))
    lo, hi = V.min(axis=0), V.max(axis=0)
    c, h = (lo + hi) / 2, (hi - lo).max() / 2 or 1.0
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[1] - h, c[1] + h)
    ax.set_zlim(c[2] - h, c[2] + h)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    if title:
        ax.set_title(title, fontsize=9)
    return fig
