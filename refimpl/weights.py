"""Weights trained elsewhere: PyTorch state dicts in, refimpl checkpoints out, and back (spec/import.md).

* :func:`read_state_dict` — a state dict file as ``name -> ndarray``: ``.npz`` (``np.savez``), ``.safetensors``
  (:mod:`refimpl.safetensors`, NumPy only), ``.pt``/``.pth``/``.bin`` only through
  ``torch.load(weights_only=True)`` when torch is installed (never unpickled otherwise). A ``module.`` prefix on
  every name (``DistributedDataParallel``) is removed; float16 / bfloat16 tensors become float32.
* :func:`layout_names` — the name map of a model in a layout: ``"published"`` (the published code's names, from
  the recipe's ``published_names(config)``: QuaterNet short-term and long-term, the pace network, acRNN's
  ``lstm1..3``) or ``"refimpl"`` (the project's own names, identical to a PyTorch module that follows
  spec/architecture.md's layout).
* :func:`to_refimpl` / :func:`from_refimpl` — rename (and reshape where a layout differs, e.g. the pace network's
  ``eos``), refusing missing, unexpected and mis-shaped entries with one message.
* :func:`import_checkpoint` — state dict + model + layout + the task's training data → the arrays and metadata of
  a normal ``refimpl train`` checkpoint (format ``refimpl.train/1``, step 0): the config from the recipe
  (``make_config`` with the layout's settings, e.g. acRNN's skewed stack, then ``--set``), the task's statistics
  and skeleton exactly as ``refimpl train`` stores them (the recipe's ``make_adapter(...).config``), and an
  ``imported`` record (source file name, SHA-256, layout). The result passes the checkpoint schema
  (:func:`refimpl.checkpoint_schema.validate_trained`) before it is returned.
* :func:`export_state_dict` / :func:`write_state_dict` — a trained model's parameters under a layout's names, as
  ``.npz`` or ``.safetensors`` (to fine-tune with PyTorch).

Every problem with a file is a ``ValueError`` whose message names the file (exit 3 through
:func:`refimpl.errors.reading`); a model without published code asked for ``--layout published`` is a
``UsageError``.

Shape legend: as each model's ``param_shapes``.
"""
from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from refimpl.atomic import atomic_path
from refimpl.checkpoint import load_state_dict_npz
from refimpl.checkpoint_schema import expected_param_shapes, validate_trained
from refimpl.errors import MissingDependency, UsageError
from refimpl.files import check_regular, open_regular
from refimpl.registry import MODELS, ModelSpec, TrainedModel, task_of
from refimpl.safetensors import is_safetensors, read_safetensors, write_safetensors

__all__ = ["LAYOUTS", "TORCH_SUFFIXES", "FORMAT", "read_state_dict", "layout_names", "to_refimpl", "from_refimpl",
           "import_checkpoint", "export_state_dict", "write_state_dict"]

#: ``--layout`` values.
LAYOUTS = ("published", "refimpl")
#: Suffixes read through ``torch.load(weights_only=True)``.
TORCH_SUFFIXES = (".pt", ".pth", ".bin")
#: The checkpoint format an import writes (the trainer's).
FORMAT = "refimpl.train/1"
_DDP_PREFIX = "module."
_SHOWN = 4


