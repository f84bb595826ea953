"""ONNX builder for quaternion forward kinematics with the skeleton baked in (QuaterNet's FK, ``refimpl/skeleton.py``).

Equations (joints ordered so that parents precede children; root ``j = 0`` has parent −1)::

    q_world[root] = q_local[root]              p[root] = root_position
    q_world[j]    = q_world[parent(j)] ⊗ q_local[j]
    p[j]          = p[parent(j)] + R(q_world[parent(j)]) · offset[j]

with ``R(q) v = v + 2 (w (u × v) + u × (u × v))`` (``refimpl.quat.quat_rotate``; local quaternions are used as
given, unit by assumption).

Graph layout: joints are processed one *depth level* at a time (all joints whose parents are already placed), so
the node count grows with the skeleton's depth, not its joint count. Each level gathers its parents' world
rotations/positions and its own local rotations, and appends its results; one final ``Gather`` restores the
skeleton's joint order. Parents and offsets are constants of the graph.

Shape legend: ``...`` leading axes (B, T), J joints, n_d joints at depth d.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from deploy.graph import GraphBuilder
from deploy.quat import quat_mul, quat_rotation_matrix

__all__ = ["forward_kinematics", "depth_levels"]


def depth_levels(parents: Sequence[int]) -> list[list[int]]:
    """Joints grouped by depth: ``[[root], [children of root], ...]``, each group in joint order.

    Raises
    ------
    ValueError
        If ``parents[0] != -1``, another joint has parent −1, or a parent does not precede its child.
    """
    parents = [int(p) for p in parents]
    if not parents or parents[0] != -1:
        raise ValueError(f"parents: expected parents[0] == -1 (the root first), got {parents[:1]}")
    depth = [0] * len(parents)
    for j, p in enumerate(parents[1:], start=1):
        if not 0 <= p < j:
            raise ValueError(f"parents: joint {j} has parent {p}; expected 0 <= parent < {j}")
        depth[j] = depth[p] + 1
    return [[j for j in range(len(parents)) if depth[j] == d] for d in range(max(depth) + 1)]


def forward_kinematics(g: GraphBuilder, local_q: str, root_position: str, parents: Sequence[int],
                       offsets: np.ndarray, *, name: str, return_rotations: bool = False,
                       wname: str | None = None):
    """Append forward kinematics.

    Parameters
    ----------
    local_q : str
        Local joint rotations ``(..., J, 4)``, ``(w, x, y, z)``.
    root_position : str
        ``(..., 3)``.
    parents : sequence of int, length J
        ``parents[0] = -1``; ``parents[j] < j``.
    offsets : ndarray (J, 3)
        Bone offsets in the parent's frame (the root's is not used).
    name : str
        Graph path.
    return_rotations : bool
        Also return the world rotations.
    wname : str, optional
        Path of the constants (default ``name``).

    Returns
    -------
    positions : str
        ``(..., J, 3)`` world positions.
    rotations : str, only with ``return_rotations``
        ``(..., J, 4)`` world rotations.
    """
    offsets = np.asarray(offsets, dtype=np.float64)
    levels = depth_levels(parents)
    n_joints = len(parents)
    if offsets.shape != (n_joints, 3):
        raise ValueError(f"offsets: expected shape ({n_joints}, 3), got {offsets.shape}")
    order: list[int] = []                                                # joint at each slot of the running tensors
    slot = {}
    world_q = world_p = None
    wn = wname or name
    for d, level in enumerate(levels):
        lname = f"{name}.d{d}"
        if d == 0:
            world_q = g.node("Gather", [local_q, g.ints([0])],
                             f"{lname}.q", axis=-2)                      # (..., 1, 4)
            world_p = g.node("Unsqueeze", [root_position, g.ints([-2])], f"{lname}.p")  # (..., 1, 3)
        else:
            par = g.constant(f"{wn}.d{d}.parent_slots", np.array([slot[parents[j]] for j in level], np.int64))
            own = g.constant(f"{wn}.d{d}.joints", np.array(level, np.int64))
            pq = g.node("Gather", [world_q, par], f"{lname}.parent_q", axis=-2)   # (..., n_d, 4)
            pp = g.node("Gather", [world_p, par], f"{lname}.parent_p", axis=-2)   # (..., n_d, 3)
            lq = g.node("Gather", [local_q, own], f"{lname}.local_q", axis=-2)    # (..., n_d, 4)
            q = quat_mul(g, pq, lq, name=f"{lname}.q")                   # (..., n_d, 4)
            m = quat_rotation_matrix(g, pq, name=f"{lname}.R")           # (..., n_d, 3, 3)
            off = g.weight(f"{wn}.d{d}.offsets", offsets[level][:, :, None])        # (n_d, 3, 1)
            rv = g.node("MatMul", [m, off], f"{lname}.R_off")            # (..., n_d, 3, 1)
            rv = g.node("Squeeze", [rv, g.ints([-1])], f"{lname}.R_off_sq")       # (..., n_d, 3)
            p = g.node("Add", [pp, rv], f"{lname}.p")                    # (..., n_d, 3)
            world_q = g.node("Concat", [world_q, q], f"{lname}.q_all", axis=-2)   # (..., n_0..d, 4)
            world_p = g.node("Concat", [world_p, p], f"{lname}.p_all", axis=-2)   # (..., n_0..d, 3)
        for j in level:
            slot[j] = len(order)
            order.append(j)
    inverse = np.array([slot[j] for j in range(n_joints)], np.int64)
    identity = bool(np.all(inverse == np.arange(n_joints)))
    if identity:
        positions = g.node("Identity", [world_p], f"{name}.positions")
    else:
        positions = g.node("Gather", [world_p, g.constant(f"{wn}.order", inverse)], f"{name}.positions",
                           axis=-2)                                      # (..., J, 3)
    if not return_rotations:
        return positions
    if identity:
        return positions, g.node("Identity", [world_q], f"{name}.rotations")
    return positions, g.node("Gather", [world_q, f"{wn}.order"],
                             f"{name}.rotations", axis=-2)              # (..., J, 4)
