"""The models in a web page (``python -m deploy web``, spec/deploy.md §14; issue #34), in a real headless Chromium.

Tiny models are trained on the embedded sample (``refimpl train ... --steps 2``) and exported; the page is served
by ``python -m deploy web`` on 127.0.0.1 and driven by ``tests/web/driver.mjs`` (playwright-core from
``deploy/web/node_modules``, Debian's ``/usr/bin/chromium``: no browser download). The frames the page generates
in onnxruntime-web (WebAssembly) equal ``python -m deploy run`` on the same inputs within 1e-4 — QTG (with the
join option in the rollout graph), the long-term walk along the path drawn with the mouse, QuaterNet's
continuation — and the downloaded BVH holds them; bad inputs give one visible line; every request goes to the
local server. Screenshots of each view are saved (``REFIMPL_WEB_SHOTS=DIR`` copies them there too).

Skipped when node, npm or chromium is absent (``.ci/run`` installs Debian's packages and runs ``npm ci``).
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

ROOT = Path(__file__).resolve().parents[1]
WEB = ROOT / "deploy" / "web"
SAMPLE = ROOT / "refimpl" / "data" / "sample"
CHROMIUM = os.environ.get("REFIMPL_CHROMIUM", "/usr/bin/chromium")
PLAYWRIGHT = WEB / "node_modules" / "playwright-core" / "index.mjs"

if shutil.which("node") is None or shutil.which("npm") is None or not Path(CHROMIUM).is_file():
    pytest.skip("node, npm or chromium is not installed (apt-get install nodejs npm chromium)",
                allow_module_level=True)

COMMON = ["--blas-threads", "1", "train", "--progress-every", "1", "--checkpoint-every", "100"]
TRAIN = {
    "qtg": ["--model", "qtg", "--steps", "2", "--batch-size", "8", "--stride", "8", "--test-fraction", "0.5",
            "--transition-length", "10", "--set", "encoder_sizes=16,8", "--set", "gru_hidden=8",
            "--set", "decoder_sizes=16"],
    "qn": ["--model", "quaternet", "--steps", "2", "--batch-size", "6", "--set", "hidden_size=8",
           "--set", "num_layers=1", "--set", "prefix_length=12", "--set", "target_length=4"],
    "long": ["--model", "quaternet-long", "--data", "sample", "--set", "hidden_size=8", "--locomotion-prefix", "6",
             "--locomotion-target", "8", "--batch-size", "4", "--steps", "2"],
    "pace": ["--model", "pace", "--data", "sample", "--steps", "2", "--batch-size", "4",
             "--pace-chunk-length", "60"],
}
QTG_START = 40                      # python -m deploy run --start: frames 40..49 generated (T = 10)
QN_FRAME = 40
WALK_SECONDS = 2


def _run(tool, *argv):
    """``python -m refimpl|deploy ARGV`` in this process (one interpreter start-up less per command)."""
    from deploy.cli import main as deploy_main
    from refimpl.cli import main as refimpl_main

    rc = {"-m refimpl": refimpl_main, "-m deploy": deploy_main}[tool](list(argv))
    assert rc == 0, (tool, argv)


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """``{"qtg": join export, "qn", "long" (step + pace)}`` of tiny trained models."""
    from deploy.serve import build_page
    from refimpl.errors import MissingDependency

    try:
        build_page()
    except MissingDependency as exc:
        pytest.skip(str(exc))
    root = tmp_path_factory.mktemp("web_models")
    for name, argv in TRAIN.items():
        _run("-m refimpl", *COMMON, *argv, "--out", str(root / f"run_{name}"))
    _run("-m refimpl", "export", "--checkpoint", str(root / "run_qtg" / "checkpoint.npz"), "--join",
         "inertialize", "--out", str(root / "qtg_join"), "--no-verify")
    _run("-m deploy", "export", str(root / "run_qn" / "checkpoint.npz"), str(root / "qn"))
    _run("-m deploy", "export", str(root / "run_long" / "checkpoint.npz"), str(root / "long"))
    _run("-m deploy", "export", str(root / "run_pace" / "checkpoint.npz"), str(root / "long"))
    return {"qtg": root / "qtg_join", "qn": root / "qn", "long": root / "long"}


@pytest.fixture(scope="module")
def server(folders):
    """``python -m deploy web`` on a free port; yields its URL."""
    proc = subprocess.Popen([sys.executable, "-m", "deploy", "web", str(folders["qtg"]), str(folders["long"]),
                             str(folders["qn"]), "--port", "0"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("serving http://127.0.0.1:"), (line, proc.stderr.read() if proc.poll() else "")
        yield line.split()[1]
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def page(server, tmp_path_factory):
    """The driver's run of every view: ``(out, shots folder)``."""
    work = tmp_path_factory.mktemp("web_page")
    shots = work / "shots"
    shots.mkdir()
    job = {"url": server, "chromium": CHROMIUM, "userDataDir": str(work / "profile"), "shots": str(shots),
           "qtg": {"folder": "qtg_join (qtg)", "clip": "bvh/02_01.bvh", "source": QTG_START - 1,
                   "target": QTG_START + 10},
           "walk": {"folder": "long (quaternet-long)", "speed": "walk", "seconds": WALK_SECONDS,
                    "drag": [[0.5, 0.5], [0.62, 0.5], [0.7, 0.56], [0.74, 0.68]]},
           "qn": {"folder": "qn (quaternet)", "clip": "walking/walking_1.txt", "frame": QN_FRAME},
           "bad": {"bvh": "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition\n",
                   "rigBvh": str(SAMPLE / "salsa" / "01.bvh"), "otherFolder": "qn (quaternet)"}}
    (work / "job.json").write_text(json.dumps(job))
    proc = subprocess.run(["node", str(ROOT / "tests" / "web" / "driver.mjs"), str(PLAYWRIGHT), str(work / "job.json"),
                           str(work / "out.json")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads((work / "out.json").read_text())
    assert out.get("error") is None, (out.get("error"), out.get("lastMessage"))
    copy = os.environ.get("REFIMPL_WEB_SHOTS")
    if copy:
        for f in shots.glob("*.png"):
            shutil.copy(f, Path(copy) / f"web_{f.name}")
    return out, shots


def _quat_close(a, b, tol=1e-4):
    """Max |a - b| over unit quaternions, each pair sign-aligned (q and -q are one rotation)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    s = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return float(np.max(np.abs(a - s * b)))


def test_qtg_transition_equals_python(page, folders, tmp_path):
    from refimpl.bvh import read_bvh

    out, _ = page
    assert out["messages"]["qtg"]["ok"], out["messages"]["qtg"]
    assert "join: inertialize" in out["messages"]["qtg"]["text"]
    _run("-m deploy", "run", str(folders["qtg"]), str(SAMPLE / "bvh" / "02_01.bvh"), str(tmp_path / "py.bvh"),
         "--start", str(QTG_START))
    from deploy.metadata import read_metadata

    names = read_metadata(str(folders["qtg"] / "qtg_rollout.onnx"))["skeleton"]["names"]    # the page's order
    py = read_bvh(tmp_path / "py.bvh")
    idx = [list(py.skeleton.names).index(n) for n in names]
    rot_py = np.asarray(py.rotations)[QTG_START:QTG_START + 10][:, idx]      # (T, 22, 4)
    pos_py = np.asarray(py.root_positions)[QTG_START:QTG_START + 10]
    rot_js, pos_js = np.asarray(out["qtg"]["rot"]), np.asarray(out["qtg"]["pos"])
    assert rot_js.shape == rot_py.shape == (10, 22, 4)
    assert _quat_close(rot_js, rot_py) < 1e-4                                  # 6 decimals of degrees in the file
    assert np.max(np.abs(pos_js - pos_py)) < 1e-4 * max(1.0, np.max(np.abs(pos_py)))
    # the downloaded BVH holds the transition: frames start .. stop of the page's result
    dl = read_bvh(Path(page[1]) / "transition.bvh")
    a, b = out["qtg"]["start"], out["qtg"]["stop"]
    dl_names = list(dl.skeleton.names)
    didx = [dl_names.index(n) for n in names]
    assert _quat_close(np.asarray(dl.rotations)[a:b][:, didx], rot_js) < 1e-4
    assert np.max(np.abs(np.asarray(dl.root_positions)[a:b] - pos_js)) < 1e-4 * max(1.0, np.max(np.abs(pos_js)))


def test_walk_along_the_drawn_path_equals_python(page, folders, tmp_path):
    out, _ = page
    assert out["messages"]["walk"]["ok"], out["messages"]["walk"]
    points = out["walk"]["points"]                                            # metres, from the mouse
    assert len(points) >= 10
    with open(tmp_path / "path.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([[repr(float(x)), repr(float(z))] for x, z in points])
    _run("-m deploy", "run", str(folders["long"]), str(tmp_path / "path.csv"), str(tmp_path / "walk.npy"),
         "--speed", "walk", "--seconds", str(WALK_SECONDS))
    py = np.load(tmp_path / "walk.npy")
    js = np.asarray(out["walk"]["frames"])
    assert js.shape == py.shape and js.shape[0] > 10, (js.shape, py.shape)
    J = (py.shape[1] - 3) // 4
    assert _quat_close(js[:, :4 * J].reshape(-1, J, 4), py[:, :4 * J].reshape(-1, J, 4)) < 1e-4
    root_js, root_py = js[:, 4 * J:], py[:, 4 * J:]
    assert np.max(np.abs(root_js - root_py)) < 1e-4 * max(1.0, np.max(np.abs(root_py)))


def test_quaternet_continuation_equals_python(page, folders, tmp_path):
    out, _ = page
    assert out["messages"]["qn"]["ok"], out["messages"]["qn"]
    _run("-m deploy", "run", str(folders["qn"]), str(SAMPLE / "expmap" / "test" / "walking" / "walking_1.txt"),
         str(tmp_path / "pred.npy"), "--start", str(QN_FRAME))
    py = np.load(tmp_path / "pred.npy")                                       # (k, J, 4)
    js = np.asarray(out["qn"]["pred"])
    assert js.shape == py.shape == (10, 38, 4)
    assert _quat_close(js, py) < 1e-4


def test_bad_inputs_give_one_visible_line(page):
    out, _ = page
    m = out["messages"]
    expected = {"malformed": "broken.bvh", "rig": "a clip of another rig",
                "otherFolder": "holds the models of quaternet, not qtg", "onePoint": "at least two points"}
    for key, phrase in expected.items():
        assert not m[key]["ok"] and m[key]["text"].startswith("error: "), (key, m[key])
        assert phrase in m[key]["text"] and "\n" not in m[key]["text"], (key, m[key])
    assert out["console"] == [], out["console"]                               # no script error, no failed load


def test_nothing_leaves_the_local_server(page, server):
    out, _ = page
    assert out["requests"]
    foreign = [u for u in out["requests"] if not u.startswith((server, "blob:", "data:"))]
    assert foreign == []


def test_screenshots_of_every_view(page):
    _, shots = page
    for view in ("qtg", "walk", "qn"):
        png = shots / f"{view}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_server_answers_only_its_table(server):
    import urllib.error
    import urllib.request

    with urllib.request.urlopen(server + "models/manifest.json", timeout=10) as r:
        man = json.loads(r.read())
        assert "connect-src 'self'" in r.headers["Content-Security-Policy"]
    assert {f["model"] for f in man["folders"]} == {"qtg", "quaternet-long", "quaternet"}
    for bad in ("vendor/ort/", "src/", "../pyproject.toml", "models/0/../../x", "sample/", "node_modules/three/package.json"):
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(server + bad, timeout=10)
        assert exc.value.code == 404, bad
