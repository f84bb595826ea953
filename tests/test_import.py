"""Importing weights trained elsewhere (refimpl/weights.py, ``refimpl import`` / ``export-weights``; spec/import.md).

For each published layout a state dict with the published names and shapes (random weights, no torch) is saved
with ``np.savez`` and as safetensors, imported with the command, and the imported checkpoint's generation /
prediction is compared with an independent NumPy computation of the *published* network written here from the
documented facts (acRNN: three ``nn.LSTMCell`` in the skewed stack; QuaterNet: 2-layer GRU, learned ``h0``, ``fc``,
velocity mode ``q = normalize(fc(h) ⊗ x)``), or with the project's model on the same tensors. ``refimpl export``
of an imported checkpoint runs in onnxruntime and reproduces the same outputs. With torch, the published
architectures are built in torch (our own code from the same facts), their ``state_dict`` saved with
``torch.save`` and imported.
"""
import json

import numpy as np
import pytest

from refimpl.protocols.prediction import canonical_prefix
from refimpl.cli import build_parser, main
from refimpl.registry import MODELS, task_of
from refimpl.safetensors import write_safetensors
from refimpl.services import load_trained
from refimpl.weights import (export_state_dict, from_refimpl, import_checkpoint, layout_names, read_state_dict,
                             to_refimpl)

H = 8  # tiny hidden size: fast, and every layout rule is the same as at the paper's size


def _datasets(model, *extra):
    args = build_parser().parse_args(["import", "x.npz", "--model", model, "--out", "y.npz", *extra])
    return args, task_of(MODELS[model]).train_datasets(args)


def _state(model, layout="published", overrides=(), seed=0, scale=0.3):
    """A random state dict with ``model``'s names and shapes in ``layout`` for the sample data."""
    spec = MODELS[model]
    _, (train_ds, _) = _datasets(model)
    settings = tuple(getattr(spec.recipe, "PUBLISHED_SETTINGS", ())) if layout == "published" else ()
    config = spec.make_config(train_ds, (*settings, *overrides))
    rng = np.random.default_rng(seed)
    return {n: rng.uniform(-scale, scale, s).astype(np.float32)
            for n, s in layout_names(spec, config, layout).values()}


def _import(tmp_path, weights, model, *extra, out="ckpt.npz"):
    return main(["--blas-threads", "1", "import", str(weights), "--model", model, "--out", str(tmp_path / out),
                 *extra])


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def _published_acrnn(sd, seed, n):
    """The published acRNN (papagina ``forward_lstm``) on standardised frames: ``lstm1..3`` LSTMCells where cell
    k+1 reads cell k's hidden state of the *previous* step, decoder on the new top state; seed read, outputs fed
    back. float64."""
    sd = {k: np.asarray(v, np.float64) for k, v in sd.items()}
    B = seed.shape[0]
    Hs = sd["lstm1.weight_hh"].shape[1]
    h = [np.zeros((B, Hs)) for _ in range(3)]
    c = [np.zeros((B, Hs)) for _ in range(3)]

    def cell(k, x, h, c):
        g = x @ sd[f"lstm{k}.weight_ih"].T + sd[f"lstm{k}.bias_ih"] + h @ sd[f"lstm{k}.weight_hh"].T \
            + sd[f"lstm{k}.bias_hh"]
        i, f, gg, o = np.split(g, 4, axis=-1)
        c2 = _sigmoid(f) * c + _sigmoid(i) * np.tanh(gg)
        return _sigmoid(o) * np.tanh(c2), c2

    def step(x):
        new = [cell(1, x, h[0], c[0]), cell(2, h[0], h[1], c[1]), cell(3, h[1], h[2], c[2])]
        for k in range(3):
            h[k], c[k] = new[k]
        return h[2] @ sd["decoder.weight"].T + sd["decoder.bias"]

    for t in range(seed.shape[1]):
        y = step(seed[:, t])
    out = [y]
    for _ in range(n - 1):
        out.append(step(out[-1]))
    return np.stack(out, axis=1)


def _hamilton(a, b):
    w1, x1, y1, z1 = np.moveaxis(a, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(b, -1, 0)
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=-1)


