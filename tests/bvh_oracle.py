"""An independent, straightforward BVH reading with 4x4 matrix forward kinematics (a test oracle).

Written from the BVH format alone, sharing nothing with ``refimpl.bvh``: a recursive-descent parse of the
hierarchy, one loop over the joints (batched over frames), homogeneous 4x4 matrices, one elementary rotation
matrix per rotation channel multiplied in channel order, and position channels that REPLACE the joint's
OFFSET (missing position axes 0), as Blender's importer reads them (spec/data.md §2.1)::

    M_local[j] = Translation(channels if j has position channels else OFFSET) · R_c0 · R_c1 · R_c2
    M_world[j] = M_world[parent] · M_local[j],   position = M_world[j][:3, 3]

End Sites are named ``<parent>_end`` (the name ``refimpl.bvh`` gives them, so results can be matched).
Used by tests/test_bvh_oracle.py and experiments/bvh_fk_check.py.
"""
from __future__ import annotations

import math

import numpy as np


def _rot(axis: str, degrees: np.ndarray) -> np.ndarray:
    """Elementary rotation matrices (T, 4, 4) about ``axis`` by ``degrees`` (T,)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    m = np.tile(np.eye(4), (a.shape[0], 1, 1))
    i, k = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
    m[:, i, i], m[:, i, k], m[:, k, i], m[:, k, k] = c, -s, s, c
    return m


def parse(path):
    """Return (joints, frames): joints = list of dicts {name, parent, offset, channels}, frames (T, C)."""
    text = open(path, encoding="utf-8").read()
    words = text.split()
    i = 0
    joints = []

    def node(parent, name):
        nonlocal i
        assert words[i] == "{", words[i]
        i += 1
        me = len(joints)
        joints.append({"name": name, "parent": parent, "offset": None, "channels": []})
        while words[i] != "}":
            w = words[i]
            if w == "OFFSET":
                joints[me]["offset"] = [float(x) for x in words[i + 1:i + 4]]
                i += 4
            elif w == "CHANNELS":
                n = int(words[i + 1])
                joints[me]["channels"] = words[i + 2:i + 2 + n]
                i += 2 + n
            elif w == "JOINT":
                # joint names in the files used here are single words
                i += 2
                node(me, words[i - 1])
            elif w == "End":
                i += 2
                node(me, joints[me]["name"] + "_end")
            else:
                raise ValueError(f"unexpected {w!r}")
        i += 1

    assert words[0] == "HIERARCHY" and words[1] == "ROOT"
    i = 3
    node(-1, words[2])
    assert words[i] == "MOTION" and words[i + 1] == "Frames:"
    nframes = int(words[i + 2])
    assert words[i + 3] == "Frame" and words[i + 4] == "Time:"
    i += 6
    nchan = sum(len(j["channels"]) for j in joints)
    values = np.array([float(x) for x in words[i:]])
    assert values.size == nframes * nchan
    return joints, values.reshape(nframes, nchan)


def world_positions(path, frames=None) -> tuple[list[str], np.ndarray]:
    """Joint names and world positions ``(T', J, 3)`` of the frames ``frames`` (default all)."""
    joints, data = parse(path)
    rows = data if frames is None else data[list(frames)]                 # (T', C)
    n = rows.shape[0]
    out = np.zeros((n, len(joints), 3))
    col = 0
    world = []
    for j in joints:
        has_pos = any(c.endswith("position") for c in j["channels"])
        trans = np.zeros((n, 3)) if has_pos else np.tile(j["offset"], (n, 1))
        rot = np.tile(np.eye(4), (n, 1, 1))
        for c in j["channels"]:
            if c.endswith("position"):
                trans[:, "XYZ".index(c[0])] = rows[:, col]
            else:
                rot = rot @ _rot(c[0], rows[:, col])
            col += 1
        local = np.tile(np.eye(4), (n, 1, 1))
        local[:, :3, 3] = trans
        local = local @ rot
        w = local if j["parent"] < 0 else world[j["parent"]] @ local
        world.append(w)
        out[:, len(world) - 1] = w[:, :3, 3]
    return [j["name"] for j in joints], out
