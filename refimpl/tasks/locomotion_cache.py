"""The locomotion sequences of a list of files, through the data cache (:mod:`refimpl.datacache`).

Loading the Bandai Namco set (830 BVH files → 1,660 mirrored sequences) takes ~95 s; its prepared sequences
(rotations, trajectory, FK positions, phase, features, skeletons) are ~0.2 GB of float64 that load in seconds.
The key covers the files (path, size, mtime), the options (``kind``, ``mirror``, frame rate) and the loader
itself: the sha256 of the source of every module the preparation runs through, so editing the loader
invalidates the cache without a version number to remember. The decoded sequences are equal, array for array,
to the ones :func:`refimpl.tasks.locomotion.build_sequences` returns.

Shapes: N sequences of T_i frames, J joints; concatenated along time in the entry (``lengths`` (N,)).
"""
from __future__ import annotations

import hashlib
import inspect
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from refimpl import bvh, expmap, motion, quat, skeleton
from refimpl.datacache import cached, fingerprint
from refimpl.skeleton import Skeleton
from refimpl.tasks import locomotion as _loco

__all__ = ["LOADER_VERSION", "loader_version", "load_sequences", "encode_sequences", "decode_sequences"]

#: Bumped by hand when the entry's layout changes (the loader's own code is hashed, see :func:`loader_version`).
LOADER_VERSION = 1
_FIELDS = ("rotations", "trajectory", "positions_world", "positions_local", "phase", "features")


def loader_version() -> str:
    """``LOADER_VERSION`` and the sha256 of the source of the modules a sequence is prepared by."""
    h = hashlib.sha256(str(LOADER_VERSION).encode())
    for mod in (_loco, bvh, expmap, motion, quat, skeleton):
        h.update(Path(inspect.getsourcefile(mod)).read_bytes())
    return h.hexdigest()


def _skeleton_arrays(s: Skeleton, i: int) -> dict:
    return {f"skel{i}.parents": np.asarray(s.parents, dtype=np.int64),
            f"skel{i}.offsets": np.asarray(s.offsets, dtype=np.float64),
            f"skel{i}.names": np.array(s.names, dtype=str),
            f"skel{i}.end_sites": np.array(s.end_sites, dtype=np.int64),
            f"skel{i}.joints_left": np.array(s.joints_left, dtype=np.int64),
            f"skel{i}.joints_right": np.array(s.joints_right, dtype=np.int64)}


def _skeleton_of(arrays: dict, i: int) -> Skeleton:
    a = {k.split(".", 1)[1]: v for k, v in arrays.items() if k.startswith(f"skel{i}.")}
    return Skeleton(a["parents"], a["offsets"], names=[str(n) for n in a["names"]],
                    end_sites=a["end_sites"].tolist(), joints_left=a["joints_left"].tolist(),
                    joints_right=a["joints_right"].tolist())


def encode_sequences(value: tuple) -> tuple[dict, dict]:
    """``(arrays, meta)`` of ``(sequences, rig)`` for :func:`refimpl.datacache.save_entry`."""
    seqs, rig = value
    skels: list[Skeleton] = []
    index = []
    for s in seqs:
        for i, k in enumerate(skels):
            if k is s.skeleton or (k.names == s.skeleton.names and np.array_equal(k.parents, s.skeleton.parents)
                                   and np.array_equal(k.offsets, s.skeleton.offsets)
                                   and k.end_sites == s.skeleton.end_sites
                                   and k.joints_left == s.skeleton.joints_left
                                   and k.joints_right == s.skeleton.joints_right):
                index.append(i)
                break
        else:
            index.append(len(skels))
            skels.append(s.skeleton)
    arrays = {f: np.concatenate([getattr(s, f) for s in seqs], axis=0) for f in _FIELDS}
    arrays.update(lengths=np.array([s.num_frames for s in seqs], dtype=np.int64),
                  skeleton_index=np.array(index, dtype=np.int64),
                  names=np.array([s.name for s in seqs], dtype=str),
                  sources=np.array([s.source for s in seqs], dtype=str))
    for i, k in enumerate(skels):
        arrays.update(_skeleton_arrays(k, i))
    return arrays, dict(rig=rig.name, sequences=len(seqs), skeletons=len(skels))


def decode_sequences(arrays: dict, meta: dict) -> tuple[list, object]:
    """Inverse of :func:`encode_sequences`: ``(list of LocomotionSequence, LocomotionRig)``."""
    rigs = {r.name: r for r in (_loco.BANDAI_NAMCO_RIG, _loco.CMU_RIG)}
    rig = rigs[meta["rig"]]
    lengths = arrays["lengths"]
    if lengths.sum() != arrays["rotations"].shape[0] or len(lengths) != int(meta["sequences"]):
        raise ValueError("lengths do not add up to the stored frames")
    skels = [_skeleton_of(arrays, i) for i in range(int(meta["skeletons"]))]
    ends = np.cumsum(lengths)
    out = []
    for i, (a, b) in enumerate(zip(ends - lengths, ends)):
        out.append(_loco.LocomotionSequence(
            name=str(arrays["names"][i]), source=str(arrays["sources"][i]),
            skeleton=skels[int(arrays["skeleton_index"][i])], **{f: arrays[f][a:b] for f in _FIELDS}))
    return out, rig


def load_sequences(kind: str, files: Sequence[str], build: Callable[[], tuple[list, object]], *,
                   mirror: bool = True, progress: Callable[[str], None] | None = None,
                   folder=None) -> tuple[list, object]:
    """``(sequences, rig)`` of ``files`` of one ``kind`` (:func:`refimpl.tasks.locomotion.resolve_files`):
    the cache's verified entry for these files and options, else ``build()`` (which reads them), stored.

    Raises
    ------
    OSError, ValueError
        A file is missing or cannot be parsed (as without the cache).
    """
    key = fingerprint(files, name="locomotion", version=loader_version(),
                      options=dict(kind=kind, mirror=bool(mirror), fps=_loco.FPS))
    return cached(f"locomotion-{kind}", key, build, encode_sequences, decode_sequences, folder=folder,
                  progress=progress)
