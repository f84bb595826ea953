"""onnxruntime sessions with the project's settings (``spec/deploy.md`` §7).

CPU execution provider; ``intra_op_num_threads`` configurable (default 1: batch-1 steps are latency-bound and a
second thread mostly adds synchronisation); ``inter_op_num_threads = 1`` with sequential execution;
``session.intra_op.allow_spinning = "0"`` so that several sessions (init, step, rollout) driven alternately do not
fight over the cores with spinning worker threads (``spinning=True`` turns it on: faster for one session with two
threads on an idle machine); full graph optimisation.

Model-size guard (``spec/deploy.md`` §7.1, ``spec/robustness.md``): :func:`make_session` first runs
:func:`check_model_size`, which refuses — before onnxruntime sees the model — a file whose *declared* sizes exceed
the documented limits. onnxruntime folds constant subgraphs when it creates a session, so a 300-byte model whose
``ConstantOfShape``/``Expand``/``Tile``/``Range`` of constants describes a 30000 × 30000 tensor would otherwise
allocate gigabytes there (a *model bomb*). Checked, in the main graph and every subgraph:

* each initializer, ``Constant`` node value and sparse initializer: declared elements × element size
  ≤ :data:`MAX_TENSOR_BYTES`; their sum ≤ :data:`MAX_CONSTANT_BYTES`; declared dimensions non-negative;
* every tensor shape that ``onnx.shape_inference`` (with data propagation) knows statically — symbolic dimensions
  counted as 1, so the bound holds at batch 1 and grows only with the caller's own inputs — ≤
  :data:`MAX_TENSOR_BYTES`;
* nodes that can enlarge data (``ConstantOfShape``, ``Expand``, ``Tile``, ``Range``, ``Resize``, ``Upsample``,
  ``Pad``, ``OneHot``, ``CenterCropPad``) whose inputs are all constants must have a statically known output
  shape (else the size cannot be bounded before folding: refused);
* ``Loop`` trip counts given as constants ≤ :data:`MAX_LOOP_ITERATIONS`.

Sizes that depend on the *values* of run-time inputs (e.g. an int64 input fed to ``ConstantOfShape``) are not
bounded here; the models exported by this package have none, and the runtime checks the size of every input.
"""
from __future__ import annotations

import os

import numpy as np
import onnx

from refimpl.bounds import check_count
from refimpl.files import read_bytes

__all__ = ["make_session_options", "make_session", "check_model_size", "MAX_TENSOR_BYTES", "MAX_CONSTANT_BYTES",
           "MAX_LOOP_ITERATIONS"]

#: Largest tensor a model may declare or statically imply (initializer, constant, inferred shape): 256 MiB.
MAX_TENSOR_BYTES = 256 * 2 ** 20
#: Largest total of a model's initializers and constants: 1 GiB (the paper-sized QuaterNet has 37.5 MB).
MAX_CONSTANT_BYTES = 2 ** 30
#: Largest constant ``Loop`` trip count.
MAX_LOOP_ITERATIONS = 10 ** 6

_EXPANDING = frozenset({"ConstantOfShape", "Expand", "Tile", "Range", "Resize", "Upsample", "Pad", "OneHot",
                        "CenterCropPad"})


def _itemsize(elem_type: int) -> int:
    try:
        return int(np.dtype(onnx.helper.tensor_dtype_to_np_dtype(elem_type)).itemsize)
    except Exception:  # undefined / string / unknown element types: count 8 bytes per element
        return 8


def _tensor_bytes(t: onnx.TensorProto, where: str) -> int:
    dims = [int(d) for d in t.dims]
    if any(d < 0 for d in dims):
        raise ValueError(f"model: {where} declares a negative dimension {dims}")
    n = 1
    for d in dims:
        n *= d
    size = n * _itemsize(t.data_type)
    if size > MAX_TENSOR_BYTES:
        raise ValueError(f"model: {where} declares shape {dims} ({size / 2**20:.0f} MiB); the limit is "
                         f"MAX_TENSOR_BYTES = {MAX_TENSOR_BYTES // 2**20} MiB per tensor (deploy/session.py)")
    return size


def _static_bytes(vi: onnx.ValueInfoProto) -> int | None:
    """Bytes of a value with a known rank (symbolic or unknown dimensions counted as 1), else None."""
    t = vi.type.tensor_type if vi.type.HasField("tensor_type") else None
    if t is None or not t.HasField("shape"):
        return None
    n = 1
    for d in t.shape.dim:
        if d.HasField("dim_value"):
            if d.dim_value < 0:
                return None
            n *= int(d.dim_value)
    return n * _itemsize(t.elem_type)


def _fully_static(vi) -> bool:
    t = vi.type.tensor_type if (vi is not None and vi.type.HasField("tensor_type")) else None
    return t is not None and t.HasField("shape") and all(d.HasField("dim_value") for d in t.shape.dim)


