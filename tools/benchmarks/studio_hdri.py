#!/usr/bin/env python
"""A studio-like HDRI made by code (issue 43): a bright window (a soft box) up front, a dimmer fill opposite it, a
soft sky dome and a dim floor, as an equirectangular EXR for ``--light env:FILE.exr`` (tests and benchmarks).

Directions are those of meshshade's maps with ``up = y`` (meshshade.light.environment: the image's centre column
looks along +X, u = 0.75 along +Z, the top row is +Y). Radiance per unit strength, W/(mm^2 sr):

* window: 40 x 30 degrees (azimuth x elevation) centred at azimuth 30 degrees from +Z towards +X, elevation 35
  degrees, radiance 20, its edges softened over 3 degrees (a smoothstep, so the window is not a hard pixel edge);
* fill: 60 x 40 degrees at azimuth 180 + 40 degrees, elevation 15, radiance 2.5, edges softened over 10 degrees;
* dome: the upper hemisphere, 0.6 at the horizon rising to 1.0 at the zenith (as sin(elevation));
* floor: the lower hemisphere, 0.15 at the horizon falling to 0.1 at the nadir.

The map is grey (R = G = B), so meshshade uses it as it is (its lights are white). Each pixel holds the value at
its centre direction. ``studio_hdri(height)`` returns the (H, 2H, 3) float64 array; run as a script it writes the
EXR through meshshade.io (OpenImageIO)::

    python tools/benchmarks/studio_hdri.py studio.exr [--height 256]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from meshshade.io import write_exr  # noqa: E402
from meshshade.light.environment import map_frame  # noqa: E402

WINDOW = {"azimuth": 30.0, "elevation": 35.0, "width": 40.0, "height": 30.0, "radiance": 20.0, "soft": 3.0}
FILL = {"azimuth": 220.0, "elevation": 15.0, "width": 60.0, "height": 40.0, "radiance": 2.5, "soft": 10.0}
DOME = (0.6, 1.0)      # horizon, zenith
FLOOR = (0.15, 0.1)    # horizon, nadir


def pixel_directions(height: int) -> np.ndarray:
    """(H, 2H, 3) unit directions (mesh frame, up = y) at the pixels' centres."""
    H, W = int(height), 2 * int(height)
    s = (np.arange(H) + 0.5) / H                       # row from the top, in [0, 1]
    u = (np.arange(W) + 0.5) / W
    theta = np.pi * s[:, None]
    phi = np.pi - 2.0 * np.pi * u[None, :]
    t = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)),
                 axis=-1)
    return t @ map_frame("y", 0.0)                     # M^T t


def _smooth(x, soft):
    """1 inside (x <= 0), 0 beyond ``soft`` degrees, smoothstep between."""
    t = np.clip(1.0 - x / soft, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _box(az, el, box) -> np.ndarray:
    """A soft box's radiance at azimuth ``az`` and elevation ``el`` (degrees)."""
    daz = np.abs((az - box["azimuth"] + 180.0) % 360.0 - 180.0)
    dx = daz - box["width"] / 2
    dy = np.abs(el - box["elevation"]) - box["height"] / 2
    return box["radiance"] * _smooth(dx, box["soft"]) * _smooth(dy, box["soft"])


def studio_hdri(height: int = 256) -> np.ndarray:
    """(H, 2H, 3) float64 grey radiance per unit strength (module docstring)."""
    w = pixel_directions(height)
    el = np.degrees(np.arcsin(np.clip(w[..., 1], -1.0, 1.0)))
    az = np.degrees(np.arctan2(w[..., 0], w[..., 2]))          # 0 along +Z, 90 along +X
    up = w[..., 1] >= 0.0
    sky = np.where(up, DOME[0] + (DOME[1] - DOME[0]) * np.clip(w[..., 1], 0.0, 1.0),
                   FLOOR[0] + (FLOOR[1] - FLOOR[0]) * np.clip(-w[..., 1], 0.0, 1.0))
    L = sky + _box(az, el, WINDOW) + _box(az, el, FILL)
    return np.repeat(L[..., None], 3, axis=2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="the EXR to write")
    ap.add_argument("--height", type=int, default=256, help="rows of the map (its width is twice; default 256)")
    args = ap.parse_args(argv)
    write_exr(args.out, studio_hdri(args.height))
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
