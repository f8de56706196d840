"""twin_croc's pinocchio model is twin's arm: its tcp, DH frames and sphere-proxy centres equal
`twin.robot.kinematics` (and the nmpc sphere model it shares) to round-off on random configurations."""

from __future__ import annotations

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")
pytest.importorskip("crocoddyl")

from twin.planning.proxy_spheres import TCP_FRAME, robot_spheres, sphere_centres  # noqa: E402
from twin.plugin import URArm  # noqa: E402
from twin_croc.pinocchio_arm import TCP_FRAME_NAME, arm_model, dh_frame_name, sphere_frames  # noqa: E402
from twin_nmpc.params import NMPCParams  # noqa: E402


def _configurations(n: int) -> np.ndarray:
    kin = URArm()
    rng = np.random.default_rng(28)
    return rng.uniform(kin.joint_limits[:, 0], kin.joint_limits[:, 1], size=(n, 6))


def test_the_tcp_and_every_dh_frame_equal_twins_kinematics():
    kin = URArm()
    model = arm_model(kin)
    data = model.createData()
    assert model.nq == 6 and list(model.names)[1:] == list(kin.joint_names)
    np.testing.assert_array_equal(model.lowerPositionLimit, kin.joint_limits[:, 0])
    np.testing.assert_array_equal(model.upperPositionLimit, kin.joint_limits[:, 1])
    qs = _configurations(200)
    frames = kin.dh_frames(qs)
    worst = 0.0
    for q, F in zip(qs, frames, strict=True):
        pin.framesForwardKinematics(model, data, q)
        worst = max(worst, float(np.abs(data.oMf[model.getFrameId(TCP_FRAME_NAME)].homogeneous - kin.fk(q)).max()))
        for i in range(1, 7):
            worst = max(worst, float(np.abs(data.oMf[model.getFrameId(dh_frame_name(i))].homogeneous - F[i]).max()))
    assert worst < 1e-9, worst


def test_sphere_frames_sit_where_the_nmpc_sphere_model_puts_the_spheres():
    kin = URArm()
    p = NMPCParams()
    spheres = robot_spheres(p.tool_spheres, p.wrist_spheres)
    spheres = np.vstack([spheres, [[3, 0.01, -0.02, 0.03, 0.05]]])  # a sphere on a DH frame below the wrist too
    model = arm_model(kin)
    ids = sphere_frames(model, spheres, tcp_index=TCP_FRAME)
    data = model.createData()
    qs = _configurations(50)
    expected = sphere_centres(kin.dh_frames(qs), kin.tcp_offset_m, spheres)
    for q, centres in zip(qs, expected, strict=True):
        pin.framesForwardKinematics(model, data, q)
        got = np.array([data.oMf[i].translation for i in ids])
        np.testing.assert_allclose(got, centres, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="sphere 0: frame 9"):
        sphere_frames(arm_model(kin), np.array([[9, 0.0, 0.0, 0.0, 0.1]]), tcp_index=TCP_FRAME)
