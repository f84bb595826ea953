"""``python -m deploy web DIR [DIR ...] [--port N]``: the exported models in a web page (spec/deploy.md §14).

The page (``deploy/web/``: ``index.html``, ``src/*.js``) runs the exported graphs in onnxruntime-web's WebAssembly
build and draws them with three.js, both npm packages pinned by ``deploy/web/package-lock.json`` and installed
with ``npm ci`` (:func:`build_page`). :func:`serve` serves it on 127.0.0.1 only with Python's ``http.server``:
a fixed table of URLs (:func:`routes`) built at start-up — the page, the two packages' files it imports, the
embedded sample clips and each folder's model files — and nothing else (no directory listing, GET/HEAD only,
a Content-Security-Policy that lets the page connect to this server alone).

The model list is a manifest (:func:`manifest`, served as ``/models/manifest.json``): per folder its model name
(``deploy.models.model_name_of_dir``), its files and every ``.onnx`` file's metadata (``metadata_props`` decoded
as JSON, which onnxruntime-web does not expose). A folder of another kind of model is listed too: the page says
which model it holds when a view needs another.

Shape legend: none (files and URLs).
"""
from __future__ import annotations

import base64
import hashlib
import http.server
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

__all__ = ["WEB_DIR", "SAMPLE_DIR", "NPM_FILES", "manifest", "routes", "build_page", "serve", "main_web"]

#: The page's folder (``index.html``, ``src/``, ``package.json``, ``package-lock.json``).
WEB_DIR = Path(__file__).resolve().parent / "web"
#: The embedded sample clips offered by the page.
SAMPLE_DIR = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"
#: URL prefix -> (folder under node_modules, the files the page may load from it).
NPM_FILES = {
    "/vendor/ort/": ("onnxruntime-web/dist", ("ort.wasm.min.mjs", "ort-wasm-simd-threaded.mjs",
                                              "ort-wasm-simd-threaded.wasm")),
    "/vendor/three/": ("three", ("build/three.module.js", "build/three.core.js",
                                 "examples/jsm/controls/OrbitControls.js")),
}
_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript", ".mjs": "text/javascript",
          ".css": "text/css", ".json": "application/json", ".wasm": "application/wasm", ".png": "image/png",
          ".bvh": "text/plain; charset=utf-8", ".txt": "text/plain; charset=utf-8",
          ".onnx": "application/octet-stream", ".npy": "application/octet-stream"}
_MODEL_SUFFIXES = (".onnx", ".npy")
_SAMPLES = (("bvh", "*.bvh", "bvh"), ("expmap/test/walking", "*.txt", "expmap"))


def manifest(folders) -> dict:
    """The model list of the page: ``{"folders": [{"id", "label", "path", "model", "files", "metadata"}],
    "samples": [{"name", "kind", "url"}]}``.

    Parameters
    ----------
    folders : sequence of path-like
        Folders written by ``python -m deploy export``.

    Raises
    ------
    ValueError
        A folder that does not exist or holds no exported model (the message names it).
    """
    from deploy.metadata import read_metadata
    from deploy.models import model_name_of_dir

    out = []
    for i, d in enumerate(folders):
        p = Path(d)
        if not p.is_dir():
            raise ValueError(f"{d}: no such folder of exported models")
        name = model_name_of_dir(p)
        files = sorted(f.name for f in p.iterdir() if f.is_file() and f.suffix in _MODEL_SUFFIXES)
        meta = {f: read_metadata(str(p / f)) for f in files if f.endswith(".onnx")}
        out.append({"id": i, "label": p.name or str(p), "path": str(p.resolve()), "model": name, "files": files,
                    "metadata": meta})
    return {"folders": out, "samples": _samples()}


def _samples() -> list:
    items = []
    for sub, pattern, kind in _SAMPLES:
        for f in sorted((SAMPLE_DIR / sub).glob(pattern)):
            items.append({"name": f"{sub.split('/')[-1]}/{f.name}", "kind": kind, "url": f"/sample/{sub}/{f.name}"})
    return items


def routes(folders_manifest: dict, web_dir: Path = WEB_DIR) -> dict:
    """URL path -> file path of everything the server answers (:data:`NPM_FILES`, the page, the samples, each
    folder's model files); any other URL is a 404."""
    table = {"/": web_dir / "index.html", "/index.html": web_dir / "index.html",
             "/style.css": web_dir / "style.css"}
    for f in sorted((web_dir / "src").glob("*.js")):
        table[f"/src/{f.name}"] = f
    modules = web_dir / "node_modules"
    for prefix, (folder, files) in NPM_FILES.items():
        for f in files:
            table[prefix + f] = modules / folder / f
    for s in folders_manifest["samples"]:
        table[s["url"]] = SAMPLE_DIR / s["url"][len("/sample/"):]
    for d in folders_manifest["folders"]:
        for f in d["files"]:
            table[f"/models/{d['id']}/{f}"] = Path(d["path"]) / f
    return table


