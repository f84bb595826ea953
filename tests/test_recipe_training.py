"""Short training runs through a recipe's adapter and the generic trainer (refimpl/train.py): what the task
modules' own training loops (``train_acrnn``, ``train_pace_network``, removed in issue #23) used to show — the loss
falls — now shown on the path ``refimpl train`` takes (spec/acrnn.md §8, spec/locomotion.md §5)."""
from __future__ import annotations

from argparse import Namespace
from types import SimpleNamespace

import numpy as np

from refimpl.models import pace
from refimpl.recipes import acrnn as acrnn_recipe
from refimpl.recipes import pace as pace_recipe
from refimpl.protocols import locomotion as L
from refimpl.protocols import locomotion_data as LD
from refimpl.tasks import synthesis as synthesis_task
from refimpl.train import OptimConfig, TrainConfig, train


def test_acrnn_recipe_training_lowers_the_dq_loss():
    """acRNN, the dual-quaternion row with all losses on the embedded salsa sample (the task's own training set,
    windows of 20 + 1 frames, 16 hidden units), 80 Adam steps through the recipe's adapter: the mean loss of the
    last 10 steps is under 0.75 × that of the first 10."""
    train_ds, _ = synthesis_task.train_datasets(Namespace(representation="dq-all", data="sample", window_length=20))
    config = acrnn_recipe.make_config(train_ds, ["hidden_size=16"])
    adapter = acrnn_recipe.make_adapter(train_ds, None, config, np.float64, {})
    result = train(adapter, OptimConfig(lr=3e-3), TrainConfig(steps=80, batch_size=8, seed=0), progress=None)
    losses = np.asarray(result.losses, dtype=np.float64)
    assert losses.shape == (80,) and np.all(np.isfinite(losses))
    assert np.mean(losses[-10:]) < 0.75 * np.mean(losses[:10])


def _straight_walk_pace_data():
    """Pace training data (spline inputs, pace targets) of three synthetic straight walks."""
    from test_locomotion import _straight_walk
    out = []
    for spd, d in ((0.5, 0.0), (1.0, 0.5), (0.8, -0.3)):
        seq = LD.build_sequences(_straight_walk(speed=spd, direction=d, frames=80), LD.CMU_RIG, mirror=False)[0]
        out.append(L.pace_training_data(L.sequence_spline(seq)))
    return out


def test_pace_recipe_training_lowers_the_l1_loss_and_validates():
    """The pace network (8 hidden units) on chunks of 40 spline points, 40 Adam steps at lr 1e-2 through the
    recipe's adapter: the L1 loss halves, and the held-out L1 (the recipe's ``validate``) is finite."""
    data = _straight_walk_pace_data()
    train_ds = SimpleNamespace(pace_data=lambda: data, pace_chunk_length=40)
    val_ds = SimpleNamespace(pace_data=lambda: data[:1])
    adapter = pace_recipe.make_adapter(train_ds, val_ds, pace.PaceConfig(hidden_size=8), np.float64, {})
    result = train(adapter, OptimConfig(lr=1e-2), TrainConfig(steps=40, batch_size=4, seed=1234, validate_every=40),
                   progress=None)
    losses = np.asarray(result.losses, dtype=np.float64)
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:5])
    assert result.validation and np.isfinite(result.validation[-1]["val_l1"])
