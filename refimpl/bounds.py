"""Bounds on every size a command-line option or a runtime argument can ask for (spec/cli.md §1.1).

One table, :data:`BOUNDS`, used in three places so that they cannot disagree: the argparse ``type`` callables of
``refimpl``'s options (:func:`bounded_int`, :func:`bounded_float`; a value outside is a usage error, exit 2),
``--set`` overrides of a model's config (:func:`check_config_sizes`, :func:`check_parameter_count`) and the
onnxruntime wrappers in ``deploy/models/*_io.py`` (:func:`check_count`, raising ``ValueError``). Nothing a user
types can make a command work longer than its honest work on a bounded size or allocate beyond these bounds.

The numbers are generous for the papers' settings (QTG T = 30, QuaterNet 10-100 frames, acRNN 1,000 frames,
the locomotion demos 10-60 s, hidden sizes 1,000-1,024, 2-3 layers) and small enough that the largest request
finishes in minutes on one core.
"""
from __future__ import annotations

import argparse
import math
import numbers
from typing import Mapping

import numpy as np

__all__ = ["Bound", "BOUNDS", "MAX_FRAMES", "MAX_TRANSITION_FRAMES", "MAX_CONFIG_SIZE", "MAX_CONFIG_LIST",
           "MAX_LAYERS", "MAX_PARAMETERS", "bounded_int", "bounded_float", "check_count", "check_number",
           "check_config_sizes", "check_parameter_count"]


class Bound:
    """An inclusive range ``[lo, hi]`` of one kind of size, with what it counts (for messages and the spec)."""

    def __init__(self, lo, hi, what: str):
        self.lo, self.hi, self.what = lo, hi, what

    def __repr__(self) -> str:
        return f"[{self.lo:g}, {self.hi:g}] {self.what}"


#: Frames generated or predicted in one call (``--length``, ``k``, ``num_frames``, a clip's frames).
MAX_FRAMES = 100_000
#: Frames of one QTG transition (``--transition-length``, ``qtg_io.Runtime.transition``'s ``T``).
MAX_TRANSITION_FRAMES = 10_000
#: Largest integer a ``--set`` override may give a config field (sizes, lengths), and the longest size list.
MAX_CONFIG_SIZE = 100_000
MAX_CONFIG_LIST = 64
#: Largest layer count (``--set num_layers=``, ``gru_layers=``; one list entry per layer for size lists).
MAX_LAYERS = 64
#: Largest number of network parameters a ``--set`` override may ask for (4e8 bytes in float32).
MAX_PARAMETERS = 100_000_000

#: name -> Bound. Spec/cli.md §1.1 prints this table.
BOUNDS: dict[str, Bound] = {
    "frames": Bound(1, MAX_FRAMES, "frames generated or predicted (--length, k, num_frames)"),
    "transition_length": Bound(1, MAX_TRANSITION_FRAMES, "frames of a transition (--transition-length, T)"),
    "context": Bound(1, 10_000, "frames kept around a transition (--context)"),
    "seconds": Bound(0.1, 3_000.0, "seconds of generated locomotion (--seconds)"),
    "speed": Bound(0.01, 5.0, "units per frame of generated locomotion (--speed)"),
    "path_metres": Bound(0.25, 1_000.0, "size of a built-in path in metres (circle:r=, figure8:size=)"),
    "path_turn": Bound(-3_600.0, 3_600.0, "turn of line-turn in degrees (line-turn:turn=)"),
    "path_csv_metres": Bound(-10_000.0, 10_000.0, "coordinates of a --path CSV file, metres"),
    "path_length_metres": Bound(0.0, 10_000.0, "length of a path in metres"),
    "samples": Bound(1, 100_000, "samples per sequence (--samples-per-sequence)"),
    "downsample": Bound(1, 100, "decimation factor (--downsample)"),
    "window": Bound(1, MAX_FRAMES, "frames of a training window (--window-length, --locomotion-prefix/-target)"),
    "files": Bound(0, 1_000_000, "files read (--locomotion-max-files; 0 = all)"),
    "chunk": Bound(0, MAX_FRAMES, "spline points per pace-network chunk (--pace-chunk-length; 0 = the data's)"),
    "stride": Bound(1, MAX_FRAMES, "frames between windows (--stride)"),
    "batch": Bound(1, 1_000_000, "windows per batch (--batch-size)"),
    "steps": Bound(0, 10**9, "optimiser steps or epochs (--steps, --epochs)"),
    "every": Bound(1, 10**9, "steps between checkpoints / validations / progress lines"),
    "panels": Bound(1, 1_000, "panels of a picture (--num-frames)"),
    "threads": Bound(0, 1_024, "BLAS threads (--blas-threads; 0 = the library's default)"),
    "ort_threads": Bound(1, 256, "onnxruntime threads (python -m deploy run --threads)"),
    "fps": Bound(1.0, 1_000.0, "frames per second (--fps, --source-fps)"),
    "frame_index": Bound(0, MAX_FRAMES, "a frame of a clip (--start, --source-frame)"),
    "config_int": Bound(-MAX_CONFIG_SIZE, MAX_CONFIG_SIZE, "an integer of a --set override (sizes, lengths)"),
    "layers": Bound(1, MAX_LAYERS, "layers of a network (--set num_layers=, gru_layers=, size lists)"),
    "parameters": Bound(1, MAX_PARAMETERS, "network parameters implied by a config"),
}


