"""deploy/examples/qtg_footlock.c (foot locking in C, spec/qtg.md §7.5) against its NumPy oracle
``refimpl.protocols.transition_footlock.lock_feet`` on real frames, and ``qtg_rollout --footlock`` against the
NumPy ``inertialize+footlock`` chain.

The function alone needs only a C compiler (built with ``-Wall -Wextra -Werror -std=c99 -pedantic`` and a small
driver written here); the example needs onnxruntime's C headers as ``tests/test_c_example.py`` (``ORT_C_DIR``,
e.g. the headers of Debian's ``libonnxruntime-dev``) and skips cleanly without them.
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from refimpl.protocols.transition import split_pose
from refimpl.protocols.transition_footlock import lock_feet
from refimpl.protocols.transition_join import inertialize_joins
from refimpl.quat import hemisphere_sign
from tests.test_c_example import SOURCE as ROLLOUT_SOURCE
from tests.test_c_example import _compiler, build_example

ROOT = Path(__file__).resolve().parents[1]
FOOTLOCK = ROOT / "deploy" / "examples" / "qtg_footlock.c"
DT = 1.0 / 30.0
TOL_CM = 1e-4

# reads skeleton.json, seq.f64 (N sequences of F x P doubles), writes out.f64 and one line per sequence;
# argv: skeleton seq out F start stop fps N [up]
_DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include "qtg_footlock.h"

int main(int argc, char** argv) {
  if (argc < 9) return 2;
  FILE* f = fopen(argv[1], "rb");
  if (f == NULL) return 3;
  static char json[1 << 20];
  size_t n = fread(json, 1, sizeof json - 1, f);
  json[n] = '\0';
  fclose(f);
  qtg_skeleton sk;
  if (qtg_skeleton_from_json(json, &sk) != 0) { printf("bad skeleton\n"); return 4; }
  const int F = atoi(argv[4]), P = 3 + 4 * sk.joints, N = atoi(argv[8]);
  const size_t count = (size_t)N * (size_t)(F * P);
  double* seq = malloc(sizeof(double) * count);
  f = fopen(argv[2], "rb");
  if (seq == NULL || f == NULL || fread(seq, sizeof(double), count, f) != count) return 5;
  fclose(f);
  qtg_footlock_options o = qtg_footlock_defaults(atof(argv[7]));
  if (argc > 9) o.up = atoi(argv[9]);
  for (int i = 0; i < N; ++i) {
    const int rc = qtg_footlock(&sk, &o, seq + (size_t)i * (size_t)(F * P), F, atoi(argv[5]), atoi(argv[6]));
    printf("%d %s\n", rc, qtg_footlock_error(rc));
  }
  f = fopen(argv[3], "wb");
  fwrite(seq, sizeof(double), count, f);
  fclose(f);
  free(seq);
  qtg_skeleton_free(&sk);
  return 0;
}
"""


@pytest.fixture(scope="module")
def driver(tmp_path_factory):
    cc = _compiler()
    if cc is None:
        pytest.skip("no C compiler (set CC, or install cc/gcc/clang)")
    work = tmp_path_factory.mktemp("c_footlock")
    (work / "driver.c").write_text(_DRIVER)
    exe = work / "driver"
    build = subprocess.run([cc, "-O2", "-Wall", "-Wextra", "-Werror", "-std=c99", "-pedantic", f"-I{FOOTLOCK.parent}",
                            str(work / "driver.c"), str(FOOTLOCK), "-lm", "-o", str(exe)],
                           capture_output=True, text=True, timeout=120)
    assert build.returncode == 0, build.stderr
    assert "warning" not in build.stderr, build.stderr
    return exe


def _skeleton_json(skeleton) -> str:
    from deploy.metadata import skeleton_metadata

    return json.dumps(skeleton_metadata(skeleton, units="cm"), sort_keys=True)


