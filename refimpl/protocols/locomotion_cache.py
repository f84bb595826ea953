"""The locomotion sequences of a list of files, through the data cache (:mod:`refimpl.datacache`).

Loading the Bandai Namco set (830 BVH files → 1,660 mirrored sequences) takes ~95 s; its prepared sequences
(rotations, trajectory, FK positions, phase, features, skeletons) are ~0.2 GB of float64 that load in seconds.
The key covers the files (path, size, mtime), the options (``kind``, ``mirror``, frame rate) and the loader
itself: the sha256 of the source of every module the preparation runs through, so editing the loader
invalidates the cache without a version number to remember. The decoded sequences are equal, array for array,
to the ones :func:`refimpl.protocols.locomotion_data.build_sequences` returns.

Shapes: N sequences of T_i frames, J joints; concatenated along time in the entry (``lengths`` (N,)).
"""
from __future__ import annotations

import hashlib
import inspect
import sys
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from refimpl import bvh, expmap, motion, quat, rotations, skeleton
from refimpl.datacache import cached, fingerprint
from refimpl.skeleton import Skeleton

__all__ = ["LOADER_VERSION", "loader_version", "sequences_key", "load_sequences", "load_pace_data",
           "encode_sequences", "decode_sequences"]

#: Bumped by hand when the entry's layout changes (the loader's own code is hashed, see :func:`loader_version`).
LOADER_VERSION = 1
_FIELDS = ("rotations", "trajectory", "positions_world", "positions_local", "phase", "features")


def loader_version(sequence_type: type, *modules) -> str:
    """``LOADER_VERSION`` and the sha256 of the source of the modules a sequence is prepared by: the module
    defining ``sequence_type`` (the locomotion protocol's data module), ``modules`` (the caller's: the module
    of its ``build``) and the readers and kinematics below them."""
    h = hashlib.sha256(str(LOADER_VERSION).encode())
    for mod in (sys.modules[sequence_type.__module__], *modules, bvh, expmap, motion, quat, rotations, skeleton):
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


def decode_sequences(arrays: dict, meta: dict, sequence_type: type, rigs: Sequence) -> tuple[list, object]:
    """Inverse of :func:`encode_sequences`: ``(list of sequence_type, the rig of rigs named in meta)``."""
    rig = {r.name: r for r in rigs}[meta["rig"]]
    lengths = arrays["lengths"]
    if lengths.sum() != arrays["rotations"].shape[0] or len(lengths) != int(meta["sequences"]):
        raise ValueError("lengths do not add up to the stored frames")
    skels = [_skeleton_of(arrays, i) for i in range(int(meta["skeletons"]))]
    ends = np.cumsum(lengths)
    out = []
    for i, (a, b) in enumerate(zip(ends - lengths, ends)):
        out.append(sequence_type(
            name=str(arrays["names"][i]), source=str(arrays["sources"][i]),
            skeleton=skels[int(arrays["skeleton_index"][i])], **{f: arrays[f][a:b] for f in _FIELDS}))
    return out, rig


def sequences_key(files: Sequence[str], build: Callable, sequence_type: type, options: dict) -> str:
    """The cache key of the sequences ``build`` makes from ``files`` with ``options`` (see the module docstring)."""
    version = loader_version(sequence_type, sys.modules[build.__module__])
    return fingerprint(files, name="locomotion", version=version, options=options)


def load_sequences(files: Sequence[str], build: Callable[[], tuple[list, object]], *, sequence_type: type,
                   rigs: Sequence, options: dict, progress: Callable[[str], None] | None = None,
                   folder=None) -> tuple[list, object]:
    """``(sequences, rig)`` of ``files``: the cache's verified entry for these files and ``options`` (the
    loader's: source kind, mirroring, frame rate), else ``build()`` (which reads them), stored.

    ``sequence_type`` is :class:`refimpl.protocols.locomotion_data.LocomotionSequence`, ``rigs`` the rigs a stored
    rig name may refer to.

    Raises
    ------
    OSError, ValueError
        A file is missing or cannot be parsed (as without the cache).
    """
    key = sequences_key(files, build, sequence_type, options)
    return cached(f"locomotion-{options.get('kind', 'data')}", key, build, encode_sequences,
                  lambda arrays, meta: decode_sequences(arrays, meta, sequence_type, rigs), folder=folder,
                  progress=progress)


def _encode_pairs(pairs: list) -> tuple[dict, dict]:
    lengths = np.array([a.shape[0] for a, _ in pairs], dtype=np.int64)
    arrays = {"lengths": lengths,
              "inputs": np.concatenate([a for a, _ in pairs]) if pairs else np.zeros((0, 2)),
              "targets": np.concatenate([b for _, b in pairs]) if pairs else np.zeros((0, 4))}
    return arrays, {"count": len(pairs)}


def _decode_pairs(arrays: dict, meta: dict) -> list:
    lengths = arrays["lengths"]
    if len(lengths) != int(meta["count"]) or lengths.sum() != arrays["inputs"].shape[0]:
        raise ValueError("lengths do not add up to the stored points")
    ends = np.cumsum(lengths)
    return [(arrays["inputs"][a:b], arrays["targets"][a:b]) for a, b in zip(ends - lengths, ends)]


def load_pace_data(sequences_key_: str, build: Callable[[], list], *, folder=None,
                   progress: Callable[[str], None] | None = None) -> list:
    """The pace network's ``(inputs (N_i, 2), targets (N_i, 4))`` pairs of the sequences cached under
    ``sequences_key_`` (:func:`sequences_key`): the cache's entry, else ``build()`` stored. The key adds the
    source of the module defining ``build`` (the spline and pace-data code)."""
    h = hashlib.sha256(sequences_key_.encode())
    h.update(Path(inspect.getsourcefile(sys.modules[build.__module__])).read_bytes())
    from refimpl import splines

    h.update(Path(inspect.getsourcefile(splines)).read_bytes())
    return cached("locomotion-pace", h.hexdigest(), build, _encode_pairs, _decode_pairs, folder=folder,
                  progress=progress)
