"""The public names people rely on (issues' contracts; spec/architecture.md): importable from the top level,
and the package never imports deploy, onnx, onnxruntime or matplotlib."""
import subprocess
import sys

import numpy as np

import refimpl

CONTRACT = """quat_mul quat_conj quat_inv quat_normalize quat_rotate quat_slerp quat_fix quat_from_euler euler_from_quat
quat_from_axis_angle axis_angle_from_quat matrix_from_quat quat_from_matrix ortho6d_from_matrix matrix_from_ortho6d
dq_mul dq_conj dq_normalize dq_from_quat_translation translation_from_dq dq_transform_point
Skeleton read_bvh write_bvh Motion read_expmap""".split()


def test_contract_names_are_exported_at_top_level():
    missing = [n for n in CONTRACT if not hasattr(refimpl, n)]
    assert not missing, f"missing from refimpl: {missing}"
    for n in CONTRACT:
        assert n in refimpl.__all__, n


def test_all_is_consistent():
    assert len(set(refimpl.__all__)) == len(refimpl.__all__)
    for n in refimpl.__all__:
        assert hasattr(refimpl, n), n


def test_namespaces():
    from refimpl import losses, models, nn, representations  # noqa: F401
    assert callable(nn.gru_forward) and callable(losses.mse_loss_forward)
    assert callable(representations.encode)


def test_refimpl_imports_no_optional_dependency():
    code = ("import sys, refimpl, refimpl.cli, refimpl.demo, refimpl.render, refimpl.train, refimpl.models.qtg; "
            "bad = [m for m in ('deploy', 'onnx', 'onnxruntime', 'matplotlib', 'scipy', 'hypothesis') if m in sys.modules]; "
            "print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"importing refimpl pulled in: {out}"


def test_skeleton_forward_kinematics_contract_shapes():
    sk = refimpl.Skeleton([-1, 0, 1], np.array([[0.0, 0, 0], [0, 1, 0], [0, 1, 0]]))
    rot = np.tile(refimpl.quat_from_axis_angle(np.array([0.0, 0, np.pi / 2])), (5, 2, 3, 1))  # (5, 2, J, 4)
    pos = sk.forward_kinematics(rot, np.zeros((5, 2, 3)))
    assert pos.shape == (5, 2, 3, 3)
    # joint 1 sits 1 unit along the root-rotated y axis: R_z(90°) y = -x
    np.testing.assert_allclose(pos[0, 0, 1], [-1.0, 0.0, 0.0], atol=1e-12)
