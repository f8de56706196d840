"""The arm's kinematic chain compiled for the collision model: every link's world pose at q as a few numpy
products.

Why a module of its own: the planning scene poses its robot shapes millions of times, so the URDF chain is
reduced once to constants. Frame 0 is the root, frame k+1 the child link of arm joint k; every link is
rigidly attached to one of these 7 frames (gripper joints are not arm joints: the fingers are rigid at the
current finger opening). A joint's local transform is A + u*B + v*C with u = sin q, v = 1 - cos q
(revolute, Rodrigues) or u = q, v = 0 (prismatic). The sphere kernel (`twin.collision.sphere_kernel`) reads
the same constants, so the sphere check and FCL see the same poses.
"""

from __future__ import annotations

import numpy as np

from twin.robot.urdf_model import RobotModel

__all__ = ["CompiledChain"]


class CompiledChain:
    """The 6 arm joints of `model` as frame constants at a finger opening (`set_opening` recomputes them).

    `chain`: (joint k, parent frame) in URDF order; `frame_of`: link -> its frame; `A`, `B`, `C`: (6, 4, 4)
    joint constants; `link_const`: link -> (4, 4) pose in its frame; `tcp_const`: the tcp's.
    """

    def __init__(self, model: RobotModel, *, tcp_link: str, finger_opening_m: float):
        self.model = m = model
        self.tcp_link = tcp_link
        self.frame_links = [m.root] + [m.joints[n].child for n in m.arm_joints]
        self.frame_of = {ln: self.frame_links.index(m.rigid_parent(ln, movable=m.arm_joints)) for ln in m.link_names}
        order = sorted(range(6), key=lambda k: m.joint_order.index(m.joints[m.arm_joints[k]]))
        self.chain = [(k, self.frame_of[m.joints[m.arm_joints[k]].parent]) for k in order]
        self.revolute = np.array([m.joints[n].type != "prismatic" for n in m.arm_joints])
        self.chain_arr = np.array(self.chain, dtype=np.int64)
        self.frame_parent = {k + 1: f for k, f in self.chain}  # frame -> its parent frame (0: the root)
        self.all_revolute = bool(self.revolute.all())
        self.tcp_frame = self.frame_of[tcp_link]
        self._F_list: list[np.ndarray] = [np.eye(4)] * 7
        self._gen = np.zeros((6, 4, 4))  # generator of each joint's motion (rotation K or translation)
        for k, n in enumerate(m.arm_joints):
            a = m.joints[n].axis
            if self.revolute[k]:
                self._gen[k, :3, :3] = [[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]]
            else:
                self._gen[k, :3, 3] = a
        self.set_opening(finger_opening_m)

    def set_opening(self, opening_m: float) -> None:
        """Recompute the constants for a total finger opening of `opening_m` (the fingers' links move)."""
        m = self.model
        L0 = m.link_pose_array(np.zeros((1, 6)), finger_opening=opening_m)[0]
        # frame 0 is the base frame itself (the root link sits at the model's root_pose in it)
        F0inv = [np.eye(4)] + [np.linalg.inv(L0[m.link_index[ln]]) for ln in self.frame_links[1:]]
        J = np.empty((6, 4, 4))
        for k, name in enumerate(m.arm_joints):
            j = m.joints[name]
            J[k] = F0inv[self.frame_of[j.parent]] @ L0[m.link_index[j.parent]] @ j.origin
        self.A = J
        self.B = J @ self._gen
        self.C = J @ self._gen @ self._gen
        self.C[~self.revolute] = 0.0
        self._ABC = np.ascontiguousarray(np.stack([self.A, self.B, self.C], axis=1).reshape(6, 3, 16))
        self._W = np.ones((6, 3))
        # every link relative to its frame
        self.link_const = {ln: F0inv[self.frame_of[ln]] @ L0[m.link_index[ln]] for ln in m.link_names}
        self.tcp_const = self.link_const[self.tcp_link]

    def frames(self, qs: np.ndarray) -> np.ndarray:
        """(n, 7, 4, 4) frame poses (root + the 6 arm-joint child links) for (n, 6) qs."""
        if self.all_revolute:
            u, v = np.sin(qs), 1.0 - np.cos(qs)
        else:
            u = np.where(self.revolute, np.sin(qs), qs)
            v = np.where(self.revolute, 1.0 - np.cos(qs), 0.0)
        local = self.A + u[:, :, None, None] * self.B + v[:, :, None, None] * self.C
        F = np.empty((qs.shape[0], 7, 4, 4))
        F[:, 0] = np.eye(4)
        for k, f in self.chain:
            np.matmul(F[:, f], local[:, k], out=F[:, k + 1])
        return F

    def frames_one(self, q: np.ndarray) -> np.ndarray:
        """(7, 4, 4) frames for one configuration (2-D products: fewer numpy calls than `frames`)."""
        if self.all_revolute:
            u, v = np.sin(q), 1.0 - np.cos(q)
        else:
            u = np.where(self.revolute, np.sin(q), q)
            v = np.where(self.revolute, 1.0 - np.cos(q), 0.0)
        W = self._W  # local_k = [1, u_k, v_k] @ [A_k; B_k; C_k]: one small matmul instead of five ops
        W[:, 1] = u
        W[:, 2] = v
        local = np.matmul(W[:, None, :], self._ABC).reshape(6, 4, 4)
        F = self._F_list  # ndarray.dot on 2-D arrays is ~2x cheaper than matmul for 4x4
        for k, f in self.chain:
            F[k + 1] = F[f].dot(local[k])
        return np.array(F)

    def link_poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """{link: (4, 4)} world poses of every link at q (6,), at the current finger opening."""
        F = self.frames_one(q)
        return {ln: F[self.frame_of[ln]] @ C for ln, C in self.link_const.items()}

    def joint_reach(self, object_frame: np.ndarray, object_const: np.ndarray, object_radius: np.ndarray) -> np.ndarray:
        """(6,) for each arm joint, how far any point of a part it moves can be from its axis, m: a joint
        motion dq moves no point farther than sum_k |dq_k| reach_k. Parts: object o hangs from frame
        `object_frame[o]` at `object_const[o]` (4, 4) with bounding radius `object_radius[o]`. Bounded by the
        chain's link offsets from the joint's child frame (on its axis) to the part's frame, plus the part's
        centre offset and bounding radius. A chain with a prismatic joint gets no bound (inf: nothing is
        cleared by advancement), as its link offsets change with the joint."""
        per_part = self.object_reach(object_frame, object_const, object_radius)
        return per_part.max(axis=0) if per_part.shape[0] else np.zeros(6)

    def object_reach(self, object_frame: np.ndarray, object_const: np.ndarray, object_radius: np.ndarray) -> np.ndarray:
        """(n, 6): for each part o (as `joint_reach`) and arm joint k, how far any point of part o can be from
        joint k's axis, m (0 where joint k does not move it): a joint motion dq moves no point of part o
        farther than sum_k |dq_k| reach[o, k]. inf for a chain with a prismatic joint."""
        out = np.zeros((len(object_frame), 6))
        if not self.all_revolute:
            out[:] = np.inf
            return out
        parent = self.frame_parent
        offset = {k + 1: float(np.linalg.norm(self.A[k][:3, 3])) for k in range(6)}
        for o, f in enumerate(object_frame.tolist()):
            extent = float(np.linalg.norm(object_const[o][:3, 3])) + float(object_radius[o])
            g, path = f, 0.0
            while g != 0:
                out[o, g - 1] = path + extent
                path += offset[g]
                g = parent[g]
        return out

    def joints_moving(self, frames: np.ndarray) -> np.ndarray:
        """(n, 6) 1.0 where arm joint k moves frame `frames[i]` (n,), else 0.0."""
        parent = self.frame_parent

        def moved_by(frame: int) -> np.ndarray:
            out = np.zeros(6)
            while frame != 0:
                out[frame - 1] = 1.0
                frame = parent[frame]
            return out

        return np.array([moved_by(f) for f in frames.tolist()]).reshape(-1, 6)