def _fmt(v) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


def _in(bound: Bound, v) -> bool:
    return bound.lo <= v <= bound.hi


def _bounded(name: str, convert, expected: str, finite: bool):
    bound = BOUNDS[name]
    span = f"[{_fmt(bound.lo)}, {_fmt(bound.hi)}]"

    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected} in {span}, got {text!r}") from None
        if (finite and not math.isfinite(v)) or not _in(bound, v):
            raise argparse.ArgumentTypeError(f"expected {expected} in {span} ({bound.what}), got {text!r}")
        return v
    parse.__name__ = f"{name} ({expected} in {span})"
    return parse


def bounded_int(name: str):
    """An argparse ``type``: an integer within ``BOUNDS[name]`` (else ``ArgumentTypeError``, exit 2)."""
    return _bounded(name, int, "an integer", finite=False)


def bounded_float(name: str):
    """An argparse ``type``: a finite number within ``BOUNDS[name]`` (else ``ArgumentTypeError``, exit 2)."""
    return _bounded(name, float, "a number", finite=True)


def check_number(value, name: str, bound: str) -> float:
    """``value`` as a float within ``BOUNDS[bound]``; ``ValueError`` naming ``name`` otherwise (a bool, a string,
    NaN or a complex number is refused, not converted)."""
    b = BOUNDS[bound]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.integer, np.floating)):
        raise ValueError(f"{name}: expected a number in [{b.lo:g}, {b.hi:g}], got {type(value).__name__}")
    v = float(value)
    if not (math.isfinite(v) and _in(b, v)):
        raise ValueError(f"{name}: expected a number in [{b.lo:g}, {b.hi:g}] ({b.what}), got {value!r}")
    return v


def check_count(value, name: str, bound: str = "frames") -> int:
    """``value`` as an int within ``BOUNDS[bound]``; ``ValueError`` naming ``name`` otherwise.

    Refused, never converted: ``bool``, strings, floats (``3.0`` and ``3.5`` alike), 0-d or larger arrays of any
    kind other than an integer scalar, ``None``. Python and NumPy integers are accepted.
    """
    b = BOUNDS[bound]
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iu":
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer in [{b.lo}, {b.hi}] ({b.what}), got "
                         f"{type(value).__name__} {value!r:.40}")
    v = int(value)
    if not _in(b, v):
        raise ValueError(f"{name}: expected an integer in [{b.lo}, {b.hi}] ({b.what}), got {v}")
    return v


def _is_int(x) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


_LAYER_FIELDS = ("num_layers", "gru_layers", "lstm_layers", "layers")


def check_config_sizes(values: Mapping, where: str = "--set") -> None:
    """Every integer of ``values`` (field -> value, tuples included) within ``BOUNDS["config_int"]``, tuples of
    at most :data:`MAX_CONFIG_LIST` entries, layer counts within ``BOUNDS["layers"]``; ``ValueError`` naming
    ``<where> <field>``."""
    for key, value in values.items():
        items = value if isinstance(value, (tuple, list)) else (value,)
        if isinstance(value, (tuple, list)) and len(value) > MAX_CONFIG_LIST:
            raise ValueError(f"{where} {key}: {len(value)} entries, more than the limit {MAX_CONFIG_LIST}")
        for x in items:
            if _is_int(x) and not _in(BOUNDS["config_int"], x):
                raise ValueError(f"{where} {key}: {x} is beyond the limit {MAX_CONFIG_SIZE} for a size")
        if key in _LAYER_FIELDS and _is_int(value) and value > MAX_LAYERS:
            raise ValueError(f"{where} {key}: {value} layers, more than the limit {MAX_LAYERS}")


def check_parameter_count(shapes: Mapping[str, tuple], where: str = "config") -> int:
    """The number of parameters of ``shapes`` (name -> shape); ``ValueError`` above :data:`MAX_PARAMETERS`."""
    total = sum(math.prod(int(d) for d in s) for s in shapes.values())
    if total > MAX_PARAMETERS:
        raise ValueError(f"{where}: {total:,} network parameters, more than the limit {MAX_PARAMETERS:,} "
                         f"({4 * MAX_PARAMETERS / 1e9:g} GB in float32)")
    return total
