"""Tests of the generic training loop (spec/qtg.md §10): exact resume, divergence, interrupts, logs."""
from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint
from refimpl.models.qtg import QTGConfig
from refimpl.recipes.qtg import PAPER_OPTIM, qtg_adapter, train_qtg
from refimpl.train import OptimConfig, TrainConfig, TrainingDiverged, format_duration, train

TINY = QTGConfig(pose_size=11, encoder_sizes=(6, 4), gru_hidden=5, decoder_sizes=(6,), transition_length=3)


def _data(n=10, seed=0):
    return np.random.default_rng(seed).standard_normal((n, 7, 11))


def _adapter(nan_at=None, nan_in="loss", noise=True):
    """Tiny QTG (float64) whose batches get Gaussian noise from ctx.rng (exercises the saved RNG state).

    ``nan_at``: a mutable [step] list; the loss (or a gradient) becomes NaN when ctx.step + 1 equals it."""
    base = qtg_adapter(_data(), config=TINY, dtype=np.float64)

    def get_batch(idx, ctx):
        b = base.get_batch(idx, ctx)
        if noise:
            b = b + 0.01 * ctx.rng.standard_normal(b.shape)
        return (b, ctx.step)

    def loss_and_grads(params, batch):
        b, step = batch
        loss, grads = base.loss_and_grads(params, b)
        if nan_at is not None and nan_at[0] == step + 1:
            if nan_in == "loss":
                loss = float("nan")
            else:
                grads = dict(grads)
                grads["vel.bias"] = grads["vel.bias"] * np.inf
        return loss, grads

    return dataclasses.replace(base, get_batch=get_batch, loss_and_grads=loss_and_grads)


OPT = OptimConfig(lr=1e-2, betas=PAPER_OPTIM.betas, clip_norm=1.0, lr_decay=0.9)


def _cfg(tmp_path, steps, **kw):
    return TrainConfig(steps=steps, batch_size=4, seed=3, checkpoint_path=str(tmp_path / "ckpt.npz"),
                       log_path=str(tmp_path / "log.csv"), progress_every=2, **kw)


