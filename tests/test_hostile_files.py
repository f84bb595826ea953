"""Issue #36: files that are not files, the data cache's own damage, ``python -m deploy``'s options, files and
metadata, options of another task — one test per cause found at 4f4f4ef (each fails there), and a share of the
campaign ``tests/fuzz/hostile_files.py`` (spec/robustness.md §13)."""
from __future__ import annotations

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from refimpl import datacache
from refimpl.errors import BadInputError, existing_file
from refimpl.files import check_regular, read_bytes
from tests.fuzz import hostile_files as hf
from tests.fuzz import surfaces as fs

ROOT = Path(__file__).resolve().parents[1]
pytest.importorskip("onnxruntime")


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    """Tiny checkpoints of the six models and their exports (``fuzz_surfaces.make_seeds``)."""
    return fs.make_seeds(tmp_path_factory.mktemp("hostile4_seeds"))


def _limit():  # pragma: no cover - runs in the child: 3 GB of address space, so a reader of /dev/zero stops
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))


def _process(tool: str, argv, cwd) -> tuple[int, str]:
    """``python -m <tool> argv`` as a real process with a 60 s limit; a hang is a test failure, not a hang."""
    cmd = [sys.executable, "-m", tool, *map(str, argv)]
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1")
    try:
        p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=60, env=env, preexec_fn=_limit)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{' '.join(cmd[2:])} did not return within 60 s")
    return p.returncode, p.stderr


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    assert len(lines) == 1 and "error: " in lines[0] and "Traceback" not in err, err
    return lines[0]


# ---------------------------------------------------------------------------------------------------------------
# 1. paths that are not regular files (real processes, a FIFO and a symlink to /dev/zero)
# ---------------------------------------------------------------------------------------------------------------

CASES = [("refimpl", ["import", "{P}.npz", "--model", "quaternet", "--out", "o.npz"], "fifo"),
         ("refimpl", ["import", "{P}.safetensors", "--model", "quaternet", "--out", "o.npz"], "fifo"),
         ("refimpl", ["export-weights", "{P}.npz", "--out", "w.npz"], "fifo"),
         ("refimpl", ["info", "{P}.npz"], "zero"), ("refimpl", ["eval", "--checkpoint", "{P}.npz"], "zero"),
         ("deploy", ["info", "{P}.onnx"], "fifo")]
#: The same in-process (a SIGALRM limit per case): the other readers of the issue.
IN_PROCESS = [("refimpl", ["info", "{P}.bvh"], "zero"), ("refimpl", ["info", "{P}.onnx"], "zero"),
              ("refimpl", ["info", "{P}.txt"], "fifo"),
              ("refimpl", ["import", "{P}.npz", "--model", "quaternet", "--out", "o.npz"], "zero"),
              ("refimpl", ["import", "{P}.pt", "--model", "quaternet", "--out", "o.npz"], "fifo"),
              ("deploy", ["info", "{P}.onnx"], "zero"), ("deploy", ["export", "{P}.npz", "dx"], "fifo")]


@pytest.mark.parametrize("tool,argv,kind", CASES, ids=[f"{t}-{a[0]}-{a[1 if a[0] != 'eval' else 2]}-{k}"
                                                       for t, a, k in CASES])
def test_special_files_are_refused_at_once(tmp_path, tool, argv, kind):
    """At 4f4f4ef a FIFO blocked forever and /dev/zero grew memory without end (``existing_file`` accepted
    anything that is not a folder; the readers read to EOF). Now: exit 3, one line naming the path."""
    suffix = next(a for a in argv if "{P}" in a)[3:]
    p = hf.make_special(tmp_path / f"in{suffix}", kind, [])
    code, err = _process(tool, [str(p) if "{P}" in a else a for a in argv], tmp_path)
    assert code == 3, err
    assert p.name in _one_line(err) and "not a regular file" in err


def _in_process(tool, argv):
    """``(code, stderr)`` of ``tool``'s main in-process under a 30 s SIGALRM limit (a FIFO open is interrupted);
    the modules are imported first (on a busy machine that alone can take 20 s)."""
    import deploy.cli
    import refimpl.cli

    deploy.cli._parser(), refimpl.cli.build_parser()
    got = []
    kind, failure, detail, _, _ = hf.fc._classify(
        lambda: got.append(fs._main(argv) if tool == "refimpl" else hf.deploy_main(argv)), (), 30.0)
    assert failure is None, (kind, detail)
    return got[0]


