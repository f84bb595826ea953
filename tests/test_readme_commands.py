"""Every command of README.md and deploy/README.md runs as written (issue #35): a documented command that fails is
a failing test.

Each ```bash / ```sh block of the two pages is split into commands (``\\`` continues a line, ``#`` starts a
comment, ``&&`` separates commands). Every command is parsed by its own parser (``refimpl``'s, ``python -m
deploy``'s), and then run, in the order of the page, in one scratch folder per page that holds ``refimpl/``
(the embedded sample), ``examples/``, ``deploy/`` and ``pretrained/`` and has ``../shared`` beside it (a link to the real one), so
the relative paths of the pages resolve as in a clone. Blocks that need earlier outputs get them from the
commands before them; the few inputs a page names without making them are made first (:data:`SETUP`).

What changes, declared here (nothing else is touched):

* :data:`BUDGETS`: budgets become tiny (``--steps 2``, small hidden sizes, a 2 s walk, 40 of the locomotion
  set's files), so the whole file takes a few minutes on an idle machine; the commands, paths and every other
  option are the page's.
* :data:`NOT_RUN`: the install (this environment is it; ``test_ci_installs_as_the_readme_says`` checks that
  ``.ci/run`` runs the README's line), ``refimpl demo`` (``.ci/run`` runs it as written before the tests), the
  test suite itself, and the C build and run (``tests/test_c_example.py`` builds and runs it with ``ORT_C_DIR``).
* :data:`SERVERS`: ``python -m deploy web ...`` serves until Ctrl-C: it is started as written, its page fetched
  from the address it prints and checked to list the folders' models, then stopped with SIGINT (exit 0). Its
  ``demo_out/onnx`` is ``refimpl demo``'s output: the folder ``REFIMPL_DEMO_OUT`` names (``.ci/run`` sets it to
  the demo it ran), linked into the scratch folder; without it those commands are skipped. A port the page
  names that is already taken skips the command.
* Commands that need ``../shared`` are skipped when it is absent (they are still parsed).
* Nothing else is skipped: the QTG commands on the Bandai Namco set read its 830 takes once (~30 s idle) and
  then from the data cache (``refimpl/protocols/transition_cache.py``).
"""
from __future__ import annotations

import functools
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
PAGES = ("README.md", "deploy/README.md")
FENCE = re.compile(r"^```(bash|sh)\s*$")

#: Seconds one command may take (the slowest, the first read of the locomotion set, takes ~1 min idle).
TIMEOUT_S = 1200

#: (regular expression, replacement) applied to every command's text: the budgets, nothing else.
BUDGETS = [
    (r"--steps \d+", "--steps 2"),
    (r"--epochs \d+", "--steps 2"),
    (r"hidden_size=\d+", "hidden_size=16"),
    (r"channels=\d+", "channels=16"),
    (r"--seconds \d+", "--seconds 2"),
    (r"--length 300\b", "--length 12"),
    (r"--frames 300\b", "--frames 12"),
    # the locomotion networks read 40 of the 830 files (the whole set: minutes on a loaded machine)
    (r"(--model (?:pace|quaternet-long) --data \.\./shared/data/bandai_namco_locomotion)",
     r"\1 --locomotion-max-files 40"),
    # the imported acRNN is a small one (the setup exports a 16-unit network): its evaluation takes seconds
    (r"^(refimpl import weights\.npz --model acrnn)", r"\1 --set hidden_size=16"),
]

#: Options the budgets may add to a command.
ADDED = ("--locomotion-max-files", "--set")

#: Commands not run (prefix of the command's text -> why).
NOT_RUN = {
    "python -m pip install": "the environment of this test is the install (.ci/run runs the README's line)",
    "python -m pytest": "the test suite itself",
    "refimpl demo": ".ci/run runs it as written before the tests (tests/test_versions.py compares its numbers with "
                    "benchmarks/results/demo_eval.json); tests/test_demo.py runs demo --quick",
    "cc ": "the C example (shell variables, a C compiler): tests/test_c_example.py builds it with ORT_C_DIR",
    "LD_LIBRARY_PATH=": "the C example: tests/test_c_example.py runs it with ORT_C_DIR",
}

