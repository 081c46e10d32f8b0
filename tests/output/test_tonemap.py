import numpy as np
import pytest

from meshshade.errors import MeshshadeError
from meshshade.output.tonemap import drago_tonemap, exposure_tonemap, srgb_encode, to_uint8, tonemap


def test_drago_tonemap_monotonic_and_zero_to_zero():
    L = np.concatenate([[0.0], np.logspace(-8, 3, 400)])
    rgb = np.repeat(L[:, None], 3, axis=1)
    out = drago_tonemap(rgb)[:, 0]
    assert out[0] == 0.0
    assert np.all(np.diff(out) >= 0)
    below = out[1:] < 1.0  # strictly increasing below the display clip
    assert np.all(np.diff(out[1:])[below[1:]] > 0)
    assert out.max() <= 1.0


@pytest.mark.parametrize("bias", [0.6, 0.85, 0.95])
def test_drago_tonemap_max_maps_to_display_max(bias):
    # Drago eq. 4: at L_w = L_wmax the denominator is log(10) and L_d = L_dmax/100 = 1
    rgb = np.array([[0.1, 0.1, 0.1], [2.0, 2.0, 2.0], [50.0, 50.0, 50.0]])
    out = drago_tonemap(rgb, bias=bias)
    assert out[2, 0] == pytest.approx(1.0, rel=1e-12)


def test_drago_tonemap_keeps_hue_ratios():
    rgb = np.array([[0.2, 0.1, 0.05], [1.0, 1.0, 1.0]])
    out = drago_tonemap(rgb)
    assert out[0, 0] / out[0, 1] == pytest.approx(2.0)
    assert out[0, 1] / out[0, 2] == pytest.approx(2.0)


def test_srgb_encode_known_values():
    # IEC 61966-2-1: linear 0.0031308 is the breakpoint, 0.5 -> 0.735357, 1 -> 1
    assert srgb_encode(0.0) == 0.0
    assert srgb_encode(1.0) == pytest.approx(1.0)
    assert srgb_encode(0.5) == pytest.approx(0.7353569830524495, rel=1e-12)
    assert srgb_encode(0.0031308) == pytest.approx(12.92 * 0.0031308, rel=1e-4)


def test_exposure_and_uint8():
    rgb = np.linspace(0, 2, 30).reshape(10, 3)
    out = exposure_tonemap(rgb, exposure=0.5)
    assert np.allclose(out, np.clip(rgb * 0.5, 0, 1))
    u8 = to_uint8(out)
    assert u8.dtype == np.uint8 and u8.min() == 0 and u8.max() == 255
    assert tonemap(rgb, operator="exposure").dtype == np.uint8
    with pytest.raises(MeshshadeError, match="unknown tone-mapping operator 'reinhard'"):
        tonemap(rgb, operator="reinhard")


def test_tonemap_handles_nonfinite_and_empty():
    rgb = np.array([[np.nan, 1.0, np.inf], [0.0, 0.0, 0.0]])
    assert np.all(np.isfinite(drago_tonemap(rgb)))
    assert np.all(drago_tonemap(np.zeros((4, 3))) == 0)
