"""The volume transport's options: how fine its lattice is and how precisely it is solved; a frozen record, checked
where it is made (a one-line :class:`~meshshade.errors.ParameterError`)."""
from __future__ import annotations

import math
from dataclasses import dataclass

from meshshade.errors import ParameterError
from meshshade.volume.multigrid import SOLVE_RTOL
from meshshade.volume.resolution import DEFAULT_BUDGET

__all__ = ["VolumeOptions"]


@dataclass(frozen=True)
class VolumeOptions:
    """How :class:`~meshshade.volume.transport.VolumeTransport` resolves and solves (docs/physics.md §15.2).

    h0 : float mm or None
        The lattice's surface spacing; None (default): from the material, the object and ``budget``
        (:func:`~meshshade.volume.resolution.volume_resolution`).
    budget : int >= 1000
        The surface cubes the resolution may take (:data:`~meshshade.volume.resolution.DEFAULT_BUDGET`).
    solve_rtol : float in (0, 0.1]
        The multigrid conjugate gradients' relative residual per channel
        (:data:`~meshshade.volume.multigrid.SOLVE_RTOL`: the exitance moves by about this share of its peak).
    uncollided : bool
        Whether the light that crosses a thin part before it scatters leaves on the far side (default True,
        docs/physics.md §15.6; False: diffusion and the near field alone, for comparison).
    """

    h0: float | None = None
    budget: int = DEFAULT_BUDGET
    solve_rtol: float = SOLVE_RTOL
    uncollided: bool = True

    def __post_init__(self):
        h0 = self.h0
        if h0 is not None and not (isinstance(h0, (int, float)) and not isinstance(h0, bool) and math.isfinite(h0)
                                   and h0 > 0):
            raise ParameterError(f"the volume's lattice spacing h0 must be a positive number of mm, got {h0!r}")
        if not (isinstance(self.budget, int) and not isinstance(self.budget, bool) and self.budget >= 1000):
            raise ParameterError(f"the volume's cell budget must be an integer >= 1000, got {self.budget!r}")
        r = self.solve_rtol
        if not (isinstance(r, (int, float)) and not isinstance(r, bool) and 0.0 < r <= 0.1):
            raise ParameterError(f"the volume's solve tolerance solve_rtol must lie in (0, 0.1], got {r!r}")
        if not isinstance(self.uncollided, bool):
            raise ParameterError(f"the volume's uncollided must be True or False, got {self.uncollided!r}")
