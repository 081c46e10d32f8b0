"""The reference CSVs in tests/data and their shared loader (tests/conftest.py ``reference_csv``).

Every CSV must be current (its generator in tools/, and every script the generator imports, hashes to the
sha256 recorded in its header) and must be listed in tests/data/README.md. The loader itself is checked on a
fake repository in tmp_path: a changed generator, a changed dependency or a header without a sha256 must fail.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data"
CSVS = sorted(p.name for p in DATA.glob("*.csv"))


def test_every_reference_csv_is_listed_in_the_readme():
    readme = (DATA / "README.md").read_text()
    assert CSVS, "no reference CSVs found"
    for name in CSVS:
        assert f"`{name}`" in readme, name


@pytest.mark.parametrize("name", CSVS)
def test_reference_csv_is_current(reference_csv, name):
    header, rows = reference_csv(name)
    assert header["generator"].startswith("tools/references/precompute_") and len(header["sha256"]) == 64
    assert header["mpmath"] and header["dps"] and header["date"]
    assert rows and all(None not in row and None not in row.values() for row in rows)  # no ragged rows


def _fake_repo(tmp_path, *, dependency=True):
    """tmp_path/tools/precompute_fake.py (+ _dep.py) and tmp_path/data/fake.csv written against them."""
    tools = tmp_path / "tools"
    tools.mkdir()
    script = tools / "precompute_fake.py"
    script.write_text("VALUE = 1\n")
    dep = tools / "_dep.py"
    dep.write_text("X = 2\n")
    sha = hashlib.sha256(script.read_bytes()).hexdigest()
    deps = f"tools/_dep.py sha256 {hashlib.sha256(dep.read_bytes()).hexdigest()}" if dependency else "none"
    data = tmp_path / "data"
    data.mkdir()
    (data / "fake.csv").write_text(
        "# title: fake reference: two lines\n# function: f(x) = x,\n#   continued\n# dps: 30\n"
        f"# generator: tools/precompute_fake.py\n# sha256: {sha}\n# dependencies: {deps}\n"
        "# mpmath: 1.3.0 (backend python)\n# python: 3.11.7\n# date: 2026-01-01T00:00:00Z\n"
        "x,f\n1.5,1.5\n2.5,2.5\n")
    return data, script, dep


def test_loader_reads_header_and_rows(reference_csv, tmp_path):
    data, _, _ = _fake_repo(tmp_path)
    header, rows = reference_csv("fake.csv", data=data, root=tmp_path)
    assert header["title"] == "fake reference: two lines"
    assert header["function"] == "f(x) = x,\ncontinued"
    assert header["dps"] == "30" and header["mpmath"].startswith("1.3.0")
    assert rows == [{"x": "1.5", "f": "1.5"}, {"x": "2.5", "f": "2.5"}]


def test_loader_fails_on_a_changed_generator(reference_csv, tmp_path):
    data, script, _ = _fake_repo(tmp_path)
    script.write_text("VALUE = 2\n")
    with pytest.raises(pytest.fail.Exception, match="rerun tools/precompute_fake.py"):
        reference_csv("fake.csv", data=data, root=tmp_path)


def test_loader_fails_on_a_changed_dependency(reference_csv, tmp_path):
    data, _, dep = _fake_repo(tmp_path)
    dep.write_text("X = 3\n")
    with pytest.raises(pytest.fail.Exception, match=r"tools/_dep.py changed .* rerun tools/precompute_fake.py"):
        reference_csv("fake.csv", data=data, root=tmp_path)


def test_loader_fails_on_a_missing_generator_or_hash(reference_csv, tmp_path):
    data, script, _ = _fake_repo(tmp_path, dependency=False)
    text = (data / "fake.csv").read_text()
    (data / "nohash.csv").write_text("".join(line for line in text.splitlines(keepends=True)
                                             if not line.startswith("# sha256:")))
    with pytest.raises(pytest.fail.Exception, match=r"header lacks \['sha256'\]"):
        reference_csv("nohash.csv", data=data, root=tmp_path)
    script.unlink()
    with pytest.raises(pytest.fail.Exception, match="rerun tools/precompute_fake.py"):
        reference_csv("fake.csv", data=data, root=tmp_path)


def test_loader_fails_on_a_free_text_header_line(reference_csv, tmp_path):
    data, _, _ = _fake_repo(tmp_path)
    (data / "free.csv").write_text("# some free text\n" + (data / "fake.csv").read_text())
    with pytest.raises(pytest.fail.Exception, match="malformed header"):
        reference_csv("free.csv", data=data, root=tmp_path)
