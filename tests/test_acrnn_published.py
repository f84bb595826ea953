"""acRNN as the published code trains it (spec/acrnn.md §1.1): both 60 fps parities, raw frames, a random heading
per window, the skewed stack as the recipe's default; all selectable from ``refimpl train``."""
import numpy as np
import pytest

from refimpl.cli import build_parser, main
from refimpl.registry import MODELS
from refimpl.services import load_trained
from refimpl.tasks import synthesis
from refimpl.protocols.synthesis import SAMPLE_TEST, SAMPLE_TRAIN, load_salsa_motion, load_synthesis_data
from refimpl.tasks.synthesis import SAMPLE_SALSA
from refimpl.train import TrainContext


def test_both_parities_and_raw_frames():
    one = load_synthesis_data("positions", SAMPLE_SALSA, SAMPLE_TRAIN, SAMPLE_TEST)
    two = load_synthesis_data("positions", SAMPLE_SALSA, SAMPLE_TRAIN, SAMPLE_TEST, parities=2, standardise=False)
    assert len(two.train) == 2 * len(one.train) and two.train_names == ("01", "01/odd") and two.parities == 2
    np.testing.assert_array_equal(two.train[0], one.train[0])
    odd = synthesis.motion_to_frames("positions", load_salsa_motion(SAMPLE_SALSA / "01.bvh", phase=1))
    np.testing.assert_array_equal(two.train[1], odd)
    even60 = load_salsa_motion(SAMPLE_SALSA / "01.bvh", stride=1)
    np.testing.assert_array_equal(load_salsa_motion(SAMPLE_SALSA / "01.bvh", phase=1).root_positions,
                                  even60.root_positions[1::2])
    assert not two.standardised and np.all(two.mean == 0) and np.all(two.std == 1)
    assert [len(t) for t in two.test] == [len(t) for t in one.test]          # the protocol is unchanged
    with pytest.raises(ValueError, match="parities"):
        load_synthesis_data("positions", SAMPLE_SALSA, SAMPLE_TRAIN, SAMPLE_TEST, parities=3)


def test_recipe_default_is_the_skewed_stack():
    args = build_parser().parse_args(["train", "--model", "acrnn"])
    train_ds, _ = synthesis.train_datasets(args)
    assert MODELS["acrnn"].make_config(train_ds, ()).skewed is True
    assert MODELS["acrnn"].make_config(train_ds, ("skewed=false",)).skewed is False


def test_heading_augmented_batches_are_turned_windows_of_the_takes():
    args = build_parser().parse_args(["train", "--model", "acrnn", "--representation", "positions", "--raw-frames",
                                      "--augment-heading", "--parities", "2", "--window-length", "20",
                                      "--set", "hidden_size=4"])
    train_ds, test_ds = synthesis.train_datasets(args)
    spec = MODELS["acrnn"]
    config = spec.make_config(train_ds, args.set)
    adapter = spec.make_adapter(train_ds, test_ds, config, np.float64, synthesis.checkpoint_extra(train_ds))
    batch = adapter.get_batch(np.arange(6), TrainContext(rng=np.random.default_rng(0), epoch=0, step=0))
    assert batch.shape == (6, 21, train_ds.data.frame_size)
    turned = 0
    for w in batch:  # hip height and hip speed are those of some window of some take; the heading differs
        hits = []
        for take in train_ds.data.train:
            for s in range(len(take) - 20):
                ref = take[s:s + 21]
                if np.allclose(w[:, 1], ref[:, 1], atol=1e-12) and np.allclose(
                        np.hypot(w[:, 0], w[:, 2]), np.hypot(ref[:, 0], ref[:, 2]), atol=1e-12):
                    hits.append(ref)
        assert hits
        turned += not np.allclose(w, hits[0], atol=1e-9)
    assert turned >= 5
    assert adapter.config["augment_heading"] is True and adapter.config["parities"] == 2
    assert adapter.config["standardised"] is False


