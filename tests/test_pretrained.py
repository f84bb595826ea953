"""Shipped trained models (refimpl/pretrained.py, spec/cli.md §10, issue 32): loadable by name, checked by their
checksum, and each card's numbers reproduced by its own evaluation command.

The per-model checks re-run ``evaluation.eval_sample`` (the embedded sample) always and ``evaluation.eval`` (the
real data) when ``../shared/data`` is present; the numbers must equal the card's ``eval*.json`` bit for bit when
the library versions are the card's, else within the card's relative tolerance (``evaluation.tolerance``).
"""
from __future__ import annotations

import json
import os
import shlex
from pathlib import Path

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint, save_checkpoint
from refimpl.cli import EXIT_BAD_INPUT, main
from refimpl.errors import BadInputError
from refimpl.pretrained import CARD_FIELDS, PREFIX, catalogue, resolve_checkpoint, sha256_of, weights_only
from refimpl.services import load_trained

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "pretrained"
SHARED = ROOT.parent / "shared" / "data"
NAMES = sorted(p.parent.name for p in SHIPPED.glob("*/card.json"))
WALK = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"


def _numbers(x, path="") -> dict:
    """Every number of a JSON value by its path."""
    if isinstance(x, dict):
        return {k: v for key, val in x.items() for k, v in _numbers(val, f"{path}/{key}").items()}
    if isinstance(x, list):
        return {k: v for i, val in enumerate(x) for k, v in _numbers(val, f"{path}[{i}]").items()}
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return {path: float(x)}
    return {}


def _same_versions(card: dict) -> bool:
    import experiments.pretrained as ep

    now = ep.library_versions()
    return all(card["versions"].get(k) == now.get(k) for k in card["evaluation"]["tolerance"]["versions_compared"])


# ------------------------------------------------------------------------------------------------------------
# the mechanism, on a model made here


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    """A shipped-model root with one tiny QTG (trained 2 steps on the sample), its card filled by hand."""
    root = tmp_path_factory.mktemp("shipped")
    run = root / "run"
    assert main(["--blas-threads", "1", "train", "--data", str(WALK), "--steps", "2", "--set", "encoder_sizes=8,8",
                 "--set", "gru_hidden=8", "--set", "decoder_sizes=8", "--out", str(run)]) == 0
    arrays, meta = load_checkpoint(run / "checkpoint.npz")
    kept, kept_meta = weights_only(arrays, meta)
    folder = root / "tiny-qtg"
    folder.mkdir()
    save_checkpoint(folder / "model.npz", kept, kept_meta)
    card = {f: {} for f in CARD_FIELDS}
    card.update(name="tiny-qtg", title="a tiny QTG", system="QTG", model="qtg", file="model.npz",
                sha256=sha256_of(folder / "model.npz"), size_bytes=(folder / "model.npz").stat().st_size,
                parameters=int(sum(a.size for a in kept.values())), licence={"weights": "MIT: test"})
    (folder / "card.json").write_text(json.dumps(card))
    return root, run


@pytest.fixture
def shipped_env(tiny_root, monkeypatch):
    monkeypatch.setenv("REFIMPL_PRETRAINED", str(tiny_root[0]))
    return tiny_root


def test_weights_only_loads_like_the_checkpoint(tiny_root):
    root, run = tiny_root
    full, small = load_trained(run / "checkpoint.npz"), load_trained(root / "tiny-qtg" / "model.npz")
    assert full.spec.name == small.spec.name and full.config == small.config and full.fields.keys() == small.fields.keys()
    for k in full.params:
        np.testing.assert_array_equal(full.params[k], small.params[k])
    arrays, meta = load_checkpoint(root / "tiny-qtg" / "model.npz")
    assert all(k.startswith("param.") for k in arrays)
    assert not {"rng_state", "train_config", "position"} & set(meta)
    with pytest.raises(ValueError, match="param"):
        weights_only({"optim.step": np.zeros(())}, {})


def test_resolve_by_name(shipped_env):
    assert resolve_checkpoint(PREFIX + "tiny-qtg") == shipped_env[0] / "tiny-qtg" / "model.npz"
    assert resolve_checkpoint("some/path.npz") == Path("some/path.npz")      # plain paths untouched
    assert "tiny-qtg" in catalogue()
    with pytest.raises(BadInputError, match="no such shipped model"):
        resolve_checkpoint(PREFIX + "nope")


@pytest.mark.parametrize("argv", [["info", "{m}"], ["eval", "--checkpoint", "{m}", "--stride", "16"],
                                  ["generate", "--checkpoint", "{m}", "--source", str(WALK), "--source-frame", "30",
                                   "--out", "{tmp}/t.bvh"]])
def test_commands_take_a_name(shipped_env, tmp_path, capsys, argv):
    argv = [a.format(m=PREFIX + "tiny-qtg", tmp=tmp_path) for a in argv]
    assert main(argv) == 0, capsys.readouterr().err


def test_export_of_a_name_defaults_outside_the_repository(shipped_env, tmp_path, monkeypatch):
    pytest.importorskip("onnxruntime")
    monkeypatch.chdir(tmp_path)
    assert main(["export", "--checkpoint", PREFIX + "tiny-qtg"]) == 0
    assert (tmp_path / "onnx" / "tiny-qtg" / "qtg_rollout.onnx").is_file()
    assert not (shipped_env[0] / "tiny-qtg" / "onnx").exists()


