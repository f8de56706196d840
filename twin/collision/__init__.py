"""FCL collision checking for the arm in its cell (pybullet-free).

* `twin.collision.fcl_shapes`: URDF collision primitives as FCL shapes (padding, bounding spheres,
  transforms, broadphase callbacks); meshes are rejected.
* `twin.collision.rules`: the allowed-collision rules (which robot link pairs are never tested, the
  reference-configuration contact rule, what a held object is tested against).
* `twin.collision.chain`: the arm's URDF chain compiled to numpy constants (link poses at q).
* `twin.collision.robot_body`: the robot set up for collision checks (FCL shapes posed through the chain,
  gripper opening, held box, allowed self pairs, sphere model).
* `twin.collision.obstacles`: the environment (fixtures and run-time boxes) as padded FCL objects.
* `twin.collision.planning_model`: `SphereModel`, the planning model (sphere cover, touching = collision, no FCL).
* `twin.collision.scene`: `PlanningScene`, one robot body and one environment, with its queries (collision,
  signed distance, clearance, path checks) and edits (boxes, fixtures, gripper opening, attach/detach,
  `padded` copies).

Padding: `padding_m` inflates every environment shape (fixtures and boxes) on each side; the robot, the
held object and self-collision are unpadded. Distances are signed: < 0 is a penetration.
"""

from twin.collision.planning_model import SphereModel
from twin.collision.rules import CollisionRules
from twin.collision.scene import DistanceResult, FixtureSpec, PathCheck, PlanningScene
from twin.robot.urdf_model import read_fixture_shapes

__all__ = [
    "CollisionRules",
    "DistanceResult",
    "FixtureSpec",
    "PathCheck",
    "PlanningScene",
    "SphereModel",
    "read_fixture_shapes",
]
