"""The takes QTG's transition windows are cut from, through the data cache (:mod:`refimpl.datacache`).

Reading the Bandai Namco locomotion set for the transition task (830 BVH takes -> the 21-joint rotations and
root positions of each, :func:`refimpl.protocols.transition_locomotion.load_bandai_namco_source`) takes ~15 s
on one core; what the reader returns is ~0.1 GB of float64 that loads in about a second. One entry holds one
LIST of sources (the training takes, or the held-out takes): ``refimpl train`` reads both entries, ``refimpl
eval`` on the held-out side only the held-out one (it reads only what it scores).

* Key: :func:`refimpl.datacache.fingerprint` of the takes' resolved paths, sizes and ``st_mtime_ns`` (sorted by
  path: the order a caller lists them in does not matter), the options (each source's kind, declared rate and
  frame fraction, the rate asked for) and the loader's version: :data:`LOADER_VERSION` plus the sha256 of the
  source of every module a take is read and prepared by (:func:`loader_version`), so editing the reader
  invalidates the entries.
* Entry ``transition-takes-<key[:24]>.npz``: every clip's rotations and root positions concatenated along time,
  with the clips' lengths, the number of clips of each source, and the distinct skeletons (concatenated, with
  their joint counts). The decoded takes equal the reader's, array for array and skeleton for skeleton.

Shapes: N sources, C clips, F_c frames of clip c, J joints (21 for the Bandai Namco rig), S distinct skeletons.
"""
from __future__ import annotations

import hashlib
import inspect
import sys
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from refimpl.progress import PROGRESS_EVERY_S, Throttle
from refimpl import bvh, motion, quat, rigs, rotations, skeleton
from refimpl.datacache import cached, fingerprint
from refimpl.protocols import locomotion_data
from refimpl.skeleton import Skeleton

__all__ = ["LOADER_VERSION", "loader_version", "takes_key", "encode_takes", "decode_takes", "load_takes",
           "cached_loader"]

#: Bumped by hand when the entry's layout changes (the reader's own code is hashed, see :func:`loader_version`).
LOADER_VERSION = 1
_NAME = "transition-takes"


def loader_version(loader: Callable) -> str:
    """``LOADER_VERSION`` and the sha256 of the source of the module defining ``loader``, of this module and of
    the readers and kinematics below them (BVH, the locomotion rig's reader, joint subsets, quaternions)."""
    h = hashlib.sha256(str(LOADER_VERSION).encode())
    for mod in (sys.modules[loader.__module__], sys.modules[__name__], locomotion_data, bvh, motion, quat, rigs,
                rotations, skeleton):
        h.update(Path(inspect.getsourcefile(mod)).read_bytes())
    return h.hexdigest()


def _order(sources: Sequence) -> list[int]:
    """Indices of ``sources`` sorted by resolved path, then frame fraction (the entry's order)."""
    return sorted(range(len(sources)), key=lambda i: (str(Path(sources[i].path).resolve()),
                                                      tuple(sources[i].frames)))


def takes_key(sources: Sequence, loader: Callable, fps: float) -> str:
    """The cache key of what ``loader(source, fps=fps)`` returns for each of ``sources`` (module docstring).

    Raises
    ------
    OSError
        A take is missing (as reading it would).
    """
    order = _order(sources)
    options = {"fps": float(fps), "sources": [[sources[i].kind, float(sources[i].fps), list(sources[i].frames)]
                                               for i in order]}
    return fingerprint([sources[i].path for i in order], name=_NAME, version=loader_version(loader),
                       options=options)


def _pack_skeletons(skels: Sequence[Skeleton]) -> dict:
    """The distinct skeletons as concatenated arrays (each list field with its per-skeleton counts)."""
    def cat(field, dtype):
        parts = [np.asarray(getattr(s, field), dtype=dtype).reshape(-1) for s in skels]
        return np.concatenate(parts) if parts else np.zeros(0, dtype), np.array([len(p) for p in parts], np.int64)

    out = {"skel_joints": np.array([s.num_joints for s in skels], dtype=np.int64)}
    out["skel_parents"] = cat("parents", np.int64)[0]
    out["skel_offsets"] = cat("offsets", np.float64)[0].reshape(-1, 3)
    out["skel_names"] = np.array([n for s in skels for n in s.names], dtype=str)
    for field in ("end_sites", "joints_left", "joints_right"):
        out[f"skel_{field}"], out[f"skel_{field}_counts"] = cat(field, np.int64)
    return out


def _unpack_skeletons(a: dict) -> list[Skeleton]:
    """Inverse of :func:`_pack_skeletons`."""
    joints = a["skel_joints"]
    j_end = np.cumsum(joints)
    ends = {f: np.cumsum(a[f"skel_{f}_counts"]) for f in ("end_sites", "joints_left", "joints_right")}
    out = []
    for i, (j0, j1) in enumerate(zip(j_end - joints, j_end)):
        lists = {f: a[f"skel_{f}"][e[i] - a[f"skel_{f}_counts"][i]:e[i]].tolist() for f, e in ends.items()}
        out.append(Skeleton(a["skel_parents"][j0:j1], a["skel_offsets"][j0:j1],
                            names=[str(n) for n in a["skel_names"][j0:j1]], **lists))
    return out


