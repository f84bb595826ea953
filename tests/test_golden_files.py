"""The golden vectors in ``tests/golden/`` are complete, pickle-free, and what PyTorch computes from their inputs.

The first test needs only NumPy (so it runs in any clone); the second recomputes every output and gradient with
PyTorch through ``tests/golden/make_golden.py --check`` and is skipped when torch is not installed.
"""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from conftest import GOLDEN, load_golden


def _make_golden():
    spec = importlib.util.spec_from_file_location("make_golden", GOLDEN / "make_golden.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_recipe_has_its_file_in_the_repository():
    mod = _make_golden()
    on_disk = sorted(p.name for p in GOLDEN.glob("*.npz"))
    assert on_disk == sorted(mod.RECIPES)
    for name in on_disk:
        g = load_golden(name)
        assert any(k.startswith("in.") for k in g) and any(k.startswith(("out.", "grad.")) for k in g)
        assert all(v.dtype in (np.float64, np.int64) for v in g.values()), name


def test_outputs_and_gradients_are_pytorchs(capsys):
    pytest.importorskip("torch")
    mod = _make_golden()
    assert mod.main(["--check", str(GOLDEN)]) == 0
    assert "worst" in capsys.readouterr().out


def test_check_fails_on_a_changed_output(tmp_path):
    pytest.importorskip("torch")
    mod = _make_golden()
    for p in GOLDEN.glob("*.npz"):
        (tmp_path / p.name).write_bytes(p.read_bytes())
    g = load_golden("mlp_leaky005.npz")
    g["out.y"][0, 0] += 1e-9
    np.savez(tmp_path / "mlp_leaky005.npz", **g)
    assert mod.main(["--check", str(tmp_path)]) == 1