def _check_graph(graph: onnx.GraphProto, path: str, total: list, inferred: bool) -> None:
    constants = set()
    for t in graph.initializer:
        total[0] += _tensor_bytes(t, f"{path}initializer {t.name!r}")
        constants.add(t.name)
    for st in graph.sparse_initializer:
        total[0] += _tensor_bytes(st.values, f"{path}sparse initializer {st.values.name!r}")
        dims = [int(d) for d in st.dims]
        n = int(np.prod(dims, dtype=np.float64)) if dims else 1
        if any(d < 0 for d in dims) or n * _itemsize(st.values.data_type) > MAX_TENSOR_BYTES:
            raise ValueError(f"model: {path}sparse initializer declares dense shape {dims}; the limit is "
                             f"MAX_TENSOR_BYTES = {MAX_TENSOR_BYTES // 2**20} MiB per tensor (deploy/session.py)")
        constants.add(st.values.name)
    known = {vi.name: vi for vi in list(graph.value_info) + list(graph.output)}
    for name, vi in (known.items() if inferred else ()):
        size = _static_bytes(vi)
        if size is not None and size > MAX_TENSOR_BYTES:
            dims = [d.dim_value if d.HasField("dim_value") else (d.dim_param or "?")
                    for d in vi.type.tensor_type.shape.dim]
            raise ValueError(f"model: {path}tensor {name!r} has the statically known shape {dims} "
                             f"({size / 2**20:.0f} MiB at batch 1); the limit is MAX_TENSOR_BYTES = "
                             f"{MAX_TENSOR_BYTES // 2**20} MiB (deploy/session.py)")
    for node in graph.node:
        where = f"{path}node {node.name or node.op_type!r} ({node.op_type})"
        if node.op_type == "Constant":
            for a in node.attribute:
                if a.type == onnx.AttributeProto.TENSOR:
                    total[0] += _tensor_bytes(a.t, where)
                elif a.type == onnx.AttributeProto.SPARSE_TENSOR:
                    total[0] += _tensor_bytes(a.sparse_tensor.values, where)
                    dims = [int(d) for d in a.sparse_tensor.dims]
                    if any(d < 0 for d in dims) or np.prod(dims, dtype=np.float64) * 8 > MAX_TENSOR_BYTES:
                        raise ValueError(f"model: {where} declares dense shape {dims}; the limit is "
                                         f"MAX_TENSOR_BYTES = {MAX_TENSOR_BYTES // 2**20} MiB (deploy/session.py)")
                elif a.type in (onnx.AttributeProto.FLOATS, onnx.AttributeProto.INTS, onnx.AttributeProto.STRINGS):
                    total[0] += 8 * (len(a.floats) + len(a.ints) + len(a.strings))
            constants.update(o for o in node.output if o)
        else:
            inputs = [i for i in node.input if i]
            if all(i in constants for i in inputs):
                if inferred and node.op_type in _EXPANDING and not all(_fully_static(known.get(o))
                                                                       for o in node.output if o):
                    raise ValueError(f"model: {where} enlarges constants to a size shape inference cannot "
                                     "bound before onnxruntime folds it; refused (deploy/session.py)")
                if node.op_type not in ("Loop", "Scan", "If", "RandomNormal", "RandomUniform", "Multinomial"):
                    constants.update(o for o in node.output if o)
            if node.op_type == "Loop" and node.input and node.input[0] in constants:
                trips = _constant_value(graph, node.input[0])
                if trips is None or trips.size != 1 or int(trips.reshape(-1)[0]) > MAX_LOOP_ITERATIONS:
                    raise ValueError(f"model: {where} has a constant trip count "
                                     f"{None if trips is None else trips.reshape(-1)[:1].tolist()}; the limit is "
                                     f"MAX_LOOP_ITERATIONS = {MAX_LOOP_ITERATIONS} (deploy/session.py)")
        for a in node.attribute:
            if a.type == onnx.AttributeProto.GRAPH:
                _check_graph(a.g, f"{where} / {a.name}: ", total, inferred)
            elif a.type == onnx.AttributeProto.GRAPHS:
                for sub in a.graphs:
                    _check_graph(sub, f"{where} / {a.name}: ", total, inferred)
    if total[0] > MAX_CONSTANT_BYTES:
        raise ValueError(f"model: its initializers and constants declare {total[0] / 2**20:.0f} MiB; the limit is "
                         f"MAX_CONSTANT_BYTES = {MAX_CONSTANT_BYTES // 2**20} MiB (deploy/session.py)")


def _constant_value(graph: onnx.GraphProto, name: str):
    """The value of a small initializer / Constant output ``name`` (≤ 16 elements), else None."""
    from onnx import numpy_helper

    for t in graph.initializer:
        if t.name == name and int(np.prod(list(t.dims), dtype=np.float64)) <= 16:
            return numpy_helper.to_array(t)
    for node in graph.node:
        if node.op_type == "Constant" and name in node.output:
            for a in node.attribute:
                if a.name == "value" and int(np.prod(list(a.t.dims), dtype=np.float64)) <= 16:
                    return numpy_helper.to_array(a.t)
    return None


