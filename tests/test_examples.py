"""The README's oracle example (examples/oracle_check.py) runs, and its oracles catch a wrong backward."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "oracle_check.py"


def _run(*args):
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return subprocess.run([sys.executable, str(EXAMPLE), *args], capture_output=True, text=True, env=env,
                          timeout=300, cwd=ROOT)


def test_oracle_example_passes():
    r = _run()
    assert r.returncode == 0, r.stdout + r.stderr
    assert "forward: matches" in r.stdout and "backward: matches" in r.stdout


def test_oracle_example_catches_a_wrong_backward():
    r = _run("--broken")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "MISMATCH: gradient 'b' differs from central differences" in r.stdout
