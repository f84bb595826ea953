"""spec/robustness.md §10: training faults — divergence with absurd learning rates, SIGTERM, two writers of one
output, stale temporary files of a killed checkpoint write.

The command-line cases run ``python -m refimpl train`` in a subprocess on a tiny QTG (a few KB of parameters) and
send real signals; the library cases run :func:`refimpl.train.train` on a tiny adapter in-process.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint
from refimpl.train import ModelAdapter, OptimConfig, TrainConfig, TrainingDiverged, train
from refimpl.train_files import OutputLocked, output_lock, remove_stale_temp_files

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]
TRAIN = [sys.executable, "-m", "refimpl", "train", "--data", str(WALK_BVH), "--batch-size", "8", "--stride", "8",
         "--test-fraction", "0.5", *TINY]
posix_only = pytest.mark.skipif(os.name != "posix", reason="signals and flock: POSIX")


def _env():
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _finite_checkpoint(path: Path) -> dict:
    """The checkpoint's metadata, after asserting that its loader would accept its values: finite, and every
    parameter within the checkpoint schema's ``MAX_PARAM_ABS``."""
    from refimpl.checkpoint_schema import MAX_PARAM_ABS

    arrays, meta = load_checkpoint(path)
    for k, a in arrays.items():
        if a.dtype.kind == "f":
            assert np.isfinite(a).all(), k
            if k.startswith("param.") and a.size:
                assert np.abs(a).max() <= MAX_PARAM_ABS, k
    return meta


