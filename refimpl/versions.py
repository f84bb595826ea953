"""The library versions a result was made with, recorded in every results file the demo and the benchmarks write
(spec/cli.md §8, issue #35): Python, NumPy and its BLAS (name, version, the kernel it chose, threads), and the
installed versions of the optional libraries (onnxruntime, onnx, SciPy, matplotlib, threadpoolctl).

The same network trained with another NumPy or another BLAS kernel rounds differently, and training amplifies
the rounding into another (equally good) number: a result is reproducible bit for bit only under the versions it
records. ``constraints.txt`` (the README's install) pins the versions the README's numbers were made with;
:func:`matches_locked` tells whether this environment has them.

Shapes: none (JSON-able dicts of strings and integers).
"""
from __future__ import annotations

import importlib.metadata
import os
import platform
from pathlib import Path

__all__ = ["library_versions", "with_versions", "blas_info", "locked_versions", "matches_locked", "CONSTRAINTS"]

#: The lock file of the README's install (``python -m pip install -c constraints.txt -e ".[all]"``).
CONSTRAINTS = Path(__file__).resolve().parents[1] / "constraints.txt"

_PACKAGES = ("numpy", "onnxruntime", "onnx", "scipy", "matplotlib", "threadpoolctl")


def _installed(name: str) -> str | None:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def blas_info() -> dict:
    """NumPy's BLAS as threadpoolctl sees it: ``{"name", "version", "kernel", "threads", "library"}`` (the
    kernel: OpenBLAS's ``architecture``, e.g. ``Haswell`` or ``SkylakeX``; ``OPENBLAS_CORETYPE`` forces one);
    ``{"name": None, ...}`` without threadpoolctl."""
    import numpy  # noqa: F401 - loads the BLAS library that threadpoolctl inspects

    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return {"name": None, "version": None, "kernel": None, "threads": None, "library": None,
                "note": "threadpoolctl is not installed"}
    blas = [d for d in threadpool_info() if d.get("user_api") == "blas"]
    if not blas:
        return {"name": None, "version": None, "kernel": None, "threads": None, "library": None}
    d = blas[0]
    return {"name": d.get("internal_api"), "version": d.get("version"), "kernel": d.get("architecture"),
            "threads": d.get("num_threads"), "library": os.path.basename(str(d.get("filepath", "")))}


def library_versions() -> dict:
    """What a results file records: ``{"python", "platform", "numpy", "blas": blas_info(), "onnxruntime", ...}``
    (a library that is not installed is None)."""
    out = {"python": platform.python_version(), "platform": platform.platform()}
    out.update({name: _installed(name) for name in _PACKAGES})
    out["blas"] = blas_info()
    env = {k: os.environ[k] for k in ("OPENBLAS_CORETYPE", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
           if k in os.environ}
    if env:
        out["blas_environment"] = env
    return out


def locked_versions(path=None) -> dict:
    """``{package: version}`` of the ``name==version`` lines of a constraints file (default ``constraints.txt``)."""
    text = Path(path or CONSTRAINTS).read_text(encoding="utf-8")
    pins = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        name, sep, version = line.partition("==")
        if sep:
            pins[name.strip().lower()] = version.strip()
    return pins


def matches_locked(recorded: dict | None = None, path=None) -> list[str]:
    """The differences between this environment (or ``recorded``, a :func:`library_versions` dict) and the lock
    file, one line each (``"numpy 2.3.0, locked 2.4.6"``); empty when every pinned package that
    :func:`library_versions` records has its locked version."""
    have = recorded if recorded is not None else library_versions()
    diffs = []
    for name, version in locked_versions(path).items():
        if name in have and have[name] != version:
            diffs.append(f"{name} {have[name]}, locked {version}")
    return diffs


def with_versions(doc: dict) -> dict:
    """``doc`` with its ``"versions"`` key set to :func:`library_versions` (a results file's record)."""
    return {**doc, "versions": library_versions()}
