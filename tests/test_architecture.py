"""The import graph of refimpl and deploy (spec/architecture.md §layers): no upward import, no cycle, no module
importing another module's underscore names, and ``deploy`` imported only lazily by the top layer."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Layer of each refimpl module (spec/architecture.md); a module imports only from its own layer or below.
#: Modules not listed (new ones) must be added here: the test fails until they are.
LAYERS = {
    0: ["refimpl", "refimpl._parsing", "refimpl.arrays", "refimpl.atomic", "refimpl.datacache", "refimpl.testing", "refimpl.gradcheck",
        "refimpl.bounds", "refimpl.versions", "refimpl.files", "refimpl.npy_files", "refimpl.progress"],
    1: ["refimpl.quat", "refimpl.rotations", "refimpl.dualquat"],
    2: ["refimpl.skeleton", "refimpl.current_dq", "refimpl.mirroring", "refimpl.bone_ik"],
    3: ["refimpl.motion", "refimpl.bvh", "refimpl.bvh_write", "refimpl.expmap", "refimpl.skeletons",
        "refimpl.preprocess", "refimpl.representations", "refimpl.strategies", "refimpl.splines", "refimpl.augment"],
    4: ["refimpl.nn", "refimpl.nn.*", "refimpl.losses", "refimpl.dq_output", "refimpl.dq_output_fast", "refimpl.dq_prediction",
        "refimpl.schedules"],
    # 4.5: the generic training machinery and the checkpoint schema, below every model (they name none)
    4.5: ["refimpl.optim", "refimpl.checkpoint", "refimpl.checkpoint_fields", "refimpl.checkpoint_schema",
          "refimpl.safetensors", "refimpl.train", "refimpl.train_files"],
    5: ["refimpl.models", "refimpl.models.*"],
    6: ["refimpl.rigs", "refimpl.protocols", "refimpl.protocols.*"],
    7: ["refimpl.errors", "refimpl.options", "refimpl.render", "refimpl.render_kernel", "refimpl.render_strip", "refimpl.tasks",
        "refimpl.tasks.*", "refimpl.recipes", "refimpl.recipes.*", "refimpl.registry", "refimpl.services",
        "refimpl.allocator", "refimpl.weights", "refimpl.task_api", "refimpl.recipe_api", "refimpl.run_options",
        "refimpl.threads", "refimpl.pretrained"],
    8: ["refimpl.cli", "refimpl.cli_info", "refimpl.weights_cli", "refimpl.cache_cli", "refimpl.demo", "refimpl.__main__"],
}
#: The only refimpl modules that may import deploy, and only inside functions (lazily).
DEPLOY_IMPORTERS = {"refimpl.cli", "refimpl.demo", "refimpl.services"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _sources(package: str):
    return {_module_name(p): p for p in sorted((ROOT / package).rglob("*.py"))}


def _is_module(name: str) -> bool:
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _layer(module: str) -> int | None:
    for layer, patterns in LAYERS.items():
        for pat in patterns:
            if module == pat or (pat.endswith(".*") and module.startswith(pat[:-1])):
                return layer
    return None


def _imports(module: str, path: Path):
    """``(target module, imported names, top-level?)`` for every import of package modules in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    top = set(map(id, tree.body))
    pkg = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, (), id(node) in top) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = pkg.split(".")[:len(pkg.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names = tuple(a.name for a in node.names)
            out.append((base, names, id(node) in top))
            # "from package import submodule" imports the submodule
            out += [(f"{base}.{n}", (), id(node) in top) for n in names if _is_module(f"{base}.{n}")]
    return [(t, n, lvl) for t, n, lvl in out if t.split(".")[0] in ("refimpl", "deploy")]


def _graph(packages=("refimpl", "deploy")):
    mods = {}
    for pkg in packages:
        mods.update(_sources(pkg))
    edges = {m: set() for m in mods}
    for m, p in mods.items():
        for target, _, _ in _imports(m, p):  # lazy (function-level) imports count: a loop is a loop
            if target in mods and target != m:
                edges[m].add(target)
    return mods, edges


def test_every_refimpl_module_has_a_layer():
    missing = [m for m in _sources("refimpl") if _layer(m) is None]
    assert not missing, f"add these modules to LAYERS (and to spec/architecture.md): {missing}"


def test_no_upward_import_in_refimpl():
    bad = []
    for m, p in _sources("refimpl").items():
        if m in ("refimpl", "refimpl.nn", "refimpl.models"):  # packages re-export their own modules
            continue
        for target, _, _ in _imports(m, p):
            if not target.startswith("refimpl") or _layer(target) is None:
                continue
            if _layer(target) > _layer(m):
                bad.append(f"{m} (layer {_layer(m)}) imports {target} (layer {_layer(target)})")
    assert not bad, "\n".join(bad)


def test_deploy_is_imported_only_lazily_by_the_top_layer():
    bad = []
    for m, p in _sources("refimpl").items():
        for target, _, toplevel in _imports(m, p):
            if target.split(".")[0] == "deploy" and (toplevel or m not in DEPLOY_IMPORTERS):
                bad.append(f"{m} imports {target}" + (" at module level" if toplevel else ""))
    assert not bad, "\n".join(bad)


#: deploy's command layer (``python -m deploy``): reads clips, checkpoints and options as ``refimpl``'s
#: application layer does, so it may import layer 7 (tasks, recipes, services, errors, registry), inside functions.
DEPLOY_COMMANDS = {"deploy.cli", "deploy.models.qtg_cli", "deploy.models.run_commands",
                   "deploy.models.quaternet_long_walk", "deploy.serve"}


def test_deploy_imports_only_lower_refimpl_layers():
    bad = [f"{m} imports {t}" for m, p in _sources("deploy").items() for t, _, top in _imports(m, p)
           if t.startswith("refimpl") and (_layer(t) or 0) > (7 if m in DEPLOY_COMMANDS else 6)]
    bad += [f"{m} imports {t} at module level" for m, p in _sources("deploy").items() if m in DEPLOY_COMMANDS
            for t, _, top in _imports(m, p) if t.startswith("refimpl") and top and (_layer(t) or 0) > 6]
    assert not bad, "\n".join(bad)


def test_no_import_cycle():
    mods, edges = _graph()
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(edges[m]):
            if state.get(t) == 1:
                cycles.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(mods):
        if m not in state:
            visit(m)
    # a package's __init__ importing its own modules, and those importing package siblings, is not a cycle of
    # modules: drop cycles through a package module
    real = [c for c in cycles if not any(x in ("refimpl", "deploy", "refimpl.nn", "refimpl.models") for x in c)]
    assert not real, "\n".join(" -> ".join(c) for c in real)


def test_no_cross_module_underscore_imports():
    bad = []
    for pkg in ("refimpl", "deploy"):
        for m, p in _sources(pkg).items():
            for target, names, _ in _imports(m, p):
                if target.split(".")[0] != pkg and target.split(".")[0] not in ("refimpl", "deploy"):
                    continue
                bad += [f"{m}: from {target} import {n}" for n in names
                        if n.startswith("_") and not n.startswith("__") and target != m]
    assert not bad, "\n".join(bad)


#: Longest function of ``refimpl`` in lines, its docstring not counted (spec/architecture.md: one screen).
MAX_FUNCTION_LINES = 80


def test_no_refimpl_function_is_longer_than_a_screen():
    long = []
    for m, p in _sources("refimpl").items():
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = node.body[0]
                doc = (first.end_lineno - first.lineno + 1 if isinstance(first, ast.Expr)
                       and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str) else 0)
                n = node.end_lineno - node.lineno + 1 - doc
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{m}.{node.name} (line {node.lineno}): {n} lines")
    assert not long, "split these functions (one screen each):\n" + "\n".join(long)


def test_no_recipe_imports_a_task():
    """A recipe knows its network and its task's protocol, never the task module (not even inside a function):
    the tasks call the services, which import the registry, which imports every recipe."""
    bad = [f"{m} imports {t}" for m, p in _sources("refimpl").items() if m.startswith("refimpl.recipes.")
           for t, _, _ in _imports(m, p) if t == "refimpl.tasks" or t.startswith("refimpl.tasks.")]
    assert not bad, "\n".join(bad)
