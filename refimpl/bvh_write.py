"""BVH (Biovision hierarchy) writing (spec/data.md §2); reading is in :mod:`refimpl.bvh`.

``write_bvh`` emits the standard syntax (tab indentation, ``End Site`` blocks, ROOT with 6 channels
``Xposition Yposition Zposition`` + rotations, other joints 3 rotation channels or 6 by ``position_channels``,
End Sites none) in the per-joint Euler orders requested, numbers in fixed-point with ``precision`` decimals,
written atomically (temporary file, fsync, ``os.replace``). Rotations are in degrees and compose in the listed
channel order, ``R = R_c0 · R_c1 · R_c2`` (``Zrotation Xrotation Yrotation`` is Euler order ``"zxy"``).

Shape legend: T frames, J joints, C channels per frame.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.motion import Motion
from refimpl.rotations import euler_from_quat
from refimpl.skeleton import Skeleton

__all__ = ["write_bvh"]


def _resolve_orders(order, skel: Skeleton) -> list[str]:
    ends = set(skel.end_sites)
    if isinstance(order, str):
        orders = [order] * skel.num_joints
    else:
        orders = list(order)
        if len(orders) != skel.num_joints:
            raise ValueError(f"order: expected one Euler order per joint ({skel.num_joints}), got {len(orders)}")
    out = []
    for j, o in enumerate(orders):
        if j in ends:
            out.append("")
            continue
        if not isinstance(o, str) or len(o) != 3 or sorted(o.lower()) != ["x", "y", "z"]:
            raise ValueError(f"order: joint {j} ({skel.names[j]!r}) needs a permutation of 'xyz' "
                             f"(Tait-Bryan, as BVH channels), got {o!r}")
        out.append(o.lower())
    return out


def _fmt(v, precision: int) -> str:
    return f"{v:.{precision}f}"


def write_bvh(path, motion: Motion, order: str | Sequence[str] = "zyx", precision: int = 6,
              position_channels: str = "auto") -> None:
    """Write a motion as a BVH file (atomically).

    Parameters
    ----------
    path : str or os.PathLike
    motion : Motion
    order : str or sequence of str
        Euler order of the rotation channels: one order for every joint, or one per joint (End Site entries
        are ignored; ``BvhHeader.rotation_orders`` keeps a file's layout). ``"zyx"`` writes the channels
        ``Zrotation Yrotation Xrotation`` (CMU files).
    precision : int
        Decimals of every number (fixed point), 1..17.
    position_channels : {"auto", "all", "root"}
        Which joints get ``Xposition Yposition Zposition`` channels (before their rotation channels):
        ``"auto"`` the root and the joints in ``motion.translated_joints`` (lossless); ``"all"`` every joint
        but the End Sites (Blender and Bandai Namco style; the values are the per-frame translations or the
        offsets); ``"root"`` the root only (``ValueError`` if the motion has per-frame translations).

    Notes
    -----
    Joints are written depth-first (children in increasing index order), the only order BVH has: a skeleton
    whose index order is not depth-first reads back permuted (same tree, same names); End Sites read back as
    ``<parent>_end``. The ROOT gets ``OFFSET = skeleton.offsets[0]`` and position channels
    ``root_positions − offsets[0]``;
    End Sites become ``End Site`` blocks (their rotation is not written); a leaf that is not an End Site is
    written as a JOINT without children. Joint names must not contain whitespace. Position channels replace
    the OFFSET (spec/data.md §2.1): the ROOT's hold ``root_positions``, another joint's its translation.
    """
    if not isinstance(motion, Motion):
        raise ValueError(f"motion: expected a Motion, got {type(motion).__name__}")
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)) or not 1 <= precision <= 17:
        raise ValueError(f"precision: expected an int in 1..17, got {precision!r}")
    if position_channels not in ("auto", "all", "root"):
        raise ValueError(f"position_channels: expected 'auto', 'all' or 'root', got {position_channels!r}")
    skel = motion.skeleton
    if position_channels == "root" and motion.translated_joints:
        raise ValueError(f"position_channels: 'root' would drop the per-frame translations of "
                         f"{list(motion.translated_joint_names)}; use 'auto' or 'all' (or "
                         "refimpl.motion.simplify_translations first)")
    orders = _resolve_orders(order, skel)
    for n in skel.names:
        if any(ch.isspace() for ch in n) or n in ("{", "}"):
            raise ValueError(f"motion.skeleton.names: BVH joint names cannot contain whitespace, got {n!r}")
    ends = set(skel.end_sites)
    p = int(precision)
    if position_channels == "all":
        with_pos = {j for j in range(skel.num_joints) if j not in ends}
    else:
        with_pos = {0, *motion.translated_joints}

    out = ["HIERARCHY"]
    written: list[int] = []  # joints with channels in the order their CHANNELS lines appear (depth-first)

    def offset_line(j: int, depth: int) -> str:
        return "\t" * depth + "OFFSET " + " ".join(_fmt(float(v), p) for v in skel.offsets[j])

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        if j in ends:
            out.extend([ind + "End Site", ind + "{", offset_line(j, depth + 1), ind + "}"])
            return
        out.append(ind + ("ROOT " if j == 0 else "JOINT ") + skel.names[j])
        out.append(ind + "{")
        out.append(offset_line(j, depth + 1))
        written.append(j)
        rot = " ".join(f"{a.upper()}rotation" for a in orders[j])
        if j in with_pos:
            out.append(ind + "\tCHANNELS 6 Xposition Yposition Zposition " + rot)
        else:
            out.append(ind + "\tCHANNELS 3 " + rot)
        for c in skel.children[j]:
            emit(c, depth + 1)
        out.append(ind + "}")

    emit(0, 0)
    num_frames = motion.num_frames
    out.append("MOTION")
    out.append(f"Frames: {num_frames}")
    out.append(f"Frame Time: {motion.frame_time:.10g}")

    rot = motion.rotations.astype(np.float64)
    local = (np.broadcast_to(skel.offsets, (num_frames,) + skel.offsets.shape) if motion.translations is None
             else motion.translations).astype(np.float64)                  # (T, J, 3)
    by_order: dict[str, list[int]] = {}
    for j in range(skel.num_joints):
        if j not in ends:
            by_order.setdefault(orders[j], []).append(j)
    angles = np.zeros((num_frames, skel.num_joints, 3))
    for o, joints in by_order.items():
        angles[:, joints, :] = np.rad2deg(euler_from_quat(rot[:, joints, :], o))
    blocks = []
    for j in written:                                                      # file order
        if j in with_pos:
            blocks.append(motion.root_positions.astype(np.float64) if j == 0 else local[:, j, :])
        blocks.append(angles[:, j, :])
    data = np.concatenate(blocks, axis=1) if blocks else np.zeros((num_frames, 0))   # (T, C)
    data = np.where(np.abs(data) < 0.5 * 10.0 ** -p, 0.0, data)            # no "-0.000000"
    row_fmt = " ".join([f"%.{p}f"] * data.shape[1])
    out.extend(row_fmt % tuple(row) for row in data.tolist())
    atomic_write_text(path, "\n".join(out) + "\n")
