"""Recipe of acRNN (Zhou, Li et al., ICLR 2018) with the dual-quaternion paper's representations (Andreou et al.
2022) on the ``synthesis`` task (spec/acrnn.md §8, spec/architecture.md).

* ``--representation`` picks a row of Table 1 (:data:`refimpl.protocols.synthesis.TABLE1_ROWS`: ``dq-all`` (default),
  ``dq-mse``, ``quaternions``, ``quaternions-fk``, ``quaternions+positions``, ``ortho6d``, ``ortho6d+positions``,
  ``positions``, ``positions-published``, ``euler``); ``--losses mse=1,pos=0.333,...`` overrides its loss weights
  (the ablation);
* :func:`make_config` — :class:`~refimpl.models.acrnn.ACRNNConfig` with the data's frame size and the published
  skewed stack (:data:`PAPER_SKEWED`, spec/acrnn.md §1.1), ``--set`` overrides (``hidden_size``, ``num_layers``,
  ``skewed``, ``ground_truth_length``, ``condition_length``);
* :func:`make_adapter` — the trainer's :class:`~refimpl.train.ModelAdapter`: windows of ``T + 1`` standardised
  frames drawn by :func:`~refimpl.protocols.synthesis.sample_windows` with the trainer's Generator (so resuming is
  exact), or with ``--augment-heading`` cut from the takes, turned to a random heading and encoded per batch
  (:func:`refimpl.augment.random_heading_windows`); the row's loss over every step
  (:func:`refimpl.models.acrnn.loss_and_grads`);
* :func:`published_names`, :data:`PUBLISHED_SETTINGS` — ``refimpl import --layout published`` (spec/import.md);
* :func:`make_method` — NumPy generation ``f(seed (B, S, F), n) -> (B, n, F)`` on raw frames;
* :data:`EXPORTER` ``"acrnn"`` and :func:`export_inputs`, :func:`reference_outputs`, :func:`verify_onnx`.

The paper's settings are the named constants below; ``refimpl train --model acrnn`` uses them as defaults.

Shape legend: B batch, S seed frames, N generated frames, F frame size, J joints, D values per joint.
"""
from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.augment import random_heading_windows
from refimpl.errors import UsageError
from refimpl.models import acrnn
from refimpl.models.acrnn import ACRNNConfig
from refimpl.optim import ACRNN_ADAM
from refimpl.options import config_with_overrides
from refimpl.protocols.synthesis import (TABLE1_ROWS, VARIANTS, WINDOW_MARGIN, count_windows, motion_to_frames, sample_windows,
                                         skeleton_of)
from refimpl.train import ModelAdapter, OptimConfig

__all__ = ["PUBLISHED_SETTINGS", "IMPORT_HINT", "published_names", "NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE",
           "EXPORTER", "PAPER_OPTIM", "PAPER_BATCH", "PAPER_WINDOW", "PAPER_GROUND_TRUTH", "PAPER_CONDITION",
           "PAPER_SEED_FRAMES", "PAPER_SKEWED", "make_config",
           "loss_spec", "make_adapter", "acrnn_method", "make_method", "export_inputs", "reference_outputs",
           "verify_onnx"]

NAME = "acrnn"
SUMMARY = ("acRNN (Zhou, Li et al. 2018) with the dual-quaternion paper's representations and losses: "
           "seed of 10 frames -> long-term motion")
TASK = "synthesis"
#: ``--representation`` values: the rows of Table 1 (the first is the default, the paper's proposal).
REPRESENTATIONS = tuple(TABLE1_ROWS)
CONFIG_TYPE = ACRNNConfig
EXPORTER = "acrnn"
#: Adam, lr 1e-4, β = (0.9, 0.999), no clipping, no decay (:data:`refimpl.optim.ACRNN_ADAM`).
PAPER_OPTIM = OptimConfig(**ACRNN_ADAM)
#: Batch 32, sequences of 100 predicted frames, auto-conditioning 5 ground-truth / 5 own frames, seed of 10.
PAPER_BATCH = 32
PAPER_WINDOW = 100
PAPER_GROUND_TRUTH = 5
PAPER_CONDITION = 5
PAPER_SEED_FRAMES = 10
#: The published code's skewed stack (spec/acrnn.md §1.1: every number of the dual-quaternion paper came from
#: training code built on it); ``--set skewed=false`` for the ordinary stack.
PAPER_SKEWED = True


#: ``--set`` values that make the network the published code's (``refimpl import --layout published``): its
#: skewed stack (spec/acrnn.md §1).
PUBLISHED_SETTINGS = ("skewed=true",)
#: Added to ``refimpl import``'s message for a state dict of other shapes.
IMPORT_HINT = ("the frame size comes from --representation and --data; the published code's positions frame "
               "(171 values) is --representation positions-published --raw-frames")


def published_names(config: ACRNNConfig) -> dict:
    """Our parameter name -> (published name, shape) (:func:`refimpl.models.acrnn.published_names`)."""
    return acrnn.published_names(config)


def make_config(train_ds, overrides: Sequence[str] = ()) -> ACRNNConfig:
    """The paper's config (3 × 1024 LSTM in the published skewed stack, 5/5 auto-conditioning) with the data's
    frame size and ``--set`` overrides. Raises UsageError for an unknown field, a bad value or a ``frame_size`` other than the data's."""
    F = int(train_ds.data.frame_size)
    base = ACRNNConfig(frame_size=F, skewed=PAPER_SKEWED, ground_truth_length=PAPER_GROUND_TRUTH,
                       condition_length=PAPER_CONDITION)
    return config_with_overrides(base, overrides, "frame_size", f"the data has frames of {F} values")