def _published_quaternet(sd, prefix, k):
    """The published short-term QuaterNet (facebookresearch ``common/quaternet.py``): GRU(4J → H, 2 layers, gates
    r|z|n), h0, fc, velocity mode ``q = normalize(pre ⊗ x)``; prefix read, then k − 1 fed-back steps. float64."""
    sd = {kk: np.asarray(v, np.float64) for kk, v in sd.items()}
    B, _, J, _ = prefix.shape
    L = sum(1 for kk in sd if kk.startswith("rnn.weight_ih_l"))
    h = [np.repeat(sd["h0"][l], B, axis=0) for l in range(L)]

    def gru(l, x, h):
        gi = x @ sd[f"rnn.weight_ih_l{l}"].T + sd[f"rnn.bias_ih_l{l}"]
        gh = h @ sd[f"rnn.weight_hh_l{l}"].T + sd[f"rnn.bias_hh_l{l}"]
        ir, iz, i_n = np.split(gi, 3, axis=-1)
        hr, hz, h_n = np.split(gh, 3, axis=-1)
        r, z = _sigmoid(ir + hr), _sigmoid(iz + hz)
        n = np.tanh(i_n + r * h_n)
        return (1 - z) * n + z * h

    def step(x):  # x (B, J, 4)
        inp = x.reshape(B, -1)
        for l in range(L):
            h[l] = gru(l, inp, h[l])
            inp = h[l]
        pre = (inp @ sd["fc.weight"].T + sd["fc.bias"]).reshape(B, J, 4)
        q = _hamilton(pre, x)
        return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)

    for t in range(prefix.shape[1]):
        y = step(prefix[:, t])
    out = [y]
    for _ in range(k - 1):
        out.append(step(out[-1]))
    return np.stack(out, axis=1)


# ------------------------------------------------------------------------------------------------------------
# name maps, both directions

@pytest.mark.parametrize("model", ["acrnn", "quaternet", "quaternet-long", "pace"])
def test_name_maps_round_trip_both_directions(model):
    spec = MODELS[model]
    _, (train_ds, _) = _datasets(model)
    config = spec.make_config(train_ds, ("hidden_size=8",) + (("bidirectional=false",) if model == "pace" else ()))
    names = layout_names(spec, config, "published")
    rng = np.random.default_rng(1)
    shapes = {k: s for k, s in layout_names(spec, config, "refimpl").values()}
    params = {k: rng.standard_normal(s) for k, s in shapes.items()}
    state = from_refimpl(params, names)
    assert len(set(state)) == len(params)                      # a bijection of names
    back = to_refimpl(state, names, shapes)
    assert set(back) == set(params) and all(np.array_equal(back[k], params[k]) for k in params)
    again = from_refimpl(back, names)
    assert all(np.array_equal(again[k], state[k]) for k in state)
    for ours, (theirs, shape) in names.items():
        assert state[theirs].shape == shape and state[theirs].size == params[ours].size


def test_acrnn_published_names_are_the_lstm_cells():
    from refimpl.models.acrnn import ACRNNConfig, published_names

    names = published_names(ACRNNConfig(frame_size=171, hidden_size=1024))
    assert names["lstm.weight_ih_l0"] == ("lstm1.weight_ih", (4096, 171))
    assert names["lstm.weight_hh_l1"] == ("lstm2.weight_hh", (4096, 1024))
    assert names["lstm.bias_ih_l2"] == ("lstm3.bias_ih", (4096,))
    assert names["decoder.weight"] == ("decoder.weight", (171, 1024))
    assert len(names) == 14


def test_pace_delayed_eos_shape_differs():
    from refimpl.models.pace import PaceConfig, published_names

    assert published_names(PaceConfig(bidirectional=False))["eos"] == ("eos", (1, 1, 2))
    assert "eos" not in published_names(PaceConfig())


def test_refimpl_layout_is_the_identity_and_qtg_has_no_published_layout(tmp_path):
    from refimpl.errors import UsageError

    spec = MODELS["qtg"]
    _, (train_ds, _) = _datasets("qtg")
    config = spec.make_config(train_ds, ())
    assert all(k == n for k, (n, _) in layout_names(spec, config, "refimpl").items())
    with pytest.raises(UsageError, match="no published code"):
        layout_names(spec, config, "published")


# ------------------------------------------------------------------------------------------------------------
# each published layout: np.savez and safetensors -> refimpl import -> the published network's outputs

