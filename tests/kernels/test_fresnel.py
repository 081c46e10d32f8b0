"""Tests of meshshade.kernels.fresnel against closed forms, identities and mpmath references."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from mpmath import mp

from meshshade.kernels.fresnel import fresnel_reflectance, fresnel_transmittance_entry


@pytest.fixture(scope="module")
def reference(reference_csv):
    """Columns of tests/data/fresnel_reference.csv as float arrays (the shared loader checks the generator)."""
    header, table = reference_csv("fresnel_reference.csv")
    assert header["generator"] == "tools/references/precompute_fresnel_references.py"
    assert header["dps"].startswith("50 ")
    return {k: np.array([float(r[k]) for r in table]) for k in table[0]}


@pytest.mark.parametrize("eta_i, eta_t", [(1.0, 1.3), (1.0, 1.5), (1.0, 2.4), (1.5, 1.0), (1.0, 1.0 + 1e-9)])
def test_fresnel_reflectance_normal_incidence(eta_i, eta_t):
    expected = ((eta_i - eta_t) / (eta_i + eta_t)) ** 2
    assert fresnel_reflectance(1.0, eta_i, eta_t) == pytest.approx(expected, rel=1e-13)


def test_fresnel_reflectance_air_glass_textbook():
    # 4 % at normal incidence for n = 1.5, and the Brewster angle tan(theta_B) = 1.5 where R_p = 0, so that
    # F = R_s / 2 with R_s = cos^2(theta_i + theta_t) ... = ((n^2 - 1) / (n^2 + 1))^2 (closed form at Brewster)
    assert fresnel_reflectance(1.0, 1.0, 1.5) == pytest.approx(0.04, rel=1e-14)
    n = 1.5
    cos_b = 1.0 / np.sqrt(1.0 + n * n)
    assert fresnel_reflectance(cos_b, 1.0, n) == pytest.approx(0.5 * ((n * n - 1) / (n * n + 1)) ** 2, rel=1e-13)


def test_fresnel_reflectance_total_internal_reflection():
    eta_i, eta_t = 1.5, 1.0
    cos_crit = np.sqrt(1.0 - (eta_t / eta_i) ** 2)
    beyond = np.linspace(0.0, cos_crit * (1 - 1e-12), 50)
    assert np.all(fresnel_reflectance(beyond, eta_i, eta_t) == 1.0)
    inside = np.linspace(cos_crit * (1 + 1e-6), 1.0, 50)
    assert np.all(fresnel_reflectance(inside, eta_i, eta_t) < 1.0)


def test_fresnel_reflectance_grazing_is_one():
    for eta_t in (1.0001, 1.3, 2.0, 0.7):
        assert fresnel_reflectance(0.0, 1.0, eta_t) == 1.0


def test_fresnel_reflectance_index_matched_is_zero():
    cos = np.linspace(0.0, 1.0, 101)
    assert np.all(fresnel_reflectance(cos, 1.0, 1.0) == 0.0)
    assert np.all(fresnel_reflectance(cos, 1.4, 1.4) == 0.0)
    assert np.all(fresnel_transmittance_entry(cos, 1.0) == 1.0)


@pytest.mark.parametrize("eta_i, eta_t", [(1.0, 1.001), (1.0, 1.3), (1.0, 2.0), (1.0, 3.5), (1.33, 1.0), (1.5, 1.0)])
def test_fresnel_reflectance_monotonic_in_angle(eta_i, eta_t):
    cos = np.linspace(0.0, 1.0, 20001)             # angle of incidence decreases along the array
    F = fresnel_reflectance(cos, eta_i, eta_t)
    assert np.all(np.diff(F) <= 1e-15)


def test_fresnel_reflectance_mpmath_reference(reference):
    """Against tests/data/fresnel_reference.csv (tools/references/precompute_fresnel_references.py, mpmath 50 digits,
    Fresnel's sine/tangent laws: an independent form of the equations). Observed max rel. error 1e-15."""
    ref = reference
    F = fresnel_reflectance(ref["cos_i"], ref["eta_i"], ref["eta_t"])
    np.testing.assert_allclose(F, ref["F"], rtol=1e-14, atol=0.0)


@pytest.mark.slow
def test_fresnel_reflectance_live_mpmath(data_dir, reference):
    """Recompute the reference rows in mpmath and compare them with the committed CSV."""
    spec = importlib.util.spec_from_file_location("fresnel_ref", data_dir.parents[1] / "tools" / "references" /
                                                  "precompute_fresnel_references.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ref = reference
    with mp.workdps(50):
        live = np.array([float(mod.reference(c, a, b)) for c, a, b in zip(ref["cos_i"], ref["eta_i"], ref["eta_t"])])
    np.testing.assert_allclose(live, ref["F"], rtol=1e-15)


@pytest.mark.parametrize("eta", [1.0001, 1.3, 1.5, 2.4, 0.75])
def test_fresnel_energy_conservation(eta):
    """R + T = 1 with T from the Fresnel *transmission* amplitudes (an independent formula):
    T_s = (eta cos_t / cos_i) t_s^2, t_s = 2 cos_i / (cos_i + eta cos_t); T_p likewise with t_p = 2 cos_i /
    (eta cos_i + cos_t) (Born & Wolf 1.5.3)."""
    cos_i = np.linspace(1e-3, 1.0, 1001)
    cos2_t = ((eta - 1) * (eta + 1) + cos_i**2) / eta**2   # = 1 - sin^2(theta_i)/eta^2, no cancellation
    ok = cos2_t > 0.0
    cos_i, cos_t = cos_i[ok], np.sqrt(cos2_t[ok])
    t_s = 2 * cos_i / (cos_i + eta * cos_t)
    t_p = 2 * cos_i / (eta * cos_i + cos_t)
    T = 0.5 * (eta * cos_t / cos_i) * (t_s**2 + t_p**2)
    np.testing.assert_allclose(fresnel_reflectance(cos_i, 1.0, eta) + T, 1.0, rtol=0, atol=2e-14)


@pytest.mark.parametrize("n1, n2", [(1.0, 1.3), (1.0, 1.5), (1.2, 1.7)])
def test_fresnel_reflectance_reciprocal(n1, n2):
    """Stokes reciprocity: the same pair of angles reflects equally from either side."""
    cos_i = np.linspace(0.01, 1.0, 200)
    cos_t = np.sqrt(1 - (n1 / n2) ** 2 * (1 - cos_i**2))
    np.testing.assert_allclose(fresnel_reflectance(cos_i, n1, n2), fresnel_reflectance(cos_t, n2, n1),
                               rtol=1e-12, atol=1e-15)


def test_fresnel_transmittance_entry_is_one_minus_reflectance():
    cos = np.linspace(0.0, 1.0, 11)
    for eta in (1.0, 1.3, 1.5):
        np.testing.assert_array_equal(fresnel_transmittance_entry(cos, eta), 1.0 - fresnel_reflectance(cos, 1.0, eta))
    assert fresnel_transmittance_entry(1.0, 1.5) == pytest.approx(0.96, rel=1e-14)
    assert fresnel_transmittance_entry(0.0, 1.3) == 0.0


def test_fresnel_reflectance_finite_and_bounded_on_domain():
    cos = np.concatenate([[0.0, 5e-324, 1e-300, 1e-16, 1e-8], np.linspace(0, 1, 257), [1 - 1e-16, 1.0]])
    eta = np.array([1e-3, 0.5, 1 - 1e-15, 1.0, 1 + 1e-15, 1 + 1e-9, 1.3, 2.0, 10.0, 1e3])
    F = fresnel_reflectance(cos[:, None], 1.0, eta[None, :])
    assert F.shape == (cos.size, eta.size) and F.dtype == np.float64
    assert np.all(np.isfinite(F)) and np.all((F >= 0) & (F <= 1))
    T = fresnel_transmittance_entry(cos[:, None], eta[None, :])
    assert np.all(np.isfinite(T)) and np.all((T >= 0) & (T <= 1))


def test_fresnel_reflectance_broadcasts_and_scalars():
    assert np.ndim(fresnel_reflectance(0.5, 1.0, 1.3)) == 0
    assert fresnel_reflectance(np.ones((2, 3)), 1.0, np.array([1.1, 1.2, 1.3])).shape == (2, 3)
    assert np.isnan(fresnel_reflectance(np.nan, 1.0, 1.3))


def test_refract_in_obeys_snell():
    """Snell's law, not a formula copy: unit length, pointing into the medium, tangential part divided by eta
    (n_1 sin_i = eta sin_t), and normal incidence unchanged."""
    from meshshade.kernels.fresnel import refract_in

    rng = np.random.default_rng(3)
    n = rng.normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where((np.einsum("ij,ij->i", d, n) < 0)[:, None], d, -d)          # arriving from outside
    for eta in (1.0, 1.33, 2.5):
        t = refract_in(d, n, eta)
        np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, rtol=1e-13)
        assert np.all(np.einsum("ij,ij->i", t, n) < 0)
        tan_d = d - np.einsum("ij,ij->i", d, n)[:, None] * n
        tan_t = t - np.einsum("ij,ij->i", t, n)[:, None] * n
        np.testing.assert_allclose(tan_t, tan_d / eta, atol=1e-13)
    np.testing.assert_allclose(refract_in(-n, n, 1.4), -n, atol=1e-15)