def loss_spec(variant: str, weights: Mapping | None, mean, std, skeleton) -> acrnn.LossSpec:
    """The :class:`~refimpl.models.acrnn.LossSpec` of a row (``weights`` overrides, UsageError when invalid)."""
    try:
        return acrnn.LossSpec.for_variant(VARIANTS[variant], mean, std, skeleton, weights=weights)
    except ValueError as exc:
        raise UsageError(f"--losses: {exc}") from None


def make_adapter(train_ds, val_ds, config: ACRNNConfig, dtype, extra: Mapping) -> ModelAdapter:
    """The trainer's adapter: batches of ``window_length + 1`` standardised frames (``ctx.rng``), the row's loss.

    ``extra`` (the task's :func:`~refimpl.tasks.synthesis.checkpoint_extra`) goes into the checkpoint's model
    config, with ``representation`` = the row.
    """
    data = train_ds.data
    spec = loss_spec(train_ds.variant, train_ds.weights, data.mean, data.std, data.skeleton)
    train = [np.ascontiguousarray(data.standardise(s), dtype=dtype) for s in data.train]   # (T_i, F)
    length = int(train_ds.window_length)

    def get_batch(idx, ctx):
        if getattr(train_ds, "augment", False):  # the published trainer: each window at a random heading
            windows, _ = random_heading_windows(ctx.rng, train_ds.motions, len(idx), length + 2, WINDOW_MARGIN)
            return np.stack([data.standardise(motion_to_frames(data.representation, w)) for w in windows]
                            ).astype(dtype)                                                 # (B, T + 1, F)
        return sample_windows(ctx.rng, train, len(idx), length)                             # (B, T + 1, F)

    def loss_and_grads(params, batch):
        total, _, grads = acrnn.loss_and_grads(params, config, batch, spec)
        return total, grads

    cfg = dict(config.to_dict(), dtype=np.dtype(dtype).name, **{**extra, "representation": train_ds.row})
    return ModelAdapter(name=NAME, num_examples=count_windows(train_ds.data.train, train_ds.window_length),
                        init_params=lambda rng: acrnn.init_params(config, rng, dtype=dtype),
                        get_batch=get_batch, loss_and_grads=loss_and_grads, config=cfg)


def acrnn_method(params: Mapping[str, np.ndarray], config: ACRNNConfig, mean, std) -> Callable:
    """``f(seed (B, S, F), n) -> (B, n, F)``: raw frames in and out (standardised with ``mean``, ``std`` inside),
    :func:`refimpl.models.acrnn.generate` in the parameters' dtype."""
    dtype = next(iter(params.values())).dtype
    mean, std = np.asarray(mean, np.float64), np.asarray(std, np.float64)

    def generate(seed, n):
        s = ((np.asarray(seed, np.float64) - mean) / std).astype(dtype)
        return acrnn.generate(params, config, s, int(n)).astype(np.float64) * std + mean

    return generate


def make_method(model) -> Callable:
    """:func:`acrnn_method` of a :class:`~refimpl.registry.TrainedModel`."""
    return acrnn_method(model.params, model.config, model.extra["mean"], model.extra["std"])


def export_inputs(model) -> dict:
    """Keyword arguments of acRNN's exporter: standardisation, data representation, skeleton parents, metadata."""
    ex = model.extra
    sk = skeleton_of(ex)
    meta = {"frame_rate": float(model.fps or 30.0),
            "training": {"checkpoint_step": model.meta.get("step"), "row": ex.get("row"),
                         "variant": ex.get("variant")}}
    return {"mean": np.asarray(ex["mean"]), "std": np.asarray(ex["std"]), "representation": ex["data_representation"],
            "parents": tuple(int(p) for p in sk.parents), "metadata": meta,
            "skeleton": {"names": list(sk.names), "parents": [int(p) for p in sk.parents],
                         "offsets": np.asarray(sk.offsets, dtype=np.float64).tolist(), "units": "m",
                         "source": "the training takes' skeleton without End Sites, lengths x 0.01 (cm -> m)"}}


def reference_outputs(model, seed, num_frames: int) -> np.ndarray:
    """What an exported acRNN must reproduce: raw generated frames ``(B, N, F)`` of :func:`make_method`."""
    return make_method(model)(seed, num_frames)


def verify_onnx(model, runtime, seed, num_frames: int | None = None) -> dict:
    """onnxruntime against :func:`reference_outputs` on raw seed frames ``(B, S, F)``: the generator graph and the
    step loop. Returns ``{"generate": max |Δ|, "step_loop": max |Δ|, "ok": bool}`` (:data:`TOL_ORT_ROLLOUT`)."""
    from refimpl.testing import TOL_ORT_ROLLOUT

    n = int(num_frames or 30)
    ref = reference_outputs(model, seed, n)
    out, ok = {}, True
    for key, use_generator in (("generate", True), ("step_loop", False)):
        got = np.asarray(runtime.generate(np.asarray(seed, np.float32), n, use_generator=use_generator), np.float64)
        diff = np.abs(got - ref)
        out[key] = float(diff.max())
        ok &= bool(np.all(diff <= TOL_ORT_ROLLOUT["atol"] + TOL_ORT_ROLLOUT["rtol"] * np.abs(ref)))
    out["ok"] = ok
    return out
