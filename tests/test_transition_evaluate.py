"""The transition task's evaluation (refimpl/tasks/transition.py ``evaluate``, spec/cli.md §4, issue 35): each
method's predictions are made once per evaluation and measured by both the paper's error
(``prediction_errors``) and the animator's measures (``prediction_quality``), with the numbers of measuring each
separately (``evaluate_methods``, ``evaluate_quality``)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from refimpl.protocols.transition_baselines import interpolate, method_registry
from refimpl.protocols.transition_metrics import evaluate_methods, predict_transitions, prediction_errors
from refimpl.protocols.transition_quality import evaluate_quality, prediction_quality


@pytest.fixture(scope="module")
def sample_test():
    from refimpl.tasks.transition import build_datasets

    _, test = build_datasets("sample", 30, 1, test_stride=4)
    return test


def _counting(methods: dict, seen: dict) -> dict:
    """``methods`` that add up, per name, the windows they are asked to fill (``needs_skeleton`` kept)."""
    def wrap(name, f):
        def method(past, target, T, **kw):
            seen[name] = seen.get(name, 0) + len(past)
            return f(past, target, T, **kw)

        method.needs_skeleton = getattr(f, "needs_skeleton", False)
        return method

    return {name: wrap(name, f) for name, f in methods.items()}


def test_evaluate_predicts_each_window_once_with_the_separate_measures_numbers(sample_test):
    from refimpl.tasks.transition import evaluate

    seen: dict = {}
    methods = method_registry(dt=1.0 / sample_test.fps)
    got = evaluate(sample_test, _counting(methods, seen))
    assert seen == {name: sample_test.num_windows for name in methods}  # twice would be 2 N
    errors, quality = evaluate_methods(sample_test, methods), evaluate_quality(sample_test, methods)
    assert list(got) == list(methods)
    for name in methods:
        want = {**errors[name], "quality": quality[name]}
        assert json.dumps(got[name], default=list, sort_keys=True) == json.dumps(want, default=list, sort_keys=True)
        assert np.array_equal(got[name]["per_frame_cm"], errors[name]["per_frame_cm"])


def test_eval_command_runs_the_network_once_per_method(monkeypatch, tmp_path, capsys):
    """``refimpl eval`` of the shipped sample QTG with ``--join inertialize+footlock``: the network's rollout fills
    every held-out window once for each of qtg, qtg+join, qtg+join+footlock (not once more for the joins and
    skating)."""
    import refimpl.recipes.qtg as recipe
    from refimpl.cli import main

    inner, seen = recipe.rollout_inference, []

    def counted(model, past, target, T):
        seen.append(len(past))
        return inner(model, past, target, T)

    monkeypatch.setattr(recipe, "rollout_inference", counted)
    out = tmp_path / "eval.json"
    assert main(["--blas-threads", "1", "eval", "--checkpoint", "pretrained:qtg-cmu-sample", "--join",
                 "inertialize+footlock", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    names = ["qtg", "qtg+join", "qtg+join+footlock"]
    assert all(n in res and "quality" in res[n] for n in names)
    assert sum(seen) == len(names) * res["qtg"]["num_windows"]
    capsys.readouterr()


def test_the_measures_of_given_predictions_check_them(sample_test):
    """prediction_errors / prediction_quality equal the method's evaluate_* numbers; a wrong shape or an empty
    dataset is a ValueError."""
    pred = predict_transitions(sample_test, interpolate)
    e = prediction_errors(sample_test, pred)
    assert e["mean_cm"] == evaluate_methods(sample_test, {"i": interpolate})["i"]["mean_cm"]
    q = prediction_quality(sample_test, pred)
    assert q["skate_cm_s"] == evaluate_quality(sample_test, {"i": interpolate})["i"]["skate_cm_s"]
    for measure in (prediction_errors, prediction_quality):
        with pytest.raises(ValueError, match="pred"):
            measure(sample_test, pred[:, 1:])
        with pytest.raises(ValueError, match="no windows"):
            measure(sample_test.select(np.zeros(sample_test.num_windows, bool)), pred[:0])
    with pytest.raises(ValueError, match="TransitionDataset"):
        prediction_quality(object(), pred)


def test_the_clock_reports_a_stage_reached(capsys):
    from refimpl.tasks.transition_report import _Clock

    _Clock(every_s=-1.0).reached("qtg", "error")
    assert "evaluating: qtg (error)" in capsys.readouterr().err
    _Clock().reached("qtg", "error")  # a quick one says nothing
    assert capsys.readouterr().err == ""
