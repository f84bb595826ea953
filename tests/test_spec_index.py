"""spec/index.md stays true: every module, function, class or constant its "function" column names must import.

A cell names code in backticks. A dotted name starting with ``refimpl.`` or ``deploy.`` is resolved as written
(call arguments such as ``(q, "zyx")`` are ignored); a name starting with ``nn.`` or ``models.`` is one below
``refimpl``; a bare name (``init_params``, ``QuaterNetConfig.long_term()``) belongs to the module of the last
dotted name before it in the same cell (``refimpl.models.acrnn.ACRNNConfig``, ``init_params`` →
``refimpl.models.acrnn.init_params``).
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

INDEX = Path(__file__).resolve().parents[1] / "spec" / "index.md"
_NAME = re.compile(r"^([A-Za-z_][\w.]*)(\(.*\))?$")
_PACKAGES = ("refimpl", "deploy")


def _rows() -> list[tuple[int, str]]:
    """(line number, function cell) of every table row of the index (header and rule rows skipped)."""
    rows = []
    for n, line in enumerate(INDEX.read_text(encoding="utf-8").splitlines(), 1):
        cells = [c.strip() for c in line.split("|")]
        if len(cells) >= 5 and line.startswith("|") and not set(cells[3]) <= {"-", ""} and cells[3] != "function":
            rows.append((n, cells[3]))
    return rows


def _resolve(dotted: str):
    """Import the longest module prefix of ``dotted``, then follow attributes; raises on a missing name."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def _module_of(dotted: str) -> str:
    """The module part of a resolvable dotted name (``refimpl.models.acrnn.ACRNNConfig`` -> ``refimpl.models.acrnn``)."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        name = ".".join(parts[:k])
        try:
            importlib.import_module(name)
            return name
        except ModuleNotFoundError:
            continue
    raise ModuleNotFoundError(dotted)


def _names(cell: str) -> list[str]:
    """The fully qualified names a cell mentions."""
    out, context = [], None
    for token in re.findall(r"`([^`]+)`", cell):
        m = _NAME.match(token.strip())
        if m is None:
            continue  # a formula or a literal, not a name
        name = m.group(1)
        if name.startswith(("nn.", "models.")):
            name = "refimpl." + name
        if name.split(".")[0] in _PACKAGES:
            context = _module_of(name)
            out.append(name)
        elif context is not None:
            out.append(f"{context}.{name}")
        else:
            out.append(name)  # no module before it in the cell: reported as unresolvable below
    return out


ROWS = _rows()


def test_the_index_has_rows():
    assert len(ROWS) > 60


@pytest.mark.parametrize("line, cell", ROWS, ids=[f"line{n}" for n, _ in ROWS])
def test_every_name_of_a_row_resolves(line, cell):
    missing = []
    for name in _names(cell):
        try:
            _resolve(name)
        except (ImportError, AttributeError) as exc:
            missing.append(f"{name} ({type(exc).__name__}: {exc})")
    assert not missing, f"spec/index.md line {line}: " + "; ".join(missing)


def test_a_wrong_name_is_caught():
    """The checker itself: a misspelt function and a module that does not exist do not resolve."""
    for bad in ("refimpl.quat.quat_mull", "refimpl.no_such_module.f"):
        with pytest.raises((ImportError, AttributeError)):
            _resolve(bad)
    assert _names("`refimpl.models.acrnn.ACRNNConfig`, `init_params`") == [
        "refimpl.models.acrnn.ACRNNConfig", "refimpl.models.acrnn.init_params"]
