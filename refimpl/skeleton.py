"""Skeletons and kinematics: forward kinematics, current ↔ local dual quaternions, joint removal, mirroring.

Conventions (spec/kinematics.md, spec/conventions.md)
-----------------------------------------------------
* A skeleton is a tree of ``J`` joints stored in *topological order*: joint 0 is the only root
  (``parents[0] == -1``) and ``0 <= parents[j] < j`` for every other joint, so a single pass in index order
  (or depth by depth) visits every parent before its children.
* ``offsets[j]`` is joint ``j``'s rest translation from its parent, expressed in the parent's frame.
  ``offsets[0]`` is stored (a BVH ROOT has an OFFSET) but forward kinematics ignores it: the root's position
  is the per-frame ``root_positions`` (QuaterNet's definition; the BVH reader folds the ROOT OFFSET into
  ``root_positions``).
* Local rotations are unit quaternions ``(w, x, y, z)`` (Hamilton product, active rotations, column vectors).
  Forward kinematics (QuaterNet, quaternet_reference_code.md §3.2)::

      q_world[0] = q[0]                      p[0] = root_position
      q_world[j] = q_world[p(j)] ⊗ q[j]      p[j] = p[p(j)] + R(q_world[p(j)]) · offset[j]

* End Sites (BVH leaves without channels) are kept as ordinary joints whose rotation is the identity; their
  indices are listed in ``Skeleton.end_sites`` so that the BVH writer emits them as ``End Site`` blocks.
  A leaf's own rotation never moves any position.
* Current coordinates (dual-quaternion paper, Eq. 9-12): ``C[0] = (q[0] | 0)`` (rotation only),
  ``C[j] = C[p(j)] ⊗ DQ(q[j], offset[j])`` with ``DQ(q, t) = (q | ½ (0, t) ⊗ q)``. The translation of
  ``C[j]`` (Eq. 8) is joint ``j``'s position relative to the root position, in world axes.

Shape legend: ``...`` any leading axes (batch B, time T), J joints, 4 quaternion, 8 dual quaternion,
3 vector, (4, 4) homogeneous matrix.
"""
from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

from refimpl.dualquat import (dq_conj_kernel, dq_from_quat_translation_kernel,
                              dq_mul_kernel, dq_from_quat_translation, dq_mul, translation_from_dq)
from refimpl.quat import check_scalar, finite_output, quat_mul_kernel, quat_rotate_kernel, quat_mul, quat_rotate
from refimpl.rotations import matrix_from_quat, quat_from_axis_angle

__all__ = [
    "Skeleton",
    "UNIT_TOLERANCE",
    "current_dq_from_local",
    "local_from_current_dq",
    "positions_from_current_dq",
    "offsets_from_current_dq",
    "remove_joints",
    "mirror",
    "rotate_about_up",
    "random_rotate_about_up",
]

_AXES = {"x": 0, "y": 1, "z": 2}


# ---------------------------------------------------------------------------------------------------------
# validation helpers (public boundaries only)
# ---------------------------------------------------------------------------------------------------------

def _validate_parents(parents, name: str = "parents") -> np.ndarray:
    """Return ``parents`` as an int64 array after checking the topological-order rules."""
    try:
        arr = np.asarray(parents)
    except (TypeError, OverflowError, ValueError) as exc:  # ragged nesting, objects refusing conversion
        raise ValueError(f"{name}: expected a sequence of ints, got {type(parents).__name__} ({exc})") from None
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name}: expected a non-empty 1-D sequence of ints, got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise ValueError(f"{name}: expected integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if arr[0] != -1:
        raise ValueError(f"{name}: joint 0 must be the root (parent -1), got parents[0] = {arr[0]}")
    roots = np.flatnonzero(arr == -1)
    if roots.size != 1:
        raise ValueError(f"{name}: expected exactly one root (parent -1) at index 0, got roots at {roots.tolist()}")
    j = np.arange(arr.size)
    bad = np.flatnonzero((arr[1:] < 0) | (arr[1:] >= j[1:])) + 1
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"{name}: parents must precede their children (0 <= parents[j] < j); "
                         f"got parents[{k}] = {arr[k]}")
    return arr


def as_float_array(x, name: str) -> np.ndarray:
    try:
        arr = np.asarray(x)
    except (TypeError, OverflowError, ValueError) as exc:  # ragged nesting, objects refusing conversion
        raise ValueError(f"{name}: expected a real numeric array, got {type(x).__name__} ({exc})") from None
    if arr.dtype.kind not in "fiub":
        raise ValueError(f"{name}: expected a real numeric array, got dtype {arr.dtype}")
    if arr.dtype.kind != "f":
        arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


UNIT_TOLERANCE = 1e-3
"""Largest accepted ``| |q| - 1 |`` for rotations entering forward kinematics and :class:`refimpl.motion.Motion`."""


