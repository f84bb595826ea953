"""Shipped trained models, loadable by name: ``pretrained:<name>`` wherever a checkpoint is accepted (spec/cli.md §10).

A shipped model is a folder ``<root>/<name>/`` holding

* ``model.npz`` — a weights-only ``refimpl train`` checkpoint (format ``refimpl.train/1``: the parameters under
  ``param.<name>`` and the metadata a checkpoint carries — model config, statistics, skeleton, task fields — but no
  optimiser state, sampler permutation or generator state, so it loads everywhere a checkpoint does and cannot be
  resumed);
* ``card.json`` — the model card as data (what it is, the data, split and licence, the training command, budget
  and wall time, the evaluation numbers with the command that reproduces them, library versions, sha256,
  parameter count, file size, inference time); :data:`CARD_FIELDS` are required;
* ``card.md`` — the same card for people (written from ``card.json`` by ``python -m experiments.pretrained``).

Roots, searched in order: the folders of ``$REFIMPL_PRETRAINED`` (``os.pathsep``-separated), then the repository's
``pretrained/`` folder beside the package (present in a clone and an editable install). The models trained on the
Bandai Namco set carry its CC BY-NC 4.0 terms, so none is inside the installed package (the wheel).

:func:`resolve_checkpoint` is the one way a command turns its ``--checkpoint`` text into a file: a plain path is
returned unchanged; ``pretrained:<name>`` is looked up and its ``model.npz`` verified against the card's sha256
before use. An unknown name, a missing or damaged file is :class:`~refimpl.errors.BadInputError` (exit 3).

Shape legend: none (files and dicts).
"""
from __future__ import annotations

import dataclasses
import hashlib
import os
from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl._parsing import json_loads_strict
from refimpl.errors import BadInputError

__all__ = ["PREFIX", "CARD_FIELDS", "ShippedModel", "roots", "catalogue", "find", "resolve_checkpoint",
           "shipped_name", "sha256_of", "weights_only"]

#: What ``--checkpoint`` starts with to name a shipped model.
PREFIX = "pretrained:"
#: The fields every ``card.json`` has (``experiments/pretrained.py`` writes them; ``tests/test_pretrained.py``).
CARD_FIELDS = ("name", "title", "system", "model", "file", "sha256", "size_bytes", "parameters", "data",
               "licence", "training", "evaluation", "inference", "versions")
#: Largest ``card.json`` read (a card is a few kB).
_CARD_MAX_BYTES = 1 << 20
_HASH_CHUNK = 1 << 20


@dataclasses.dataclass(frozen=True)
class ShippedModel:
    """One shipped model: its folder and its card (``card.json`` as a dict)."""

    name: str
    folder: Path
    card: dict

    @property
    def path(self) -> Path:
        """The model file (``card["file"]`` inside the folder)."""
        return self.folder / self.card["file"]


def roots() -> list[Path]:
    """The folders searched for shipped models, in order (module docstring)."""
    out = [Path(p) for p in os.environ.get("REFIMPL_PRETRAINED", "").split(os.pathsep) if p]
    out.append(Path(__file__).resolve().parents[1] / "pretrained")
    return out


def _read_card(path: Path) -> dict:
    if not path.is_file() or path.stat().st_size > _CARD_MAX_BYTES:
        raise BadInputError(f"{path}: not a model card (a regular file of at most {_CARD_MAX_BYTES} bytes)")
    try:
        card = json_loads_strict(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise BadInputError(f"{path}: unreadable model card ({exc})") from None
    if not isinstance(card, dict):
        raise BadInputError(f"{path}: model card: expected a JSON object")
    missing = [f for f in CARD_FIELDS if f not in card]
    if missing:
        raise BadInputError(f"{path}: model card lacks {', '.join(missing)}")
    if not isinstance(card["file"], str) or Path(card["file"]).name != card["file"]:
        raise BadInputError(f"{path}: model card: 'file' must be a file name inside the card's folder")
    if not isinstance(card["sha256"], str) or len(card["sha256"]) != 64:
        raise BadInputError(f"{path}: model card: 'sha256' must be 64 hexadecimal digits")
    return card


def catalogue() -> dict[str, ShippedModel]:
    """Every shipped model found under :func:`roots` (the first root that has a name wins), by name."""
    found: dict[str, ShippedModel] = {}
    for root in roots():
        if not root.is_dir():
            continue
        for card_path in sorted(root.glob("*/card.json")):
            name = card_path.parent.name
            if name not in found:
                found[name] = ShippedModel(name, card_path.parent, _read_card(card_path))
    return found


def shipped_name(text) -> str | None:
    """The shipped model's name when a ``--checkpoint`` value is ``pretrained:<name>``, else None."""
    if isinstance(text, str) and text.startswith(PREFIX):
        return text[len(PREFIX):]
    return None


def find(name: str) -> ShippedModel:
    """The shipped model ``name`` (without the prefix); unknown names are :class:`BadInputError`."""
    models = catalogue()
    if name not in models:
        where = ", ".join(str(r) for r in roots())
        known = ", ".join(sorted(models)) or "none found"
        raise BadInputError(f"{PREFIX}{name}: no such shipped model (known: {known}; searched {where}; "
                            f"`refimpl pretrained` lists them)")
    return models[name]


def sha256_of(path) -> str:
    """Hex SHA-256 of a regular file's bytes (read in 1 MiB chunks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(_HASH_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def resolve_checkpoint(text) -> Path:
    """The checkpoint file a ``--checkpoint`` value names: a plain path unchanged, ``pretrained:<name>`` the
    shipped model's file once its sha256 matches its card.

    Raises
    ------
    BadInputError
        Unknown name, missing file, or a file whose sha256 is not the card's (damaged or replaced).
    """
    name = shipped_name(text)
    if name is None:
        return Path(text)
    model = find(name)
    p = model.path
    if not p.is_file():
        raise BadInputError(f"{text}: its file {p} is missing (a clone without the file? see its card.md)")
    digest = sha256_of(p)
    if digest != model.card["sha256"].lower():
        raise BadInputError(f"{text}: {p} is damaged or replaced (sha256 {digest[:12]}…, the card says "
                            f"{model.card['sha256'][:12]}…)")
    return p


#: Training-only entries of a checkpoint's metadata (resuming needs them; a shipped model does not).
_TRAINING_META = ("rng_state", "position", "lr", "num_examples", "train_config")


def weights_only(arrays: Mapping[str, np.ndarray], meta: Mapping) -> tuple[dict, dict]:
    """``(arrays, meta)`` of a training checkpoint without the optimiser, sampler and generator state.

    Keeps every ``param.<name>`` array and the metadata a loaded model reads (``format``, ``model``,
    ``model_config``, ``step``, ``epoch``, ...); the result loads with :func:`refimpl.services.load_trained` like
    the original, with bit-identical parameters.
    """
    kept = {k: v for k, v in arrays.items() if k.startswith("param.")}
    if not kept:
        raise ValueError("weights_only: no param.<name> arrays (not a training checkpoint)")
    return kept, {k: v for k, v in meta.items() if k not in _TRAINING_META}
