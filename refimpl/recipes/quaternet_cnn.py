"""Recipe of the convolutional QuaterNet (Pavllo et al., IJCV 2019, §3.2, §4.1) on the ``prediction`` task
(spec/quaternet.md §5, §7).

The same training as the recurrent recipe (:mod:`refimpl.recipes.quaternet`: published batches, Adam 1e-3,
lr × 0.999 and teacher-forcing ratio × 0.995 per epoch, clipping 0.1, penalty 0.01, wrapped-Euler L1 or
``1 − p·q`` for teacher forcing) with the paper's CNN differences: a 32-frame conditioning window (its receptive
field, §4.1) and, under scheduled sampling, gradients only through the first term (the fed-back predictions are
constants, :func:`refimpl.models.quaternet_cnn.backward_scheduled`).

Shape legend: B batch, P prefix frames, T target frames, J joints.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.losses import QUATERNET_PENALTY_WEIGHT
from refimpl.models import quaternet_cnn as cnn
from refimpl.recipes import quaternet as rnn_recipe
from refimpl.schedules import QUATERNET_TF_DECAY
from refimpl.train import ModelAdapter

__all__ = ["param_shapes", "NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE", "EXPORTER", "PAPER_OPTIM",
           "PAPER_BATCH",
           "PAPER_PREFIX", "CNNShortTermConfig", "parse_skips", "make_config", "make_adapter", "predictor",
           "make_method", "export_inputs", "reference_outputs", "verify_onnx"]

NAME = "quaternet-cnn"
SUMMARY = ("QuaterNet convolutional pose network (IJCV 2019 §3.2; our reconstruction of the unreleased model): "
           "causal dilated convolutions, 32-frame window -> next frames, velocity mode")
TASK = "prediction"
REPRESENTATIONS = ("quat",)
EXPORTER = "quaternet-cnn"
PAPER_OPTIM = rnn_recipe.PAPER_OPTIM
PAPER_BATCH = rnn_recipe.PAPER_BATCH
#: The CNN conditions on n = 32 frames (its receptive field, §4.1).
PAPER_PREFIX = 32


def parse_skips(text: str) -> tuple:
    """``"0:2,1:3" -> ((0, 2), (1, 3))``; ``""`` -> ``()``."""
    out = []
    for item in str(text).split(","):
        if not item.strip():
            continue
        s, sep, k = item.partition(":")
        try:
            out.append((int(s), int(k)))
        except ValueError:
            raise ValueError(f"skips: expected pairs like '0:2,1:3', got {text!r}") from None
        if not sep:
            raise ValueError(f"skips: expected pairs like '0:2,1:3', got {text!r}")
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class CNNShortTermConfig:
    """Network sizes (:class:`~refimpl.models.quaternet_cnn.QuaterNetCNNConfig` fields; ``skips`` as text
    ``"s:k,..."``) and training settings (as :class:`~refimpl.recipes.quaternet.ShortTermConfig`)."""

    num_joints: int = 32
    channels: int = 1024
    kernel_sizes: tuple = (2, 2, 2, 2, 2)
    dilations: tuple = (1, 2, 4, 8, 16)
    skips: str = "0:2,1:3"
    activation: str = "relu"
    velocity: bool = True
    prefix_length: int = PAPER_PREFIX
    target_length: int = rnn_recipe.PAPER_TARGET
    schedule: str = "scheduled"
    tf_decay: float = QUATERNET_TF_DECAY
    loss: str = "auto"
    penalty_weight: float = QUATERNET_PENALTY_WEIGHT

    def __post_init__(self):
        object.__setattr__(self, "kernel_sizes", tuple(int(v) for v in self.kernel_sizes))
        object.__setattr__(self, "dilations", tuple(int(v) for v in self.dilations))
        self.network  # validates the network fields
        rnn_recipe.ShortTermConfig(num_joints=self.num_joints, prefix_length=self.prefix_length,
                                   target_length=self.target_length, schedule=self.schedule, tf_decay=self.tf_decay,
                                   loss=self.loss, penalty_weight=self.penalty_weight, hidden_size=1)

    @property
    def network(self) -> cnn.QuaterNetCNNConfig:
        return cnn.QuaterNetCNNConfig(num_joints=self.num_joints, channels=self.channels,
                                      kernel_sizes=self.kernel_sizes, dilations=self.dilations,
                                      skips=parse_skips(self.skips), activation=self.activation,
                                      velocity=self.velocity)

    @property
    def loss_kind(self) -> str:
        """``euler`` or ``quat`` (:func:`refimpl.recipes.quaternet.resolve_loss`)."""
        return rnn_recipe.resolve_loss(self.loss, self.schedule)

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["kernel_sizes"], d["dilations"] = list(self.kernel_sizes), list(self.dilations)
        return d


CONFIG_TYPE = CNNShortTermConfig


def param_shapes(config) -> dict:
    """Name -> shape of every parameter of the network ``config`` describes (the checkpoint schema's reference,
    spec/robustness.md §9): the model module's ``param_shapes`` of ``config.network``."""
    return cnn.param_shapes(config.network)