def test_train_with_the_published_options_then_eval(tmp_path):
    out = tmp_path / "run"
    assert main(["--blas-threads", "1", "train", "--model", "acrnn", "--representation", "positions",
                 "--augment-heading", "--parities", "2", "--raw-frames", "--window-length", "20",
                 "--batch-size", "2", "--steps", "2", "--set", "hidden_size=4", "--out", str(out)]) == 0
    model = load_trained(out / "checkpoint.npz")
    assert model.config.skewed is True and model.extra["augment_heading"] is True
    assert model.extra["parities"] == 2 and model.extra["standardised"] is False
    assert np.all(np.asarray(model.extra["std"]) == 1)
    assert main(["--blas-threads", "1", "eval", "--checkpoint", str(out / "checkpoint.npz")]) == 0


def test_the_published_171_value_frame():
    """``positions_acrnn`` on the salsa skeleton with its End Sites: hip (x/z as forward differences), then every
    other BVH node (depth-first, End Sites included) minus the hip, × 0.01 — computed here from the BVH reader's
    own forward kinematics at 60 fps, decimated."""
    from refimpl.bvh import read_bvh
    from refimpl.representations import frame_size, positions_from_frames

    d = load_synthesis_data("positions_acrnn", SAMPLE_SALSA, SAMPLE_TRAIN, SAMPLE_TEST, standardise=False)
    assert d.frame_size == 171 == frame_size("positions_acrnn", 57) and d.skeleton.num_joints == 57
    world = read_bvh(SAMPLE_SALSA / "01.bvh").positions()[::2] * 0.01                  # (T, 57, 3)
    frames = d.train[0]                                                                  # (T - 1, 171)
    np.testing.assert_allclose(frames[:, 3:].reshape(-1, 56, 3), (world[:, 1:] - world[:, :1])[:-1], atol=1e-12)
    np.testing.assert_allclose(frames[:, 1], world[:-1, 0, 1], atol=1e-12)
    np.testing.assert_allclose(frames[:, [0, 2]], np.diff(world[:, 0, [0, 2]], axis=0), atol=1e-12)
    rel = positions_from_frames("positions_acrnn", d.skeleton, frames) - frames[:, None, :3]
    np.testing.assert_allclose(rel, (world[:, :] - world[:, :1])[:-1], atol=1e-12)      # hip block: zero


def test_published_positions_acrnn_imports_and_generates(tmp_path):
    """A published acRNN state dict of the 171-value frame (raw metres, no standardisation) imports with
    ``--representation positions-published --raw-frames`` and generates as the published network."""
    from tests.test_import import _published_acrnn

    from refimpl.models.acrnn import ACRNNConfig, published_names
    from refimpl.safetensors import write_safetensors

    rng = np.random.default_rng(0)
    sd = {n: rng.uniform(-0.3, 0.3, s).astype(np.float32)
          for n, s in published_names(ACRNNConfig(frame_size=171, hidden_size=8)).values()}
    write_safetensors(tmp_path / "w.safetensors", sd)
    assert main(["--blas-threads", "1", "import", str(tmp_path / "w.safetensors"), "--model", "acrnn",
                 "--representation", "positions-published", "--raw-frames", "--set", "hidden_size=8",
                 "--out", str(tmp_path / "ckpt.npz")]) == 0
    model = load_trained(tmp_path / "ckpt.npz")
    assert model.extra["standardised"] is False and model.config.frame_size == 171
    seed = rng.standard_normal((2, 10, 171)) * 0.1
    np.testing.assert_allclose(model.spec.make_method(model)(seed, 8), _published_acrnn(sd, seed, 8),
                               rtol=1e-4, atol=1e-5)
    assert main(["--blas-threads", "1", "eval", "--checkpoint", str(tmp_path / "ckpt.npz")]) == 0
    pytest.importorskip("onnxruntime")
    assert main(["export", "--checkpoint", str(tmp_path / "ckpt.npz"), "--out", str(tmp_path / "onnx")]) == 0
