"""Block-wise int8/int4 weight quantisation and the matrix products that use it (onnxruntime ``MatMulNBits``).

A weight matrix ``W (K, N)`` multiplies activations as ``y = x W`` (``x (B, K)``, ``y (B, N)``). The quantised form
cuts every column ``j`` along ``K`` into blocks of ``block_size`` rows and stores, per block, one float32 scale and
``bits``-bit integers (symmetric, implicit zero point ``2^(bits−1)``): the layout of onnxruntime's contrib operator
``com.microsoft.MatMulNBits``. With ``accuracy_level = 4`` the kernel also quantises ``x`` to int8 per block and
uses integer dot products, so a product reads 1 byte (int8) or ½ byte (int4) per weight instead of 4
(``spec/deploy.md`` §5.4, §9). Models using it are onnxruntime-specific (the ``com.microsoft`` domain).

* :func:`quantize_blocks` — the quantiser (packed bytes, scales, and the dequantised matrix for accuracy checks).
* :class:`WeightMatmul` — emits ``x @ W (+ bias)`` into a :class:`deploy.graph.GraphBuilder` as a float ``Gemm`` /
  ``MatMul`` or as ``MatMulNBits``, chosen once by the weight format (:data:`WEIGHT_FORMATS`).

Shape legend: B batch, K inner (input) size, N output size, kb = ceil(K / block_size) blocks per column.
"""
from __future__ import annotations

import numpy as np

from deploy.graph import GraphBuilder

__all__ = ["WEIGHT_FORMATS", "quantize_blocks", "WeightMatmul"]

#: Weight storage formats: float initializers, or 8-/4-bit block-quantised ``MatMulNBits`` weights.
WEIGHT_FORMATS = ("float32", "int8", "int4")


