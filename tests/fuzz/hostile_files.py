"""Hostile inputs, fourth round (issue #36, spec/robustness.md §13): files that are not files, the data cache's own
damage, ``python -m deploy``'s options, files and metadata, options of another task.

Families (each case seeded from ``random.Random`` and classified by ``tests.fuzz.campaign._classify``: a time
limit per case, NumPy warnings are errors, ``tracemalloc`` peak ≤ 256 MB for the in-process work):

==================  =========================================================================================
``special-files``   every path a ``refimpl`` or ``python -m deploy`` command reads (checkpoints, state dicts
                    ``.npz``/``.safetensors``/``.pt``, BVH, exp-map ``.txt``, ``.onnx``, ``.npy``, ``--path``
                    CSV, ``--data`` files, the ``.onnx`` of a model folder) replaced by a FIFO, a symlink to
                    ``/dev/zero``, ``/dev/urandom`` or ``/dev/null``, a socket, a dangling symlink, a folder,
                    a chain of symlinks to a FIFO: exit 3, one line naming the path, within 20 s
``cache-damage``    a data-cache entry damaged in one of 30 ways (``__meta__`` valid JSON but not an object, a
                    member declaring a huge shape, deflated members, a 64 MB deflate bomb, bit flips, truncation,
                    junk, an object dtype, a FIFO, ``/dev/zero``, a decode that raises, ...) with stale and live
                    temporary files beside it: ``cached`` returns the freshly built value, notes "ignored" for
                    damage, the entry verifies afterwards; stale temporary files removed, a live writer's kept
``deploy-options``  ``python -m deploy run`` / ``export`` with one option hostile (``--threads``, ``--fps``,
                    ``--source-fps``, ``--start``, ``--frames``, ``--prefix``: 0, -1, 10^20, 1e-300, NaN, ...):
                    a value outside ``refimpl.bounds`` is exit 2 naming the option; otherwise exit 0, 2 or 3 with
                    one line
``deploy-files``    ``python -m deploy info`` / ``run`` on model folders with mutated metadata (types of every
                    documented key and of the fields inside: ``skeleton.names = 5``, ``normalization.mean = 5``,
                    ``input_transform.steps = 5``, missing fields), crafted ``.npy`` inputs (declared shapes of
                    TiBs, object dtypes, truncation), damaged BVH / exp-map inputs and takes shorter than the seed:
                    exit 0 or 3 (2 only naming an option), one line
``task-options``    ``refimpl eval / export / generate / train`` with an option of another task's group: exit 2
                    naming the option
==================  =========================================================================================

Usage::

    python -m tests.fuzz.hostile_files [--scale 1.0] [--seed 0] [--only special-files,cache-damage]

``--scale 1`` runs 3,400 cases. Prints the table, writes ``tests/fuzz/results/fuzz_hostile_files.json`` (atomic)
and exits 1 on any failure. ``tests/test_hostile_files.py`` runs a share and one test per cause of #36.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import random
import shutil
import socket
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

from tests.fuzz import campaign as fc
from tests.fuzz import surfaces as fs

#: Cases per family at ``--scale 1``.
BASE_CASES = {"special-files": 900, "cache-damage": 1200, "deploy-options": 500, "deploy-files": 600,
              "task-options": 200}
FAMILIES = tuple(BASE_CASES)


def deploy_main(argv) -> tuple[int, str]:
    """``python -m deploy``'s ``main(argv)`` in-process: ``(exit code, stderr)`` (argparse's exit included)."""
    from deploy.cli import main

    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, err.getvalue()


def check_deploy(code, err, codes=(0, 2, 3), names=None) -> str | None:
    """Why ``(code, stderr)`` of ``python -m deploy`` breaks the contract, or None: an allowed code, no traceback
    or warning, on failure exactly one error line (besides argparse's usage text), naming one of ``names``."""
    if code not in codes:
        return f"exit {code} (expected one of {codes}): {err.strip()[-200:]}"
    if "Traceback" in err or "Warning" in err:
        return f"traceback or warning: {err.strip()[-200:]}"
    if code == 0:
        return None
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    if len(lines) != 1 or "error: " not in lines[0]:
        return f"{len(lines)} error lines: {err.strip()[-200:]}"
    if names and not any(str(n) in lines[0] for n in names):
        return f"the error does not name {names[0]}: {lines[0][:200]}"
    return None


# ------------------------------------------------------------------------------------------------------------
# special-files
# ------------------------------------------------------------------------------------------------------------

SPECIAL_KINDS = ("fifo", "zero", "urandom", "null", "socket", "dangling", "folder", "fifo-chain")


def make_special(path: Path, kind: str, keep: list) -> Path:
    """``path`` made into a special file of ``kind`` (``keep`` holds sockets open until the case ends)."""
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind in ("zero", "urandom", "null"):
        path.symlink_to(f"/dev/{kind}")
    elif kind == "socket":
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.bind(str(path))
        keep.append(s)
    elif kind == "dangling":
        path.symlink_to(path.with_name(path.name + ".missing"))
    elif kind == "folder":
        path.mkdir()
    elif kind == "fifo-chain":
        target = path.with_name(path.name + ".fifo")
        with contextlib.suppress(FileNotFoundError):
            target.unlink()
        os.mkfifo(target)
        middle = path.with_name(path.name + ".link")
        with contextlib.suppress(FileNotFoundError):
            middle.unlink()
        middle.symlink_to(target)
        path.symlink_to(middle)
    return path


def _special_commands(seeds, out: Path) -> list:
    """``(tool, argv with "{P}", suffix)``: every path a command reads ("{P}" is replaced by the special file)."""
    S, W, B = fs.SALSA, fs.WALK_TXT, fs.WALK_BVH
    r = [("refimpl", ["info", "{P}"], s) for s in (".npz", ".bvh", ".txt", ".onnx")]
    r += [("refimpl", ["eval", "--checkpoint", "{P}"], ".npz"),
          ("refimpl", ["export", "--checkpoint", "{P}", "--out", out / "x", "--no-verify"], ".npz"),
          ("refimpl", ["generate", "--checkpoint", "{P}", "--source", S, "--length", "3", "--out", out / "g.bvh"],
           ".npz"),
          ("refimpl", ["generate", "--checkpoint", seeds["acrnn"], "--source", "{P}", "--length", "3", "--out",
                       out / "g.bvh"], ".bvh"),
          ("refimpl", ["generate", "--checkpoint", seeds["quaternet"], "--source", "{P}", "--source-frame", "20",
                       "--length", "3", "--out", out / "g.bvh"], ".txt"),
          ("refimpl", ["generate", "--checkpoint", seeds["qtg"], "--source", "{P}", "--source-frame", "5",
                       "--out", out / "g.bvh"], ".bvh"),
          ("refimpl", ["generate", "--model", "quaternet-long", "--checkpoint", seeds["quaternet-long"], "--pace",
                       seeds["pace"], "--path", "{P}", "--seconds", "0.3", "--out", out / "g.bvh"], ".csv"),
          ("refimpl", ["generate", "--model", "quaternet-long", "--checkpoint", "{P}", "--pace", seeds["pace"],
                       "--seconds", "0.3", "--out", out / "g.bvh"], ".npz"),
          ("refimpl", ["export-weights", "{P}", "--out", out / "w.npz"], ".npz"),
          ("refimpl", ["train", "--model", "qtg", "--data", "{P}", "--steps", "1", "--out", out / "run",
                       *fc.TINY], ".bvh"),
          ("refimpl", ["render", "{P}", "--out", out / "r.png"], ".bvh")]
    r += [("refimpl", ["import", "{P}", "--model", "quaternet", "--out", out / "i.npz"], s)
          for s in (".npz", ".safetensors", ".pt")]
    r += [("deploy", ["info", "{P}"], ".onnx"),
          ("deploy", ["export", "{P}", out / "dx"], ".npz"),
          ("deploy", ["run", seeds["onnx:qtg"], "{P}", out / "d.bvh", "--start", "5"], ".bvh"),
          ("deploy", ["run", seeds["onnx:acrnn"], "{P}", out / "d.bvh", "--frames", "3"], ".bvh"),
          ("deploy", ["run", seeds["onnx:quaternet"], "{P}", out / "d.bvh", "--frames", "3"], ".txt"),
          ("deploy", ["run", seeds["onnx:quaternet-long"], "{P}", out / "d.npy"], ".npy"),
          ("deploy", ["run", seeds["onnx:quaternet-long"], "{P}", out / "d.bvh", "--pace", seeds["onnx:pace"]],
           ".csv")]
    return r


def _special_case(rng, seeds, tmp, keep):
    """One command with one of its paths special: ``(tool, argv, description, names)``."""
    out = tmp / "sp_out"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    kind = rng.choice(SPECIAL_KINDS)
    if rng.random() < 0.15:  # an .onnx inside a model folder, special
        model = rng.choice(["qtg", "acrnn", "quaternet"])
        d = out / "models"
        shutil.copytree(seeds[f"onnx:{model}"], d)
        victim = rng.choice(sorted(d.glob("*.onnx")))
        make_special(victim, kind, keep)
        if rng.random() < 0.5:
            argv = ["deploy", ["run", d, {"qtg": fs.WALK_BVH, "acrnn": fs.SALSA, "quaternet": fs.WALK_TXT}[model],
                               out / "d.bvh", *(["--start", "5"] if model == "qtg" else [])]]
        else:
            argv = ["refimpl", ["generate", "--checkpoint", seeds[model], "--onnx", d, "--backend", "onnx",
                                "--source", {"qtg": fs.WALK_BVH, "acrnn": fs.SALSA, "quaternet": fs.WALK_TXT}[model],
                                *(["--source-frame", "5"] if model == "qtg" else
                                  ["--source-frame", "20"] if model == "quaternet" else []),
                                *(["--length", "3"] if model != "qtg" else []), "--out", out / "g.bvh"]]
        return (*argv, f"{argv[0]} {argv[1][0]} folder with {victim.name} {kind}", [victim.name, d.name])
    tool, argv, suffix = rng.choice(_special_commands(seeds, out))
    stem = rng.choice(["p", "with space", "ünï", "a.b"])
    if rng.random() < 0.2:
        suffix = suffix.upper()
    p = make_special(out / f"{stem}{suffix}", kind, keep)
    argv = [p if a == "{P}" else a for a in argv]
    return tool, argv, f"{tool} {argv[0]} {kind} {p.name}", [p.name]


def fam_special_files(stats, n, seed, seeds, tmp, log):
    rng = random.Random(seed)
    for i in range(n):
        keep: list = []
        tool, argv, what, names = _special_case(rng, seeds, tmp, keep)

        def case():
            code, err = fs._main(argv) if tool == "refimpl" else deploy_main(argv)
            if tool == "refimpl":
                return fs._check_cli(code, err, argv[0], (3,), names)
            return check_deploy(code, err, (3,), names)
        kind, failure, detail, sec, peak = fc._classify(case, (), 20.0)
        for s in keep:
            s.close()
        stats.add("special-files", kind, "CliContract" if failure == "AcceptedMalformed" else failure, detail,
                  sec, peak, what)
        if log and (i + 1) % 100 == 0:
            log(f"  special-files {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# cache-damage
# ------------------------------------------------------------------------------------------------------------

def _member_bytes(arrays: dict) -> dict:
    return {f"{k}.npy": fc.readers._npy_of(v) for k, v in arrays.items()}


def _npy_header(shape, descr="<f8", fortran=False) -> bytes:
    header = repr({"descr": descr, "fortran_order": fortran, "shape": tuple(shape)}).encode("latin1")
    pad = 64 - (10 + len(header) + 1) % 64
    return b"\x93NUMPY\x01\x00" + (len(header) + pad + 1).to_bytes(2, "little") + header + b" " * pad + b"\n"


_BOMB: dict = {}


def _bomb() -> bytes:
    """A deflated member declaring 64 MB of zeros (~64 KB on disk), built once."""
    if "zip" not in _BOMB:
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            with z.open("x.npy", "w", force_zip64=True) as f:
                f.write(_npy_header((2**23,)))
                block = bytes(2**22)
                for _ in range(16):
                    f.write(block)
        _BOMB["zip"] = buf.getvalue()
    return _BOMB["zip"]


CACHE_DAMAGE = ("meta-list", "meta-number", "meta-string", "meta-null", "meta-inner-list", "meta-deep",
                "meta-not-json", "meta-nan", "meta-uint8", "meta-2d", "no-meta", "no-checksum", "checksum-wrong",
                "checksum-int", "key-other", "name-other", "huge-shape", "shape-mismatch", "negative-shape",
                "deflated", "bomb", "object-dtype", "truncate", "bitflip", "junk", "empty", "extra-member",
                "fifo", "zero", "folder", "decode-raises", "none")


def _damage_entry(path: Path, kind: str, rng, keep) -> None:
    """Damage the valid entry at ``path`` (``none``, ``decode-raises``: left as it is)."""
    from refimpl import datacache

    data = path.read_bytes()
    members = fc.readers._unzip(data)
    meta = json.loads(str(np.load(io.BytesIO(members["__meta__.npy"]), allow_pickle=False)))
    text = {"meta-list": "[1, 2]", "meta-number": "5", "meta-string": '"x"', "meta-null": "null",
            "meta-inner-list": json.dumps(dict(meta, meta=[1])), "meta-deep": "[" * 100_000 + "]" * 100_000,
            "meta-not-json": "{", "meta-nan": "NaN", "key-other": json.dumps(dict(meta, key="0" * 64)),
            "name-other": json.dumps(dict(meta, name="other"))}
    if kind in text:
        members["__meta__.npy"] = fc.readers._npy_of(np.array(text[kind]))
    elif kind == "meta-uint8":
        members["__meta__.npy"] = fc.readers._npy_of(np.frombuffer(json.dumps(meta).encode(), np.uint8))
    elif kind == "meta-2d":
        members["__meta__.npy"] = fc.readers._npy_of(np.array([[json.dumps(meta)]]))
    elif kind in ("no-meta", "no-checksum"):
        members.pop("__meta__.npy" if kind == "no-meta" else "__checksum__.npy")
    elif kind == "checksum-wrong":
        members["__checksum__.npy"] = fc.readers._npy_of(np.array("crc32:00000000"))
    elif kind == "checksum-int":
        members["__checksum__.npy"] = fc.readers._npy_of(np.array(5))
    elif kind in ("huge-shape", "shape-mismatch", "negative-shape", "object-dtype"):
        shape = {"huge-shape": (10**7, 10**7), "shape-mismatch": (3, 1000), "negative-shape": (-1, 3),
                 "object-dtype": (3,)}[kind]
        members["a.npy"] = _npy_header(shape, "|O" if kind == "object-dtype" else "<f8") + bytes(48)
    elif kind == "extra-member":
        members["notes.txt"] = b"hello"
    if kind in ("deflated", "extra-member") or kind in text or kind.startswith(("meta-", "no-", "checksum-")) \
            or kind in ("huge-shape", "shape-mismatch", "negative-shape", "object-dtype"):
        path.write_bytes(fc.readers._zip(members, compress=kind == "deflated"))
    elif kind == "bomb":
        path.write_bytes(_bomb())
    elif kind == "truncate":
        path.write_bytes(data[:rng.randrange(len(data))])
    elif kind == "bitflip":
        b = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        path.write_bytes(bytes(b))
    elif kind == "junk":
        path.write_bytes(bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 3000))))
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind in ("fifo", "zero", "folder"):
        make_special(path, kind, keep)
    assert datacache  # the module under test (imported for its side-effect-free name)


