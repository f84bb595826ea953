"""onnxruntime sessions with the project's settings (``spec/deploy.md`` §7).

CPU execution provider; ``intra_op_num_threads`` configurable (default 1: batch-1 steps are latency-bound and a
second thread mostly adds synchronisation); ``inter_op_num_threads = 1`` with sequential execution;
``session.intra_op.allow_spinning = "0"`` so that several sessions (init, step, rollout) driven alternately do not
fight over the cores with spinning worker threads; full graph optimisation.
"""
from __future__ import annotations

import os

import numpy as np
import onnx

__all__ = ["make_session_options", "make_session"]


def make_session_options(intra_op_threads: int = 1, *, optimization: str = "all"):
    """``onnxruntime.SessionOptions`` with the project's settings (module docstring).

    Parameters
    ----------
    intra_op_threads : int
        Threads inside one operator (``>= 1``).
    optimization : {"all", "extended", "basic", "disabled"}
        Graph optimisation level.
    """
    import onnxruntime as ort

    if not isinstance(intra_op_threads, (int, np.integer)) or intra_op_threads < 1:
        raise ValueError(f"intra_op_threads: expected a positive integer, got {intra_op_threads!r}")
    levels = {"all": ort.GraphOptimizationLevel.ORT_ENABLE_ALL,
              "extended": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED,
              "basic": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC,
              "disabled": ort.GraphOptimizationLevel.ORT_DISABLE_ALL}
    if optimization not in levels:
        raise ValueError(f"optimization: expected one of {sorted(levels)}, got {optimization!r}")
    so = ort.SessionOptions()
    so.intra_op_num_threads = int(intra_op_threads)
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = levels[optimization]
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    so.add_session_config_entry("session.inter_op.allow_spinning", "0")
    so.log_severity_level = 3
    return so


def make_session(model: onnx.ModelProto | bytes | str | os.PathLike, *, intra_op_threads: int = 1,
                 optimization: str = "all"):
    """An ``onnxruntime.InferenceSession`` on the CPU provider with :func:`make_session_options` (no validation).

    Raises
    ------
    ValueError
        When onnxruntime refuses the model (unsupported opset or operator, malformed file, ...).
    """
    import onnxruntime as ort

    if isinstance(model, onnx.ModelProto):
        model = model.SerializeToString()
    elif isinstance(model, os.PathLike):
        model = os.fspath(model)
    options = make_session_options(intra_op_threads, optimization=optimization)
    try:
        return ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph/NotImplemented classes
        raise ValueError(f"model: onnxruntime refused it: {exc}") from exc
