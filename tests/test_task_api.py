"""The application's seams (spec/architecture.md §the application): a model is a recipe and a registry line, a
task a module implementing :class:`refimpl.task_api.Task`, and ``refimpl/cli.py`` / ``refimpl/services.py`` know
neither.

The guard tests register a toy model (a linear map ``y = x W`` fitted by least squares: a recipe, an exporter
entry) and a toy task from this file (monkeypatching the registry's tables and deploy's exporter table) and run
``train``, ``eval`` and ``generate`` through :func:`refimpl.cli.main`, then (the ONNX half, a test of its own that
alone is skipped without onnx) ``export``, ``eval --onnx`` and ``python -m deploy export | run | info``: if the
command line, the services or deploy's commands still named a model or a task, or reached past the interfaces
(task, recipe, exporter entry), the toy could not go through them. The word check reads ``cli.py``,
``services.py``, ``train.py`` and the checkpoint schema, compound names included (``transition_length``).
"""
from __future__ import annotations

import ast
import dataclasses
import json
import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from refimpl import registry
from refimpl.checkpoint_fields import TaskSchema, positive_int
from refimpl.cli import main
from refimpl.task_api import TASK_MEMBERS, Task, check_task
from refimpl.train import ModelAdapter, OptimConfig

ROOT = Path(__file__).resolve().parents[1]
TOY_A = np.array([[1.0, -2.0], [0.5, 3.0], [-1.5, 0.25]])  # (3, 2): the toy data's true map


# ----------------------------------------------------------------------------------------------------------------
# the toy task: rows x (3,) -> y = x A (2,); metric mean |f(x) - y|; baseline "zero"
# ----------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ToyData:
    x: np.ndarray  # (N, 3)
    y: np.ndarray  # (N, 2)
    fps: float = 1.0


def _toy_data(n: int, seed: int) -> ToyData:
    x = np.random.default_rng(seed).standard_normal((n, 3))
    return ToyData(x, x @ TOY_A)


def _toy_task_module() -> types.ModuleType:
    t = types.ModuleType("toy_task_for_tests")
    t.NAME = "toy"
    t.EVAL_SUMMARY = "toy: mean |f(x) - y| on held-out rows, against zero"
    t.GENERATE_USAGE = "refimpl generate --model toy-linear (toy)"
    t.CHECKPOINT_SCHEMA = TaskSchema("toy", fields={"rows": positive_int})
    t.add_train_options = lambda parser: parser.add_argument("--toy-rows", type=int, default=64)
    t.add_eval_options = lambda parser: None
    t.add_export_options = lambda parser: None
    t.add_generate_options = lambda parser: None
    t.train_datasets = lambda args: (_toy_data(args.toy_rows, 1), _toy_data(32, 2))
    t.import_datasets = t.train_datasets
    t.num_examples = lambda ds: len(ds.x)
    t.describe_data = lambda train, test: f"toy rows: {len(train.x)} / {len(test.x)}"
    t.checkpoint_extra = lambda train_ds: {"rows": len(train_ds.x)}
    t.check_checkpoint = lambda model_config, path: None
    t.trained_fields = lambda model_config, config: {"fps": 1.0, "fields": {"rows": model_config["rows"]}}
    t.onnx_method = lambda runtime: runtime.run
    t.methods = lambda networks=None, *, fps=None: {**dict(networks or {}), "zero": lambda x: np.zeros((len(x), 2))}
    t.evaluate = lambda ds, methods: {k: float(np.abs(f(ds.x) - ds.y).mean()) for k, f in methods.items()}

    def eval_command(args, model):
        from refimpl.services import evaluate_model

        results = evaluate_model(model, _toy_data(32, 2), onnx_dir=args.onnx, task="toy")
        Path(args.json).write_text(json.dumps(results))
        return 0

    def generate_command(args, model):
        from refimpl.services import checkpoint_for

        model = checkpoint_for("toy", model, args.checkpoint)
        x = _toy_data(args.length or 5, 3).x
        np.save(args.out, model.spec.make_method(model)(x), allow_pickle=False)
        return 0

    t.eval_command = eval_command
    t.generate_command = generate_command
    t.export_options = lambda args: {}
    t.verify_inputs = lambda args, model: ((np.random.default_rng(args.seed).standard_normal((4, 3)),), {})
    return t


# ----------------------------------------------------------------------------------------------------------------
# the toy recipe and its exporter
# ----------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ToyConfig:
    inputs: int = 3
    outputs: int = 2