@pytest.mark.parametrize("fmt", ["npz", "safetensors"])
def test_acrnn_published_import_generates_as_the_published_network(tmp_path, fmt, capsys):
    sd = _state("acrnn", overrides=("hidden_size=8",))
    path = tmp_path / f"acrnn.{fmt}"
    (np.savez(path, **sd) if fmt == "npz" else write_safetensors(path, sd))
    assert _import(tmp_path, path, "acrnn", "--set", "hidden_size=8") == 0
    model = load_trained(tmp_path / "ckpt.npz")
    assert model.config.skewed is True and model.config.hidden_size == 8
    assert model.meta["imported"]["layout"] == "published"
    capsys.readouterr()
    assert main(["info", str(tmp_path / "ckpt.npz")]) == 0
    assert f"imported    from acrnn.{fmt} (published names" in capsys.readouterr().out
    mean, std = np.asarray(model.extra["mean"]), np.asarray(model.extra["std"])
    rng = np.random.default_rng(2)
    seed = mean + std * rng.standard_normal((2, 10, mean.size))
    got = model.spec.make_method(model)(seed, 12)
    want = _published_acrnn(sd, (seed - mean) / std, 12) * std + mean
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * float(std.max()))   # float32 parameters
    # the ordinary stack is another network: the published weights need the skew
    assert _import(tmp_path, path, "acrnn", "--set", "hidden_size=8", "--set", "skewed=false",
                   out="plain.npz") == 0
    plain = load_trained(tmp_path / "plain.npz")
    assert np.abs(plain.spec.make_method(plain)(seed, 12) - want).max() > 1e-3 * float(std.max())


@pytest.mark.parametrize("fmt", ["npz", "safetensors"])
def test_quaternet_short_term_published_import_predicts_as_the_published_network(tmp_path, fmt):
    sd = _state("quaternet", overrides=("hidden_size=8",))
    path = tmp_path / f"q.{fmt}"
    (np.savez(path, **sd) if fmt == "npz" else write_safetensors(path, sd))
    assert _import(tmp_path, path, "quaternet", "--set", "hidden_size=8") == 0
    model = load_trained(tmp_path / "ckpt.npz")
    J = model.config.num_joints
    rng = np.random.default_rng(3)
    q = rng.standard_normal((2, 6, J, 4))
    prefix = q / np.linalg.norm(q, axis=-1, keepdims=True)
    got = model.spec.recipe.reference_outputs(model, prefix.astype(np.float32), 5)
    want = _published_quaternet(sd, prefix, 5)
    np.testing.assert_allclose(got, want, atol=2e-5)


def test_quaternet_long_and_pace_published_import_equal_the_project_models(tmp_path):
    from refimpl.models import pace, quaternet

    sd = _state("quaternet-long", overrides=("hidden_size=8",))
    np.savez(tmp_path / "long.npz", **sd)
    assert _import(tmp_path, tmp_path / "long.npz", "quaternet-long", "--set", "hidden_size=8", out="l.npz") == 0
    model = load_trained(tmp_path / "l.npz")
    net = model.config.network()
    rng = np.random.default_rng(4)
    x = rng.standard_normal((2, 5, net.input_size)).astype(np.float32)
    ctrl = rng.standard_normal((2, 3, net.num_controls)).astype(np.float32)
    np.testing.assert_array_equal(quaternet.predict(model.params, x, 4, net, controls=ctrl),
                                  quaternet.predict(sd, x, 4, net, controls=ctrl))
    # the delayed pace network: the published eos (1, 1, 2) becomes ours (2,)
    sd = _state("pace", overrides=("bidirectional=false",))
    write_safetensors(tmp_path / "pace.safetensors", sd)
    assert _import(tmp_path, tmp_path / "pace.safetensors", "pace", "--set", "bidirectional=false",
                   out="p.npz") == 0
    model = load_trained(tmp_path / "p.npz")
    np.testing.assert_array_equal(model.params["eos"], sd["eos"].reshape(2))
    assert pace.published_names(model.config)["eos"][1] == sd["eos"].shape


def test_refimpl_layout_round_trip_through_export_weights(tmp_path):
    sd = _state("qtg", layout="refimpl")
    np.savez(tmp_path / "qtg.npz", **sd)
    assert _import(tmp_path, tmp_path / "qtg.npz", "qtg", "--layout", "refimpl") == 0
    for fmt in ("npz", "safetensors"):
        out = tmp_path / f"back.{fmt}"
        assert main(["export-weights", str(tmp_path / "ckpt.npz"), "--layout", "refimpl", "--out", str(out)]) == 0
        back = read_state_dict(out)
        assert set(back) == set(sd) and all(np.array_equal(back[k], sd[k]) for k in sd)


