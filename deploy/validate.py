"""Validation of exported models: the checks every export goes through before it is used (``spec/deploy.md`` §6).

1. ``onnx.checker.check_model(full_check=True)``: structure, operator schemas, types, and shape inference;
2. ``onnx.shape_inference.infer_shapes(strict_mode=True)``: every output shape inferable;
3. the model's ``ir_version`` and opset are at most what the installed onnxruntime accepts (``MAX_IR_VERSION``);
4. :func:`run_reference`: ``onnx.reference.ReferenceEvaluator``, a pure-NumPy interpreter of the ONNX spec, as a
   second oracle independent of onnxruntime (float64-capable). Its ``Loop`` stacks scan outputs with
   ``np.vstack`` (a per-iteration ``(B, P)`` would arrive as ``(T·B, P)``), so our ``Loop`` graphs emit 1-D
   per-iteration values, on which both runtimes agree.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx

from deploy.graph import check_model_strict

__all__ = ["MAX_IR_VERSION", "validate_model", "run_reference", "run_onnxruntime"]

MAX_IR_VERSION = 13
"""Highest IR version we stamp (onnxruntime 1.31 rejects 14; see ``spec/deploy.md`` §1)."""


def validate_model(model: onnx.ModelProto) -> onnx.ModelProto:
    """Run checks 1-3 of the module docstring; return the model with inferred shapes.

    Raises
    ------
    ValueError
        Whatever the check: IR version above :data:`MAX_IR_VERSION`, no default-domain opset import, no graph
        output, or a rejection by the checker or strict shape inference (their message is kept).
    """
    if not isinstance(model, onnx.ModelProto):
        raise ValueError(f"model: expected an onnx.ModelProto, got {type(model).__name__}")
    if model.ir_version > MAX_IR_VERSION:
        raise ValueError(f"model.ir_version: expected <= {MAX_IR_VERSION}, got {model.ir_version}")
    if not any(op.domain in ("", "ai.onnx") for op in model.opset_import):
        raise ValueError("model.opset_import: expected an entry for the default domain")
    if not model.graph.output:
        raise ValueError("model.graph.output: expected at least one graph output")
    try:
        return check_model_strict(model)
    except (onnx.checker.ValidationError, onnx.shape_inference.InferenceError) as exc:
        raise ValueError(f"model: rejected by onnx.checker / strict shape inference: {exc}") from exc


def run_reference(model: onnx.ModelProto, feeds: Mapping[str, np.ndarray]) -> list[np.ndarray]:
    """Outputs of ``onnx.reference.ReferenceEvaluator`` (in graph-output order)."""
    from onnx.reference import ReferenceEvaluator

    return [np.asarray(o) for o in ReferenceEvaluator(model).run(None, dict(feeds))]


def run_onnxruntime(model: onnx.ModelProto | bytes, feeds: Mapping[str, np.ndarray], *,
                    intra_op_threads: int = 1) -> list[np.ndarray]:
    """Outputs of onnxruntime's CPU execution provider (one throw-away session; see ``deploy.runtime``)."""
    from deploy.session import make_session

    session = make_session(model, intra_op_threads=intra_op_threads)
    return session.run(None, dict(feeds))