def quantize_blocks(w: np.ndarray, bits: int = 8, block_size: int = 32):
    """Symmetric block-wise quantisation of ``w`` ``(K, N)`` in onnxruntime's ``MatMulNBits`` layout.

    Each column ``j`` is cut along ``K`` into blocks of ``block_size`` (the last one zero-padded); block ``b`` gets
    ``scale[j, b] = max |w| / (2^(bits−1) − 1)`` (1 for an all-zero block) and integer values
    ``q = round(w / scale)`` in ``[−(2^(bits−1) − 1), 2^(bits−1) − 1]``, stored with the implicit zero point
    ``2^(bits−1)`` as unsigned ``bits``-bit numbers (two per byte for 4 bits, low nibble first).

    Returns
    -------
    packed : ndarray uint8 (N, ceil(K / block_size), block_size · bits / 8)
    scales : ndarray float32 (N · ceil(K / block_size),)
    dequantized : ndarray float64 (K, N)
        ``scale · q``, what the kernel multiplies with (for accuracy checks).
    """
    w = np.asarray(w, dtype=np.float64)
    if w.ndim != 2:
        raise ValueError(f"w: expected a matrix (K, N), got shape {w.shape}")
    if bits not in (4, 8):
        raise ValueError(f"bits: expected 4 or 8, got {bits}")
    K, N = w.shape
    n_blocks = -(-K // block_size)
    padded = np.zeros((n_blocks * block_size, N))
    padded[:K] = w
    blocks = padded.T.reshape(N, n_blocks, block_size)                   # (N, kb, bs)
    qmax = 2 ** (bits - 1) - 1
    amax = np.abs(blocks).max(axis=-1)                                   # (N, kb)
    scales = np.where(amax > 0, amax / qmax, 1.0).astype(np.float32)
    q = np.clip(np.rint(blocks / scales[..., None].astype(np.float64)), -qmax, qmax).astype(np.int64)
    u = q + 2 ** (bits - 1)                                              # unsigned with zero point 2^(bits-1)
    packed = u.astype(np.uint8) if bits == 8 else (u[..., 0::2] | (u[..., 1::2] << 4)).astype(np.uint8)
    deq = (q * scales[..., None].astype(np.float64)).reshape(N, -1).T[:K]  # (K, N)
    return packed, scales.reshape(-1), deq


class WeightMatmul:
    """Emits ``y = x @ W (+ bias)`` for a constant ``W (K, N)`` into a graph, in one weight storage format.

    Parameters
    ----------
    g : GraphBuilder
        The graph to append to (float32 graphs; ``MatMulNBits`` has no float64 kernel).
    fmt : {"float32", "int8", "int4"}
        ``"float32"``: float initializer ``{wname}.W`` and ``Gemm`` (with a bias) or ``MatMul``.
        ``"int8"`` / ``"int4"``: :func:`quantize_blocks` initializers ``{wname}.Wq{bits}``, ``{wname}.scales`` and
        one ``com.microsoft.MatMulNBits`` node (``accuracy_level`` below); a constant bias is its own bias input,
        a computed one (a tensor name) is added by an ``Add`` node.
    block_size : int, optional
        Quantisation block length along ``K``: a power of two ≥ 16 (the kernel's requirement), default 32.
    accuracy_level : {4, 1}, optional
        ``MatMulNBits``' compute type. 4 (default): the activations are quantised to int8 per block as well and
        the dot products are integer (fast; each activation is rounded by up to ½ / 127 ≈ 0.4 % of its block's
        largest ``|x|``). 1: float32 compute with the dequantised weights, so the product equals
        ``x @ quantize_blocks(w)[2]`` to float32 rounding (used to test layouts exactly). Ignored for float32.

    Raises
    ------
    ValueError
        ``fmt`` not in :data:`WEIGHT_FORMATS`, a bad ``block_size`` or ``accuracy_level``, or ``g`` not a
        float32 graph while ``fmt`` is int8/int4.
    """

    def __init__(self, g: GraphBuilder, fmt: str, block_size: int = 32, accuracy_level: int = 4):
        if fmt not in WEIGHT_FORMATS:
            raise ValueError(f"fmt: expected one of {WEIGHT_FORMATS}, got {fmt!r}")
        if not isinstance(block_size, (int, np.integer)) or block_size < 16 or block_size & (block_size - 1):
            raise ValueError(f"block_size: expected a power of two >= 16, got {block_size!r}")
        if accuracy_level not in (1, 4):
            raise ValueError(f"accuracy_level: expected 4 (int8 compute) or 1 (float32 compute), "
                             f"got {accuracy_level!r}")
        if fmt != "float32" and np.dtype(g.dtype) != np.float32:
            raise ValueError(f"g: {fmt} weights (MatMulNBits) need a float32 graph, got dtype {np.dtype(g.dtype)}")
        self.g, self.fmt, self.block_size, self.accuracy_level = g, fmt, int(block_size), int(accuracy_level)

    def matmul(self, x: str, w: np.ndarray, wname: str, name: str, bias: np.ndarray | str | None = None) -> str:
        """Append ``x @ w (+ bias)``.

        Parameters
        ----------
        x : str
            Activations ``(B, K)``.
        w : ndarray (K, N)
            Weights, laid out ``(in, out)``.
        wname : str
            Initializer path (``{wname}.W``, ``{wname}.b``, ...); equal ``wname`` and content share initializers.
        name : str
            Node name (and output name).
        bias : ndarray (N,) or str, optional
            A constant bias (stored as ``{wname}.b``) or the name of a tensor broadcastable to ``(B, N)``.

        Returns
        -------
        str
            Output ``(B, N)``.
        """
        g = self.g
        if isinstance(bias, np.ndarray):
            bias = g.weight(f"{wname}.b", bias)
        if self.fmt == "float32":
            wt = g.weight(f"{wname}.W", w)
            if bias is None:
                return g.node("MatMul", [x, wt], name)
            return g.node("Gemm", [x, wt, bias], name)                   # (B, N)
        bits = 8 if self.fmt == "int8" else 4
        packed, scales, _ = quantize_blocks(w, bits, self.block_size)
        K, N = np.shape(w)
        inputs = [x, g.constant(f"{wname}.Wq{bits}", packed), g.constant(f"{wname}.scales", scales)]
        const_bias = bias is not None and g.is_initializer(bias)  # a constant (N,): MatMulNBits' own bias input
        if const_bias:
            inputs += ["", "", bias]                                     # no zero points, no g_idx
        y = g.node("MatMulNBits", inputs, name if bias is None or const_bias else f"{name}.mm",
                   domain="com.microsoft", K=int(K), N=int(N), bits=bits, block_size=self.block_size,
                   accuracy_level=self.accuracy_level)                   # (B, N)
        return y if bias is None or const_bias else g.node("Add", [y, bias], name)
