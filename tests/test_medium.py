"""The medium record (meshshade/medium.py): a material's per-channel constants, computed once where it is made.

References are independent of the code under test: d'Eon's diffusion constants written out here from their
definitions (d'Eon 2012; docs/physics.md eqs. (73)-(75)), the Fresnel moments integrated with mpmath from the
Fresnel equations written here, Jensen's A from the Groenhuis polynomial written here (Jensen et al. 2001 eq. 5),
and the Monte Carlo's real scattering coefficient sigma_s' / (1 - g).
"""
from __future__ import annotations

import cProfile
import pickle
import pstats

import mpmath as mp
import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.kernels.near_field import near_field_profile, near_field_ring, near_field_total, incidence_gain
from meshshade.light import DirectionalLight
from meshshade.materials import Material
from meshshade.medium import Medium, medium_of
from meshshade.transport import bake

SKIN = Material.preset("skin1")
MARBLE = Material.preset("marble")


def _fresnel_inside(mu, eta):
    """Unpolarised Fresnel reflectance seen from inside a medium of index eta at cosine mu (mpmath)."""
    sin_t = eta * mp.sqrt(1 - mu * mu)
    if sin_t >= 1:
        return mp.mpf(1)
    cos_t = mp.sqrt(1 - sin_t * sin_t)
    rs = (eta * mu - cos_t) / (eta * mu + cos_t)
    rp = (eta * cos_t - mu) / (eta * cos_t + mu)
    return (rs * rs + rp * rp) / 2


def _moments(eta):
    with mp.workdps(30):
        e = mp.mpf(eta)
        mu_c = mp.sqrt(1 - 1 / (e * e))
        c1 = mu_c ** 2 / 2 + mp.quad(lambda m: _fresnel_inside(m, e) * m, [mu_c, 1])
        c2 = mu_c ** 3 / 3 + mp.quad(lambda m: _fresnel_inside(m, e) * m * m, [mu_c, 1])
        return float(c1), float(c2)


@pytest.mark.parametrize("material", [SKIN, MARBLE, Material([0.5, 2.0, 8.0], [0.5, 0.01, 0.0], 1.45, 0.3)],
                         ids=["skin1", "marble", "custom"])
def test_medium_constants_match_their_definitions(material):
    m = material.medium
    s, a = np.array(material.sigma_s_prime), np.array(material.sigma_a)
    st = s + a
    alb = s / st
    c1, c2 = _moments(material.eta)
    A = (1 + 3 * c2) / (1 - 2 * c1)                      # d'Eon's boundary mismatch
    D = (2 - alb) / (3 * st)                              # Grosjean's D, mm
    np.testing.assert_allclose(m.sigma_t_prime, st, rtol=1e-15)
    np.testing.assert_allclose(m.albedo_prime, alb, rtol=1e-15)
    np.testing.assert_allclose(m.sigma_s, s / (1 - material.g), rtol=1e-15)
    np.testing.assert_allclose([m.C1, m.C2], [c1, c2], rtol=1e-9)
    np.testing.assert_allclose(m.D, D, rtol=1e-14)
    np.testing.assert_allclose(m.A, A, rtol=1e-9)
    np.testing.assert_allclose(m.z_b, 2 * A * D, rtol=1e-9)
    np.testing.assert_allclose(m.kappa, np.sqrt(a / D), rtol=1e-14)
    np.testing.assert_allclose(m.better.mu, np.sqrt((1 - alb) / ((2 - alb) / 3)), rtol=1e-14)
    np.testing.assert_allclose(m.better.c_phi, (1 - 2 * c1) / 4, rtol=1e-9)
    np.testing.assert_allclose(m.better.c_E, (1 - 3 * c2) / 2, rtol=1e-9)
    e = material.eta
    F_dr = -1.440 / e ** 2 + 0.710 / e + 0.668 + 0.0636 * e   # Groenhuis et al. 1983, Jensen et al. eq. 5
    np.testing.assert_allclose(m.jensen.A, (1 + F_dr) / (1 - F_dr), rtol=1e-14)
    np.testing.assert_allclose(m.jensen.mu, np.sqrt(3 * (1 - alb)), rtol=1e-14)