#: Commands that serve until Ctrl-C (prefix): run as written, the page fetched from the address they print, then
#: stopped with SIGINT (exit 0 expected). tests/test_web.py drives headless Chromium through the same server.
SERVERS = ("python -m deploy web",)
#: Seconds a server may take to print its address (the first start runs ``npm ci``).
SERVER_START_S = 300


_TINY_QTG = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]
#: Inputs a page names without making them: made before the page's first command (refimpl argv lists).
SETUP = {
    "README.md": [
        # published names of a small acRNN (BUDGETS imports it with --set hidden_size=16)
        ["train", "--model", "acrnn", "--data", "../shared/data", "--set", "hidden_size=16", "--steps", "1",
         "--out", "setup/acrnn"],
        ["export-weights", "setup/acrnn/checkpoint.npz", "--out", "weights.npz"],
    ],
    "deploy/README.md": [
        ["train", "--model", "qtg", "--steps", "2", *_TINY_QTG, "--out", "runs/qtg"],
        ["train", "--model", "quaternet", "--steps", "2", "--set", "hidden_size=16", "--out", "runs/quaternet"],
        ["train", "--model", "acrnn", "--steps", "2", "--set", "hidden_size=16", "--out", "runs/acrnn"],
        ["train", "--model", "quaternet-long", "--data", "../shared/data/bandai_namco_locomotion", "--steps", "2",
         "--set", "hidden_size=16", "--locomotion-max-files", "40", "--out", "runs/long"],
        ["train", "--model", "pace", "--data", "../shared/data/bandai_namco_locomotion", "--steps", "2",
         "--locomotion-max-files", "40", "--out", "runs/pace"],
    ],
}


@dataclass(frozen=True)
class Command:
    page: str
    line: int
    text: str   # as written (continuations joined, comment removed)
    argv: tuple  # after BUDGETS

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"


def _logical_lines(block: list[tuple[int, str]]):
    buf, start = "", None
    for n, line in block:
        if start is None:
            start = n
        if line.rstrip().endswith("\\"):
            buf += line.rstrip()[:-1] + " "
            continue
        yield start, buf + line
        buf, start = "", None


def page_commands(page: str) -> list[Command]:
    """The commands of ``page``'s ```bash / ```sh blocks, in order."""
    lines = (ROOT / page).read_text(encoding="utf-8").splitlines()
    out, block, inside = [], [], False
    for n, line in enumerate(lines, 1):
        if not inside and FENCE.match(line):
            inside, block = True, []
        elif inside and line.startswith("```"):
            inside = False
            for start, text in _logical_lines(block):
                tokens = shlex.split(text, comments=True)
                while tokens:
                    cut = tokens.index("&&") if "&&" in tokens else len(tokens)
                    written = shlex.join(tokens[:cut])
                    budget = written
                    for pattern, repl in BUDGETS:
                        budget = re.sub(pattern, repl, budget)
                    out.append(Command(page, start, written, tuple(shlex.split(budget))))
                    tokens = tokens[cut + 1:]
        elif inside:
            block.append((n, line))
    return out


def _kind(argv) -> str:
    if argv[0] == "refimpl":
        return "refimpl"
    if argv[:3] == ("python", "-m", "deploy"):
        return "deploy"
    return "other"


@functools.lru_cache(maxsize=None)
def _parser_of(kind: str):
    if kind == "refimpl":
        from refimpl.cli import build_parser

        return build_parser()
    from deploy.cli import _parser

    return _parser()


def _parse(cmd: Command) -> None:
    """The command's own parser accepts it (an unknown option, a typo of the page: exit 2 here)."""
    kind = _kind(cmd.argv)
    if kind == "other":
        return
    parser, rest = _parser_of(kind), list(cmd.argv[1:] if kind == "refimpl" else cmd.argv[3:])
    try:
        parser.parse_args(rest)
    except SystemExit as exc:
        pytest.fail(f"{cmd.id}: `{cmd.text}` does not parse (exit {exc.code})")


def _not_run(cmd: Command) -> str | None:
    plain = " ".join(shlex.split(cmd.text))   # unquoted (shlex.join quotes `VAR=$X`)
    for prefix, why in NOT_RUN.items():
        if plain.startswith(prefix):
            return why
    return None


