"""QuaterNet short-term in the application layer (spec/quaternet.md §7-§8, spec/cli.md, spec/deploy.md §10):
the prediction task's interface, the ``quaternet`` / ``quaternet-cnn`` recipes, ``refimpl train / eval / export /
generate`` on the embedded CMU sample, resume, checkpoint round trip and ONNX parity. Tiny sizes, a few steps."""
from __future__ import annotations

import json

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint
from refimpl.cli import EXIT_OK, EXIT_USAGE, main
from refimpl.protocols import prediction as PP
from refimpl.protocols import prediction_data as PD
from refimpl.recipes import quaternet as rnn_recipe
from refimpl.recipes import quaternet_cnn as cnn_recipe
from refimpl.registry import MODELS
from refimpl.services import load_trained
from refimpl.tasks import prediction as pr
from refimpl.testing import TOL_ORT_ROLLOUT, TOL_ORT_STEP
from refimpl.train import TrainContext

TINY_RNN = ["--set", "hidden_size=8", "--set", "num_layers=1", "--set", "prefix_length=12",
            "--set", "target_length=4"]
TINY_CNN = ["--set", "channels=8", "--set", "kernel_sizes=2,2,2", "--set", "dilations=1,2,4",
            "--set", "skips=0:1", "--set", "prefix_length=8", "--set", "target_length=4"]
WALK_TXT = pr.SAMPLE_EXPMAP_DIR / "test" / "walking" / "walking_1.txt"


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _train(out, model, tiny, steps, *extra):
    return main(["train", "--model", model, "--out", str(out), "--steps", str(steps), "--batch-size", "6",
                 "--progress-every", "1", "--checkpoint-every", "2", *tiny, *extra])


@pytest.fixture(scope="module")
def rnn_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("qn_rnn")
    assert _train(out, "quaternet", TINY_RNN, 4) == EXIT_OK
    return out


@pytest.fixture(scope="module")
def cnn_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("qn_cnn")
    assert _train(out, "quaternet-cnn", TINY_CNN, 3) == EXIT_OK
    return out


# ------------------------------------------------------------------------------------------- task + recipes
def test_registry_lines():
    assert MODELS["quaternet"].task == "prediction" and MODELS["quaternet-cnn"].task == "prediction"
    assert MODELS["quaternet"].exporter == "quaternet" and MODELS["quaternet-cnn"].exporter == "quaternet-cnn"


def test_paper_settings_are_the_defaults():
    o = rnn_recipe.PAPER_OPTIM
    assert (o.lr, o.betas, o.clip_norm, o.lr_decay) == (1e-3, (0.9, 0.999), 0.1, 0.999)
    c = rnn_recipe.ShortTermConfig()
    assert (c.prefix_length, c.target_length, c.tf_decay, c.penalty_weight, c.loss_kind) == (50, 10, 0.995, 0.01,
                                                                                             "euler")
    assert rnn_recipe.PAPER_BATCH == 60 and c.network.hidden_size == 1000 and c.network.velocity
    assert rnn_recipe.ShortTermConfig(schedule="teacher_forcing").loss_kind == "quat"
    # one rule for both recipes (refimpl.recipes.quaternet.resolve_loss): "auto" follows the schedule
    assert [rnn_recipe.resolve_loss(lo, sc) for lo, sc in (("auto", "teacher_forcing"), ("auto", "scheduled"),
                                                              ("euler", "teacher_forcing"), ("quat", "scheduled"))] \
        == ["quat", "euler", "euler", "quat"]
    assert cnn_recipe.CNNShortTermConfig(schedule="teacher_forcing").loss_kind == "quat"
    assert cnn_recipe.CNNShortTermConfig().loss_kind == "euler"
    assert cnn_recipe.CNNShortTermConfig().prefix_length == 32
    assert cnn_recipe.CNNShortTermConfig().network.receptive_field == 32


def test_task_data_and_windows():
    data = pr.resolve_data("sample")
    assert data.dataset == "cmu" and pr.num_examples(data) == len(data.train) == 20
    assert "20 training sequences" in pr.describe_data(data)
    a = PD.training_windows(data, [0, 3, 3], np.random.default_rng(1), 60)
    b = PD.training_windows(data, [0, 3, 3], np.random.default_rng(1), 60)
    assert a.shape == (3, 60, 38, 4) and np.array_equal(a, b)
    seq = data.train[3].rotations
    starts = [next(s for s in range(seq.shape[0] - 59) if np.array_equal(seq[s:s + 60], w)) for w in a[1:]]
    assert all(0 <= s <= seq.shape[0] - 60 for s in starts)
    with pytest.raises(ValueError, match="no training sequence"):
        PD.usable_training(data, 10 ** 6)