def _toy_recipe_module() -> types.ModuleType:
    r = types.ModuleType("toy_recipe_for_tests")
    r.NAME, r.SUMMARY, r.TASK = "toy-linear", "y = x W (tests only)", "toy"
    r.REPRESENTATIONS, r.CONFIG_TYPE, r.EXPORTER = ("rows",), ToyConfig, "toy-linear"
    r.PAPER_OPTIM, r.PAPER_BATCH = OptimConfig(lr=0.05), 16
    r.make_config = lambda train_ds, overrides: ToyConfig()
    r.param_shapes = lambda config: {"weight": (config.inputs, config.outputs)}

    def make_adapter(train_ds, val_ds, config, dtype, extra):
        def loss_and_grads(params, batch):
            x, y = batch
            err = x @ params["weight"] - y                                    # (B, 2)
            return float((err ** 2).mean()), {"weight": (2.0 / err.size) * (x.T @ err).astype(dtype)}

        return ModelAdapter(
            name="toy-linear", num_examples=len(train_ds.x),
            init_params=lambda rng: {"weight": np.zeros((config.inputs, config.outputs), dtype)},
            get_batch=lambda idx, ctx: (train_ds.x[idx].astype(dtype), train_ds.y[idx].astype(dtype)),
            loss_and_grads=loss_and_grads,
            config=dict(dataclasses.asdict(config), dtype=np.dtype(dtype).name, **extra))

    r.make_adapter = make_adapter
    r.make_method = lambda model: (lambda x: np.asarray(x) @ model.params["weight"].astype(np.float64))

    def verify_onnx(model, runtime, x):
        diff = float(np.abs(runtime.run(x) - x @ model.params["weight"]).max())
        return {"step": diff, "ok": diff < 1e-5}

    r.verify_onnx = verify_onnx
    return r


def _toy_exporter_module() -> types.ModuleType:
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    e = types.ModuleType("toy_exporter_for_tests")

    def export_dir(params, config, out_dir, *, dtype=np.float32, mode="unrolled"):
        w = numpy_helper.from_array(np.asarray(params["weight"], np.float32), "weight")
        graph = helper.make_graph([helper.make_node("MatMul", ["x", "weight"], ["y"])], "toy_linear",
                                  [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["B", config.inputs])],
                                  [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["B", config.outputs])],
                                  [w])
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
        meta = {"format": "refimpl.deploy/1", "model": {"name": "toy-linear", "role": "step",
                                                        "config": dataclasses.asdict(config)},
                "io": {"inputs": [{"name": "x"}], "outputs": [{"name": "y"}]}, "representation": {"name": "rows"},
                "normalization": None, "skeleton": None, "exporter": {"name": "toy"}, "frame_rate": 1.0,
                "source_paper": ""}  # every key of deploy's metadata contract (deploy/metadata.py)
        helper.set_model_props(model, {k: json.dumps(v) for k, v in meta.items()})
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / "toy-linear_step.onnx"
        onnx.save(model, str(path))
        return {"step": path}

    class Runtime:
        def __init__(self, path):
            import onnxruntime

            self.session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])

        @classmethod
        def from_dir(cls, directory, intra_op_threads: int = 1):
            return cls(Path(directory) / "toy-linear_step.onnx")

        def run(self, x):
            return self.session.run(None, {"x": np.asarray(x, np.float32)})[0].astype(np.float64)

    def load_checkpoint(path):
        from deploy.models.entry_io import checked_params, checkpoint_params, config_from_meta, read_checkpoint

        arrays, meta = read_checkpoint(path)
        config = config_from_meta(ToyConfig, meta, where=str(path))
        return checked_params(checkpoint_params(arrays), config, str(path)), config, meta

    def run_command(runtime, args):
        from deploy.models.entry_io import write_npy

        write_npy(args.output, runtime.run(np.load(args.input, allow_pickle=False)))
        return 0

    e.load_checkpoint, e.export_dir, e.Runtime, e.run_command = load_checkpoint, export_dir, Runtime, run_command
    return e


@pytest.fixture()
def toy(monkeypatch):
    """The toy task, model and exporter registered for one test (the tables restored afterwards)."""
    task, recipe = _toy_task_module(), _toy_recipe_module()
    monkeypatch.setitem(sys.modules, task.__name__, task)
    monkeypatch.setitem(registry.TASKS, "toy", task.__name__)
    monkeypatch.setitem(registry.RECIPES, "toy-linear", (recipe.__name__, "toy"))
    monkeypatch.setitem(registry.MODELS, "toy-linear", registry.ModelSpec.from_recipe(recipe, "toy"))
    try:
        import deploy.models
    except ImportError:
        deploy = None
    else:
        exporter = _toy_exporter_module()
        monkeypatch.setitem(sys.modules, exporter.__name__, exporter)
        monkeypatch.setitem(deploy.models.EXPORTERS, "toy-linear", exporter.__name__)
    return deploy


