"""The options of a training run, stored in its checkpoint so that ``refimpl train --resume`` reuses them
(spec/cli.md §4).

A run is decided by its model, representation, data (with its frame rate, held-out share and window stride),
``--set`` overrides, optimiser (the learning rate and betas stored as numbers), batch, dtype, seed and its task's
options; its budget and its checkpoint / validation / progress intervals (:data:`INTERVALS`) are in every
checkpoint's ``train_config`` (spec/cli.md §4). ``refimpl train`` stores them (:func:`run_options`) in the checkpoint's
``train_config["run_options"]``; on ``--resume`` (:func:`reconcile`) an option left at its default takes the
stored value, an option given with the stored value is accepted, and an option given with another value is a
conflict, reported field by field (for ``--set``: only the fields that differ) before any data is read.

Shapes: none (JSON-able values: str, int, float, lists).
"""
from __future__ import annotations

from typing import Iterable, Mapping

__all__ = ["RUN_OPTIONS", "INTERVALS", "run_options", "reconcile", "restore_intervals"]

#: The ``refimpl train`` options that decide a run (besides each task's own options).
RUN_OPTIONS = ("model", "representation", "data", "fps", "test_fraction", "stride", "set", "lr", "betas",
               "clip_norm", "batch_size", "dtype", "seed")

#: Options that shape a run's files but not its numbers: restored on ``--resume`` when not given (from the
#: checkpoint's ``train_config``, which every checkpoint holds), and free to change.
INTERVALS = ("checkpoint_every", "validate_every", "progress_every")


def _json(value):
    return list(value) if isinstance(value, tuple) else value


def run_options(args, names: Iterable[str]) -> dict:
    """``{name: value}`` of ``args`` for ``names`` (tuples as lists), as stored in the checkpoint."""
    return {n: _json(getattr(args, n)) for n in names if hasattr(args, n)}


def restore_intervals(args, train_config: Mapping, defaults: Mapping) -> None:
    """Set each :data:`INTERVALS` option of ``args`` left at its parser default to ``train_config``'s value."""
    for name in INTERVALS:
        if name in train_config and getattr(args, name, None) == defaults.get(name):
            setattr(args, name, train_config[name])


def _set_fields(items) -> dict:
    out = {}
    for item in items or ():
        key, _, value = str(item).partition("=")
        out[key.strip().replace("-", "_")] = value.strip()
    return out


def _shown(value) -> str:
    if isinstance(value, list):
        return " ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
    if value is None:
        return "none"
    return f"{value:g}" if isinstance(value, float) else str(value)


def reconcile(args, stored: Mapping, defaults: Mapping) -> list[str]:
    """Fill ``args`` from the ``stored`` options of a checkpoint; return the conflicts (one line each).

    An option whose value in ``args`` equals its parser default (``defaults``) was not given: it takes the stored
    value. A given option that differs from the stored one is a conflict, e.g.
    ``"--lr: the checkpoint has 0.001, the command line 0.01"``; for ``--set`` each differing field is one
    line (``"--set hidden_size: the checkpoint has 8, the command line 16"``), fields not given keep the stored
    value. ``args`` is changed in place only where there is no conflict.
    """
    conflicts = []
    for name, value in stored.items():
        if not hasattr(args, name):
            continue
        current = _json(getattr(args, name))
        if name == "set":
            given, kept = _set_fields(current), _set_fields(value)
            for k in sorted(set(given) | set(kept)):
                if k in given and given[k] != kept.get(k):
                    conflicts.append(f"--set {k}: the checkpoint has {kept.get(k, '(the default)')}, "
                                     f"the command line {given[k]}")
            if not any(c.startswith("--set ") for c in conflicts):
                args.set = list(value)
            continue
        if current == _json(defaults.get(name)):
            setattr(args, name, tuple(value) if isinstance(value, list) else value)
        elif current != value:
            conflicts.append(f"--{name.replace('_', '-')}: the checkpoint has {_shown(value)}, "
                             f"the command line {_shown(current)}")
    return conflicts