def test_canonical_prefix_keeps_rotations():
    data = pr.resolve_data("sample")
    x = data.test[0].rotations[None, :20]
    c = PP.canonical_prefix(x)
    assert np.allclose(np.abs(np.sum(c * x, axis=-1)), 1.0, atol=1e-9)
    assert np.all(np.sum(c[:, 1:] * c[:, :-1], axis=-1) >= 0)


def test_teacher_forcing_mask_modes():
    rng = np.random.default_rng(0)
    cfg = rnn_recipe.ShortTermConfig(target_length=6)
    assert rnn_recipe.teacher_forcing_mask(cfg, 0, rng).all()  # ratio 1 at epoch 0
    assert not rnn_recipe.teacher_forcing_mask(cfg, 10 ** 5, rng).any()  # ratio 0.995^1e5 ≈ 0
    m = rnn_recipe.teacher_forcing_mask(cfg, 138, np.random.default_rng(3))
    assert m.shape == (5,) and m.dtype == bool
    assert rnn_recipe.teacher_forcing_mask(rnn_recipe.ShortTermConfig(schedule="free"), 0, rng).sum() == 0


@pytest.mark.parametrize("kind", ["euler", "quat"])
def test_loss_terms_gradient(kind):
    rng = np.random.default_rng(2)
    cfg = rnn_recipe.ShortTermConfig(num_joints=2, loss=kind)
    y = rng.standard_normal((2, 3, 8))
    y /= np.linalg.norm(y.reshape(2, 3, 2, 4), axis=-1).repeat(4, axis=-1)
    pre = rng.standard_normal((2, 3, 8))
    target = rng.standard_normal((2, 3, 2, 4))
    target /= np.linalg.norm(target, axis=-1, keepdims=True)
    _, total, dy, dpre = rnn_recipe.loss_terms(y, pre, target, cfg)
    for arr, grad, which in ((y, dy, 0), (pre, dpre, 1)):
        num = np.zeros_like(arr)
        for i in np.ndindex(arr.shape):
            for s in (1, -1):
                a = arr.copy()
                a[i] += s * 1e-6
                args = (a, pre) if which == 0 else (y, a)
                num[i] += s * rnn_recipe.loss_terms(*args, target, cfg)[1] / 2e-6
        assert np.allclose(num, grad, atol=1e-6)


def test_adapter_batches_come_from_the_trainer_rng():
    data = pr.resolve_data("sample")
    cfg = rnn_recipe.make_config(data, ["hidden_size=4", "num_layers=1", "prefix_length=6", "target_length=3"])
    ad = rnn_recipe.make_adapter(data, None, cfg, np.float64, {})
    b1 = ad.get_batch(np.arange(4), TrainContext(rng=np.random.default_rng(5), step=0, epoch=200))
    b2 = ad.get_batch(np.arange(4), TrainContext(rng=np.random.default_rng(5), step=0, epoch=200))
    assert all(np.array_equal(u, v) for u, v in zip(b1, b2))
    x, target, mask = b1
    assert x.shape == (4, 9, 152) and target.shape == (4, 3, 38, 4) and mask.shape == (2,)
    loss, grads = ad.loss_and_grads(ad.init_params(np.random.default_rng(0)), b1)
    assert np.isfinite(loss) and set(grads) == set(ad.init_params(np.random.default_rng(0)))


def test_make_config_checks():
    from refimpl.errors import UsageError

    data = pr.resolve_data("sample")
    assert not rnn_recipe.make_config(data, ["velocity=false"]).network.velocity
    with pytest.raises(UsageError):
        rnn_recipe.make_config(data, ["num_joints=32"])
    with pytest.raises(UsageError):
        rnn_recipe.make_config(data, ["schedule=sometimes"])
    assert cnn_recipe.make_config(data, ["skips="]).network.skips == ()


# ---------------------------------------------------------------------------------------------- CLI
def test_train_checkpoint_round_trip(rnn_run):
    model = load_trained(rnn_run / "checkpoint.npz")
    assert model.spec.name == "quaternet" and model.config == rnn_recipe.ShortTermConfig(
        num_joints=38, hidden_size=8, num_layers=1, prefix_length=12, target_length=4)
    arrays, meta = load_checkpoint(rnn_run / "checkpoint.npz")
    assert meta["step"] == 4 and meta["optim"]["clip_norm"] == 0.1 and meta["optim"]["lr_decay"] == 0.999
    assert model.extra["dataset"] == "cmu" and model.fps == pytest.approx(60.0)
    for k, v in model.params.items():
        assert np.array_equal(v, arrays[f"param.{k}"])
    lines = (rnn_run / "loss.csv").read_text().splitlines()
    assert lines[0].startswith("step,epoch,loss") and len(lines) == 5


