"""The portable export target (``--target portable``): graphs that engines other than onnxruntime load.

Purpose
-------
Today's target (``"default"``) writes fused ``GRU``/``LSTM`` nodes and ``Scan``/``Loop`` rollouts at opset 17,
which only onnxruntime runs. The portable target writes, for every model, the *per-call* graphs (init, one step,
a window, QTG's join) with

- opset :data:`PORTABLE_OPSET` (15) and recurrent cells in primitive operators: ``MatMul``/``Gemm``, ``Add``,
  ``Mul``, ``Sigmoid``, ``Tanh``, ``Split``, ... (``GraphBuilder(primitive="recurrent")``, ``spec/deploy.md`` §2); no
  ``GRU``, ``LSTM``, ``RNN``, ``Scan``, ``Loop``, ``If`` (:data:`FORBIDDEN_OPERATORS`) and no subgraph at all;
- static shapes at batch 1: every symbolic dimension of the graph's inputs and outputs becomes a number
  (:func:`portable_model`);
- the recurrent state as explicit inputs and outputs that the host carries from call to call, described in the
  metadata entry ``target`` (:func:`target_entry`): the graphs, the carried state (input ← output, shape, where
  the first value comes from) and the loop the host runs.

The supported-operator tables of the engines aimed at are data in ``deploy/engines/*.json`` (:func:`engine_table`;
sources and versions inside); :func:`engine_problems` lists what a graph uses outside one of them
(``tests/test_deploy_portable.py`` requires none for the Unity table).

The same graph builders serve both targets (the exporters take ``opset`` and ``primitive``); this module only
fixes the shapes and writes the metadata. Shape legend: B batch (1 here), L layers, H hidden size.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Mapping

import numpy as np
import onnx

__all__ = ["TARGETS", "PORTABLE_OPSET", "FORBIDDEN_OPERATORS", "ENGINE_TABLES", "check_target", "builder_options",
           "portable_model", "target_entry", "is_portable", "operators", "engine_table", "engine_problems"]

#: Export targets: ``"default"`` (today's graphs, onnxruntime) and ``"portable"``.
TARGETS = ("default", "portable")

#: Default-domain opset of every portable graph (Unity Inference Engine 2.2 asks for 15,
#: ``deploy/engines/unity_inference_engine_2.2.json``).
PORTABLE_OPSET = 15

#: Operators no portable graph contains (recurrent nodes and control flow).
FORBIDDEN_OPERATORS = ("GRU", "LSTM", "RNN", "Scan", "Loop", "If")

_ENGINE_DIR = Path(__file__).resolve().parent / "engines"
#: Engine name -> operator table file in ``deploy/engines/``.
ENGINE_TABLES = {"unity-inference-engine-2.2": "unity_inference_engine_2.2.json",
                 "onnxruntime-web-webgpu": "onnxruntime_web_webgpu.json"}

_TENSOR_TYPES = {onnx.TensorProto.FLOAT: "float32", onnx.TensorProto.INT64: "int64", onnx.TensorProto.BOOL: "bool",
                 onnx.TensorProto.DOUBLE: "float64", onnx.TensorProto.INT32: "int32"}


def check_target(target) -> str:
    """``target`` if it is one of :data:`TARGETS`, else ``ValueError``."""
    if target not in TARGETS:
        raise ValueError(f"target: expected one of {TARGETS}, got {target!r}")
    return target


def builder_options() -> dict:
    """The graph-builder options of the portable target: float32, :data:`PORTABLE_OPSET`, recurrent cells in
    primitive operators (``primitive="recurrent"``: ``Conv`` and ``LeakyRelu`` stay, both in the engines'
    tables and faster than their decompositions)."""
    return {"dtype": np.float32, "opset": PORTABLE_OPSET, "primitive": "recurrent"}


def operators(model: onnx.ModelProto) -> set[str]:
    """Every ``op_type`` in ``model`` (subgraphs included), prefixed ``domain::`` outside the default domain."""
    ops: set[str] = set()

    def walk(graph):
        for n in graph.node:
            ops.add(f"{n.domain}::{n.op_type}" if n.domain not in ("", "ai.onnx") else n.op_type)
            for a in n.attribute:
                if a.type == onnx.AttributeProto.GRAPH:
                    walk(a.g)
                for sub in a.graphs:
                    walk(sub)
    walk(model.graph)
    return ops


def _fix_dims(values, fixed: Mapping[str, int], where: str) -> dict[str, int]:
    """Set the symbolic dimensions of ``values`` (ValueInfoProtos) from ``fixed``; return ``name -> batch axis``."""
    batch_axes = {}
    for v in values:
        for axis, d in enumerate(v.type.tensor_type.shape.dim):
            if d.HasField("dim_param"):
                sym = d.dim_param
                if sym not in fixed:
                    raise ValueError(f"{where} {v.name!r}: symbolic dimension {sym!r} has no static size (give it "
                                     f"in static=)")
                if sym == "B":
                    batch_axes[v.name] = axis
                d.Clear()
                d.dim_value = int(fixed[sym])
    return batch_axes


def _fixed_shape(shape, fixed):
    return [int(fixed[d]) if isinstance(d, str) and d in fixed else d for d in shape]


def portable_model(model: onnx.ModelProto, *, host_loop: Mapping, static: Mapping[str, int] | None = None
                   ) -> onnx.ModelProto:
    """``model`` (built with :func:`builder_options`) as a portable graph: static shapes, the ``target`` entry.

    Parameters
    ----------
    model : onnx.ModelProto
        A model of an exporter in ``deploy/models`` with the metadata of ``deploy.metadata.build_metadata``.
    host_loop : dict
        The loop the host runs (:func:`target_entry`'s ``host_loop``).
    static : dict, optional
        Sizes of symbolic dimensions other than the batch (``{"W": 9}``); ``"B"`` is always 1.

    Returns
    -------
    onnx.ModelProto
        A copy: every graph input, output and value info with numeric dimensions, ``metadata["io"]`` shapes
        likewise, ``metadata["exporter"]["target"] = "portable"`` and ``metadata["target"]``.

    Raises
    ------
    ValueError
        A forbidden operator or a subgraph, an opset other than :data:`PORTABLE_OPSET`, or a symbolic dimension
        without a size.
    """
    fixed = {"B": 1, **dict(static or {})}
    bad = sorted(operators(model) & set(FORBIDDEN_OPERATORS))
    if bad or any(a.type in (onnx.AttributeProto.GRAPH, onnx.AttributeProto.GRAPHS)
                  for n in model.graph.node for a in n.attribute):
        raise ValueError(f"portable: {model.graph.name}: forbidden operators {bad} or a subgraph (build it with "
                         "deploy.portable.builder_options())")
    opset = {o.domain: o.version for o in model.opset_import}
    if opset.get("", None) != PORTABLE_OPSET or len(opset) != 1:
        raise ValueError(f"portable: {model.graph.name}: expected the default domain at opset {PORTABLE_OPSET} only, "
                         f"got {opset}")
    m = onnx.ModelProto()
    m.CopyFrom(model)
    batch = {}
    for kind, values in (("input", m.graph.input), ("output", m.graph.output), ("value info", m.graph.value_info)):
        axes = _fix_dims(values, fixed, kind)
        if kind != "value info":
            batch[kind] = axes
    meta = {p.key: json.loads(p.value) for p in m.metadata_props}
    for side in ("inputs", "outputs"):
        for entry in meta["io"][side]:
            entry["shape"] = _fixed_shape(entry["shape"], fixed)
    meta["exporter"] = {**meta["exporter"], "target": "portable"}
    meta["target"] = target_entry(host_loop, batch_axes={**batch["input"], **batch["output"]}, static=fixed)
    del m.metadata_props[:]
    for key in sorted(meta):
        p = m.metadata_props.add()
        p.key, p.value = key, json.dumps(meta[key], sort_keys=True, allow_nan=False)
    return m


def target_entry(host_loop: Mapping, *, batch_axes: Mapping[str, int], static: Mapping[str, int]) -> dict:
    """The ``target`` metadata entry of a portable graph.

    ``{"name": "portable", "opset", "batch": 1, "batch_axes": {tensor: axis}, "static": {symbol: size},
    "forbidden_operators", "engines": {name: table file}, "host_loop": {...}}``. ``batch_axes`` names the axis
    of each input and output that holds the batch (1 here): a host with several sequences runs them one after
    another (``deploy.runtime.DeployedModel.run`` does). ``host_loop`` (written by each model's entry module)
    has ``"graphs"`` (files, in call order), ``"state"`` (one entry per carried tensor: ``input``, ``output``
    it comes back as, ``shape``, ``initial``) and ``"loop"`` (the host's loop, one line per statement).
    """
    return {"name": "portable", "opset": PORTABLE_OPSET, "batch": 1, "batch_axes": dict(sorted(batch_axes.items())),
            "static": {k: int(v) for k, v in sorted(static.items())},
            "forbidden_operators": list(FORBIDDEN_OPERATORS),
            "engines": {k: f"deploy/engines/{v}" for k, v in ENGINE_TABLES.items()}, "host_loop": dict(host_loop)}


def is_portable(metadata: Mapping) -> bool:
    """Whether a model's decoded metadata says it is a portable graph."""
    target = metadata.get("target") if isinstance(metadata, Mapping) else None
    return isinstance(target, Mapping) and target.get("name") == "portable"


@lru_cache(maxsize=None)
def _read_table(file: str) -> str:
    return (_ENGINE_DIR / file).read_text(encoding="utf-8")


def engine_table(name: str) -> dict:
    """The operator table of engine ``name`` (:data:`ENGINE_TABLES`), decoded from ``deploy/engines/``."""
    if name not in ENGINE_TABLES:
        raise ValueError(f"engine: expected one of {sorted(ENGINE_TABLES)}, got {name!r}")
    return json.loads(_read_table(ENGINE_TABLES[name]))


def _supported(table: dict) -> set[str]:
    return set(table.get("operators_cpu_types") or table.get("operators_opsets") or {})


def _tensor_types(model: onnx.ModelProto) -> set[str]:
    g = onnx.shape_inference.infer_shapes(model, strict_mode=True).graph
    types = {t.data_type for t in g.initializer}
    types |= {v.type.tensor_type.elem_type for v in list(g.input) + list(g.output) + list(g.value_info)}
    return {_TENSOR_TYPES.get(t, str(t)) for t in types}


def engine_problems(model: onnx.ModelProto, name: str = "unity-inference-engine-2.2") -> list[str]:
    """What ``model`` uses outside engine ``name``'s table: operators, opset (``max_opset``), tensor types
    (``project_rule.tensor_types``, when the table has one). Empty when it fits."""
    table = engine_table(name)
    out = [f"operator {op} is not in the table" for op in sorted(operators(model) - _supported(table))]
    out += [f"operator {op} is listed as unsupported" for op in sorted(operators(model) & set(table.get(
        "unsupported", ())))]
    opset = {o.domain: o.version for o in model.opset_import}.get("", 0)
    if "max_opset" in table and opset > table["max_opset"]:
        out.append(f"opset {opset} > {table['max_opset']}")
    allowed = set((table.get("project_rule") or {}).get("tensor_types", ()))
    if allowed:
        out += [f"tensor type {t}" for t in sorted(_tensor_types(model) - allowed)]
    return out