def test_the_kernels_records_give_what_the_kernels_give():
    """The near-field model read from the medium is the one the kernels make from the numbers, to the last bit."""
    r = np.geomspace(1e-3, 20.0, 50)
    for c in range(3):
        kw = {"albedo_prime": float(SKIN.albedo_prime[c]), "eta": SKIN.eta, "g": SKIN.g}
        model = SKIN.medium.near_field(c)
        np.testing.assert_array_equal(model.profile(r), near_field_profile(r, **kw))
        np.testing.assert_array_equal(model.ring(0 * r, r), near_field_ring(0 * r, r, **kw))
        assert model.total() == near_field_total(**kw)
        assert model.incidence_gain(0.7) == incidence_gain(cos_t=0.7, **kw)
        d = SKIN.medium.dipole(c)
        assert (d.D, d.z_b) == pytest.approx(((2 - kw["albedo_prime"]) / 3, 2 * SKIN.medium.A[c] * d.D), rel=1e-14)


def test_a_stack_of_media_is_each_medium_and_take_picks_them():
    """Media that vary over the object: a Medium of shape (n, 3) made at once equals each material's own, and
    take(index) picks one per vertex."""
    mats = [SKIN, MARBLE, Material([1.0, 2.0, 3.0], [0.1, 0.2, 0.3], 1.5, 0.2)]
    stack = medium_of(np.stack([m.sigma_s_prime for m in mats]), np.stack([m.sigma_a for m in mats]),
                      [m.eta for m in mats], [m.g for m in mats])
    assert stack.shape == (3,) and stack.D.shape == (3, 3)
    for i, m in enumerate(mats):
        for name in ("D", "kappa", "A", "z_b", "sigma_s", "near_strengths", "incidence_rho"):
            np.testing.assert_array_equal(getattr(stack, name)[i], getattr(m.medium, name), err_msg=name)
        for c in range(3):
            assert stack.dipole(c, i) == m.medium.dipole(c)
            assert stack.dipole(c, i, "jensen") == m.medium.dipole(c, variant="jensen")
            np.testing.assert_array_equal(stack.near_field(c, i).profile(np.array([0.5, 2.0])),
                                          m.medium.near_field(c).profile(np.array([0.5, 2.0])))
    per_vertex = stack.take(np.array([2, 0, 0, 1]))
    assert per_vertex.shape == (4,)
    np.testing.assert_array_equal(per_vertex.D[1], SKIN.medium.D)
    np.testing.assert_array_equal(per_vertex.better.mu[3], MARBLE.medium.better.mu)
    with pytest.raises(ValueError, match="no leading axis"):
        SKIN.medium.take([0])


def test_the_medium_is_made_with_the_material_read_only_and_travels_with_it():
    m = SKIN.medium
    assert isinstance(m, Medium) and SKIN.medium is m
    with pytest.raises(ValueError):
        m.D[0] = 1.0
    back = pickle.loads(pickle.dumps(SKIN))   # batch workers receive materials pickled
    np.testing.assert_array_equal(back.medium.kappa, m.kappa)
    assert "D 0.4497/0.3689/0.2958 mm" in repr(m)


#: the functions that compute per-channel constants from a material's numbers
CONSTANTS = ("dipole_variant", "_dipole_variant", "dipole_constants", "diffusion_params", "diffusion_constants",
             "near_field_sources", "incidence_ratios", "fresnel_moments", "medium_of")


def _calls(fn) -> dict:
    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    out = {}
    for (_file, _line, name), (_cc, nc, *_rest) in pstats.Stats(pr).stats.items():
        if name in CONSTANTS or name in ("dipole", "near_field"):
            out[name] = out.get(name, 0) + nc
    return out


def test_the_default_bake_reads_the_constants_and_computes_none():
    """The volume, its correction's tables and the near field read the material's medium: a default bake
    computes no per-channel constant (issue 48: 526 requests per bake before) and reads 3 near-field records,
    one per distinct channel; the material computes its medium once, vectorised over the channels."""
    mesh = Mesh.from_arrays(*icosphere(10.0, 2))
    light = [DirectionalLight((0, 0, -1))]
    bake(mesh, Material([0.9, 1.1, 1.3], [0.03, 0.1, 0.4], 1.4), light)   # compiled code, caches: not counted
    made = _calls(lambda: Material([0.9, 1.1, 1.3], [0.03, 0.1, 0.4], 1.4, name="again"))
    assert made == {"medium_of": 1, "dipole_constants": 1, "diffusion_params": 1, "near_field_sources": 3,
                    "incidence_ratios": 3}, made     # fresnel_moments: cached per eta since the first material
    material = Material([0.9, 1.1, 1.3], [0.03, 0.1, 0.4], 1.4, name="again")
    got = _calls(lambda: bake(mesh, material, light))
    assert {k: v for k, v in got.items() if k in CONSTANTS} == {}, got
    assert got == {"near_field": 3, "dipole": 3}, got
