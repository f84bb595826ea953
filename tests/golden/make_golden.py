"""Regenerate the PyTorch golden vectors in ``tests/golden/`` (float64), or check them.

Each file holds inputs ``in.*``, parameters ``param.*`` (PyTorch names and layouts), outputs ``out.*``,
gradients ``grad.*`` of the scalar loss ``sum(out.y * in.gy) + sum(out.h_n * in.gh) [+ sum(out.c_n * in.gc)]``
and settings ``meta.*`` (README.md in this folder lists the files).

Usage
-----
``python tests/golden/make_golden.py --check``
    recompute every ``out.*`` and ``grad.*`` with PyTorch from the ``in.*`` and ``param.*`` stored in the
    files and print the largest difference per file; exit 1 when one exceeds ``--tol`` (default 1e-13).
``python tests/golden/make_golden.py --write DIR``
    draw fresh inputs and parameters (``torch.manual_seed(0)`` per file, the module first, then the inputs in
    the order of the table) and write a complete new set to DIR; the committed set was drawn by the same
    recipe but its cotangents (``in.gy``, ``in.gh``, ``in.gc``) came from a draw order not recorded, so a fresh
    set differs from it in those inputs, and therefore in ``grad.*``, while ``--check`` reproduces it.

Needs ``torch`` (only this script; the tests read the ``.npz`` files with ``numpy.load(allow_pickle=False)``).
"""
from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
from refimpl.atomic import atomic_write_bytes  # noqa: E402

# name -> (kind, settings)
RECIPES = {
    "gru_2layer.npz": ("gru", dict(input_size=4, hidden_size=6, num_layers=2, bidirectional=False, B=3, T=5)),
    "gru_bidirectional.npz": ("gru", dict(input_size=2, hidden_size=5, num_layers=1, bidirectional=True, B=2, T=7)),
    "lstm_3layer.npz": ("lstm", dict(input_size=5, hidden_size=6, num_layers=3, bidirectional=False, B=3, T=6)),
    "conv1d_causal_k2_d1.npz": ("conv1d", dict(kernel_size=2, dilation=1)),
    "conv1d_causal_k2_d4.npz": ("conv1d", dict(kernel_size=2, dilation=4)),
    "conv1d_causal_k3_d2.npz": ("conv1d", dict(kernel_size=3, dilation=2)),
    "mlp_leaky005.npz": ("mlp", dict()),
    "adam_default.npz": ("adam", dict(lr=1e-3, betas=(0.9, 0.999))),
    "adam_qtg.npz": ("adam", dict(lr=1e-4, betas=(0.5, 0.9))),
    "clip_grad_norm_0p1.npz": ("clip", dict(max_norm=0.1)),
}


def _t(a):
    import torch

    return torch.tensor(np.asarray(a), dtype=torch.float64)


def _module(kind: str, s: dict):
    """The PyTorch module of a recipe (parameters drawn from the current seed)."""
    import torch

    if kind in ("gru", "lstm"):
        cls = torch.nn.GRU if kind == "gru" else torch.nn.LSTM
        return cls(s["input_size"], s["hidden_size"], num_layers=s["num_layers"],
                   bidirectional=s["bidirectional"], batch_first=True)
    if kind == "conv1d":
        return torch.nn.Conv1d(3, 4, s["kernel_size"], dilation=s["dilation"])
    if kind == "mlp":
        return torch.nn.ModuleDict({"fc1": torch.nn.Linear(6, 30), "fc2": torch.nn.Linear(30, 30)})
    raise ValueError(kind)


def _draw(kind: str, s: dict) -> dict:
    """Fresh inputs and parameters for one recipe: ``torch.manual_seed(0)``, module, then inputs."""
    import torch

    torch.manual_seed(0)
    d: dict = {}
    if kind in ("gru", "lstm", "conv1d", "mlp"):
        mod = _module(kind, s)
        for k, v in mod.state_dict().items():
            d[f"param.{k}"] = v.numpy().copy()
    if kind in ("gru", "lstm"):
        L = s["num_layers"] * (2 if s["bidirectional"] else 1)
        H, B, T = s["hidden_size"], s["B"], s["T"]
        d["in.x"] = torch.randn(B, T, s["input_size"]).numpy()
        d["in.h0"] = torch.randn(L, B, H).numpy()
        if kind == "lstm":
            d["in.c0"] = torch.randn(L, B, H).numpy()
        d["in.gy"] = torch.randn(B, T, H * (2 if s["bidirectional"] else 1)).numpy()
        d["in.gh"] = torch.randn(L, B, H).numpy()
        if kind == "lstm":
            d["in.gc"] = torch.randn(L, B, H).numpy()
    elif kind == "conv1d":
        d["in.x"] = torch.randn(2, 11, 3).numpy()
        d["in.gy"] = torch.randn(2, 11, 4).numpy()
        d["meta.kernel_size"] = np.array(s["kernel_size"])
        d["meta.dilation"] = np.array(s["dilation"])
    elif kind == "mlp":
        d["in.x"] = torch.randn(4, 6).numpy()
        d["in.gy"] = torch.randn(4, 30).numpy()
    elif kind == "adam":
        d["in.p0"] = torch.randn(7, 3).numpy()
        d["in.grads"] = torch.randn(5, 7, 3).numpy()
        d["meta.lr"] = np.array(s["lr"])
        d["meta.betas"] = np.array(s["betas"])
        d["meta.eps"] = np.array(1e-8)
    elif kind == "clip":
        d["in.grad_a"] = torch.randn(5, 4).numpy()
        d["in.grad_b"] = torch.randn(3).numpy()
        d["meta.max_norm"] = np.array(s["max_norm"])
    return d


