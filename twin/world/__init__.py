"""The simulated cell: the one package of twin that imports PyBullet.

A `World` owns one PyBullet physics client (DIRECT unless a GUI is asked for) and builds the scene of a
config: the UR5e with its gripper at the origin (the world frame IS the robot base frame), the fixtures
(table, bins, the ArUco base plate, obstacles) and the objects, placed where
`twin.scene_layout.sample_layout` puts them for the seed (in the spawn region, without overlap). It
drives the arm by joint position control at the physics rate and the gripper by force-limited closing,
and it exposes ground truth for metrics and tests only. URDFs are found by `Settings.resolve`; the
marker's texture is generated once by `twin.assets` into the cache directory.

Determinism: every PyBullet call passes this world's client id, overlapping pairs are processed in a
deterministic order, and the scene is built by the same call sequence for the same config and seed, so
two worlds given the same calls produce bit-identical states. `reset()` rebuilds the scene the same way
(a restored snapshot would keep solver caches and drift by ~40 um).

Grasping is physical: the fingers squeeze the object and friction holds it; nothing is attached.

The parts, data flowing one way (each imports only those above it):
- `bullet`: PyBullet itself, imported here only, its C-level banners silenced;
- `values`: the joint and link names the physics drives, `ObjectState`, `ContactPoint` (PyBullet-free);
- `scene_builder`: `build_scene`, the engine parameters and every body, returning a `BuiltScene`;
- `rendering`: the EGL renderer plugin and RGB-D frames; `tracking`: the faulty joint controller;
- `truth`: `GroundTruth`, the reads of what the physics says, mixed into `World`;
- `simulation`: `World`, connecting, stepping, commanding and sensing, and its read-only `WorldView`.
"""

from __future__ import annotations

from twin.scene_layout import marker_pose_in_base
from twin.world.simulation import World, WorldView
from twin.world.values import (
    ARM_JOINT_NAMES,
    FINGER_JOINT_NAMES,
    FINGER_TRAVEL_M,
    ContactPoint,
    ObjectState,
    physics_parts_missing,
)

__all__ = [
    "ARM_JOINT_NAMES",
    "FINGER_JOINT_NAMES",
    "FINGER_TRAVEL_M",
    "ContactPoint",
    "ObjectState",
    "World",
    "WorldView",
    "marker_pose_in_base",
    "physics_parts_missing",
]
