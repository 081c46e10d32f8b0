"""Tone mapping as the images use it: monotonic, 0 -> 0."""
import numpy as np
import pytest

from meshshade.output.render import display_rgba
from meshshade.output.tonemap import tonemap


@pytest.mark.parametrize("op", ["drago", "exposure"])
@pytest.mark.parametrize("bias", [0.7, 0.85, 0.95])
def test_tonemap_monotonic_zero_to_zero(op, bias):
    L = np.concatenate([[0.0], np.geomspace(1e-9, 1e-1, 400)])
    rgb = np.stack([L] * 3, 1)
    out = tonemap(rgb, operator=op, bias=bias).astype(int)
    assert np.all(out[0] == 0)
    assert np.all(np.diff(out[:, 1]) >= 0)
    img = display_rgba(rgb.reshape(1, -1, 3), np.ones((1, L.size)), operator=op, bias=bias)
    assert np.all(img[0, 0, :3] == 0) and np.all(np.diff(img[0, :, 1].astype(int)) >= 0)