def _c_lock(driver, tmp_path, skeleton, seq, start, stop, fps=30.0, up=None):
    """(return code lines, locked sequences) of the C function on sequences (N, F, P) (or one line and one
    sequence for seq (F, P))."""
    one = seq.ndim == 2
    seqs = seq[None] if one else seq
    (tmp_path / "sk.json").write_text(_skeleton_json(skeleton))
    np.ascontiguousarray(seqs, "<f8").tofile(tmp_path / "seq.f64")
    argv = [str(driver), tmp_path / "sk.json", tmp_path / "seq.f64", tmp_path / "out.f64", seqs.shape[1], start,
            stop, fps, len(seqs)] + ([] if up is None else [up])
    run = subprocess.run([str(a) for a in argv], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, (run.stdout, run.stderr)
    lines, out = run.stdout.strip().splitlines(), np.fromfile(tmp_path / "out.f64", "<f8").reshape(seqs.shape)
    return (lines[0], out[0]) if one else (lines, out)


def _positions(skeleton, seq):
    root, q = split_pose(np.asarray(seq, np.float64))
    return skeleton.forward_kinematics(q / np.linalg.norm(q, axis=-1, keepdims=True), root)


def _assert_same(skeleton, got, want, tol=TOL_CM):
    """Joint positions within ``tol`` cm, quaternions equal up to sign within 1e-6."""
    assert np.abs(_positions(skeleton, got) - _positions(skeleton, want)).max() <= tol
    _, qg = split_pose(got)
    _, qw = split_pose(want)
    assert np.abs(qg * hemisphere_sign(qw, qg) - qw).max() <= 1e-6


@pytest.fixture(scope="module")
def sample_windows():
    from refimpl.protocols.transition_baselines import method_registry
    from refimpl.tasks.transition import build_datasets

    _, test = build_datasets("sample", 30, 1, test_stride=4)
    past, gt, target = test.context()
    interp = method_registry(dt=DT)["interpolation"](past, target, test.transition_length)
    joined = inertialize_joins(past, interp, target, dt=DT)
    return test, past, gt, target, joined


def test_c_footlock_equals_numpy_on_real_windows(driver, tmp_path, sample_windows):
    """Every held-out window of the sample's three skeletons (CMU, salsa, ...), two kinds of transition: the
    interpolation baseline with the join option (its feet slide: the C function must pin them) and the ground
    truth; the C output equals lock_feet to 1e-4 cm in every joint position (measured ~1e-12)."""
    test, past, gt, target, joined = sample_windows
    T = test.transition_length
    changed_total, worst = 0, 0.0
    for k in np.unique(test.skeleton_index):
        sel = np.flatnonzero(test.skeleton_index == k)
        sk = test.skeletons[int(k)]
        for frames in (joined[sel], gt[sel]):
            seqs = np.concatenate([past[sel], frames, target[sel]], axis=1)  # (N, F, P)
            lines, got = _c_lock(driver, tmp_path, sk, seqs, 2, T + 2)
            wants = lock_feet(seqs, sk, 2, T + 2, DT)  # (N, F, P)
            _assert_same(sk, got, wants)
            worst = max(worst, float(np.abs(_positions(sk, got) - _positions(sk, wants)).max()))
            for i, want in enumerate(wants):
                changed = int(np.any(want != seqs[i], axis=-1).sum())
                assert lines[i].startswith(f"{changed} "), (sel[i], lines[i], changed)
                same = np.all(want == seqs[i], axis=-1)
                assert np.array_equal(got[i][same], seqs[i][same])
                changed_total += changed
    assert changed_total > test.num_windows * 10, changed_total  # the function had work to do
    assert len(set(test.skeleton_index.tolist())) == 3
    print(f"c footlock vs numpy: worst {worst:.3g} cm over {test.num_windows} windows, {changed_total} frames")


def test_c_footlock_refuses_bad_arguments(driver, tmp_path, sample_windows):
    """Out-of-range start/stop, a zero quaternion, a skeleton without feet: a negative code, the sequence as it
    was."""
    test, past, _, target, joined = sample_windows
    sk = test.skeletons[int(test.skeleton_index[0])]
    seq = np.concatenate([past[0], joined[0], target[0]])
    for start, stop in ((0, 5), (3, 3), (2, len(seq))):
        line, got = _c_lock(driver, tmp_path, sk, seq, start, stop)
        assert line.startswith("-1 ") and np.array_equal(got, seq)
    bad = seq.copy()
    bad[5, 3:7] = 0.0
    line, got = _c_lock(driver, tmp_path, sk, bad, 2, len(seq) - 2)
    assert line.startswith("-3 ") and np.array_equal(got, bad)
    from refimpl.skeleton import Skeleton

    nofeet = Skeleton(sk.parents, sk.offsets, [f"j{j}" for j in range(sk.num_joints)])
    line, _ = _c_lock(driver, tmp_path, nofeet, seq, 2, len(seq) - 2)
    assert line.startswith("-2 ")


# ------------------------------------------------------------------------------------------------------------
# the C example: rollout graph (join option inside) + qtg_footlock.c = NumPy inertialize+footlock
# ------------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rollout_binary(tmp_path_factory):
    return build_example(tmp_path_factory, (ROLLOUT_SOURCE, FOOTLOCK), "qtg_rollout_footlock", extra=("-Werror",))


def _export(folder, test, sk, join):
    import onnx

    from deploy.models.qtg import export_qtg_rollout
    from refimpl.models.qtg import QTGConfig, init_params

    config = QTGConfig(pose_size=3 + 4 * sk.num_joints, encoder_sizes=(16, 8), gru_hidden=8, gru_layers=2,
                       decoder_sizes=(16,), negative_slope=0.05, transition_length=test.transition_length)
    params = init_params(config, np.random.default_rng(3))
    norm = (np.asarray(test.root_mean), np.asarray(test.root_std))
    path = folder / f"rollout_{join}.onnx"
    onnx.save(export_qtg_rollout(params, config, join=join, normalization=norm, skeleton=sk), str(path))
    return path, params, config, norm


def test_c_example_footlock_equals_numpy(rollout_binary, tmp_path, sample_windows):
    """Real contexts of the sample, a QTG network with default-style random weights exported with the join
    option: ``qtg_rollout --footlock`` equals (a) refimpl's lock_feet on the graph's own frames (same float32
    rollout; measured 5e-6 cm, the float32 rounding of poses.f32) to 1e-4 cm and (b) the whole NumPy chain (the
    float64 NumPy network, inertialize_joins, lock_feet) to 1e-3 cm and within 2x (+1e-4 cm) of the float32
    graph's own distance from the float64 network before foot locking (measured 1.5-2.0e-4 cm: the graph's
    float32, not the locking); the frames it changed are written to poses.f32."""
    pytest.importorskip("onnxruntime")
    from refimpl.models.qtg_fast import rollout_forward
    from refimpl.protocols.transition import denormalize_poses, normalize_poses
    from tests.test_c_example import _python_rollout

    test, past, _, target, _ = sample_windows
    T = test.transition_length
    changed = 0
    for i in (0, test.num_windows // 2, test.num_windows - 1):
        sk = test.skeletons[int(test.skeleton_index[i])]
        model, params, config, (mean, std) = _export(tmp_path, test, sk, "inertialize")
        p32, t32 = past[i:i + 1].astype(np.float32), target[i:i + 1].astype(np.float32)
        inputs, outputs = tmp_path / "inputs.f32", tmp_path / "poses.f32"
        np.concatenate([p32.ravel(), t32.ravel()]).astype("<f4").tofile(inputs)
        run = subprocess.run([str(rollout_binary), "--footlock", str(model), str(inputs), str(outputs)],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        assert "footlock: " in run.stdout
        got = np.fromfile(outputs, "<f4").reshape(T, -1).astype(np.float64)
        graph = _python_rollout(model, p32, t32)[0].astype(np.float64)
        ctx = (p32[0].astype(np.float64), t32[0].astype(np.float64))
        want = lock_feet(np.concatenate([ctx[0], graph, ctx[1]])[None], sk, 2, T + 2, DT)[0, 2:T + 2]
        _assert_same(sk, got, want, tol=TOL_CM)
        n = int(run.stdout.split("footlock: ")[1].split()[0])
        assert n == int(np.any(want != graph, axis=-1).sum())
        changed += n
        # (b) the NumPy chain from the float64 network
        net = denormalize_poses(rollout_forward(params, normalize_poses(ctx[0][None], mean, std),
                                                normalize_poses(ctx[1][None], mean, std), T, config)[0], mean, std)
        joined = inertialize_joins(ctx[0][None], net, ctx[1][None], dt=DT)[0]
        chain = lock_feet(np.concatenate([ctx[0], joined, ctx[1]])[None], sk, 2, T + 2, DT)[0, 2:T + 2]
        before = np.abs(_positions(sk, graph) - _positions(sk, joined)).max()  # float32 graph vs float64 net
        after = np.abs(_positions(sk, got) - _positions(sk, chain)).max()
        assert after <= 1e-3 and after <= 2.0 * before + TOL_CM, (after, before)
    assert changed > 0


def test_c_example_footlock_refuses_normalised_poses(rollout_binary, tmp_path, sample_windows):
    """--footlock on a model without in-graph normalisation (poses not in centimetres) exits 1 with one line."""
    pytest.importorskip("onnx")
    import onnx

    from deploy.models.qtg import export_qtg_rollout
    from refimpl.models.qtg import QTGConfig, init_params

    test = sample_windows[0]
    sk = test.skeletons[0]
    config = QTGConfig(pose_size=3 + 4 * sk.num_joints, encoder_sizes=(9, 6), gru_hidden=5, gru_layers=2,
                       decoder_sizes=(8,), negative_slope=0.05, transition_length=4)
    path = tmp_path / "plain.onnx"
    onnx.save(export_qtg_rollout(init_params(config, np.random.default_rng(0)), config, skeleton=sk), str(path))
    run = subprocess.run([str(rollout_binary), "--footlock", str(path)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 1 and "in_graph" in run.stderr


def test_c_example_runs_the_portable_graphs_with_footlock(rollout_binary, tmp_path, sample_windows):
    """A portable folder (``--target portable`` with the join: qtg_init, qtg_step, qtg_join; no rollout graph):
    ``qtg_rollout qtg_init.onnx`` runs the host loop of its metadata and equals ``Runtime.transition`` (qtg) on the
    folder (the same host loop in Python) to float32 rounding; with ``--footlock`` it equals refimpl's lock_feet on
    those frames to 1e-4 cm."""
    pytest.importorskip("onnxruntime")
    from deploy.models.qtg_io import Runtime, export_dir
    from refimpl.models.qtg import QTGConfig, init_params

    test, past, _, target, _ = sample_windows
    T = test.transition_length
    i = test.num_windows // 3
    sk = test.skeletons[int(test.skeleton_index[i])]
    config = QTGConfig(pose_size=3 + 4 * sk.num_joints, encoder_sizes=(16, 8), gru_hidden=8, gru_layers=2,
                       decoder_sizes=(16,), negative_slope=0.05, transition_length=T)
    folder = tmp_path / "portable"
    export_dir(init_params(config, np.random.default_rng(5)), config, folder, skeleton=sk, join="inertialize",
                   normalization=(np.asarray(test.root_mean), np.asarray(test.root_std)), target="portable")
    assert not (folder / "qtg_rollout.onnx").exists() and (folder / "qtg_join.onnx").is_file()
    p32, t32 = past[i:i + 1].astype(np.float32), target[i:i + 1].astype(np.float32)
    inputs = tmp_path / "inputs.f32"
    np.concatenate([p32.ravel(), t32.ravel()]).astype("<f4").tofile(inputs)
    want = Runtime.from_dir(folder).transition(p32, t32, T)[0].astype(np.float64)
    outs = {}
    for flag in ((), ("--footlock",)):
        out = tmp_path / f"poses{len(flag)}.f32"
        run = subprocess.run([str(rollout_binary), *flag, str(folder / "qtg_init.onnx"), str(inputs), str(out)],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        assert f"host loop: init, {T} steps, qtg_join.onnx" in run.stdout
        outs[flag] = np.fromfile(out, "<f4").reshape(T, -1).astype(np.float64)
    np.testing.assert_allclose(outs[()], want, atol=1e-5)
    ctx = (p32[0].astype(np.float64), t32[0].astype(np.float64))
    locked = lock_feet(np.concatenate([ctx[0], outs[()], ctx[1]])[None], sk, 2, T + 2, DT)[0, 2:T + 2]
    _assert_same(sk, outs[("--footlock",)], locked, tol=TOL_CM)