def _cache_case(rng, tmp: Path):
    """One damaged entry; returns the case function and its description."""
    from refimpl import datacache

    folder = tmp / f"cache_{rng.randrange(10**9)}"
    folder.mkdir()
    n = rng.randint(1, 50)
    value = {"a": np.arange(3 * n, dtype=np.float64).reshape(n, 3) * rng.random(),
             "b": np.arange(n, dtype=rng.choice([np.int32, np.int64, np.uint8])), "c": np.array(["x", "yz"][:1 + n % 2])}
    encode = lambda v: (dict(v), {"n": n})  # noqa: E731
    kind = rng.choice(CACHE_DAMAGE)
    raising = kind == "decode-raises"

    def decode(arrays, meta):
        if raising:
            raise rng.choice([AttributeError, TypeError, RuntimeError, ZeroDivisionError])("decoder of another layout")
        return {k: arrays[k] for k in ("a", "b", "c")}
    key = f"{rng.getrandbits(128):032x}"
    path = datacache.save_entry("fz", key, *encode(value), folder=folder)
    keep: list = []
    _damage_entry(path, kind, rng, keep)
    stale = [folder / f".{path.stem}.{rng.getrandbits(48):012x}.tmp.npz" for _ in range(rng.randint(0, 2))]
    for s in stale:
        s.write_bytes(b"partial")
    live = None
    if rng.random() < 0.3:
        import fcntl
        live_path = folder / f".{path.stem}.{rng.getrandbits(48):012x}.tmp.npz"
        live = os.open(live_path, os.O_WRONLY | os.O_CREAT, 0o666)
        fcntl.flock(live, fcntl.LOCK_EX)
    notes: list = []
    built = []

    def build():
        built.append(1)
        return {k: v.copy() for k, v in value.items()}

    def case():
        try:
            got = datacache.cached("fz", key, build, encode, decode, folder=folder, progress=notes.append)
            if set(got) != set(value) or not all(np.array_equal(got[k], value[k]) for k in value):
                return "cached returned other arrays than the built ones"
            damaged = kind not in ("none",)
            if damaged and kind != "bitflip" and not built:
                return f"a damaged entry ({kind}) was used"
            if built and kind not in ("none",) and not any("ignored" in m for m in notes) and kind != "bitflip":
                return f"the damage ({kind}) was not noted: {notes}"
            if any(s.exists() for s in stale):
                return "a stale temporary file was left"
            if live is not None and not live_path.exists():
                return "a live writer's temporary file was removed"
            if kind != "folder" and not raising:
                _, _, status = datacache.load_entry("fz", key, folder=folder)
                if status != "hit":
                    return f"the rebuilt entry does not verify: {status}"
            return None
        finally:
            if live is not None:
                os.close(live)
            for s in keep:
                s.close()
    return case, f"{kind}, {len(stale)} stale, {'a live writer' if live is not None else 'no writer'}"