@pytest.mark.parametrize("tool,argv,kind", IN_PROCESS, ids=[f"{t}-{a[0]}-{a[1]}-{k}" for t, a, k in IN_PROCESS])
def test_special_files_in_process(tmp_path, monkeypatch, tool, argv, kind):
    monkeypatch.chdir(tmp_path)
    suffix = next(a for a in argv if "{P}" in a)[3:]
    p = hf.make_special(tmp_path / f"in{suffix}", kind, [])
    code, err = _in_process(tool, [str(p) if "{P}" in a else a for a in argv])
    assert code == 3 and p.name in _one_line(err), err


def test_deploy_run_of_a_special_npy_and_a_special_model(seeds, tmp_path):
    """``python -m deploy run DIR fifo.npy`` and a folder whose ``.onnx`` is a FIFO: exit 3 at once."""
    fifo = hf.make_special(tmp_path / "x.npy", "fifo", [])
    code, err = _in_process("deploy", ["run", seeds["onnx:quaternet-long"], fifo, tmp_path / "y.npy"])
    assert code == 3 and "x.npy" in _one_line(err), err
    d = tmp_path / "models"
    shutil.copytree(seeds["onnx:qtg"], d)
    hf.make_special(d / "qtg_step.onnx", "fifo", [])
    code, err = _in_process("deploy", ["run", d, fs.WALK_BVH, tmp_path / "o.bvh", "--start", "5"])
    assert code == 3 and "qtg_step.onnx" in _one_line(err), err


def test_the_rule_in_the_library(tmp_path):
    """``existing_file`` refuses a FIFO, a device, a socket; the readers refuse them without blocking."""
    keep = []
    for kind in hf.SPECIAL_KINDS:
        p = hf.make_special(tmp_path / f"{kind}.npz", kind, keep)
        with pytest.raises(BadInputError, match=p.name):
            existing_file(p)
        with pytest.raises((ValueError, OSError)):
            read_bytes(p)
    for s in keep:
        s.close()
    ok = tmp_path / "ok.bin"
    ok.write_bytes(b"abc")
    assert read_bytes(ok) == b"abc" and check_regular(ok).st_size == 3
    with pytest.raises(ValueError, match="more than the 2"):
        read_bytes(ok, limit=2)


# ---------------------------------------------------------------------------------------------------------------
# 2. the data cache's own damage and the temporary files of killed writers
# ---------------------------------------------------------------------------------------------------------------

def _entry(tmp_path, meta_text=None, member=None, compress=False):
    value = {"a": np.arange(12.0).reshape(4, 3)}
    path = datacache.save_entry("t", "k" * 64, value, {"n": 1}, folder=tmp_path)
    members = hf.fc.readers._unzip(path.read_bytes())
    if meta_text is not None:
        members["__meta__.npy"] = hf.fc.readers._npy_of(np.array(meta_text))
    if member is not None:
        members["a.npy"] = member
    path.write_bytes(hf.fc.readers._zip(members, compress=compress))
    return value, path


def _cached(tmp_path, value):
    notes = []
    got = datacache.cached("t", "k" * 64, lambda: value, lambda v: (dict(v), {"n": 1}),
                           lambda a, m: {"a": a["a"]}, folder=tmp_path, progress=notes.append)
    assert np.array_equal(got["a"], value["a"])
    return notes


@pytest.mark.parametrize("meta", ["[1, 2]", "5", '"x"', "null", json.dumps({"key": "k" * 64, "name": "t",
                                                                           "meta": [1]})])
def test_cache_meta_that_is_not_an_object_is_rebuilt(tmp_path, meta):
    """``__meta__`` valid JSON but not an object: AttributeError (exit 1) at 4f4f4ef on every later command."""
    value, path = _entry(tmp_path, meta_text=meta)
    assert any("ignored" in n for n in _cached(tmp_path, value))
    assert datacache.load_entry("t", "k" * 64, folder=tmp_path)[2] == "hit"


def test_cache_member_declaring_a_huge_shape_is_rebuilt(tmp_path):
    """A header declaring 72 TiB: MemoryError escaped at 4f4f4ef; now corrupt, nothing allocated."""
    value, path = _entry(tmp_path, member=hf._npy_header((10**7, 10**7)) + bytes(96))
    status = datacache.load_entry("t", "k" * 64, folder=tmp_path)[2]
    assert status.startswith("corrupt") and "declares" in status
    assert any("ignored" in n for n in _cached(tmp_path, value))


