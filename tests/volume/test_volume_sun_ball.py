"""The default bake of a sun-lit ball against its exact solution (tests/volume/_sun_ball_reference.py: the Robin
ball series of the line sources plus the near-field continuum, both from their definitions).

The reference's pieces are checked first: the 0F1 series against mpmath's Bessel functions at 30 digits, the
refraction written there against Snell's law's angles. The bake is the volume model as users get it (lattice,
Ewald split, singularity-subtracted remainder, sampling surface), on icospheres of 642 and 2562 vertices: the
coarse one has edges of 3.3 mm, longer than the model samples (its sampling surface splits them).
"""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.light import DirectionalLight
from meshshade.transport.baking import bake


def _load(name):
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


ref = _load("_sun_ball_reference")
vref = _load("_volume_reference")
SUN = [DirectionalLight((0.0, 0.0, -1.0), 1.0)]


def test_series_matches_the_mpmath_ball():
    """The 0F1 ratios of the reference against i_l from mpmath's besseli (30 digits), a source 1 mm deep."""
    gamma = np.linspace(0.2, 1.6, 5)
    kw = dict(D=1.0 / 3.03, sigma_a=0.01, A=2.5, radius=5.0)
    ours = vref.ball_exitance(np.cos(gamma), 4.0, **kw)
    np.testing.assert_allclose(ours, vref.ball_exitance_mpmath(gamma, 4.0, **kw), rtol=1e-10)


def test_refraction_of_the_reference_follows_snell():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = np.array([0.0, 0.0, -1.0])
    n[:, 2] = np.abs(n[:, 2])                                      # facing the light
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = ref.refracted(d, n, 1.3)
    sin_i = np.linalg.norm(np.cross(d, n), axis=1)
    sin_t = np.linalg.norm(np.cross(t, n), axis=1)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(sin_t * 1.3, sin_i, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", t, n) < 0)                  # into the ball


@pytest.fixture(scope="module")
def exact():
    return ref.exact_at()


@pytest.mark.parametrize("level, bound, shadow_bound", [
    (4, 0.032, 0.045),                                             # measured 2.68 % mean, -3.5 % past the terminator
    pytest.param(5, 0.028, 0.035, marks=pytest.mark.slow),          # measured 2.28 %, -2.5 %
])
def test_default_bake_of_the_sun_lit_ball(exact, level, bound, shadow_bound):
    """Mean |M/ref - 1| over every vertex (the whole ball is above 1e-3 of the peak), and the mean signed error
    past the terminator (95-180 deg), where only the volume's diffusion carries light. Icospheres of 2562 and
    10,242 vertices (a 642-vertex one is a polyhedron whose facets change the terminator: 7.6 % against the
    sphere). The error is mostly the lattice's (docs/limitations.md: light that crosses the body is carried by
    cells up to kappa h ~ 1 of the longest-reaching channel; the far pole is -5 to -6 % here)."""
    mesh = Mesh.from_arrays(*icosphere(ref.R, level))
    res = bake(mesh, ref.MATERIAL, SUN)
    assert res.model == "volume"
    expected = exact(mesh.vertices)
    assert np.all(expected > 1e-3 * expected.max())
    e = res.radiance[:, 0] / expected - 1.0
    theta = np.degrees(np.arccos(np.clip(mesh.vertices[:, 2] / ref.R, -1.0, 1.0)))
    shadow = theta > 95.0
    assert np.mean(np.abs(e)) < bound, np.mean(np.abs(e))
    assert abs(np.mean(e[shadow])) < shadow_bound, np.mean(e[shadow])