def test_damaged_missing_or_unknown_is_exit_3(shipped_env, tmp_path, capsys):
    root = shipped_env[0]
    bad = tmp_path / "bad"
    (bad / "tiny-qtg").mkdir(parents=True)
    data = bytearray((root / "tiny-qtg" / "model.npz").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (bad / "tiny-qtg" / "model.npz").write_bytes(bytes(data))
    (bad / "tiny-qtg" / "card.json").write_text((root / "tiny-qtg" / "card.json").read_text())
    os.environ["REFIMPL_PRETRAINED"] = str(bad)
    assert main(["info", PREFIX + "tiny-qtg"]) == EXIT_BAD_INPUT
    assert "damaged or replaced" in capsys.readouterr().err
    (bad / "tiny-qtg" / "model.npz").unlink()
    assert main(["eval", "--checkpoint", PREFIX + "tiny-qtg"]) == EXIT_BAD_INPUT
    assert "missing" in capsys.readouterr().err
    assert main(["export", "--checkpoint", PREFIX + "nope"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no such shipped model" in err
    (bad / "tiny-qtg" / "card.json").write_text("[1, 2]")
    assert main(["pretrained"]) == EXIT_BAD_INPUT
    assert "JSON object" in capsys.readouterr().err


def test_pretrained_command_lists_and_shows(shipped_env, capsys):
    assert main(["pretrained"]) == 0
    assert "pretrained:tiny-qtg" in capsys.readouterr().out
    assert main(["pretrained", "tiny-qtg", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["name"] == "tiny-qtg"
    assert main(["pretrained", "nope"]) == EXIT_BAD_INPUT


def test_deploy_export_takes_a_name(shipped_env, tmp_path):
    pytest.importorskip("onnxruntime")
    from deploy.cli import main as deploy_main

    assert deploy_main(["export", PREFIX + "tiny-qtg", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o" / "qtg_rollout.onnx").is_file()
    assert deploy_main(["export", PREFIX + "nope", str(tmp_path / "p")]) == 3


# ------------------------------------------------------------------------------------------------------------
# the shipped models themselves


def test_the_repository_ships_a_model_per_system():
    systems = {json.loads((SHIPPED / n / "card.json").read_text())["model"] for n in NAMES}
    assert systems >= {"qtg", "quaternet", "quaternet-long", "pace", "acrnn"}, systems


def test_all_shipped_models_fit_the_budget():
    assert sum((SHIPPED / n / "model.npz").stat().st_size for n in NAMES) <= 60e6


@pytest.mark.parametrize("name", NAMES)
def test_shipped_card_and_file(name, monkeypatch):
    monkeypatch.delenv("REFIMPL_PRETRAINED", raising=False)
    card = json.loads((SHIPPED / name / "card.json").read_text())
    assert set(CARD_FIELDS) <= set(card)
    assert sha256_of(SHIPPED / name / card["file"]) == card["sha256"]
    assert (SHIPPED / name / card["file"]).stat().st_size == card["size_bytes"]
    model = load_trained(PREFIX + name)
    assert model.spec.name == card["model"]
    assert sum(a.size for a in model.params.values()) == card["parameters"]
    if "Bandai Namco" in card["data"]["name"]:
        assert "CC BY-NC 4.0" in card["licence"]["weights"] and "CC BY-NC 4.0" in card["data"]["licence"]
    assert (SHIPPED / name / "card.md").is_file()


def _reevaluate(name: str, which: str, tmp_path: Path, monkeypatch):
    import experiments.pretrained as ep

    monkeypatch.delenv("REFIMPL_PRETRAINED", raising=False)
    card = json.loads((SHIPPED / name / "card.json").read_text())
    if which not in card["evaluation"]:
        pytest.skip(f"{name}: no {which} on its card")
    entry = card["evaluation"][which]
    argv = shlex.split(entry["command"])
    argv = argv[:argv.index("--json")]
    got = _numbers(ep.run_eval(argv, tmp_path / "e.json"))
    want = _numbers(json.loads((SHIPPED / name / entry["results_file"]).read_text()))
    assert got.keys() == want.keys()
    tol = card["evaluation"]["tolerance"]["same_versions" if _same_versions(card) else "other_versions"]
    bad = {k: (got[k], want[k]) for k in want
           if not np.isclose(got[k], want[k], rtol=tol["rtol"], atol=tol["atol"]) and not (
               np.isnan(got[k]) and np.isnan(want[k]))}
    assert not bad, f"{name}: {len(bad)} numbers differ from the card, e.g. {list(bad.items())[:3]}"


@pytest.mark.parametrize("name", NAMES)
def test_card_numbers_reproduce_on_the_sample(name, tmp_path, monkeypatch):
    _reevaluate(name, "eval_sample", tmp_path, monkeypatch)


@pytest.mark.shared
@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_card_numbers_reproduce_on_the_real_data(name, tmp_path, monkeypatch):
    if not SHARED.is_dir():
        pytest.skip("../shared/data is absent")
    _reevaluate(name, "eval", tmp_path, monkeypatch)