def test_cache_deflated_members_are_refused_before_inflating(tmp_path):
    """A deflated member declaring 2 GiB was inflated completely before the checksum refused it; the project
    never writes compressed entries, so the reader refuses any (the checkpoint reader's rule) in bounded memory."""
    import tracemalloc

    value, path = _entry(tmp_path)
    path.write_bytes(hf._bomb())
    tracemalloc.start()
    status = datacache.load_entry("t", "k" * 64, folder=tmp_path)[2]
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert status.startswith("corrupt") and ("compression" in status or "zip bomb" in status)
    assert peak < 20 * 2**20
    _, path = _entry(tmp_path, compress=True)  # a plain deflated copy of a valid entry: corrupt too
    assert "compression" in datacache.load_entry("t", "k" * 64, folder=tmp_path)[2]


@pytest.mark.parametrize("kind", ["fifo", "zero", "folder"])
def test_cache_entry_that_is_not_a_file_is_corrupt(tmp_path, kind):
    value, path = _entry(tmp_path)
    hf.make_special(path, kind, [])
    assert datacache.load_entry("t", "k" * 64, folder=tmp_path)[2].startswith("corrupt")
    assert any("ignored" in n for n in _cached(tmp_path, value))


def test_decode_failure_of_any_kind_is_corrupt(tmp_path):
    value, _ = _entry(tmp_path)
    notes = []

    def decode(a, m):
        raise AttributeError("'list' object has no attribute 'get'")
    got = datacache.cached("t", "k" * 64, lambda: value, lambda v: (dict(v), {}), decode, folder=tmp_path,
                           progress=notes.append)
    assert got is value and any("AttributeError" in n for n in notes)


_WRITER = """
import sys, time
from refimpl.atomic import atomic_path
with atomic_path(sys.argv[1]) as tmp:
    open(tmp, "wb").write(b"x" * 1000)
    print("writing", flush=True)
    time.sleep(60)
"""