def _toy_trained(tmp_path, capsys) -> Path:
    out = tmp_path / "run"
    assert main(["--blas-threads", "1", "train", "--model", "toy-linear", "--out", str(out), "--steps", "150",
                 "--toy-rows", "48", "--progress-every", "50"]) == 0
    assert "toy rows: 48 / 32" in capsys.readouterr().out
    return out / "checkpoint.npz"


def test_a_toy_model_and_task_go_through_the_command_line(toy, tmp_path, capsys):
    """train, eval and generate of a model and task registered from this file (NumPy only)."""
    ckpt = _toy_trained(tmp_path, capsys)
    js = tmp_path / "eval.json"
    assert main(["eval", "--checkpoint", str(ckpt), "--json", str(js)]) == 0
    got = json.loads(js.read_text())
    from refimpl.services import load_trained

    model = load_trained(ckpt)
    assert model.spec.name == "toy-linear" and model.fields == {"rows": 48}
    data = _toy_data(32, 2)
    assert got["toy-linear"] == pytest.approx(float(np.abs(data.x @ model.params["weight"] - data.y).mean()),
                                              rel=1e-12)
    assert got["toy-linear"] < 0.2 * got["zero"]  # trained: the least-squares fit beats the zero baseline
    gen = tmp_path / "gen.npy"
    assert main(["generate", "--model", "toy-linear", "--checkpoint", str(ckpt), "--length", "7",
                 "--out", str(gen)]) == 0
    np.testing.assert_allclose(np.load(gen), _toy_data(7, 3).x @ model.params["weight"], rtol=1e-12)


def test_a_toy_model_exports_and_runs_through_refimpl_and_deploy(toy, tmp_path, capsys):
    """export (verified), eval --onnx, and ``python -m deploy export | run | info`` of the toy model (the ONNX half:
    skipped alone when onnx is missing)."""
    if toy is None:
        pytest.skip("deploy (onnx) is not installed: export not exercised")
    from deploy.cli import main as deploy_main
    from refimpl.services import load_trained

    ckpt = _toy_trained(tmp_path, capsys)
    weight = load_trained(ckpt).params["weight"]
    assert main(["export", "--checkpoint", str(ckpt), "--out", str(tmp_path / "onnx")]) == 0
    text = capsys.readouterr().out
    assert "toy-linear_step.onnx" in text and "onnxruntime vs NumPy (step)" in text
    js = tmp_path / "eval.json"
    assert main(["eval", "--checkpoint", str(ckpt), "--onnx", str(tmp_path / "onnx"), "--json", str(js)]) == 0
    got = json.loads(js.read_text())
    assert got["toy-linear_onnx"] == pytest.approx(got["toy-linear"], abs=1e-5)
    folder = tmp_path / "deployed"
    assert deploy_main(["export", str(ckpt), str(folder)]) == 0
    assert (folder / "toy-linear_step.onnx").read_bytes() == \
        (tmp_path / "onnx" / "toy-linear_step.onnx").read_bytes()  # the same export as refimpl's
    x = _toy_data(6, 4).x
    np.save(tmp_path / "x.npy", x)
    assert deploy_main(["run", str(folder), str(tmp_path / "x.npy"), str(tmp_path / "y.npy")]) == 0
    np.testing.assert_allclose(np.load(tmp_path / "y.npy"), x @ weight, atol=1e-5)
    capsys.readouterr()
    assert deploy_main(["info", str(folder / "toy-linear_step.onnx")]) == 0
    info = capsys.readouterr().out
    assert "inputs:" in info and "x ('B', 3)" in info and "y ('B', 2)" in info and "toy-linear" in info


def test_every_registered_task_implements_the_interface():
    for name in registry.TASKS:
        module = registry.task_of(name)
        assert isinstance(module, Task) and module.NAME == name
    spec = {n: registry.MODELS[n] for n in registry.MODELS}
    text = (ROOT / "deploy" / "models" / "__init__.py").read_text(encoding="utf-8")
    for name, s in spec.items():  # a recipe's exporter is a line of deploy's table
        assert s.exporter is None or f'"{s.exporter}":' in text, name


def test_a_module_lacking_a_member_is_refused():
    task = _toy_task_module()
    assert check_task(task) is task
    del task.verify_inputs
    with pytest.raises(TypeError, match="verify_inputs"):
        check_task(task)
    assert "verify_inputs" in TASK_MEMBERS and "eval_command" in TASK_MEMBERS