def _assert_same(a, b):
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_resume_is_bit_for_bit(tmp_path):
    """spec/qtg.md §10: N steps straight == k steps, stop, resume from the checkpoint, N − k steps."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    straight = train(_adapter(), OPT, _cfg(tmp_path / "a", 13, checkpoint_every=4), progress=None)
    first = train(_adapter(), OPT, _cfg(tmp_path / "b", 6, checkpoint_every=4), progress=None)
    assert first.step == 6 and first.epoch == 3  # 10 examples, batch 4 -> 2 steps per epoch
    resumed = train(_adapter(), OPT, _cfg(tmp_path / "b", 13, checkpoint_every=4), progress=None)
    assert resumed.step == 13 and len(resumed.losses) == 7
    _assert_same(straight.params, resumed.params)
    _assert_same(straight.optim_state, resumed.optim_state)
    assert straight.losses[6:] == resumed.losses
    # the CSV log of the resumed run has each step once
    rows = list(csv.DictReader(open(tmp_path / "b" / "log.csv")))
    assert [int(r["step"]) for r in rows] == list(range(1, 14))
    assert float(rows[-1]["loss"]) == straight.losses[-1]
    # the learning rate decays per epoch
    assert float(rows[0]["lr"]) == pytest.approx(1e-2) and float(rows[2]["lr"]) == pytest.approx(9e-3)


def test_checkpoint_contents(tmp_path):
    """spec/qtg.md §10: params, Adam state, sampler, RNG and schedule state, configs in the checkpoint."""
    res = train(_adapter(), OPT, _cfg(tmp_path, 5, checkpoint_every=10), progress=None)
    arrays, meta = load_checkpoint(tmp_path / "ckpt.npz")
    assert meta["step"] == 5 and meta["epoch"] == 2 and meta["position"] == 1
    assert meta["model"] == "qtg" and meta["optim"]["betas"] == [0.5, 0.9]
    assert meta["lr"] == pytest.approx(1e-2 * 0.9 ** 2)
    assert "rng_state" in meta and meta["model_config"]["encoder_sizes"] == [6, 4]
    assert int(arrays["optim.step"]) == 5
    for k, v in res.params.items():
        assert np.array_equal(arrays[f"param.{k}"], v)
    assert sorted(arrays["sampler.perm"]) == list(range(10))


@pytest.mark.parametrize("where", ["loss", "grad"])
def test_nan_stops_and_keeps_last_good_checkpoint(tmp_path, where):
    """spec/qtg.md §10: a NaN/inf loss or gradient raises TrainingDiverged; the last checkpoint stays intact."""
    nan_at = [8]
    cfg = _cfg(tmp_path, 20, checkpoint_every=3)
    with pytest.raises(TrainingDiverged, match="step 8" if where == "loss" else "vel.bias"):
        train(_adapter(nan_at, nan_in=where), OPT, cfg, progress=None)
    arrays, meta = load_checkpoint(tmp_path / "ckpt.npz")
    assert meta["step"] == 6
    (tmp_path / "ref").mkdir()
    ref = train(_adapter(), OPT, _cfg(tmp_path / "ref", 6, checkpoint_every=100), progress=None)
    for k, v in ref.params.items():
        assert np.array_equal(arrays[f"param.{k}"], v)
    rows = list(csv.DictReader(open(tmp_path / "log.csv")))
    assert [int(r["step"]) for r in rows] == list(range(1, 8))
    # fixing the cause and resuming continues from step 6 exactly like an uninterrupted run
    nan_at[0] = None
    resumed = train(_adapter(nan_at), OPT, _cfg(tmp_path, 10, checkpoint_every=3), progress=None)
    (tmp_path / "ref10").mkdir()
    ref10 = train(_adapter(), OPT, _cfg(tmp_path / "ref10", 10, checkpoint_every=100), progress=None)
    _assert_same(resumed.params, ref10.params)
    rows = list(csv.DictReader(open(tmp_path / "log.csv")))
    assert [int(r["step"]) for r in rows] == list(range(1, 11))


def test_keyboard_interrupt_saves_and_resumes(tmp_path):
    """spec/qtg.md §10: KeyboardInterrupt (here from the callback) checkpoints the last completed step."""
    def stop_at_5(info):
        if info.step == 5:
            raise KeyboardInterrupt

    res = train(_adapter(), OPT, _cfg(tmp_path, 12, checkpoint_every=100), callback=stop_at_5, progress=None)
    assert res.interrupted and res.step == 5
    _, meta = load_checkpoint(tmp_path / "ckpt.npz")
    assert meta["step"] == 5
    resumed = train(_adapter(), OPT, _cfg(tmp_path, 12, checkpoint_every=100), progress=None)
    (tmp_path / "ref").mkdir()
    ref = train(_adapter(), OPT, _cfg(tmp_path / "ref", 12, checkpoint_every=100), progress=None)
    assert not resumed.interrupted
    _assert_same(resumed.params, ref.params)


def test_interrupt_inside_a_step_keeps_the_previous_state(tmp_path):
    """spec/qtg.md §10: an interrupt raised while computing a step drops that step (RNG restored)."""
    base = _adapter()
    calls = []

    def get_batch(idx, ctx):
        calls.append(ctx.step)
        b = base.get_batch(idx, ctx)  # draws from ctx.rng first
        if ctx.step == 4 and len(calls) == 5:
            raise KeyboardInterrupt
        return b

    res = train(dataclasses.replace(base, get_batch=get_batch), OPT, _cfg(tmp_path, 9, checkpoint_every=100),
                progress=None)
    assert res.interrupted and res.step == 4
    resumed = train(base, OPT, _cfg(tmp_path, 9, checkpoint_every=100), progress=None)
    (tmp_path / "ref").mkdir()
    ref = train(_adapter(), OPT, _cfg(tmp_path / "ref", 9, checkpoint_every=100), progress=None)
    _assert_same(resumed.params, ref.params)


def test_progress_validation_and_mismatch(tmp_path):
    """spec/qtg.md §10: progress lines with rate and ETA, validation log, refusing a foreign checkpoint."""
    lines = []
    base = qtg_adapter(_data(), config=TINY, dtype=np.float64, validation_poses=_data(3, seed=1))
    res = train(base, OPT, _cfg(tmp_path, 4, checkpoint_every=100, validate_every=2), progress=lines.append)
    assert len(lines) == 2 and "it/s" in lines[0] and "ETA" in lines[0] and "val_mae" in lines[0]
    assert [v["step"] for v in res.validation] == [2, 4]
    rows = list(csv.DictReader(open(tmp_path / "log_val.csv")))
    assert [int(r["step"]) for r in rows] == [2, 4] and float(rows[0]["val_mae"]) > 0
    with pytest.raises(ValueError, match="optim"):
        train(base, dataclasses.replace(OPT, lr=1e-3), _cfg(tmp_path, 6), progress=None)
    other = dataclasses.replace(base, name="other")
    with pytest.raises(ValueError, match="model"):
        train(other, OPT, _cfg(tmp_path, 6), progress=None)
    fresh = train(base, OPT, _cfg(tmp_path, 2), resume=False, progress=None)
    assert fresh.step == 2


def test_bad_config():
    """Public boundary checks."""
    with pytest.raises(ValueError, match="batch_size"):
        TrainConfig(steps=3, batch_size=0)
    with pytest.raises(ValueError, match="adapter"):
        train(object(), OPT, TrainConfig(steps=1))
    with pytest.raises(ValueError, match="train_poses"):
        qtg_adapter(np.zeros((4, 7, 12)), config=TINY)
    assert format_duration(3723.4) == "1h02m03s" and format_duration(42) == "42s"


def test_train_qtg_reduces_the_loss(tmp_path):
    """spec/qtg.md §10.2: the QTG convenience runs on a TransitionDataset and learns (tiny sizes)."""
    from refimpl.protocols.transition import TransitionDataset

    rng = np.random.default_rng(0)
    poses = np.cumsum(0.1 * rng.standard_normal((16, 7, 11)), axis=1)
    ds = TransitionDataset(poses=poses, skeleton_index=np.zeros(16, int), skeletons=(), source_index=np.zeros(16, int),
                           sources=(), root_mean=np.zeros(3), root_std=np.ones(3))
    res = train_qtg(ds, 40, config=TINY, optim=OptimConfig(lr=3e-3, betas=PAPER_OPTIM.betas), batch_size=8,
                    dtype=np.float32,
                    checkpoint_path=str(tmp_path / "q.npz"), progress=None)
    assert res.params["enc.0.weight"].dtype == np.float32
    assert np.mean(res.losses[-5:]) < 0.8 * np.mean(res.losses[:5])
    arrays, meta = load_checkpoint(tmp_path / "q.npz")
    assert meta["model_config"]["dtype"] == "float32" and meta["step"] == 40


def test_resume_keeps_the_log_files_mode(tmp_path):
    """spec/qtg.md §10: a resumed run rewrites loss.csv atomically (refimpl.atomic) with the usual permissions
    (0o666 & ~umask), not a temporary file's 0o600."""
    import os

    umask = os.umask(0o022)
    try:
        kw = dict(batch_size=2, seed=0, checkpoint_path=str(tmp_path / "c.npz"), log_path=str(tmp_path / "loss.csv"))
        train(_adapter(), OPT, TrainConfig(steps=2, **kw), progress=None)
        train(_adapter(), OPT, TrainConfig(steps=4, **kw), resume=True, progress=None)
        assert os.stat(tmp_path / "loss.csv").st_mode & 0o777 == 0o644
        rows = (tmp_path / "loss.csv").read_text().splitlines()
        assert rows[0].startswith("step,") and [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3", "4"]
    finally:
        os.umask(umask)
