"""The presets as a table (text, CSV) and as swatches (a matplotlib figure): ``meshshade materials``.

Pure: rows in (:func:`meshshade.materials.preset_table`), text or a figure out; :mod:`meshshade.io` writes them.
A swatch is the colour of a flat half-space of the material under white light: the planar dipole's total diffuse
reflectance R_d per channel (linear), sRGB-encoded.
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.output.tonemap import srgb_encode

__all__ = ["materials_text", "materials_csv", "swatch_colours", "swatches_figure"]

_COLUMNS = ("sigma_s_prime", "sigma_a", "albedo_prime", "z_r", "diffusion_length", "R_d")
_HEAD = {"sigma_s_prime": "sigma_s' [1/mm]", "sigma_a": "sigma_a [1/mm]", "albedo_prime": "albedo'",
         "z_r": "z_r [mm]", "diffusion_length": "1/sigma_tr [mm]", "R_d": "R_d"}


def _rgb(v) -> str:
    return "/".join(f"{x:.3g}" if math.isfinite(x) else "inf" for x in v)


def materials_text(rows) -> str:
    """A fixed-width table: name, source, eta and the r/g/b values of every column."""
    table = [["name", "source", "eta", *(_HEAD[c] for c in _COLUMNS)]]
    table += [[r["name"], r["source"], f"{r['eta']:g}", *(_rgb(r[c]) for c in _COLUMNS)] for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in table) + "\n"


def materials_csv(rows) -> str:
    """CSV: name, source, eta, then ``<column>_<r|g|b>`` for every column (1/mm, mm, dimensionless)."""
    head = ["name", "source", "eta"] + [f"{c}_{ch}" for c in _COLUMNS for ch in "rgb"]
    lines = [",".join(head)]
    for r in rows:
        vals = [f"{x!r}" for c in _COLUMNS for x in r[c]]
        lines.append(",".join([r["name"], r["source"], repr(r["eta"]), *vals]))
    return "\n".join(lines) + "\n"


def swatch_colours(rows) -> np.ndarray:
    """(k, 3) sRGB-encoded colours in [0, 1]: R_d per channel."""
    return srgb_encode(np.array([r["R_d"] for r in rows], dtype=np.float64))


def swatches_figure(rows, *, columns: int = 6):
    """A grid of swatches with the preset names and their sources."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = swatch_colours(rows)
    n = len(rows)
    nrows = -(-n // columns)
    fig, axes = plt.subplots(nrows, columns, figsize=(2.0 * columns, 1.5 * nrows), squeeze=False)
    for i, ax in enumerate(axes.ravel()):
        ax.set_axis_off()
        if i >= n:
            continue
        ax.add_patch(matplotlib.patches.Rectangle((0, 0.3), 1, 0.7, facecolor=colours[i], edgecolor="0.6", lw=0.5))
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.text(0.5, 0.15, rows[i]["name"], ha="center", va="center", fontsize=8)
        ax.text(0.5, 0.02, rows[i]["source"].replace(" et al. ", " "), ha="center", va="center", fontsize=6,
                color="0.4")
    fig.suptitle("meshshade presets: a flat half-space under white light (planar dipole R_d, sRGB)", fontsize=10)
    fig.tight_layout()
    return fig
