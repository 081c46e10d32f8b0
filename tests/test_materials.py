"""Materials (presets, validation, derived optics) and length units."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from meshshade.errors import DiffusionValidityWarning, MaterialError, MeshshadeError, UnitsError
from meshshade.kernels.optics import diffusion_params, fresnel_diffuse_reflectance
from meshshade.materials import JENSEN_2001_PRESETS, Material, material_from_options
from meshshade.units import MM_PER_UNIT, mm_per_unit

PRESET_NAMES = ["apple", "chicken1", "chicken2", "cream", "ketchup", "marble", "potato", "skimmilk", "skin1",
                "skin2", "spectralon", "wholemilk"]


def _quiet_preset(name, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DiffusionValidityWarning)
        return Material.preset(name, **kw)


# --- presets ------------------------------------------------------------------------------------------

def test_presets_all_twelve_present():
    assert sorted(JENSEN_2001_PRESETS) == PRESET_NAMES


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_preset_eta_and_table_values(name):
    m = _quiet_preset(name)
    s, a = JENSEN_2001_PRESETS[name]
    assert m.eta == 1.3  # Jensen et al. 2001 measured all 12 at eta = 1.3
    assert m.name == name
    np.testing.assert_array_equal(m.sigma_s_prime, s)
    np.testing.assert_array_equal(m.sigma_a, a)
    assert m.sigma_s_prime.dtype == np.float64 and m.sigma_s_prime.shape == (3,)


# Spot checks typed in independently from the published table, mm^-1, RGB:
# Jensen, Marschner, Levoy & Hanrahan, "A Practical Model for Subsurface Light Transport", SIGGRAPH 2001,
# Table 2, as transcribed in pbrt-v3 src/core/medium.cpp (SubsurfaceParameterTable, "// mm^-1",
# commit 2f208c190e21ba89b77618aadd82cffb57474f23).
TABLE_SPOT_CHECKS = {
    "skin1": ((0.74, 0.88, 1.01), (0.032, 0.17, 0.48)),
    "marble": ((2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)),
    "ketchup": ((0.18, 0.07, 0.03), (0.061, 0.97, 1.45)),
    "chicken1": ((0.15, 0.21, 0.38), (0.015, 0.077, 0.19)),
    "potato": ((0.68, 0.70, 0.55), (0.0024, 0.0090, 0.12)),
    "spectralon": ((11.6, 20.4, 14.9), (0.0, 0.0, 0.0)),
}


@pytest.mark.parametrize("name", sorted(TABLE_SPOT_CHECKS))
def test_preset_matches_published_table(name):
    s, a = TABLE_SPOT_CHECKS[name]
    m = _quiet_preset(name)
    np.testing.assert_array_equal(m.sigma_s_prime, s)
    np.testing.assert_array_equal(m.sigma_a, a)


@pytest.mark.parametrize("spelling", ["Skin1", " SKIN1 ", "skin-1", "skin_1"])
def test_preset_name_is_normalised(spelling):
    assert Material.preset(spelling).name == "skin1"


def test_preset_eta_override():
    assert Material.preset("marble", eta=1.5).eta == 1.5


def test_preset_unknown_suggests_close_name():
    with pytest.raises(MaterialError, match=r"unknown material 'marbel'.*did you mean 'marble'"):
        Material.preset("marbel")
    with pytest.raises(MaterialError, match=r"unknown material 'skn1'.*did you mean 'skin1'"):
        Material.preset("skn1")


def test_preset_unknown_without_match_lists_presets():
    with pytest.raises(MaterialError, match=r"unknown material 'xyzzy' \(meshshade materials lists the 42 presets\)") \
            as info:
        Material.preset("xyzzy")
    assert "did you mean" not in str(info.value)


# --- derived quantities (docs/physics.md §2.1) ---------------------------------------------------------------

# docs/physics.md §11.1, skin test case sigma_s' = 1, sigma_a = 0.01 /mm, eta = 1.3, printed to 12 significant
# digits; rtol 1e-11 covers the printing (half a unit in the 12th digit is <= 5e-12 relative).
PHYSICS_MD_A_ETA13 = {
    "sigma_t_prime": 1.01,
    "albedo_prime": 0.990099009901,
    "D": 0.330033003300,
    "sigma_tr": 0.174068951855,
    "z_r": 0.990099009901,
    "F_dr": 0.444762840237,
    "A": 2.60206438786,
    "z_b": 1.71753424941,
    "z_v": 4.42516750873,
}
# docs/physics.md §11.1, column "eta = 1.0" (same coefficients)
PHYSICS_MD_A_ETA10 = {"F_dr": 0.0016, "A": 1.00320512821, "z_b": 0.662181602776, "z_v": 2.31446221545}


@pytest.mark.parametrize("quantity", sorted(PHYSICS_MD_A_ETA13))
def test_material_derived_quantities_physics_md_eta13(quantity):
    m = Material(1.0, 0.01, 1.3)
    got = np.broadcast_to(getattr(m, quantity), (3,))
    np.testing.assert_allclose(got, PHYSICS_MD_A_ETA13[quantity], rtol=1e-11, atol=0)


@pytest.mark.parametrize("quantity", sorted(PHYSICS_MD_A_ETA10))
def test_material_derived_quantities_physics_md_eta10(quantity):
    m = Material(1.0, 0.01, 1.0)
    got = np.broadcast_to(getattr(m, quantity), (3,))
    np.testing.assert_allclose(got, PHYSICS_MD_A_ETA10[quantity], rtol=1e-11, atol=0)


def test_material_dimensional_and_optical_parameters_agree():
    """Material's mm quantities are diffusion_params' optical ones divided by sigma_t' (docs/physics.md §2.1)."""
    m = _quiet_preset("skin1")
    p = diffusion_params(m.albedo_prime, m.eta)
    st = m.sigma_t_prime
    np.testing.assert_allclose(m.z_r * st, p.z_r, rtol=1e-15)
    np.testing.assert_allclose(m.z_b * st, p.z_b, rtol=1e-14)
    np.testing.assert_allclose(m.z_v * st, p.z_v, rtol=1e-14)
    np.testing.assert_allclose(m.D * st, p.D, rtol=1e-15)
    np.testing.assert_allclose(m.sigma_tr / st, p.mu, rtol=1e-13)
    np.testing.assert_allclose(m.transport_length, 1.0 / st, rtol=0)
    assert fresnel_diffuse_reflectance(1.3) == pytest.approx(PHYSICS_MD_A_ETA13["F_dr"], rel=1e-11)


