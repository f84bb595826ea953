"""``deploy.serve`` without a browser (spec/deploy.md §14): the manifest of exported folders, the URL table, the
server's answers (only its table, a same-origin CSP, nothing outside), ``build_page``'s missing-tool error.
The page itself in Chromium: ``tests/test_web.py``."""
from __future__ import annotations

import json
import threading
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from deploy.models.qtg_io import export_dir  # noqa: E402
from deploy.serve import NPM_FILES, WEB_DIR, build_page, manifest, routes, serve  # noqa: E402
from refimpl.errors import MissingDependency  # noqa: E402
from refimpl.models.qtg import QTGConfig, init_params  # noqa: E402

SMALL = QTGConfig(pose_size=91, encoder_sizes=(8,), gru_hidden=8, decoder_sizes=(8,), transition_length=3)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("qtg_export")
    export_dir(init_params(SMALL, np.random.default_rng(0), dtype=np.float32), SMALL, d)
    return d


def test_manifest_lists_model_files_and_metadata(folder, tmp_path):
    man = manifest([folder])
    (entry,) = man["folders"]
    assert entry["model"] == "qtg" and entry["files"] == ["qtg_init.onnx", "qtg_rollout.onnx", "qtg_step.onnx"]
    assert entry["metadata"]["qtg_rollout.onnx"]["model"]["transition_length"] == 3
    assert {s["kind"] for s in man["samples"]} == {"bvh", "expmap"}
    with pytest.raises(ValueError, match="no such folder"):
        manifest([tmp_path / "nope"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no .onnx models"):
        manifest([tmp_path / "empty"])


def test_routes_are_a_fixed_table(folder):
    table = routes(manifest([folder]))
    assert table["/"] == WEB_DIR / "index.html" and "/src/app.js" in table
    assert {f"/models/0/{f}" for f in ("qtg_init.onnx", "qtg_rollout.onnx", "qtg_step.onnx")} <= set(table)
    assert all(prefix + f in table for prefix, (_, files) in NPM_FILES.items() for f in files)
    assert not any(".." in url or url.endswith("/") and url != "/" for url in table)


def test_server_answers_its_table_only(folder):
    urls = []
    t = threading.Thread(target=serve, args=(manifest([folder]), 0), kwargs={"ready": urls.append}, daemon=True)
    t.start()
    for _ in range(200):
        if urls:
            break
        t.join(0.05)
    base = urls[0]
    assert base.startswith("http://127.0.0.1:")
    with urllib.request.urlopen(base + "models/manifest.json", timeout=10) as r:
        assert json.loads(r.read())["folders"][0]["model"] == "qtg"
        assert "connect-src 'self'" in r.headers["Content-Security-Policy"]
    with urllib.request.urlopen(base + "models/0/qtg_step.onnx", timeout=10) as r:
        assert r.read() == (folder / "qtg_step.onnx").read_bytes()
    for bad in ("src/", "models/0/", "../pyproject.toml", "models/0/../../x", "deploy/serve.py"):
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(base + bad, timeout=10)
        assert exc.value.code == 404, bad


def test_build_page_without_node(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(MissingDependency, match="node not found"):
        build_page()


def test_web_command_exit_codes(folder, tmp_path, monkeypatch):
    """``python -m deploy web``: 3 for a missing folder or one without models (before npm runs), 2 for a bad
    port, 1 without node / npm; one line on stderr each."""
    from deploy.cli import main

    assert main(["web", str(tmp_path / "nope")]) == 3
    (tmp_path / "empty").mkdir()
    assert main(["web", str(tmp_path / "empty")]) == 3
    assert main(["web", str(folder), "--port", "70000"]) == 2
    monkeypatch.setenv("PATH", str(tmp_path))                                # no node, no npm
    assert main(["web", str(folder)]) == 1
