"""Transitions between two clips in world coordinates (the transition task's ``refimpl generate``; spec/cli.md):
:func:`make_transition` (the source and target frames into the window frame, a method's T frames, back to the
world), :class:`Transition`, :func:`with_end_sites` (End Sites for BVH readers), :func:`render_transition`.

Shape legend: T transition frames, F frames of a clip, J joints, P pose size (3 + 4 J), B batch.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np

from refimpl.errors import UsageError
from refimpl.motion import Motion
from refimpl.protocols.transition import heading_from_root, make_windows, window_to_world
from refimpl.protocols.transition_quality import foot_joints
from refimpl.quat import quat_conj, quat_mul, quat_rotate
from refimpl.skeleton import Skeleton

__all__ = [
    "Transition", "with_end_sites", "make_transition", "render_transition",
]


def _say(*parts) -> None:
    print(*parts, flush=True)


@dataclasses.dataclass(frozen=True)
class Transition:
    """A generated transition in world coordinates with its context frames.

    Attributes
    ----------
    motion : Motion
        ``context`` source frames ending at the source frame, the ``T`` generated frames, then ``context``
        target frames starting at the target frame (placed by the alignment), 22 joints, centimetres.
    truth : Motion or None
        The same frames from the data, when source and target come from one clip and
        ``target_frame = source_frame + T + 1`` (a held-out window): the ground truth to compare with.
    start, stop : int
        The generated frames are ``motion`` frames ``[start, stop)``.
    method : str
    """

    motion: Any
    truth: Any
    start: int
    stop: int
    method: str

    def error_cm(self) -> float | None:
        """Mean joint-position error (cm) of the generated frames against ``truth`` (None without truth)."""
        if self.truth is None:
            return None
        a = self.motion.positions()[self.start:self.stop]
        b = self.truth.positions()[self.start:self.stop]
        return float(np.mean(np.linalg.norm(a - b, axis=-1)))


def with_end_sites(motion, fraction: float = 0.4):
    """The motion with an End Site below every leaf joint, for BVH files that other tools read.

    The 22-joint transition skeleton has no End Sites (toes, head and hands are leaves). Each leaf ``j`` gets a
    child ``<name>_end`` with offset ``fraction · offsets[j]`` (the bone continued; straight up for a leaf with a
    zero offset) and identity rotation. Joint positions of the original joints are unchanged.
    """
    skel = motion.skeleton
    leaves = [j for j in range(skel.num_joints) if not skel.children[j] and j not in set(skel.end_sites)]
    if not leaves:
        return motion
    offsets = np.asarray(skel.offsets, dtype=np.float64)
    scale = float(np.median(np.linalg.norm(offsets[1:], axis=-1))) if skel.num_joints > 1 else 1.0
    extra = [fraction * offsets[j] if np.linalg.norm(offsets[j]) > 0 else np.array([0.0, fraction * scale, 0.0])
             for j in leaves]
    J = skel.num_joints
    new = Skeleton(list(skel.parents) + leaves, np.concatenate([offsets, np.asarray(extra)]),
                   names=list(skel.names) + [f"{skel.names[j]}_end" for j in leaves],
                   end_sites=tuple(skel.end_sites) + tuple(range(J, J + len(leaves))))
    rot = np.asarray(motion.rotations)
    ident = np.zeros(rot.shape[:1] + (len(leaves), 4), dtype=rot.dtype)
    ident[..., 0] = 1.0
    return Motion(new, np.concatenate([rot, ident], axis=1), motion.root_positions, motion.frame_time, motion.name)


def _heading(q_root) -> np.ndarray:
    return heading_from_root(np.asarray(q_root, dtype=np.float64))


def _align_target(src_rot, src_pos, s, tgt_rot, tgt_pos, g, T):
    """Move and turn the target clip about the vertical so that it continues the source clip.

    The target's heading at frame ``g`` is made equal to the source's at ``s``, and its root is placed (in the
    horizontal plane) where the source root would be after ``T + 1`` frames at the mean of the source's
    velocity at ``s`` and the (turned) target's velocity at ``g``. Heights are kept.
    """
    turn = quat_mul(_heading(src_rot[s, 0]), quat_conj(_heading(tgt_rot[g, 0])))  # (4,)
    rot = np.array(tgt_rot, dtype=np.float64, copy=True)
    rot[:, 0] = quat_mul(turn[None], rot[:, 0])
    rel = quat_rotate(turn[None], np.asarray(tgt_pos, np.float64) - tgt_pos[g])  # (F, 3)
    v_src = src_pos[s] - src_pos[s - 1]
    v_tgt = rel[g + 1] - rel[g]
    anchor = src_pos[s] + (T + 1) * 0.5 * (v_src + v_tgt)
    anchor[1] = tgt_pos[g][1]  # keep the target's own root height (Y up)
    return rot, rel + anchor


def make_transition(method: Callable, skeleton, source_clip, source_frame: int, target_clip, target_frame: int,
                    T: int, *, frame_time: float, context: int = 10, align: str = "auto", same_clip: bool = False,
                    method_name: str = "qtg", name: str = "transition") -> Transition:
    """Generate the ``T`` frames between two clips and return them in world coordinates.

    The four context poses (source frames ``s − 1, s``, target frames ``g, g + 1``) are expressed relative to
    the first one (:func:`refimpl.protocols.transition.make_windows` on the 4 frames), ``method`` generates the
    transition in that frame, and the result is moved back to the world (:func:`refimpl.protocols.transition.window_to_world`).

    Parameters
    ----------
    method : callable ``f(past (1, 2, P), target (1, 2, P), T) -> (1, T, P)`` (un-normalised poses)
    skeleton : Skeleton
        The 22-joint skeleton of both clips (centimetres).
    source_clip, target_clip : (rotations (F, J, 4), root_positions (F, 3))
    source_frame, target_frame : int
        ``s`` (the last source frame kept, ``>= 1``) and ``g`` (the first target frame, ``<= F − 2``).
    T : int
    frame_time : float
    context : int
        Source frames before and target frames after the transition included in the output (>= 1).
    align : {"auto", "none", "continue"}
        ``none`` keeps the target clip where it is; ``continue`` places it after the source
        (:func:`_align_target`); ``auto`` = ``none`` for one clip, ``continue`` for two.
    same_clip : bool
        Both clips are the same one (enables the ground truth).
    """
    src_rot, src_pos = (np.asarray(a, np.float64) for a in source_clip)
    tgt_rot, tgt_pos = (np.asarray(a, np.float64) for a in target_clip)
    s, g = int(source_frame), int(target_frame)
    if not 1 <= s < len(src_rot):
        raise UsageError(f"--source-frame must lie in [1, {len(src_rot) - 1}] (frames at the model's rate), got {s}")
    if not 0 <= g < len(tgt_rot) - 1:
        raise UsageError(f"--target-frame must lie in [0, {len(tgt_rot) - 2}] (frames at the model's rate), got {g}")
    if context < 1:
        raise UsageError(f"--context must be >= 1, got {context}")
    if align not in ("auto", "none", "continue"):
        raise UsageError(f"--align must be auto, none or continue, got {align!r}")
    if align == "continue" or (align == "auto" and not same_clip):
        tgt_rot, tgt_pos = _align_target(src_rot, src_pos, s, tgt_rot, tgt_pos, g, T)

    rot4 = np.stack([src_rot[s - 1], src_rot[s], tgt_rot[g], tgt_rot[g + 1]])  # (4, J, 4)
    pos4 = np.stack([src_pos[s - 1], src_pos[s], tgt_pos[g], tgt_pos[g + 1]])  # (4, 3)
    window = make_windows(rot4, pos4, length=4)  # (1, 4, P) relative to source frame s - 1
    extra = {"skeleton": skeleton} if getattr(method, "needs_skeleton", False) else {}  # foot locking
    pred = np.asarray(method(window[:, :2], window[:, 2:], T, **extra), dtype=np.float64)[0]  # (T, P)
    gen_pos, gen_rot = window_to_world(pred, _heading(src_rot[s - 1, 0]), src_pos[s - 1])  # (T, 3), (T, J, 4)

    a = max(0, s - context + 1)
    b = min(len(tgt_rot), g + context)
    rot = np.concatenate([src_rot[a:s + 1], gen_rot, tgt_rot[g:b]])  # (F, J, 4)
    pos = np.concatenate([src_pos[a:s + 1], gen_pos, tgt_pos[g:b]])  # (F, 3)
    start = s + 1 - a
    motion = Motion(skeleton, rot, pos, frame_time, name)
    truth = None
    if same_clip and g == s + T + 1 and align in ("auto", "none"):
        truth = Motion(skeleton, src_rot[a:b], src_pos[a:b], frame_time, f"{name}_truth")
    return Transition(motion=motion, truth=truth, start=start, stop=start + T, method=method_name)


def render_transition(tr: Transition, png=None, gif=None, title=None) -> list:
    """Draw a :class:`Transition` (against its ground truth when it has one) as a PNG strip and / or a GIF.

    The strip shows the frames on both sides of each join (:func:`refimpl.render_strip.join_frames`: last past,
    first generated, a middle one, last generated, first target), left and right limbs in two shades
    (:func:`refimpl.render_strip.limb_sides`), the feet's floor tracks
    (:func:`refimpl.protocols.transition_quality.foot_joints`) and one floor for the whole clip, its grid fixed
    in the world (spec/cli.md §8), under a title (default: the method and the generated frames).
    """
    from refimpl.progress import stderr_line
    from refimpl.render import render_gif
    from refimpl.render_strip import join_frames, limb_sides, render_strip

    skel = tr.motion.skeleton
    parents = np.asarray(skel.parents)
    gt = (tr.truth if tr.truth is not None else tr.motion).positions()
    pred = tr.motion.positions() if tr.truth is not None else None
    labels = ("ground truth", tr.method) if pred is not None else (tr.method, "")
    sides = limb_sides(skel)
    title = title or f"{tr.method}: frames {tr.start}-{tr.stop - 1} generated; green = context"
    written = []
    if png:
        frames = join_frames(tr.start, tr.stop, tr.motion.num_frames)
        written.append(render_strip(png, gt, parents, prediction=pred, frames=frames, highlight=(tr.start, tr.stop),
                                    labels=labels, title=title, frame_time=tr.motion.frame_time, sides=sides,
                                    feet=_feet(skel)))
        _say(f"wrote {png}")
    if gif:
        written.append(render_gif(gif, gt, parents, prediction=pred, fps=tr.motion.fps, progress=stderr_line,
                                  highlight=(tr.start, tr.stop), labels=labels, title=title, sides=sides))
        _say(f"wrote {gif}")
    return written


def _feet(skel):
    try:
        return foot_joints(skel)
    except ValueError:  # a skeleton without foot joints: no tracks
        return None
