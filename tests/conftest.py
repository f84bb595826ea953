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

# One BLAS thread for the whole suite, in this process and its subprocesses: `--blas-threads auto` (the command
# line's default, refimpl/threads.py) never goes above these, so the tests that compare runs bit for bit (resume,
# exports, demo numbers) do not depend on what else the machine is doing. Set them yourself to test other counts.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# The tests' data cache (refimpl/datacache.py) lives in a fresh temporary folder, never in ~/.cache/refimpl;
# subprocesses of the tests inherit it.
if "REFIMPL_CACHE" not in os.environ:
    import tempfile

    os.environ["REFIMPL_CACHE"] = tempfile.mkdtemp(prefix="refimpl-test-cache-")

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
SHARED_DATA = SHARED / "data"
GOLDEN = ROOT / "tests" / "golden"  # in the repository (tests/golden/README.md); was ../shared/golden


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; the test is skipped when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not available")
    return SHARED_DATA


def load_golden(name: str) -> dict:
    """Load one golden ``.npz`` of ``tests/golden/`` as a plain dict (no pickle); a missing file fails."""
    import numpy as np

    path = GOLDEN / name
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