def make_config(train_ds, overrides: Sequence[str] = ()) -> CNNShortTermConfig:
    """The config for ``train_ds`` (its joint count) with ``--set`` overrides (``--set channels=256``,
    ``--set kernel_sizes=2,2,2,2,3``, ``--set skips=`` for none)."""
    return rnn_recipe.make_config(train_ds, overrides, config_type=CNNShortTermConfig)


class _ScheduledCNN:
    """:mod:`refimpl.models.quaternet_cnn` in the recurrent model's training interface (``forward(params,
    prefix, future, mask, config)``, ``backward(dy, dpre, cache)``, ``init_params``)."""

    forward = staticmethod(cnn.forward_scheduled)
    init_params = staticmethod(cnn.init_params)

    @staticmethod
    def backward(dy, dpre, cache):
        return cnn.backward_scheduled(dy, dpre, cache)


def make_adapter(train_ds, val_ds, config: CNNShortTermConfig, dtype, extra: Mapping) -> ModelAdapter:
    """:func:`refimpl.recipes.quaternet.make_adapter` with the CNN (first-term gradients under scheduled
    sampling)."""
    return rnn_recipe.make_adapter(train_ds, val_ds, config, dtype, extra, name=NAME, model_module=_ScheduledCNN)


def predictor(params: Mapping[str, np.ndarray], config: CNNShortTermConfig) -> Callable:
    """``f(prefix (B, P, J, 4), k) -> (B, k, J, 4)``: canonical prefix, then
    :func:`refimpl.models.quaternet_cnn.predict` (reads the last R frames)."""
    return rnn_recipe.network_method(cnn.predict, params, config.network, NAME)


def make_method(model) -> Callable:
    return predictor(model.params, model.config)


def export_inputs(model) -> dict:
    """As :func:`refimpl.recipes.quaternet.export_inputs`."""
    return rnn_recipe.export_inputs(model)


def reference_outputs(model, prefix, k: int) -> np.ndarray:
    """:func:`refimpl.models.quaternet_cnn.predict` of the raw prefix ``(B, P, J, 4)``, ``(B, k, J, 4)`` float64."""
    return rnn_recipe.raw_outputs(cnn.predict, model.params, model.config.network, prefix, k)


def verify_onnx(model, runtime, prefix, k: int = 10) -> dict:
    """Compare the exported window model, run ``k`` times by the runtime, with :func:`reference_outputs`:
    ``{"window_loop": max |Δ|, "ok": bool}``."""
    from refimpl.protocols.prediction import canonical_prefix
    from refimpl.testing import TOL_ORT_ROLLOUT

    prefix = canonical_prefix(prefix)   # the sign rule, as the predictor (the runtime repeats it)
    ref = reference_outputs(model, prefix, k)
    got = np.asarray(runtime.predict(np.asarray(prefix, np.float32), int(k)), np.float64)
    diff = np.abs(got - ref)
    ok = bool(np.all(diff <= TOL_ORT_ROLLOUT["atol"] + TOL_ORT_ROLLOUT["rtol"] * np.abs(ref)))
    return {"window_loop": float(diff.max()), "ok": ok}