def test_export_weights_published_names_round_trip(tmp_path):
    sd = _state("acrnn", overrides=("hidden_size=8",))
    np.savez(tmp_path / "a.npz", **sd)
    assert _import(tmp_path, tmp_path / "a.npz", "acrnn", "--set", "hidden_size=8") == 0
    assert main(["export-weights", str(tmp_path / "ckpt.npz"), "--out", str(tmp_path / "b.safetensors")]) == 0
    back = read_state_dict(tmp_path / "b.safetensors")
    assert set(back) == set(sd) and all(np.array_equal(back[k], sd[k]) for k in sd)
    assert set(export_state_dict(load_trained(tmp_path / "ckpt.npz"))) == set(sd)


def test_ddp_prefix_and_float16_are_accepted(tmp_path):
    sd = _state("acrnn", overrides=("hidden_size=8",))
    np.savez(tmp_path / "ddp.npz", **{f"module.{k}": v.astype(np.float16) for k, v in sd.items()})
    got = read_state_dict(tmp_path / "ddp.npz")
    assert set(got) == set(sd) and all(v.dtype == np.float32 for v in got.values())
    assert _import(tmp_path, tmp_path / "ddp.npz", "acrnn", "--set", "hidden_size=8") == 0


# ------------------------------------------------------------------------------------------------------------
# export of an imported checkpoint: onnxruntime reproduces the published network

def test_export_of_imported_acrnn_reproduces_the_published_outputs(tmp_path):
    pytest.importorskip("onnxruntime")
    from refimpl.services import onnx_method

    sd = _state("acrnn", overrides=("hidden_size=8",))
    write_safetensors(tmp_path / "a.safetensors", sd)
    assert _import(tmp_path, tmp_path / "a.safetensors", "acrnn", "--set", "hidden_size=8") == 0
    assert main(["export", "--checkpoint", str(tmp_path / "ckpt.npz"), "--out", str(tmp_path / "onnx")]) == 0
    model = load_trained(tmp_path / "ckpt.npz")
    mean, std = np.asarray(model.extra["mean"]), np.asarray(model.extra["std"])
    seed = mean + std * np.random.default_rng(5).standard_normal((2, 10, mean.size))
    got = onnx_method(tmp_path / "onnx")(seed, 12)
    want = _published_acrnn(sd, (seed - mean) / std, 12) * std + mean
    np.testing.assert_allclose(got, want, rtol=1e-3, atol=1e-4 * float(std.max()))


def test_export_of_imported_quaternet_reproduces_the_published_outputs(tmp_path):
    pytest.importorskip("onnxruntime")
    from deploy.models import runtime_for_dir

    sd = _state("quaternet", overrides=("hidden_size=8",))
    np.savez(tmp_path / "q.npz", **sd)
    assert _import(tmp_path, tmp_path / "q.npz", "quaternet", "--set", "hidden_size=8") == 0
    assert main(["export", "--checkpoint", str(tmp_path / "ckpt.npz"), "--out", str(tmp_path / "onnx")]) == 0
    model = load_trained(tmp_path / "ckpt.npz")
    J = model.config.num_joints
    q = np.random.default_rng(6).standard_normal((2, 6, J, 4))
    # the published predict canonicalises its prefix first (spec/deploy.md §11.1); the exported graph does too, so
    # the published network is fed the canonical prefix and the graph any signs of it
    prefix = canonical_prefix(q / np.linalg.norm(q, axis=-1, keepdims=True))
    got = runtime_for_dir(tmp_path / "onnx").predict(prefix.astype(np.float32), 5)
    np.testing.assert_allclose(np.asarray(got, np.float64), _published_quaternet(sd, prefix, 5), atol=1e-4)


# ------------------------------------------------------------------------------------------------------------
# bad input: one line, exit 3 (bad file) or 2 (bad option); nothing written

def _one_line_error(capsys, code, want):
    err = capsys.readouterr().err.strip()
    assert code == want and err.count("\n") == 0 and "Traceback" not in err, err
    return err


