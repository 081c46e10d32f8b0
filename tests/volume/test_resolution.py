"""The volume's resolution (meshshade.volume.resolution, docs/physics.md §15.2): the material's spacing rule and
what it buys on a far-scattering material against an exact reference (issue 47)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from meshshade.bench import plan as bench_plan
from meshshade.bench import runner as bench_runner
from meshshade.bench.scenes import Scene
from meshshade.materials import Material
from meshshade.volume.resolution import material_spacing, volume_resolution


@given(st.floats(1e-3, 1e3))
@settings(max_examples=200, deadline=None)
def test_material_spacing_resolves_short_decays_at_kappa_h_1_and_long_ones_at_one_half(kappa):
    """kappa h0 = 1 where the decay length 1/kappa is at most 1 mm, kappa h0 = 1/2 where it is at least 2 mm, 1 mm
    between (continuous), and the spacing never grows as the decay shortens."""
    h = material_spacing(kappa)
    decay = 1.0 / kappa
    if decay <= 1.0:
        assert h == pytest.approx(decay, rel=1e-12)
    elif decay >= 2.0:
        assert h == pytest.approx(0.5 * decay, rel=1e-12)
    else:
        assert h == pytest.approx(1.0, rel=1e-12)
    assert material_spacing(kappa * 1.01) <= h * (1 + 1e-12)


def test_object_cap_is_not_passed_by_rounding_the_material_spacing_up():
    """The material's spacing is rounded up to 2^(k/4) mm; on a small object that must not pass the object's cap
    (its smallest extent over 12, rounded down): a 40 mm ball of sigma_s' = 1, sigma_a = 0.01 /mm asks 2.88 mm from
    the material (3.36 rounded up) and 3.33 from the object (2.83 rounded down)."""
    mat = Material(1.0, 0.01, 1.3)
    res = volume_resolution(mat, 4 * math.pi * 20.0 ** 2, np.full(3, 40.0))
    assert res.limited_by == "object" and res.h0 == pytest.approx(2.0 ** 1.5)
    big = volume_resolution(mat, 4 * math.pi * 100.0 ** 2, np.full(3, 200.0))
    assert big.limited_by == "material" and big.h0 == pytest.approx(2.0 ** 1.75)


def test_a_beam_on_a_far_scattering_sphere_against_its_exact_series():
    """A pencil beam on a 100 mm sphere (2,562 vertices) of sigma_s' = 1, sigma_a = 0.01 /mm (decay length 5.75 mm),
    the default bake against the exact sphere series (meshshade.bench.references, an independent route): mean
    relative error over vertices above 1e-4 of the peak outside the beam's entry fan. Measured 0.065 (0.050 on
    10,242 vertices); at kappa h0 = 1 (the rule before issue 47) 0.38. Planted: RESOLVED rule for every decay
    length (kappa h0 = 1) -> 0.38, fails."""
    scene = Scene("test_sphere_r100_beam", "sphere", 100.0, "beam", "exact", level=4)
    plan = bench_plan.bench_plan(config=bench_plan.BenchConfig(scenes=(scene,), levels={}), models=("volume",))
    (row,) = bench_runner.run_bench(plan, seed=0).rows
    assert row["error_mean"] < 0.1, row