def _start(out: Path, *extra) -> subprocess.Popen:
    return subprocess.Popen([*TRAIN, "--out", str(out), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env())


def _wait_training(proc: subprocess.Popen, timeout: float = 60.0) -> list[str]:
    """Read stderr until the first progress line (the loop is running, the signal handlers are installed)."""
    lines, t0 = [], time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if line.startswith("[qtg] step"):
            return lines
    raise AssertionError(f"the trainer did not start: {''.join(lines)}")


# ---------------------------------------------------------------------------------------------------------
# signals


@posix_only
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_saves_and_exits(tmp_path, sig, code):
    """SIGTERM is handled like SIGINT: the run stops at the next step boundary, saves the last completed step and
    exits 128 + signal (143 / 130); the checkpoint resumes."""
    out = tmp_path / "run"
    proc = _start(out, "--steps", "1000000", "--progress-every", "1", "--checkpoint-every", "1000000")
    _wait_training(proc)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr
    assert "interrupted" in stdout
    meta = _finite_checkpoint(out / "checkpoint.npz")
    assert meta["step"] >= 1
    r = subprocess.run([*TRAIN, "--out", str(out), "--steps", str(meta["step"] + 1), "--resume"],
                       capture_output=True, text=True, env=_env(), timeout=120)
    assert r.returncode == 0, r.stderr
    assert load_checkpoint(out / "checkpoint.npz")[1]["step"] == meta["step"] + 1


# ---------------------------------------------------------------------------------------------------------
# two writers, stale lock, stale temporary files


@posix_only
def test_second_trainer_on_same_out_is_refused(tmp_path):
    """Two trainers on one --out: the second stops with one clear line (exit 1) and touches nothing; the first
    finishes normally."""
    out = tmp_path / "run"
    first = _start(out, "--steps", "1000000", "--progress-every", "1", "--checkpoint-every", "5")
    try:
        _wait_training(first)
        while not (out / "checkpoint.npz").is_file():
            time.sleep(0.05)
        before = (out / "checkpoint.npz").stat().st_mtime_ns
        for flags in (["--overwrite"], ["--resume"], []):
            r = subprocess.run([*TRAIN, "--out", str(out), "--steps", "3", *flags], capture_output=True, text=True,
                               env=_env(), timeout=120)
            lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
            assert r.returncode == 1, r.stderr
            assert len(lines) == 1 and "another trainer (PID" in lines[0] and str(first.pid) in lines[0], lines
        assert (out / "checkpoint.npz").is_file() and (out / "loss.csv").is_file()
        assert (out / "checkpoint.npz").stat().st_mtime_ns >= before
    finally:
        first.send_signal(signal.SIGTERM)
        first.communicate(timeout=60)
    assert first.returncode == 143
    _finite_checkpoint(out / "checkpoint.npz")


@posix_only
def test_lock_of_a_killed_trainer_is_taken_over(tmp_path):
    """kill -9 leaves the lock file behind (with the dead PID); the next run takes it over and resumes."""
    out = tmp_path / "run"
    proc = _start(out, "--steps", "1000000", "--progress-every", "1", "--checkpoint-every", "2")
    _wait_training(proc)
    while not (out / "checkpoint.npz").is_file():
        time.sleep(0.05)
    proc.kill()
    proc.communicate(timeout=60)
    lock = out / ".refimpl-train.lock"
    assert lock.is_file() and lock.read_text().strip() == str(proc.pid)
    step = load_checkpoint(out / "checkpoint.npz")[1]["step"]
    r = subprocess.run([*TRAIN, "--out", str(out), "--steps", str(step + 2), "--resume"], capture_output=True,
                       text=True, env=_env(), timeout=120)
    assert r.returncode == 0, r.stderr
    assert load_checkpoint(out / "checkpoint.npz")[1]["step"] == step + 2


def test_output_lock_in_process(tmp_path):
    """The lock is exclusive while held, free after the block, and a file naming a dead PID is no obstacle."""
    (tmp_path / ".refimpl-train.lock").write_text("999999999\n")  # a PID that does not exist
    with output_lock(tmp_path):
        with pytest.raises(OutputLocked, match=f"PID {os.getpid()}"):
            with output_lock(tmp_path):
                pass
    with output_lock(tmp_path):
        pass


def _tiny_adapter(grad_scale=1.0, n=8):
    rng = np.random.default_rng(0)
    x = rng.standard_normal((n, 3))
    y = x @ np.array([1.0, -2.0, 0.5])

    def loss_and_grads(params, idx):
        r = x[idx] @ params["w"] - y[idx]
        return float(np.mean(r * r)), {"w": grad_scale * 2 * x[idx].T @ r / len(idx)}

    return ModelAdapter(name="tiny", num_examples=n, init_params=lambda g: {"w": g.standard_normal(3)},
                        get_batch=lambda idx, ctx: idx, loss_and_grads=loss_and_grads)


def test_stale_temp_files_are_removed_on_start(tmp_path):
    """Temporary files of the atomic writer for the trainer's own files are removed when a run starts; other
    files, including look-alikes, stay."""
    stale = [".ckpt.0123456789ab.tmp.npz", ".log.deadbeef0000.tmp.csv", ".log_val.00000000ffff.tmp.csv"]
    kept = [".ckpt.0123456789ab.tmp.csv", ".ckpt.xyz.tmp.npz", ".other.0123456789ab.tmp.npz", "ckpt.npz.bak",
            ".ckpt.0123456789AB.tmp.npz", ".ckpt.0123456789ab.tmp.npz.1"]
    for name in stale + kept:
        (tmp_path / name).write_bytes(b"partial")
    cfg = TrainConfig(steps=2, batch_size=4, checkpoint_path=str(tmp_path / "ckpt.npz"),
                      log_path=str(tmp_path / "log.csv"))
    train(_tiny_adapter(), OptimConfig(), cfg, progress=None)
    names = {p.name for p in tmp_path.iterdir()}
    assert not names & set(stale)
    assert set(kept) <= names
    assert remove_stale_temp_files(tmp_path / "ckpt.npz") == []


# ---------------------------------------------------------------------------------------------------------
# divergence


@pytest.mark.parametrize("lr, grad_scale", [(1e308, 1.0), (1e300, 1.0), (1e-3, 1e200), (1e308, 1e-300)])
def test_absurd_updates_never_reach_a_checkpoint(tmp_path, lr, grad_scale):
    """Huge learning rates or gradients: parameters or Adam moments that become non-finite stop the run with
    TrainingDiverged; every checkpoint ever written holds finite parameters and optimiser state."""
    ckpt = tmp_path / "ckpt.npz"
    cfg = TrainConfig(steps=50, batch_size=4, checkpoint_path=str(ckpt), checkpoint_every=1)
    seen = []

    def callback(info):
        if ckpt.is_file():
            seen.append(_finite_checkpoint(ckpt)["step"])

    try:
        train(_tiny_adapter(grad_scale), OptimConfig(lr=lr), cfg, progress=None, callback=callback)
    except TrainingDiverged as exc:
        assert "\n" not in str(exc) and ("non-finite" in str(exc) or "loss is" in str(exc) or "gradient" in str(exc)
                                         or "diverged at step" in str(exc))
    if ckpt.is_file():
        _finite_checkpoint(ckpt)


def test_overflowing_updates_are_caught_before_saving(tmp_path):
    """Gradients of 1e200 would overflow Adam's second moment at step 1; a learning rate of 1e308 on gradients near
    the float limit overflows the parameters: diverged, and no checkpoint is written."""
    ckpt = tmp_path / "ckpt.npz"
    cfg = TrainConfig(steps=5, batch_size=4, checkpoint_path=str(ckpt), checkpoint_every=1)
    with pytest.raises(TrainingDiverged, match="squares of the gradient of 'w' overflow at step 1"):
        train(_tiny_adapter(1e200), OptimConfig(lr=1e-3), cfg, progress=None)
    assert not ckpt.exists()
    init = {"w": np.full(3, 1.7e308)}  # parameters near the limit: one step of lr 1e308 leaves the float range
    adapter = ModelAdapter(name="const", num_examples=4, init_params=lambda g: dict(init),
                           get_batch=lambda idx, ctx: idx, loss_and_grads=lambda p, b: (1.0, {"w": -np.ones(3)}))
    with pytest.raises(TrainingDiverged, match="parameter 'w' became non-finite in the update of step 1"):
        train(adapter, OptimConfig(lr=1e308), cfg, progress=None)
    assert not ckpt.exists()


def test_cli_divergence_is_one_line_without_warnings(tmp_path):
    """``refimpl train --lr 1e308``: exit 1, one error line, no RuntimeWarning or source lines on stderr, and the
    checkpoint on disk (written every step) is finite."""
    out = tmp_path / "run"
    r = subprocess.run([*TRAIN, "--out", str(out), "--steps", "40", "--lr", "1e308", "--checkpoint-every", "1",
                        "--progress-every", "1000"], capture_output=True, text=True, env=_env(), timeout=120)
    assert r.returncode == 1, r.stderr
    assert "Warning" not in r.stderr and "Traceback" not in r.stderr
    errors = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("[qtg] step")]
    assert len(errors) == 1 and errors[0].startswith("refimpl train: error: qtg: "), r.stderr
    if (out / "checkpoint.npz").is_file():
        _finite_checkpoint(out / "checkpoint.npz")


