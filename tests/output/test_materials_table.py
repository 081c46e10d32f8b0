"""``meshshade materials``: the preset table, its CSV and the swatches."""
from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from meshshade.cli.main import main
from meshshade.kernels.dipole import dipole_total_reflectance
from meshshade.materials import PRESETS, preset_table
from meshshade.output.materials_table import materials_csv, swatch_colours


def test_table_rows_follow_from_the_coefficients():
    rows = preset_table()
    assert [r["name"] for r in rows] == list(PRESETS) and len(rows) == 42
    for r in rows:
        s, a = np.array(r["sigma_s_prime"]), np.array(r["sigma_a"])
        t = s + a
        np.testing.assert_allclose(r["albedo_prime"], s / t, rtol=1e-14)
        np.testing.assert_allclose(r["z_r"], 1 / t, rtol=1e-14)
        with np.errstate(divide="ignore"):
            np.testing.assert_allclose(r["diffusion_length"], 1 / np.sqrt(3 * a * t), rtol=1e-14)
        # R_d: docs/physics.md eq. (16), through the kernel (its own tests hold it to mpmath)
        assert r["R_d"] == [pytest.approx(dipole_total_reflectance(albedo_prime=x, eta=r["eta"]), rel=1e-14)
                            for x in s / t]
    spectralon = next(r for r in rows if r["name"] == "spectralon")
    assert spectralon["diffusion_length"] == [float("inf")] * 3 and spectralon["R_d"] == [pytest.approx(1.0)] * 3


def test_swatches_are_the_srgb_encoded_half_space_reflectance():
    rows = preset_table()
    c = swatch_colours(rows)
    milk = c[[r["name"] for r in rows].index("wholemilk")]
    ketchup = c[[r["name"] for r in rows].index("ketchup")]
    assert np.all(milk > 0.85) and ketchup[0] > 0.4 > ketchup[1]       # white milk, red ketchup
    rd = np.array(rows[0]["R_d"])
    lin = np.where(c[0] <= 0.04045, c[0] / 12.92, ((c[0] + 0.055) / 1.055) ** 2.4)   # sRGB decode (IEC 61966-2-1)
    np.testing.assert_allclose(lin, rd, rtol=1e-12)


def test_csv_round_trips():
    rows = preset_table()
    parsed = list(csv.DictReader(io.StringIO(materials_csv(rows))))
    assert len(parsed) == 42 and parsed[0]["name"] == "apple"
    assert float(parsed[0]["sigma_a_b"]) == 0.046 and float(parsed[-1]["eta"]) == 1.33


def test_materials_command(tmp_path, capsys):
    assert main(["materials"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 43 and "lowfat-milk" in out and "Narasimhan et al. 2006" in out
    assert main(["materials", "--quiet", "--csv", str(tmp_path / "m.csv"), "--plot", str(tmp_path / "m.png")]) == 0
    assert capsys.readouterr().out == ""
    assert (tmp_path / "m.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and (tmp_path / "m.csv").stat().st_size
    assert main(["materials", "--csv", str(tmp_path / "m.txt")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--csv" in err
