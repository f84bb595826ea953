"""``python -m deploy run`` of a QTG folder with ``--join inertialize+footlock`` (spec/qtg.md §7.5, spec/deploy.md
§8): the numbers of ``refimpl generate --join inertialize+footlock`` on the same clip and frames, through the same
exported graphs (onnx backend) and through the NumPy network."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from deploy.cli import main as deploy_main  # noqa: E402
from refimpl.cli import EXIT_OK, main as refimpl_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
T, START = 10, 40  # frames START … START+T−1 replaced: context START−2, START−1 and START+T, START+T+1


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A tiny trained QTG, its ``deploy export`` folder (no join) and its ``refimpl export --join inertialize``
    folder (the join inside the rollout graph)."""
    root = tmp_path_factory.mktemp("run_footlock")
    run = root / "qtg"
    argv = ["--blas-threads", "1", "train", "--model", "qtg", "--data", str(WALK_BVH), "--steps", "3",
            "--batch-size", "8", "--stride", "8", "--test-fraction", "0.5", "--transition-length", str(T),
            "--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16",
            "--progress-every", "1", "--checkpoint-every", "100", "--out", str(run)]
    assert refimpl_main(argv) == EXIT_OK
    ck = run / "checkpoint.npz"
    assert deploy_main(["export", str(ck), str(root / "plain")]) == 0
    assert refimpl_main(["export", "--checkpoint", str(ck), "--out", str(root / "joined"), "--join",
                         "inertialize"]) == EXIT_OK
    clip = root / "walk30.bvh"  # the take at the model's 30 fps: deploy run and refimpl generate read the same frames
    from refimpl.bvh import read_bvh
    from refimpl.bvh_write import write_bvh
    from refimpl.motion import Motion

    m = read_bvh(WALK_BVH)
    write_bvh(clip, Motion(m.skeleton, m.rotations[::4], m.root_positions[::4], frame_time=1.0 / 30.0, name="walk30"))
    return ck, root / "plain", root / "joined", clip


def _generated_positions(path, first: int, count: int):
    """Joint positions (count, 22, 3) in cm of frames ``first …`` of a written BVH (end sites left out)."""
    from refimpl.bvh import read_bvh

    m = read_bvh(path)
    x = np.asarray(m.positions())[first:first + count]
    keep = [j for j, n in enumerate(m.skeleton.names) if j not in set(m.skeleton.end_sites)]
    return x[:, keep]


def _deploy_run(folder, clip, out, join, capsys):
    argv = ["run", str(folder), str(clip), str(out), "--start", str(START)]
    code = deploy_main(argv + ([] if join is None else ["--join", join]))
    assert code == 0, capsys.readouterr().err
    return capsys.readouterr().out


def _refimpl_generate(ck, clip, out, join, backend, folder=None):
    """refimpl generate drops a clip's first frame (its reference pose; deploy run keeps it): its source frame
    START − 2 is the file's START − 1, the last context frame before the transition."""
    argv = ["generate", "--checkpoint", str(ck), "--method", "qtg", "--source", str(clip), "--source-frame",
            str(START - 2), "--join", join, "--context", "2", "--out", str(out)]
    if backend == "onnx":
        argv += ["--backend", "onnx", "--onnx", str(folder)]
    assert refimpl_main(argv) == EXIT_OK


def test_deploy_run_footlock_equals_refimpl_generate(trained, tmp_path, capsys):
    """deploy run --join inertialize+footlock on the plain folder = refimpl generate --join inertialize+footlock
    on the same graphs (measured: 0) and on the NumPy network (float32 graphs against float64);
    the folder with the join inside the rollout graph gives the same frames (its join is the graph's); foot
    locking changed the frames of --join inertialize."""
    ck, plain, joined, clip = trained
    outs = {}
    for key, folder, join in (("locked", plain, "inertialize+footlock"), ("join", plain, "inertialize"),
                              ("baked", joined, "inertialize+footlock")):
        text = _deploy_run(folder, clip, tmp_path / f"{key}.bvh", join, capsys)
        assert "+join" in text or "wrote" in text
        outs[key] = _generated_positions(tmp_path / f"{key}.bvh", START, T)
    _refimpl_generate(ck, clip, tmp_path / "gen_onnx.bvh", "inertialize+footlock", "onnx", plain)
    _refimpl_generate(ck, clip, tmp_path / "gen_numpy.bvh", "inertialize+footlock", "numpy")
    gen_onnx = _generated_positions(tmp_path / "gen_onnx.bvh", 2, T)  # --context 2: frames 0, 1, then T frames
    gen_numpy = _generated_positions(tmp_path / "gen_numpy.bvh", 2, T)
    assert np.abs(outs["locked"] - gen_onnx).max() <= 1e-4    # measured 0
    assert np.abs(outs["locked"] - gen_numpy).max() <= 1e-3   # measured 2.6e-5 cm
    assert np.abs(outs["baked"] - outs["locked"]).max() <= 1e-3  # the float32 graph's join; measured 1.3e-4 cm
    assert np.abs(outs["locked"] - outs["join"]).max() > 1.0  # foot locking moved the legs (measured 30 cm)


def test_deploy_run_join_options(trained, tmp_path, capsys):
    """--join none on a folder whose rollout has the join inside: exit 2, one line; a bad mode: exit 2."""
    _, plain, joined, _ = trained
    argv = ["run", str(joined), str(WALK_BVH), str(tmp_path / "x.bvh"), "--start", str(START), "--join", "none"]
    assert deploy_main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--join none" in err
    assert deploy_main(["run", str(plain), str(WALK_BVH), str(tmp_path / "y.bvh"), "--start", str(START),
                        "--join", "none"]) == 0
    with pytest.raises(SystemExit) as exc:
        deploy_main(["run", str(plain), str(WALK_BVH), str(tmp_path / "z.bvh"), "--join", "footlock"])
    assert exc.value.code == 2
