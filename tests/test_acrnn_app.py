"""acRNN through the application layer (spec/acrnn.md §8, spec/cli.md, spec/deploy.md §8.2): the recipe and the
synthesis task wired into ``refimpl train / eval / generate / export``, exact resume, BVH decoding, and the
exported step / generator graphs against NumPy (onnxruntime and the ONNX reference evaluator)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import read_bvh
from refimpl.checkpoint import load_checkpoint
from refimpl.cli import EXIT_OK, EXIT_USAGE, main
from refimpl.models import acrnn
from refimpl.protocols import synthesis as SP
from refimpl.registry import MODELS
from refimpl.services import load_trained
from refimpl.tasks import synthesis as S

ROOT = Path(__file__).resolve().parents[1]
SALSA = ROOT / "refimpl" / "data" / "sample" / "salsa"
TINY = ["--model", "acrnn", "--data", "sample", "--set", "hidden_size=8", "--set", "num_layers=2",
        "--batch-size", "3", "--window-length", "12", "--progress-every", "1", "--dtype", "float64"]


def _train(out, *extra):
    return main(["train", *TINY, "--out", str(out), *[str(e) for e in extra]])


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("acrnn")
    assert _train(out, "--steps", "3", "--representation", "dq-all") == EXIT_OK
    return out


def test_registry_knows_acrnn_on_the_synthesis_task():
    spec = MODELS["acrnn"]
    assert spec.task == "synthesis" and spec.exporter == "acrnn"
    assert set(spec.representations) == set(S.TABLE1_ROWS) and spec.representations[0] == "dq-all"
    assert all(v in acrnn.VARIANTS for v in S.TABLE1_ROWS.values())
    assert spec.optim.lr == 1e-4 and spec.recipe.PAPER_BATCH == 32 and spec.recipe.PAPER_WINDOW == 100


def test_train_writes_a_checkpoint_with_the_row_and_its_statistics(trained):
    model = load_trained(trained / "checkpoint.npz")
    ex = model.extra
    assert model.spec.name == "acrnn" and model.config.hidden_size == 8 and model.config.frame_size == 3 + 8 * 43
    assert ex["row"] == "dq-all" and ex["representation"] == "dq-all" and ex["variant"] == "dual_quaternions_all"
    assert ex["data_representation"] == "dual_quaternions" and ex["loss_weights"]["reg"] == 0.01
    assert len(ex["mean"]) == model.config.frame_size and len(ex["skeleton"]["parents"]) == 43
    assert model.meta["step"] == 3


def test_resume_is_bit_for_bit(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert _train(a, "--steps", "4", "--representation", "quaternions-fk") == EXIT_OK
    assert _train(b, "--steps", "2", "--representation", "quaternions-fk") == EXIT_OK
    assert _train(b, "--steps", "4", "--representation", "quaternions-fk", "--resume") == EXIT_OK
    pa, _ = load_checkpoint(a / "checkpoint.npz")
    pb, _ = load_checkpoint(b / "checkpoint.npz")
    for k in pa:
        if k.startswith("param."):
            assert np.array_equal(pa[k], pb[k]), k


def test_losses_override_and_bad_values(tmp_path, capsys):
    assert _train(tmp_path / "o", "--steps", "1", "--representation", "dq-mse", "--losses", "mse=1,pos=0.5") == EXIT_OK
    assert load_trained(tmp_path / "o" / "checkpoint.npz").extra["loss_weights"] == {"mse": 1.0, "pos": 0.5}
    assert _train(tmp_path / "x", "--steps", "1", "--representation", "ortho6d", "--losses", "pos=1") == EXIT_USAGE
    assert _train(tmp_path / "y", "--steps", "1", "--representation", "nope") == EXIT_USAGE
    capsys.readouterr()


def test_eval_prints_table1_metrics_and_writes_json(trained, tmp_path, capsys):
    js = tmp_path / "r.json"
    assert main(["eval", "--checkpoint", str(trained / "checkpoint.npz"), "--data", "sample",
                 "--json", str(js)]) == EXIT_OK
    out = capsys.readouterr().out
    assert "NPSS 'real'" in out and "acrnn" in out and "hold" in out
    res = json.loads(js.read_text())
    assert set(res) == {"acrnn", "hold"}
    assert set(res["acrnn"]["horizons"]) == {"100", "400", "1000"}
    assert res["acrnn"]["num_seeds"] == 116 and np.isfinite(res["acrnn"]["acceleration"]["pred"])


@pytest.mark.parametrize("row", ["dq-all", "ortho6d"])
def test_generate_decodes_to_bvh_and_keeps_the_seed(trained, tmp_path, row, capsys):
    ck = trained / "checkpoint.npz"
    if row != "dq-all":
        ck = tmp_path / "m" / "checkpoint.npz"
        assert _train(ck.parent, "--steps", "1", "--representation", row) == EXIT_OK
    out = tmp_path / "gen.bvh"
    assert main(["generate", "--model", "acrnn", "--checkpoint", str(ck), "--source", str(SALSA / "16.bvh"),
                 "--source-frame", "7", "--length", "15", "--out", str(out)]) == EXIT_OK
    assert "10 seed frames" in capsys.readouterr().out
    m = read_bvh(out)
    assert m.num_frames == 25
    src = SP.load_salsa_motion(SALSA / "16.bvh")
    # the seed frames decode back to the source's joint positions (the End Sites added for readers are extra)
    names = list(m.skeleton.names)
    idx = [names.index(n) for n in src.skeleton.names]
    got = m.positions()[:10, idx]
    want = src.positions()[7:17] / SP.LENGTH_SCALE   # the BVH keeps the take's centimetres (issue #24)
    np.testing.assert_allclose(got, want, atol=1e-3)


def test_generate_writes_positions_as_bvh(tmp_path):
    """A positional row has no rotation decoding: its frames become rotations along the bones (spec/kinematics.md
    §7; this was exit 2 before issue 32)."""
    ck = tmp_path / "p"
    assert _train(ck, "--steps", "1", "--representation", "positions") == EXIT_OK
    code = main(["generate", "--model", "acrnn", "--checkpoint", str(ck / "checkpoint.npz"), "--source",
                 str(SALSA / "16.bvh"), "--length", "4", "--out", str(tmp_path / "g.bvh")])
    assert code == EXIT_OK and read_bvh(tmp_path / "g.bvh").num_frames == 14


def test_export_verifies_and_onnx_backends_agree(trained, tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    onnx_dir = tmp_path / "onnx"
    assert main(["export", "--checkpoint", str(trained / "checkpoint.npz"), "--out", str(onnx_dir)]) == EXIT_OK
    out = capsys.readouterr().out
    assert "acrnn_step.onnx" in out and "acrnn_generate.onnx" in out and "(generate)" in out
    gen = tmp_path / "g.bvh"
    assert main(["generate", "--model", "acrnn", "--checkpoint", str(trained / "checkpoint.npz"), "--backend", "onnx",
                 "--onnx", str(onnx_dir), "--source", str(SALSA / "16.bvh"), "--length", "5",
                 "--out", str(gen)]) == EXIT_OK
    assert read_bvh(gen).num_frames == 15
    js = tmp_path / "r.json"
    assert main(["eval", "--checkpoint", str(trained / "checkpoint.npz"), "--onnx", str(onnx_dir),
                 "--json", str(js)]) == EXIT_OK
    res = json.loads(js.read_text())
    for ms in ("100", "400", "1000"):
        assert abs(res["acrnn_onnx"]["horizons"][ms]["euclidean"] - res["acrnn"]["horizons"][ms]["euclidean"]) < 1e-4


def _tiny_model(representation, J=3, skewed=False, seed=0):
    rng = np.random.default_rng(seed)
    cfg = acrnn.config_for(representation, J, hidden_size=6, num_layers=2, skewed=skewed)
    params = acrnn.init_params(cfg, rng, np.float64)
    mean = 0.1 * rng.standard_normal(cfg.frame_size)
    std = 0.5 + rng.random(cfg.frame_size)
    return cfg, params, mean, std, rng


@pytest.mark.parametrize("representation,skewed", [("dual_quaternions", False), ("quaternions", True),
                                                   ("ortho6d", False)])
def test_exported_graphs_match_numpy(representation, skewed):
    pytest.importorskip("onnxruntime")
    from deploy.models.acrnn import export_acrnn_generate, export_acrnn_step
    from deploy.validate import run_onnxruntime, run_reference, validate_model
    from refimpl.dualquat import dq_normalize, translation_from_dq
    from refimpl.recipes.acrnn import acrnn_method

    cfg, params, mean, std, rng = _tiny_model(representation, skewed=skewed)
    F, J = cfg.frame_size, 3
    seed = mean + std * rng.standard_normal((2, 4, F))
    want = acrnn_method(params, cfg, mean, std)(seed, 5)                                      # (B, N, F)
    kw = dict(mean=mean, std=std, representation=representation, dtype=np.float64)
    gen = validate_model(export_acrnn_generate(params, cfg, **kw))
    feeds = {"seed": seed, "num_frames": np.array(5, dtype=np.int64)}
    for run in (run_onnxruntime, run_reference):
        outs = run(gen, feeds)
        np.testing.assert_allclose(outs[0], want, rtol=1e-9, atol=1e-9)
        blocks = want[..., 3:].reshape(2, 5, J, -1)
        if representation == "dual_quaternions":
            np.testing.assert_allclose(outs[1], dq_normalize(blocks), atol=1e-9)
            np.testing.assert_allclose(outs[2], translation_from_dq(dq_normalize(blocks)), atol=1e-9)
        elif representation == "quaternions":
            np.testing.assert_allclose(outs[1], blocks / np.linalg.norm(blocks, axis=-1, keepdims=True), atol=1e-9)
        else:
            assert len(outs) == 1
    step = validate_model(export_acrnn_step(params, cfg, **kw))
    h, c = acrnn.init_state(cfg, 2)
    x = seed[:, 0]
    y, (h1, c1) = acrnn.step(params, cfg, (x - mean) / std, (h, c))
    for run in (run_onnxruntime, run_reference):
        outs = run(step, {"frame": x, "h": h, "c": c})
        np.testing.assert_allclose(outs[0], y * std + mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(outs[1], h1, atol=1e-12)
        np.testing.assert_allclose(outs[2], c1, atol=1e-12)