def test_material_channel_kernel_parameters():
    m = _quiet_preset("marble")
    ch = m.channel(0)
    assert ch == {"albedo_prime": 2.19 / (2.19 + 0.0021), "eta": 1.3, "sigma_t_prime": 2.19 + 0.0021}


def test_material_scalar_broadcasts_to_rgb():
    m = Material(1.0, 0.01)
    assert m.sigma_s_prime.shape == (3,) and m.sigma_a.shape == (3,)
    assert m.eta == 1.3 and m.g == 0.0


def test_material_is_immutable():
    m = Material(1.0, 0.01)
    with pytest.raises(ValueError):
        m.sigma_a[0] = 5.0
    with pytest.raises(AttributeError):
        m.eta = 1.5


def test_material_equality_and_hash_are_by_value():
    """Regression: the dataclass-generated __eq__ raised ValueError and __hash__ TypeError on the ndarray fields."""
    a, b = Material(1.0, 0.01), Material((1.0, 1.0, 1.0), [0.01] * 3)
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a != Material(1.0, 0.02) and a != Material(1.0, 0.01, 1.0) and a != Material(1.0, 0.01, name="x")
    assert Material.preset("marble") == Material.preset("Marble")
    assert a != "custom"


# --- validation -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, -1.0, 0.0, (1.0, 0.0, 1.0), (1.0, math.nan, 1.0),
                                 1e200, (1.0, 2e6, 1.0)])
def test_material_rejects_bad_sigma_s_prime(bad):
    with pytest.raises(MaterialError, match=r"sigma_s_prime must be finite and > 0 \[1/mm\]"):
        Material(bad, 0.01)


@pytest.mark.parametrize("bad", [math.nan, -0.01, math.inf, (0.01, -1e-9, 0.01), 1e200])
def test_material_rejects_bad_sigma_a(bad):
    with pytest.raises(MaterialError, match=r"sigma_a must be finite and >= 0 \[1/mm\]"):
        Material(1.0, bad)


def test_material_accepts_zero_sigma_a():
    assert np.all(Material(1.0, 0.0).albedo_prime == 1.0)


def test_material_coefficient_bounds_are_inclusive():
    m = Material(1e6, 1e6)  # a mean free path of 0.5 nm: the largest allowed (SIGMA_MAX)
    assert np.all(np.isfinite(m.z_v))


