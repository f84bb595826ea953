"""refimpl/versions.py and the reproducible numbers of issue #35: the lock file, the versions every results file
records, and the demo's numbers against ``benchmarks/results/demo_eval.json`` under the locked versions."""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from refimpl.versions import (CONSTRAINTS, blas_info, library_versions, locked_versions, matches_locked,
                              with_versions)

ROOT = Path(__file__).resolve().parents[1]
DEMO_EVAL = ROOT / "benchmarks" / "results" / "demo_eval.json"
#: The demo's results per BLAS kernel (OpenBLAS picks SkylakeX on an AVX-512 machine unless OPENBLAS_CORETYPE says).
DEMO_EVALS = (DEMO_EVAL, ROOT / "benchmarks" / "results" / "demo_eval_skylakex.json")


def test_library_versions_names_numpy_blas_and_python():
    v = library_versions()
    assert v["numpy"] == np.__version__ and re.match(r"\d+\.\d+", v["python"])
    assert set(blas_info()) >= {"name", "version", "kernel", "threads"}
    assert json.loads(json.dumps(v)) == v  # JSON as it is written


def test_with_versions_adds_the_record_and_keeps_the_document():
    doc = with_versions({"a": 1})
    assert doc["a"] == 1 and doc["versions"]["numpy"] == np.__version__


def test_the_lock_file_pins_the_libraries_and_mismatches_are_named(tmp_path):
    pins = locked_versions()
    for name in ("numpy", "onnx", "onnxruntime", "scipy", "matplotlib", "hypothesis", "pytest", "threadpoolctl"):
        assert re.fullmatch(r"\d+(\.\d+)+", pins[name]), name
    lock = tmp_path / "c.txt"
    lock.write_text("# a comment\nnumpy==0.0.1  # old\n")
    assert matches_locked({"numpy": "2.4.6"}, lock) == ["numpy 2.4.6, locked 0.0.1"]
    assert matches_locked({"numpy": "0.0.1"}, lock) == []
    assert CONSTRAINTS.name == "constraints.txt" and CONSTRAINTS.is_file()


def test_every_benchmark_that_writes_json_records_the_versions():
    missing = []
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        text = path.read_text()
        writes = re.findall(r"json\.dumps?\((?!.*print)", text)
        if writes and "with_versions(" not in text:
            missing.append(path.name)
    assert not missing, f"call refimpl.versions.with_versions on the results of {missing}"


def test_the_demo_results_file_records_its_versions():
    doc = json.loads(DEMO_EVAL.read_text())
    assert {"numpy", "python", "blas", "onnxruntime"} <= set(doc["versions"])
    assert doc["versions"]["blas"]["kernel"] and doc["run"]["steps"] == 3000


def _comparable(v: dict) -> dict:
    """What decides the demo's numbers: NumPy, the BLAS library, version and kernel."""
    b = v.get("blas") or {}
    return {"numpy": v.get("numpy"), "blas": b.get("name"), "blas_version": b.get("version"),
            "kernel": b.get("kernel")}


def test_the_demo_reproduces_its_results_file():
    """``refimpl demo``'s numbers equal the results file of its NumPy, BLAS and kernel (``demo_eval.json``:
    Haswell, ``demo_eval_skylakex.json``: SkylakeX). The demo takes 5-15 min, so this compares the output of a demo already run:
    ``REFIMPL_DEMO_OUT`` names its folder (``.ci/run`` sets it to the demo it runs)."""
    out = os.environ.get("REFIMPL_DEMO_OUT")
    if not out:
        pytest.skip("REFIMPL_DEMO_OUT is not set: run `refimpl demo` and point it at its folder (.ci/run does)")
    got = json.loads((Path(out) / "eval.json").read_text())
    here = _comparable(got["versions"])
    files = {f.name: json.loads(f.read_text()) for f in DEMO_EVALS}
    want = next((doc for doc in files.values() if _comparable(doc["versions"]) == here), None)
    if want is None:
        there = {name: _comparable(doc["versions"]) for name, doc in files.items()}
        pytest.skip(f"other versions than the results files': {here} vs {there} (README 'Reproducible numbers')")
    assert got["run"] == want["run"]
    for method in ("qtg", "qtg+join", "qtg+join+footlock", "inertialization", "interpolation"):
        assert got[method]["mean_cm"] == pytest.approx(want[method]["mean_cm"], rel=1e-9, abs=1e-9), method
