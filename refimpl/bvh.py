"""BVH (Biovision hierarchy) reading (spec/data.md §2); writing is in :mod:`refimpl.bvh_write`.

* ``HIERARCHY`` with one ``ROOT``, nested ``JOINT`` and ``End Site`` blocks, then ``MOTION``, ``Frames: N``,
  ``Frame Time: dt`` and N lines of numbers. Line endings LF, CRLF, CR or mixed; tabs or spaces; keywords
  and channel names are case-insensitive; a joint name is the rest of its line.
* Channels: any order per joint, any subset of ``Xposition Yposition Zposition Xrotation Yrotation
  Zrotation`` (each at most once). Rotations are in degrees and compose in the listed order,
  ``R = R_c0 · R_c1 · R_c2`` (so ``Zrotation Xrotation Yrotation`` is Euler order ``"zxy"``); missing rotation
  axes are 0.
* Position channels replace the OFFSET (as Blender's importer reads them): a joint with position channels has
  their values (missing axes 0) as its local translation, the ROOT as its world position (its OFFSET when it
  has none). Non-root joints with position channels become per-frame ``Motion.translations``; by default
  (``translations="auto"``) the motion is then simplified (:func:`refimpl.motion.simplify_translations`:
  re-rooted at the moving only child of a static root, constant translations folded into the offsets).
* End Sites become joints with identity rotation, named ``<parent>_end`` and listed in
  ``Skeleton.end_sites``; a JOINT without CHANNELS gets identity rotation too.
* The quaternions of every joint are made continuous over time (``quat_fix``).
* ``frame_time`` overrides the declared ``Frame Time`` (the CMU salsa files declare 120 fps but are 60 fps).
* Malformed input raises ``ValueError("<file>:<line>: <problem>")``: each frame line must hold exactly the
  declared number of values; NUL bytes, duplicate joint names and files beyond ``MAX_JOINTS``, ``MAX_DEPTH``
  or ``MAX_FRAME_VALUES`` are refused. The hierarchy is tokenised lazily (a hostile one stops at its first
  error), the numbers are parsed in one NumPy call on the motion block; nothing is allocated from the declared
  frame count before the data has been counted.

Shape legend: T frames, J joints, C channels per frame.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path

import numpy as np

from refimpl._parsing import locate_bad_row
from refimpl.files import read_bytes
from refimpl.motion import TRANSLATION_TOLERANCE, Motion, simplify_translations
from refimpl.quat import quat_fix
from refimpl.rotations import quat_from_euler
from refimpl.skeleton import Skeleton

__all__ = ["BvhHeader", "read_bvh", "read_bvh_header", "MAX_JOINTS", "MAX_DEPTH", "MAX_FRAME_VALUES"]

#: most joints (End Sites included) a BVH hierarchy may declare
MAX_JOINTS = 10_000
#: deepest nesting of ROOT/JOINT/End Site blocks (the ROOT is level 1)
MAX_DEPTH = 1_000
#: most numbers held per file: frames × max(channels per frame, 4 · joints) (800 MB of float64)
MAX_FRAME_VALUES = 100_000_000

_CHANNEL_NAMES = {f"{a}{kind}".lower(): f"{a.upper()}{kind}" for a in "xyz" for kind in ("position", "rotation")}
_FRAMES_RE = re.compile(r"^\s*frames\s*:\s*(\S*)\s*$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^\s*frame\s+time\s*:\s*(\S*)\s*$", re.IGNORECASE)


@dataclasses.dataclass(frozen=True)
class BvhHeader:
    """What a BVH file declares before its numbers.

    Attributes
    ----------
    skeleton : Skeleton
        Joints in file (depth-first) order, End Sites included.
    channels : tuple of tuple of str
        Per joint, the channel names in file order (canonical spelling ``"Xposition"``, ``"Zrotation"``...);
        ``()`` for End Sites and joints without channels.
    num_frames : int
        The declared ``Frames:`` count.
    frame_time : float
        The declared ``Frame Time:`` in seconds.
    """

    skeleton: Skeleton
    channels: tuple
    num_frames: int
    frame_time: float

    @property
    def num_channels(self) -> int:
        """Numbers per frame line."""
        return sum(len(c) for c in self.channels)

    @property
    def translated_joint_names(self) -> tuple:
        """Names of the non-root joints with position channels (per-frame translations in the file, before
        :func:`read_bvh` folds or re-roots them; ``Motion.translated_joint_names`` lists what is left)."""
        return tuple(self.skeleton.names[j] for j, c in enumerate(self.channels)
                     if j > 0 and any(x.endswith("position") for x in c))

    @property
    def rotation_orders(self) -> tuple:
        """Per joint, the Euler order of its rotation channels (``"zxy"``; ``""`` when it has none).

        Pass it to :func:`write_bvh` to keep a file's channel layout.
        """
        return tuple("".join(c[0].lower() for c in ch if c.endswith("rotation")) for ch in self.channels)


# ---------------------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------------------

class _Tokens:
    """Whitespace tokens of the hierarchy lines, each with its 1-based line number, split lazily (one line at
    a time, so a huge hierarchy stops at the first error or limit without tokenising the rest)."""

    def __init__(self, lines: list[str], where: str):
        self.where = where
        self.lines = lines
        self._line = 0           # index of the next line to split
        self._buf: list[str] = []  # tokens of the current line not yet consumed
        self._buf_line = 0       # 1-based line number of the tokens in _buf
        self.prev_line = 1       # line of the last token consumed

    def error(self, line: int, msg: str) -> ValueError:
        return ValueError(f"{self.where}:{line}: {msg}")

    def _fill(self) -> bool:
        while not self._buf:
            if self._line >= len(self.lines):
                return False
            self._buf = self.lines[self._line].split()
            self._buf.reverse()
            self._line += 1
            self._buf_line = self._line
        return True

    def last_line(self) -> int:
        return max(self.prev_line, 1)

    def peek(self) -> tuple[str, int] | None:
        if not self._fill():
            return None
        return self._buf[-1], self._buf_line

    def next(self, expected: str) -> tuple[str, int]:
        if not self._fill():
            raise self.error(self.last_line(), f"unexpected end of file, expected {expected} "
                                               "(truncated hierarchy)")
        tok, line = self._buf.pop(), self._buf_line
        self.prev_line = line
        return tok, line

    def more_on_line(self, line: int) -> str | None:
        """The next token if it is on ``line`` (without consuming it)."""
        if self._buf and self._buf_line == line:
            return self._buf[-1]
        return None

    def rest_of_line(self) -> tuple[str, int]:
        """Join the remaining tokens of the current line (a joint name); a trailing ``{`` is left unread."""
        line = self.prev_line
        if not self._buf or self._buf_line != line:  # name must be on the keyword's line
            if self.peek() is None:
                raise self.error(self.last_line(), "unexpected end of file, expected a joint name")
            raise self.error(line, "missing joint name after ROOT/JOINT")
        toks = []
        while self._buf and self._buf[-1] != "{":
            toks.append(self._buf.pop())
        if not toks:
            raise self.error(line, "missing joint name after ROOT/JOINT")
        return " ".join(toks), line


def _parse_float(tok: str, line: int, what: str, toks: _Tokens) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise toks.error(line, f"{what}: expected a number, got {tok!r}") from None
    if not math.isfinite(v):
        raise toks.error(line, f"{what}: expected a finite number, got {tok!r}")
    return v


def _parse_channels(toks: _Tokens, line: int, joint: str) -> tuple:
    """The channel names after ``CHANNELS`` (on ``line``, for ``joint``): a count in [0, 6], then that many known,
    distinct names and nothing more on the line."""
    ntok, _ = toks.next("the channel count")
    try:
        n = int(ntok)
    except ValueError:
        raise toks.error(line, f"CHANNELS: expected a channel count, got {ntok!r}") from None
    if not 0 <= n <= 6:
        raise toks.error(line, f"CHANNELS: expected between 0 and 6 channels, got {n}")
    chans = []
    for k in range(n):
        ctok, cline = toks.next(f"channel {k + 1} of {n}")
        canon = _CHANNEL_NAMES.get(ctok.lower())
        if canon is None:
            where_found = "" if cline == line else f" on line {cline}"
            raise toks.error(line, f"CHANNELS {n} for {joint!r}: expected {n} channel names "
                                   f"(Xposition ... Zrotation), found {ctok!r}{where_found} after {k}")
        chans.append(canon)
    if len(set(chans)) != len(chans):
        raise toks.error(line, f"CHANNELS for {joint!r} repeats a channel: {' '.join(chans)}")
    extra = toks.more_on_line(line) if n else None
    if extra is not None:
        raise toks.error(line, f"CHANNELS {n} for {joint!r} lists more than {n} channel names "
                               f"(found {extra!r})")
    return tuple(chans)


def _parse_hierarchy(toks: _Tokens):
    """Parse ``HIERARCHY ROOT ...`` up to (and including) the closing brace of the ROOT block.

    Returns parents, offsets, names, channels, end-site flags, in depth-first order.
    """
    for keyword in ("HIERARCHY", "ROOT"):
        tok = toks.next(keyword)
        if tok[0].upper() != keyword:
            raise toks.error(tok[1], f"expected {keyword}, got {tok[0]!r}")
    # joints in depth-first order: parent index, OFFSET, file name, channel names, End Site or not
    parents, offsets, names, channels, end_flags = [], [], [], [], []
    # stack of (joint index, is_end_site, has_offset, line of its opening keyword)
    stack: list[list] = []
    seen: dict[str, int] = {}  # file joint name -> line

    def open_node(parent: int, end_site: bool, name: str, line: int):
        brace = toks.next("'{'")
        if brace[0] != "{":
            raise toks.error(brace[1], f"expected '{{' after {'End Site' if end_site else name!r}, got {brace[0]!r}")
        if len(names) >= MAX_JOINTS:
            raise toks.error(line, f"more than MAX_JOINTS = {MAX_JOINTS} joints (End Sites included)")
        if len(stack) >= MAX_DEPTH:
            raise toks.error(line, f"nesting deeper than MAX_DEPTH = {MAX_DEPTH} levels")
        if not end_site:
            if name in seen:
                raise toks.error(line, f"duplicate joint name {name!r} (first on line {seen[name]})")
            seen[name] = line
        parents.append(parent)
        offsets.append((0.0, 0.0, 0.0))
        names.append(name)
        channels.append(())
        end_flags.append(end_site)
        stack.append([len(names) - 1, end_site, False, line])

    name, line = toks.rest_of_line()
    open_node(-1, False, name, line)
    while stack:
        node = stack[-1]
        j, is_end = node[0], node[1]
        tok, line = toks.next("OFFSET, CHANNELS, JOINT, End Site or '}'")
        key = tok.upper()
        if key == "OFFSET":
            if node[2]:
                raise toks.error(line, f"second OFFSET for {names[j]!r}")
            vals = [_parse_float(toks.next("an OFFSET number")[0], line, "OFFSET", toks) for _ in range(3)]
            offsets[j] = tuple(vals)
            node[2] = True
        elif key == "CHANNELS":
            if is_end:
                raise toks.error(line, "an End Site cannot have CHANNELS")
            if channels[j]:
                raise toks.error(line, f"second CHANNELS for {names[j]!r}")
            if len(names) - 1 > j:  # data columns follow the CHANNELS lines, which must precede the children
                raise toks.error(line, f"CHANNELS for {names[j]!r} after its first child")
            channels[j] = _parse_channels(toks, line, names[j])
        elif key == "JOINT":
            if is_end:
                raise toks.error(line, "an End Site cannot have children")
            if not node[2]:
                raise toks.error(line, f"missing OFFSET for {names[j]!r} before its first child")
            name, nline = toks.rest_of_line()
            open_node(j, False, name, nline)
        elif key == "END":
            site, sline = toks.next("'Site'")
            if site.upper() != "SITE":
                raise toks.error(sline, f"expected 'End Site', got 'End {site}'")
            if is_end:
                raise toks.error(line, "an End Site cannot have children")
            if not node[2]:
                raise toks.error(line, f"missing OFFSET for {names[j]!r} before its End Site")
            open_node(j, True, f"{names[j]}_end", line)
        elif key == "}":
            if not node[2]:
                what = f"the End Site of {names[parents[j]]!r}" if is_end else repr(names[j])
                raise toks.error(line, f"missing OFFSET for {what}")
            stack.pop()
        elif key == "MOTION":
            raise toks.error(line, f"MOTION before the hierarchy is closed ({len(stack)} '}}' missing: "
                                   "truncated hierarchy)")
        else:
            raise toks.error(line, f"unexpected {tok!r} in the block of {names[j]!r}")
    return parents, offsets, names, channels, end_flags


def _unique_names(names: list[str], end_flags: list[bool]) -> list[str]:
    """Make generated End Site names unique (a file joint may already be called ``X_end``)."""
    taken = {n for n, e in zip(names, end_flags) if not e}
    out = []
    for n, e in zip(names, end_flags):
        if e:
            base, k, cand = n, 1, n
            while cand in taken:
                k += 1
                cand = f"{base}{k}"
            taken.add(cand)
            n = cand
        out.append(n)
    return out


def _read_text(path) -> str:
    try:
        raw = read_bytes(path)
    except OSError as exc:
        raise ValueError(f"path: cannot read {os.fspath(path)!r}: {exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{os.fspath(path)}: not a UTF-8/ASCII text file ({exc})") from None
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    nul = text.find("\x00")
    if nul >= 0:
        raise ValueError(f"{os.fspath(path)}:{text.count(chr(10), 0, nul) + 1}: NUL byte (not a text file)")
    return text


_MOTION_LINE_RE = re.compile(r"^[^\S\n]*motion[^\S\n]*$", re.IGNORECASE | re.MULTILINE)


def _split_sections(text: str, motion):
    """Return (all lines, index of the ``MOTION`` line found by ``_MOTION_LINE_RE`` or None)."""
    return text.split("\n"), (None if motion is None else text.count("\n", 0, motion.start()))


_NODE_LINE_RE = re.compile(r"^[^\S\n]*(?:root|joint|end[^\S\n]+site)\b", re.IGNORECASE | re.MULTILINE)


def _check_joint_count(text: str, end: int, where: str) -> None:
    """Fast path of the ``MAX_JOINTS`` limit: one regex scan of ``text[:end]`` counting the lines that open a
    node (the parser checks the exact count too; this lets a huge hierarchy fail before it is parsed)."""
    for k, m in enumerate(_NODE_LINE_RE.finditer(text, 0, end), start=1):
        if k > MAX_JOINTS:
            raise ValueError(f"{where}:{text.count(chr(10), 0, m.start()) + 1}: more than MAX_JOINTS = "
                             f"{MAX_JOINTS} joints (End Sites included)")


def _parse_header(text: str, where: str):
    m = _MOTION_LINE_RE.search(text)
    _check_joint_count(text, len(text) if m is None else m.start(), where)  # before any per-line object exists
    lines, motion_at = _split_sections(text, m)
    # the MOTION line is part of the token stream so that a hierarchy cut short before it is reported there
    toks = _Tokens(lines if motion_at is None else lines[:motion_at + 1], where)
    if toks.peek() is None:
        raise ValueError(f"{where}:1: empty file (expected HIERARCHY)")
    parents, offsets, names, channels, end_flags = _parse_hierarchy(toks)
    nxt = toks.peek()
    if nxt is None:
        raise ValueError(f"{where}:{len(lines)}: missing MOTION section after the hierarchy")
    if nxt[0].upper() != "MOTION":
        if nxt[0].upper() == "ROOT":
            raise toks.error(nxt[1], "a second ROOT: files with several skeletons are not supported")
        raise toks.error(nxt[1], f"unexpected {nxt[0]!r} after the hierarchy (expected MOTION)")
    names = _unique_names(names, end_flags)  # file names are unique (checked while parsing)
    # Frames: and Frame Time: on the next non-empty lines
    i = motion_at + 1
    values = []
    for label, regex in (("Frames:", _FRAMES_RE), ("Frame Time:", _FRAME_TIME_RE)):
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise ValueError(f"{where}:{len(lines)}: unexpected end of file, expected '{label} ...'")
        m = regex.match(lines[i])
        if m is None:
            raise ValueError(f"{where}:{i + 1}: expected '{label} <value>', got {lines[i].strip()!r}")
        values.append((m.group(1), i + 1))
        i += 1
    (ftok, fline), (ttok, tline) = values
    if not re.fullmatch(r"\+?\d+", ftok):
        raise ValueError(f"{where}:{fline}: Frames: expected a non-negative integer, got {ftok!r}")
    num_frames = int(ftok)
    try:
        frame_time = float(ttok)
    except ValueError:
        raise ValueError(f"{where}:{tline}: Frame Time: expected a number of seconds, got {ttok!r}") from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise ValueError(f"{where}:{tline}: Frame Time: expected a positive finite number, got {ttok!r}")
    skel = Skeleton(parents, np.array(offsets, dtype=np.float64), names=names,
                    end_sites=[j for j, e in enumerate(end_flags) if e])
    header = BvhHeader(skeleton=skel, channels=tuple(channels), num_frames=num_frames, frame_time=frame_time)
    return header, lines, i  # i = index of the first data line


def read_bvh_header(path) -> BvhHeader:
    """Parse the hierarchy and the ``MOTION`` header of a BVH file (not its numbers).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    BvhHeader

    Raises
    ------
    ValueError
        ``"<file>:<line>: <problem>"`` for a malformed hierarchy or motion header.
    """
    where = os.fspath(path)
    header, _, _ = _parse_header(_read_text(path), where)
    return header



def _parse_motion(header: BvhHeader, lines: list[str], first: int, where: str) -> np.ndarray:
    """Numbers of the motion block as ``(T, C)`` float64, checked line by line against the header: every
    non-blank line after ``Frame Time`` is one frame of exactly ``C`` numbers."""
    data_lines = [ln for ln in lines[first:] if ln.strip()]
    c = header.num_channels
    if len(data_lines) != header.num_frames:
        last = len(lines)
        while last > first and not lines[last - 1].strip():
            last -= 1
        raise ValueError(f"{where}:{last}: Frames: declares {header.num_frames} frames but the file has "
                         f"{len(data_lines)} frame lines")
    per_frame = max(c, 4 * header.skeleton.num_joints)
    if len(data_lines) * per_frame > MAX_FRAME_VALUES:
        raise ValueError(f"{where}:{first + 1}: {len(data_lines)} frames × {per_frame} numbers per frame "
                         f"(max(channels, 4 · joints)) exceeds MAX_FRAME_VALUES = {MAX_FRAME_VALUES}")
    if c == 0:
        return np.zeros((len(data_lines), 0))
    rows = [ln.split() for ln in data_lines]
    if any(len(r) != c for r in rows):                                     # a value moved across lines too
        raise locate_bad_row(lines, first, c, where, unit="frame", expected="numbers (the channels of the hierarchy)")
    try:
        flat = np.array([t for r in rows for t in r], dtype=np.float64)    # one conversion for the block
    except ValueError:
        raise locate_bad_row(lines, first, c, where, unit="frame", expected="numbers (the channels of the hierarchy)") from None
    if not np.all(np.isfinite(flat)):
        raise locate_bad_row(lines, first, c, where, unit="frame", expected="numbers (the channels of the hierarchy)")
    return flat.reshape(len(data_lines), c)                                # (T, C)


_TRANSLATION_MODES = ("auto", "keep", "rotations", "mean")


def read_bvh(path, frame_time: float | None = None, name: str | None = None, translations: str = "auto",
             tolerance: float = TRANSLATION_TOLERANCE) -> Motion:
    """Read a BVH file into a :class:`~refimpl.motion.Motion`.

    Parameters
    ----------
    path : str or os.PathLike
    frame_time : float, optional
        Seconds per frame; overrides the declared ``Frame Time`` (use ``1/60`` for the CMU salsa files).
    name : str, optional
        Motion name; default the file stem.
    translations : {"auto", "keep", "rotations", "mean"}
        Position channels on non-root joints (they replace the joint's OFFSET, spec/data.md §2.1):

        * ``"keep"``: the motion as written: every such joint keeps per-frame translations
          (``Motion.translated_joints``);
        * ``"auto"`` (default): :func:`~refimpl.motion.simplify_translations` of that: re-root at the moving
          only child of the root, fold translations constant within ``tolerance`` into the offsets, keep
          the others per frame (same world positions);
        * ``"rotations"``: as ``"auto"`` but ``ValueError`` if a translation still varies (the result is
          rotations + root trajectory only);
        * ``"mean"``: as ``"auto"``, varying translations folded as their mean (lossy).
    tolerance : float
        Relative tolerance of "constant" (default ``TRANSLATION_TOLERANCE`` = 1e-4).

    Returns
    -------
    Motion
        Rotations ``(T, J, 4)`` float64 (End Sites identity, continuous over time), root positions
        ``(T, 3)`` = ROOT position channels (its OFFSET if it has none), optional per-frame translations.

    Raises
    ------
    ValueError
        ``"<file>:<line>: <problem>"`` for malformed files (truncated hierarchy, bad channel lists, duplicate
        joint names, limits exceeded, missing MOTION, bad Frames / Frame Time, a frame line without exactly
        the declared number of values, non-numeric or non-finite values, NUL bytes).
    """
    if translations not in _TRANSLATION_MODES:
        raise ValueError(f"translations: expected one of {_TRANSLATION_MODES}, got {translations!r}")
    if frame_time is not None:
        try:
            ok = math.isfinite(float(frame_time)) and float(frame_time) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"frame_time: expected a positive finite number of seconds, got {frame_time!r}")
    where = os.fspath(path)
    header, lines, first = _parse_header(_read_text(path), where)
    data = _parse_motion(header, lines, first, where)                     # (T, C)
    skel = header.skeleton
    num_frames, num_joints = data.shape[0], skel.num_joints

    # column index of each channel
    col = 0
    rot_cols: dict[str, list[tuple[int, list[int]]]] = {}   # padded order -> [(joint, 3 columns or -1)]
    pos_cols: list[tuple[int, list[int]]] = []
    for j, chans in enumerate(header.channels):
        rcols: dict[str, int] = {}
        pcols = [-1, -1, -1]
        for ch in chans:
            axis = ch[0].lower()
            if ch.endswith("rotation"):
                rcols[axis] = col
            else:
                pcols["xyz".index(axis)] = col
            col += 1
        if rcols:
            order = "".join(rcols) + "".join(a for a in "xyz" if a not in rcols)   # missing axes last, angle 0
            rot_cols.setdefault(order, []).append((j, [rcols.get(a, -1) for a in order]))
        if any(c >= 0 for c in pcols):
            pos_cols.append((j, pcols))

    padded = np.concatenate([data, np.zeros((num_frames, 1))], axis=1)     # column -1 reads 0
    rotations = np.zeros((num_frames, num_joints, 4))
    rotations[..., 0] = 1.0
    for order, items in rot_cols.items():
        joints = [j for j, _ in items]
        cols = np.array([c for _, c in items])                             # (n, 3)
        angles = np.deg2rad(padded[:, cols])                               # (T, n, 3)
        rotations[:, joints, :] = quat_from_euler(angles, order)
    if num_frames:
        rotations = quat_fix(rotations)

    # position channels replace the OFFSET (missing axes 0, as Blender's importer)
    root_positions = np.broadcast_to(skel.offsets[0], (num_frames, 3)).copy()
    moved = [j for j, _ in pos_cols if j != 0]
    local = None
    if moved:
        local = np.broadcast_to(skel.offsets, (num_frames, num_joints, 3)).copy()   # (T, J, 3)
    for j, pcols in pos_cols:
        values = padded[:, pcols]                                          # (T, 3)
        if j == 0:
            root_positions = values
        else:
            local[:, j, :] = values
    motion = Motion(skeleton=skel, rotations=rotations, root_positions=root_positions,
                    frame_time=header.frame_time if frame_time is None else float(frame_time),
                    name=Path(where).stem if name is None else name,
                    translations=local, translated_joints=moved if moved else None)
    if translations == "keep" or not moved:
        return motion
    varying = {"auto": "keep", "rotations": "error", "mean": "mean"}[translations]
    try:
        return simplify_translations(motion, tolerance, varying)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