def encode_takes(loaded: Sequence[tuple]) -> tuple[dict, dict]:
    """``(arrays, meta)`` of a list of ``(skeleton, clips)`` (what a transition loader returns for each source;
    ``clips`` a list of ``(rotations (F, J, 4), root_positions (F, 3))``)."""
    skels: list[Skeleton] = []
    index, counts, rots, poss = [], [], [], []
    for skel, clips in loaded:
        k = next((j for j, s in enumerate(skels) if s == skel), None)
        if k is None:
            skels.append(skel)
            k = len(skels) - 1
        index.append(k)
        counts.append(len(clips))
        for r, p in clips:
            rots.append(np.asarray(r))
            poss.append(np.asarray(p))
    J = skels[0].num_joints if skels else 0
    arrays = {"rotations": np.concatenate(rots) if rots else np.zeros((0, J, 4)),
              "root_positions": np.concatenate(poss) if poss else np.zeros((0, 3)),
              "clip_lengths": np.array([r.shape[0] for r in rots], dtype=np.int64),
              "clips_per_source": np.array(counts, dtype=np.int64),
              "skeleton_index": np.array(index, dtype=np.int64), **_pack_skeletons(skels)}
    return arrays, {"sources": len(loaded), "skeletons": len(skels)}


def decode_takes(arrays: dict, meta: dict) -> list[tuple]:
    """Inverse of :func:`encode_takes` (ValueError when the counts do not add up)."""
    lengths, counts = arrays["clip_lengths"], arrays["clips_per_source"]
    if (len(counts) != int(meta["sources"]) or counts.sum() != len(lengths)
            or lengths.sum() != arrays["rotations"].shape[0] or lengths.sum() != arrays["root_positions"].shape[0]):
        raise ValueError("the clip counts and lengths do not add up to the stored frames")
    skels = _unpack_skeletons(arrays)
    if len(skels) != int(meta["skeletons"]):
        raise ValueError("the stored skeletons are not the ones the metadata counts")
    ends = np.cumsum(lengths)
    clips = [(arrays["rotations"][a:b], arrays["root_positions"][a:b]) for a, b in zip(ends - lengths, ends)]
    c_end = np.cumsum(counts)
    return [(skels[int(k)], clips[c0:c1]) for k, c0, c1 in zip(arrays["skeleton_index"], c_end - counts, c_end)]


def _read_all(sources: Sequence, loader: Callable, fps: float, progress, every_s: float = PROGRESS_EVERY_S) -> list:
    """``loader(s, fps=fps)`` of each source, telling ``progress`` every ``every_s`` seconds how far it got."""
    tick = Throttle(every_s)
    out = []
    for n, s in enumerate(sources, 1):
        out.append(loader(s, fps=fps))
        if progress is not None and tick.due():
            progress(f"  read {n} of {len(sources)} files, {tick.elapsed:.0f} s")
    return out


def load_takes(sources: Sequence, loader: Callable, *, fps: float = 30.0, progress=None, folder=None) -> list:
    """``loader(source, fps=fps)`` of every source, in the given order: the cache's verified entry for these
    takes (:func:`takes_key`), else read (``progress`` hears every ~5 s how many files have been read) and stored.

    Raises
    ------
    OSError, ValueError
        A take is missing or cannot be read (as without the cache).
    """
    sources = list(sources)
    order = _order(sources)
    ordered = [sources[i] for i in order]
    key = takes_key(sources, loader, fps)
    got = cached(_NAME, key, lambda: _read_all(ordered, loader, fps, progress), encode_takes, decode_takes,
                 folder=folder, progress=progress)
    if len(got) != len(sources):
        raise ValueError(f"{_NAME}: the entry holds {len(got)} takes, expected {len(sources)}")
    out = [None] * len(sources)
    for i, value in zip(order, got):
        out[i] = value
    return out


def cached_loader(sides: Sequence[Sequence], loader: Callable, *, fps: float = 30.0, progress=None,
                  folder=None) -> Callable:
    """A loader for :func:`refimpl.protocols.transition.build_transition_datasets` that answers from
    :func:`load_takes` of each list in ``sides`` (one cache entry per list: e.g. the training and the held-out
    takes). It accepts only those sources, at ``fps``."""
    read_fps = float(fps)
    table = {}
    for sources in (side for side in sides if len(side)):   # an empty list: no entry
        for s, value in zip(sources, load_takes(sources, loader, fps=fps, progress=progress, folder=folder)):
            table[(s.path, tuple(s.frames))] = value

    def load(source, fps: float = read_fps):
        if abs(float(fps) - read_fps) > 1e-9:
            raise ValueError(f"fps: the takes were read at {read_fps}, not {fps}")
        return table[(source.path, tuple(source.frames))]

    return load