def _without_large_data(model: onnx.ModelProto) -> onnx.ModelProto:
    """A copy of ``model`` whose main-graph initializers of more than 4096 elements keep their type and dims but
    not their data: shape inference needs only the small ones (shape tensors), and copying a 37 MB model's
    weights would cost most of the check's time."""
    graph = model.graph
    stubs = []
    for t in graph.initializer:
        if np.prod(list(t.dims), dtype=np.float64) > 4096:
            stub = onnx.TensorProto(name=t.name, data_type=t.data_type)
            stub.dims.extend(t.dims)
            stubs.append(stub)
        else:
            stubs.append(t)
    light = onnx.helper.make_graph(graph.node, graph.name, graph.input, graph.output, initializer=stubs,
                                   value_info=graph.value_info, sparse_initializer=graph.sparse_initializer)
    out = onnx.ModelProto(ir_version=model.ir_version, graph=light)
    out.opset_import.extend(model.opset_import)
    out.functions.extend(model.functions)
    return out


def check_model_size(model: onnx.ModelProto) -> None:
    """Refuse a model whose declared or statically known sizes exceed the limits (module docstring), without
    allocating them: ``ValueError`` naming the tensor or node, its size and the limit.

    Runs ``onnx.shape_inference.infer_shapes(data_prop=True)`` (shapes only; no constant is folded).
    """
    if not isinstance(model, onnx.ModelProto):
        raise ValueError(f"model: expected an onnx.ModelProto, got {type(model).__name__}")
    total = [0]
    _check_graph(model.graph, "", total, False)   # declared sizes first: shape inference never sees a huge initializer
    try:
        inferred = onnx.shape_inference.infer_shapes(_without_large_data(model), strict_mode=False, data_prop=True)
    except Exception as exc:  # InferenceError and others on malformed models
        raise ValueError(f"model: shape inference failed: {exc}") from exc
    _check_graph(inferred.graph, "", [0], True)


def make_session_options(intra_op_threads: int = 1, *, optimization: str = "all", spinning: bool = False):
    """``onnxruntime.SessionOptions`` with the project's settings (module docstring).

    Parameters
    ----------
    intra_op_threads : int
        Threads inside one operator (``>= 1``).
    optimization : {"all", "extended", "basic", "disabled"}
        Graph optimisation level.
    spinning : bool
        Let the intra-op worker threads spin between parallel sections (``session.intra_op.allow_spinning =
        "1"``). Off by default (module docstring). With two threads on an otherwise idle machine and one session
        driven at a time, spinning cuts the batch-1 latency of many-node graphs (the QTG compact rollout:
        ``spec/deploy.md`` §9); on a busy machine, or with several sessions used alternately, it wastes a core.
    """
    import onnxruntime as ort

    check_count(intra_op_threads, "intra_op_threads", "ort_threads")  # refimpl.bounds: [1, 256]
    levels = {"all": ort.GraphOptimizationLevel.ORT_ENABLE_ALL,
              "extended": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED,
              "basic": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC,
              "disabled": ort.GraphOptimizationLevel.ORT_DISABLE_ALL}
    if optimization not in levels:
        raise ValueError(f"optimization: expected one of {sorted(levels)}, got {optimization!r}")
    if not isinstance(spinning, (bool, np.bool_)):
        raise ValueError(f"spinning: expected a bool, got {spinning!r}")
    so = ort.SessionOptions()
    so.intra_op_num_threads = int(intra_op_threads)
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = levels[optimization]
    so.add_session_config_entry("session.intra_op.allow_spinning", "1" if spinning else "0")
    so.add_session_config_entry("session.inter_op.allow_spinning", "0")
    so.log_severity_level = 3
    return so


def make_session(model: onnx.ModelProto | bytes | str | os.PathLike, *, intra_op_threads: int = 1,
                 optimization: str = "all", check_size: bool = True, spinning: bool = False):
    """An ``onnxruntime.InferenceSession`` on the CPU provider with :func:`make_session_options`, after
    :func:`check_model_size` (unless ``check_size=False``: for a caller that has just run it, like
    ``deploy.runtime.load_model``; no other validation: ``deploy.validate.validate_model``).

    Raises
    ------
    ValueError
        When the model exceeds the size limits (:func:`check_model_size`) or onnxruntime refuses it
        (unsupported opset or operator, malformed file, ...).
    """
    import onnxruntime as ort

    if not isinstance(model, onnx.ModelProto):
        try:
            model = (onnx.load_model_from_string(model) if isinstance(model, bytes)
                     else onnx.load_model_from_string(read_bytes(os.fspath(model))))
        except Exception as exc:  # DecodeError, OSError, ...
            raise ValueError(f"model: not a readable ONNX model ({type(exc).__name__}: {exc})") from exc
    if check_size:
        check_model_size(model)
    model = model.SerializeToString()
    options = make_session_options(intra_op_threads, optimization=optimization, spinning=spinning)
    try:
        return ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph/NotImplemented classes
        raise ValueError(f"model: onnxruntime refused it: {exc}") from exc
