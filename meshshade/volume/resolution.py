"""How finely the volume transport resolves a material on a mesh (docs/physics.md §15.2): the lattice's spacing,
its grading with depth and the sources' sideways spread.

The finest spacing h0 is set by the material: the channel that decays fastest (kappa = sqrt(sigma_a / D),
d'Eon's D: the material's :class:`~meshshade.medium.Medium`) is resolved at kappa h0 = RESOLVED_KAPPA_H where its
decay length is within the near-field correction's reach, and at LONG_KAPPA_H (no finer than LONG_DECAY_MM) where
it is longer and the lattice carries its profile (:func:`material_spacing`; skin1's blue: h0 = 0.84 mm; marble's:
1 mm). On curved or small objects that is capped by the object (no coarser than its smallest extent over
MIN_CELLS_ACROSS),
and on large ones raised so that the finest level holds at most ``budget`` cubes (the bake stays affordable; the
cost it saves and the accuracy it costs are in docs/benchmarks.md). h0 is rounded to the world lattice of
spacings 2^(k/4) mm, so a small change of the mesh (a defect) does not move the whole lattice.

Deeper, level l (spacing 2^l h0) is used from the depth where every channel it does not resolve (kappa 2^l h0 >
GRADE_KAPPA_H) has fallen by exp(-DECAY_EFOLDS), and where the 2:1 grading allows; nothing is kept below
TRUNCATION_EFOLDS decay lengths of the channel that reaches farthest (a no-flux cut there changes the surface by
exp(-2 TRUNCATION_EFOLDS)). The sources' sideways spread is SPREAD_OVER_H0 h0.

The surface is at h0 except where the light or the shape calls for h0 / 2: around the edges of light where the
fastest channel is resolved more coarsely than kappa h0 = EDGE_KAPPA_H (``refine_radius``), and in the parts
thinner than ``thin_below`` (eq. (135); the thickness: :mod:`meshshade.volume.thickness`).
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.errors import MeshshadeError, NoVolumeError, ParameterError
from meshshade.volume.lattice import Grading

__all__ = ["VolumeResolution", "volume_resolution", "material_spacing", "DEFAULT_BUDGET", "RESOLVED_KAPPA_H"]

#: kappa h0 of the fastest-decaying channel (1-D cut-cell study: 1-2 % at 1, 5 % at 1.6) where its decay length
#: 1/kappa is short: within the near-field correction's reach, which then carries most of that channel's profile
RESOLVED_KAPPA_H = 1.0
#: where the fastest channel's decay length is long (1/kappa above LONG_DECAY_MM), the lattice itself carries its
#: profile beyond the correction's reach: kappa h0 = LONG_KAPPA_H there, but no finer than LONG_DECAY_MM (so
#: h0 = min(1/kappa, max(LONG_KAPPA_H/kappa, LONG_DECAY_MM)), continuous in kappa). Measured (issue 47): a pencil
#: beam on a 100 mm sphere of sigma_s' = 1, sigma_a = 0.01 /mm (1/kappa = 5.75 mm) against the exact series, mean
#: error over vertices above 1e-4 of the peak 0.46 at kappa h0 = 1, 0.050 at 0.5, 0.023 at 0.25. At 0.5 with the
#: edges of light at h0 / 2 (stop 53), marble's 2 mm lattice read 0.9-1.2x the 2e6-photon Monte Carlo's lit error on
#: spot50 and blub80 (its thin parts 14-19 % off, the sources' sideways spread h0 / 2 = 1 mm three of marble's
#: mean free paths: docs/benchmarks.md, stop 58); at 0.25 (marble 1 mm everywhere at the surface, no finer at the
#: edges of light: EDGE_KAPPA_H) 0.57-0.74x on spot50, blub80, the hand and the head at 1.2-2.8x the time.
LONG_KAPPA_H, LONG_DECAY_MM = 0.25, 1.0
#: the edges of light are refined (h0 / 2 within REFINE_EFOLDS decay lengths) only where the fastest channel is
#: resolved more coarsely than kappa h0 = EDGE_KAPPA_H: a lattice at kappa h0 <= 1/2 resolves an edge as finely as
#: the refinement of one at kappa h0 = 1 does
EDGE_KAPPA_H = 0.5
#: a coarser level is used where the channels it does not resolve (kappa h > GRADE_KAPPA_H) have decayed by
#: exp(-DECAY_EFOLDS)
GRADE_KAPPA_H, DECAY_EFOLDS = 1.5, 2.0
#: nothing is kept deeper than this many decay lengths of the longest-reaching channel
TRUNCATION_EFOLDS = 6.0
#: the finest spacing is at most the object's smallest extent over this
MIN_CELLS_ACROSS = 12.0
#: surface cubes the default resolution allows: the head scan at 200 mm in skin1 gets h0 = 1.41 mm instead of the
#: material's 0.84 (lit error against a 2e7-photon Monte Carlo 6.4 / 7.7 / 10.3 %, still below the 2e6-photon run's
#: 9.0 / 10.2 / 12.4 %; 6.0 / 6.9 / 9.0 % at 1.19 mm with 250k cubes, 5.8 / 6.2 / 8.0 % at 1.0 mm with 400k), so that
#: the head at 141k vertices bakes in about 8 s and 1.3 GB on 2 cores (10-11.6 s and 1.7 GB at 250k; docs/benchmarks.md)
DEFAULT_BUDGET = 200_000
#: the sources' sideways spread, in units of h0
SPREAD_OVER_H0 = 1.0
#: levels of the lattice (2^LEVELS - 1 h0 at the coarsest)
LEVELS = 7
#: around an edge of light (and a beam's entry) the lattice is twice as fine, over this many decay lengths of the
#: fastest-decaying channel (2 would save 5-10 % of the 141k head's time at equal Monte Carlo errors, but the sun-lit
#: ball's terminator reads 15.6 % off at worst instead of 10.7 %: tests/volume/test_volume_sun_ball.py)
REFINE_EFOLDS = 3.0
#: thin parts (docs/physics.md §15.2, eq. (135)): where the object is thinner (its shape diameter,
#: :mod:`meshshade.volume.thickness`) than THIN_CELLS_ACROSS surface cubes h0 and than THIN_DECAYS decay lengths of
#: the channel that reaches farthest (its light crosses the part), the lattice is twice as fine (level 0, h0 / 2)
THIN_CELLS_ACROSS, THIN_DECAYS = 4.0, 2.0
#: the thickness is cast from one sampling point per cube of THIN_PROBE_OVER_H0 h0 (half the thickness a thin part
#: may have), each point taking its nearest probe's (:func:`meshshade.volume.thickness.surface_thickness`): on the
#: hand at 190 mm in marble (101k sampling points) 0.22 s at h0, 0.10 s at 2 h0 on 2 threads (0.29 / 0.12 s on one)
THIN_PROBE_OVER_H0 = 2.0


class VolumeResolution:
    """The lattice's surface spacing ``h0`` mm and why it is what it is (``limited_by``: "material", "object",
    "budget" or "given"); ``grading``: the lattice's levels with level 0 at h0 / 2, used only where the light
    calls for it (edges of light and shadow, beams: REFINE_EFOLDS decay lengths of the fastest channel around
    them) and in thin parts (thinner than ``thin_below`` mm), level 1 (h0) at the surface elsewhere; ``spread`` mm
    the sources' sideways spread, ``kappa`` (3,) 1/mm, ``refine_radius`` mm."""

    def __init__(self, h0, grading, spread, kappa, limited_by, requested, reason: str = ""):
        self.h0, self.grading, self.spread, self.kappa = h0, grading, spread, kappa
        self.limited_by, self.requested = limited_by, requested
        #: one line: what set ``h0`` (the channel and medium whose decay length it resolves, the object's thinnest
        #: extent, the budget, or the caller)
        self.reason = reason or limited_by
        #: mm around each edge of light refined to h0 / 2 (0: the edges are resolved at h0, EDGE_KAPPA_H)
        self.refine_radius = (REFINE_EFOLDS / float(np.max(kappa)) if float(np.max(kappa)) * h0 > EDGE_KAPPA_H
                              else 0.0)
        #: mm: a part thinner than this is resolved at h0 / 2 (THIN_CELLS_ACROSS cubes of h0, and THIN_DECAYS decay
        #: lengths of the farthest-reaching channel, whichever is less)
        self.thin_below = min(THIN_CELLS_ACROSS * h0, THIN_DECAYS / float(np.min(kappa)))


