"""Skeletons and kinematics: the ``Skeleton`` value, forward kinematics, joint removal. Current ↔ local dual
quaternions are in :mod:`refimpl.current_dq`, mirroring and turning about the up axis in :mod:`refimpl.mirroring`.

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
  Forward kinematics (QuaterNet, spec/kinematics.md §2)::

      q_world[0] = q[0]                      p[0] = root_position
      q_world[j] = q_world[p(j)] ⊗ q[j]      p[j] = p[p(j)] + R(q_world[p(j)]) · offset[j]

* End Sites (BVH leaves without channels) are kept as ordinary joints whose rotation is the identity; their
  indices are listed in ``Skeleton.end_sites`` so that the BVH writer emits them as ``End Site`` blocks.
  A leaf's own rotation never moves any position.

Shape legend: ``...`` any leading axes (batch B, time T), J joints, 4 quaternion, 3 vector, (4, 4) homogeneous
matrix.
"""
from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

from refimpl.arrays import float_array
from refimpl.quat import finite_output, quat_mul_kernel, quat_rotate_kernel, quat_mul, quat_rotate
from refimpl.rotations import matrix_from_quat

__all__ = [
    "Skeleton",
    "UNIT_TOLERANCE",
    "remove_joints",
]


# ---------------------------------------------------------------------------------------------------------
# validation helpers (public boundaries only)
# ---------------------------------------------------------------------------------------------------------

def validate_parents(parents, name: str = "parents") -> np.ndarray:
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


def check_last_axes(arr: np.ndarray, name: str, tail: tuple, legend: str) -> None:
    """Raise ValueError unless the trailing axes of ``arr`` are ``tail`` (``legend`` names the expected shape)."""
    if arr.ndim < len(tail) or arr.shape[arr.ndim - len(tail):] != tail:
        raise ValueError(f"{name}: expected shape {legend}, got {arr.shape}")


def depth_levels(parents: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
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
        par = validate_parents(parents)
        num = par.size
        off = float_array(offsets, "offsets").astype(np.float64)
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
        self._levels = depth_levels(par)

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
        rot = float_array(rotations, "rotations")
        check_last_axes(rot, "rotations", (self.num_joints, 4), f"(..., {self.num_joints}, 4)")
        if unit:
            check_unit(rot, "rotations")
        if root_positions is None:
            return rot, None
        pos = float_array(root_positions, "root_positions")
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
        """Joint positions by quaternion forward kinematics (QuaterNet, spec/kinematics.md §2).

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
        tr = float_array(translations, "translations")
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
# joint removal
# ---------------------------------------------------------------------------------------------------------

def remove_joints(skeleton: Skeleton, rotations, joints: Iterable[int | str], offsets: str = "compose"):
    """Remove joints, pushing each removed joint's rotation into its children.

    For each removed joint ``r`` (processed in increasing index order, so chains of removed joints compose):
    every child ``c`` gets ``q[c] ← q[r] ⊗ q[c]`` and is re-attached to ``r``'s parent (QuaterNet,
    spec/kinematics.md §4). Offsets of the re-attached children:

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


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# check_last_axes, check_unit, depth_levels, validate_parents.
