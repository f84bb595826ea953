"""The test suite's share of ``tests/fuzz/campaign.py`` (spec/robustness.md §11): a few hundred seeded cases
of every family, 0 failures; and the classifier itself is checked on cases that must count as failures."""
from __future__ import annotations

import numpy as np
import pytest

from tests.fuzz import campaign

pytestmark = pytest.mark.skipif(not hasattr(__import__("signal"), "setitimer"), reason="needs SIGALRM")

FAST = {"readers": 90, "npz": 30, "math": 120, "ckpt-schema": 200, "onnx": 30, "onnx-meta": 12, "onnx-args": 40,
        "cli": 24, "cli-process": 2}


def test_fast_share_has_no_failure():
    """About 520 cases over all families: no contract failure."""
    res = campaign.campaign(counts=FAST, seed=1, log=None)
    assert res["cases"] >= 400
    failures = {f"{fam}:{k}": v for fam, s in res["families"].items() for k, v in s["failures"].items()}
    assert not failures, (failures, res["examples"][:5])
    schema = res["families"]["ckpt-schema"]
    assert schema["refused"] > 0.5 * schema["cases"]  # the mutations do reach the schema


def test_runtime_refuses_complex_context(tmp_path):
    """``QTGRuntime.transition`` with a complex ``target``: ValueError, no warning (spec/robustness.md §7.1 R1,
    fixed in deploy/runtime.py)."""
    pytest.importorskip("onnxruntime")
    seeds = campaign.make_seeds(tmp_path)
    from deploy.models import runtime_for_dir

    rt = runtime_for_dir(seeds["onnx"])
    past, target = campaign._context()
    kind, failure, detail, _, _ = campaign._classify(
        lambda: rt.transition(past, target.astype(np.complex64), 4) and None, (ValueError,), 5.0, check_memory=False)
    assert failure is None, (kind, detail)


def test_classifier_flags_contract_breaks(tmp_path):
    """A TypeError, a hang, an accepted malformed result and a warning are failures; ValueError is not."""
    c = campaign._classify

    def type_error():
        raise TypeError("x")

    def hang():
        while True:
            pass

    def warn():
        import warnings
        warnings.warn("overflow", RuntimeWarning)

    assert c(lambda: None, (ValueError,), 1.0)[1] is None
    assert c(lambda: int("x"), (ValueError,), 1.0)[1] is None
    assert c(type_error, (ValueError,), 1.0)[1] == "TypeError"
    assert c(hang, (ValueError,), 0.2, check_memory=False)[1] == "Timeout"
    assert c(lambda: "bad result", (ValueError,), 1.0)[1] == "AcceptedMalformed"
    assert c(warn, (ValueError,), 1.0)[1] == "RuntimeWarning"
    assert c(lambda: bytearray(400 * 2**20) and None, (ValueError,), 5.0)[1] == "MemoryBound"
    assert campaign._check_cli(1, "refimpl info: error: x", "info") == "exit 1"
    assert campaign._check_cli(3, "refimpl info: error: x\nmore", "info") == "2 error lines"
    assert campaign._check_cli(3, "Traceback (most recent call last):", "info") is not None
    assert campaign._check_cli(3, "refimpl info: error: x", "info") is None


def test_crafted_checkpoints_are_signed_like_save_checkpoint(tmp_path):
    """The campaign's direct writer produces files ``load_checkpoint`` accepts (so the schema is what refuses)."""
    from refimpl.checkpoint import load_checkpoint

    arrays = {"param.w": np.arange(6, dtype=np.float32).reshape(2, 3)}
    campaign.write_crafted(tmp_path / "c.npz", arrays, {"a": [1, 2]})
    got, meta = load_checkpoint(tmp_path / "c.npz")
    assert meta == {"a": [1, 2]} and np.array_equal(got["param.w"], arrays["param.w"])