def _words(path: Path) -> set[str]:
    """Every identifier and every word of every string in ``path``, and every part of a compound one
    (``transition_length`` -> ``transition``, ``length``), except keyword-argument names (API parameters of other
    modules, e.g. ``render_strip(..., prediction=...)``) and citations of the spec (``spec/qtg.md §10``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):  # a spec citation names no model
            out |= set(re.findall(r"[A-Za-z][A-Za-z0-9_-]*", re.sub(r"spec/[\w.-]+\.md", "", node.value.lower())))
        elif isinstance(node, ast.Name):
            out.add(node.id.lower())
        elif isinstance(node, ast.Attribute):
            out.add(node.attr.lower())
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name.lower())
        elif isinstance(node, ast.alias):
            out |= set((node.asname or node.name).lower().split("."))
        elif isinstance(node, ast.arg):
            out.add(node.arg.lower())
    return out | {part for word in out for part in re.split(r"[_-]+", word) if part}


#: The modules that name no model and no task: the command line, the services, the generic trainer and the
#: checkpoint schema (spec/architecture.md).
GENERIC = ["refimpl/cli.py", "refimpl/services.py", "refimpl/train.py", "refimpl/checkpoint_schema.py",
           "refimpl/checkpoint_fields.py"]


def test_the_word_check_sees_compound_names(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("def f(args):\n    return args.transition_length, 'quaternet-long_step.onnx'\n")
    words = _words(probe)
    assert {"transition", "length", "quaternet", "long", "step"} <= words and "transition_length" in words


@pytest.mark.parametrize("module", GENERIC)
def test_the_command_line_and_the_services_name_no_model_and_no_task(module):
    names = {n.lower() for n in (*registry.MODELS, *registry.TASKS)}
    names |= {n.replace("-", "_") for n in names}
    found = sorted(_words(ROOT / module) & names)
    assert not found, f"{module} names {found}: move that code into the task or the recipe"


def test_every_exporter_entry_implements_the_entry_interface():
    """deploy.models.entry_api: every entry of the exporter table defines the protocol's names itself; a module
    lacking one is refused when the table hands it out."""
    models = pytest.importorskip("deploy.models")
    from deploy.models.entry_api import ENTRY_MEMBERS, OPTIONAL_MEMBERS, ExporterEntry, check_entry

    assert set(ENTRY_MEMBERS) == {"Runtime", "export_dir", "load_checkpoint", "run_command"}
    for name in models.EXPORTERS:
        entry = models.exporter(name)
        assert isinstance(entry, ExporterEntry), name
        src = Path(entry.__file__).read_text(encoding="utf-8")
        for member in ENTRY_MEMBERS:  # defined under its own name, not an alias line
            assert re.search(rf"^(def|class) {member}\b", src, re.M) or f"import {member}" in src \
                or re.search(rf"import \([^)]*\b{member}\b", src), (name, member)
            assert not re.search(rf"^{member} = ", src, re.M), (name, member)
    broken = types.ModuleType("broken_entry")
    broken.export_dir, broken.Runtime = (lambda *a, **k: {}), type("R", (), {"from_dir": classmethod(lambda c, d: c)})
    with pytest.raises(TypeError, match="load_checkpoint"):
        check_entry(broken)
    broken.load_checkpoint = broken.run_command = lambda *a: None
    assert check_entry(broken) is broken
    broken.add_run_options = "not callable"
    with pytest.raises(TypeError, match="add_run_options"):
        check_entry(broken)
    assert "export_checkpoint" in OPTIONAL_MEMBERS


def test_every_recipe_implements_the_recipe_interface_and_a_broken_one_is_refused():
    """refimpl.recipe_api: the registry checks each recipe and reads its optional names once into the ModelSpec."""
    from refimpl.recipe_api import OPTIONAL_MEMBERS, RECIPE_MEMBERS, Recipe, check_recipe, optional_members

    for name, spec in registry.MODELS.items():
        assert isinstance(spec.recipe, Recipe) and check_recipe(spec.recipe, spec.task) is spec.recipe
        opt = optional_members(spec.recipe)
        assert spec.exporter == opt["EXPORTER"] and spec.published_names is opt["published_names"], name
        assert spec.published_settings == tuple(opt["PUBLISHED_SETTINGS"]) and set(opt) == set(OPTIONAL_MEMBERS)
    recipe = _toy_recipe_module()
    assert optional_members(recipe)["IMPORT_HINT"] == "" and optional_members(recipe)["param_shapes"] is not None
    with pytest.raises(ValueError, match="registered as"):
        check_recipe(recipe, "transition")
    recipe.verify_onnx = "not callable"
    with pytest.raises(TypeError, match="verify_onnx"):
        check_recipe(recipe)
    del recipe.make_method
    with pytest.raises(TypeError, match="make_method"):
        registry.ModelSpec.from_recipe(recipe, "toy")
    assert "make_adapter" in RECIPE_MEMBERS and "PAPER_BATCH" in RECIPE_MEMBERS