def _compute(kind: str, s: dict, d: dict) -> dict:
    """PyTorch's outputs and gradients for the inputs and parameters in ``d`` (a dict of arrays)."""
    import torch
    import torch.nn.functional as F

    out: dict = {}
    if kind in ("gru", "lstm", "conv1d", "mlp"):
        mod = _module(kind, s)
        with torch.no_grad():
            for k, p in mod.named_parameters():
                p.copy_(_t(d[f"param.{k}"]))
        x = _t(d["in.x"]).requires_grad_(True)
        if kind in ("gru", "lstm"):
            h0 = _t(d["in.h0"]).requires_grad_(True)
            if kind == "lstm":
                c0 = _t(d["in.c0"]).requires_grad_(True)
                y, (h_n, c_n) = mod(x, (h0, c0))
                loss = (y * _t(d["in.gy"])).sum() + (h_n * _t(d["in.gh"])).sum() + (c_n * _t(d["in.gc"])).sum()
                out["out.c_n"] = c_n
            else:
                y, h_n = mod(x, h0)
                loss = (y * _t(d["in.gy"])).sum() + (h_n * _t(d["in.gh"])).sum()
            out["out.y"], out["out.h_n"] = y, h_n
            leaves = {"grad.x": x, "grad.h0": h0}
            if kind == "lstm":
                leaves["grad.c0"] = c0
        elif kind == "conv1d":
            pad = (s["kernel_size"] - 1) * s["dilation"]
            y = mod(F.pad(x.transpose(1, 2), (pad, 0))).transpose(1, 2)
            loss = (y * _t(d["in.gy"])).sum()
            out["out.y"] = y
            leaves = {"grad.x": x}
        else:
            y = F.leaky_relu(mod["fc2"](F.leaky_relu(mod["fc1"](x), 0.05)), 0.05)
            loss = (y * _t(d["in.gy"])).sum()
            out["out.y"] = y
            leaves = {"grad.x": x}
        loss.backward()
        for k, leaf in leaves.items():
            out[k] = leaf.grad
        for k, p in mod.named_parameters():
            out[f"grad.{k}"] = p.grad
    elif kind == "adam":
        p = _t(d["in.p0"]).requires_grad_(True)
        opt = torch.optim.Adam([p], lr=float(d["meta.lr"]), betas=tuple(float(b) for b in d["meta.betas"]),
                               eps=float(d["meta.eps"]))
        after = []
        for g in d["in.grads"]:
            p.grad = _t(g)
            opt.step()
            after.append(p.detach().clone())
        out["out.params_after_each_step"] = torch.stack(after)
    elif kind == "clip":
        a = _t(d["in.grad_a"]).requires_grad_(True)
        b = _t(d["in.grad_b"]).requires_grad_(True)
        a.grad, b.grad = _t(d["in.grad_a"]), _t(d["in.grad_b"])
        total = torch.nn.utils.clip_grad_norm_([a, b], float(d["meta.max_norm"]))
        out["out.grad_a"], out["out.grad_b"], out["out.total_norm"] = a.grad, b.grad, total
    return {k: v.detach().numpy().copy() for k, v in out.items()}


def _check(folder: Path, tol: float) -> int:
    worst = 0.0
    for name, (kind, s) in RECIPES.items():
        with np.load(folder / name, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
        fresh = _compute(kind, s, d)
        missing = sorted(k for k in d if k.startswith(("out.", "grad.")) and k not in fresh)
        if missing:
            print(f"{name}: keys not recomputed: {missing}")
            return 1
        diff = max(float(np.max(np.abs(fresh[k] - d[k]))) if d[k].size else 0.0 for k in fresh)
        worst = max(worst, diff)
        print(f"{name:28s} {len(fresh):3d} arrays recomputed, max |torch - stored| = {diff:.2e}")
    print(f"worst {worst:.2e} (tolerance {tol:.0e})")
    return 0 if worst <= tol else 1


def _write(folder: Path) -> int:
    import torch

    torch.set_default_dtype(torch.float64)
    folder.mkdir(parents=True, exist_ok=True)
    for name, (kind, s) in RECIPES.items():
        d = _draw(kind, s)
        d.update(_compute(kind, s, d))
        buf = io.BytesIO()
        np.savez(buf, **d)
        atomic_write_bytes(folder / name, buf.getvalue())
        print(f"wrote {folder / name} ({len(d)} arrays)")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--check", nargs="?", const=str(HERE), metavar="DIR",
                   help="recompute outputs and gradients of the files in DIR (default: this folder)")
    g.add_argument("--write", metavar="DIR", help="draw a fresh set and write it to DIR")
    ap.add_argument("--tol", type=float, default=1e-13)
    a = ap.parse_args(argv)
    import torch

    torch.set_default_dtype(torch.float64)
    torch.set_num_threads(1)
    return _check(Path(a.check), a.tol) if a.check else _write(Path(a.write))


if __name__ == "__main__":
    sys.exit(main())