def check_unit(rot: np.ndarray, name: str) -> None:
    """Raise ValueError unless every quaternion in ``rot (..., 4)`` has norm within ``UNIT_TOLERANCE`` of 1."""
    if rot.size == 0:
        return
    dev = np.abs(np.sqrt(np.sum(rot.astype(np.float64) ** 2, axis=-1)) - 1.0)
    if np.any(dev > UNIT_TOLERANCE):
        idx = tuple(int(i) for i in np.unravel_index(int(np.argmax(dev)), dev.shape))
        norm = float(np.sqrt(np.sum(rot[idx].astype(np.float64) ** 2)))
        raise ValueError(f"{name}: expected unit quaternions (| |q| - 1 | <= {UNIT_TOLERANCE}); the quaternion at "
                         f"index {idx} has norm {norm:.6g} (normalise with refimpl.quat.quat_normalize first)")


def _check_last_axes(arr: np.ndarray, name: str, tail: tuple, legend: str) -> None:
    if arr.ndim < len(tail) or arr.shape[arr.ndim - len(tail):] != tail:
        raise ValueError(f"{name}: expected shape {legend}, got {arr.shape}")


def _depth_levels(parents: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Group the non-root joints by depth: ``((joints at depth 1, their parents), (depth 2, ...), ...)``."""
    depth = np.zeros(parents.size, dtype=np.int64)
    for j in range(1, parents.size):
        depth[j] = depth[parents[j]] + 1
    order = np.argsort(depth, kind="stable")  # joints by depth, increasing index within a depth
    starts = np.searchsorted(depth[order], np.arange(1, int(depth.max()) + 2))  # O(J log J), not O(J · depth)
    return tuple((order[a:b], parents[order[a:b]]) for a, b in zip(starts[:-1], starts[1:]))


def _index_list(x, name: str, num: int, allow_names: Sequence[str] | None = None) -> tuple[int, ...]:
    """Joint indices from an iterable of ints (or, with ``allow_names``, joint names); ValueError on anything
    else: a string or a non-iterable in place of the list, bools, floats, ``None``, indices outside ``0..num-1``."""
    if isinstance(x, (str, bytes)) or not isinstance(x, Iterable):
        raise ValueError(f"{name}: expected a sequence of joint indices, got {type(x).__name__} {x!r:.60}")
    out = []
    for v in x:
        if allow_names is not None and isinstance(v, str):
            if v not in allow_names:
                raise ValueError(f"{name}: no joint called {v!r}; joints are {list(allow_names)}")
            out.append(allow_names.index(v))
            continue
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"{name}: expected integer joint indices, got {type(v).__name__} {v!r:.60}")
        if not 0 <= v < num:
            raise ValueError(f"{name}: index {v} out of range 0..{num - 1}")
        out.append(int(v))
    return tuple(out)


def _side_of(name: str) -> tuple[str, str] | None:
    """``("left"|"right", stem)`` when a joint name starts with a side prefix, else ``None``.

    Prefixes: ``left``/``right`` (any case), or a single ``l``/``L``/``r``/``R`` followed by an upper-case
    letter, a digit or ``_`` (``LHipJoint``, ``lShldr``, ``RThumb``; not ``LowerBack`` or ``Root``).
    """
    low = name.lower()
    for side in ("left", "right"):
        if low.startswith(side) and len(name) > len(side):
            return side, low[len(side):].lstrip("_")
    if len(name) > 1 and name[0] in "lLrR" and (name[1].isupper() or name[1].isdigit() or name[1] == "_"):
        return ("left" if name[0] in "lL" else "right"), low[1:].lstrip("_")
    return None


def _infer_left_right(names: Sequence[str]) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Pair left and right joints whose names differ only in the side prefix (case-insensitive stem)."""
    lefts: dict[str, list[int]] = {}
    rights: dict[str, list[int]] = {}
    for j, n in enumerate(names):
        s = _side_of(n)
        if s is not None:
            (lefts if s[0] == "left" else rights).setdefault(s[1], []).append(j)
    pairs = []
    for stem, ls in lefts.items():
        for a, b in zip(ls, rights.get(stem, [])):
            pairs.append((a, b))
    pairs.sort()
    return tuple(a for a, _ in pairs), tuple(b for _, b in pairs)


# ---------------------------------------------------------------------------------------------------------
# Skeleton
# ---------------------------------------------------------------------------------------------------------

class Skeleton:
    """An immutable skeleton: topologically ordered parents, rest offsets, names, End Sites, left/right pairs.

    Parameters
    ----------
    parents : sequence of int, length J
        ``parents[0] == -1`` (the only root); ``0 <= parents[j] < j`` for ``j >= 1``.
    offsets : array_like, shape (J, 3)
        Rest translation of each joint from its parent, in the parent's frame. ``offsets[0]`` is kept but
        ignored by forward kinematics (the root position is given per frame).
    names : sequence of str, optional
        Unique, non-empty joint names; default ``"joint_0"``, ``"joint_1"``, ...
    end_sites : iterable of int, optional
        Indices of End Sites: leaves without BVH channels (their rotation is the identity).
    joints_left, joints_right : sequence of int, optional
        Paired lists (``joints_left[i]`` mirrors ``joints_right[i]``). Default: inferred from the names by
        the side prefix (``Left``/``L``/``l`` vs ``Right``/``R``/``r``, same remaining stem); joints without
        a partner are in neither list.

    Attributes
    ----------
    parents : ndarray of int64, shape (J,), read-only
    offsets : ndarray of float64, shape (J, 3), read-only
    names : tuple of str
    children : tuple of tuple of int (increasing index order)
    end_sites : tuple of int
    joints_left, joints_right : tuple of int
    num_joints : int
    """

    __slots__ = ("_parents", "_offsets", "_names", "_children", "_end_sites", "_joints_left", "_joints_right",
                 "_levels")

    def __init__(self, parents, offsets, names: Sequence[str] | None = None, end_sites: Iterable[int] = (),
                 joints_left: Sequence[int] | None = None, joints_right: Sequence[int] | None = None):
        par = _validate_parents(parents)
        num = par.size
        off = as_float_array(offsets, "offsets").astype(np.float64)
        if off.shape != (num, 3):
            raise ValueError(f"offsets: expected shape ({num}, 3) for {num} joints, got {off.shape}")
        if names is None:
            nms = tuple(f"joint_{j}" for j in range(num))
        else:
            if isinstance(names, (str, bytes)) or not isinstance(names, Iterable):
                raise ValueError(f"names: expected a sequence of {num} strings, got {type(names).__name__}")
            nms = tuple(names)
            if len(nms) != num:
                raise ValueError(f"names: expected {num} names, got {len(nms)}")
            for n in nms:
                if not isinstance(n, str) or not n:
                    raise ValueError(f"names: expected non-empty strings, got {n!r}")
            if len(set(nms)) != num:
                dup = sorted({n for n in nms if nms.count(n) > 1})
                raise ValueError(f"names: joint names must be unique, duplicated: {dup}")
        children = [[] for _ in range(num)]
        for j in range(1, num):
            children[par[j]].append(j)
        ends = tuple(sorted(set(_index_list(end_sites, "end_sites", num))))
        for e in ends:
            if e == 0:
                raise ValueError(f"end_sites: index {e} out of range 1..{num - 1}")
            if children[e]:
                raise ValueError(f"end_sites: joint {e} ({nms[e]!r}) has children {children[e]}; "
                                 "an End Site must be a leaf")
        if joints_left is None and joints_right is None:
            left, right = _infer_left_right(nms)
        else:
            if joints_left is None or joints_right is None:
                raise ValueError("joints_left, joints_right: give both lists or neither")
            left = _index_list(joints_left, "joints_left", num)
            right = _index_list(joints_right, "joints_right", num)
            if len(left) != len(right):
                raise ValueError(f"joints_left, joints_right: expected paired lists of equal length, "
                                 f"got {len(left)} and {len(right)}")
            every = left + right
            if any(not 0 <= j < num for j in every):
                raise ValueError(f"joints_left, joints_right: indices must lie in 0..{num - 1}, got {every}")
            if len(set(every)) != len(every):
                raise ValueError("joints_left, joints_right: a joint appears twice")
        par.flags.writeable = False
        off.flags.writeable = False
        self._parents = par
        self._offsets = off
        self._names = nms
        self._children = tuple(tuple(c) for c in children)
        self._end_sites = ends
        self._joints_left = left
        self._joints_right = right
        self._levels = _depth_levels(par)

    # -- read-only attributes ------------------------------------------------------------------------------
    parents = property(lambda self: self._parents, doc="(J,) int64, read-only; ``-1`` for the root.")
    offsets = property(lambda self: self._offsets, doc="(J, 3) float64, read-only rest offsets.")
    names = property(lambda self: self._names, doc="tuple of J joint names.")
    children = property(lambda self: self._children, doc="children of each joint, increasing index order.")
    end_sites = property(lambda self: self._end_sites, doc="indices of End Sites (leaves without channels).")
    joints_left = property(lambda self: self._joints_left, doc="left joints, paired with ``joints_right``.")
    joints_right = property(lambda self: self._joints_right, doc="right joints, paired with ``joints_left``.")

    @property
    def num_joints(self) -> int:
        """Number of joints J (End Sites included)."""
        return int(self._parents.size)

    def index(self, name: str) -> int:
        """Index of the joint called ``name`` (ValueError when there is none)."""
        try:
            return self._names.index(name)
        except ValueError:
            raise ValueError(f"name: no joint called {name!r}; joints are {list(self._names)}") from None

    def __eq__(self, other) -> bool:
        if not isinstance(other, Skeleton):
            return NotImplemented
        return (np.array_equal(self._parents, other._parents) and np.array_equal(self._offsets, other._offsets)
                and self._names == other._names and self._end_sites == other._end_sites
                and self._joints_left == other._joints_left and self._joints_right == other._joints_right)

    def __hash__(self) -> int:
        return hash((self._parents.tobytes(), self._offsets.tobytes(), self._names, self._end_sites))

    def __repr__(self) -> str:
        return (f"Skeleton(num_joints={self.num_joints}, end_sites={len(self._end_sites)}, "
                f"root={self._names[0]!r})")

    # -- kinematics ----------------------------------------------------------------------------------------
    def _check_motion(self, rotations, root_positions=None, unit: bool = False):
        rot = as_float_array(rotations, "rotations")
        _check_last_axes(rot, "rotations", (self.num_joints, 4), f"(..., {self.num_joints}, 4)")
        if unit:
            check_unit(rot, "rotations")
        if root_positions is None:
            return rot, None
        pos = as_float_array(root_positions, "root_positions")
        if pos.shape != rot.shape[:-2] + (3,):
            raise ValueError(f"root_positions: expected shape {rot.shape[:-2] + (3,)} to match rotations "
                             f"{rot.shape}, got {pos.shape}")
        dtype = np.result_type(rot.dtype, pos.dtype)
        return rot.astype(dtype, copy=False), pos.astype(dtype, copy=False)

    @finite_output
    def world_rotations(self, rotations) -> np.ndarray:
        """World (global) rotation of every joint: ``q_world[j] = q_world[p(j)] ⊗ q[j]``, ``q_world[0] = q[0]``.

        Parameters
        ----------
        rotations : array_like, shape (..., J, 4)
            Local unit quaternions ``(w, x, y, z)``.

        Returns
        -------
        ndarray, shape (..., J, 4), same float dtype as ``rotations``.
        """
        rot, _ = self._check_motion(rotations, unit=True)
        return _world_rotations(self._levels, rot)

    @finite_output
    def forward_kinematics(self, rotations, root_positions, translations=None) -> np.ndarray:
        """Joint positions by quaternion forward kinematics (QuaterNet, quaternet_reference_code.md §3.2).

        ``p[0] = root_position``; ``p[j] = p[p(j)] + R(q_world[p(j)]) · t[j]`` with
        ``q_world[j] = q_world[p(j)] ⊗ q[j]`` and ``t[j] = offset[j]`` (or ``translations[..., j, :]`` when
        given: per-frame local translations, e.g. BVH position channels on non-root joints, spec/data.md §2).
        Joints are processed depth by depth (one vectorised step per tree level), so batch and time are
        handled in one call.

        Parameters
        ----------
        rotations : array_like, shape (..., J, 4)
            Local unit quaternions ``(w, x, y, z)``; not normalised here.
        root_positions : array_like, shape (..., 3)
            World position of the root per frame.
        translations : array_like, shape (..., J, 3), optional
            Local translation of every joint from its parent, in the parent's frame, replacing ``offsets``
            (row 0 is ignored: the root is at ``root_positions``). Default: the skeleton's offsets.

        Returns
        -------
        ndarray, shape (..., J, 3): world positions; dtype of the inputs (float32 stays float32).
        """
        rot, pos = self._check_motion(rotations, root_positions, unit=True)
        return _forward_kinematics(self._levels, self._translations(translations, rot), rot, pos)

    def _translations(self, translations, rot: np.ndarray) -> np.ndarray:
        """``offsets`` (J, 3) or the checked per-frame ``translations`` (..., J, 3), in ``rot``'s dtype."""
        if translations is None:
            return self._offsets.astype(rot.dtype)
        tr = as_float_array(translations, "translations")
        if tr.shape != rot.shape[:-1] + (3,):
            raise ValueError(f"translations: expected shape {rot.shape[:-1] + (3,)} to match rotations "
                             f"{rot.shape}, got {tr.shape}")
        return tr.astype(rot.dtype, copy=False)

    @finite_output
    def forward_kinematics_matrices(self, rotations, root_positions, translations=None) -> np.ndarray:
        """Joint positions by chaining 4x4 homogeneous matrices (an independent oracle for the quaternion FK).

        ``M_local[0] = [R(q[0]) | root_position]``, ``M_local[j] = [R(q[j]) | offset[j]]``,
        ``M_world[j] = M_world[p(j)] · M_local[j]`` (dual-quaternion paper Eq. 10-11 with the root translated);
        the position of joint ``j`` is the translation column of ``M_world[j]`` (``offset[j]`` replaced by
        ``translations[..., j, :]`` when given).

        Parameters and returns as :meth:`forward_kinematics`.
        """
        rot, pos = self._check_motion(rotations, root_positions, unit=True)
        off = self._translations(translations, rot)                         # (J, 3) or (..., J, 3)
        local = np.zeros(rot.shape[:-1] + (4, 4), dtype=rot.dtype)        # (..., J, 4, 4)
        local[..., :3, :3] = matrix_from_quat(rot)
        local[..., :3, 3] = off
        local[..., 0, :3, 3] = pos
        local[..., 3, 3] = 1.0
        world = np.empty_like(local)
        world[..., 0, :, :] = local[..., 0, :, :]
        for idx, par in self._levels:
            world[..., idx, :, :] = world[..., par, :, :] @ local[..., idx, :, :]
        return world[..., :3, 3].copy()                                     # (..., J, 3)

    def remove_joints(self, joints: Iterable[int | str], offsets: str = "compose") -> "Skeleton":
        """A new skeleton without ``joints`` (indices or names); see :func:`remove_joints` for the rules."""
        skel, _ = remove_joints(self, None, joints, offsets=offsets)
        return skel


# ---------------------------------------------------------------------------------------------------------
# kernels (no checks)
# ---------------------------------------------------------------------------------------------------------

def _world_rotations(levels, rot: np.ndarray) -> np.ndarray:
    world = np.empty_like(rot)                                              # (..., J, 4)
    world[..., 0, :] = rot[..., 0, :]
    for idx, par in levels:
        world[..., idx, :] = quat_mul_kernel(world[..., par, :], rot[..., idx, :])
    return world


def _forward_kinematics(levels, offsets: np.ndarray, rot: np.ndarray, root_pos: np.ndarray) -> np.ndarray:
    world = np.empty_like(rot)                                              # (..., J, 4)
    pos = np.empty(rot.shape[:-1] + (3,), dtype=rot.dtype)                  # (..., J, 3)
    world[..., 0, :] = rot[..., 0, :]
    pos[..., 0, :] = root_pos
    for idx, par in levels:
        q_par = world[..., par, :]                                          # (..., n, 4)
        off = np.broadcast_to(offsets[..., idx, :], q_par.shape[:-1] + (3,))  # (..., n, 3)
        pos[..., idx, :] = pos[..., par, :] + quat_rotate_kernel(q_par, off)
        world[..., idx, :] = quat_mul_kernel(q_par, rot[..., idx, :])
    return pos


def _forward_kinematics_naive(parents, offsets, rot, root_pos):
    """Slow per-joint loop version of :func:`_forward_kinematics` (test oracle)."""
    world = np.empty_like(rot)
    pos = np.empty(rot.shape[:-1] + (3,), dtype=rot.dtype)
    for j, p in enumerate(parents):
        if p < 0:
            world[..., j, :] = rot[..., j, :]
            pos[..., j, :] = root_pos
        else:
            off = np.broadcast_to(offsets[..., j, :], pos.shape[:-2] + (3,))
            pos[..., j, :] = pos[..., p, :] + quat_rotate(world[..., p, :], off)
            world[..., j, :] = quat_mul(world[..., p, :], rot[..., j, :])
    return pos


# ---------------------------------------------------------------------------------------------------------
# current coordinates (dual-quaternion paper Eq. 8-12)
# ---------------------------------------------------------------------------------------------------------

@finite_output
def current_dq_from_local(rotations, offsets, parents) -> np.ndarray:
    """Current (root-relative) dual quaternions from local rotations and offsets (paper Eq. 9-11).

    ``C[0] = (q[0] | 0)`` (rotation only, zero dual part, Eq. 9);
    ``C[j] = C[p(j)] ⊗ DQ(q[j], offset[j])`` with ``DQ(q, t) = (q | ½ (0, t) ⊗ q)`` (Eq. 10-11 as dual
    quaternions). ``offsets[0]`` is ignored.

    Parameters
    ----------
    rotations : array_like, shape (..., J, 4)
        Local unit quaternions ``(w, x, y, z)``.
    offsets : array_like, shape (J, 3) or (..., J, 3)
        Local bone offsets (broadcast against ``rotations``).
    parents : sequence of int, length J
        Topologically ordered parents (``parents[0] == -1``, ``parents[j] < j``).

    Returns
    -------
    ndarray, shape (..., J, 8): ``(q_r | q_d)`` per joint; the translation of ``C[j]`` is joint ``j``'s
    position relative to the root.
    """
    par = _validate_parents(parents)
    rot = as_float_array(rotations, "rotations")
    _check_last_axes(rot, "rotations", (par.size, 4), f"(..., {par.size}, 4)")
    off = as_float_array(offsets, "offsets")
    _check_last_axes(off, "offsets", (par.size, 3), f"({par.size}, 3) or (..., {par.size}, 3)")
    dtype = np.result_type(rot.dtype, off.dtype)
    return _current_dq_from_local(_depth_levels(par), rot.astype(dtype, copy=False), off.astype(dtype, copy=False))


def _current_dq_from_local(levels, rot, off):
    off = np.broadcast_to(off, rot.shape[:-1] + (3,))
    local = dq_from_quat_translation_kernel(rot, off)                             # (..., J, 8)
    cur = np.empty_like(local)
    cur[..., 0, :4] = rot[..., 0, :]
    cur[..., 0, 4:] = 0.0
    for idx, par in levels:
        cur[..., idx, :] = dq_mul_kernel(cur[..., par, :], local[..., idx, :])
    return cur


def _current_dq_from_local_naive(parents, rot, off):
    """Slow per-joint loop version of :func:`_current_dq_from_local` through 4x4-free DQ products (test oracle)."""
    off = np.broadcast_to(off, rot.shape[:-1] + (3,))
    cur = np.empty(rot.shape[:-1] + (8,), dtype=rot.dtype)
    for j, p in enumerate(parents):
        if p < 0:
            cur[..., j, :] = dq_from_quat_translation(rot[..., j, :], np.zeros(3, dtype=rot.dtype))
        else:
            cur[..., j, :] = dq_mul(cur[..., p, :], dq_from_quat_translation(rot[..., j, :], off[..., j, :]))
    return cur


@finite_output
def local_from_current_dq(dqs, parents) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations and offsets from current dual quaternions (paper Eq. 12).

    ``L[j] = C[p(j)]⁻¹ ⊗ C[j]`` (for a unit DQ the inverse is ``(q_r* | q_d*)``), ``L[0] = C[0]``; the local
    rotation is the real part of ``L[j]`` and the local offset its translation ``vec(2 q_d ⊗ q_r*)`` (Eq. 8).
    The inputs are assumed unit (normalise network outputs first with ``refimpl.dualquat.dq_normalize``).

    Parameters
    ----------
    dqs : array_like, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    rotations : ndarray, shape (..., J, 4)
        Local quaternions (sign as produced by the product; ``q`` and ``-q`` are the same rotation).
    offsets : ndarray, shape (..., J, 3)
        Local offsets (the root's is its own translation, 0 for data built by :func:`current_dq_from_local`).
    """
    par = _validate_parents(parents)
    dq = as_float_array(dqs, "dqs")
    _check_last_axes(dq, "dqs", (par.size, 8), f"(..., {par.size}, 8)")
    local = _local_dq_from_current(par, dq)
    return local[..., :4].copy(), translation_from_dq(local)


def _local_dq_from_current(par, dq):
    parent_dq = dq[..., np.maximum(par, 0), :].copy()                       # (..., J, 8)
    parent_dq[..., 0, :] = np.array([1, 0, 0, 0, 0, 0, 0, 0], dtype=dq.dtype)
    return dq_mul_kernel(dq_conj_kernel(parent_dq), dq)                                 # (..., J, 8)


@finite_output
def positions_from_current_dq(dqs) -> np.ndarray:
    """Root-relative joint positions from current dual quaternions: ``p[j] = vec(2 q_d ⊗ q_r*)`` (paper Eq. 8).

    Add the root position to get world positions (the root DQ has no translation).

    Parameters
    ----------
    dqs : array_like, shape (..., J, 8)

    Returns
    -------
    ndarray, shape (..., J, 3)
    """
    dq = as_float_array(dqs, "dqs")
    _check_last_axes(dq, "dqs", (8,), "(..., 8)")
    return translation_from_dq(dq)


@finite_output
def offsets_from_current_dq(dqs, parents) -> np.ndarray:
    """Local bone offsets ``vec(2 L_d ⊗ L_r*)`` with ``L[j] = C[p(j)]⁻¹ ⊗ C[j]`` (root: its own translation).

    Parameters
    ----------
    dqs : array_like, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    ndarray, shape (..., J, 3)
    """
    return local_from_current_dq(dqs, parents)[1]


# ---------------------------------------------------------------------------------------------------------
# joint removal
# ---------------------------------------------------------------------------------------------------------

def remove_joints(skeleton: Skeleton, rotations, joints: Iterable[int | str], offsets: str = "compose"):
    """Remove joints, pushing each removed joint's rotation into its children.

    For each removed joint ``r`` (processed in increasing index order, so chains of removed joints compose):
    every child ``c`` gets ``q[c] ← q[r] ⊗ q[c]`` and is re-attached to ``r``'s parent (QuaterNet,
    quaternet_reference_code.md §3.3). Offsets of the re-attached children:

    * ``offsets="compose"`` (default, correct rest geometry): ``offset[c] ← offset[r] + offset[c]``. This keeps
      the rest pose exactly and every posed frame exactly whenever ``q[r]`` is the identity (End Sites,
      fixed joints); no constant offset can reproduce a posed frame in which ``q[r]`` rotates ``offset[c]``.
    * ``offsets="drop"`` (QuaterNet's variant): children keep their own offset and ``offset[r]`` is lost,
      which shortens the chain when ``offset[r] != 0`` (QuaterNet's CMU Spine1, §3.6).

    Left/right pairs with a removed member are dropped; End Site flags and names are carried over.

    Parameters
    ----------
    skeleton : Skeleton
    rotations : array_like, shape (..., J, 4), or None
        Local rotations to update, or ``None`` to transform the skeleton only.
    joints : iterable of int or str
        Joints to remove (indices or names); the root cannot be removed.
    offsets : {"compose", "drop"}

    Returns
    -------
    skeleton : Skeleton with ``J - len(joints)`` joints
    rotations : ndarray, shape (..., J', 4), or None
    """
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a Skeleton, got {type(skeleton).__name__}")
    num = skeleton.num_joints
    if not isinstance(offsets, str) or offsets not in ("compose", "drop"):
        raise ValueError(f"offsets: expected 'compose' or 'drop', got {offsets!r:.60}")
    removed = set(_index_list(joints, "joints", num, allow_names=skeleton.names))
    if 0 in removed:
        raise ValueError("joints: the root (joint 0) cannot be removed")
    rot = None
    if rotations is not None:
        rot, _ = skeleton._check_motion(rotations)
        rot = rot.copy()
    parents = skeleton.parents.copy()
    offs = skeleton.offsets.copy()
    for r in sorted(removed):
        for c in skeleton.children[r]:
            if rot is not None:
                rot[..., c, :] = quat_mul(rot[..., r, :], rot[..., c, :])
            if offsets == "compose":
                offs[c] = offs[r] + offs[c]
            parents[c] = parents[r]
        if rot is not None:
            rot[..., r, :] = np.array([1, 0, 0, 0], dtype=rot.dtype)
    keep = np.array([j for j in range(num) if j not in removed], dtype=np.int64)
    new_index = -np.ones(num, dtype=np.int64)
    new_index[keep] = np.arange(keep.size)
    new_parents = [-1] + [int(new_index[parents[j]]) for j in keep[1:]]
    pairs = [(new_index[a], new_index[b]) for a, b in zip(skeleton.joints_left, skeleton.joints_right)
             if a not in removed and b not in removed]
    new_skel = Skeleton(new_parents, offs[keep], names=[skeleton.names[j] for j in keep],
                        end_sites=[int(new_index[e]) for e in skeleton.end_sites if e not in removed],
                        joints_left=[int(a) for a, _ in pairs], joints_right=[int(b) for _, b in pairs])
    return new_skel, (None if rot is None else rot[..., keep, :])


# ---------------------------------------------------------------------------------------------------------
# mirroring and rotation about the up axis
# ---------------------------------------------------------------------------------------------------------

def _axis_index(axis) -> int:
    if isinstance(axis, str) and axis.lower() in _AXES:
        return _AXES[axis.lower()]
    if isinstance(axis, (int, np.integer)) and 0 <= int(axis) <= 2:
        return int(axis)
    raise ValueError(f"axis: expected 'x', 'y', 'z' or 0, 1, 2, got {axis!r}")


@finite_output
def mirror(skeleton: Skeleton, rotations, root_positions, axis="x", mirror_offsets: bool = False):
    """Reflect a motion across the plane normal to ``axis`` through the origin and swap left and right.

    With ``M = diag(-1, 1, 1)`` for ``axis="x"``: every local rotation becomes ``M R M`` — for quaternions
    ``(w, x, y, z) → (w, x, -y, -z)`` (``axis="y"``: ``(w, -x, y, -z)``, ``axis="z"``: ``(w, -x, -y, z)``);
    the rotation columns of ``joints_left[i]`` and ``joints_right[i]`` are swapped; the root position's
    ``axis`` component is negated. This is QuaterNet's mirroring (quaternet_reference_code.md §3.4), which
    leaves the offsets alone (exact for a symmetric skeleton). With ``mirror_offsets=True`` the skeleton is
    mirrored too (offsets reflected by ``M`` and swapped between partners), which makes the result the exact
    mirror image: ``FK'(p)[swap(j)] = M · FK(p)[j]``. Mirroring twice is the identity. Consecutive frames keep
    their hemisphere (the quaternion dot products are unchanged), so no antipodal fix is needed.

    Parameters
    ----------
    skeleton : Skeleton
    rotations : array_like, shape (..., J, 4)
    root_positions : array_like, shape (..., 3)
    axis : {"x", "y", "z"} or {0, 1, 2}
        Normal of the mirror plane (QuaterNet: x).
    mirror_offsets : bool

    Returns
    -------
    skeleton : Skeleton (the same object unless ``mirror_offsets``)
    rotations : ndarray, shape (..., J, 4)
    root_positions : ndarray, shape (..., 3)
    """
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a Skeleton, got {type(skeleton).__name__}")
    a = _axis_index(axis)
    rot, pos = skeleton._check_motion(rotations, root_positions)
    perm = np.arange(skeleton.num_joints)
    left = np.asarray(skeleton.joints_left, dtype=np.int64)
    right = np.asarray(skeleton.joints_right, dtype=np.int64)
    perm[left], perm[right] = right, left
    sign_q = np.array([1.0, -1.0, -1.0, -1.0], dtype=rot.dtype)
    sign_q[1 + a] = 1.0
    new_rot = rot[..., perm, :] * sign_q                                    # (..., J, 4)
    sign_v = np.ones(3, dtype=pos.dtype)
    sign_v[a] = -1.0
    new_pos = pos * sign_v                                                  # (..., 3)
    new_skel = skeleton
    if mirror_offsets:
        new_skel = Skeleton(skeleton.parents, skeleton.offsets[perm] * sign_v.astype(np.float64),
                            names=skeleton.names, end_sites=skeleton.end_sites,
                            joints_left=skeleton.joints_left, joints_right=skeleton.joints_right)
    return new_skel, new_rot, new_pos


@finite_output
def rotate_about_up(rotations, root_positions, angle, up="y"):
    """Rotate a whole motion about the vertical axis through the origin (data augmentation).

    ``q[..., 0, :] ← q_up(angle) ⊗ q[..., 0, :]`` (only the root's local rotation changes) and
    ``root_position ← R_up(angle) · root_position``; world positions rotate rigidly about the ``up`` axis.

    Parameters
    ----------
    rotations : array_like, shape (..., J, 4)
    root_positions : array_like, shape (..., 3)
    angle : float or array_like broadcastable to ``root_positions.shape[:-1]``
        Radians, counter-clockwise seen from +up. For one angle per sequence of a ``(B, T, ...)`` batch pass
        shape ``(B, 1)``.
    up : {"x", "y", "z"}
        The up axis (y for every data set in this project).

    Returns
    -------
    rotations : ndarray, shape (..., J, 4)
    root_positions : ndarray, shape (..., 3)
    """
    a = _axis_index(up)
    rot = as_float_array(rotations, "rotations")
    _check_last_axes(rot, "rotations", (4,), "(..., J, 4)")
    if rot.ndim < 2 or rot.shape[-2] == 0:
        raise ValueError(f"rotations: expected shape (..., J, 4) with J >= 1 joints, got {rot.shape}")
    pos = as_float_array(root_positions, "root_positions")
    if pos.shape != rot.shape[:-2] + (3,):
        raise ValueError(f"root_positions: expected shape {rot.shape[:-2] + (3,)}, got {pos.shape}")
    ang = as_float_array(angle, "angle")
    try:
        ang = np.broadcast_to(ang, pos.shape[:-1])
    except ValueError:
        raise ValueError(f"angle: expected a shape broadcastable to {pos.shape[:-1]}, got {ang.shape}") from None
    dtype = np.result_type(rot.dtype, pos.dtype)
    axis_vec = np.zeros(3, dtype=dtype)
    axis_vec[a] = 1.0
    q_up = quat_from_axis_angle(ang.astype(dtype)[..., None] * axis_vec)   # (..., 4)
    new_rot = rot.astype(dtype, copy=True)
    new_rot[..., 0, :] = quat_mul(q_up, new_rot[..., 0, :])
    return new_rot, quat_rotate(q_up, pos.astype(dtype))


@finite_output
def random_rotate_about_up(rotations, root_positions, rng: np.random.Generator, low: float = -np.pi,
                           high: float = np.pi, up="y"):
    """:func:`rotate_about_up` by one angle drawn from ``U(low, high)`` for the whole motion.

    Parameters
    ----------
    rotations : array_like, shape (..., J, 4)
    root_positions : array_like, shape (..., 3)
    rng : numpy.random.Generator
    low, high : float
        Range of the angle in radians (QuaterNet's long-term training draws from [-2π, 2π]).
    up : {"x", "y", "z"}

    Returns
    -------
    rotations, root_positions : as :func:`rotate_about_up`
    angle : float
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    low, high = check_scalar(low, "low", -np.inf), check_scalar(high, "high", -np.inf)
    if not (high >= low and np.isfinite(high - low)):
        raise ValueError(f"low, high: expected low <= high with a finite difference, got {low!r}, {high!r}")
    angle = float(rng.uniform(low, high))
    rot, pos = rotate_about_up(rotations, root_positions, angle, up=up)
    return rot, pos, angle


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# as_float_array, check_unit.
