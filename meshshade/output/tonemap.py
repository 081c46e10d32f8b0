"""Tone mapping of linear radiance to display values: Drago et al. 2003 logarithmic operator, exposure, sRGB.

F. Drago, K. Myszkowski, T. Annen, N. Chiba, "Adaptive Logarithmic Mapping For Displaying High Contrast
Scenes", Computer Graphics Forum 22(3), 2003, eq. 4:

    L_d = (L_dmax * 0.01 / log10(L_wmax + 1)) * log(L_w + 1) / log(2 + 8 (L_w / L_wmax)^(log(b)/log(0.5)))

with world luminance scaled by the exposure (``L_w = luminance / L_wa``, L_wa the log-average luminance as
Drago does) and the bias ``b`` (0.85 by default, the paper's recommendation). Colour is carried by scaling RGB
by ``L_d / L_w``. All functions are pure: arrays in, arrays out.

Parameter domains (checked; :class:`~meshshade.errors.MeshshadeError`, one line naming the value): ``bias`` in
(0, 1] (Drago et al. 2003 eq. 4: ``log(b)/log(0.5)`` must be >= 0, i.e. b <= 1, for the mapping to rise
monotonically to L_dmax; b = 1 is a pure logarithm, b -> 0 darkens without limit; the paper recommends
0.7-0.9), ``exposure`` finite and > 0, ``L_dmax`` finite and > 0, ``percentile`` in (0, 100], ``operator``
"drago" or "exposure". Non-finite or negative radiance is displayed as 0.
"""
from __future__ import annotations

import math

import numpy as np

from meshshade.errors import ParameterError

OPERATORS = ("drago", "exposure")

#: Rec. 709 / sRGB luminance weights
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def _positive(value, name: str, *, upper: float = math.inf, upper_open: bool = True, what: str = "") -> float:
    """``value`` as a float in (0, upper) (or (0, upper]); MeshshadeError naming it and the range otherwise."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = math.nan
    if not (x > 0.0 and (x < upper if upper_open else x <= upper) and math.isfinite(x)):
        rng = f"(0, {upper:g}{')' if upper_open else ']'}" if math.isfinite(upper) else "finite and > 0"
        raise ParameterError(f"{name} must be {'in ' if math.isfinite(upper) else ''}{rng}{what}, got {value!r}")
    return x


def check_tonemap_options(operator="drago", bias=0.85, exposure=None) -> None:
    """Validate the options of :func:`tonemap_linear` (module docstring) before any work."""
    if operator not in OPERATORS:
        raise ParameterError(f"unknown tone-mapping operator {operator!r} (drago or exposure)")
    _positive(bias, "bias", upper=1.0, upper_open=False, what=" (Drago's bias; 0.85 is typical)")
    if exposure is not None:
        _positive(exposure, "exposure")


def luminance(rgb):
    """(..., 3) linear RGB -> (...) luminance (Rec. 709 weights)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


def srgb_encode(linear):
    """Linear [0, 1] -> sRGB-encoded [0, 1] (IEC 61966-2-1 piecewise curve); values clipped to [0, 1]."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def drago_tonemap(rgb, *, bias=0.85, exposure=1.0, L_dmax=100.0, mask=None):
    """Drago 2003 adaptive logarithmic mapping of (..., 3) linear RGB to display-linear [0, 1] RGB.

    ``mask`` selects the pixels/vertices that define the scene statistics (world adaptation luminance and
    maximum); background is excluded that way. Monotonic in luminance and maps 0 to 0. ``bias`` in (0, 1],
    ``exposure`` and ``L_dmax`` finite and > 0 (MeshshadeError otherwise).
    """
    bias = _positive(bias, "bias", upper=1.0, upper_open=False, what=" (Drago's bias; 0.85 is typical)")
    exposure = _positive(exposure, "exposure")
    L_dmax = _positive(L_dmax, "L_dmax")
    rgb = np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64), nan=0.0, posinf=0.0), 0.0, None)
    L = luminance(rgb)
    sel = L[mask] if mask is not None else L.reshape(-1)
    sel = sel[sel > 0]
    if sel.size == 0:
        return np.zeros_like(rgb)
    L_wa = np.exp(np.mean(np.log(sel)))  # log-average (Drago sec. 3, world adaptation luminance)
    Lw = exposure * L / L_wa
    Lw_max = exposure * sel.max() / L_wa
    expo = np.log(bias) / np.log(0.5)
    with np.errstate(divide="ignore", invalid="ignore"):
        Ld = (L_dmax * 0.01 / np.log10(Lw_max + 1.0)) * np.log(Lw + 1.0) / np.log(
            2.0 + 8.0 * np.power(Lw / Lw_max, expo))
        scale = np.where(L > 0, Ld / np.where(L > 0, L, 1.0), 0.0)
    return np.clip(rgb * scale[..., None], 0.0, 1.0)


def exposure_tonemap(rgb, *, exposure=None, mask=None, percentile=99.0):
    """Plain exposure: scale so that the ``percentile`` of luminance maps to 1 (or by ``exposure``), clip.

    ``exposure`` None or finite and > 0; ``percentile`` in (0, 100] (MeshshadeError otherwise)."""
    if exposure is not None:
        exposure = _positive(exposure, "exposure")
    percentile = _positive(percentile, "percentile", upper=100.0, upper_open=False)
    rgb = np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64), nan=0.0, posinf=0.0), 0.0, None)
    if exposure is None:
        L = luminance(rgb)
        sel = L[mask] if mask is not None else L.reshape(-1)
        sel = sel[sel > 0]
        exposure = 1.0 / np.percentile(sel, percentile) if sel.size else 1.0
    return np.clip(rgb * exposure, 0.0, 1.0)


def to_uint8(display_linear):
    """Display-linear [0, 1] -> sRGB-encoded uint8."""
    return np.round(srgb_encode(display_linear) * 255.0).astype(np.uint8)


def tonemap_linear(rgb, *, operator="drago", bias=0.85, exposure=None, mask=None):
    """Tone map to display-linear [0, 1] RGB: ``operator`` is "drago" or "exposure" (MeshshadeError otherwise;
    the other parameters as :func:`check_tonemap_options`)."""
    check_tonemap_options(operator, bias, exposure)
    if operator == "drago":
        return drago_tonemap(rgb, bias=bias, exposure=1.0 if exposure is None else exposure, mask=mask)
    if operator == "exposure":
        return exposure_tonemap(rgb, exposure=exposure, mask=mask)
    raise AssertionError(operator)  # pragma: no cover - check_tonemap_options refused it


def tonemap(rgb, *, operator="drago", bias=0.85, exposure=None, mask=None):
    """Tone map and sRGB-encode to uint8 (see :func:`tonemap_linear`)."""
    return to_uint8(tonemap_linear(rgb, operator=operator, bias=bias, exposure=exposure, mask=mask))
