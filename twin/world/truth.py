"""What a `World` reads as ground truth: bodies, objects and robot links where the physics has them, and
the contacts of the last step. For judging, metrics, the simulated safety monitor and tests; a task never
decides with them (it reads the sensors: `World.gripper_opening`, `World.joint_positions`, a capture).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.errors import InvalidRequestError, WorldError
from twin.world.bullet import pb
from twin.world.scene_builder import BuiltScene
from twin.world.values import FINGER_LINKS, ContactPoint, ObjectState, as_vec, contact_points

__all__ = ["GroundTruth"]


class GroundTruth:
    """The ground-truth reads of a `World` (mixed into it): what the physics says, not what a sensor reads.

    Poses are in the base (= world) frame, metres, quaternions x-y-z-w.
    """

    robot_id: int
    _scene: BuiltScene  # the bodies of the scene `World` built (or rebuilt at its last `reset()`)

    def _check(self) -> int:
        """The physics client id; WorldError once the world is closed (`World._check`)."""
        raise NotImplementedError

    def body_ids(self) -> dict[str, int]:
        """Every body by name: 'robot', fixture names, object names, 'aruco_marker'."""
        return dict(self._scene.bodies)

    def link_indices(self) -> dict[str, int]:
        """Robot link name -> PyBullet link index ('base_link' is -1)."""
        return dict(self._scene.link_index)

    def object_ids(self) -> list[int]:
        """Body ids of the scene objects, in config order."""
        return list(self._scene.objects)

    def object_pose(self, body_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), quaternion xyzw (4,)) of an object (its geometric centre)."""
        c = self._check()
        pos, quat = pb.getBasePositionAndOrientation(body_id, physicsClientId=c)
        return np.array(pos), np.array(quat)

    def object_velocity(self, body_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(linear (3,) m/s, angular (3,) rad/s) velocity of an object: the judge's "at rest" test."""
        c = self._check()
        if body_id not in self._scene.objects:
            raise InvalidRequestError(f"{body_id} is not an object id; objects: {self.object_ids()}")
        lin, ang = pb.getBaseVelocity(body_id, physicsClientId=c)
        return np.array(lin), np.array(ang)

    def object_state(self, body_id: int) -> ObjectState:
        """Ground truth of one object."""
        if body_id not in self._scene.objects:
            raise InvalidRequestError(f"{body_id} is not an object id; objects: {self.object_ids()}")
        sp = self._scene.objects[body_id]
        pos, quat = self.object_pose(body_id)
        z_axis = np.array(pb.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3)[:, 2]
        return ObjectState(
            id=body_id,
            name=sp.name,
            cls=sp.template.cls,
            color=sp.color,
            position=pos,
            orientation_xyzw=quat,
            lying=bool(abs(z_axis[2]) < math.sqrt(0.5)),
            size=sp.template.size,
        )

    def objects(self) -> list[ObjectState]:
        """Ground truth of every object, in config order."""
        return [self.object_state(i) for i in self._scene.objects]

    def set_object_pose(
        self, body_id: int, position: Sequence[float] | np.ndarray, orientation_xyzw: Sequence[float] | np.ndarray
    ) -> None:
        """Teleport an object (zero velocity): for test setups, never during a measured run."""
        c = self._check()
        if body_id not in self._scene.objects:
            raise InvalidRequestError(f"{body_id} is not an object id; objects: {self.object_ids()}")
        pos = as_vec(position, 3, "position")
        quat = as_vec(orientation_xyzw, 4, "orientation_xyzw")
        pb.resetBasePositionAndOrientation(
            body_id, pos.tolist(), (quat / np.linalg.norm(quat)).tolist(), physicsClientId=c
        )
        pb.resetBaseVelocity(body_id, [0, 0, 0], [0, 0, 0], physicsClientId=c)
        pb.changeDynamics(body_id, -1, activationState=pb.ACTIVATION_STATE_WAKE_UP, physicsClientId=c)

    def link_pose(self, link_name: str) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,), quaternion xyzw (4,)) of a robot link frame (e.g. 'tool0', 'tcp')."""
        c = self._check()
        if link_name not in self._scene.link_index:
            raise InvalidRequestError(f"unknown robot link {link_name!r}; links: {', '.join(self._scene.link_index)}")
        j = self._scene.link_index[link_name]
        if j < 0:
            pos, quat = pb.getBasePositionAndOrientation(self.robot_id, physicsClientId=c)
        else:
            s = pb.getLinkState(self.robot_id, j, computeForwardKinematics=True, physicsClientId=c)
            pos, quat = s[4], s[5]
        return np.array(pos), np.array(quat)

    def link_matrix(self, link_name: str) -> np.ndarray:
        """(4, 4) pose of a robot link frame in the base frame."""
        pos, quat = self.link_pose(link_name)
        T = np.eye(4)
        T[:3, :3] = np.array(pb.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def marker_pose(self) -> np.ndarray:
        """(4, 4) ground-truth pose of the ArUco marker frame (OpenCV convention) in the base frame."""
        c = self._check()
        if self._scene.marker_id is None:
            raise WorldError("this scene has no ArUco plate (add a fixture with urdf: urdf/aruco_plate.urdf)")
        pos, quat = pb.getBasePositionAndOrientation(self._scene.marker_id, physicsClientId=c)
        T = np.eye(4)
        T[:3, :3] = np.array(pb.getMatrixFromQuaternion(quat)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def contacts(self, body_a: int | None = None, body_b: int | None = None) -> list[ContactPoint]:
        """Contact points of the last physics step, optionally filtered to body A (and body B)."""
        c = self._check()
        kw: dict[str, int] = {}
        if body_a is not None:
            kw["bodyA"] = body_a
        if body_b is not None:
            if body_a is None:
                raise InvalidRequestError("give body_a when filtering by body_b")
            kw["bodyB"] = body_b
        return contact_points(pb.getContactPoints(physicsClientId=c, **kw))

    def robot_contacts(self, *, ignore: Sequence[int] = ()) -> list[ContactPoint]:
        """Contacts between the robot (any link) and any other body except `ignore` (e.g. the grasped object)."""
        skip = set(ignore)
        return [p for p in self.contacts(self.robot_id) if p.body_b not in skip and p.body_b != self.robot_id]

    def unexpected_contacts(
        self, *, ignore: Sequence[int] = (), fingers_may_touch_objects: bool = False
    ) -> list[tuple[str, str]]:
        """(robot link, body) names of the robot's contacts in the last step that a protective stop reacts to.

        Not counted: bodies in `ignore` (the held object), the robot with itself, the base link on what it
        stands on (it is fixed there) and, with `fingers_may_touch_objects`, a finger on a loose object (a
        finger brushing the object it is about to grasp or has just let go of is part of grasping).
        This is the simulated cell's safety monitor, read by the executor; tasks never decide with it."""
        skip = set(ignore)
        fingers = {self._scene.link_index[n] for n in FINGER_LINKS}
        link_name = {i: n for n, i in self._scene.link_index.items()}
        body_name = {i: n for n, i in self._scene.bodies.items()}
        out: set[tuple[str, str]] = set()
        for p in self.contacts(self.robot_id):
            if p.body_b in skip or p.body_b == self.robot_id or p.link_a == -1:
                continue
            if fingers_may_touch_objects and p.link_a in fingers and p.body_b in self._scene.objects:
                continue
            name = (
                self._scene.objects[p.body_b].name
                if p.body_b in self._scene.objects
                else body_name.get(p.body_b, str(p.body_b))
            )
            out.add((link_name.get(p.link_a, str(p.link_a)), name))
        return sorted(out)

    def touched_objects(self) -> tuple[int, ...]:
        """Loose objects the robot touches in the last step (body ids, ascending): what a safety monitor
        lets a retreat after a protective stop push away from (see `Cell.recover`)."""
        return tuple(sorted({p.body_b for p in self.contacts(self.robot_id) if p.body_b in self._scene.objects}))

    def closest_points(
        self, body_a: int, body_b: int, max_distance_m: float, *, link_a: int | None = None, link_b: int | None = None
    ) -> list[ContactPoint]:
        """Closest-point pairs closer than max_distance_m (negative distance = penetration); no stepping."""
        c = self._check()
        kw: dict[str, int] = {}
        if link_a is not None:
            kw["linkIndexA"] = link_a
        if link_b is not None:
            kw["linkIndexB"] = link_b
        return contact_points(pb.getClosestPoints(body_a, body_b, max_distance_m, physicsClientId=c, **kw))
