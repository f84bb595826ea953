"""Exponential-map text files of the short-term prediction benchmarks (spec/data.md §4).

One frame per line, comma-separated floats (whitespace is accepted too), in triplets:

* ``layout="h36m"`` — 99 values = 33 triplets (Jain et al. / Martinez et al. Human3.6M release, 50 Hz):
  triplet 0 is a "corrupted" root translation that QuaterNet discards (the root position is set to 0; pass
  ``use_root_position=True`` to keep it), triplets 1..32 are the exp-maps of the 32 joints of
  :func:`refimpl.skeletons.h36m_skeleton`.
* ``layout="cmu"`` — 117 values = 39 triplets (Li et al. 2018 CMU format as shipped by DMGNN): the root
  position (Y up, equal to the BVH position channels) then the exp-maps of the 38 joints of
  :func:`refimpl.skeletons.cmu_asf_skeleton` (joint 0 = root rotation, End Sites included, always zero).

Sign convention: the files store rotation vectors in the row-vector convention (``R(r)ᵀ`` is the column-vector
rotation), so, as in QuaterNet's data preparation (spec/data.md §4), each joint's
quaternion is ``quat_from_axis_angle(−r)``, then ``quat_fix`` over time. For the CMU files this reproduces the
rotation matrices of the BVH ``Zrotation Yrotation Xrotation`` channels of the same trial to about 1e-8 for
every non-root joint (spec/data.md §4; the root agrees only to about 1e-2).

Shape legend: T frames, J joints.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from refimpl._parsing import locate_bad_row
from refimpl.files import read_bytes
from refimpl.motion import Motion
from refimpl.quat import quat_fix
from refimpl.rotations import quat_from_axis_angle
from refimpl.skeletons import cmu_asf_skeleton, h36m_skeleton

__all__ = ["read_expmap", "EXPMAP_LAYOUTS", "MAX_EXPMAP_VALUES"]

#: most numbers an exp-map file may hold (rows × values per row; 800 MB of float64)
MAX_EXPMAP_VALUES = 100_000_000

EXPMAP_LAYOUTS = {
    # layout: (values per row, default frame time in seconds, root position kept by default)
    "h36m": (99, 1.0 / 50.0, False),
    "cmu": (117, 1.0 / 120.0, True),
}



def read_expmap(path, layout: str = "cmu", frame_time: float | None = None, name: str | None = None,
                use_root_position: bool | None = None) -> Motion:
    """Read an exp-map text file into a :class:`~refimpl.motion.Motion` on a built-in skeleton.

    Parameters
    ----------
    path : str or os.PathLike
    layout : {"cmu", "h36m"}
        117 values per row on the 38-joint CMU ASF skeleton, or 99 values per row on the 32-joint H3.6M one.
    frame_time : float, optional
        Seconds per frame. Default 1/120 for ``"cmu"`` (verified for ``walking_1`` = CMU 02_01; the other
        files' trials are not documented) and 1/50 for ``"h36m"``.
    name : str, optional
        Default: the file stem.
    use_root_position : bool, optional
        Keep the first triplet as the root position. Default True for ``"cmu"``, False for ``"h36m"``
        (QuaterNet: the H3.6M triplet is corrupted, the trajectory is zero).

    Returns
    -------
    Motion
        Rotations ``(T, J, 4)`` = ``quat_fix(quat_from_axis_angle(−r))``, root positions ``(T, 3)``.

    Raises
    ------
    ValueError
        Unknown layout, or ``"<file>:<line>: <problem>"`` for a line without exactly the layout's number of
        values (each non-blank line is one frame), non-numeric or non-finite values, NUL bytes, an empty file,
        more than ``MAX_EXPMAP_VALUES`` numbers.
    """
    if layout not in EXPMAP_LAYOUTS:
        raise ValueError(f"layout: expected one of {sorted(EXPMAP_LAYOUTS)}, got {layout!r}")
    width, default_dt, default_root = EXPMAP_LAYOUTS[layout]
    where = os.fspath(path)
    try:
        text = read_bytes(path).decode("utf-8-sig")
    except OSError as exc:
        raise ValueError(f"path: cannot read {where!r}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{where}: not a UTF-8/ASCII text file ({exc})") from None
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    nul = text.find("\x00")
    if nul >= 0:
        raise ValueError(f"{where}:{text.count(chr(10), 0, nul) + 1}: NUL byte (not a text file)")
    lines = text.split("\n")
    rows = [ln.replace(",", " ").split() for ln in lines]
    rows = [r for r in rows if r]
    if not rows:
        raise ValueError(f"{where}:1: empty file (expected rows of {width} values)")
    if len(rows) * width > MAX_EXPMAP_VALUES:
        raise ValueError(f"{where}: {len(rows)} rows × {width} values exceed MAX_EXPMAP_VALUES = {MAX_EXPMAP_VALUES}")
    if any(len(r) != width for r in rows):                                 # each line is one frame
        raise locate_bad_row(lines, 0, width, where, commas=True)
    try:
        flat = np.array([t for r in rows for t in r], dtype=np.float64)    # one conversion for all rows
    except ValueError:
        raise locate_bad_row(lines, 0, width, where, commas=True) from None
    if not np.all(np.isfinite(flat)):
        raise locate_bad_row(lines, 0, width, where, commas=True)
    values = flat.reshape(len(rows), width // 3, 3)                        # (T, 1 + J, 3)

    skel = cmu_asf_skeleton() if layout == "cmu" else h36m_skeleton()
    keep_root = default_root if use_root_position is None else bool(use_root_position)
    root_positions = values[:, 0, :].copy() if keep_root else np.zeros((values.shape[0], 3))
    rotations = quat_fix(quat_from_axis_angle(-values[:, 1:, :]))          # (T, J, 4)
    return Motion(skeleton=skel, rotations=rotations, root_positions=root_positions,
                  frame_time=default_dt if frame_time is None else frame_time,
                  name=Path(where).stem if name is None else name)
