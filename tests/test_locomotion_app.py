"""The locomotion application (spec/locomotion.md §8-§10): task interface, quaternet-long and pace recipes,
generation along a path, export parity. Small sizes throughout."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import read_bvh
from refimpl.cli import main
from refimpl.gradcheck import check_gradients
from refimpl.losses import fk_position_loss_forward
from refimpl.models import pace, quaternet
from refimpl.protocols import locomotion as LP
from refimpl.protocols import locomotion_data as LD
from refimpl.quat import quat_mul, quat_rotate
from refimpl.recipes import quaternet_long as recipe
from refimpl.registry import MODELS, TASKS
from refimpl.schedules import scheduled_sampling_mask
from refimpl.skeleton import Skeleton
from refimpl.splines import circle_path, line_with_turn_path
from refimpl.tasks import locomotion as L
from refimpl.tasks import locomotion_generate as G
from refimpl.models import quaternet_long_walk as W
from refimpl.protocols.locomotion_data import FPS
from refimpl.testing import TOL_FD

SMALL = ["--data", "sample", "--set", "hidden_size=8", "--locomotion-prefix", "6", "--locomotion-target", "8",
         "--batch-size", "4", "--progress-every", "1", "--checkpoint-every", "1"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """Tiny quaternet-long and pace checkpoints trained a few steps through ``refimpl train``."""
    out = tmp_path_factory.mktemp("loco")
    assert main(["train", "--model", "quaternet-long", *SMALL, "--out", str(out / "pose"), "--steps", "2"]) == 0
    assert main(["train", "--model", "pace", "--data", "sample", "--out", str(out / "pace"), "--steps", "2",
                 "--batch-size", "4", "--pace-chunk-length", "60", "--validate-every", "2"]) == 0
    return out


def test_registry_lines():
    assert TASKS["locomotion"] == "refimpl.tasks.locomotion"
    assert MODELS["quaternet-long"].task == MODELS["pace"].task == "locomotion"
    assert MODELS["quaternet-long"].optim.clip_norm == 0.1 and MODELS["quaternet-long"].optim.lr_decay == 0.999
    assert MODELS["pace"].optim.clip_norm is None and MODELS["pace"].optim.lr_decay == 0.999


def test_train_resume_and_logs(trained, capsys):
    """spec/locomotion.md §8: the recipe through `refimpl train`; resume continues the same run."""
    pose = trained / "pose"
    rows = (pose / "loss.csv").read_text().splitlines()
    assert rows[0].startswith("step,epoch,loss") and len(rows) == 3
    assert main(["train", "--model", "quaternet-long", *SMALL, "--out", str(pose), "--steps", "3", "--resume"]) == 0
    rows = (pose / "loss.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3"]
    from refimpl.services import load_trained
    m = load_trained(pose / "checkpoint.npz")
    assert m.config.hidden_size == 8 and m.config.num_joints == 26 and m.meta["step"] == 3
    assert np.asarray(m.extra["seed_clip"]["rotations"]).shape[1:] == (26, 4)
    assert m.meta["optim"]["clip_norm"] == 0.1
    val = (trained / "pace" / "loss_val.csv").read_text().splitlines()
    assert val[0] == "step,val_l1" and float(val[1].split(",")[1]) > 0


def _tiny_batch(rng, J=3, B=2, P=3, T=4):
    parents = [-1, 0, 1][:J]
    offsets = rng.standard_normal((J, 3))
    q = rng.standard_normal((B, P + T, J, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    feats = rng.standard_normal((B, P + T, 8))
    batch = {"inputs": np.concatenate([q.reshape(B, P + T, 4 * J), feats], -1),
             "target_positions": rng.standard_normal((B, T, J, 3)), "target_translations": rng.standard_normal((B, T, 2)),
             "mask": np.array([True, False, False]), "prefix": P}
    return batch, offsets, parents


def test_recipe_loss_gradient_central_differences():
    """The FK-position-loss recipe path (FK loss + offset term + 0.01 norm penalty, BPTT through the
    scheduled-sampling unroll): 24 random entries of every parameter array against float64 central
    differences (every array, h0 and the controls block included)."""
    rng = np.random.default_rng(3)
    batch, offsets, parents = _tiny_batch(rng)
    net = recipe.QuaterNetLongConfig(num_joints=3, hidden_size=4, controls_hidden=3).network()
    params = quaternet.init_params(net, rng)
    _, grads = recipe.loss_and_grads(params, batch, net, offsets, parents)
    check_gradients(lambda: recipe.loss_and_grads(params, batch, net, offsets, parents)[0], params, grads,
                    **TOL_FD, max_entries=24)


def test_augmentation_leaves_fk_loss_invariant():
    """Rotating a window about +Y (root quaternions r ⊗ q, targets r · p) leaves the FK loss unchanged, for the
    ground truth (0) and for any prediction rotated the same way (ref §7.5)."""
    rng = np.random.default_rng(0)
    seq = LD.build_sequences(LD.load_cmu_expmap(Path(L.__file__).parents[1] / "data/sample/expmap/train/walking/"
                                               "walking_2.txt"), LD.CMU_RIG, mirror=False, all_phases=False)[0]
    b = LP.pose_batch([seq], rng, 3, 6, 8, augment=False)
    sk = seq.skeleton
    J = sk.num_joints
    rot = b.inputs[:, 6:, :4 * J].reshape(3, 8, J, 4)
    pred = rot + 0.05 * rng.standard_normal(rot.shape)
    pred /= np.linalg.norm(pred, axis=-1, keepdims=True)
    tr = b.target_translations + 0.1
    base, _ = fk_position_loss_forward(pred, tr, b.target_positions, b.target_translations, sk.offsets, sk.parents)
    zero, _ = fk_position_loss_forward(rot, b.target_translations, b.target_positions, b.target_translations,
                                       sk.offsets, sk.parents)
    assert zero < 1e-9
    for a in (0.7, -2.5, 5.0):
        r = np.array([math.cos(a / 2), 0.0, math.sin(a / 2), 0.0])
        pa = pred.copy()
        pa[..., 0, :] = quat_mul(r, pred[..., 0, :])
        loss, _ = fk_position_loss_forward(pa, tr, quat_rotate(r, b.target_positions), b.target_translations,
                                           sk.offsets, sk.parents)
        assert abs(loss - base) < 1e-9


def _random_networks(J=4, seed=0):
    rng = np.random.default_rng(seed)
    net = quaternet.QuaterNetConfig.long_term(num_joints=J, hidden_size=8)
    params = quaternet.init_params(net, rng)
    pc = pace.PaceConfig()
    pp = pace.init_params(pc, rng)
    sk = Skeleton([-1, 0, 1, 2], np.array([[0, 0, 0], [0.0, -3, 0], [0, -3, 0], [0, 0, 1.0]]),
                  names=["Hips", "Leg", "Foot", "Toe"])
    seed_rot = np.tile(np.array([1.0, 0, 0, 0]), (5, J, 1))
    feats = np.zeros((5, 8))
    feats[:, 2], feats[:, 6], feats[:, 7] = 0.5, 0.0, 1.0
    return net, params, pc, pp, sk, seed_rot, feats


def test_generation_on_a_circle_stays_on_it():
    """The root is placed on the path (x, z) at arc length s + δ: on a circle of radius r its distance from the
    centre is r within the chord error of the 5-points-per-unit spline."""
    net, params, pc, pp, sk, seed_rot, feats = _random_networks()
    r = 10.0
    walk = W.generate_walk(params, net, pp, pc, sk, seed_rot, feats, circle_path(r), 0.5, 300, fps=FPS)
    assert walk.motion.num_frames == 300  # a closed path never ends
    root = walk.motion.root_positions
    radius = np.hypot(root[:, 0], root[:, 2])
    assert np.max(np.abs(radius - r)) < 0.2 ** 2 / (8 * r) + 1e-3
    assert np.all(np.isfinite(root)) and np.ptp(root[:, 1]) > 0  # height from the network: finite, not constant
    # the height is the network's second translation output: make it the constant 0.37 (its row of the output
    # layer zero, its bias 0.37) and every root is at y = 0.37, on the same path
    R = 4 * 4  # 4 joints x 4 rotation outputs, then offset and height
    fixed = dict(params, **{k: params[k].copy() for k in ("fc.weight", "fc.bias")})
    fixed["fc.weight"][R + 1], fixed["fc.bias"][R + 1] = 0.0, 0.37
    flat = W.generate_walk(fixed, net, pp, pc, sk, seed_rot, feats, circle_path(r), 0.5, 30, fps=FPS)
    np.testing.assert_allclose(flat.motion.root_positions[:, 1], 0.37, rtol=1e-6)
    assert np.max(np.abs(np.hypot(flat.motion.root_positions[:, 0], flat.motion.root_positions[:, 2]) - r)) < 0.01
    assert G.bone_length_drift(walk.motion) < 1e-9


def test_generation_follows_an_open_path_and_stops_at_its_end():
    net, params, pc, pp, sk, seed_rot, feats = _random_networks(seed=1)
    path = line_with_turn_path(8.0, 90.0, 4.0, 8.0)
    walk = W.generate_walk(params, net, pp, pc, sk, seed_rot, feats, path, 0.5, 10_000, fps=FPS)
    assert walk.motion.num_frames < 10_000 and np.all(walk.distance < walk.path.length)
    xz = walk.motion.root_positions[:, [0, 2]]
    pts = path.points
    # distance from each root position to the input polyline: within the spline's resolution (1/5 unit)
    a, b = pts[:-1], pts[1:]
    d = xz[:, None] - a[None]
    ab = b - a
    t = np.clip(np.sum(d * ab, -1) / np.sum(ab * ab, -1), 0, 1)
    dist = np.linalg.norm(d - t[..., None] * ab, axis=-1).min(axis=1)
    assert dist.max() < 0.2


def test_controls_carry_the_pace_network_output():
    """The facing and speed controls fed at each step are the pace network's output along the path (run
    independently here), and the seed clip is turned to the pace facing at s = 0."""
    net, params, pc, pp, sk, seed_rot, feats = _random_networks(seed=2)
    path = circle_path(6.0)
    walk = W.generate_walk(params, net, pp, pc, sk, seed_rot, feats, path, 0.8, 60, fps=FPS)
    tracks = pace.predict(pp, pc, path, 0.8)
    face = tracks.interpolate(walk.travelled, "direction")
    assert np.allclose(walk.controls[:, 4:6], face, atol=1e-12)
    amp = tracks.interpolate(walk.travelled, "amplitude")[:, 0]
    assert np.allclose(np.hypot(walk.controls[:, 0], walk.controls[:, 1]), amp, atol=1e-12)
    assert np.allclose(np.diff(walk.travelled), amp[:-1], atol=1e-9)
    rot, f2 = W.align_seed(seed_rot, feats, face[0])
    assert np.allclose(f2[-1, 6:8], tracks.interpolate(0.0, "direction"), atol=1e-9)


def test_foot_skating_metric():
    pos = np.zeros((5, 2, 3))
    pos[:, 1, 0] = np.arange(5) * 0.1           # joint 1 slides on the floor at 0.1 units per frame
    pos[:, 0, 1] = np.array([0, 0, 1, 1, 0.0])  # joint 0 lifts
    out = G.foot_skating(pos, [1], fps=30)
    assert out["contact_fraction"] == 1.0
    assert out["speed_cm_s"] == pytest.approx(0.1 * 30 * LD.QUATERNET_UNIT_CM)


def test_parse_path_and_speed(tmp_path):
    assert G.parse_path("circle:r=2").length == pytest.approx(2 * math.pi * 200 / LD.QUATERNET_UNIT_CM, rel=1e-2)
    assert G.parse_path("figure8").closed and not G.parse_path("line-turn:turn=-45").closed
    f = tmp_path / "p.csv"
    f.write_text("x,z\n0,0\n1,0\n2,1\n")
    assert G.parse_path(str(f)).points[-1] == pytest.approx([2 * 100 / LD.QUATERNET_UNIT_CM, 100 / LD.QUATERNET_UNIT_CM])
    assert G.parse_speed("run") == 1.2 and G.parse_speed("0.7") == 0.7
    for bad in ("square", "circle:q=1", "circle:r=x"):
        with pytest.raises(ValueError):
            G.parse_path(bad)
    with pytest.raises(ValueError):
        G.parse_speed("fly")


def test_generate_command_writes_bvh_json_png(trained, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = tmp_path / "walk.bvh"
    code = main(["generate", "--model", "quaternet-long", "--checkpoint", str(trained / "pose" / "checkpoint.npz"),
                 "--pace", str(trained / "pace" / "checkpoint.npz"), "--path", "circle:r=2", "--speed", "walk",
                 "--seconds", "2", "--out", str(out), "--controls", str(tmp_path / "c.json"),
                 "--png", str(tmp_path / "w.png")])
    assert code == 0
    m = read_bvh(out)
    assert m.num_frames == 60 and abs(m.frame_time - 1 / 30) < 1e-6
    doc = json.loads((tmp_path / "c.json").read_text())
    assert len(doc["frames"]) == 60 and len(doc["frames"][0]["controls"]) == 6
    assert (tmp_path / "w.png").stat().st_size > 1000
    text = capsys.readouterr().out
    assert "bone-length drift" in text and "foot skating" in text
    assert main(["generate", "--model", "quaternet-long", "--checkpoint", str(trained / "pose" / "checkpoint.npz"),
                 "--out", str(out)]) == 2  # --pace missing


def test_export_parity(trained, tmp_path):
    """spec/deploy.md §12: the exported step (5 chained steps from h0) and pace network against NumPy."""
    pytest.importorskip("onnxruntime")
    from refimpl.services import export_onnx, load_trained, verify_onnx
    pose, pm = load_trained(trained / "pose" / "checkpoint.npz"), load_trained(trained / "pace" / "checkpoint.npz")
    written = export_onnx(pose, tmp_path)
    assert set(written) == {"step", "h0", "seed"}
    assert set(export_onnx(pm, tmp_path)) == {"pace"}
    check = verify_onnx(pose, tmp_path, seed=1)
    assert check["ok"] and check["step"] < 1e-4
    check = verify_onnx(pm, tmp_path, seed=1)
    assert check["ok"] and check["pace"] < 1e-4
    from deploy.models import runtime_for_dir
    rt = runtime_for_dir(tmp_path)
    ds = LP.build_dataset("cmu_expmap", [str(Path(L.__file__).parents[1] / "data/sample/expmap/test/walking/"
                                            "walking_1.txt")], prefix=6, target=8)
    res = LP.evaluate(ds, L.methods({"numpy": recipe.make_method(pose), "onnx": L.onnx_method(rt)}))
    assert abs(res["numpy"]["mean_position"] - res["onnx"]["mean_position"]) < 1e-3
    assert res["zero_velocity"]["windows"] == res["numpy"]["windows"] > 0


_BLENDER_SCRIPT = r'''
import builtins, sys, json
_open = builtins.open
builtins.open = lambda file, mode="r", *a, **k: _open(file, mode.replace("U", ""), *a, **k)  # Blender 3.4: 'rU'
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
args = sys.argv[sys.argv.index("--") + 1:]
bpy.ops.import_anim.bvh(filepath=args[0], global_scale=1.0, rotate_mode="NATIVE", axis_forward="-Z", axis_up="Y")
arm = [o for o in bpy.data.objects if o.type == "ARMATURE"][0]
out = {}
for f in (1, 20, 40):
    bpy.context.scene.frame_set(f)
    out[f] = {b.name: list(arm.matrix_world @ b.head) for b in arm.pose.bones}
print("RESULT " + json.dumps(out))
'''


def test_generated_bvh_opens_in_blender_with_the_same_motion(tmp_path):
    """spec/locomotion.md §9: Blender's BVH importer reproduces our joint positions (its Z-up = (x, −z, y))."""
    import shutil
    import subprocess
    blender = shutil.which("blender")
    if blender is None:
        pytest.skip("blender is not installed")
    net, params, pc, pp, _, _, _ = _random_networks(J=6, seed=4)
    sk = Skeleton([-1, 0, 1, 2, 0, 4], np.array([[0, 0, 0], [2, -1, 0], [0, -9, 0], [0, -8, 1], [-2, -1, 0],
                                                 [0, -9, 0.0]]),
                  names=["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg"])
    seed_rot = np.tile(np.array([1.0, 0, 0, 0]), (5, 6, 1))
    feats = np.zeros((5, 8))
    feats[:, 7] = 1.0
    walk = W.generate_walk(params, net, pp, pc, sk, seed_rot, feats, circle_path(8.0), 0.5, 40, fps=FPS)
    bvh = tmp_path / "w.bvh"
    G.write_outputs(walk, bvh=bvh)
    script = tmp_path / "check.py"
    script.write_text(_BLENDER_SCRIPT)
    res = subprocess.run([blender, "-b", "--python", str(script), "--", str(bvh)], capture_output=True, text=True,
                         timeout=300)
    line = next((ln for ln in res.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, res.stdout[-2000:] + res.stderr[-2000:]
    got = json.loads(line[len("RESULT "):])
    ours = read_bvh(bvh)
    pos = ours.positions()
    for f in (1, 20, 40):
        for j, name in enumerate(ours.skeleton.names):
            if name in got[str(f)]:
                v = pos[f - 1, j]
                assert np.allclose(got[str(f)][name], [v[0], -v[2], v[1]], atol=0.05), (f, name)


@pytest.mark.parametrize("output", ["euler_yzx", "axis_angle", "positions"])
def test_ablation_recipe_gradient_central_differences(output):
    """QN §4.4.2-4.4.3 ablations: the same recurrent network with 3J raw outputs; loss through the conversion to
    quaternions and FK (or the Euclidean position loss); gradients of every parameter array."""
    rng = np.random.default_rng(7)
    batch, offsets, parents = _tiny_batch(rng)
    sk = Skeleton(parents, offsets)
    batch["inputs"] = recipe.ablation_inputs(batch["inputs"], output, sk)
    net = recipe.QuaterNetLongConfig(num_joints=3, hidden_size=3, controls_hidden=2, output=output).network()
    assert net.num_joints == 1 and net.num_outputs == 3 * 3 + 2
    params = quaternet.init_params(net, rng)
    _, grads = recipe.loss_and_grads(params, batch, net, offsets, parents, output=output)
    check_gradients(lambda: recipe.loss_and_grads(params, batch, net, offsets, parents, output=output)[0], params,
                    grads, **TOL_FD, max_entries=12)


def test_ablation_inputs_and_rollout_layout():
    """Ground-truth windows in an ablation's layout decode back to the same FK positions."""
    rng = np.random.default_rng(3)
    batch, offsets, parents = _tiny_batch(rng, B=1)
    sk = Skeleton(parents, offsets)
    J = 3
    q = batch["inputs"][..., :4 * J].reshape(1, 7, J, 4)
    for output in ("euler_xyz", "axis_angle"):
        x = recipe.ablation_inputs(batch["inputs"], output, sk)
        assert x.shape == (1, 7, 4 + 3 * J + 8) and np.all(x[..., 0] == 1)
        q2, _ = recipe.quat_from_rotations(x[..., 4:4 + 3 * J].reshape(1, 7, J, 3), output)
        assert np.allclose(sk.forward_kinematics(q2, np.zeros((1, 7, 3))), sk.forward_kinematics(q, np.zeros((1, 7, 3))))
    x = recipe.ablation_inputs(batch["inputs"], "positions", sk)
    root = np.zeros((1, 7, 3))
    root[..., 1] = batch["inputs"][..., 4 * J + 1]
    assert np.allclose(x[..., 4:4 + 3 * J].reshape(1, 7, J, 3), sk.forward_kinematics(q, root))
    net = recipe.QuaterNetLongConfig(num_joints=J, hidden_size=4, output="positions").network()
    params = quaternet.init_params(net, rng)
    pos, tr = recipe.rollout(params, net, batch["inputs"], 3, "positions", sk)
    assert pos.shape == (1, 4, J, 3) and tr.shape == (1, 4, 2)
    with pytest.raises(ValueError):
        recipe.QuaterNetLongConfig(output="matrix")


def test_render_path_motion_gif_and_errors(tmp_path):
    pytest.importorskip("matplotlib")
    from refimpl.render import render_path_motion
    net, params, pc, pp, sk, seed_rot, feats = _random_networks(seed=5)
    walk = W.generate_walk(params, net, pp, pc, sk, seed_rot, feats, circle_path(5.0), 0.5, 8, fps=FPS)
    pos = walk.motion.positions()
    out = render_path_motion(tmp_path / "w.gif", pos, sk.parents, walk.path.points, closed=True, stride=2)
    assert out.stat().st_size > 1000 and out.read_bytes()[:3] == b"GIF"
    with pytest.raises(ValueError):
        render_path_motion(tmp_path / "w.jpg", pos, sk.parents, walk.path.points)
    with pytest.raises(ValueError):
        render_path_motion(tmp_path / "w.png", pos, sk.parents, walk.path.points[:1])


def test_eval_quaternet_long_through_the_command_line(trained, capsys, tmp_path):
    """spec/cli.md §5 (locomotion): `refimpl eval --checkpoint` of a quaternet-long model prints the held-out
    position/velocity errors against zero-velocity and writes them as JSON; they equal the task's evaluate."""
    from refimpl.services import evaluate_model, load_trained

    ckpt = trained / "pose" / "checkpoint.npz"
    out = tmp_path / "loco_eval.json"
    capsys.readouterr()
    assert main(["eval", "--checkpoint", str(ckpt), "--data", "sample", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "quaternet-long" in printed and "zero_velocity" in printed and "pos mean cm" in printed
    got = json.loads(out.read_text())
    assert set(got) == {"quaternet-long", "zero_velocity"}
    model = load_trained(ckpt)
    ds = L.load_eval_data("sample", model.extra)
    assert ds.prefix == 6 and ds.target == 8
    ref = evaluate_model(model, ds)
    for name in got:
        np.testing.assert_allclose(got[name]["position"], ref[name]["position"], rtol=1e-12)
        assert got[name]["windows"] == ref[name]["windows"] > 0
    # the pace network has no protocol here: a usage error naming its validation log
    assert main(["eval", "--checkpoint", str(trained / "pace" / "checkpoint.npz"), "--data", "sample"]) == 2
    assert "loss_val.csv" in capsys.readouterr().err


def test_generate_warns_when_the_path_ends_before_seconds(trained, tmp_path, capsys):
    """#27: an open path shorter than --seconds used to be cut short without a word."""
    path = tmp_path / "short.csv"
    path.write_text("0,0\n0.5,0\n1,0\n")
    out = tmp_path / "short.bvh"
    assert main(["generate", "--model", "quaternet-long", "--checkpoint", str(trained / "pose" / "checkpoint.npz"),
                 "--pace", str(trained / "pace" / "checkpoint.npz"), "--path", str(path), "--speed", "walk",
                 "--seconds", "30", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    frames = read_bvh(out).num_frames
    assert frames < 900
    assert f"warning: the path ends after {frames / 30:.1f} s" in err and "asked for 900 frames" in err
    # a path long enough: no warning
    assert main(["generate", "--model", "quaternet-long", "--checkpoint", str(trained / "pose" / "checkpoint.npz"),
                 "--pace", str(trained / "pace" / "checkpoint.npz"), "--path", "circle:r=2", "--seconds", "1",
                 "--out", str(out)]) == 0
    assert "warning" not in capsys.readouterr().err