def _numeric(name: str, a, where: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype.kind not in "biuf" or a.dtype.hasobject:
        raise ValueError(f"{where}: entry {name!r} has dtype {a.dtype}; expected numbers")
    if a.dtype.kind == "f" and a.dtype.itemsize < 4:
        a = a.astype(np.float32)  # float16 (bfloat16 is float32 already): exact
    return a


def _read_torch(path: Path, where: str) -> dict:
    try:
        import torch
    except ImportError:
        raise MissingDependency(f"{where}: a PyTorch file needs torch (read only with torch.load(weights_only=True)); "
                         f"without torch save the state dict as .npz or .safetensors (spec/import.md)") from None
    try:
        with open_regular(path) as f:
            obj = torch.load(f, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many kinds for a bad or unsafe file
        raise ValueError(f"{where}: torch.load(weights_only=True) refused the file: {type(exc).__name__}: "
                         f"{str(exc).splitlines()[0][:200] if str(exc) else ''}") from None
    if not isinstance(obj, Mapping):
        raise ValueError(f"{where}: expected a state dict (name -> tensor), got {type(obj).__name__}")
    out = {}
    for k, v in obj.items():
        if not isinstance(v, torch.Tensor):
            hint = " (a training checkpoint? save model.state_dict() itself)" if isinstance(v, Mapping) else ""
            raise ValueError(f"{where}: entry {k!r} is a {type(v).__name__}, not a tensor{hint}")
        v = v.detach().cpu()
        out[str(k)] = (v.float() if v.dtype in (torch.bfloat16, torch.float16) else v).numpy()
    return out


def read_state_dict(path) -> dict[str, np.ndarray]:
    """A state dict file as ``name -> ndarray`` (module docstring for the formats).

    Raises
    ------
    ValueError
        Unreadable, malformed or not a state dict (a refimpl checkpoint, non-numeric entries, no entries).
    MissingDependency
        A PyTorch file without torch installed (exit 1; the message says to save .npz or .safetensors).
    OSError
        No file, a directory.
    """
    p = Path(path)
    where = str(p)
    check_regular(p)  # a FIFO or a device would block or never end (spec/robustness.md §13)
    suffix = p.suffix.lower()
    if suffix in TORCH_SUFFIXES:
        raw = _read_torch(p, where)
    elif suffix == ".safetensors" or (suffix != ".npz" and is_safetensors(p)):
        raw = read_safetensors(p)[0]
    elif suffix == ".npz" or zipfile.is_zipfile(p):
        raw = load_state_dict_npz(p)
        if any(k.startswith("param.") for k in raw):
            raise ValueError(f"{where}: already a refimpl checkpoint; use it directly (or `refimpl export-weights` "
                             f"for a PyTorch-named state dict)")
    else:
        raise ValueError(f"{where}: unknown weights file type {p.suffix!r} (expected .npz, .safetensors or "
                         f"{'/'.join(TORCH_SUFFIXES)})")
    if not raw:
        raise ValueError(f"{where}: holds no tensors")
    if all(k.startswith(_DDP_PREFIX) for k in raw):
        raw = {k[len(_DDP_PREFIX):]: v for k, v in raw.items()}
    return {k: _numeric(k, v, where) for k, v in raw.items()}


def layout_names(spec: ModelSpec, config, layout: str) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Our parameter name -> ``(name, shape)`` in ``layout`` for ``spec``'s network of ``config``.

    Raises
    ------
    UsageError
        An unknown layout, or ``"published"`` for a model without published code (QTG, the convolutional QuaterNet).
    """
    if layout == "refimpl":
        return {k: (k, s) for k, s in expected_param_shapes(spec, spec.config_type, config).items()}
    if layout != "published":
        raise UsageError(f"--layout {layout!r}: expected one of {list(LAYOUTS)}")
    fn = spec.published_names
    if fn is None:
        raise UsageError(f"--layout published: model {spec.name!r} has no published code to take names from; "
                         f"use --layout refimpl (spec/import.md)")
    return {k: (n, tuple(int(d) for d in s)) for k, (n, s) in fn(config).items()}


def _listing(names) -> str:
    names = sorted(names)
    return str(names[:_SHOWN])[:-1] + (f", ... {len(names) - _SHOWN} more]" if len(names) > _SHOWN else "]")


def to_refimpl(state: Mapping[str, np.ndarray], names: Mapping[str, tuple], shapes: Mapping[str, tuple],
               where: str = "state dict") -> dict:
    """``state`` (names of the layout) → our parameters, by ``names`` (:func:`layout_names`), reshaped to our
    ``shapes`` (our name -> shape, ``param_shapes``; the same sizes).

    Raises
    ------
    ValueError
        One message naming the missing, the unexpected and the mis-shaped entries (with the expected shapes).
    """
    wanted = {n: (ours, tuple(s)) for ours, (n, s) in names.items()}
    missing = [n for n in wanted if n not in state]
    extra = [n for n in state if n not in wanted]
    bad = [f"{n} {tuple(np.shape(state[n]))} (expected {wanted[n][1]})" for n in wanted
           if n in state and tuple(np.shape(state[n])) != wanted[n][1]]
    problems = ([f"missing {_listing(missing)}"] if missing else []) + \
               ([f"unexpected {_listing(extra)}"] if extra else []) + \
               ([f"wrong shapes: {'; '.join(bad[:_SHOWN])}" + (f"; ... {len(bad) - _SHOWN} more" if
                                                                len(bad) > _SHOWN else "")] if bad else [])
    if problems:
        raise ValueError(f"{where}: does not match the model: " + "; ".join(problems))
    out = {}
    for n, (ours, _) in wanted.items():
        a = np.asarray(state[n])
        if a.dtype.kind != "f":
            raise ValueError(f"{where}: entry {n!r} has dtype {a.dtype}; expected floating-point weights")
        out[ours] = a.reshape(shapes[ours])
    return out


def from_refimpl(params: Mapping[str, np.ndarray], names: Mapping[str, tuple]) -> dict[str, np.ndarray]:
    """Our parameters → a state dict in the layout of ``names`` (:func:`layout_names`; the inverse of
    :func:`to_refimpl`). Raises ValueError when ``params`` lacks one of ``names``."""
    missing = [k for k in names if k not in params]
    if missing:
        raise ValueError(f"params: missing {_listing(missing)}")
    return {n: np.asarray(params[k]).reshape(s) for k, (n, s) in names.items()}


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open_regular(path) as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def import_checkpoint(spec: ModelSpec, state: Mapping[str, np.ndarray], layout: str, train_ds, test_ds=None,
                      overrides: Sequence[str] = (), dtype=None, source=None) -> tuple[dict, dict]:
    """The arrays and metadata of a refimpl checkpoint holding ``state`` (see the module docstring).

    Parameters
    ----------
    spec : ModelSpec
    state : dict name -> ndarray
        The state dict (:func:`read_state_dict`), in ``layout``'s names.
    layout : ``"published"`` or ``"refimpl"``
    train_ds, test_ds
        The task's datasets (``task.train_datasets(args)``): they give the frame size, the statistics and the
        skeleton the checkpoint stores, as ``refimpl train`` would.
    overrides : sequence of ``FIELD=VALUE``
        ``--set`` (after the layout's settings, e.g. acRNN's ``skewed=true`` for ``published``).
    dtype : None, ``float32`` or ``float64``
        The parameters' dtype (default: the state dict's, which must be one).
    source : path, optional
        The file, recorded in the metadata (name and SHA-256).

    Returns
    -------
    arrays : dict ``param.<name>`` -> ndarray
    meta : dict

    Raises
    ------
    ValueError
        The state dict does not match the model's names and shapes (one line naming the entries; with the config
        fields to ``--set`` for a network of other sizes), or fails the checkpoint schema.
    UsageError
        A bad layout, ``--set`` value or dtype.
    """
    where = str(source) if source is not None else "state dict"
    settings = spec.published_settings if layout == "published" else ()
    config = spec.make_config(train_ds, (*settings, *overrides))
    names = layout_names(spec, config, layout)
    try:
        params = to_refimpl(state, names, expected_param_shapes(spec, spec.config_type, config), where)
    except ValueError as exc:
        other = next((o for o in LAYOUTS if o != layout), None)
        try:
            if set(state) != {n for n, _ in names.values()} and \
                    set(state) == {n for n, _ in layout_names(spec, config, other).values()}:
                raise ValueError(f"{exc} (these are the names of --layout {other})") from None
        except UsageError:
            pass
        fields = ", ".join(f.name for f in getattr(config, "__dataclass_fields__", {}).values())
        hint = spec.import_hint
        sizes = ("the names are right, the sizes another network's: its frame size follows the joint count of "
                 "--data's skeleton, so pass the data the weights were trained on (H3.6M weights: H3.6M data); "
                 if set(state) == {n for n, _ in names.values()} else "")
        raise ValueError(f"{exc} (model {spec.name!r}, layout {layout!r}; {sizes}other layer sizes: --set one of "
                         f"{fields}"
                         + (f"; {hint}" if hint else "") + ")") from None
    kinds = sorted({a.dtype.name for a in params.values()})
    if dtype is None:
        if len(kinds) != 1:
            raise ValueError(f"{where}: parameters of several dtypes {kinds}; pass --dtype")
        dtype = kinds[0]
    dtype = np.dtype(dtype)
    if dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise UsageError(f"--dtype {dtype}: expected float32 or float64")
    params = {k: np.ascontiguousarray(v, dtype=dtype) for k, v in params.items()}
    extra = dict(task_of(spec).checkpoint_extra(train_ds), representation=spec.representations[0])
    adapter = spec.make_adapter(train_ds, test_ds, config, dtype.type, extra)
    model_config = json.loads(json.dumps(dict(adapter.config), default=_json_default))
    meta = {"format": FORMAT, "model": spec.name, "model_config": model_config, "step": 0, "epoch": 0,
            "imported": {"layout": layout,
                         "source": os.path.basename(os.fspath(source)) if source is not None else None,
                         "sha256": _sha256(source) if source is not None else None}}
    arrays = {f"param.{k}": v for k, v in params.items()}
    validate_trained(arrays, meta, MODELS, where, task_of=task_of)
    return arrays, meta


def _json_default(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (tuple, set)):
        return list(x)
    raise TypeError(f"not JSON-serialisable: {type(x).__name__}")


def export_state_dict(model: TrainedModel, layout: str = "published") -> dict[str, np.ndarray]:
    """A trained model's parameters under ``layout``'s names and shapes (:func:`layout_names`)."""
    return from_refimpl(model.params, layout_names(model.spec, model.config, layout))


def write_state_dict(path, state: Mapping[str, np.ndarray], metadata: Mapping[str, str] | None = None) -> None:
    """Write ``state`` atomically as ``.npz`` (``np.load`` / ``torch.from_numpy`` read it) or ``.safetensors``
    (with ``metadata``), by the suffix of ``path``. Raises UsageError for another suffix."""
    p = Path(path)
    if p.suffix.lower() == ".safetensors":
        write_safetensors(p, state, dict(metadata or {}))
    elif p.suffix.lower() == ".npz":
        with atomic_path(p) as tmp, open(tmp, "wb") as f:
            np.savez(f, **{k: np.asarray(v) for k, v in state.items()})
    else:
        raise UsageError(f"--out {p}: expected a .npz or .safetensors file name")