@pytest.mark.parametrize("bad", [0.0, -1.3, math.nan, math.inf, 0.999, 2.5000001, 60.0, 100.0])
def test_material_rejects_eta_outside_the_fit_domain(bad):
    """eta outside [1, 2.5]: below 1 F_dr < 0, above ~3.9 F_dr > 1 and A < 0 (negative reflectance at eta 100)."""
    with pytest.raises(MaterialError, match=r"eta \(relative index of refraction\) must be finite and lie in "
                                            r"\[1, 2\.5\].*got"):
        Material(1.0, 0.01, bad)
    with pytest.raises(MaterialError, match=r"lie in \[1, 2\.5\]"):
        Material.preset("skin1", eta=bad)


@pytest.mark.parametrize("eta", [1.0, 1.3, 2.2])
def test_material_accepts_eta_in_the_domain_without_warning(eta):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = Material(1.0, 0.01, eta)
    assert 0.0 <= m.F_dr < 1.0 and m.A >= 1.0


@pytest.mark.parametrize("eta", [2.21, 2.5])
def test_material_warns_in_the_grey_zone_of_the_fit(eta):
    """2.2 < eta <= 2.5: allowed, but the fit's A is 1-5 % off the exact Fresnel value (docs/physics.md §2.1)."""
    with pytest.warns(DiffusionValidityWarning, match=r"eta = 2\.[25]\d* is above 2\.2"):
        m = Material(1.0, 0.01, eta)
    assert 0.0 < m.F_dr < 1.0


def test_fdr_fit_stays_a_reflectance_on_the_whole_domain():
    """The reason for the domain: F_dr in [0, 1) (so A >= 1 and z_v > z_r) on [1, 2.5], not outside."""
    from meshshade.kernels.optics import ETA_MAX, ETA_MIN, fresnel_diffuse_reflectance
    eta = np.linspace(ETA_MIN, ETA_MAX, 2001)
    F = fresnel_diffuse_reflectance(eta)
    assert np.all((F >= 0.0) & (F < 1.0))
    assert fresnel_diffuse_reflectance(0.99) < 0.0 and fresnel_diffuse_reflectance(4.0) > 1.0


def test_material_rejects_non_numeric_eta():
    with pytest.raises(MaterialError, match=r"eta and g must be numbers"):
        Material(1.0, 0.01, "glass")


@pytest.mark.parametrize("bad", [-1.0, 1.0, math.nan])
def test_material_rejects_bad_g(bad):
    with pytest.raises(MaterialError, match=r"g must lie in \(-1, 1\)"):
        Material(1.0, 0.01, 1.3, bad)


@pytest.mark.parametrize("values, count", [((1.0, 2.0), 2), ((1.0, 2.0, 3.0, 4.0), 4), ((), 0)])
def test_material_rejects_wrong_channel_count(values, count):
    with pytest.raises(MaterialError, match=rf"sigma_s_prime needs 1 or 3 \(RGB\) values, got {count}"):
        Material(values, 0.01)
    with pytest.raises(MaterialError, match=rf"sigma_a needs 1 or 3 \(RGB\) values, got {count}"):
        Material(1.0, values)


def test_material_rejects_non_numeric_coefficients():
    with pytest.raises(MaterialError, match=r"sigma_s_prime must be a number or three numbers"):
        Material("thick", 0.01)


def test_material_error_is_meshshade_error():
    assert issubclass(MaterialError, MeshshadeError) and issubclass(MaterialError, ValueError)


def test_material_from_options():
    assert material_from_options("skin1").name == "skin1"
    m = material_from_options(sigma_s_prime=(1, 2, 3), sigma_a=0.01)
    assert m.eta == 1.3 and m.sigma_s_prime.tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(MaterialError, match="not both"):
        material_from_options("skin1", sigma_a=0.1)
    with pytest.raises(MaterialError, match="both --sigma-s-prime and --sigma-a"):
        material_from_options(sigma_s_prime=1.0)


# --- low-albedo warning -----------------------------------------------------------------------------------

def test_low_albedo_warns_for_ketchup():
    # ketchup G: 0.07/1.04 = 0.067 and B: 0.03/1.48 = 0.020 (Jensen 2001 Table 2); R: 0.18/0.241 = 0.75
    with pytest.warns(DiffusionValidityWarning, match=r"material 'ketchup'.*channel\(s\) g,b;"):
        Material.preset("ketchup")


@pytest.mark.parametrize("name", [n for n in PRESET_NAMES if n != "ketchup"])
def test_no_low_albedo_warning_for_other_presets(name):
    with warnings.catch_warnings():
        warnings.simplefilter("error", DiffusionValidityWarning)
        Material.preset(name)


def test_low_albedo_warning_threshold():
    with pytest.warns(DiffusionValidityWarning):
        Material(1.0, 1.01)  # alpha' just below 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error", DiffusionValidityWarning)
        Material(1.0, 1.0)  # alpha' = 0.5 exactly: no warning


