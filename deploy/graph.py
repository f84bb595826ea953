"""A small ONNX graph builder: nodes, initializers and value infos under deterministic, path-prefixed names.

Purpose
-------
Every exporter in ``deploy/`` builds its graph through :class:`GraphBuilder`, which wraps the ``onnx.helper`` and
``onnx.numpy_helper`` functions and enforces the project's export rules (``spec/deploy.md`` §1):

- explicit ``opset_imports`` and ``ir_version`` on every model (never the ``make_model`` defaults, which stamp an
  IR version newer than many runtimes accept); :data:`OPSET` and :data:`IR_VERSION` are the defaults, both
  configurable;
- every graph input and output carries a shape (symbolic names such as ``"B"`` for free dimensions);
- names are deterministic and path-prefixed (``enc.gru0.W``): the same weights give byte-identical models;
- one float dtype per graph (``float32`` for deployment; ``float64`` for the exact-semantics variant, which
  also switches the layer builders to primitive operators, see ``primitive``).

Non-goals: no tracing, no PyTorch, no onnxscript, no graph optimisation (onnxruntime does that on load).

Conventions
-----------
A *name* is a string naming one tensor in the graph. :meth:`GraphBuilder.node` names a node's single output
after the node itself (``name``), or ``name.<out>`` for each entry of ``outputs`` when there are several.
Shape legend: B batch, T time, F features.
"""
from __future__ import annotations

import json
from typing import Iterable, Mapping, Sequence

import numpy as np

from refimpl.atomic import atomic_write_bytes
import onnx
from onnx import helper, numpy_helper

__all__ = ["OPSET", "IR_VERSION", "MIN_OPSET", "ir_version_for", "GraphBuilder", "get_param",
           "check_model_strict", "save_model"]

OPSET = 17
"""Default ONNX opset of every exported model (widest reach for embedded and older onnxruntime builds)."""

IR_VERSION = 8
"""IR version stamped on models at :data:`OPSET` (the lowest the opset allows, ``spec/deploy.md`` §1)."""

MIN_OPSET = 15
"""The oldest opset the builders support (``Squeeze``/``Split`` take inputs from 13; GRU ``layout`` from 14; 15 is
the portable target's, ``deploy/portable.py``, with ``Shape``'s ``start``/``end``)."""


def ir_version_for(opset: int) -> int:
    """The lowest IR version that may carry default-domain ``opset`` (8 for 17 and 18, 10 for 21 and 22, ...)."""
    return int(helper.find_min_ir_version_for([helper.make_opsetid("", int(opset))]))


def get_param(params: Mapping[str, np.ndarray], prefix: str, key: str) -> np.ndarray:
    """Read ``params[prefix + "." + key]`` (``params[key]`` for the empty prefix) as an array.

    Raises
    ------
    ValueError
        When the entry is missing (the message names the full key and the available keys under ``prefix``).
    """
    full = f"{prefix}.{key}" if prefix else key
    if full not in params:
        near = sorted(k for k in params if k.startswith(prefix))[:8] if prefix else sorted(params)[:8]
        raise ValueError(f"params: missing entry {full!r}; entries under {prefix!r}: {near}")
    return np.asarray(params[full])


def check_model_strict(model: onnx.ModelProto) -> onnx.ModelProto:
    """Run ``onnx.checker.check_model(full_check=True)`` and strict shape inference; return the inferred model.

    Raises ``onnx.checker.ValidationError`` or ``onnx.shape_inference.InferenceError`` on a malformed model.
    """
    onnx.checker.check_model(model, full_check=True)
    return onnx.shape_inference.infer_shapes(model, check_type=True, strict_mode=True)


def save_model(model: onnx.ModelProto, path) -> None:
    """Write ``model`` to ``path`` atomically: temporary file in the same directory, flush, fsync, ``os.replace``.

    Models up to 2 GB only (no external data), which covers everything exported here.
    """
    atomic_write_bytes(path, model.SerializeToString())


def _elem_type(dtype) -> int:
    return int(helper.np_dtype_to_tensor_dtype(np.dtype(dtype)))


