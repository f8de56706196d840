"""The arm as a pinocchio model, built from twin's own kinematics so that Crocoddyl optimises the arm twin
judges: the joints, DH frames and tcp of `twin.plugin.URArm`, equal to its forward kinematics to round-off
(`tests/test_croc_model.py`), not a second description of the robot read from another file.

A DH link is `Rz(theta) Tz(d) Tx(a) Rx(alpha)`: joint i turns about the z axis of DH frame i-1, and the
fixed part `Tz(d) Tx(a) Rx(alpha)` is where DH frame i sits on joint i, which is also where joint i+1 is
placed on it. Frames `dh1` .. `dh6` (6: the flange) and `tcp` are pinocchio operational frames, so a
frame-placement or frame-translation residual of Crocoddyl reads them directly. A sphere of the collision
proxies (frame index, offset) becomes a frame of its own (`sphere_frames`).

Crocoddyl has no kinematic action model; the planner drives the arm through a free inverse-dynamics model,
so each link carries a small inertia (its values do not enter a kinematic problem, but the dynamics must not
be singular).

Import order matters with these wheels: pinocchio (or crocoddyl, which imports it) before mim_solvers, or
mim_solvers fails on a missing boost library.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

if TYPE_CHECKING:
    from twin.plugin import URArm

__all__ = ["TCP_FRAME_NAME", "arm_model", "dh_frame_name", "sphere_frames"]

TCP_FRAME_NAME = "tcp"
_LINK_INERTIA = pin.Inertia(0.5, np.zeros(3), np.eye(3) * 1e-3)  # kg, m, kg m^2: not singular, never read


def dh_frame_name(i: int) -> str:
    """Name of DH frame i (1..6; 6 is the flange) in `arm_model`'s model."""
    return f"dh{i}"


def _dh_fixed(d: float, a: float, alpha: float) -> pin.SE3:
    """Tz(d) Tx(a) Rx(alpha): where DH frame i sits on joint i."""
    c, s = math.cos(alpha), math.sin(alpha)
    R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return pin.SE3(R, np.array([a, 0.0, d]))


def arm_model(kin: URArm) -> pin.Model:
    """A pinocchio model of `kin`'s arm: six revolute joints named as twin names them, with twin's joint
    limits and the velocity limit left to the planner's request; frames `dh1` .. `dh6` and `tcp`."""
    dh = kin.dh
    model = pin.Model()
    model.name = "twin_arm"
    parent, placement = 0, pin.SE3.Identity()
    lo, hi = kin.joint_limits[:, 0], kin.joint_limits[:, 1]
    for i, name in enumerate(kin.joint_names):
        jid = model.addJoint(
            parent,
            pin.JointModelRZ(),
            placement,
            name,
            np.full(1, 1e3),  # effort, velocity: bounds of the inverse-dynamics model, not of the planner
            np.full(1, 1e3),
            np.array([lo[i]]),
            np.array([hi[i]]),
        )
        model.appendBodyToJoint(jid, _LINK_INERTIA, pin.SE3.Identity())
        placement = _dh_fixed(float(dh.d[i]), float(dh.a[i]), float(dh.alpha[i]))
        model.addFrame(pin.Frame(dh_frame_name(i + 1), jid, placement, pin.FrameType.OP_FRAME))
        parent = jid
    tcp = placement * pin.SE3(kin.tool_transform("tcp"))
    model.addFrame(pin.Frame(TCP_FRAME_NAME, parent, tcp, pin.FrameType.OP_FRAME))
    return model


def sphere_frames(model: pin.Model, spheres: np.ndarray, *, tcp_index: int, prefix: str = "sphere") -> list[int]:
    """Add one frame per sphere (n, 5) = (frame, x, y, z, r) of twin's sphere proxies, where `frame` is a DH
    frame index 1..6 or `tcp_index` for the tcp, and the offset is in that frame; returns their frame ids
    (the model gains frames `{prefix}0` .. `{prefix}{n-1}`)."""
    ids = []
    for k, (f, x, y, z, _) in enumerate(np.asarray(spheres, dtype=float)):
        base = TCP_FRAME_NAME if int(f) == tcp_index else dh_frame_name(int(f))
        if not model.existFrame(base):
            raise ValueError(f"sphere {k}: frame {int(f)} is neither a DH frame 1..6 nor the tcp ({tcp_index})")
        owner = model.frames[model.getFrameId(base)]
        offset = owner.placement * pin.SE3(np.eye(3), np.array([x, y, z]))
        ids.append(model.addFrame(pin.Frame(f"{prefix}{k}", owner.parentJoint, offset, pin.FrameType.OP_FRAME)))
    return ids