def test_mismatched_files_exit_3_with_one_line(tmp_path, capsys):
    sd = _state("acrnn", overrides=("hidden_size=8",))
    np.savez(tmp_path / "a.npz", **sd)
    # another model's state dict
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "a.npz", "quaternet"), 3)
    assert "missing" in err and "unexpected" in err and "lstm1" in err
    # wrong sizes: the config fields to --set are named
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "a.npz", "acrnn"), 3)
    assert "wrong shapes" in err and "hidden_size" in err and "positions-published" in err
    # a missing and an extra entry
    np.savez(tmp_path / "b.npz", **{k: v for k, v in sd.items() if k != "lstm3.bias_hh"}, extra=np.ones(2))
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "b.npz", "acrnn", "--set", "hidden_size=8"), 3)
    assert "lstm3.bias_hh" in err and "extra" in err
    # the project's names given as published ones
    np.savez(tmp_path / "c.npz", **_state("acrnn", layout="refimpl", overrides=("hidden_size=8",)))
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "c.npz", "acrnn", "--set", "hidden_size=8"), 3)
    assert "these are the names of --layout refimpl" in err
    # NaN weights
    np.savez(tmp_path / "d.npz", **{**sd, "decoder.bias": np.full_like(sd["decoder.bias"], np.nan)})
    _one_line_error(capsys, _import(tmp_path, tmp_path / "d.npz", "acrnn", "--set", "hidden_size=8"), 3)
    # a malformed safetensors file, a refimpl checkpoint, an unknown file type, a missing file
    (tmp_path / "e.safetensors").write_bytes(b"\x10\0\0\0\0\0\0\0{\"x\": 1}")
    _one_line_error(capsys, _import(tmp_path, tmp_path / "e.safetensors", "acrnn"), 3)
    assert _import(tmp_path, tmp_path / "a.npz", "acrnn", "--set", "hidden_size=8") == 0
    capsys.readouterr()
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "ckpt.npz", "acrnn", out="x.npz"), 3)
    assert "already a refimpl checkpoint" in err
    (tmp_path / "f.txt").write_text("hello")
    _one_line_error(capsys, _import(tmp_path, tmp_path / "f.txt", "acrnn", out="y.npz"), 3)
    _one_line_error(capsys, _import(tmp_path, tmp_path / "nope.npz", "acrnn", out="z.npz"), 3)
    assert not any((tmp_path / n).exists() for n in ("x.npz", "y.npz", "z.npz"))


def test_bad_options_exit_2(tmp_path, capsys):
    np.savez(tmp_path / "a.npz", **_state("qtg", layout="refimpl"))
    _one_line_error(capsys, _import(tmp_path, tmp_path / "a.npz", "qtg", "--layout", "published"), 2)  # no code
    assert _import(tmp_path, tmp_path / "a.npz", "qtg") == 0  # #35: QTG's default layout is refimpl
    capsys.readouterr()
    _one_line_error(capsys, _import(tmp_path, tmp_path / "a.npz", "qtg", "--layout", "refimpl"), 2)  # exists
    _one_line_error(capsys, _import(tmp_path, tmp_path / "a.npz", "qtg", "--layout", "refimpl", out="c.pt"), 2)
    _one_line_error(capsys, main(["export-weights", str(tmp_path / "ckpt.npz"), "--out", str(tmp_path / "w.pt")]),
                    2)


def test_import_checkpoint_passes_the_schema_and_records_the_source(tmp_path):
    sd = _state("acrnn", overrides=("hidden_size=8",))
    np.savez(tmp_path / "a.npz", **sd)
    _, (train_ds, test_ds) = _datasets("acrnn")
    arrays, meta = import_checkpoint(MODELS["acrnn"], read_state_dict(tmp_path / "a.npz"), "published", train_ds,
                                     test_ds, overrides=("hidden_size=8",), dtype="float64",
                                     source=tmp_path / "a.npz")
    assert meta["format"] == "refimpl.train/1" and meta["model"] == "acrnn"
    assert meta["imported"]["source"] == "a.npz" and len(meta["imported"]["sha256"]) == 64
    assert all(a.dtype == np.float64 for a in arrays.values())
    assert meta["model_config"]["skewed"] is True and meta["model_config"]["dtype"] == "float64"
    json.dumps(meta)


# ------------------------------------------------------------------------------------------------------------
# with torch: the published architectures built in torch, state_dict saved with torch.save, imported

