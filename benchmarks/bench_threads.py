"""Benchmark: one vs two BLAS threads for every model of the command line, training and inference (issue #17).

``refimpl``'s ``--blas-threads`` default is whatever this measures fastest on the machine. For every model of
``refimpl.registry.MODELS`` (the paper-size network the recipe builds on ``refimpl train``'s default data, the
embedded sample, float32), the same code the command line runs:

* **training step**: a batch from the recipe's own adapter (``spec.make_adapter(...).get_batch``, the recipe's
  paper batch size), ``loss_and_grads`` (forward + manual backward) and ``refimpl.optim.adam_step`` — what
  ``refimpl train`` does per step;
* **inference at batch 1**: the model's online step (QTG: a whole 30-frame transition, ``rollout_inference``;
  QuaterNet: ``quaternet.step``; the CNN: ``quaternet_cnn.step`` on a receptive-field window; acRNN:
  ``acrnn.step``; the long-term and pace networks: their training forward at batch 1).

Each case runs under ``threadpool_limits(1)`` and ``threadpool_limits(2)`` alternately, several times per round
(the order alternates between rounds), and the JSON holds the per-round ratio ``t(2 threads) / t(1 thread)``,
paired within the round, with its median, and the load average before and after. Nothing asserts on time.

    python benchmarks/bench_threads.py [--rounds 3] [--models qtg,quaternet] [--no-train] [--out PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

from threadpoolctl import threadpool_info, threadpool_limits  # noqa: E402

from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.cli import build_parser  # noqa: E402
from refimpl.optim import adam_init, adam_step  # noqa: E402
from refimpl.registry import MODELS, task_of  # noqa: E402
from refimpl.train import TrainContext  # noqa: E402


def adapter_case(name: str, batch: int | None = None):
    """``(adapter, params, config, data, spec)``: the recipe's adapter at its paper size, fresh parameters and one
    batch of ``batch`` examples (default: the recipe's paper batch), built as ``refimpl train --model name`` builds
    them (default data, float32, epoch 0)."""
    spec = MODELS[name]
    task = task_of(spec)
    with tempfile.TemporaryDirectory() as d:
        args = build_parser().parse_args(["train", "--model", name, "--out", d])
    train_ds, test_ds = task.train_datasets(args)
    config = spec.make_config(train_ds, [])
    extra = dict(task.checkpoint_extra(train_ds), representation=spec.representations[0])
    adapter = spec.make_adapter(train_ds, test_ds, config, np.float32, extra)
    rng = np.random.default_rng(0)
    params = adapter.init_params(rng)
    B = batch or int(getattr(spec.recipe, "PAPER_BATCH", 32))
    idx = rng.choice(adapter.num_examples, size=B, replace=adapter.num_examples < B)
    data = adapter.get_batch(idx, TrainContext(rng=np.random.default_rng(1), step=0, epoch=0))
    return adapter, params, config, data, spec


def training_step(adapter, params, data, spec):
    """One step as ``refimpl train`` takes it: ``loss_and_grads`` and ``adam_step`` (the recipe's lr and betas),
    in place on ``params``."""
    state = adam_init(params)

    def train_step():
        _, grads = adapter.loss_and_grads(params, data)
        adam_step(params, grads, state, spec.optim.lr, betas=spec.optim.betas)
    return train_step


def _training_case(name: str, batch: int | None):
    """``(step_fn, params, config, description)``: one training step of ``name`` the way ``refimpl train`` builds
    it."""
    adapter, params, config, data, spec = adapter_case(name, batch)
    B = batch or int(getattr(spec.recipe, "PAPER_BATCH", 32))
    n = sum(int(v.size) for v in params.values())
    return (training_step(adapter, params, data, spec), params, config,
            {"batch": B, "parameters": n, "config": str(config)[:200]})


def _inference_case(name: str, params, config):
    """``(fn, description)``: batch-1 inference of ``name``'s network, or None."""
    rng = np.random.default_rng(2)
    if name == "qtg":
        from refimpl.models.qtg_fast_inference import prepare_inference, rollout_inference
        lean = prepare_inference(params, config)
        past = rng.standard_normal((1, 2, config.pose_size)).astype(np.float32)
        target = rng.standard_normal((1, 2, config.pose_size)).astype(np.float32)
        return (lambda: rollout_inference(lean, past, target)), "30-frame transition, rollout_inference, B=1"
    if name == "quaternet":
        from refimpl.models import quaternet
        net = config.network if not callable(config.network) else config.network()
        h = quaternet.init_state(params, 1, net)
        x = rng.standard_normal((1, net.input_size if hasattr(net, "input_size") else 4 * net.num_joints))
        x = x.astype(np.float32)
        return (lambda: quaternet.step(params, h, x, net)), "quaternet.step, B=1"
    if name == "quaternet-cnn":
        from refimpl.models import quaternet_cnn
        net = config.network if not callable(config.network) else config.network()
        w = rng.standard_normal((1, net.receptive_field, 4 * net.num_joints)).astype(np.float32)
        return (lambda: quaternet_cnn.step(params, w, net)), "quaternet_cnn.step on a receptive-field window, B=1"
    if name == "acrnn":
        from refimpl.models import acrnn
        st = acrnn.init_state(config, 1, np.float32)
        x = rng.standard_normal((1, params["decoder.weight"].shape[0])).astype(np.float32)
        return (lambda: acrnn.step(params, config, x, st)), "acrnn.step, B=1"
    return None


def _time(fn, reps: int) -> float:
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps * 1e3


def _compare(fn, rounds: int, min_time: float) -> dict:
    """Per round: 1 and 2 threads (alternating order), ms per call; paired ratio 2/1."""
    with threadpool_limits(limits=1):
        fn()
        t = _time(fn, 1)
    reps = max(1, int(min_time / max(t / 1e3, 1e-6)))
    per = {1: [], 2: []}
    for r in range(rounds):
        for n in ((1, 2) if r % 2 == 0 else (2, 1)):
            with threadpool_limits(limits=n):
                fn()                                      # warm the pool at this size
                per[n].append(_time(fn, reps))
            time.sleep(0.1)
    ratios = [b / a for a, b in zip(per[1], per[2])]
    return {"ms_1thread": per[1], "ms_2threads": per[2], "ratio_2_over_1": ratios,
            "median_ratio_2_over_1": statistics.median(ratios), "reps_per_round": reps}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--min-time", type=float, default=1.0, help="seconds per variant per round")
    ap.add_argument("--models", default="qtg,quaternet,quaternet-cnn,acrnn,quaternet-long,pace")
    ap.add_argument("--no-train", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_threads.json"))
    args = ap.parse_args(argv)
    result = {"benchmark": "bench_threads", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "load_average_before": os.getloadavg(), "cpu_count": os.cpu_count(),
              "blas": [{k: v for k, v in i.items() if k in ("internal_api", "version", "architecture")}
                       for i in threadpool_info()], "cases": {}}
    for name in [m for m in args.models.split(",") if m]:
        t0 = time.perf_counter()
        train_step, params, config, desc = _training_case(name, None)
        print(f"{name}: {desc['parameters']:,} parameters, batch {desc['batch']} "
              f"(setup {time.perf_counter() - t0:.1f} s)", flush=True)
        if not args.no_train:
            res = _compare(train_step, args.rounds, args.min_time)
            result["cases"][f"{name} training step"] = dict(desc, **res)
            print(f"  training step  1 thread {statistics.median(res['ms_1thread']):9.2f} ms  2 threads "
                  f"{statistics.median(res['ms_2threads']):9.2f} ms  2/1 {res['median_ratio_2_over_1']:.2f} "
                  f"(rounds {', '.join(f'{r:.2f}' for r in res['ratio_2_over_1'])})", flush=True)
        inf = _inference_case(name, params, config)
        if inf is not None:
            fn, what = inf
            res = _compare(fn, args.rounds, min(args.min_time, 0.3))
            result["cases"][f"{name} inference"] = dict(what=what, **res)
            print(f"  inference      1 thread {statistics.median(res['ms_1thread']):9.3f} ms  2 threads "
                  f"{statistics.median(res['ms_2threads']):9.3f} ms  2/1 {res['median_ratio_2_over_1']:.2f} "
                  f"({what})", flush=True)
    result["load_average_after"] = os.getloadavg()
    print(f"load average before {result['load_average_before']}, after {result['load_average_after']}")
    atomic_write_text(Path(args.out), json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
