"""Recipe of QuaterNet's pace network (Pavllo et al., IJCV 2019, §3.7; ref §8.3) on the ``locomotion`` task
(spec/locomotion.md §4-§5, §8).

Per spline point ``[turning_angle, average_speed]`` → ``[A, ω, cos Δ, sin Δ]``; L1 loss, Adam 1e-3 with
× 0.999 per epoch, batch 40, no clipping; chunks of spline points drawn by
:func:`refimpl.protocols.locomotion.pace_batch` (the reference's 1000 points when the data's splines are that long,
else their median length). ``--set bidirectional=false`` trains the delayed online variant.

Shape legend: B batch, N spline points.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.errors import UsageError
from refimpl.models import pace
from refimpl.optim import QUATERNET_ADAM, QUATERNET_LR_DECAY
from refimpl.options import config_with_overrides
from refimpl.train import ModelAdapter, OptimConfig

__all__ = ["published_names", "NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE", "EXPORTER", "PAPER_OPTIM", "PAPER_BATCH",
           "MAX_CHUNK", "make_config", "chunk_length", "make_adapter", "make_method", "export_inputs", "verify_onnx"]

NAME = "pace"
SUMMARY = "QuaterNet pace network (Pavllo et al. 2019): spline curvature and speed -> amplitude, frequency, facing"
TASK = "locomotion"
REPRESENTATIONS = ("spline",)
CONFIG_TYPE = pace.PaceConfig
EXPORTER = "quaternet-long"
#: Adam lr 1e-3, lr × 0.999 per epoch, no clipping (ref §8.3).
PAPER_OPTIM = OptimConfig(**QUATERNET_ADAM, lr_decay=QUATERNET_LR_DECAY)
PAPER_BATCH = 40
#: The reference's chunk length (spline points).
MAX_CHUNK = 1000


def published_names(config: pace.PaceConfig) -> dict:
    """Our parameter name -> (published name, shape) (:func:`refimpl.models.pace.published_names`)."""
    return pace.published_names(config)


def make_config(train_ds, overrides: Sequence[str] = ()) -> pace.PaceConfig:
    """The paper's sizes with ``--set`` overrides (``bidirectional``, ``hidden_size``, ``delay``)."""
    base = pace.PaceConfig()
    return config_with_overrides(base, overrides, ("input_size", "output_size"),
                                 "the pace network maps 2-D path points to 4 values (amplitude, frequency, facing)")


def chunk_length(data, requested: int = 0) -> int:
    """``requested`` if > 0, else ``min(1000, median spline length)``."""
    if requested > 0:
        return int(requested)
    return int(min(MAX_CHUNK, np.median([d[0].shape[0] for d in data])))


def make_adapter(train_ds, val_ds, config: pace.PaceConfig, dtype, extra: Mapping) -> ModelAdapter:
    """Chunks of the training splines (:func:`refimpl.protocols.locomotion.pace_batch`), L1 loss; validation = L1
    over the whole held-out splines (not the last training batch, ref quirk 8)."""
    from refimpl.protocols.locomotion import pace_batch

    data = train_ds.pace_data()
    chunk = chunk_length(data, train_ds.pace_chunk_length)
    usable = [d for d in data if d[0].shape[0] >= chunk]
    if not usable:
        raise UsageError(f"pace: no training spline has {chunk} points (--pace-chunk-length)")

    def get_batch(idx, ctx):
        x, y = pace_batch(usable, ctx.rng, len(idx), chunk)
        return x.astype(dtype), y.astype(dtype)

    def loss_and_grads(params, batch):
        pred, cache = pace.forward(params, config, batch[0])
        loss, lc = pace.loss_forward(pred, batch[1])
        return loss, pace.backward(pace.loss_backward(1.0, lc), cache)[1]

    validate = None
    vdata = val_ds.pace_data() if val_ds is not None else []
    if vdata:
        def validate(params):
            vals = [pace.loss_forward(pace.forward(params, config, inp[None].astype(dtype))[0], tgt[None])[0]
                    for inp, tgt in vdata]
            return {"val_l1": float(np.mean(vals))}

    keep = {k: v for k, v in extra.items() if k != "seed_clip"}
    return ModelAdapter(name=NAME, num_examples=len(usable),
                        init_params=lambda rng: pace.init_params(config, rng, dtype=dtype),
                        get_batch=get_batch, loss_and_grads=loss_and_grads, validate=validate,
                        config=dict(dataclasses.asdict(config), dtype=np.dtype(dtype).name, chunk_length=chunk,
                                    **keep))


def make_method(model) -> Callable:
    """``f(spline, average_speed) -> Spline`` with the tracks ``amplitude``, ``frequency``, ``direction``
    (:func:`refimpl.models.pace.predict`)."""
    def pace_method(spline, average_speed):
        return pace.predict(model.params, model.config, spline, average_speed)

    return pace_method


def export_inputs(model) -> dict:
    return {"metadata": {"frame_rate": float(model.fps or 30.0), "training": {"checkpoint_step": model.meta.get("step")}}}


def verify_onnx(model, runtime, x=None, seed: int = 0) -> dict:
    """The exported pace network (``runtime.pace``) against :func:`refimpl.models.pace.forward` on ``x (B, N, 2)``
    (default: 2 random paths of 50 points). Returns ``{"pace": max |Δ|, "ok": max |Δ| <= 1e-4}``."""
    if x is None:
        rng = np.random.default_rng(seed)
        x = np.stack([0.2 * rng.standard_normal((2, 50)), rng.uniform(0.3, 1.5, (2, 1)).repeat(50, 1)], axis=-1)
    dtype = np.asarray(model.params["h0"]).dtype
    ref, _ = pace.forward(model.params, model.config, np.asarray(x).astype(dtype))
    diff = float(np.abs(np.asarray(runtime.pace(x), np.float64) - ref).max())
    return {"pace": diff, "ok": diff <= 1e-4}