def _round_h(h: float) -> float:
    """h rounded up to 2^(k/4) mm."""
    return float(2.0 ** (math.ceil(4.0 * math.log2(h) - 1e-9) / 4.0))


def _bands(h0, kappa):
    bands = [0.0]
    for l in range(1, LEVELS):
        h = h0 * 2 ** l
        need = [DECAY_EFOLDS / k for k in kappa if k * h > GRADE_KAPPA_H]
        grade = bands[-1] + (math.sqrt(3.0) * h0 * 2 ** (l - 1) if l >= 2 else h)
        bands.append(max([grade] + need))
    return tuple(bands)


def material_spacing(kappa: float) -> float:
    """The surface spacing (mm) that resolves a channel decaying as exp(-kappa r), kappa in 1/mm: kappa h0 =
    RESOLVED_KAPPA_H where its decay length is short, LONG_KAPPA_H (no finer than LONG_DECAY_MM) where it is
    long (module constants), before rounding."""
    decay = 1.0 / float(kappa)
    return min(RESOLVED_KAPPA_H * decay, max(LONG_KAPPA_H * decay, LONG_DECAY_MM))


def volume_resolution(material, area_mm2: float, extent_mm, *, h0: float | None = None,
                      budget: int = DEFAULT_BUDGET) -> VolumeResolution:
    """The resolution for ``material`` on a surface of ``area_mm2`` whose bounding box is ``extent_mm`` (3,);
    ``h0`` forces the finest spacing (mm), ``budget`` caps the level-0 cubes (module docstring). Its ``reason``
    names what set the spacing; ``material``'s ``name`` (a preset's, or what a varying medium's resolution
    material says it stands for) is part of it."""
    kappa = np.array(material.medium.kappa, dtype=np.float64)
    if h0 is not None:
        if not (isinstance(h0, (int, float)) and math.isfinite(h0) and h0 > 0):
            raise ParameterError(f"the volume's lattice spacing must be a positive number of mm, got {h0!r}")
        h, why = float(h0), "given"
    else:
        if not (isinstance(budget, int) and budget >= 1000):
            raise ParameterError(f"the volume's cell budget must be an integer >= 1000, got {budget!r}")
        fast = int(np.argmax(kappa))
        h_mat = material_spacing(float(kappa[fast]))
        thinnest = float(np.min(extent_mm))
        if not (thinnest > 0.0 and area_mm2 > 0.0):
            raise NoVolumeError("the mesh is flat (a sheet of zero thickness): it encloses no volume")
        h_obj = thinnest / MIN_CELLS_ACROSS
        # the material's spacing rounded up, the object's down, and the finer of the two (rounding the material's
        # up must not pass the object's cap)
        h_mat, h_obj = _round_h(h_mat), float(2.0 ** (math.floor(4.0 * math.log2(h_obj)) / 4.0))
        h, why = (h_mat, "material") if h_mat <= h_obj else (h_obj, "object")
        name = getattr(material, "name", None)
        whose = f"{name}'s " if name else ""
        colour = ("red", "green", "blue")[fast % 3]
        reason = (f"material: {whose}{colour} decays in {1.0 / kappa[fast]:.3g} mm" if why == "material" else
                  f"object: its thinnest extent {thinnest:.3g} mm over {MIN_CELLS_ACROSS:g}")
        # surface cubes (h0): the surface's area times their band (to where level 2 starts) and a cut layer, over
        # h0^3 (the finer cubes at edges of light come on top, in proportion to the edges' length)
        for _ in range(40):
            cells = area_mm2 * (_bands(0.5 * h, kappa)[2] + h) / h ** 3
            if cells <= budget:
                break
            h *= 2.0 ** 0.25
            why = "budget"
            reason = f"budget: {budget} surface cubes"
    depth_max = TRUNCATION_EFOLDS / float(kappa.min())
    fine = 0.5 * h
    grading = Grading(fine, _bands(fine, kappa), depth_max)
    return VolumeResolution(h, grading, SPREAD_OVER_H0 * fine, kappa, why, h0,
                            "given" if h0 is not None else reason)
