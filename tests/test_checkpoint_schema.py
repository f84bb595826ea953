"""spec/robustness.md §9: a crafted training checkpoint (content edited, checksum recomputed) is validated against
its schema before anything is built from it, in ``load_trained`` and in deploy's ``load_qtg_checkpoint``.

Every case is a checkpoint written by ``save_checkpoint`` (so its checksum is right) from a real 3-step training
run with one thing changed; each must give ``BadInputError`` / ``ValueError`` naming the field.
"""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint, save_checkpoint
from refimpl.checkpoint_schema import (MAX_FALLBACK_SIZE, expected_param_shapes, validate_model_config,
                                       validate_params, validate_training_state)
from refimpl.cli import main
from refimpl.errors import BadInputError
from refimpl.models.qtg import QTGConfig, init_params, param_shapes
from refimpl.services import load_trained

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    out = tmp_path_factory.mktemp("schema")
    assert main(["train", "--data", str(WALK_BVH), "--out", str(out), "--steps", "2", "--batch-size", "8",
                 "--stride", "8", "--test-fraction", "0.5", "--progress-every", "1", *TINY]) == 0
    return load_checkpoint(out / "checkpoint.npz")


def _craft(tmp_path, good, edit, name="crafted.npz"):
    arrays, meta = copy.deepcopy(good[0]), copy.deepcopy(good[1])
    edit(arrays, meta)
    path = tmp_path / name
    save_checkpoint(path, arrays, meta)  # a valid checksum over the edited content
    return path


def _cfg(key, value):
    def edit(arrays, meta):
        meta["model_config"][key] = value
    return edit


def _meta(key, value):
    def edit(arrays, meta):
        meta[key] = value
    return edit


def _delete_cfg(key):
    def edit(arrays, meta):
        del meta["model_config"][key]
    return edit


def _param(fn):
    def edit(arrays, meta):
        fn(arrays)
    return edit


def _nan(arrays):
    a = arrays["param.gru.weight_hh_l0"].copy()
    a[0, 0] = np.nan
    arrays["param.gru.weight_hh_l0"] = a


def _inf(arrays):
    a = arrays["param.dec.0.bias"].copy()
    a[-1] = -np.inf
    arrays["param.dec.0.bias"] = a


def _huge(arrays):
    arrays["param.dec.0.bias"] = np.full(arrays["param.dec.0.bias"].shape, 3e38, np.float32)