# --- grey detection ------------------------------------------------------------------------------------

def test_is_grey():
    assert Material(1.0, 0.01).is_grey
    assert Material((1.0, 1.0, 1.0), (0.01, 0.01, 0.01)).is_grey
    assert not Material((1.0, 1.0, 1.0), (0.01, 0.01, 0.02)).is_grey
    assert not Material((1.0, 1.1, 1.0), 0.01).is_grey
    assert not _quiet_preset("skin1").is_grey


# --- units ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("unit, factor", [("mm", 1.0), ("cm", 10.0), ("m", 1000.0), ("in", 25.4)])
def test_mm_per_unit(unit, factor):
    assert mm_per_unit(unit) == factor  # exact by definition (1 in = 25.4 mm since 1959)
    assert mm_per_unit(f" {unit.upper()} ") == factor


def test_mm_per_unit_table_is_complete():
    assert set(MM_PER_UNIT) == {"mm", "cm", "m", "in"}


@pytest.mark.parametrize("bad", ["ft", "", "millimetre", None, 25.4])
def test_mm_per_unit_unknown(bad):
    with pytest.raises(UnitsError, match=r"unknown length unit .*; choose one of mm, cm, m, in"):
        mm_per_unit(bad)
    assert issubclass(UnitsError, MeshshadeError)


# --- Narasimhan et al. 2006 -------------------------------------------------------------------------------------
#: rows of Narasimhan et al. 2006 Table 1 as the paper gives them, sigma_s (not reduced), sigma_a [1/mm] and g per
#: channel, from an independent transcription (the csrt renderer's parser/medium_lut.cpp, values rounded to 5-6
#: significant digits): the presets hold pbrt's sigma_s' = sigma_s (1 - g), so the two copies must agree to that
#: rounding
NARASIMHAN_TABLE1_ROWS = {
    "lowfat-milk": ((13.1157, 15.4445, 17.9572), (0.00287, 0.00575, 0.01150), (0.932, 0.902, 0.859)),
    "espresso": ((7.78262, 8.13050, 8.53875), (4.79838, 6.57512, 8.84925), (0.907, 0.896, 0.880)),
    "regular-soy-milk": ((4.66325, 5.20183, 8.74575), (0.00192, 0.00958, 0.06517), (0.873, 0.858, 0.832)),
    "white-grapefruit-juice": ((0.50499, 0.52742, 0.75282), (0.01380, 0.01883, 0.05678), (0.548, 0.545, 0.565)),
    "cappuccino-powder": ((12.2094, 16.4659, 29.2727), (35.8441, 49.5470, 61.0844), (0.849, 0.843, 0.926)),
    "suisse-mocha-powder": ((30.0848, 33.4452, 38.7191), (17.5020, 27.0044, 35.4334), (0.907, 0.894, 0.888)),
    "pacific-ocean-surface-water": ((0.00180, 0.00183, 0.00228), (0.03184, 0.03132, 0.03015),
                                    (0.902, 0.825, 0.914)),
}


@pytest.mark.filterwarnings("ignore::meshshade.errors.DiffusionValidityWarning")  # espresso, cappuccino: low albedo
@pytest.mark.parametrize("name", sorted(NARASIMHAN_TABLE1_ROWS))
def test_narasimhan_presets_agree_with_an_independent_copy_of_table_1(name):
    sigma_s, sigma_a, g = (np.array(v) for v in NARASIMHAN_TABLE1_ROWS[name])
    m = Material.preset(name)
    # g is given to 3 decimals, so (1 - g) carries up to 0.5e-3 / (1 - g) of relative rounding
    np.testing.assert_allclose(m.sigma_s_prime, sigma_s * (1 - g), rtol=0.5e-3 / (1 - g).min() + 1e-4)
    np.testing.assert_allclose(m.sigma_a, sigma_a, rtol=2e-3, atol=6e-6)
    assert m.eta == 1.33 and m.name == name


def test_presets_are_found_by_any_spelling_and_clear_liquids_are_refused():
    from meshshade.materials import NARASIMHAN_2006_LEFT_OUT, PRESETS

    assert len(PRESETS) == 42 and Material.preset("Head & Shoulders Shampoo").name == "head-and-shoulders-shampoo"
    assert Material.preset("lowfat_milk").name == "lowfat-milk" and Material.preset("skin1").eta == 1.3
    for name in NARASIMHAN_2006_LEFT_OUT:
        with pytest.raises(MaterialError, match="not a preset: sigma_s' = 0"):
            Material.preset(name.replace("-", " ").title())
