"""Shared fixtures: seeded RNG, the ../shared folder (skip with a reason where absent), hypothesis profiles, the
one loader of the reference CSVs in tests/data (``reference_csv``) and a load-independent clock for Monte Carlo
time budgets (``mc_work_clock``). tools/benchmarks/ is put on ``sys.path`` (it is not a package), so tests import its
generators by name (``import mesh_defects``), as its own scripts do."""
from __future__ import annotations

import csv
import hashlib
import importlib
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest

try:
    from hypothesis import HealthCheck, settings

    # deterministic profile for CI (scipy's conftest pattern); "thorough" for slow-marked runs
    settings.register_profile("ci", derandomize=True, max_examples=60, deadline=None,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.register_profile("thorough", max_examples=10_000, deadline=None,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
except ImportError:  # pragma: no cover - hypothesis is in the test extra
    pass

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"
SHARED = Path(os.environ.get("MESHSHADE_SHARED", ROOT.parent / "shared"))
SHARED_MESHES = SHARED / "meshes"
if str(ROOT / "tools" / "benchmarks") not in sys.path:
    sys.path.append(str(ROOT / "tools" / "benchmarks"))


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


@pytest.fixture(scope="session")
def shared_meshes() -> Path:
    if not SHARED_MESHES.is_dir():
        pytest.skip(f"../shared/meshes not found at {SHARED_MESHES} (only present in the developers' workspace)")
    return SHARED_MESHES


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


#: header lines of the reference CSVs (tools/references/_refheader.py): "# key: value", continued on "#   more"
_HEADER_LINE = re.compile(r"^# ([a-z][a-z0-9 _-]*): (.*)$")
_REQUIRED = ("title", "generator", "sha256", "dependencies", "mpmath", "dps", "date")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def parse_reference_header(lines: list[str]) -> dict[str, str]:
    """The ``# key: value`` header of a reference CSV (continuation lines ``#   ...`` joined with a newline)."""
    header: dict[str, str] = {}
    key = None
    for line in lines:
        match = _HEADER_LINE.match(line)
        if match:
            key = match.group(1)
            if key in header:
                raise ValueError(f"header key {key!r} twice")
            header[key] = match.group(2)
        elif line.startswith("#   ") and key is not None:
            header[key] += "\n" + line[4:]
        else:
            raise ValueError(f"not a header line: {line!r}")
    return header


def stale_generators(header: dict[str, str], root: Path = ROOT) -> list[str]:
    """Generator scripts (and their dependencies) whose sha256 differs from the one recorded in ``header``."""
    recorded = [(header["generator"], header["sha256"])]
    if header["dependencies"] != "none":
        for item in header["dependencies"].split("; "):
            path, _, digest = item.partition(" sha256 ")
            recorded.append((path, digest))
    stale = []
    for rel, digest in recorded:
        script = root / rel
        if not (rel.startswith("tools/") and script.is_file()) or _sha256(script) != digest:
            stale.append(rel)
    return stale


def load_reference(name: str, data: Path = DATA, root: Path = ROOT) -> tuple[dict[str, str], list[dict[str, str]]]:
    """``(header, rows)`` of ``tests/data/<name>``, after checking it is current.

    ``header`` maps the ``# key: value`` lines written by tools/references/_refheader.py (title, dps, generator, sha256,
    dependencies, mpmath, date, ...); ``rows`` are the CSV rows as dicts of strings (column -> text; the tests
    convert). Fails if the header lacks an entry, if the sha256 of the generator in tools/ (or of a script it
    imports) differs from the recorded one ("rerun tools/<script>"), or if the file has no rows.
    """
    path = data / name
    lines = path.read_text().splitlines()
    n_head = next((i for i, line in enumerate(lines) if not line.startswith("#")), len(lines))
    try:
        header = parse_reference_header(lines[:n_head])
    except ValueError as exc:
        pytest.fail(f"tests/data/{name}: malformed header ({exc}); regenerate it with its tools/ script")
    missing = [key for key in _REQUIRED if key not in header]
    if missing:
        pytest.fail(f"tests/data/{name}: header lacks {missing}; regenerate it with its tools/ script")
    stale = stale_generators(header, root)
    if stale:
        pytest.fail(f"tests/data/{name} is out of date: {', '.join(stale)} changed since it was written; "
                    f"rerun {header['generator']}")
    rows = list(csv.DictReader(lines[n_head:]))
    if not rows:
        pytest.fail(f"tests/data/{name} has no data rows")
    return header, rows


@pytest.fixture(scope="session")
def reference_csv():
    """The reference loader :func:`load_reference`: ``header, rows = reference_csv("dipole_reference.csv")``."""
    return load_reference


class WorkClock:
    """Stands in for the ``time`` module of the Monte Carlo engine and of simulate(): its seconds advance only with
    the walk's own work, SECONDS_PER_STEP per live photon and step of each round, so a time budget sees the same
    elapsed time however loaded the machine is (wall-clock bounds flake on a busy 2-core machine)."""

    SECONDS_PER_STEP = 1e-7  # ~10 M photon steps per second, the order of the pooled engine on 2 cores

    def __init__(self):
        self.t = 0.0
        self.longest_round = 0.0

    def perf_counter(self) -> float:
        return self.t

    def process_time(self) -> float:
        return self.t


@pytest.fixture
def mc_work_clock(monkeypatch):
    """``start()`` -> WorkClock: from then on the pooled engine and simulate() (and the CLI's ``mc``) run on it."""

    def start() -> WorkClock:
        # imported here, not at the top: test sessions that never run Monte Carlo do not load its engine
        engine = importlib.import_module("meshshade.montecarlo.engine")
        simulate_module = importlib.import_module("meshshade.montecarlo.simulation")
        clock = WorkClock()
        real_round = engine.PoolWalk._round

        def timed_round(self, st, steps):
            dt = int(np.count_nonzero(st.status)) * steps * clock.SECONDS_PER_STEP
            clock.t += dt
            clock.longest_round = max(clock.longest_round, dt)
            return real_round(self, st, steps)

        monkeypatch.setattr(engine.PoolWalk, "_round", timed_round)
        monkeypatch.setattr(engine, "time", clock)
        monkeypatch.setattr(simulate_module, "time", clock)
        return clock

    return start


@pytest.fixture(scope="session")
def dask_client():
    """A real local Dask cluster of 2 worker processes (one task thread and one numba thread each), shared by the
    tests that only submit work to it. A test that kills workers starts its own cluster."""
    from meshshade.batch.dask_cluster import open_client

    with open_client(workers=2, quiet=True) as client:
        yield client
