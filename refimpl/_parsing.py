"""Parsing helpers shared by the file readers (BVH, exp-map text, checkpoint metadata, ONNX metadata).

Private: the readers are the public boundary; these helpers only build their error messages and parse JSON
strictly (spec/robustness.md §1).
"""
from __future__ import annotations

import json
import math
from typing import Any

from refimpl.arrays import finite_float

__all__: list[str] = []


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not JSON (RFC 8259 has no NaN or Infinity)")


def _json_number(text: str) -> float:
    return finite_float(text, "JSON number")  # a number that overflows a float (1e999)


def json_loads_strict(text: str | bytes) -> Any:
    """``json.loads`` that refuses ``NaN``/``Infinity``/overflowing numbers and turns a too-deep document's
    ``RecursionError`` into ``ValueError``; it parses data only, nothing is ever executed."""
    try:
        return json.loads(text, parse_constant=_refuse_constant, parse_float=_json_number)
    except RecursionError as e:
        raise ValueError("JSON nested too deeply") from e


def locate_bad_row(lines: list[str], first: int, width: int, where: str, *, unit: str = "row",
                   commas: bool = False, expected: str = "values") -> ValueError:
    """Slow path, only after a fast whole-block parse failed: describe the first bad data line.

    Parameters
    ----------
    lines : list of str
        The file's lines.
    first : int
        Index of the first data line.
    width : int
        Numbers expected per line.
    where : str
        The file name, for ``"<file>:<line>: <unit> <k>: <problem>"``.
    unit, expected : str
        Words used in the message (``"frame"``/``"row"``; what the numbers are).
    commas : bool
        Commas separate numbers too (exp-map text).
    """
    row = 0
    for i in range(first, len(lines)):
        line = lines[i].replace(",", " ") if commas else lines[i]
        toks = line.split()
        if not toks:
            continue
        row += 1
        for t in toks:
            try:
                v = float(t)
            except ValueError:
                return ValueError(f"{where}:{i + 1}: {unit} {row}: non-numeric value {t!r}")
            if not math.isfinite(v):
                return ValueError(f"{where}:{i + 1}: {unit} {row}: non-finite value {t!r}")
        if len(toks) != width:
            return ValueError(f"{where}:{i + 1}: {unit} {row}: expected {width} {expected}, got {len(toks)}")
    return ValueError(f"{where}: malformed data")