def fam_cache_damage(stats, n, seed, tmp, log):
    rng = random.Random(seed)
    for i in range(n):
        case, what = _cache_case(rng, tmp)
        kind, failure, detail, sec, peak = fc._classify(case, (), 20.0)
        stats.add("cache-damage", kind, failure, detail, sec, peak, what)
        if log and (i + 1) % 200 == 0:
            log(f"  cache-damage {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# deploy-options
# ------------------------------------------------------------------------------------------------------------

OPTION_VALUES = ["0", "-1", "1", "2", "3", "5", "30", "60", "256", "257", "1000", "1001", "100000", "100001",
                 "99999999999999999999", "1e-300", "1e300", "nan", "inf", "-inf", "1.5", "0.5", "x", "", "0x10"]
#: option -> its range (spec/cli.md §1.1, written out here as the oracle: ``refimpl.bounds`` is under test).
DEPLOY_OPTIONS = {"--threads": (1, 256), "--fps": (1.0, 1000.0), "--source-fps": (1.0, 1000.0),
                  "--start": (0, 100_000), "--frames": (1, 100_000), "--prefix": (1, 100_000)}


def _in_bounds(flag: str, text: str) -> bool:
    lo, hi = DEPLOY_OPTIONS[flag]
    try:
        v = float(text) if isinstance(lo, float) else int(text)
    except ValueError:
        return False
    return v == v and lo <= v <= hi


def _deploy_run_argv(rng, seeds, out: Path) -> tuple[str, list]:
    model = rng.choice(["qtg", "acrnn", "quaternet", "quaternet-long"])
    base = {"qtg": [fs.WALK_BVH, out / "d.bvh"], "acrnn": [fs.SALSA, out / "d.bvh"],
            "quaternet": [fs.WALK_TXT, out / "d.bvh"], "quaternet-long": ["circle:r=2", out / "d.bvh", "--pace",
                                                                         seeds["onnx:pace"], "--seconds", "0.3"]}
    return model, ["run", seeds[f"onnx:{model}"], *base[model]]


def fam_deploy_options(stats, n, seed, seeds, tmp, log):
    rng = random.Random(seed)
    owners = {"--source-fps": ("qtg",), "--prefix": ("quaternet",)}
    for i in range(n):
        out = tmp / "do_out"
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir()
        model, argv = _deploy_run_argv(rng, seeds, out)
        flag = rng.choice(sorted(DEPLOY_OPTIONS))
        value = rng.choice(OPTION_VALUES)
        if flag in owners and model not in owners[flag]:
            model, argv = "qtg" if flag == "--source-fps" else "quaternet", None
            argv = ["run", seeds[f"onnx:{model}"], fs.WALK_BVH if model == "qtg" else fs.WALK_TXT, out / "d.bvh"]
        if model == "qtg" and flag != "--start":
            argv += ["--start", "5"]
        if model == "quaternet-long" and flag in ("--start", "--frames", "--fps"):
            argv = ["run", seeds["onnx:qtg"], fs.WALK_BVH, out / "d.bvh"] + (["--start", "5"] if flag != "--start"
                                                                            else [])
        argv += [flag, value]
        bad = not _in_bounds(flag, value)

        def case():
            code, err = deploy_main(argv)
            if bad:
                return check_deploy(code, err, (2,), [flag])
            return check_deploy(code, err, (0, 2, 3))
        # honest work up to the bound (100,000 predicted frames) takes minutes on a busy core
        limit = 600.0 if not bad and flag in ("--frames", "--prefix") and int(value) >= 10_000 else 60.0
        kind, failure, detail, sec, peak = fc._classify(case, (), limit, check_memory=False)
        stats.add("deploy-options", kind, "CliContract" if failure == "AcceptedMalformed" else failure, detail,
                  sec, peak, " ".join(map(str, argv[3:]))[:200] + f" ({model})")
        if log and (i + 1) % 100 == 0:
            log(f"  deploy-options {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# deploy-files
# ------------------------------------------------------------------------------------------------------------

META_EDITS = [("skeleton", {"names": 5}), ("skeleton", "names=5"), ("skeleton", "del names"), ("skeleton", "del parents"),
              ("skeleton", "parents=['a']"), ("skeleton", "offsets=[[1, 2]]"), ("skeleton", 5), ("skeleton", []),
              ("normalization", "mean=5"), ("normalization", "del mean"), ("normalization", "del in_graph"),
              ("normalization", "in_graph='yes'"), ("normalization", "std=['x']"), ("normalization", "mean=[]"),
              ("normalization", 5), ("input_transform", "steps=5"), ("output_transform", "steps=5"),
              ("input_transform", "summary=5"), ("input_transform", 5), ("model", "del name"), ("model", "name=5"),
              ("model", "config=5"), ("model", 5), ("representation", "name=5"), ("representation", "size='x'"),
              ("representation", "size=7"), ("frame_rate", 0), ("frame_rate", -1), ("frame_rate", 1e308),
              ("frame_rate", "30"), ("frame_rate", 1e-300), ("format", 5), ("io", 5), ("exporter", "x"),
              ("source_paper", None)]


def edit_metadata(src: Path, dst: Path, key: str, edit) -> None:
    """Copy the ``.onnx`` ``src`` to ``dst`` with metadata ``key`` edited: a value (JSON), ``"del <field>"`` or
    ``"<field>=<python literal>"`` on the object it holds."""
    import ast

    import onnx

    m = onnx.load_model_from_string(src.read_bytes())
    props = {p.key: p.value for p in m.metadata_props}
    value = json.loads(props[key]) if key in props else None
    if isinstance(edit, str) and edit.startswith("del ") and isinstance(value, dict):
        value.pop(edit[4:], None)
    elif isinstance(edit, str) and "=" in edit and isinstance(value, dict):
        field, _, lit = edit.partition("=")
        value[field] = ast.literal_eval(lit)
    else:
        value = edit
    props[key] = json.dumps(value)
    del m.metadata_props[:]
    for k, v in props.items():
        m.metadata_props.add(key=k, value=v)
    dst.write_bytes(m.SerializeToString())


NPY_KINDS = ("huge", "negative", "object", "truncated", "trailing", "bad-magic", "version-3", "bool", "complex",
             "zero-d", "nan", "rank-2", "fortran", "big-endian", "ok")


def crafted_npy(kind: str, rng) -> bytes:
    """A ``.npy`` of ``kind`` for the quaternet-long step model (112 values per frame; ``ok`` is valid)."""
    good = np.asarray(np.random.default_rng(rng.randrange(99)).standard_normal((1, 8, 112)) * 0.1, np.float32)
    if kind == "huge":
        return _npy_header((10**6, 10**6, 112), "<f4")
    if kind == "negative":
        return _npy_header((-1, 8, 112), "<f4")
    if kind == "object":
        return _npy_header((1, 8, 112), "|O") + b"\x00" * 64
    if kind == "bad-magic":
        return b"\x93NUMPX" + fc.readers._npy_of(good)[6:]
    if kind == "version-3":
        return b"\x93NUMPY\x03\x00" + fc.readers._npy_of(good)[8:]
    data = {"bool": good > 0, "complex": good.astype(np.complex64), "zero-d": np.float32(1.0),
            "rank-2": good[0], "fortran": np.asfortranarray(good[0]), "big-endian": good.astype(">f4"),
            "nan": np.where(good > 0.1, np.nan, good).astype(np.float32)}.get(kind, good)
    raw = fc.readers._npy_of(data)
    if kind == "truncated":
        return raw[:rng.randrange(10, len(raw) - 1)]
    if kind == "trailing":
        return raw + b"junk"
    return raw


def _text_damage(data: bytes, rng) -> tuple[bytes, str]:
    kind = rng.choice(["truncate", "nan", "junk-line", "bitflip", "empty", "frame-time-0", "frame-time-tiny",
                       "frame-time-huge", "frames-huge", "utf16", "nul", "short"])
    lines = data.split(b"\n")
    if kind == "truncate":
        return data[:rng.randrange(len(data))], kind
    if kind == "nan":
        k = rng.randrange(len(lines) // 2, len(lines))
        return b"\n".join(lines[:k] + [lines[k].replace(b"0", b"nan", 1)] + lines[k + 1:]), kind
    if kind == "junk-line":
        k = rng.randrange(len(lines))
        return b"\n".join(lines[:k] + [b"hello world"] + lines[k:]), kind
    if kind == "bitflip":
        b = bytearray(data)
        b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b), kind
    if kind == "empty":
        return b"", kind
    if kind.startswith("frame-time") or kind == "frames-huge":
        new = {"frame-time-0": b"Frame Time: 0", "frame-time-tiny": b"Frame Time: 1e-300",
               "frame-time-huge": b"Frame Time: 1e300", "frames-huge": b"Frames: 99999999999"}[kind]
        start = b"Frames:" if kind == "frames-huge" else b"Frame Time:"
        return b"\n".join(new if ln.startswith(start) else ln for ln in lines), kind
    if kind == "utf16":
        return data.decode("latin1").encode("utf-16"), kind
    if kind == "nul":
        return data[:200] + b"\x00" + data[200:], kind
    keep = rng.randint(1, 12)  # a take of a few frames: shorter than a seed or a prefix
    head = [i for i, ln in enumerate(lines) if ln.startswith(b"Frame Time")]
    if head:
        i = head[0]
        return b"\n".join([ln if not ln.startswith(b"Frames:") else b"Frames: %d" % keep for ln in lines[:i + 1]]
                          + lines[i + 1:i + 1 + keep]) + b"\n", f"short {keep}"
    return b"\n".join(lines[:keep]) + b"\n", f"short {keep}"


def _files_case(rng, seeds, tmp):
    out = tmp / "df_out"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    what = rng.random()
    if what < 0.45:  # metadata mutated: info on the file, or run on the folder
        model = rng.choice(["qtg", "acrnn", "quaternet", "quaternet-cnn", "quaternet-long"])
        d = out / "models"
        shutil.copytree(seeds[f"onnx:{model}"], d)
        f = rng.choice(sorted(d.glob("*.onnx")))
        key, edit = rng.choice(META_EDITS)
        edit_metadata(f, f, key, edit)
        desc = f"{model} {f.name} {key} {edit!r}"[:200]
        if rng.random() < 0.5:
            return ["info", f], desc, (0, 3), [f.name]
        _, argv = _deploy_run_argv(random.Random(0), seeds, out)  # noqa: F841 - shape of a run command only
        inputs = {"qtg": [fs.WALK_BVH, out / "d.bvh", "--start", "5"], "acrnn": [fs.SALSA, out / "d.bvh",
                  "--frames", "3"], "quaternet": [fs.WALK_TXT, out / "d.bvh", "--frames", "3"],
                  "quaternet-cnn": [fs.WALK_TXT, out / "d.bvh", "--frames", "3"],
                  "quaternet-long": ["circle:r=2", out / "d.bvh", "--pace", seeds["onnx:pace"], "--seconds", "0.3"]}
        return ["run", d, *inputs[model]], "run " + desc, (0, 3), ["models"]
    if what < 0.65:  # crafted .npy inputs
        kind = rng.choice(NPY_KINDS)
        p = out / "x.npy"
        p.write_bytes(crafted_npy(kind, rng))
        return ["run", seeds["onnx:quaternet-long"], p, out / "y.npy"], f"npy {kind}", (0, 3), ["x.npy"]
    model = rng.choice(["qtg", "acrnn", "quaternet"])  # damaged motion inputs
    src = {"qtg": fs.WALK_BVH, "acrnn": fs.SALSA, "quaternet": fs.WALK_TXT}[model]
    data, kind = _text_damage(src.read_bytes(), rng)
    p = out / f"in{src.suffix}"
    p.write_bytes(data)
    extra = {"qtg": ["--start", "5"], "acrnn": ["--frames", "3"], "quaternet": ["--frames", "3"]}[model]
    return ["run", seeds[f"onnx:{model}"], p, out / "d.bvh", *extra], f"{model} input {kind}", (0, 2, 3), [p.name]


def fam_deploy_files(stats, n, seed, seeds, tmp, log):
    rng = random.Random(seed)
    for i in range(n):
        argv, what, codes, names = _files_case(rng, seeds, tmp)

        def case():
            code, err = deploy_main(argv)
            bad = check_deploy(code, err, codes, names if code == 3 else None)
            if bad is None and code == 2 and "--" not in err.splitlines()[-1]:
                bad = f"exit 2 for an input file (expected 3): {err.strip()[-200:]}"
            if bad is None and code == 2 and "[0, -" in err:
                bad = f"an empty range: {err.strip()[-200:]}"
            return bad
        kind, failure, detail, sec, peak = fc._classify(case, (), 60.0)
        stats.add("deploy-files", kind, "CliContract" if failure == "AcceptedMalformed" else failure, detail,
                  sec, peak, what)
        if log and (i + 1) % 100 == 0:
            log(f"  deploy-files {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# task-options
# ------------------------------------------------------------------------------------------------------------

def _task_flags(command: str) -> list:
    """``[(task, flag, argv tail)]`` of ``refimpl <command>``'s task groups, each with a value that parses."""
    from refimpl.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    p = sub.choices[command]
    out = []
    for task, options in p.get_default("task_options").items():
        for dest, _, flag in options:
            action = next(a for a in p._actions if a.dest == dest)
            if action.nargs == 0:
                tail = [flag]
            elif action.choices:
                tail = [flag, next(str(c) for c in sorted(action.choices, key=str) if c != action.default)]
            elif action.nargs in (3, "+"):
                tail = [flag, "1", "1", "1"]
            elif isinstance(action.default, (int, float)) and not isinstance(action.default, bool):
                tail = [flag, str(type(action.default)(action.default + 1))]
            else:
                tail = [flag, "2"]
            out.append((task, flag, tail))
    return out


def fam_task_options(stats, n, seed, seeds, tmp, log):
    from refimpl.registry import MODELS

    rng = random.Random(seed)
    commands = {c: _task_flags(c) for c in ("eval", "export", "generate", "train")}
    for i in range(n):
        command = rng.choice(sorted(commands))
        model = rng.choice(sorted(fs.TINY))
        task = MODELS[model].task
        choices = [c for c in commands[command] if c[0] != task]
        if not choices:
            continue
        owner, flag, tail = rng.choice(choices)
        out = tmp / "to_out"
        shutil.rmtree(out, ignore_errors=True)
        if command == "train":
            argv = ["train", *fs.TINY[model], "--steps", "1", "--out", out]
        elif command == "export":
            argv = ["export", "--checkpoint", seeds[model], "--out", out, "--no-verify"]
        elif command == "eval":
            argv = ["eval", "--checkpoint", seeds[model]]
        else:
            argv = ["generate", "--checkpoint", seeds[model], "--out", out / "g.bvh"]
        argv += tail

        def case():
            code, err = fs._main(argv)
            return fs._check_cli(code, err, command, (2,), [flag])
        kind, failure, detail, sec, peak = fc._classify(case, (), 60.0, check_memory=False)
        stats.add("task-options", kind, "CliContract" if failure == "AcceptedMalformed" else failure, detail,
                  sec, peak, f"{command} {model} {' '.join(tail)}")
        if log and (i + 1) % 50 == 0:
            log(f"  task-options {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# campaign
# ------------------------------------------------------------------------------------------------------------

def campaign(scale: float = 1.0, seed: int = 0, only: set | None = None, log=print,
             counts: dict | None = None) -> dict:
    """Run the families (``counts``: cases per family, default :data:`BASE_CASES` × ``scale``)."""
    counts = fc.family_counts(BASE_CASES, scale, only, counts)
    stats = fc.Stats()
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz_hostile_files_") as tmp:
        tmp = Path(tmp)
        if log:
            log("training and exporting the seed models ...")
        seeds = fs.make_seeds(tmp)
        runners = {"special-files": lambda n: fam_special_files(stats, n, seed, seeds, tmp, log),
                   "cache-damage": lambda n: fam_cache_damage(stats, n, seed, tmp, log),
                   "deploy-options": lambda n: fam_deploy_options(stats, n, seed, seeds, tmp, log),
                   "deploy-files": lambda n: fam_deploy_files(stats, n, seed, seeds, tmp, log),
                   "task-options": lambda n: fam_task_options(stats, n, seed, seeds, tmp, log)}
        fc.run_families(stats, counts, runners, log)
    return fc.summary(stats, seed, scale, counts, t_all)


def _with_command(scale: float, seed: int, only) -> dict:
    """:func:`campaign`'s result with the command line that reproduces it (stored in the result JSON)."""
    res = campaign(scale, seed, only)
    res["command"] = (f"python -m tests.fuzz.hostile_files --scale {scale:g} --seed {seed}"
                      + (f" --only {','.join(sorted(only))}" if only else ""))
    return res


def main(argv=None) -> int:
    return fc.run_main(argv, __doc__, FAMILIES, _with_command, "fuzz_hostile_files.json")


if __name__ == "__main__":
    sys.exit(main())