CASES = {
    # the parameters
    "param huge": (_param(_huge), "param.dec.0.bias"),  # finite, but overflows float32 in the first product
    "param NaN": (_param(_nan), "param.gru.weight_hh_l0"),
    "param inf": (_param(_inf), "param.dec.0.bias"),
    "param missing": (_param(lambda a: a.pop("param.vel.bias")), "param.vel.bias"),
    "param unexpected": (_param(lambda a: a.__setitem__("param.extra", np.zeros(3, np.float32))), "param.extra"),
    "param shape": (_param(lambda a: a.__setitem__("param.vel.bias", np.zeros(9, np.float32))), "param.vel.bias"),
    "param transposed": (_param(lambda a: a.__setitem__("param.enc.0.weight", a["param.enc.0.weight"].T.copy())),
                         "param.enc.0.weight"),
    "param int": (_param(lambda a: a.__setitem__("param.vel.bias", np.zeros(8, np.int64))), "param.vel.bias"),
    "param float16": (_param(lambda a: a.__setitem__("param.vel.bias", np.zeros(8, np.float16))), "param.vel.bias"),
    "param mixed dtype": (_param(lambda a: a.__setitem__("param.vel.bias", np.zeros(8, np.float64))),
                          "param.vel.bias"),
    "param 0-d": (_param(lambda a: a.__setitem__("param.vel.bias", np.array(1.0, np.float32))), "param.vel.bias"),
    # the config, by the dataclass's field types
    "config list": (_meta("model_config", [1, 2]), "model_config"),
    "config string": (_meta("model_config", "gru_hidden=8"), "model_config"),
    "config null": (_meta("model_config", None), "model_config"),
    "size null": (_cfg("gru_hidden", None), "model_config.gru_hidden"),
    "size string": (_cfg("gru_hidden", "8"), "model_config.gru_hidden"),
    "size float": (_cfg("gru_hidden", 8.0), "model_config.gru_hidden"),
    "size bool": (_cfg("pose_size", True), "model_config.pose_size"),
    "layers bool": (_cfg("gru_layers", True), "model_config.gru_layers"),
    "layers 2 (params for 1)": (_cfg("gru_layers", 2), "gru.weight_ih_l1"),
    "layers 0": (_cfg("gru_layers", 0), "gru_layers"),
    "size negative": (_cfg("gru_hidden", -8), "gru_hidden"),
    "size huge": (_cfg("gru_hidden", 10**30), "model_config.gru_hidden"),
    "layers huge": (_cfg("gru_layers", 10**30), "model_config.gru_layers"),  # looped for ever in param_shapes
    "sizes long": (_cfg("encoder_sizes", [8] * 5000), "model_config.encoder_sizes"),
    "sizes string": (_cfg("encoder_sizes", "16,8"), "model_config.encoder_sizes"),
    "sizes bool entry": (_cfg("encoder_sizes", [16, True]), "model_config.encoder_sizes[1]"),
    "sizes float entry": (_cfg("encoder_sizes", [16, 8.5]), "model_config.encoder_sizes[1]"),
    "sizes empty": (_cfg("encoder_sizes", []), "encoder_sizes"),
    "sizes dict": (_cfg("decoder_sizes", {"a": 1}), "model_config.decoder_sizes"),
    "slope string": (_cfg("negative_slope", "0.01"), "model_config.negative_slope"),
    "slope bool": (_cfg("negative_slope", False), "model_config.negative_slope"),
    "slope out of range": (_cfg("negative_slope", 5.0), "negative_slope"),
    "pose size": (_cfg("pose_size", 95), "enc.0.weight"),
    # what the task stores
    "fps 0": (_cfg("fps", 0), "model_config.fps"),
    "fps negative": (_cfg("fps", -30.0), "model_config.fps"),
    "fps string": (_cfg("fps", "30"), "model_config.fps"),
    "fps bool": (_cfg("fps", True), "model_config.fps"),
    "fps null": (_cfg("fps", None), "model_config.fps"),
    "root_std 0": (_cfg("root_std", [1.0, 0.0, 1.0]), "model_config.root_std[1]"),
    "root_std negative": (_cfg("root_std", [1.0, 1.0, -2.0]), "model_config.root_std[2]"),
    "root_std short": (_cfg("root_std", [1.0, 1.0]), "model_config.root_std"),
    "root_std string": (_cfg("root_std", "1,1,1"), "model_config.root_std"),
    "root_mean strings": (_cfg("root_mean", ["a", 0, 0]), "model_config.root_mean[0]"),
    "root_mean missing": (_delete_cfg("root_mean"), "root_mean"),
    "T 0": (_cfg("transition_length", 0), "model_config.transition_length"),
    "T string": (_cfg("transition_length", "30"), "model_config.transition_length"),
    "dtype float16": (_cfg("dtype", "float16"), "model_config.dtype"),
    "dtype mismatch": (_cfg("dtype", "float64"), "dtype"),
    "representation number": (_cfg("representation", 5), "model_config.representation"),
    # the metadata around it
    "model number": (_meta("model", 5), "model"),
    "model unknown": (_meta("model", "nope"), "unknown model"),
    "model list": (_meta("model", ["qtg"]), "model"),
    "format": (_meta("format", "other/1"), "format"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_crafted_checkpoint_is_refused_naming_the_field(tmp_path, good, case):
    """spec/robustness.md §9: ``load_trained`` refuses each crafted checkpoint with BadInputError naming the file and
    the field; nothing is built from it."""
    edit, field = CASES[case]
    path = _craft(tmp_path, good, edit)
    with pytest.raises(BadInputError) as info:
        load_trained(path)
    msg = str(info.value)
    assert str(path) in msg and field in msg, msg
    assert "\n" not in msg


DEPLOY_CASES = [c for c in sorted(CASES) if not c.startswith(("model ", "format", "root_mean missing"))]


@pytest.mark.parametrize("case", DEPLOY_CASES)
def test_deploy_loader_validates_too(tmp_path, good, case):
    """spec/robustness.md §9: deploy's ``load_qtg_checkpoint`` applies the same schema (ValueError naming the field)."""
    pytest.importorskip("onnx")
    from deploy.models.qtg_io import load_checkpoint as load_qtg_checkpoint

    edit, field = CASES[case]
    path = _craft(tmp_path, good, edit)
    with pytest.raises(ValueError) as info:
        load_qtg_checkpoint(path)
    assert field.split(".")[-1].split("[")[0] in str(info.value) or "param" in str(info.value), str(info.value)


def test_good_checkpoint_loads_everywhere(tmp_path, good):
    """The unmodified content re-signed loads in both loaders with the same parameters."""
    path = _craft(tmp_path, good, lambda a, m: None)
    model = load_trained(path)
    assert model.config.gru_hidden == 8 and model.fps > 0 and np.all(model.fields["root_std"] > 0)
    pytest.importorskip("onnx")
    from deploy.models.qtg_io import load_checkpoint as load_qtg_checkpoint

    params, config, _ = load_qtg_checkpoint(path)
    assert config == model.config and set(params) == set(model.params)


def test_state_dict_validated_against_default_config(tmp_path):
    """A plain state dict (no metadata) is checked against ``QTGConfig()``'s shapes and finiteness."""
    pytest.importorskip("onnx")
    from deploy.models.qtg_io import load_checkpoint as load_qtg_checkpoint

    params = init_params(QTGConfig(), np.random.default_rng(0), dtype=np.float32)
    np.savez(tmp_path / "sd.npz", **params)
    assert set(load_qtg_checkpoint(tmp_path / "sd.npz")[0]) == set(params)
    params["vel.bias"] = params["vel.bias"].copy()
    params["vel.bias"][0] = np.nan
    np.savez(tmp_path / "bad.npz", **params)
    with pytest.raises(ValueError, match="vel.bias"):
        load_qtg_checkpoint(tmp_path / "bad.npz")


def test_schema_helpers_directly():
    """The generic pieces: field types from the dataclass, shapes from ``param_shapes`` or ``init_params``."""
    assert validate_model_config(QTGConfig, {"gru_hidden": 4, "encoder_sizes": [3, 2], "unknown": 1}).gru_hidden == 4
    with pytest.raises(ValueError, match="gru_layers: expected an integer, got bool"):
        validate_model_config(QTGConfig, {"gru_layers": True})
    cfg = QTGConfig(pose_size=7, encoder_sizes=(3, 2), gru_hidden=4, decoder_sizes=(5,))
    from refimpl.models import qtg as qtg_module

    assert expected_param_shapes(None, QTGConfig, cfg) == param_shapes(cfg)

    class InitOnly:  # a recipe whose model has only init_params: shapes found by running it on a tiny generator
        @staticmethod
        def init_params(config, rng, dtype=np.float64):
            return qtg_module.init_params(config, rng, dtype=dtype)

    class Cfg:  # a config type from a module without param_shapes
        __module__ = "no.such.module"

    assert expected_param_shapes(InitOnly, Cfg, cfg) == param_shapes(cfg)
    big = QTGConfig(pose_size=7, encoder_sizes=(3, 2), gru_hidden=MAX_FALLBACK_SIZE + 1, decoder_sizes=(5,))
    with pytest.raises(ValueError, match="gru_hidden"):
        expected_param_shapes(InitOnly, Cfg, big)
    params = init_params(cfg, np.random.default_rng(0))
    assert validate_params(params, param_shapes(cfg)) == np.float64


def test_training_state_schema():
    """Resume-only state: counters, Adam moments (finite, v >= 0, one per parameter) and the permutation."""
    from refimpl.optim import adam_init

    params = {"w": np.ones((2, 3))}
    opt = adam_init(params)
    meta = {"step": 1, "epoch": 0, "position": 1, "rng_state": "{}"}
    validate_training_state(params, opt, np.arange(4), meta, 4)
    bad = dict(opt, **{"v.w": -np.ones((2, 3))})
    with pytest.raises(ValueError, match="optim.v.w"):
        validate_training_state(params, bad, np.arange(4), meta, 4)
    bad = dict(opt, **{"m.w": np.full((2, 3), np.inf)})
    with pytest.raises(ValueError, match="optim.m.w"):
        validate_training_state(params, bad, np.arange(4), meta, 4)
    with pytest.raises(ValueError, match="optim"):
        validate_training_state(params, {"step": opt["step"]}, np.arange(4), meta, 4)
    with pytest.raises(ValueError, match="sampler.perm"):
        validate_training_state(params, opt, np.array([0, 0, 1, 2]), meta, 4)
    for key, value in (("step", -1), ("epoch", True), ("position", "1"), ("rng_state", 5)):
        with pytest.raises(ValueError, match=key):
            validate_training_state(params, opt, np.arange(4), dict(meta, **{key: value}), 4)
