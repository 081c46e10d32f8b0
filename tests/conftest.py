"""Shared fixtures: seeded RNG, the ../shared folder (skip with a reason where absent), hypothesis profiles."""
from __future__ import annotations

import os
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