def test_resume_is_bit_for_bit(tmp_path, rnn_run):
    a = tmp_path / "a"
    assert _train(a, "quaternet", TINY_RNN, 2) == EXIT_OK
    assert _train(a, "quaternet", TINY_RNN, 4, "--resume") == EXIT_OK
    pa, _ = load_checkpoint(a / "checkpoint.npz")
    pb, _ = load_checkpoint(rnn_run / "checkpoint.npz")
    assert all(np.array_equal(pa[k], pb[k]) for k in pb if k.startswith("param."))


def test_eval_json_schema(capsys, tmp_path, rnn_run):
    path = tmp_path / "r.json"
    code, out, _ = _run(capsys, "eval", "--checkpoint", rnn_run / "checkpoint.npz", "--json", path)
    assert code == EXIT_OK and "zero-velocity" in out and "quaternet" in out and "milliseconds" in out
    doc = json.loads(path.read_text())
    assert [d["method"] for d in doc] == ["zero-velocity", "run. avg. 2", "run. avg. 4", "quaternet"]
    for d in doc:
        assert {"dataset", "protocol", "method", "samples_per_sequence", "horizons_ms", "actions",
                "average"} <= set(d)
        assert d["dataset"] == "cmu" and d["protocol"] == "standard" and d["samples_per_sequence"] == 4
        assert set(d["actions"]) == {"running", "walking"}
        assert len(d["average"]) == len(d["horizons_ms"]) == 6


def test_eval_baselines_alone_dense(capsys, tmp_path):
    path = tmp_path / "b.json"
    code, out, _ = _run(capsys, "eval", "--model", "quaternet", "--protocol", "dense", "--json", path)
    assert code == EXIT_OK and "protocol dense" in out
    doc = json.loads(path.read_text())
    assert [d["method"] for d in doc] == ["zero-velocity", "run. avg. 2", "run. avg. 4"]
    assert all(d["samples_per_sequence"] == 128 for d in doc)
    direct = PP.evaluate(PP.zero_velocity, pr.resolve_data("sample"), PP.make_protocol("cmu", dense=True))
    assert np.allclose(doc[0]["average"], direct.average)


def test_generate_bvh(capsys, tmp_path, rnn_run):
    out = tmp_path / "p.bvh"
    code, text, _ = _run(capsys, "generate", "--checkpoint", rnn_run / "checkpoint.npz", "--source", WALK_TXT,
                         "--source-frame", "30", "--length", "6", "--out", out, "--truth", tmp_path / "t.bvh")
    assert code == EXIT_OK and "ground truth available" in text
    from refimpl.bvh import read_bvh

    m = read_bvh(out)
    assert m.num_frames == 12 + 6 and (tmp_path / "t.bvh").is_file()
    code, _, err = _run(capsys, "generate", "--checkpoint", rnn_run / "checkpoint.npz", "--source", WALK_TXT,
                        "--source-frame", "3", "--out", out)
    assert code == EXIT_USAGE and "--source-frame" in err


# -------------------------------------------------------------------------------------------- export
onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")


def _prefix(model, B=3):
    return pr.check_prefixes(model, np.random.default_rng(0), B)


def test_export_rnn_parity(capsys, rnn_run, tmp_path):
    from deploy.validate import run_reference

    from refimpl.models import quaternet as net

    code, out, _ = _run(capsys, "export", "--checkpoint", rnn_run / "checkpoint.npz", "--out", tmp_path)
    assert code == EXIT_OK and "predict" in out and "step_loop" in out
    model = load_trained(rnn_run / "checkpoint.npz")
    from deploy.models import runtime_for_dir

    rt = runtime_for_dir(tmp_path)
    prefix = _prefix(model)
    ref = rnn_recipe.reference_outputs(model, prefix, 10)
    for use_graph in (True, False):
        assert np.allclose(rt.predict(prefix, 10, use_graph=use_graph), ref, **TOL_ORT_ROLLOUT)
    predict = onnx.load(str(tmp_path / "quaternet_predict.onnx"))
    got = run_reference(predict, {"prefix": prefix.reshape(3, prefix.shape[1], -1).astype(np.float32)})[0]
    assert np.allclose(got.reshape(ref.shape), ref, **TOL_ORT_ROLLOUT)
    x = prefix[:, 0].reshape(3, -1).astype(np.float32)
    h = net.init_state(model.params, 3, model.config.network)
    y, hn = net.step(model.params, h, x, model.config.network)
    step = onnx.load(str(tmp_path / "quaternet_step.onnx"))
    for got in (run_reference(step, {"x": x, "hidden": h}), list(rt.step(x, h))):
        assert np.allclose(got[0], y, **TOL_ORT_STEP) and np.allclose(got[1], hn, **TOL_ORT_STEP)
    meta = rt.step_model.metadata
    assert meta["model"]["name"] == "quaternet" and meta["dataset"] == "cmu" and len(meta["skeleton"]["names"]) == 38