def _csp(index_html: str) -> str:
    """A policy allowing this origin only (and the page's inline import map by its hash)."""
    hashes = " ".join(f"'sha256-{base64.b64encode(hashlib.sha256(m.encode()).digest()).decode()}'"
                      for m in re.findall(r"<script type=\"importmap\">(.*?)</script>", index_html, re.S))
    return (f"default-src 'self'; script-src 'self' 'wasm-unsafe-eval' {hashes}; connect-src 'self'; "
            "img-src 'self' data: blob:; style-src 'self'; worker-src 'self'; object-src 'none'; "
            "base-uri 'none'; form-action 'none'")


def _handler(table: dict, manifest_bytes: bytes, csp: str):
    class Handler(http.server.BaseHTTPRequestHandler):
        server_version = "refimpl-web"
        sys_version = ""
        timeout = 30

        def log_message(self, fmt, *args):  # quiet: one line per error only
            if args and str(args[1] if len(args) > 1 else "").startswith(("4", "5")):
                sys.stderr.write(f"python -m deploy web: {self.command} {self.path} -> {args[1]}\n")

        def _send(self, body: bytes | None, ctype: str, status: int = 200, length: int | None = None):
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body) if body is not None else length))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header("Content-Security-Policy", csp)
            self.end_headers()
            if body is not None and self.command != "HEAD":
                self.wfile.write(body)

        def do_GET(self):
            path = self.path.split("?", 1)[0]
            if path == "/models/manifest.json":
                return self._send(manifest_bytes, _TYPES[".json"])
            f = table.get(path)
            if f is None or not f.is_file():
                return self._send(b"not found\n", "text/plain", 404)
            try:
                data = f.read_bytes()
            except OSError:
                return self._send(b"unreadable\n", "text/plain", 500)
            return self._send(data, _TYPES.get(f.suffix, "application/octet-stream"))

        do_HEAD = do_GET

    return Handler


def build_page(web_dir: Path = WEB_DIR, *, quiet: bool = False) -> None:
    """``npm ci`` in ``web_dir`` when its ``node_modules`` lacks a file of :data:`NPM_FILES`.

    Raises
    ------
    refimpl.errors.MissingDependency
        node or npm is not installed, or ``npm ci`` fails (its last line in the message).
    """
    from refimpl.errors import MissingDependency

    for tool in ("node", "npm"):
        if shutil.which(tool) is None:
            raise MissingDependency(f"{tool} not found: the web page needs Node.js and npm to install its pinned "
                                    "packages (Debian: apt-get install nodejs npm)")
    modules = web_dir / "node_modules"
    if all((modules / folder / f).is_file() for folder, files in NPM_FILES.values() for f in files):
        return
    if not quiet:
        print(f"npm ci in {web_dir} (once: onnxruntime-web, three from package-lock.json) ...", flush=True)
    proc = subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--ignore-scripts"], cwd=web_dir,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or proc.stdout.strip().splitlines() or ["(no output)"])[-1]
        raise MissingDependency(f"npm ci failed in {web_dir}: {last}")


def serve(folders_manifest: dict, port: int = 8000, *, ready=None, web_dir: Path = WEB_DIR) -> None:
    """Serve the page for a :func:`manifest` on ``http://127.0.0.1:port/`` until interrupted (``port`` 0: any
    free port). ``ready(url)`` is called once the socket listens (default: print the URL); ``OSError`` when the
    port cannot be bound."""
    table = routes(folders_manifest, web_dir)
    csp = _csp((web_dir / "index.html").read_text(encoding="utf-8"))
    body = json.dumps(folders_manifest, separators=(",", ":")).encode()
    server = http.server.ThreadingHTTPServer(("127.0.0.1", int(port)), _handler(table, body, csp))
    server.daemon_threads = True
    server.request_queue_size = 16
    url = f"http://127.0.0.1:{server.server_address[1]}/"
    n = len(folders_manifest["folders"])
    (ready or (lambda u: print(f"serving {u} for {n} folder(s) (Ctrl-C to stop)", flush=True)))(url)
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()


def main_web(args) -> int:
    """``python -m deploy web``'s command: build if needed, then serve (exit codes of ``deploy/cli.py``)."""
    from refimpl.errors import BadInputError, UsageError

    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port: expected 0 ... 65535, got {args.port}")
    try:
        man = manifest(args.folders)                    # every folder checked before npm runs
    except ValueError as exc:
        raise BadInputError(str(exc)) from None
    build_page()
    try:
        serve(man, args.port)
    except OSError as exc:
        raise UsageError(f"--port {args.port}: cannot listen on 127.0.0.1 ({exc.strerror or exc})") from None
    return 0