def _killed_writer(target: Path) -> Path:
    p = subprocess.Popen([sys.executable, "-c", _WRITER, str(target)], stdout=subprocess.PIPE, text=True,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert p.stdout.readline().strip() == "writing"
    (tmp,) = target.parent.glob(f".{target.stem}.*.tmp{target.suffix}")
    from refimpl.atomic import remove_stale_temp_files
    assert remove_stale_temp_files(target) == [] and tmp.exists()  # a live writer's file is kept
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert tmp.exists()  # what kill -9 leaves
    return tmp


def test_temp_files_of_killed_writers_are_removed_by_the_next_run(tmp_path, seeds):
    """kill -9 during a cache write, an import or an export-weights left its temporary file for ever (up to
    ~0.4 GB for the locomotion set); the next reader or writer of the target removes it (and never a live
    writer's)."""
    value, path = _entry(tmp_path)
    tmp = _killed_writer(path)
    _cached(tmp_path, value)
    assert not tmp.exists()
    out = tmp_path / "w.npz"
    tmp = _killed_writer(out)
    code, err = fs._main(["export-weights", seeds["quaternet"], "--out", out])
    assert code == 0 and not tmp.exists(), err
    out = tmp_path / "i.npz"
    tmp = _killed_writer(out)
    code, err = fs._main(["import", tmp_path / "w.npz", "--model", "quaternet", "--set", "hidden_size=8",
                          "--set", "num_layers=1", "--set", "prefix_length=12", "--set", "target_length=4",
                          "--out", out])
    assert not tmp.exists(), err


# ---------------------------------------------------------------------------------------------------------------
# 3. python -m deploy: options, metadata, exit codes, .npy inputs
# ---------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("value", ["100000", "99999999999999999999", "0", "-1"])
def test_deploy_threads_are_bounded(seeds, tmp_path, value):
    """``--threads 100000`` hung, ``99999999999999999999`` was a traceback, 0 / -1 named ``intra_op_threads``."""
    code, err = hf.deploy_main(["run", seeds["onnx:acrnn"], fs.SALSA, tmp_path / "o.bvh", "--threads", value])
    assert code == 2 and "--threads" in _one_line(err)


@pytest.mark.parametrize("flag,value", [("--fps", "1e-300"), ("--fps", "nan"), ("--source-fps", "1e-300"),
                                        ("--start", "-1"), ("--frames", "1e20")])
def test_deploy_frame_rate_and_frames_are_bounded(seeds, tmp_path, flag, value):
    """``--fps 1e-300`` resampled the clip toward infinity (4.4 GB after 30 s)."""
    argv = ["run", seeds["onnx:qtg"], fs.WALK_BVH, tmp_path / "o.bvh", *(["--start", "5"] if flag != "--start"
                                                                         else []), flag, value]
    code, err = hf.deploy_main(argv)
    assert code == 2 and flag in _one_line(err)


def test_deploy_npy_inputs_are_checked_against_the_file_size(seeds, tmp_path):
    """A 128-byte header declaring 40.7 TiB: "Unable to allocate" traceback at 4f4f4ef; now exit 3."""
    import random

    p = tmp_path / "x.npy"
    for kind in ("huge", "negative", "object", "truncated", "trailing", "bad-magic", "zero-d", "rank-2"):
        p.write_bytes(hf.crafted_npy(kind, random.Random(0)))
        code, err = hf.deploy_main(["run", seeds["onnx:quaternet-long"], p, tmp_path / "y.npy"])
        assert code == 3 and "x.npy" in _one_line(err), (kind, err)
    p.write_bytes(hf.crafted_npy("ok", random.Random(0)))
    code, err = hf.deploy_main(["run", seeds["onnx:quaternet-long"], p, tmp_path / "y.npy"])
    assert code == 0, err


@pytest.mark.parametrize("key,edit,field", [("skeleton", {"names": 5}, "skeleton"),
                                            ("skeleton", "names=5", "names"),
                                            ("normalization", "mean=5", "mean"),
                                            ("input_transform", "steps=5", "steps"),
                                            ("skeleton", "del names", "names"),
                                            ("normalization", "del mean", "mean"),
                                            ("normalization", "del in_graph", "in_graph"),
                                            ("frame_rate", 1e-300, "frame_rate")])
def test_deploy_info_checks_the_metadata_types(seeds, tmp_path, key, edit, field):
    """Tracebacks (wrong types) or exit 2 with a bare ``KeyError`` text (missing keys) at 4f4f4ef; now one line
    naming the field, exit 3, from ``info`` and from ``run``."""
    d = tmp_path / "m"
    shutil.copytree(seeds["onnx:qtg"], d)
    for f in d.glob("*.onnx"):
        hf.edit_metadata(f, f, key, edit)
    code, err = hf.deploy_main(["info", d / "qtg_step.onnx"])
    assert code == 3 and field in _one_line(err), err
    code, err = hf.deploy_main(["run", d, fs.WALK_BVH, tmp_path / "o.bvh", "--start", "5"])
    assert code == 3 and field in _one_line(err), err


def test_deploy_bad_input_files_are_exit_3(seeds, tmp_path):
    """The QTG runner and ``load_model`` raised plain ``ValueError`` (exit 2) for input files."""
    code, err = hf.deploy_main(["run", seeds["onnx:qtg"], tmp_path / "nope.bvh", tmp_path / "o.bvh", "--start", "5"])
    assert code == 3 and "nope.bvh" in _one_line(err)
    bad = tmp_path / "nan.bvh"
    lines = fs.WALK_BVH.read_text().splitlines()
    lines[-3] = lines[-3].replace("0", "nan", 1)
    bad.write_text("\n".join(lines) + "\n")
    code, err = hf.deploy_main(["run", seeds["onnx:qtg"], bad, tmp_path / "o.bvh", "--start", "5"])
    assert code == 3 and "nan.bvh" in _one_line(err), err
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    code, err = hf.deploy_main(["info", junk])
    assert code == 3 and "junk.onnx" in _one_line(err), err


# ---------------------------------------------------------------------------------------------------------------
# 4. options of another task; --onnx folders of another layout; task fields in the schema
# ---------------------------------------------------------------------------------------------------------------

def test_eval_refuses_options_of_another_task(seeds):
    """``refimpl eval --checkpoint qn.npz --join inertialize`` exited 0 with the plain table."""
    code, err = fs._main(["eval", "--checkpoint", seeds["quaternet"], "--join", "inertialize"])
    assert code == 2 and "--join" in err


def test_onnx_folder_of_another_acrnn_representation_is_refused_when_opened(seeds, tmp_path):
    """Another representation's acRNN folder passed the model-name check and failed at the first step (exit 1,
    ``seed: expected shape ['B', 'S', 132], got (1, 10, 347)``)."""
    run = tmp_path / "quat"
    argv = [a if a != "euler" else "quaternions" for a in fs.TINY["acrnn"]]
    assert fs._main(["train", *argv, "--out", run, "--steps", "1"])[0] == 0
    assert fs._main(["export", "--checkpoint", run / "checkpoint.npz", "--out", tmp_path / "oq", "--no-verify"])[0] == 0
    code, err = fs._main(["generate", "--checkpoint", seeds["acrnn"], "--onnx", tmp_path / "oq", "--backend", "onnx",
                          "--source", fs.SALSA, "--length", "3", "--out", tmp_path / "g.bvh"])
    assert code == 3 and "frame_size" in err and "oq" in err, err


def test_qtg_step_graph_with_other_inputs_is_refused_when_opened(seeds, tmp_path):
    """A QTG folder whose ``qtg_step.onnx`` is another graph failed at run time (exit 1)."""
    from deploy.models import runtime_for_dir

    d = tmp_path / "q"
    shutil.copytree(seeds["onnx:qtg"], d)
    shutil.copy(d / "qtg_init.onnx", d / "qtg_step.onnx")
    hf.edit_metadata(d / "qtg_step.onnx", d / "qtg_step.onnx", "model", "role='step'")
    with pytest.raises(ValueError, match="step: expected a graph with inputs"):
        runtime_for_dir(d)
    code, err = hf.deploy_main(["run", d, fs.WALK_BVH, tmp_path / "o.bvh", "--start", "5"])
    assert code == 3 and "inputs" in _one_line(err)


def test_frame_size_of_the_graph_must_match_the_metadata(seeds, tmp_path):
    from deploy.models import runtime_for_dir

    d = tmp_path / "a"
    shutil.copytree(seeds["onnx:acrnn"], d)
    hf.edit_metadata(d / "acrnn_step.onnx", d / "acrnn_step.onnx", "representation", "size=347")
    with pytest.raises(ValueError, match="frames of 132"):
        runtime_for_dir(d)


def test_quaternet_checkpoint_without_frame_time_is_refused(seeds, tmp_path):
    """``KeyError: 'frame_time'`` (exit 1) at 4f4f4ef; now the schema requires it (exit 3)."""
    from refimpl.checkpoint import load_checkpoint
    from refimpl.services import load_trained

    arrays, meta = hf.fc._inference_content(load_checkpoint(seeds["quaternet"]))
    del meta["model_config"]["frame_time"]
    path = tmp_path / "qn.npz"
    hf.fc.write_crafted(path, arrays, meta)
    with pytest.raises(BadInputError, match="frame_time"):
        load_trained(path)


# ---------------------------------------------------------------------------------------------------------------
# 5. the smaller ones
# ---------------------------------------------------------------------------------------------------------------

def test_safetensors_dtype_of_another_json_type_is_exit_3(tmp_path):
    """``"dtype": ["F32"]`` was a TypeError (exit 1)."""
    header = json.dumps({"w": {"dtype": ["F32"], "shape": [1], "data_offsets": [0, 4]}}).encode()
    p = tmp_path / "w.safetensors"
    p.write_bytes(len(header).to_bytes(8, "little") + header + bytes(4))
    code, err = fs._main(["import", p, "--model", "quaternet", "--out", tmp_path / "o.npz"])
    assert code == 3 and "dtype" in err, err


def test_acrnn_run_on_a_short_take_says_too_short(seeds, tmp_path):
    """``--source-frame must lie in [0, -1]``: an option deploy does not have and an empty range."""
    lines = fs.SALSA.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("Frames:"))
    short = tmp_path / "short.bvh"
    short.write_text("\n".join(lines[:i] + ["Frames: 6", lines[i + 1]] + lines[i + 2:i + 8]) + "\n")
    code, err = hf.deploy_main(["run", seeds["onnx:acrnn"], short, tmp_path / "o.bvh"])
    assert code == 3 and "short.bvh: too short" in _one_line(err), err
    code, err = hf.deploy_main(["run", seeds["onnx:acrnn"], fs.SALSA, tmp_path / "o.bvh", "--start", "99999"])
    assert code == 2 and "--start must lie in [0, " in _one_line(err) and "--source-frame" not in err


# ---------------------------------------------------------------------------------------------------------------
# 6. the campaign's share
# ---------------------------------------------------------------------------------------------------------------

FAST = {"special-files": 30, "cache-damage": 60, "deploy-options": 6, "deploy-files": 6, "task-options": 10}


def test_campaign_share_has_no_failure():
    res = hf.campaign(counts=FAST, seed=3, log=None)
    failures = {f"{fam}:{k}": v for fam, s in res["families"].items() for k, v in s["failures"].items()}
    assert res["cases"] >= 100 and not failures, (failures, res["examples"][:5])
