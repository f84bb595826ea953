"""Command-line option types and groups shared by ``refimpl``'s commands and the tasks' own options.

argparse ``type`` callables that convert and check a value (a bad one is a usage error, exit 2), and the data
options every training / evaluation command takes (:func:`add_data_options`).
"""
from __future__ import annotations

import argparse
import math

__all__ = ["number_parser", "positive_int", "nonneg_int", "positive_float", "add_data_options"]


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


def add_data_options(p, default="sample") -> None:
    """``--data``, ``--fps``, ``--test-fraction``, ``--stride`` (train and eval)."""
    p.add_argument("--data", default=default,
                   help="'sample' (the embedded CMU sample, default), a folder like ../shared/data, a folder of "
                        ".bvh / exp-map .txt files (train/ and test/ sub-folders, or split by file), or one file "
                        "(split by time)")
    p.add_argument("--fps", type=positive_float, default=None,
                   help="true frame rate of the files when the header is wrong (CMU salsa: 60)")
    p.add_argument("--test-fraction", type=float, default=0.2, help="held-out share when splitting (default 0.2)")
    p.add_argument("--stride", type=positive_int, default=4, help="frames between window starts (default 4)")
