"""deploy/examples/qtg_rollout.c: built with the C compiler and run against exported QTG models, compared with
Python's onnxruntime (deploy/README.md "Embedded use").

Needs a C compiler (``$CC``, ``cc``, ``gcc`` or ``clang``) and onnxruntime's C headers: set ``ORT_C_DIR`` to an
unpacked ``onnxruntime-linux-x64-<version>.tgz`` (``include/onnxruntime_c_api.h``, ``lib/libonnxruntime.so*``), or
to the root of Debian's ``libonnxruntime-dev`` files (``include/onnxruntime/onnxruntime_c_api.h``; ``/usr`` once
installed).
Without ``lib/`` the shared library of the installed ``onnxruntime`` wheel is used (it ships the library, not the
headers). The header's ``ORT_API_VERSION`` must not exceed the library's version (1.N provides API versions
<= N). Skips cleanly when any of this is missing.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "deploy" / "examples" / "qtg_rollout.c"
FOOTLOCK_SOURCE = ROOT / "deploy" / "examples" / "qtg_footlock.c"  # compiled with it (--footlock)


def test_source_reads_sizes_from_the_model():
    """No hard-coded pose size, and the frame loop cannot spin on T = 1 (issue 16)."""
    text = SOURCE.read_text()
    assert "t += T - 1" not in text
    assert not re.search(r"\b91\b", re.sub(r"/\*.*?\*/", "", text, flags=re.S)), "pose size 91 hard-coded"
    assert "SessionGetInputTypeInfo" in text and "SessionGetOutputTypeInfo" in text


# ------------------------------------------------------------------------------------------------------------
# the model: the only use of the deploy API (adapt here if the exporter's API changes)
# ------------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def export_rollout(tmp_path_factory):
    """``export(T, pose_size) -> path`` of a small float32 QTG rollout model (random weights)."""
    onnx = pytest.importorskip("onnx")
    from deploy.models.qtg import export_qtg_rollout
    from refimpl.models.qtg import QTGConfig, init_params

    folder = tmp_path_factory.mktemp("c_models")

    def export(T: int, pose_size: int, join: str = "none") -> Path:
        config = QTGConfig(pose_size=pose_size, encoder_sizes=(9, 6), gru_hidden=5, gru_layers=2,
                           decoder_sizes=(8,), negative_slope=0.05, transition_length=T)
        path = folder / f"qtg_rollout_T{T}_P{pose_size}_{join}.onnx"
        onnx.save(export_qtg_rollout(init_params(config, np.random.default_rng(0)), config, join=join), str(path))
        return path

    return export


# ------------------------------------------------------------------------------------------------------------
# toolchain
# ------------------------------------------------------------------------------------------------------------

def _compiler():
    for cc in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


def _wheel_library():
    """(path, version) of the installed onnxruntime wheel's shared library, or None."""
    try:
        import onnxruntime
    except ImportError:
        return None
    libs = sorted((Path(onnxruntime.__file__).parent / "capi").glob("libonnxruntime.so.*"))
    return (libs[0], onnxruntime.__version__) if libs else None


def build_example(tmp_path_factory, source, name: str, extra=()) -> Path:
    """Build ``source`` (a path or a tuple of paths) with ``-Wall -Wextra`` (+ ``extra``) against ``$ORT_C_DIR``'s headers and its ``lib/`` (or
    the wheel's library); ``pytest.skip`` when the compiler, headers or a fitting library are missing."""
    cc = _compiler()
    if cc is None:
        pytest.skip("no C compiler (set CC, or install cc/gcc/clang)")
    ort = os.environ.get("ORT_C_DIR")
    if not ort:
        pytest.skip("ORT_C_DIR not set: point it at an unpacked onnxruntime-linux-x64-<version>.tgz "
                    "(include/onnxruntime_c_api.h; see deploy/README.md)")
    header = Path(ort) / "include" / "onnxruntime_c_api.h"
    if not header.is_file():  # Debian's libonnxruntime-dev: ORT_C_DIR=/usr, /usr/include/onnxruntime/
        header = Path(ort) / "include" / "onnxruntime" / "onnxruntime_c_api.h"
    if not header.is_file():
        pytest.skip(f"{Path(ort) / 'include' / 'onnxruntime_c_api.h'} not found")
    api = re.search(r"#define\s+ORT_API_VERSION\s+(\d+)", header.read_text(errors="replace"))
    if api is None:
        pytest.skip(f"{header}: no ORT_API_VERSION")
    work = tmp_path_factory.mktemp(f"c_build_{name}")
    libs = sorted((Path(ort) / "lib").glob("libonnxruntime.so*"))
    if libs:
        lib_dir = Path(ort) / "lib"
        found = re.search(r"libonnxruntime\.so\.(\d+\.\d+\.\d+)", " ".join(p.name for p in libs))
        version = found.group(1) if found else None
    else:  # the pip wheel's library, under the names the linker and the loader look for
        wheel = _wheel_library()
        if wheel is None:
            pytest.skip(f"no library in {ort}/lib and no onnxruntime wheel")
        lib_dir = work / "lib"
        lib_dir.mkdir()
        for lib in ("libonnxruntime.so", "libonnxruntime.so.1"):
            (lib_dir / lib).symlink_to(wheel[0])
        version = wheel[1]
    if version is not None and int(api.group(1)) > int(version.split(".")[1]):
        pytest.skip(f"header ORT_API_VERSION {api.group(1)} is newer than the library {version}: "
                    "use headers of the library's release")
    exe = work / name
    sources = [str(s) for s in (source if isinstance(source, (tuple, list)) else (source,))]
    build = subprocess.run([cc, "-O2", "-Wall", "-Wextra", *extra, *sources, f"-I{header.parent}", f"-L{lib_dir}",
                            "-lonnxruntime", "-lm", f"-Wl,-rpath,{lib_dir}", "-o", str(exe)],
                           capture_output=True, text=True, timeout=120)
    assert build.returncode == 0, build.stderr
    assert "warning" not in build.stderr, build.stderr
    return exe