class GraphBuilder:
    """Collects the nodes, initializers, inputs, outputs and value infos of one ONNX graph.

    Parameters
    ----------
    name : str
        Graph name.
    dtype : numpy dtype, default float32
        The float type of the graph: weights are cast to it and float inputs/outputs declared with it.
    opset : int, default :data:`OPSET`
        Default-domain opset; some builders emit version-dependent forms (``Reduce*`` take ``axes`` as an input
        from opset 18 on).
    primitive : bool or "recurrent", optional
        Decompose GRU, LSTM, Conv and LeakyRelu into primitive operators (MatMul, Add, Sigmoid, ...). Default:
        ``True`` for float64 (onnxruntime's CPU kernels of those operators are float32-only), else ``False``.
        ``"recurrent"`` decomposes the recurrent cells only and keeps ``Conv`` and ``LeakyRelu`` (the portable
        target, ``deploy/portable.py``: engines without GRU/LSTM/Scan have those two); float32 graphs only.
        :attr:`primitive` is then ``True`` and :attr:`primitive_layers` ``False``.

    Notes
    -----
    Names must be unique within a graph; reusing one raises ``ValueError``. Constants made by :meth:`ints` and
    :meth:`scalar` are shared and named by their value (``const.i64[0,2,1]``), so they are deterministic too.
    All initializers live in the outermost graph; asking twice for one name with equal content shares it.
    """

    def __init__(self, name: str = "graph", *, dtype=np.float32, opset: int = OPSET,
                 primitive: bool | None = None, _outer: "GraphBuilder | None" = None):
        if int(opset) < MIN_OPSET:
            raise ValueError(f"opset: expected >= {MIN_OPSET}, got {opset}")
        dtype = np.dtype(dtype)
        if dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype: expected float32 or float64, got {dtype}")
        self.name = name
        self.dtype = dtype
        self.opset = int(opset)
        if primitive == "recurrent" and dtype != np.float32:
            raise ValueError(f"primitive: 'recurrent' keeps Conv and LeakyRelu, float32 only; got dtype {dtype}")
        self._primitive_arg = primitive
        self.primitive = bool(dtype == np.float64) if primitive is None else bool(primitive)
        #: whether Conv and LeakyRelu are decomposed too (``primitive`` other than ``"recurrent"``)
        self.primitive_layers = self.primitive and primitive != "recurrent"
        self.nodes: list[onnx.NodeProto] = []
        self.initializers: list[onnx.TensorProto] = []
        self.inputs: list[onnx.ValueInfoProto] = []
        self.outputs: list[onnx.ValueInfoProto] = []
        self.value_infos: list[onnx.ValueInfoProto] = []
        self._outer = _outer
        self._names: set[str] = set()
        self._aliases: dict[str, str] = {}
        self._arrays: dict[str, np.ndarray] = {}
        self._domains: set[str] = set()

    # ----------------------------------------------------------------------------------------------- names
    def _claim(self, name: str) -> str:
        if not name:
            raise ValueError("name: expected a non-empty string")
        if name in self._names or (self._outer is not None and self._outer._has(name)):
            raise ValueError(f"name {name!r} is already used in graph {self.name!r}")
        self._names.add(name)
        outer = self._outer
        while outer is not None:  # reserve it in the enclosing graphs too: ONNX names must not shadow across scopes
            outer._names.add(name)
            outer = outer._outer
        return name

    def _has(self, name: str) -> bool:
        return name in self._names or (self._outer is not None and self._outer._has(name))

    @property
    def elem_type(self) -> int:
        """The ``TensorProto`` element type of the graph's float dtype."""
        return _elem_type(self.dtype)

    # ------------------------------------------------------------------------------------ inputs/outputs
    def input(self, name: str, shape: Sequence[int | str], dtype=None) -> str:
        """Declare a graph input ``name`` of ``shape`` (ints or symbolic names); ``dtype`` defaults to the graph's."""
        self._claim(name)
        et = self.elem_type if dtype is None else _elem_type(dtype)
        self.inputs.append(helper.make_tensor_value_info(name, et, list(shape)))
        return name

    def output(self, src: str, name: str, shape: Sequence[int | str], dtype=None) -> str:
        """Declare the tensor ``src`` a graph output called ``name`` (renaming it, or through Identity if needed)."""
        et = self.elem_type if dtype is None else _elem_type(dtype)
        src = self._aliases.get(src, src)
        if src != name:
            producer = [n for n in self.nodes if src in n.output]
            is_io = any(v.name == src for v in self.inputs + self.outputs)
            if producer and not is_io and not self._used_in_subgraph(src):
                self._claim(name)
                self._rename(src, name)
            else:
                self.node("Identity", [src], name)
        self.outputs.append(helper.make_tensor_value_info(name, et, list(shape)))
        return name

    def value_info(self, name: str, shape: Sequence[int | str], dtype=None) -> str:
        """Record the type and shape of an intermediate tensor (documentation; shape inference checks it)."""
        et = self.elem_type if dtype is None else _elem_type(dtype)
        self.value_infos.append(helper.make_tensor_value_info(name, et, list(shape)))
        return name

    def _used_in_subgraph(self, name: str) -> bool:
        for n in self.nodes:
            for a in n.attribute:
                if a.type == onnx.AttributeProto.GRAPH and _graph_mentions(a.g, name):
                    return True
        return False

    def _rename(self, old: str, new: str) -> None:
        self._names.discard(old)
        self._aliases[old] = new
        for n in self.nodes:
            n.output[:] = [new if o == old else o for o in n.output]
            n.input[:] = [new if i == old else i for i in n.input]

    # ------------------------------------------------------------------------------------ initializers
    def weight(self, name: str, array) -> str:
        """A float initializer ``name`` holding ``array`` cast to the graph dtype (C order); returns ``name``.

        Initializers always live in the outermost graph (Loop/Scan bodies read them from the outer scope, see
        ``spec/deploy.md`` §1). Asking again for an existing ``name`` with equal content returns it (weights shared
        by the steps of an unrolled rollout); different content raises ``ValueError``.
        """
        return self.constant(name, np.asarray(array, dtype=self.dtype))

    def constant(self, name: str, array) -> str:
        """An initializer ``name`` holding ``array`` with its own dtype (int64 indices, ...); see :meth:`weight`."""
        arr = np.array(array, order="C")  # copies; keeps 0-d shapes (ascontiguousarray would not)
        root = self._root()
        if name in root._arrays:
            old = root._arrays[name]
            if old.dtype != arr.dtype or old.shape != arr.shape or not np.array_equal(old, arr):
                raise ValueError(f"initializer {name!r} already exists with different content")
            return name
        root._claim(name)
        if self is not root and self._has_local(name):
            raise ValueError(f"name {name!r} is already used in graph {self.name!r}")
        root._arrays[name] = arr
        root.initializers.append(numpy_helper.from_array(arr, name))
        return name

    def ints(self, values: Iterable[int]) -> str:
        """A shared int64 1-D constant (axes, shapes, perms, slice bounds), named by its values."""
        vals = [int(v) for v in values]
        return self.constant("const.i64[" + ",".join(str(v) for v in vals) + "]", np.array(vals, dtype=np.int64))

    def scalar(self, value: float) -> str:
        """A shared 0-d float constant of the graph dtype, named by its value (``repr`` of the float)."""
        v = float(np.asarray(value, dtype=self.dtype))
        return self.constant(f"const.f[{v!r}]", np.array(v, dtype=self.dtype))

    def shared(self, name: str, array) -> str:
        """A constant shared by every builder that asks for ``name`` (fixed tables such as ``const.quat_mul.sign``).

        Float arrays are cast to the graph dtype; other dtypes are kept.
        """
        arr = np.asarray(array)
        return self.weight(name, arr) if arr.dtype.kind == "f" else self.constant(name, arr)

    def is_initializer(self, name: str) -> bool:
        """Whether ``name`` is an initializer (of the outermost graph, where all initializers live)."""
        return name in self._root()._arrays

    def _root(self) -> "GraphBuilder":
        return self if self._outer is None else self._outer._root()

    def _has_local(self, name: str) -> bool:
        return name in self._names

    # ------------------------------------------------------------------------------------------- nodes
    def node(self, op: str, inputs: Sequence[str], name: str, *, outputs: Sequence[str] | None = None,
             domain: str = "", **attrs) -> str | tuple[str, ...]:
        """Append one node ``op`` named ``name``; return its output name (or names, one per entry of ``outputs``).

        ``domain`` other than the default adds an opset import for that domain (version 1) to the model.

        ``outputs=None`` gives one output named ``name``; ``outputs=("Y", "Y_h")`` gives ``name.Y``, ``name.Y_h``
        (an empty entry ``""`` skips an optional output). ``inputs`` may contain ``""`` for skipped optional inputs.
        """
        self._claim(name)
        if outputs is None:
            outs = [name]
        else:
            outs = [f"{name}.{o}" if o else "" for o in outputs]
            for o in outs:
                if o:
                    self._claim(o)
        if domain:
            self._root()._domains.add(domain)
        self.nodes.append(helper.make_node(op, list(inputs), outs, name=name, domain=domain or None, **attrs))
        return outs[0] if outputs is None else tuple(outs)

    def reduce(self, op: str, x: str, axes: Sequence[int], name: str, *, keepdims: bool = True) -> str:
        """``Reduce*`` over ``axes``, as an attribute before opset 18 and as an input from 18 on (ReduceSum: 13)."""
        axes_as_input = self.opset >= 18 or op == "ReduceSum"
        if axes_as_input:
            return self.node(op, [x, self.ints(axes)], name, keepdims=int(keepdims))
        return self.node(op, [x], name, axes=[int(a) for a in axes], keepdims=int(keepdims))

    def subgraph(self, name: str) -> "GraphBuilder":
        """A builder for a Loop/Scan body: same dtype, opset and ``primitive``; may read this graph's names."""
        return GraphBuilder(name, dtype=self.dtype, opset=self.opset, primitive=self._primitive_arg, _outer=self)

    # ------------------------------------------------------------------------------------------ output
    def graph(self, doc_string: str | None = None) -> onnx.GraphProto:
        """The ``GraphProto`` (nodes in insertion order, which is a topological order by construction)."""
        return helper.make_graph(self.nodes, self.name, self.inputs, self.outputs,
                                 initializer=self.initializers, value_info=self.value_infos,
                                 doc_string=doc_string)

    def model(self, *, metadata: Mapping[str, object] | None = None, doc_string: str | None = None,
              ir_version: int | None = None, producer_version: str = "") -> onnx.ModelProto:
        """The ``ModelProto`` with explicit ``opset_imports`` and ``ir_version`` and JSON metadata.

        Parameters
        ----------
        metadata : mapping, optional
            Each value is stored as ``json.dumps(value, sort_keys=True)`` in ``model.metadata_props`` (keys sorted),
            so a consumer reads it with ``json.loads`` and nothing is ever executed.
        ir_version : int, optional
            Default: :data:`IR_VERSION` at :data:`OPSET`, else :func:`ir_version_for` ``(opset)``.
        """
        if self._outer is not None:
            raise ValueError("model: called on a subgraph builder")
        if ir_version is None:
            ir_version = IR_VERSION if self.opset == OPSET else ir_version_for(self.opset)
        # other domains (only "com.microsoft" for onnxruntime's MatMulNBits, deploy/qtg_compact.py) at version 1
        opsets = [helper.make_opsetid("", self.opset)] + [helper.make_opsetid(d, 1) for d in sorted(self._domains)]
        m = helper.make_model(self.graph(), opset_imports=opsets, ir_version=int(ir_version),
                              producer_name="refimpl.deploy", producer_version=producer_version)
        if doc_string:
            m.doc_string = doc_string
        for key in sorted(metadata or {}):
            entry = m.metadata_props.add()
            entry.key = str(key)
            entry.value = json.dumps(metadata[key], sort_keys=True, allow_nan=False)
        return m


def _graph_mentions(g: onnx.GraphProto, name: str) -> bool:
    for n in g.node:
        if name in n.input or name in n.output:
            return True
        for a in n.attribute:
            if a.type == onnx.AttributeProto.GRAPH and _graph_mentions(a.g, name):
                return True
    return any(v.name == name for v in list(g.output))