def test_torch_acrnn_state_dict_imports_and_generates_the_same(tmp_path):
    torch = pytest.importorskip("torch")

    _, (train_ds, _) = _datasets("acrnn")
    F = train_ds.data.frame_size

    class Published(torch.nn.Module):   # the documented architecture: three LSTMCells, skewed, linear decoder
        def __init__(self):
            super().__init__()
            self.lstm1, self.lstm2, self.lstm3 = (torch.nn.LSTMCell(F if k == 0 else H, H) for k in range(3))
            self.decoder = torch.nn.Linear(H, F)

        def forward(self, seed, n):
            B = seed.shape[0]
            h = [torch.zeros(B, H, dtype=seed.dtype) for _ in range(3)]
            c = [torch.zeros(B, H, dtype=seed.dtype) for _ in range(3)]

            def step(x):
                n1, n2, n3 = self.lstm1(x, (h[0], c[0])), self.lstm2(h[0], (h[1], c[1])), \
                    self.lstm3(h[1], (h[2], c[2]))
                for k, (hh, cc) in enumerate((n1, n2, n3)):
                    h[k], c[k] = hh, cc
                return self.decoder(h[2])

            for t in range(seed.shape[1]):
                y = step(seed[:, t])
            out = [y]
            for _ in range(n - 1):
                out.append(step(out[-1]))
            return torch.stack(out, 1)

    torch.manual_seed(0)
    net = Published()
    torch.save(net.state_dict(), tmp_path / "acrnn.pt")
    assert _import(tmp_path, tmp_path / "acrnn.pt", "acrnn", "--set", f"hidden_size={H}") == 0
    model = load_trained(tmp_path / "ckpt.npz")
    mean, std = np.asarray(model.extra["mean"]), np.asarray(model.extra["std"])
    seed = mean + std * np.random.default_rng(7).standard_normal((2, 10, F))
    with torch.no_grad():
        want = net.double()(torch.from_numpy((seed - mean) / std), 12).numpy() * std + mean
    np.testing.assert_allclose(model.spec.make_method(model)(seed, 12), want, rtol=1e-4,
                               atol=1e-5 * float(std.max()))


def test_torch_quaternet_state_dict_imports_and_predicts_the_same(tmp_path):
    torch = pytest.importorskip("torch")

    _, (train_ds, _) = _datasets("quaternet")
    spec = MODELS["quaternet"]
    J = spec.make_config(train_ds, ()).num_joints

    class Published(torch.nn.Module):   # the documented short-term QuaterNet: GRU 2 layers, h0, fc, velocities
        def __init__(self):
            super().__init__()
            self.rnn = torch.nn.GRU(4 * J, H, num_layers=2, batch_first=True)
            self.h0 = torch.nn.Parameter(torch.randn(2, 1, H) * 0.01)
            self.fc = torch.nn.Linear(H, 4 * J)

        def forward(self, x, h=None):
            h = self.h0.expand(-1, x.shape[0], -1).contiguous() if h is None else h
            out, h = self.rnn(x, h)
            pre = self.fc(out[:, -1:]).view(x.shape[0], 1, J, 4)
            xin = x[:, -1:].view(x.shape[0], 1, J, 4)
            q = torch.stack(list(map(torch.from_numpy, np.moveaxis(
                _hamilton(pre.detach().numpy(), xin.detach().numpy()), -1, 0))), -1)
            return torch.nn.functional.normalize(q, dim=-1).view(x.shape[0], 1, 4 * J), h

    torch.manual_seed(1)
    net = Published().double()
    torch.save(net.state_dict(), tmp_path / "q.pt")
    assert _import(tmp_path, tmp_path / "q.pt", "quaternet", "--set", f"hidden_size={H}",
                   "--dtype", "float64") == 0
    model = load_trained(tmp_path / "ckpt.npz")
    q = np.random.default_rng(8).standard_normal((2, 6, J, 4))
    prefix = q / np.linalg.norm(q, axis=-1, keepdims=True)
    with torch.no_grad():
        y, h = net(torch.from_numpy(prefix.reshape(2, 6, -1)))
        outs = [y]
        for _ in range(4):
            y, h = net(y, h)
            outs.append(y)
    want = torch.cat(outs, 1).numpy().reshape(2, 5, J, 4)
    np.testing.assert_allclose(model.spec.recipe.reference_outputs(model, prefix, 5), want, atol=1e-12)


class _Pickled:
    """An arbitrary class: only a full unpickler could rebuild it; torch's weights_only loader refuses it."""


def test_torch_files_need_torch_and_are_never_unpickled(tmp_path, capsys, monkeypatch):
    torch = pytest.importorskip("torch")
    sd = _state("acrnn", overrides=("hidden_size=8",))
    torch.save({"decoder.bias": torch.zeros(3), "evil": _Pickled()}, tmp_path / "bad.pt")
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "bad.pt", "acrnn"), 3)
    assert "weights_only" in err
    torch.save({k: torch.from_numpy(v) for k, v in sd.items()}, tmp_path / "ok.pt")
    monkeypatch.setitem(__import__("sys").modules, "torch", None)   # as if torch were not installed
    err = _one_line_error(capsys, _import(tmp_path, tmp_path / "ok.pt", "acrnn"), 1)
    assert "needs torch" in err and ".safetensors" in err
