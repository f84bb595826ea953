"""deploy/examples/quaternet_step.c: QuaterNet's online loop (init, then one step per frame with the carried GRU
state, predictions fed back) through onnxruntime's C API, built with ``-Wall -Wextra -Werror`` and compared with
Python (deploy/README.md "Embedded use", spec/deploy.md §10).

Same toolchain rules as ``tests/test_c_example.py`` (``ORT_C_DIR`` with ``include/onnxruntime_c_api.h``; its
``lib/`` or the wheel's library); skips cleanly without them. The prefix has two joints' quaternions negated, so
the C program's sign rule (read from the metadata's ``input_transform``) is exercised.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.test_c_example import build_example

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "deploy" / "examples" / "quaternet_step.c"
J, H, L, K = 5, 7, 2, 6


def test_source_reads_everything_from_the_model():
    text = re.sub(r"/\*.*?\*/", "", SOURCE.read_text(), flags=re.S)
    assert "SessionGetInputTypeInfo" in text and "ModelMetadataLookupCustomMetadataMap" in text
    assert '"representation"' in text and '"input_transform"' in text
    assert not re.search(r"\b(152|38|1000)\b", text), "a model size is hard-coded"


@pytest.fixture(scope="module")
def binary(tmp_path_factory):
    return build_example(tmp_path_factory, SOURCE, "quaternet_step", extra=("-Werror",))


@pytest.fixture(scope="module", params=["default", "portable"])
def model(tmp_path_factory, request):
    """A small exported QuaterNet (random weights), today's graphs and the portable ones (spec/deploy.md §13: the
    same names, batch 1, primitive GRU cells): ``(folder, params, config)``."""
    pytest.importorskip("onnxruntime")
    from deploy.models.quaternet_io import export_dir as export_quaternet_dir
    from refimpl.models.quaternet import QuaterNetConfig, init_params

    config = QuaterNetConfig(num_joints=J, hidden_size=H, num_layers=L)
    params = init_params(config, np.random.default_rng(3), dtype=np.float32)
    folder = tmp_path_factory.mktemp(f"c_qn_model_{request.param}")
    export_quaternet_dir(params, config, folder, k=K, target=request.param)
    return folder, params, config


def _prefix(P=9):
    rng = np.random.default_rng(5)
    q = np.cumsum(0.2 * rng.standard_normal((P, J, 4)), axis=0) + np.array([1.0, 0, 0, 0])
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[:4, 1] *= -1                                   # the same rotations with other signs
    q[:, 3] *= -1
    return q


def test_c_loop_matches_python(binary, model, tmp_path):
    from deploy.models.quaternet_io import Runtime as QuaterNetRuntime
    from refimpl.models import quaternet as rnn
    from refimpl.protocols.prediction import canonical_prefix

    folder, params, config = model
    x = _prefix()
    P = x.shape[0]
    x.astype("<f4").tofile(tmp_path / "prefix.f32")
    run = subprocess.run([str(binary), str(folder), str(tmp_path / "prefix.f32"), str(P), str(K),
                          str(tmp_path / "frames.f32")], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert f"F = {4 * J}, J = {J}, L = {L}, H = {H}; sign rule applied here: yes" in run.stdout
    got = np.fromfile(tmp_path / "frames.f32", "<f4").reshape(K, J, 4)
    rt = QuaterNetRuntime.from_dir(folder)
    loop = rt.predict(x[None], K, use_graph=False)[0]                     # Python: init + step loop
    graph = rt.predict(x[None], K)[0]                                     # the predict graph (sign rule inside);
    #                                                                       the portable folder has none: the loop
    numpy = rnn.predict(params, canonical_prefix(x[None]).reshape(1, P, -1).astype(np.float32), K,
                        config).reshape(K, J, 4)                          # NumPy on the canonical prefix
    assert np.abs(got - loop).max() <= 1e-5
    assert np.abs(got - graph).max() <= 1e-5
    assert np.abs(got - numpy).max() <= 1e-5
    first = [float(v) for v in re.search(r"^frame 1: joint 0 q (\S+) (\S+) (\S+) (\S+)", run.stdout,
                                         flags=re.M).groups()]
    np.testing.assert_allclose(first, got[0, 0], atol=2e-6)


def test_c_loop_usage_and_bad_inputs(binary, model, tmp_path):
    folder = model[0]
    assert subprocess.run([str(binary)], capture_output=True, timeout=30).returncode == 2
    assert subprocess.run([str(binary), str(folder), "x", "0", "3"], capture_output=True, timeout=30).returncode == 2
    np.zeros(4 * J * 3 - 1, "<f4").tofile(tmp_path / "short.f32")
    bad = subprocess.run([str(binary), str(folder), str(tmp_path / "short.f32"), "3", "2"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 1 and "prefix file" in bad.stderr
