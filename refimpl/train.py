"""A generic training loop: Adam, clipping, LR decay, logging, atomic checkpoints, exact resume (spec/qtg.md §10).

A model plugs in through a :class:`ModelAdapter` (plain callables, no subclassing):

* ``init_params(rng) -> dict`` — initial parameters (the trainer's Generator, so runs are reproducible);
* ``get_batch(indices, ctx) -> batch`` — the training examples ``indices`` (N,), plus any randomness
  (augmentation, scheduled-sampling masks) drawn from ``ctx.rng`` and any schedule read from
  ``ctx.epoch``/``ctx.step``;
* ``loss_and_grads(params, batch) -> (loss, grads)`` — a Python float and one gradient per parameter;
* ``validate(params) -> dict`` (optional) — metrics logged every ``validate_every`` steps.

Batches: one ``numpy.random.Generator`` (PCG64, ``seed``) initialises the parameters, then draws a permutation
of the ``num_examples`` training examples at the start of every epoch; an epoch is ``max(1, N // batch_size)``
consecutive slices of it (the remainder is dropped). The same Generator is handed to ``get_batch``.

Checkpoints (``refimpl.checkpoint``: atomic ``.npz``, no pickle, checksum; written and read by
:mod:`refimpl.train_files`) hold the parameters
(``param.<name>``), the Adam state (``optim.<key>``), the current permutation, and as metadata the step,
epoch, position in the epoch, the Generator state, the schedule state (current learning rate), both configs
and the adapter's config. Resuming restores all of it, so ``k`` steps + resume + ``N − k`` steps gives
bit-for-bit the parameters of ``N`` steps in one go (tested).

Failure handling (spec/robustness.md §10):

* a NaN/inf loss or gradient raises :class:`TrainingDiverged` before the parameters change; parameters or Adam
  state that become non-finite in an update (an absurd learning rate) raise it too, and nothing non-finite is
  ever saved (every save checks first); the last checkpoint on disk is left as it was. NumPy's floating-point
  warnings are silenced inside the loop (the trainer checks finiteness itself), so a divergence prints one
  message and no ``RuntimeWarning`` lines;
* ``KeyboardInterrupt`` (Ctrl-C, or raised by a callback), ``SIGINT`` and ``SIGTERM`` end the run at a step
  boundary: the state after the last completed step is checkpointed and the result is returned with
  ``interrupted=True`` and ``signal`` the signal number (2 or 15; None for a ``KeyboardInterrupt``);
* the checkpoint is locked (:func:`refimpl.train_files.output_lock`, a ``.<checkpoint name>.lock`` file beside
  it): a second trainer of the same checkpoint stops with :class:`~refimpl.train_files.OutputLocked`; a lock left
  by a dead process is taken over;
* temporary files of the atomic writer left beside the trainer's files by a killed run
  (``.checkpoint.<12 hex>.tmp.npz``, ``.loss.<12 hex>.tmp.csv``) are removed when the next run starts (it holds
  the lock, so no writer of those files is alive).
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import re
import signal
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from refimpl.progress import stderr_line
from refimpl.checkpoint import rng_from_json, rng_state_to_json
from refimpl.checkpoint_schema import MAX_PARAM_ABS, validate_training_state
from refimpl.optim import adam_init, adam_step, clip_grad_norm, exponential_lr
from refimpl.train_files import (TRAIN_FORMAT, CsvLog, load_state, output_lock, remove_stale_temp_files, save_state,
                                 truncate_csv)

__all__ = [
    "ModelAdapter", "OptimConfig", "TrainConfig", "TrainContext", "StepInfo", "TrainResult", "TrainingDiverged",
    "train", "format_duration",
]

_LOG_FIELDS = ("step", "epoch", "loss", "grad_norm", "lr", "elapsed_s")


class TrainingDiverged(RuntimeError):
    """A non-finite loss, gradient, parameter or optimiser state; no checkpoint was written with it."""


@dataclasses.dataclass(frozen=True)
class ModelAdapter:
    """How the trainer talks to a model (see the module docstring).

    Attributes
    ----------
    name : str
        Stored in checkpoints; resuming a checkpoint of another model raises ValueError.
    num_examples : int
        Size of the training set the indices refer to.
    init_params : callable ``rng -> dict``
    get_batch : callable ``(indices (B,), ctx: TrainContext) -> batch``
    loss_and_grads : callable ``(params, batch) -> (float, dict)``
    validate : callable ``params -> dict[str, float]``, optional
    config : dict
        JSON-friendly description of the model (stored in checkpoints, compared on resume).
    """

    name: str
    num_examples: int
    init_params: Callable[[np.random.Generator], dict]
    get_batch: Callable[[np.ndarray, "TrainContext"], Any]
    loss_and_grads: Callable[[dict, Any], tuple]
    validate: Callable[[dict], Mapping[str, float]] | None = None
    config: Mapping = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class OptimConfig:
    """Adam with optional global-norm clipping and per-epoch exponential LR decay.

    ``lr_epoch = lr · lr_decay^epoch`` (:func:`refimpl.optim.exponential_lr`). Defaults: Adam's own (Kingma & Ba;
    lr 1e-3, β = (0.9, 0.999)), no clipping, no decay. A model's paper values are named constants of its recipe
    (its ``PAPER_OPTIM``, :class:`refimpl.recipe_api.Recipe`).
    """

    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.999)
    eps: float = 1e-8
    weight_decay: float = 0.0
    clip_norm: float | None = None
    lr_decay: float = 1.0

    def to_dict(self) -> dict:
        return {"lr": self.lr, "betas": list(self.betas), "eps": self.eps, "weight_decay": self.weight_decay,
                "clip_norm": self.clip_norm, "lr_decay": self.lr_decay}


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Run settings.

    Attributes
    ----------
    steps : int
        Total optimiser steps of the run (a resumed run continues up to this number).
    batch_size : int
    seed : int
        Seed of the run's Generator (initialisation, shuffling, ``ctx.rng``).
    checkpoint_path : str, optional
        ``.npz`` file rewritten atomically every ``checkpoint_every`` steps and at the end.
    checkpoint_every : int
    log_path : str, optional
        CSV file with one row per ``log_every_csv`` steps (``step, epoch, loss, grad_norm, lr, elapsed_s``);
        validation metrics go to ``<stem>_val.csv``.
    log_every_csv : int
    progress_every : int
        Steps between progress lines (rate and ETA).
    validate_every : int, optional
    run_options : dict, optional
        The command line's options of the run (:mod:`refimpl.run_options`), stored in the checkpoint's
        ``train_config`` so that ``refimpl train --resume`` reuses them; the loop itself ignores them.
    """

    steps: int
    batch_size: int = 32
    seed: int = 0
    checkpoint_path: str | None = None
    checkpoint_every: int = 1000
    log_path: str | None = None
    log_every_csv: int = 1
    progress_every: int = 100
    validate_every: int | None = None
    run_options: dict | None = None

    def __post_init__(self):
        for name in ("steps", "batch_size", "checkpoint_every", "log_every_csv", "progress_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < (0 if name == "steps" else 1):
                raise ValueError(f"TrainConfig.{name}: expected a positive integer, got {v!r}")
        if self.validate_every is not None and (not isinstance(self.validate_every, int) or self.validate_every < 1):
            raise ValueError(f"TrainConfig.validate_every: expected a positive integer or None, "
                             f"got {self.validate_every!r}")


@dataclasses.dataclass(frozen=True)
class TrainContext:
    """What ``get_batch`` may use: the run's Generator and the schedule position of the coming step."""

    rng: np.random.Generator
    step: int
    epoch: int


@dataclasses.dataclass(frozen=True)
class StepInfo:
    """Passed to the per-step callback after each completed step (``step`` = steps done so far)."""

    step: int
    epoch: int
    loss: float
    grad_norm: float
    lr: float
    elapsed_s: float
    params: Mapping[str, np.ndarray]


@dataclasses.dataclass
class TrainResult:
    """Outcome of :func:`train`."""

    params: dict
    optim_state: dict
    step: int
    epoch: int
    losses: list
    interrupted: bool
    elapsed_s: float
    checkpoint_path: str | None
    validation: list
    signal: int | None = None


def format_duration(seconds: float) -> str:
    """``3723.4 -> '1h02m03s'``; ``42.0 -> '42s'``."""
    if not math.isfinite(seconds):
        return "?"
    s = int(round(seconds))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


def _kept(ckpt, step) -> str:
    if ckpt is None:
        return "no checkpoint path"
    return f"last checkpoint {ckpt} (step {step}) kept" if step is not None else "no checkpoint written"


def _first_beyond(arrays: Mapping[str, np.ndarray], limit: float):
    """``(name, magnitude)`` of the first array with an entry beyond ``limit`` in magnitude, else None."""
    for k, a in arrays.items():
        if a.size:
            m = float(np.max(np.abs(a)))
            if m > limit:
                return k, m
    return None


#: Messages of the layers' input checks that mean "a non-finite value reached me".
_NON_FINITE_TEXT = re.compile(r"NaN|nan|inf|non-finite|not finite|finite values")


def _first_non_finite(arrays: Mapping[str, np.ndarray]) -> str | None:
    for k, a in arrays.items():
        if not np.isfinite(a).all():
            return k
    return None


#: Signals that stop a run at the next step boundary (with a checkpoint): Ctrl-C and the schedulers' stop.
_STOP_SIGNALS = tuple(s for s in (getattr(signal, "SIGINT", None), getattr(signal, "SIGTERM", None)) if s is not None)


class _DeferSigint:
    """Turn SIGINT / SIGTERM into a flag checked at step boundaries (main thread only); a second one raises
    ``KeyboardInterrupt`` at once (the step in progress is dropped, the last completed one is saved)."""

    def __init__(self):
        self.requested = False
        self.signum = None
        self.old = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            def handler(signum, frame):
                if self.requested:
                    raise KeyboardInterrupt
                self.requested, self.signum = True, signum

            for s in _STOP_SIGNALS:
                self.old[s] = signal.getsignal(s)
                signal.signal(s, handler)
        return self

    def __exit__(self, *exc):
        for s, old in self.old.items():
            if old is not None:
                signal.signal(s, old)
        return False



# ----------------------------------------------------------------------------------------------------------------
# the loop
# ----------------------------------------------------------------------------------------------------------------

def train(adapter: ModelAdapter, optim: OptimConfig, config: TrainConfig, *, resume: bool = True,
          callback: Callable[[StepInfo], None] | None = None,
          progress: Callable[[str], None] | None = stderr_line) -> TrainResult:
    """Train ``adapter``'s model with Adam (spec/qtg.md §10).

    Parameters
    ----------
    adapter : ModelAdapter
    optim : OptimConfig
    config : TrainConfig
    resume : bool
        When ``config.checkpoint_path`` exists, continue from it (same model, optimiser and batch settings
        required); otherwise start fresh. With ``resume=False`` an existing checkpoint is overwritten.
    callback : callable, optional
        Called with a :class:`StepInfo` after every completed step; may raise ``KeyboardInterrupt`` to stop.
    progress : callable, optional
        Receives the progress lines (step, loss, it/s, ETA); default: print to stderr; None: silent.

    Returns
    -------
    TrainResult

    Raises
    ------
    TrainingDiverged
        On a NaN/inf loss or gradient (parameters unchanged), or parameters / Adam state that became non-finite
        in an update; the checkpoint on disk is the last good one.
    OutputLocked
        Another live process trains into the same checkpoint.
    ValueError
        Bad configuration, or a checkpoint that is damaged, fails the training-state schema
        (:func:`refimpl.checkpoint_schema.validate_training_state`) or does not match the
        adapter/optimiser/batch settings.
    """
    if not isinstance(adapter, ModelAdapter):
        raise ValueError(f"adapter: expected a ModelAdapter, got {type(adapter).__name__}")
    if not isinstance(optim, OptimConfig) or not isinstance(config, TrainConfig):
        raise ValueError("optim, config: expected an OptimConfig and a TrainConfig")
    N = int(adapter.num_examples)
    if N < 1:
        raise ValueError(f"adapter.num_examples: expected at least 1 example, got {N}")
    B = min(config.batch_size, N)
    per_epoch = max(1, N // B)
    ckpt = Path(config.checkpoint_path) if config.checkpoint_path else None
    identity = {"model": adapter.name, "model_config": _jsonable(adapter.config), "optim": optim.to_dict(),
                "batch_size": config.batch_size, "num_examples": N}
    with contextlib.ExitStack() as stack:
        if ckpt is not None:
            stack.enter_context(output_lock(ckpt.parent, f".{ckpt.name}.lock"))
            for target in (ckpt, config.log_path):
                if target is not None:
                    remove_stale_temp_files(target)
                    if target is config.log_path:
                        p = Path(target)
                        remove_stale_temp_files(p.with_name(p.stem + "_val.csv"))
        return _train_unlocked(adapter, optim, config, resume, callback, progress, N, B, per_epoch, ckpt, identity)


@dataclasses.dataclass
class _Run:
    """The mutable state of one training run (what a checkpoint stores, and the clock)."""

    params: dict
    opt_state: dict
    perm: np.ndarray
    rng: np.random.Generator
    step: int = 0
    epoch: int = 0
    pos: int = 0
    elapsed0: float = 0.0
    last_saved: int | None = None
    t0: float = 0.0

    def elapsed(self) -> float:
        return self.elapsed0 + (time.perf_counter() - self.t0)


def _start(adapter, config, resume, N, ckpt, identity) -> _Run:
    """The run's state: the checkpoint's (``resume``, checked against this run's ``identity``) or a fresh one."""
    if ckpt is not None and resume and ckpt.is_file():
        params, opt_state, perm, meta = load_state(ckpt)
        validate_training_state(params, opt_state, perm, meta, N, where=f"checkpoint {ckpt}")
        for key, value in identity.items():
            if _jsonable(meta.get(key)) != _jsonable(value):
                raise ValueError(f"checkpoint {ckpt}: {key} {meta.get(key)!r} does not match this run's {value!r}")
        step = int(meta["step"])
        return _Run(params, opt_state, perm, rng_from_json(meta["rng_state"]), step, int(meta["epoch"]),
                    int(meta["position"]), float(meta.get("elapsed_s", 0.0)), last_saved=step)
    rng = np.random.Generator(np.random.PCG64(config.seed))
    params = {k: np.array(v) for k, v in adapter.init_params(rng).items()}
    return _Run(params, adam_init(params), np.arange(N), rng)


def _open_logs(config, step: int) -> tuple[CsvLog, CsvLog]:
    """The loss log and the validation log (``<log>_val.csv``), cut back to ``step``."""
    log = CsvLog(Path(config.log_path) if config.log_path else None, _LOG_FIELDS)
    val_log = CsvLog(None if config.log_path is None else
                     Path(config.log_path).with_name(Path(config.log_path).stem + "_val.csv"), None)
    for lg in (log, val_log):
        if lg.path is not None:
            lg.path.parent.mkdir(parents=True, exist_ok=True)
            truncate_csv(lg.path, step)
    return log, val_log


def _save(run: _Run, name: str, optim, config, ckpt, identity) -> None:
    """Write the run's checkpoint (nothing without a path); never a non-finite or out-of-range one."""
    if ckpt is None:
        return
    bad = _first_non_finite(run.params) or _first_non_finite(run.opt_state) or \
        (_first_beyond(run.params, MAX_PARAM_ABS) or (None,))[0]
    if bad is not None:  # never reached by the loop's checks; a last line of defence
        raise TrainingDiverged(f"{name}: {bad!r} is not finite or beyond {MAX_PARAM_ABS:g} at step "
                               f"{run.step}; not saved, " + _kept(ckpt, run.last_saved))
    ckpt.parent.mkdir(parents=True, exist_ok=True)
    meta = dict(identity, format=TRAIN_FORMAT, step=run.step, epoch=run.epoch, position=run.pos,
                rng_state=rng_state_to_json(run.rng), lr=exponential_lr(optim.lr, optim.lr_decay, run.epoch),
                steps_target=config.steps, elapsed_s=run.elapsed(), train_config=dataclasses.asdict(config))
    save_state(ckpt, run.params, run.opt_state, run.perm, meta)
    run.last_saved = run.step


def _divergence(name: str, run: _Run, ckpt, *, loss=None, grads=None, lr=None) -> str | None:
    """Why the run diverged at this step, or None: a non-finite ``loss``, a non-finite gradient or one whose
    squares overflow (before the update, ``grads``), or after the update (``lr`` given) a parameter or Adam state
    that became non-finite or a parameter beyond the checkpoint limit :data:`MAX_PARAM_ABS`."""
    at = f"step {run.step + 1} (epoch {run.epoch}"
    left = f"parameters left at step {run.step}" + (f", last checkpoint {ckpt}" if ckpt is not None else "")
    if loss is not None and not math.isfinite(loss):
        return f"{name}: loss is {loss} at {at}); {left}"
    for k, g in (grads or {}).items():
        if not np.all(np.isfinite(g)):
            return f"{name}: gradient of {k!r} is not finite at {at}); {left}"
    for k, g in (grads or {}).items():
        if not math.isfinite(float(np.vdot(g, g))):  # Adam's second moment would overflow
            return f"{name}: the squares of the gradient of {k!r} overflow at {at}); {left}"
    if lr is None:
        return None
    bad = _first_non_finite(run.params) or _first_non_finite(run.opt_state)
    if bad is not None:
        return (f"{name}: {'parameter' if bad in run.params else 'Adam state'} {bad!r} became non-finite in the "
                f"update of {at}, learning rate {lr:g}); nothing saved"
                + (f", last checkpoint {ckpt} kept" if ckpt is not None else ""))
    big = _first_beyond(run.params, MAX_PARAM_ABS)
    if big is not None:  # the loader refuses such a checkpoint (checkpoint_schema.MAX_PARAM_ABS)
        return (f"{name}: training diverged at {at}, learning rate {lr:g}): parameter {big[0]!r} reached "
                f"magnitude {big[1]:.3g}, beyond the checkpoint limit {MAX_PARAM_ABS:g}; nothing saved, "
                + _kept(ckpt, run.last_saved))
    return None


def _forward(run: _Run, adapter, N: int, B: int, start_step: int, ckpt):
    """``(loss, grads)`` of the next batch, or None when interrupted (nothing of the step kept); TrainingDiverged
    when the forward pass or the gradients are not finite (the generator restored)."""
    snapshot = run.rng.bit_generator.state
    try:
        if run.pos == 0:
            run.perm = run.rng.permutation(N)
        idx = run.perm[run.pos * B:(run.pos + 1) * B]
        batch = adapter.get_batch(idx, TrainContext(rng=run.rng, step=run.step, epoch=run.epoch))
        loss, grads = adapter.loss_and_grads(run.params, batch)
    except KeyboardInterrupt:
        run.rng.bit_generator.state = snapshot  # nothing of this step is kept
        return None
    except ValueError as exc:
        if run.step == start_step or not _NON_FINITE_TEXT.search(str(exc)):
            raise
        # a layer refused the non-finite values the updated parameters produced: the run diverged
        run.rng.bit_generator.state = snapshot
        raise TrainingDiverged(f"{adapter.name}: training diverged at step {run.step + 1} (epoch {run.epoch}): "
                               f"the forward pass produced non-finite values ({exc}); parameters left at step "
                               f"{run.step}" + (f", last checkpoint {ckpt} kept" if ckpt is not None else "")) from None
    loss = float(loss)
    why = _divergence(adapter.name, run, ckpt, loss=loss, grads=grads)
    if why is not None:
        run.rng.bit_generator.state = snapshot
        raise TrainingDiverged(why)
    return loss, grads


def _update(run: _Run, adapter, optim, grads, per_epoch: int, ckpt) -> tuple[float, float]:
    """Clip, Adam, check, advance the counters; returns ``(grad_norm, lr)``."""
    lr = exponential_lr(optim.lr, optim.lr_decay, run.epoch)
    if optim.clip_norm is not None:
        gnorm = clip_grad_norm(grads, optim.clip_norm)
    else:
        gnorm = math.sqrt(math.fsum(float(np.vdot(g, g)) for g in grads.values()))
    adam_step(run.params, grads, run.opt_state, lr, betas=optim.betas, eps=optim.eps,
              weight_decay=optim.weight_decay)
    why = _divergence(adapter.name, run, ckpt, lr=lr)
    if why is not None:
        raise TrainingDiverged(why)
    run.step += 1
    run.pos += 1
    if run.pos == per_epoch:
        run.pos, run.epoch = 0, run.epoch + 1
    return gnorm, lr


class _Reporter:
    """What happens after a completed step: the CSV logs, validation, progress lines, checkpoints, callback."""

    def __init__(self, run, adapter, config, progress, callback, save):
        self.run, self.adapter, self.config = run, adapter, config
        self.progress, self.callback, self.save = progress, callback, save
        self.log, self.val_log = _open_logs(config, run.step)
        self.validation = []
        self.t_rate, self.step_rate = run.t0, run.step

    def after_step(self, loss: float, gnorm: float, lr: float) -> None:
        run, config = self.run, self.config
        step, elapsed = run.step, run.elapsed()
        if step % config.log_every_csv == 0 or step == config.steps:
            self.log.write({"step": step, "epoch": run.epoch, "loss": loss, "grad_norm": gnorm, "lr": lr,
                            "elapsed_s": round(elapsed, 3)})
        if self.adapter.validate is not None and config.validate_every and step % config.validate_every == 0:
            metrics = {k: float(v) for k, v in self.adapter.validate(run.params).items()}
            self.validation.append(dict(step=step, **metrics))
            self.val_log.write(dict(step=step, **metrics))
        if self.progress is not None and (step % config.progress_every == 0 or step == config.steps):
            self.progress(self._line(loss, lr, elapsed))
        if step % config.checkpoint_every == 0:
            self.save()
        if self.callback is not None:
            self.callback(StepInfo(step=step, epoch=run.epoch, loss=loss, grad_norm=gnorm, lr=lr,
                                   elapsed_s=elapsed, params=run.params))

    def _line(self, loss: float, lr: float, elapsed: float) -> str:
        step, steps = self.run.step, self.config.steps
        now = time.perf_counter()
        rate = (step - self.step_rate) / max(now - self.t_rate, 1e-9)
        self.t_rate, self.step_rate = now, step
        eta = (steps - step) / rate if rate > 0 else math.inf
        last = self.validation[-1] if self.validation else None
        val = "" if last is None or last["step"] != step else " | " + " ".join(
            f"{k} {v:.4g}" for k, v in last.items() if k != "step")
        return (f"[{self.adapter.name}] step {step}/{steps} epoch {self.run.epoch} loss {loss:.5g} lr {lr:.3g} | "
                f"{rate:.1f} it/s | elapsed {format_duration(elapsed)} ETA {format_duration(eta)}{val}")

    def close(self) -> None:
        self.log.close()
        self.val_log.close()


def _train_unlocked(adapter, optim, config, resume, callback, progress, N, B, per_epoch, ckpt, identity):
    run = _start(adapter, config, resume, N, ckpt, identity)
    run.t0 = time.perf_counter()
    report = _Reporter(run, adapter, config, progress, callback,
                       save=lambda: _save(run, adapter.name, optim, config, ckpt, identity))
    losses, interrupted, stopped_by, start_step = [], False, None, run.step
    try:
        with _DeferSigint() as sigint, np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            while run.step < config.steps:
                forward = _forward(run, adapter, N, B, start_step, ckpt)
                if forward is None:
                    interrupted = True
                    break
                loss, grads = forward
                gnorm, lr = _update(run, adapter, optim, grads, per_epoch, ckpt)
                losses.append(loss)
                try:  # the step is complete: an interrupt from here on keeps it
                    report.after_step(loss, gnorm, lr)
                except KeyboardInterrupt:
                    interrupted = True
                    break
                if sigint.requested:
                    interrupted = True
                    break
        stopped_by = sigint.signum
    finally:
        report.close()
    _save(run, adapter.name, optim, config, ckpt, identity)
    if interrupted and progress is not None:
        progress(f"[{adapter.name}] interrupted after step {run.step}; checkpoint "
                 f"{ckpt if ckpt is not None else '(none: no checkpoint_path)'}")
    return TrainResult(params=run.params, optim_state=run.opt_state, step=run.step, epoch=run.epoch, losses=losses,
                       interrupted=interrupted, elapsed_s=run.elapsed(),
                       checkpoint_path=None if ckpt is None else str(ckpt), validation=report.validation,
                       signal=stopped_by if interrupted else None)


def _jsonable(x):
    """Tuples -> lists, numpy scalars -> Python numbers (for comparing configs with JSON metadata)."""
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x
