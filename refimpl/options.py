"""Command-line option types and groups shared by ``refimpl``'s commands and the tasks' own options.

argparse ``type`` callables that convert and check a value (a bad one is a usage error, exit 2), and the data
options every training / evaluation command takes (:func:`add_data_options`).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from typing import Mapping, Sequence

from refimpl.bounds import bounded_float, bounded_int, check_config_sizes
from refimpl.errors import UsageError

__all__ = ["number_parser", "positive_int", "nonneg_int", "positive_float", "beta", "add_data_options",
           "add_export_length_option", "export_length", "parse_overrides", "check_overrides", "config_with_overrides"]


def number_parser(convert, accept, expected: str):
    """An argparse ``type`` that converts with ``convert`` and accepts the value when ``accept(value)``."""
    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not accept(v):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return v
    return parse


positive_int = number_parser(int, lambda v: v >= 1, "a positive integer")
nonneg_int = number_parser(int, lambda v: v >= 0, "an integer >= 0")
positive_float = number_parser(float, lambda v: math.isfinite(v) and v > 0, "a positive number")
#: Adam's β₁, β₂ (``--betas``): outside [0, 1) the bias correction divides by zero or changes sign.
beta = number_parser(float, lambda v: math.isfinite(v) and 0 <= v < 1, "a number in [0, 1)")


def add_data_options(p, default="sample") -> None:
    """``--data``, ``--fps``, ``--test-fraction``, ``--stride`` (train and eval)."""
    p.add_argument("--data", default=default,
                   help="'sample' (the embedded CMU sample, default), a folder like ../shared/data, a folder of "
                        ".bvh / exp-map .txt files (train/ and test/ sub-folders, or split by file), or one file "
                        "(split by time)")
    p.add_argument("--fps", type=bounded_float("fps"), default=None,
                   help="true frame rate of the files when the header is wrong (CMU salsa: 60)")
    p.add_argument("--test-fraction", type=float, default=0.2, help="held-out share when splitting (default 0.2)")
    p.add_argument("--stride", type=bounded_int("stride"), default=4, help="frames between window starts (default 4)")


def add_export_length_option(p) -> None:
    """``refimpl export --transition-length``: the frames of an exported fixed-length graph (QTG's rollout,
    QuaterNet's predict model), an option of every task's export; each task's ``export_options`` passes it on
    (:func:`export_length`)."""
    p.add_argument("--transition-length", type=bounded_int("transition_length"), default=None,
                   help="frames of the rollout / predict model (default: the model's)")


def export_length(args) -> dict:
    """The exporter's keyword ``{"T": n}`` of ``refimpl export --transition-length n``; ``{}`` when not given (the
    model's own length, its recipe's ``export_inputs``)."""
    return {"T": args.transition_length} if args.transition_length else {}


# ----------------------------------------------------------------------------------------------------------------
# --set FIELD=VALUE overrides of a model config (every recipe's make_config)
# ----------------------------------------------------------------------------------------------------------------

#: Accepted spellings of a boolean ``--set`` value (anything else is a usage error, never silently False).
_BOOL_WORDS = {"1": True, "true": True, "yes": True, "on": True, "0": False, "false": False, "no": False, "off": False}


def parse_overrides(config_type, defaults: Mapping, overrides: Sequence[str]) -> dict:
    """``["gru_hidden=128", "encoder_sizes=128,64"]`` -> typed values, by the type of the default.

    Tuples are comma-separated integers; booleans one of ``1/0, true/false, yes/no, on/off`` (any case); ints,
    finite floats and strings as written. Raises ``UsageError`` naming the item for an unknown field, a missing ``=`` or
    a value of the wrong type."""
    fields = {f.name for f in dataclasses.fields(config_type)}
    out = {}
    for item in overrides or ():
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in fields:
            raise UsageError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {sorted(fields)}")
        default = defaults[key]
        try:
            if isinstance(default, tuple):
                out[key] = tuple(int(v) for v in value.split(",") if v.strip())
            elif isinstance(default, bool):
                word = value.strip().lower()
                if word not in _BOOL_WORDS:
                    raise ValueError(word)
                out[key] = _BOOL_WORDS[word]
            elif isinstance(default, int):
                out[key] = int(value)
            elif isinstance(default, float):
                out[key] = float(value)
                if not math.isfinite(out[key]):
                    raise ValueError(value)
            else:
                out[key] = value
        except ValueError:
            raise UsageError(f"--set {item!r}: {value!r} is not a valid {type(default).__name__}") from None
    return out


def check_overrides(config_type, overrides: Sequence[str]) -> dict:
    """Validate ``--set`` items against ``config_type`` alone, before any data is read: the field exists and the
    value parses as the type of the field's default (fields the data fills in, without a default, are checked
    by name only; :func:`config_with_overrides` checks them against the data). Returns the parsed values of the
    fields that have defaults. Raises ``UsageError`` as :func:`parse_overrides` does."""
    defaults = {}
    for f in dataclasses.fields(config_type):
        if f.default is not dataclasses.MISSING:
            defaults[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
            defaults[f.name] = f.default_factory()  # type: ignore[misc]
    known = [item for item in overrides or () if item.partition("=")[0].strip().replace("-", "_") in defaults]
    unknown_default = [item for item in overrides or () if item not in known]
    parse_overrides(config_type, {**{f.name: "" for f in dataclasses.fields(config_type)}, **defaults},
                    unknown_default)  # names (and the FIELD=VALUE form) of the rest
    return parse_overrides(config_type, defaults, known)


def config_with_overrides(base, overrides: Sequence[str], fixed: str | Sequence[str] | None = None,
                          fixed_note: str = ""):
    """``base`` (a config dataclass) with the ``--set`` ``overrides`` (:func:`parse_overrides`). ``fixed`` names a
    field (or a sequence of fields) the data or the model determines: overriding it with another value than ``base``'s raises
    ``UsageError("--set <fixed>=<value>: <fixed_note>")``; a value the config refuses, or a size beyond
    :mod:`refimpl.bounds` (:func:`~refimpl.bounds.check_config_sizes`), raises ``UsageError``."""
    values = parse_overrides(type(base), dataclasses.asdict(base), overrides)
    try:
        check_config_sizes(values)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for name in ((fixed,) if isinstance(fixed, str) else tuple(fixed or ())):
        if name in values and values[name] != getattr(base, name):
            raise UsageError(f"--set {name}={values[name]}: {fixed_note}")
    try:
        return dataclasses.replace(base, **values)
    except ValueError as exc:
        raise UsageError(f"--set: {exc}") from None