def test_a_diverging_run_stops_at_the_last_step_the_loader_accepts(tmp_path):
    """#28: a learning rate that throws the parameters beyond the checkpoint limit (finite, 1e30) stops the run at
    that step with one line naming the step, the parameter and the limit; the checkpoint on disk is the previous
    step's, which the loader accepts (before: a step-1 checkpoint of 1e30 weights that info/eval/resume refused)."""
    ckpt = tmp_path / "ckpt.npz"
    init = {"w": np.full(3, 0.5)}
    adapter = ModelAdapter(name="const", num_examples=4, init_params=lambda g: dict(init),
                           get_batch=lambda idx, ctx: idx, loss_and_grads=lambda p, b: (1.0, {"w": -np.ones(3)}))
    cfg = TrainConfig(steps=8, batch_size=4, checkpoint_path=str(ckpt), checkpoint_every=1)
    with pytest.raises(TrainingDiverged) as info:  # Adam moves w by ~lr = 3e5 per step: beyond 1e6 at step 4
        train(adapter, OptimConfig(lr=3e5), cfg, progress=None)
    msg = str(info.value)
    assert "\n" not in msg and "diverged at step 4" in msg and "'w'" in msg and "1e+06" in msg, msg
    meta = _finite_checkpoint(ckpt)
    assert meta["step"] == 3 and "(step 3) kept" in msg
