"""Length units. The only place where unit factors live; meshshade works in millimetres inside."""
from __future__ import annotations

from meshshade.errors import UnitsError

#: millimetres per unit, exact by definition
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}


def mm_per_unit(units: str) -> float:
    """Return the factor that converts lengths in ``units`` to millimetres."""
    try:
        return MM_PER_UNIT[str(units).strip().lower()]
    except KeyError:
        raise UnitsError(
            f"unknown length unit {units!r}; choose one of {', '.join(MM_PER_UNIT)}"
        ) from None
