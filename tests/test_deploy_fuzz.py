"""Runtime wrapper and model-size limits under hostile input (spec/robustness.md "Runtime wrapper and model-size
limits", spec/deploy.md §7): the test suite's share of ``tests/fuzz/deploy_runtime.py`` and one test per family."""
from __future__ import annotations

import random
import resource

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from deploy.session import MAX_LOOP_ITERATIONS, MAX_TENSOR_BYTES, check_model_size, make_session  # noqa: E402
from tests.fuzz import deploy_runtime as F  # noqa: E402


def test_fuzz_campaign_share():
    """300 cases of every family: only ValueError escapes, hostile input is refused, valid input runs, each case
    within 2 s, and the process's peak memory grows by less than 300 MiB (no bomb reached onnxruntime)."""
    F.fixture()
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rng = random.Random(1234)
    outcomes = {}
    for _ in range(300):
        case = F.make_case(rng)
        outcome = F.run_case(case, limit=2.0)
        outcomes.setdefault(outcome, []).append(case.get("kind"))
    assert set(outcomes) <= set(F.FINE), {k: v[:5] for k, v in outcomes.items() if k not in F.FINE}
    assert (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024 < 300


@pytest.mark.parametrize("kind", ["ConstantOfShape", "Expand", "Tile", "Range", "Pad", "OneHot", "initializer",
                                  "Constant", "Loop_trips", "Loop_body", "If_branch", "chain"])
def test_every_bomb_kind_is_refused_before_a_session(kind):
    """Each bomb kind, found by drawing cases until it comes up, is refused by check_model_size and make_session."""
    rng = random.Random(7)
    for _ in range(2000):
        got, model = F.make_bomb(rng)
        if got == kind:
            break
    else:
        pytest.fail(f"no {kind} bomb drawn")
    with pytest.raises(ValueError, match="MAX_|bound"):
        check_model_size(model)
    with pytest.raises(ValueError, match="MAX_|bound"):
        make_session(model)


def test_exported_models_pass_the_size_check():
    """No false alarm: every exported QTG variant (Scan, Loop, unrolled, compact float32/int8/int4) and a model
    with a small constant Expand pass."""
    from onnx import helper, numpy_helper, TensorProto
    from refimpl.models.qtg import QTGConfig, init_params
    from deploy.models.qtg import export_qtg_rollout
    from deploy.models.qtg_compact import export_qtg_rollout_compact

    cfg = QTGConfig(pose_size=91, encoder_sizes=(16, 8), gru_hidden=12, decoder_sizes=(16,), transition_length=5)
    params = init_params(cfg, np.random.default_rng(0), dtype=np.float32)
    for mode in ("scan", "loop", "unrolled"):
        check_model_size(export_qtg_rollout(params, cfg, mode=mode))
    for weights in ("float32", "int8", "int4"):
        check_model_size(export_qtg_rollout_compact(params, cfg, weights=weights))
    nodes = [F._const("one", np.ones((1, 1), np.float32)), F._const("shape", np.array([64, 64], np.int64)),
             helper.make_node("Expand", ["one", "shape"], ["big"]),
             helper.make_node("ReduceMax", ["big"], ["m"], keepdims=0), helper.make_node("Add", ["x", "m"], ["y"])]
    make_session(F._graph_model(nodes))
    assert MAX_TENSOR_BYTES == 256 * 2 ** 20 and MAX_LOOP_ITERATIONS == 10 ** 6


def test_runtime_refusals_name_input_expected_and_actual():
    """Issue 16/18: batch mismatch, batch 0 (would kill the process in the GRU kernel), inf, object arrays of None,
    complex, wrong dtype, wrong rank, huge T — each a ValueError naming the input, the expected and the actual."""
    rt = F.fixture()["runtime"]
    P = F.P
    ok = np.zeros((2, 2, P))
    cases = [((ok, np.zeros((3, 2, P))), r"target: dimension 'B'.*'past', 2; got shape \(3, 2, 15\)"),
             ((np.zeros((0, 2, P)), np.zeros((0, 2, P))), r"past: expected shape \['B', 2, 15\].*got \(0, 2, 15\)"),
             ((np.full((2, 2, P), np.inf), ok), "past: expected finite values"),
             ((np.full((2, 2, P), None, dtype=object), ok), "past: expected a floating or integer array.*object"),
             ((ok, ok + 1j), "target: expected a floating or integer array.*complex128"),
             ((ok.astype(str), ok), "past: expected a floating or integer array.*<U"),
             ((ok[0], ok), r"past: expected shape \['B', 2, 15\] \(rank 3\), got \(2, 15\) \(rank 2\)"),
             ((np.full((2, 2, P), 1e300), ok), "overflow float32")]
    for args, match in cases:
        with pytest.raises(ValueError, match=match):
            rt.transition(*args)
    for T in (10 ** 9, 0, True, 2.5, "30"):
        with pytest.raises(ValueError, match=r"T: expected an integer in \[1, MAX_TRANSITION_FRAMES"):
            rt.transition(ok, ok, T)
    state = rt.start(ok, ok)
    with pytest.raises(ValueError, match="hidden: expected shape"):
        rt.step(dict(state, hidden=np.zeros((1, 0, F.H), np.float32)))
    with pytest.raises(ValueError, match="state: expected a mapping"):
        rt.step([1, 2])
    assert rt.transition(ok.astype(np.int64), ok, 3).shape == (2, 3, P)     # integers are exact: accepted