@pytest.fixture(scope="module")
def binary(tmp_path_factory):
    return build_example(tmp_path_factory, (SOURCE, FOOTLOCK_SOURCE), "qtg_rollout", extra=("-Werror",))


def _python_rollout(model: Path, past: np.ndarray, target: np.ndarray) -> np.ndarray:
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    session = onnxruntime.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
    return session.run(["poses"], {"past": past, "target": target})[0]


@pytest.mark.parametrize("T, P, join", [(1, 11, "none"), (4, 11, "none"), (3, 15, "none"), (6, 15, "inertialize")])
def test_c_example_matches_python(binary, export_rollout, tmp_path, T, P, join):
    """Sizes come from the model (P = 11 and 15, no 91), T = 1 terminates, the output equals onnxruntime's in
    Python (same library, same options: to float32 rounding); a model exported with the join option runs its
    joins inside the graph (spec/qtg.md §7.4) and the example says so."""
    model = export_rollout(T, P, join)
    rng = np.random.default_rng(T * 100 + P)
    past = rng.normal(size=(1, 2, P)).astype(np.float32)
    target = rng.normal(size=(1, 2, P)).astype(np.float32)
    inputs, outputs = tmp_path / "inputs.f32", tmp_path / "poses.f32"
    np.concatenate([past.ravel(), target.ravel()]).astype("<f4").tofile(inputs)
    run = subprocess.run([str(binary), str(model), str(inputs), str(outputs)], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0, run.stderr
    assert f"context C = 2, pose P = {P}, T = {T}" in run.stdout
    assert ("join: none" in run.stdout) == (join == "none")
    assert ('"mode": "inertialize"' in run.stdout) == (join == "inertialize")
    frames = re.findall(r"^frame (\d+):", run.stdout, flags=re.M)
    assert frames == (["1"] if T == 1 else ["1", str(T)])
    got = np.fromfile(outputs, dtype="<f4").reshape(1, T, P)
    want = _python_rollout(model, past, target)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    first = [float(v) for v in re.search(r"^frame 1: root (\S+) (\S+) ([^\s,]+)", run.stdout, flags=re.M).groups()]
    np.testing.assert_allclose(first, want[0, 0, :3], atol=2e-6)


def test_c_example_identity_inputs_and_usage(binary, export_rollout, tmp_path):
    """Without an inputs file the example builds identity poses of the model's size; bad usage exits 2."""
    model = export_rollout(1, 15)
    run = subprocess.run([str(binary), str(model)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    past = np.zeros((1, 2, 15), np.float32)
    past[..., 3::4] = 1  # w of each joint quaternion
    want = _python_rollout(model, past, past)
    first = [float(v) for v in re.search(r"^frame 1: root (\S+) (\S+) ([^\s,]+)", run.stdout, flags=re.M).groups()]
    np.testing.assert_allclose(first, want[0, 0, :3], atol=2e-6)
    assert subprocess.run([str(binary)], capture_output=True, timeout=30).returncode == 2
    short = tmp_path / "short.f32"
    np.zeros(2 * 2 * 15 - 1, "<f4").tofile(short)  # one value short of 2·C·P
    bad = subprocess.run([str(binary), str(model), str(short)], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 1 and "inputs file" in bad.stderr
