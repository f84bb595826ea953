"""The transition task's evaluation and its report (spec/qtg.md §9, spec/cli.md §5): each method's predictions once,
measured by the paper's metric and the animator's measures, then printed as the paper's comparison and written as
JSON / CSV.

* :func:`evaluate`: every method over the held-out windows once
  (:func:`refimpl.protocols.transition_metrics.predict_transitions`), measured by
  :func:`refimpl.protocols.transition_metrics.prediction_errors` and
  :func:`refimpl.protocols.transition_quality.prediction_quality`, per style and kind for Bandai Namco takes;
* :func:`print_results` (protocol line, table, joins and skating, groups, per-frame curve), :func:`write_results`
  (JSON of everything, CSV of the per-frame curves), :func:`results_json` (strict JSON: a non-finite number is null).

Shape legend: N windows, T transition frames, P pose size (3 + 4 J).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from refimpl.progress import PROGRESS_EVERY_S, Throttle, stderr_line
from refimpl.atomic import atomic_write_text
from refimpl.protocols.transition_locomotion import KIND as BANDAI_NAMCO_KIND, window_groups
from refimpl.protocols.transition_metrics import format_table, predict_transitions, prediction_errors
from refimpl.protocols.transition_quality import format_groups, format_quality, prediction_quality

__all__ = ["evaluate", "print_results", "write_results", "results_json"]


def _say(*parts) -> None:
    print(*parts, flush=True)


def evaluate(test_ds, methods_by_name: Mapping[str, Callable]) -> dict:
    """The paper's protocol on ``test_ds`` (:func:`refimpl.protocols.transition_metrics.prediction_errors`) and,
    under each method's ``"quality"``, the animator's measures
    (:func:`refimpl.protocols.transition_quality.prediction_quality`: joins, foot skating, first and last frame,
    with the ground truth's numbers), both of the same predictions: each method runs once over the windows
    (:func:`refimpl.protocols.transition_metrics.predict_transitions`); windows of Bandai Namco takes also
    ``by_style`` and ``by_kind`` in both (:func:`refimpl.protocols.transition_locomotion.window_groups`)."""
    groups = _groups(test_ds)
    clock = _Clock()
    results = {}
    for name, f in clock.wrap(methods_by_name, "predictions").items():
        pred = predict_transitions(test_ds, f, name)  # (N, T, P)
        clock.reached(name, "error")
        results[name] = prediction_errors(test_ds, pred, groups=groups)
        clock.reached(name, "joins and skating")
        results[name]["quality"] = prediction_quality(test_ds, pred, groups=groups)
    return results


class _Clock:
    """Progress of a long evaluation on stderr: every ``every_s`` seconds at most, at a method's next batch or
    measure, which method and stage it has reached (``"  evaluating: qtg (error), 6 s"``); nothing when it is
    quick."""

    def __init__(self, every_s: float = PROGRESS_EVERY_S):
        self._tick = Throttle(every_s)

    def reached(self, name: str, stage: str) -> None:
        """Report ``name (stage)`` when ``every_s`` seconds have passed since the last report."""
        if self._tick.due():
            stderr_line(f"  evaluating: {name} ({stage}), {self._tick.elapsed:.0f} s")

    def wrap(self, methods_by_name: Mapping[str, Callable], stage: str) -> dict:
        """``methods_by_name`` with each method reporting through the clock (its ``needs_skeleton`` kept)."""
        return {name: self._wrap(f, name, stage) for name, f in methods_by_name.items()}

    def _wrap(self, f: Callable, name: str, stage: str) -> Callable:
        def method(past, target, T, **kw):
            self.reached(name, stage)
            return f(past, target, T, **kw)

        method.needs_skeleton = getattr(f, "needs_skeleton", False)
        return method


def _groups(test_ds) -> dict:
    """Per style and per transition kind for windows of Bandai Namco takes (their names say the style), else none."""
    if test_ds.num_windows and all(s.kind == BANDAI_NAMCO_KIND for s in test_ds.sources):
        return window_groups(test_ds)
    return {}


def _curve_csv(results: Mapping[str, dict], frame_time: float) -> str:
    names = list(results)
    T = len(results[names[0]]["per_frame_cm"])
    lines = ["frame,time_ms," + ",".join(f"{n}_cm" for n in names)]
    for t in range(T):
        lines.append(f"{t + 1},{(t + 1) * frame_time * 1000:.1f},"
                     + ",".join(f"{results[n]['per_frame_cm'][t]:.4f}" for n in names))
    return "\n".join(lines) + "\n"


def results_json(results: Mapping[str, dict]) -> str:
    def conv(v):
        if isinstance(v, np.ndarray):
            return [conv(float(x)) for x in v]
        if isinstance(v, dict):
            return {k: conv(x) for k, x in v.items()}
        if isinstance(v, (np.floating, np.integer)):
            v = v.item()
        if isinstance(v, float) and not np.isfinite(v):
            return None  # e.g. skating without a contact: null, so that the file is strict JSON
        return v

    return json.dumps({k: conv(v) for k, v in results.items()}, indent=2, sort_keys=True, allow_nan=False) + "\n"


def _curve_table(results: Mapping[str, dict], frame_time: float) -> str:
    names = list(results)
    T = len(results[names[0]]["per_frame_cm"])
    head = ["frame", "ms"] + names
    rows = [head] + [[str(t + 1), f"{(t + 1) * frame_time * 1000:.0f}"]
                     + [f"{results[n]['per_frame_cm'][t]:.2f}" for n in names] for t in range(T)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows)


def _protocol_line(ds, model=None) -> str:
    labels = sorted({ds.sources[i].label for i in np.unique(ds.source_index)})
    return (f"protocol: {ds.num_windows} held-out windows ({', '.join(labels)}) from {len(ds.sources)} sources, "
            f"{ds.past} past + T = {ds.transition_length} + {ds.future} target poses at {ds.fps:g} fps, "
            f"{(ds.poses.shape[-1] - 3) // 4} joints; error = mean over windows and joints of the Euclidean joint-position error (cm) per "
            "transition frame" + ("" if model is None else f"; network {model.spec.name} from {model.path}"))


def print_results(results: Mapping[str, dict], test_ds, model=None, *,
                  curve: bool = True) -> None:
    """Print :func:`refimpl.services.evaluate_model` results as the paper's comparison: protocol line, table,
    per-frame curve."""
    _say(_protocol_line(test_ds, model))
    _say("")
    _say("Mean joint-position error per joint per frame (cm), by motion category and at transition frames fK:")
    _say(format_table(results))
    if all("quality" in r for r in results.values()):
        _say("")
        _say("Joins (mean joint displacement into frame 1 and out of frame T), foot skating (horizontal speed of "
             "the foot joints in contact) and the error at the first and last frames:")
        _say(format_quality({k: r["quality"] for k, r in results.items()}))
    for g, table in format_groups(results):
        _say("")
        _say(f"By {g}: mean error cm | foot skating cm/s at contact share (the ground truth's in the last column; "
             "windows per group in brackets):")
        _say(table)
    if curve:
        _say("")
        _say("Per-frame curve (cm):")
        _say(_curve_table(results, 1.0 / test_ds.fps))


def write_results(results: Mapping[str, dict], frame_time: float, *, json_path=None, csv_path=None,
                  extra: Mapping | None = None) -> None:
    """Write :func:`refimpl.services.evaluate_model` results as JSON (everything, and the keys of ``extra``, e.g.
    the demo's ``versions``) and / or CSV (the per-frame curves)."""
    if json_path:
        atomic_write_text(Path(json_path), results_json({**results, **(extra or {})}), make_parents=True)
    if csv_path:
        atomic_write_text(Path(csv_path), _curve_csv(results, frame_time), make_parents=True)
