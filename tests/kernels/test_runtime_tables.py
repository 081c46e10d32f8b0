"""The runtime tables shipped as data (meshshade/kernels/data/*.csv) and their provenance.

Each table's header records its generator in tools/tables/ with the sha256 of the generator's source, and the
sha256 of every file the generator read (the training set, the near-field table): a generator changed without
rerunning it, or an input changed under it, fails here with "rerun tools/tables/<script>", as the reference CSVs
of tests/data fail in test_reference_data.py. The arrays the package loads must have the grid's shapes and finite
values. The check itself is tried on a fake repository in tmp_path.
"""
from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np
import pytest

from meshshade.kernels import fitted_curvature_table, incidence_table, near_field_table
from meshshade.kernels.table_files import DATA, read_table

ROOT = Path(__file__).resolve().parents[2]
#: table file -> (its loader module, its generator)
TABLES = {
    "near_field.csv": (near_field_table, "tools/tables/make_near_field_table.py"),
    "incidence.csv": (incidence_table, "tools/tables/make_incidence_table.py"),
    "fitted_curvature.csv": (fitted_curvature_table, "tools/tables/fit_curvature_model.py"),
}
REQUIRED = ("title", "description", "generator", "sha256", "inputs", "command", "meshshade", "commit", "date")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def stale_sources(header: dict[str, str], root: Path = ROOT) -> list[str]:
    """The generator and inputs of a table whose sha256 differs from the one its header records (or are gone)."""
    recorded = [(header["generator"], header["sha256"])]
    if header["inputs"] != "none":
        recorded += [tuple(item.split(" sha256 ")) for item in header["inputs"].split("; ")]
    return [rel for rel, digest in recorded if not (root / rel).is_file() or _sha256(root / rel) != digest]


def check_table(name: str, folder: Path = DATA, root: Path = ROOT) -> dict[str, str]:
    """The header of ``folder/name`` after checking it is complete and current; fails the test otherwise."""
    header, _ = read_table(name, folder)
    missing = [key for key in REQUIRED if key not in header]
    if missing:
        pytest.fail(f"{name}: header lacks {missing}; regenerate it with its tools/tables/ script")
    stale = stale_sources(header, root)
    if stale:
        pytest.fail(f"{name} is out of date: {', '.join(stale)} changed since it was written; "
                    f"rerun {header['generator']}")
    return header


def test_every_table_file_is_checked_and_shipped():
    assert sorted(p.name for p in DATA.glob("*")) == sorted(TABLES)
    config = (ROOT / "pyproject.toml").read_text()
    assert re.search(r'\[tool\.setuptools\.package-data\]\s*\n(#.*\n)?"meshshade\.kernels" = \["data/\*\.csv"\]',
                     config), "pyproject.toml must ship meshshade/kernels/data/*.csv"


@pytest.mark.parametrize("name", sorted(TABLES))
def test_table_is_current(name):
    header = check_table(name)
    module, generator = TABLES[name]
    assert header["generator"] == generator
    assert header["command"].startswith(f"python {generator}")
    assert re.fullmatch(r"\d+\.\d+\.\d+\S*", header["meshshade"]) and re.fullmatch(r"[0-9a-f]{7,}", header["commit"])
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", header["date"])
    assert module.HEADER == header


def _ascending(a):
    return a.ndim == 1 and a.dtype == np.float64 and np.all(np.isfinite(a)) and np.all(np.diff(a) > 0)


def test_near_field_table_arrays():
    t = near_field_table
    assert all(_ascending(a) for a in (t.X_NODES, t.ETA_NODES, t.G_NODES, t.DEPTHS))
    grid = (len(t.X_NODES), len(t.ETA_NODES), len(t.G_NODES))
    assert grid == (18, 6, 4) and t.WEIGHTS.shape == (*grid, len(t.DEPTHS)) and t.FIT_ERROR.shape == grid
    assert np.all(np.isfinite(t.WEIGHTS)) and np.all(t.WEIGHTS >= 0)
    high = t.X_NODES <= -0.3          # alpha' >= 0.5: orders >= 2 are a large part of the light, every medium fitted
    assert np.all(t.WEIGHTS[high].sum(axis=-1) > 0)
    assert np.all(np.isfinite(t.FIT_ERROR[high])) and np.all((t.FIT_ERROR[high] > 0) & (t.FIT_ERROR[high] < 1))
    # below alpha' = 0.5 the orders >= 2 may be too faint for a ring within 5 % (fit_error NaN: 11 media, g >= 0.7 or
    # eta >= 1.4 at alpha' <= 0.09) or for any source (one medium, eta 1, g 0, alpha' 0.018: single scattering alone)
    low = t.FIT_ERROR[~high]
    assert np.all(np.isnan(low) | ((low > 0) & (low < 1))) and np.isnan(low).sum() <= 12
    assert (t.WEIGHTS[~high].sum(axis=-1) == 0).sum() <= 2