def test_export_cnn_parity(capsys, cnn_run, tmp_path):
    from deploy.validate import run_reference

    from refimpl.models import quaternet_cnn as cnn

    code, out, _ = _run(capsys, "export", "--checkpoint", cnn_run / "checkpoint.npz", "--out", tmp_path)
    assert code == EXIT_OK and "window_loop" in out
    model = load_trained(cnn_run / "checkpoint.npz")
    from deploy.models import runtime_for_dir

    rt = runtime_for_dir(tmp_path)
    prefix = _prefix(model)
    assert np.allclose(rt.predict(prefix, 5), cnn_recipe.reference_outputs(model, prefix, 5), **TOL_ORT_ROLLOUT)
    w = prefix.reshape(3, prefix.shape[1], -1).astype(np.float32)
    want = cnn.step(model.params, w, model.config.network)
    got = run_reference(onnx.load(str(tmp_path / "quaternet-cnn_window.onnx")), {"window": w})[0]
    assert np.allclose(got, want, **TOL_ORT_STEP)
    code, text, _ = _run(capsys, "generate", "--backend", "onnx", "--onnx", tmp_path, "--source", WALK_TXT,
                         "--source-frame", "20", "--length", "4", "--out", tmp_path / "g.bvh")
    assert code == EXIT_OK and "quaternet-cnn_onnx" in text


def _write_h36m(path, T, rate):
    """A synthetic Human3.6M exp-map file: 99 values per row (junk translation + 32 exp-maps), joint 3 turning."""
    e = np.zeros((T, 33, 3))
    e[:, 0] = 50.0
    e[:, 4, 0] = -rate * np.arange(T)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(",".join(repr(float(v)) for v in r) for r in e.reshape(T, 99)) + "\n")


def test_h36m_directory_train_and_eval(capsys, tmp_path):
    """--data pointing at a user's Human3.6M folder: train a few steps, evaluate with the H3.6M protocol."""
    root = tmp_path / "h36m"
    for sub, T in ((1, 460), (2, 400)):
        _write_h36m(root / "S5" / f"walking_{sub}.txt", T, 0.004)
    for s in ("S1", "S6"):
        for sub in (1, 2):
            _write_h36m(root / s / f"walking_{sub}.txt", 80, 0.01)
    out = tmp_path / "run"
    assert _train(out, "quaternet", TINY_RNN, 2, "--data", str(root)) == EXIT_OK
    model = load_trained(out / "checkpoint.npz")
    assert model.extra["dataset"] == "h36m" and model.config.num_joints == 32 and model.fps == pytest.approx(25.0)
    path = tmp_path / "h.json"
    code, text, _ = _run(capsys, "eval", "--checkpoint", out / "checkpoint.npz", "--data", root, "--json", path)
    assert code == EXIT_OK and "dataset h36m" in text
    doc = json.loads(path.read_text())
    assert doc[0]["horizons_ms"] == [80, 160, 320, 400, 560, 1000, 2000, 3000, 4000]
    assert doc[0]["method"] == "zero-velocity" and list(doc[0]["actions"]) == ["walking"]
    # joint 3 turns 0.008 rad per 25 Hz frame about x: zero-velocity's error at frame k is 0.008 (k + 1)
    assert np.allclose(doc[0]["average"][:4], [0.016, 0.032, 0.064, 0.080], atol=1e-9)
    assert doc[-1]["method"] == "quaternet"


def test_eval_protocol_and_curves():
    assert pr.eval_protocol("cmu", "dense").samples_per_sequence == 128
    assert pr.eval_protocol("h36m", "standard", 8).samples_per_sequence == 8
    with pytest.raises(ValueError, match="standard"):
        pr.eval_protocol("cmu", "sparse")
    assert PD.stride_of("cmu", 1 / 60) == 2 and PD.stride_of("h36m", 0.04) == 2
    data = pr.resolve_data("sample")
    res = PP.evaluate_all(data, pr.methods())
    curves = PP.average_curves(res)
    assert list(curves) == ["zero-velocity", "run. avg. 2", "run. avg. 4"]
    assert np.allclose(curves["zero-velocity"], np.mean([res[0].curves[a] for a in res[0].curves], axis=0))


def test_render_prediction_and_plot(capsys, tmp_path, rnn_run):
    pytest.importorskip("matplotlib")
    code, text, _ = _run(capsys, "generate", "--checkpoint", rnn_run / "checkpoint.npz", "--source", WALK_TXT,
                         "--source-frame", "30", "--length", "6", "--out", tmp_path / "p.bvh", "--png",
                         tmp_path / "p.png")
    assert code == EXIT_OK and (tmp_path / "p.png").stat().st_size > 1000
    code, _, _ = _run(capsys, "eval", "--model", "quaternet-cnn", "--plot", tmp_path / "c.png")
    assert code == EXIT_OK and (tmp_path / "c.png").is_file()
