"""`meshshade profile` in-process (meshio pattern): CSV columns, table, plot, errors with exit code 2."""
import csv

import numpy as np
import pytest

from meshshade.cli.main import main
from meshshade.kernels.dipole import dipole_profile
from meshshade.kernels.sphere import sphere_series_profile
from meshshade.materials import Material


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_profile_csv_plane_has_exact_columns_and_dipole_values(tmp_path):
    out = tmp_path / "p.csv"
    assert main(["profile", "--material", "skin1", "--distances", "0,0.5,1,5", "--models", "dipole",
                 "--csv", str(out)]) == 0
    rows = read_csv(out)
    assert list(rows[0].keys()) == ["model", "channel", "distance_mm", "reflectance_per_mm2"]
    assert len(rows) == 3 * 4
    m = Material.preset("skin1")
    for r in rows:
        c = "rgb".index(r["channel"])
        st = m.sigma_t_prime[c]
        expect = dipole_profile(float(r["distance_mm"]) * st, albedo_prime=m.albedo_prime[c], eta=1.3) * st**2
        assert float(r["reflectance_per_mm2"]) == pytest.approx(expect, rel=1e-15)


def test_profile_sphere_several_radii_adds_radius_column(tmp_path):
    out = tmp_path / "p.csv"
    assert main(["profile", "--sigma-s-prime", "1", "--sigma-a", "0.01", "--eta", "1.3", "--shape", "sphere",
                 "--radius", "5,50", "--max-distance", "10", "--samples", "11", "--csv", str(out)]) == 0
    rows = read_csv(out)
    assert list(rows[0].keys()) == ["model", "channel", "distance_mm", "reflectance_per_mm2", "radius_mm"]
    assert {r["radius_mm"] for r in rows} == {"5", "50"}
    assert {r["model"] for r in rows} == {"dipole", "exact"}
    # on a convex sphere the exact solution lies above the chord dipole away from the entry point
    ex = {(r["radius_mm"], r["distance_mm"]): float(r["reflectance_per_mm2"]) for r in rows
          if r["model"] == "exact" and r["channel"] == "r"}
    dp = {(r["radius_mm"], r["distance_mm"]): float(r["reflectance_per_mm2"]) for r in rows
          if r["model"] == "dipole" and r["channel"] == "r"}
    assert all(ex[k] > dp[k] for k in ex if float(k[1]) >= 1)


def test_profile_table_and_plot(tmp_path, capsys):
    assert main(["profile", "--material", "marble", "--distances", "0,1,2"]) == 0
    text = capsys.readouterr().out
    assert "distance_mm" in text and "marble" in text and "dipole [r]" in text
    png = tmp_path / "p.png"
    assert main(["profile", "--sigma-s-prime", "1", "--sigma-a", "0.01", "--shape", "sphere", "--radius",
                 "2,10", "--max-distance", "5", "--samples", "6", "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not any(p.name.endswith(".tmp.png") for p in tmp_path.iterdir())


@pytest.mark.parametrize("argv,needle", [
    (["profile", "--material", "skn1"], "did you mean 'skin1'"),
    (["profile", "--sigma-s-prime", "1"], "--sigma-a"),
    (["profile", "--sigma-s-prime", "-1", "--sigma-a", "0.01"], "sigma_s_prime"),
    (["profile", "--sigma-s-prime", "nan", "--sigma-a", "0.01"], "--sigma-s-prime"),
    (["profile", "--material", "skin1", "--shape", "sphere"], "--radius"),
    (["profile", "--material", "skin1", "--distances", "1,x"], "--distances"),
    (["profile", "--material", "skin1", "--distances", "-1"], "distances"),
    (["profile", "--material", "skin1", "--sigma-s-prime", "1,2"], "1 or 3"),
    (["profile", "--material", "skin1", "--shape", "sphere", "--radius", "1", "--distances", "10"], "no requested"),
])
def test_profile_bad_input_one_line_exit_2(argv, needle, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    errors = [ln for ln in err.splitlines() if not ln.startswith("meshshade: warning:")]
    assert len(errors) == 1 and errors[0].startswith("meshshade: error:") and needle in errors[0]
    assert "Traceback" not in err


def test_profile_unwritable_output_is_one_line_error(tmp_path, capsys):
    out = tmp_path / "missing-dir" / "p.csv"
    assert main(["profile", "--material", "skin1", "--distances", "1", "--csv", str(out)]) == 2
    assert "error" in capsys.readouterr().err
    assert not out.exists()


def test_profile_grey_material_table_merges_channels(capsys):
    assert main(["profile", "--sigma-s-prime", "1", "--sigma-a", "0.01", "--distances", "0,1"]) == 0
    out = capsys.readouterr().out
    assert "[r]" not in out


def test_profile_sphere_exact_equals_series_kernel(tmp_path):
    out = tmp_path / "p.csv"
    assert main(["profile", "--sigma-s-prime", "1", "--sigma-a", "0.01", "--shape", "sphere", "--radius", "10",
                 "--models", "exact", "--distances", "0,3,7", "--csv", str(out)]) == 0
    rows = [r for r in read_csv(out) if r["channel"] == "g"]
    s = np.array([float(r["distance_mm"]) for r in rows])
    st = 1.01
    ref = sphere_series_profile(s / 10.0, R0_opt=10 * st, albedo_prime=1 / 1.01, eta=1.3) * st**2
    assert np.allclose([float(r["reflectance_per_mm2"]) for r in rows], ref, rtol=1e-14, atol=0)


def test_profile_sphere_drops_distances_beyond_half_girth(tmp_path, capsys):
    out = tmp_path / "p.csv"
    assert main(["profile", "--sigma-s-prime", "1", "--sigma-a", "0.01", "--shape", "sphere", "--radius", "2,50",
                 "--max-distance", "20", "--samples", "5", "--models", "exact", "--csv", str(out)]) == 0
    assert "half the circumference" in capsys.readouterr().err
    rows = read_csv(out)
    small = [float(r["distance_mm"]) for r in rows if r["radius_mm"] == "2" and r["channel"] == "r"]
    big = [float(r["distance_mm"]) for r in rows if r["radius_mm"] == "50" and r["channel"] == "r"]
    assert max(small) <= np.pi * 2 and len(big) == 5