def _workspace(tmp: Path) -> Path:
    """A folder laid out as a clone: refimpl/, examples/, deploy/, pretrained/ linked; ../shared beside it."""
    work = tmp / "repo"
    work.mkdir()
    for name in ("refimpl", "examples", "deploy", "pretrained", "constraints.txt"):
        if (ROOT / name).exists():
            (work / name).symlink_to(ROOT / name)
    if SHARED.is_dir():
        (tmp / "shared").symlink_to(SHARED)
    return work


def _run(cmd: Command, cwd: Path) -> tuple[int, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    argv = list(cmd.argv)
    if argv[0] == "refimpl":
        argv = [sys.executable, "-m", "refimpl", *argv[1:]]
    elif argv[0] == "python":
        argv = [sys.executable, *argv[1:]]
    try:
        p = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        out = (exc.stdout or b"").decode(errors="replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        return -9, f"timed out after {TIMEOUT_S} s (a loaded machine?)\n{out[-1500:]}"
    return p.returncode, (p.stdout[-1500:] + p.stderr[-1500:])


def _serve(cmd: Command, cwd: Path) -> tuple[int, str]:
    """Start a :data:`SERVERS` command as written, fetch its page and model list from the address it prints, stop
    it with SIGINT: ``(exit code, log)``; a page or manifest that does not answer is reported as exit -1."""
    import json
    import signal
    import urllib.request

    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    argv = [sys.executable, *cmd.argv[1:]]
    p = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    log, url, t0 = [], None, time.monotonic()
    try:
        while url is None and time.monotonic() - t0 < SERVER_START_S:
            line = p.stdout.readline()
            if not line:
                break                                     # exited before serving
            log.append(line)
            m = re.search(r"serving (http://127\.0\.0\.1:\d+/)", line)
            url = m.group(1) if m else None
        if url is None:
            p.kill()
            return (p.wait(30) or -1), "".join(log)[-1500:] + "\n(no address printed)"
        with urllib.request.urlopen(url, timeout=30) as r:
            page = r.read().decode()
        with urllib.request.urlopen(url + "models/manifest.json", timeout=30) as r:
            folders = json.loads(r.read())["folders"]
        named = [a for a in cmd.argv[4:] if not a.startswith("-")]
        if "<html" not in page.lower() or len(folders) != len(named) or not all(f["files"] for f in folders):
            p.kill()
            p.wait(30)
            return -1, f"page or manifest wrong: {len(folders)} folders for {named}"
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    try:
        rc = p.wait(30)
    except subprocess.TimeoutExpired:
        p.kill()
        return -9, "did not stop on SIGINT within 30 s"
    return rc, "".join(log)[-1500:] + p.stdout.read()[-1500:]


def _server_skip(cmd: Command, work: Path) -> str | None:
    """Why a :data:`SERVERS` command cannot run here (None: it can): its port taken, no npm for the page's
    packages, or ``refimpl demo``'s output not available."""
    import socket

    from deploy.serve import NPM_FILES, WEB_DIR

    argv = list(cmd.argv)
    port = int(argv[argv.index("--port") + 1]) if "--port" in argv else 8000
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as http.server does (a stopped server's TIME_WAIT)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return f"port {port} is taken on this machine"
    modules = WEB_DIR / "node_modules"
    have = all((modules / folder / f).is_file() for folder, files in NPM_FILES.values() for f in files)
    if not have and not shutil.which("npm"):
        return "the page's npm packages are not installed and there is no npm"
    if "demo_out/onnx" in argv and not (work / "demo_out" / "onnx").is_dir():
        demo = os.environ.get("REFIMPL_DEMO_OUT")
        if not demo or not (Path(demo) / "onnx").is_dir():
            return "needs `refimpl demo`'s ./demo_out (REFIMPL_DEMO_OUT names it; .ci/run sets it)"
        (work / "demo_out").symlink_to(Path(demo).resolve())
    return None


def _needs_shared(cmd: Command) -> bool:
    return "../shared" in cmd.text


def _setup(page: str, work: Path) -> None:
    for argv in SETUP.get(page, ()):
        if "../shared" in " ".join(argv) and not SHARED.is_dir():
            continue
        cmd = Command(page, 0, "refimpl " + shlex.join(argv), ("refimpl", *argv))
        rc, log = _run(cmd, work)
        assert rc == 0, f"setup `{cmd.text}` failed:\n{log}"
    if page == "deploy/README.md":  # the path CSV and the .npy frames the page's walk commands read
        (work / "path.csv").write_text("x,z\n" + "\n".join(f"{0.05 * i:.2f},{0.01 * i:.2f}" for i in range(80)))


def _frames_for_the_long_model(work: Path) -> None:
    """``inputs.npy`` of deploy/README.md's ``run long/ inputs.npy ...``: (1, 40, 4 J + 8) frames with controls,
    J from the exported step model's skeleton (identity rotations, zero controls)."""
    from deploy.runtime import load_model

    J = len(load_model(work / "long" / "quaternet-long_step.onnx").metadata["skeleton"]["names"])
    x = np.zeros((1, 40, 4 * J + 8), np.float32)
    x[:, :, 0:4 * J:4] = 1.0
    np.save(work / "inputs.npy", x)


#: Inputs made just before the first command that names them (a page's earlier commands make what they need).
PREPARE = {"inputs.npy": _frames_for_the_long_model}


def test_every_page_has_commands():
    for page in PAGES:
        assert len(page_commands(page)) >= 8, page


@pytest.mark.parametrize("page", PAGES)
def test_every_documented_command_parses(page):
    for cmd in page_commands(page):
        _parse(cmd)


def test_ci_installs_as_the_readme_says():
    install = next(c.text for c in page_commands("README.md") if c.text.startswith("python -m pip install"))
    assert "-c constraints.txt" in install
    script = (ROOT / ".ci" / "run").read_text().replace("\\\n", " ")   # continuation lines joined
    ci = [shlex.split(line, comments=True) for line in script.splitlines()]
    assert shlex.split(install) in ci, ".ci/run must install exactly as the README says"


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_every_documented_command_runs(page, tmp_path):
    """Run every command of ``page`` in order (budgets of :data:`BUDGETS`); collect every failure."""
    work = _workspace(tmp_path)
    _setup(page, work)
    failed, ran, skipped = [], 0, []
    for cmd in page_commands(page):
        why = _not_run(cmd)
        if why is None and _needs_shared(cmd) and not SHARED.is_dir():
            why = "needs ../shared"
        if why is None and page == "deploy/README.md" and "long/" in cmd.text and not SHARED.is_dir():
            why = "the long-term models train on ../shared"
        if why is not None:
            skipped.append(f"{cmd.id} {cmd.text[:60]}: {why}")
            continue
        server = cmd.text.startswith(SERVERS)
        if server and (why := _server_skip(cmd, work)) is not None:
            skipped.append(f"{cmd.id} {cmd.text[:60]}: {why}")
            continue
        _parse(cmd)
        for name, make in PREPARE.items():
            if name in cmd.argv and not (work / name).exists():
                make(work)
        t0 = time.perf_counter()
        rc, log = (_serve if server else _run)(cmd, work)
        print(f"{cmd.id}: exit {rc} in {time.perf_counter() - t0:.0f} s: {cmd.text[:90]}", flush=True)  # with -s
        ran += 1
        if rc != 0:
            failed.append(f"{cmd.id}: `{' '.join(cmd.argv)}` exit {rc}\n{log}")
    print("\n".join(["not run:"] + skipped))
    assert not failed, "\n\n".join(failed)
    assert ran >= 5


def test_budgets_only_shrink_numbers():
    """The replacements change budgets, never a path or an option name."""
    for page in PAGES:
        for cmd in page_commands(page):
            written = shlex.split(cmd.text)
            flags = [t for t in written if t.startswith("--")]
            want = [("--steps" if f == "--epochs" else f) for f in flags]
            got = [t for t in cmd.argv if t.startswith("--")]
            extra = list(got)
            for f in want:
                extra.remove(f)
            assert all(f in ADDED for f in extra), cmd.id  # and every written option is still there (remove)

