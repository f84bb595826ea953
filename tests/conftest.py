"""Shared pytest configuration: hypothesis profiles and the location of ``../shared``.

Profiles
--------
``ci`` (used when the environment variable ``CI`` is set): derandomised, few examples, no deadline.
``dev`` (default): random, a few more examples, no deadline.
Select explicitly with ``HYPOTHESIS_PROFILE=<name>``.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci", derandomize=True, max_examples=25, deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "dev", max_examples=40, deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
SHARED_DATA = SHARED / "data"
GOLDEN = SHARED / "golden"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; the test is skipped when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not available")
    return SHARED_DATA


@pytest.fixture(scope="session")
def golden_dir() -> Path:
    """``../shared/golden`` (PyTorch float64 reference vectors); skipped when absent."""
    if not GOLDEN.is_dir():
        pytest.skip("../shared/golden is not available")
    return GOLDEN


def load_golden(name: str) -> dict:
    """Load one golden ``.npz`` as a plain dict (no pickle); skip when ``../shared`` is absent."""
    import numpy as np

    path = GOLDEN / name
    if not path.is_file():
        pytest.skip(f"golden file {name} is not available")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