def test_incidence_table_arrays():
    t = incidence_table
    assert all(_ascending(a) for a in (t.X_NODES, t.ETA_NODES, t.G_NODES, t.ANGLES))
    shape = (len(t.X_NODES), len(t.ETA_NODES), len(t.G_NODES), len(t.ANGLES))
    assert shape == (7, 6, 4, 4) and t.RHO.shape == t.GAIN.shape == t.GAIN_STDERR.shape == shape
    assert np.all(np.isfinite(t.RHO)) and np.all((t.RHO >= 0) & (t.RHO <= 10))  # robust_rho's clip
    assert np.all(np.isfinite(t.GAIN)) and np.all(t.GAIN > 0)
    assert np.all(np.isfinite(t.GAIN_STDERR)) and np.all(t.GAIN_STDERR >= 0)


def test_fitted_curvature_table_arrays():
    from meshshade.kernels.fitted_curvature import FEATURES

    t = fitted_curvature_table
    assert t.FEATURES == FEATURES and all(isinstance(f, str) for f in t.FEATURES)
    assert t.COEF.shape == (len(FEATURES),) and t.COEF.dtype == np.float64 and np.all(np.isfinite(t.COEF))
    for split in ("train", "held-out radius", "held-out media"):
        for errors in t.ERRORS[split].values():
            assert set(errors) == {"fitted", "first", "plane", "rings"} and errors["rings"] > 0


def _fake_repo(tmp_path):
    """tmp_path/tools/tables/make_fake.py reading tmp_path/tools/tables/data/in.csv, and its table in tmp_path/data."""
    tools = tmp_path / "tools" / "tables"
    (tools / "data").mkdir(parents=True)
    script, source = tools / "make_fake.py", tools / "data" / "in.csv"
    script.write_text("VALUE = 1\n")
    source.write_text("x\n1\n")
    data = tmp_path / "data"
    data.mkdir()
    (data / "fake.csv").write_text(
        "# title: a fake table\n# description: two numbers,\n#   one per row\n"
        f"# generator: tools/tables/make_fake.py\n# sha256: {_sha256(script)}\n"
        f"# inputs: tools/tables/data/in.csv sha256 {_sha256(source)}\n"
        "# command: python tools/tables/make_fake.py\n# x_nodes: 1.0 2.0\n"
        "# meshshade: 0.1.0\n# commit: 0123abc\n# date: 2026-01-01\nx,v\n1.0,0.5\n2.0,0.25\n")
    return data, script, source


def test_check_passes_on_a_current_table(tmp_path):
    data, _, _ = _fake_repo(tmp_path)
    header = check_table("fake.csv", data, tmp_path)
    assert header["description"] == "two numbers,\none per row" and header["x_nodes"] == "1.0 2.0"
    assert read_table("fake.csv", data)[1] == {"x": ["1.0", "2.0"], "v": ["0.5", "0.25"]}


def test_check_fails_on_a_changed_generator_or_input(tmp_path):
    data, script, source = _fake_repo(tmp_path)
    script.write_text("VALUE = 2\n")
    with pytest.raises(pytest.fail.Exception, match=r"tools/tables/make_fake.py changed .* rerun tools/tables/"):
        check_table("fake.csv", data, tmp_path)
    data, script, source = _fake_repo(tmp_path / "again")
    source.write_text("x\n2\n")
    with pytest.raises(pytest.fail.Exception, match=r"tools/tables/data/in.csv changed"):
        check_table("fake.csv", data, tmp_path / "again")
    source.unlink()
    with pytest.raises(pytest.fail.Exception, match=r"tools/tables/data/in.csv changed"):
        check_table("fake.csv", data, tmp_path / "again")


def test_check_fails_on_a_header_without_a_hash(tmp_path):
    data, _, _ = _fake_repo(tmp_path)
    text = (data / "fake.csv").read_text()
    (data / "nohash.csv").write_text("".join(x for x in text.splitlines(keepends=True) if not x.startswith("# sha")))
    with pytest.raises(pytest.fail.Exception, match=r"header lacks \['sha256'\]"):
        check_table("nohash.csv", data, tmp_path)
