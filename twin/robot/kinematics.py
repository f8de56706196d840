"""Kinematics of a Universal Robots arm (`robot.model`, default the UR5e; `twin.robot.ur_models` has their DH
parameters): forward kinematics, every analytic IK branch, Jacobian, manipulability.

Frames: `base` is the robot base (DH frame 0, z up, at the world origin); `flange` is tool0 (DH frame 6);
`tcp` is the point between the gripper's fingertips, `tcp_offset_m` along the flange z axis. IK uses the
closed form of `ur_analytic_ik` (8 branches), then adds every 2*pi wrap that stays inside the joint limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, overload

import numpy as np
import ur_analytic_ik

from twin.errors import InvalidRequestError
from twin.robot.ur_models import UR_MODELS, ur_model
from twin.timing import stage

if TYPE_CHECKING:
    from twin.robot.urdf_model import RobotModel

__all__ = [
    "DH_A",
    "DH_ALPHA",
    "DH_D",
    "JOINT_LIMITS",
    "JOINT_NAMES",
    "TCP_OFFSET_M",
    "DHParameters",
    "URArm",
    "dh_frames",
    "jacobian_one",
    "jacobians",
    "wrap_to_pi",
]

JOINT_NAMES = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
DH_D = np.array(UR_MODELS["ur5e"].d, dtype=float)  # the default arm's (UR5e) DH parameters
DH_A = np.array(UR_MODELS["ur5e"].a, dtype=float)
DH_ALPHA = np.array(UR_MODELS["ur5e"].alpha, dtype=float)
_TWO_PI = 2.0 * math.pi
JOINT_LIMITS = np.array([[-_TWO_PI, _TWO_PI]] * 6)
JOINT_LIMITS[2] = [-math.pi, math.pi]
TCP_OFFSET_M = 0.135  # tcp frame of urdf/ur5e.urdf, along tool0 z
_FRAMES = ("tcp", "flange")


@overload
def wrap_to_pi(a: float) -> float: ...
@overload
def wrap_to_pi(a: np.ndarray) -> np.ndarray: ...
def wrap_to_pi(a: np.ndarray | float) -> np.ndarray | float:
    """Angles mapped to [-pi, pi): the shortest angular difference for continuous joints."""
    return (np.asarray(a) + math.pi) % _TWO_PI - math.pi


_CA, _SA = np.cos(DH_ALPHA), np.sin(DH_ALPHA)


def dh_frames(qs: np.ndarray, dh: DHParameters | None = None) -> np.ndarray:
    """(n, 7, 4, 4) DH frames 0..6 (6 = flange) in the base frame for (n, 6) configurations of the arm with
    DH parameters `dh` (default the UR5e's; compiled loop, `twin.robot.kinematics_kernel`, loaded on first use)."""
    if dh is None:
        return _frames(qs, DH_D, DH_A, _CA, _SA)
    return _frames(qs, dh.d, dh.a, np.cos(dh.alpha), np.sin(dh.alpha))


def _frames(qs: np.ndarray, d: np.ndarray, a: np.ndarray, ca: np.ndarray, sa: np.ndarray) -> np.ndarray:
    from twin.robot.kinematics_kernel import dh_frames_into  # lazy: numba (compiled on first use)

    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    if not (qs.flags.c_contiguous and qs.flags.writeable):
        qs = np.array(qs, order="C")  # one compiled specialisation: writeable C float64
    F = np.empty((qs.shape[0], 7, 4, 4))
    dh_frames_into(qs, d, a, ca, sa, F)
    return F


def jacobians(frames: np.ndarray, tool: np.ndarray) -> np.ndarray:
    """(n, 6, 6) geometric Jacobians (rows vx, vy, vz, wx, wy, wz) of the point `tool` (4, 4, in the
    flange frame), from DH frames (n, 7, 4, 4)."""
    p = frames[:, 6, :3, :3] @ tool[:3, 3] + frames[:, 6, :3, 3]  # (n, 3)
    z = frames[:, :6, :3, 2].transpose(0, 2, 1)  # (n, 3, 6): column i is z_i
    r = p[:, :, None] - frames[:, :6, :3, 3].transpose(0, 2, 1)  # (n, 3, 6)
    J = np.empty((frames.shape[0], 6, 6))
    J[:, 0] = z[:, 1] * r[:, 2] - z[:, 2] * r[:, 1]
    J[:, 1] = z[:, 2] * r[:, 0] - z[:, 0] * r[:, 2]
    J[:, 2] = z[:, 0] * r[:, 1] - z[:, 1] * r[:, 0]
    J[:, 3:] = z
    return J


def _dh_lists(d: np.ndarray, a: np.ndarray, alpha: np.ndarray) -> tuple[list[float], ...]:
    return (
        [float(x) for x in a],
        [float(x) for x in d],
        [round(math.cos(x), 15) for x in alpha],
        [round(math.sin(x), 15) for x in alpha],
    )


_UR5E_LISTS = _dh_lists(DH_D, DH_A, DH_ALPHA)


def jacobian_one(q: np.ndarray, tool: np.ndarray, dh: DHParameters | None = None) -> np.ndarray:
    """(6, 6) geometric Jacobian at one configuration `q` (6,), for the point `tool` (4, 4) in the flange,
    of the arm with DH parameters `dh` (default the UR5e's).

    Plain float arithmetic: for one configuration this is ~6x faster than numpy's small-array overhead.
    """
    return _jacobian(q, tool, _UR5E_LISTS if dh is None else _dh_lists(dh.d, dh.a, dh.alpha))


def _jacobian(q: np.ndarray, tool: np.ndarray, lists: tuple[list[float], ...]) -> np.ndarray:
    _A, _D, _CA1, _SA1 = lists
    cos, sin = math.cos, math.sin
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    ox = oy = oz = 0.0
    zs, os_ = [], []
    for i, qi in enumerate(np.asarray(q, dtype=float).tolist()):
        zs.append((r02, r12, r22))
        os_.append((ox, oy, oz))
        c, s, ca, sa, a, d = cos(qi), sin(qi), _CA1[i], _SA1[i], _A[i], _D[i]
        tx, ty = a * c, a * s
        ox, oy, oz = (
            ox + r00 * tx + r01 * ty + r02 * d,
            oy + r10 * tx + r11 * ty + r12 * d,
            oz + r20 * tx + r21 * ty + r22 * d,
        )
        m01, m02, m11, m12 = -s * ca, s * sa, c * ca, -c * sa
        r00, r01, r02 = r00 * c + r01 * s, r00 * m01 + r01 * m11 + r02 * sa, r00 * m02 + r01 * m12 + r02 * ca
        r10, r11, r12 = r10 * c + r11 * s, r10 * m01 + r11 * m11 + r12 * sa, r10 * m02 + r11 * m12 + r12 * ca
        r20, r21, r22 = r20 * c + r21 * s, r20 * m01 + r21 * m11 + r22 * sa, r20 * m02 + r21 * m12 + r22 * ca
    t0, t1, t2 = float(tool[0, 3]), float(tool[1, 3]), float(tool[2, 3])
    px = ox + r00 * t0 + r01 * t1 + r02 * t2
    py = oy + r10 * t0 + r11 * t1 + r12 * t2
    pz = oz + r20 * t0 + r21 * t1 + r22 * t2
    cols = []
    for (zx, zy, zz), (qx, qy, qz) in zip(zs, os_, strict=True):
        dx, dy, dz = px - qx, py - qy, pz - qz
        cols.append((zy * dz - zz * dy, zz * dx - zx * dz, zx * dy - zy * dx, zx, zy, zz))
    return np.array(cols).T


@dataclass(frozen=True)
class DHParameters:
    """The standard Denavit-Hartenberg parameters of the arm, per joint (6,): d and a in m, alpha in rad."""

    d: np.ndarray
    a: np.ndarray
    alpha: np.ndarray


def _axes_frame(p1: np.ndarray, a1: np.ndarray, p2: np.ndarray, a2: np.ndarray) -> np.ndarray:
    """(4, 4) frame of two joint axes (point, unit direction): x along the first, y the second's direction
    square to it, origin the point of the first axis nearest the second (identity rotation when parallel)."""
    T = np.eye(4)
    T[:3, 3] = p1
    b = float(a1 @ a2)
    y = a2 - b * a1
    if np.linalg.norm(y) < 1e-9:
        return T
    y = y / np.linalg.norm(y)
    w = p1 - p2
    T[:3, :3] = np.column_stack([a1, y, np.cross(a1, y)])
    T[:3, 3] += (b * float(a2 @ w) - float(a1 @ w)) / (1.0 - b * b) * a1
    return T


def _root_note(root_pose: np.ndarray) -> str:
    """', its root placed ... from the arm's base' for a URDF `urdf_base` moved; '' for one rooted at the base."""
    if np.array_equal(root_pose, np.eye(4)):
        return ""
    turn = math.acos(max(-1.0, min(1.0, (float(np.trace(root_pose[:3, :3])) - 1.0) / 2.0)))
    shift = float(np.linalg.norm(root_pose[:3, 3]))
    return f" (with its root placed {shift * 1e3:.3g} mm and {turn:.3g} rad from the arm's base)"


def _tool(frame: str, tcp_offset_m: float) -> np.ndarray:
    if frame not in _FRAMES:
        raise InvalidRequestError(f"unknown frame {frame!r}; allowed: {', '.join(_FRAMES)}")
    T = np.eye(4)
    if frame == "tcp":
        T[2, 3] = tcp_offset_m
    return T


class URArm:
    """Analytic kinematics of a Universal Robots arm (`model`: a `twin.robot.ur_models` name, default the UR5e)
    with our gripper.

    `q`: (6,) joint angles in rad, order shoulder_pan .. wrist_3. Poses are (4, 4) homogeneous
    transforms of the named frame in the base frame, metres.
    """

    def __init__(
        self, *, model: str = "ur5e", tcp_offset_m: float = TCP_OFFSET_M, joint_limits: np.ndarray | None = None
    ):
        arm = ur_model(model)
        self.model = arm.name
        self._dh = DHParameters(
            np.array(arm.d, dtype=float), np.array(arm.a, dtype=float), np.array(arm.alpha, dtype=float)
        )
        self._lists = _dh_lists(self._dh.d, self._dh.a, self._dh.alpha)
        self._ca, self._sa = np.cos(self._dh.alpha), np.sin(self._dh.alpha)
        self._ik_module = getattr(ur_analytic_ik, arm.name)
        self.tcp_offset_m = float(tcp_offset_m)
        self.joint_limits = np.array(JOINT_LIMITS if joint_limits is None else joint_limits, dtype=float)
        self._tool = {f: _tool(f, self.tcp_offset_m) for f in _FRAMES}
        self._tool_inv = {f: np.linalg.inv(T) for f, T in self._tool.items()}
        with stage("imports"):  # load (or, the first time on a machine, compile) the DH kernel now, not in a
            self.dh_frames(np.zeros((1, 6)))  # planner's time limit

    def urdf_base(self, model: RobotModel) -> np.ndarray:
        """(4, 4) pose of a URDF's root link in this arm's base frame, from the first two arm joints at q = 0:
        the base axis on the URDF's first joint axis, turned so the second joint's axis is where the DH
        puts it, and the two axes crossing where the DH has them cross. The identity (exactly, within 1e-9)
        for twin's URDFs, whose root is the base; a world link above the arm, or a base_link turned a half
        turn from the controller's base (ur_description before 2020), otherwise. `urdf_mismatch` then checks
        every joint and the flange in that frame."""
        if len(model.arm_joints) < 2:
            return np.eye(4)
        q0 = np.zeros((1, 6))
        poses = np.linalg.inv(model.root_pose) @ model.link_pose_array(q0)[0]
        axes = []
        for name in model.arm_joints[:2]:
            j = model.joints[name]
            F = poses[model.link_index[j.parent]] @ j.origin
            axes += [F[:3, 3], F[:3, :3] @ j.axis]
        dh = self.dh_frames(q0)[0]
        root = _axes_frame(dh[0, :3, 3], dh[0, :3, 2], dh[1, :3, 3], dh[1, :3, 2]) @ np.linalg.inv(_axes_frame(*axes))
        return np.eye(4) if float(np.abs(root - np.eye(4)).max()) < 1e-9 else root

    def fit_urdf(self, model: RobotModel) -> RobotModel:
        """A URDF model in this arm's base frame (`urdf_base`), with a `tcp` frame at this arm's TCP (tool0 +
        `tcp_offset_m` along z) when the URDF has none (a collision model without twin's gripper). Check it
        with `urdf_mismatch`."""
        fitted = model.rebased(self.urdf_base(model))
        if "tcp" not in fitted.link_index and "tool0" in fitted.link_index:
            fitted = fitted.with_frame("tcp", "tool0", self._tool["tcp"])
        return fitted

    def urdf_mismatch(self, model: RobotModel, *, samples: int = 16, tol: float = 1e-6) -> str | None:
        """Where a robot URDF's arm differs from this arm's DH kinematics, in words; None when it matches.

        Checked on `samples` seeded configurations: each arm joint's axis must lie on the DH axis it stands
        for (z of DH frame i-1: the same line, the same direction), tool0 must be the DH flange and a tcp link
        this arm's TCP, within `tol` (m, rad), in the model's base frame (`fit_urdf` puts a URDF there)."""
        if "tool0" not in model.link_index:
            return "it has no tool0 link (the flange)"
        qs = np.random.default_rng(0).uniform(-math.pi, math.pi, (samples, 6))
        poses = model.link_pose_array(qs)
        dh = self.dh_frames(qs)
        joints = {j.name: j for j in model.joint_order}
        for i, name in enumerate(model.arm_joints):
            j = joints[name]
            frame = poses[:, model.link_index[j.parent]] @ j.origin  # the joint frame, before it turns
            axis = np.einsum("nij,j->ni", frame[:, :3, :3], j.axis)
            z, o = dh[:, i, :3, 2], dh[:, i, :3, 3]
            tilt = float(np.abs(axis - z).max())
            off = float(np.linalg.norm(np.cross(frame[:, :3, 3] - o, z), axis=1).max())
            if tilt > tol or off > tol:
                why = f"joint {name}: its axis is {off * 1e3:.3g} mm off and {tilt:.3g} rad turned from DH axis {i}"
                return why + _root_note(model.root_pose)
        flange = poses[:, model.link_index["tool0"]]
        err_p = float(np.abs(flange[:, :3, 3] - dh[:, 6, :3, 3]).max())
        err_r = float(np.abs(flange[:, :3, :3] - dh[:, 6, :3, :3]).max())
        if err_p > tol or err_r > tol:
            why = f"tool0 is {err_p * 1e3:.3g} mm and {err_r:.3g} (rotation entries) from the DH flange"
            return why + _root_note(model.root_pose)
        if "tcp" in model.link_index:  # the planners' TCP (pose goals, the held object) is the arm's
            tcp = np.linalg.inv(flange[0]) @ poses[0, model.link_index["tcp"]]
            err = float(np.abs(tcp - self._tool["tcp"]).max())
            if err > tol:
                where = f"tool0 + {self.tcp_offset_m} m along z"
                return f"its tcp link is {err * 1e3:.3g} mm (or rotation entries) from the arm's TCP, {where}"
        return None

    # ---- forward kinematics -------------------------------------------------------------------
    def fk(self, q: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """(4, 4) pose of `frame` ('tcp' or 'flange') in the base frame."""
        q = np.asarray(q, dtype=float)
        if q.shape != (6,):
            raise InvalidRequestError(f"q must have shape (6,), got {q.shape}")
        return self._ik_module.forward_kinematics(*q) @ self._tool_for(frame)

    def fk_batch(self, qs: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """(n, 4, 4) poses for (n, 6) configurations (vectorised DH)."""
        return self.dh_frames(qs)[:, 6] @ self._tool_for(frame)

    def _tool_for(self, frame: str) -> np.ndarray:
        tool = self._tool.get(frame)
        if tool is None:
            raise InvalidRequestError(f"unknown frame {frame!r}; allowed: {', '.join(_FRAMES)}")
        return tool

    def dh_frames(self, qs: np.ndarray) -> np.ndarray:
        """(n, 7, 4, 4) DH frames 0..6 in the base frame for (n, 6) configurations."""
        return _frames(qs, self._dh.d, self._dh.a, self._ca, self._sa)

    @property
    def dh(self) -> DHParameters:
        """The DH parameters (copies), for plugins that build their own symbolic kinematics (NMPC)."""
        return DHParameters(self._dh.d.copy(), self._dh.a.copy(), self._dh.alpha.copy())

    @property
    def joint_names(self) -> tuple[str, ...]:
        return JOINT_NAMES

    def tool_transform(self, frame: str = "tcp") -> np.ndarray:
        """(4, 4) transform of `frame` ('tcp' or 'flange') in the flange frame."""
        return self._tool_for(frame).copy()

    def jacobians_from_frames(self, frames: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """(n, 6, 6) Jacobians of `frame` from DH frames already computed by `dh_frames` (saves a second FK)."""
        return jacobians(frames, self._tool_for(frame))

    def jacobian_batch(self, qs: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """(n, 6, 6) geometric Jacobians for (n, 6) configurations (rows vx, vy, vz, wx, wy, wz)."""
        return jacobians(self.dh_frames(qs), self._tool_for(frame))

    # ---- inverse kinematics -------------------------------------------------------------------
    def ik(self, T: np.ndarray, frame: str = "tcp", *, tol: float = 1e-6, all_wraps: bool = True) -> np.ndarray:
        """(k, 6) every analytic solution for pose `T` of `frame`, with all 2*pi wraps inside the limits.

        Solutions that do not reproduce `T` within `tol` (m and rad, near singular branches) are dropped.
        k = 0 when the pose is out of reach. `all_wraps=False` gives only the (at most 8) branches with
        every angle in [-pi, pi).
        """
        T = np.asarray(T, dtype=float)
        if T.shape != (4, 4):
            raise InvalidRequestError(f"T must be a (4, 4) homogeneous transform, got shape {T.shape}")
        T_flange = T @ self._tool_inv.get(frame, self._tool_for(frame))
        branches: list[np.ndarray] = []
        for s in self._ik_module.inverse_kinematics(T_flange):
            s = np.asarray(s, dtype=float)
            if not np.all(np.isfinite(s)):
                continue
            s = wrap_to_pi(s)
            F = self._ik_module.forward_kinematics(*s)
            if np.abs(F[:3, 3] - T_flange[:3, 3]).max() > tol or np.abs(F[:3, :3] - T_flange[:3, :3]).max() > tol:
                continue
            # branches can coincide at singular poses: keep one of each
            if not any(np.abs(s - b).max() < 1e-9 for b in branches):
                branches.append(s)
        if not branches:
            return np.zeros((0, 6))
        arr = np.array(branches)
        if not all_wraps:
            return arr[[self.within_limits(a) for a in arr]]
        return np.concatenate([self._wraps(a) for a in arr])

    def _wraps(self, s: np.ndarray) -> np.ndarray:
        """Every combination of s_j + {-2pi, 0, 2pi} inside the joint limits, (m, 6)."""
        cand = s[:, None] + np.array([-_TWO_PI, 0.0, _TWO_PI])[None, :]
        ok = (cand >= self.joint_limits[:, :1] - 1e-12) & (cand <= self.joint_limits[:, 1:] + 1e-12)
        options = [cand[j, ok[j]] for j in range(6)]
        grids = np.meshgrid(*options, indexing="ij")
        return np.stack([g.reshape(-1) for g in grids], axis=1)

    def within_limits(self, q: np.ndarray) -> bool:
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.joint_limits[:, 0] - 1e-12) and np.all(q <= self.joint_limits[:, 1] + 1e-12))

    # ---- differential kinematics --------------------------------------------------------------
    def jacobian(self, q: np.ndarray, frame: str = "tcp") -> np.ndarray:
        """(6, 6) geometric Jacobian in the base frame: rows vx, vy, vz, wx, wy, wz."""
        return _jacobian(np.asarray(q, dtype=float), self._tool_for(frame), self._lists)

    def manipulability(self, q: np.ndarray, frame: str = "tcp") -> float:
        """Yoshikawa's measure sqrt(det(J J^T)); zero at a singularity."""
        J = self.jacobian(q, frame)
        return float(math.sqrt(max(np.linalg.det(J @ J.T), 0.0)))

    def condition_number(self, q: np.ndarray, frame: str = "tcp") -> float:
        """cond(J); the seed's defensive IK penalises values above 500."""
        return float(np.linalg.cond(self.jacobian(q, frame)))
