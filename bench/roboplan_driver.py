"""Plan joint-goal problems with roboplan (C++ RRT-Connect on pinocchio + coal): for bench/roboplan_peer.py.

Runs inside roboplan's own virtual environment (bench/.roboplan-venv: roboplan 0.7.0's wheels pin a pinocchio
other than twin's croc extra), so it imports nothing from twin; roboplan_peer.py writes its input.

    python roboplan_driver.py [SPEC.json] < SPEC.json         # plan: one JSON answer on stdout
    python roboplan_driver.py --check-cost N [SPEC.json]       # the median time of one collision check

The SPEC is one JSON object (all poses 4x4 nested lists; lengths m, angles rad):

    {"urdf": path,                    # the robot; its <visual> elements are dropped (meshes need not exist)
     "package_paths": [dir, ...],     # for package:// collision meshes, if any
     "arm_joints": [6 names],         # the planning group, in the order of every start, goal and path
     "fixed_positions": {joint: value, ...},   # the other joints (twin's fingers: open); absent ones ignored
     "excluded_pairs": [[link, link], ...],   # self pairs never checked (twin's allowed self-collisions)
     "static_links": [link, ...],     # links fixed to the world: never checked against the obstacles
     "base_pose": 4x4,                # the obstacles' frame (twin's base_link) in the URDF's root frame
     "obstacles": [{"name", "shape": "box"|"cylinder"|"sphere", "size": [...], "pose": 4x4}, ...],
                                      # sizes: box x, y, z full extents; cylinder radius, length; sphere radius
     "time_limit_s": float, "seed": int,
     "rrt": {RRTOptions field: value, ...},   # on top of the defaults below
     "shortcut": bool,                # run roboplan's PathShortcutter on a found path (timed apart)
     "problems": [{"id", "start": [6], "goal": [6], "obstacles": [...] (this problem's own world, replacing
                   the top-level one), "time_limit_s", "seed"}, ...]}

Answer: {"roboplan_version", "setup_s" (URDF, scene, groups), "results": [{"id", "ok", "status",
"planning_time_s" (around RRT.plan only), "shortcut_s", "setup_s" (this problem's obstacles and planner),
"start_valid", "goal_valid", "path": [[6], ...]}]}. A start or goal in collision (or out of the joint limits)
in roboplan's scene is not planned: ok false, status start_in_collision / goal_in_collision.

With --check-cost N: {"roboplan_version", "results": [{"id", "obstacles", "checks", "median_us", "mean_us",
"colliding"}]} per problem (with "return_samples": true in the SPEC, also "samples" [[6], ...] and "hits"
[bool]): N configurations drawn uniformly in the arm's joint limits (seeded), each checked
once with Scene.hasCollisions and timed alone (perf_counter around the call; the Python call is included).
"""

from __future__ import annotations

import itertools
import json
import os
import re
import statistics
import sys
import time
from typing import Any

# RRT-Connect as roboplan's own examples run it, with room to grow for a whole time limit (max_nodes' default,
# 1000, ends most hard problems long before it); roboplan's defaults for the rest (range 3.0, edges checked
# every 0.05 by bisection)
RRT_DEFAULTS: dict[str, Any] = {"rrt_connect": True, "max_nodes": 10_000_000}
_COLOR = [0.5, 0.5, 0.5, 1.0]


def _version() -> str:
    from roboplan import core

    return str(getattr(core, "__version__", "?"))


class World:
    """roboplan's Scene of the robot and one set of obstacles at a time."""

    def __init__(self, spec: dict[str, Any]):
        import numpy as np
        from roboplan import core

        self.np, self.core = np, core
        with open(spec["urdf"]) as f:
            xml = f.read()
        xml = re.sub(r"<visual\b.*?</visual>", "", xml, flags=re.DOTALL)  # visual meshes: not needed, maybe absent
        desc = core.loadUrdfSceneDescriptionFromXml(xml, spec.get("package_paths", []))
        self.scene = core.Scene("robot", desc)
        self.arm = list(spec["arm_joints"])
        self.scene.addGroup("arm", self.arm)
        names = self.scene.getJointNames()
        missing = [j for j in self.arm if j not in names]
        if missing:
            raise SystemExit(f"arm joints {missing} are not joints of {spec['urdf']} ({names})")
        full = np.asarray(self.scene.getCurrentJointPositions(), dtype=float).copy()
        idx = {j: int(self.scene.getJointPositionIndices([j])[0]) for j in names}
        for joint, value in spec.get("fixed_positions", {}).items():
            if joint in idx:
                full[idx[joint]] = value
        self.arm_idx = [idx[j] for j in self.arm]
        self.full = full
        self.scene.setJointPositions(full)
        pairs = [tuple(p) for p in spec.get("excluded_pairs", [])]
        if pairs:
            self.scene.setCollisions(pairs, False)
        self.static = [s for s in spec.get("static_links", []) if self._has_frame(s)]
        self.base = np.asarray(spec.get("base_pose", np.eye(4)), dtype=float)
        self.obstacles: list[str] = []
        self.lo, self.hi = (np.asarray(v, dtype=float) for v in self.scene.getPositionLimitVectors("arm"))

    def _has_frame(self, name: str) -> bool:
        try:
            self.scene.getFrameId(name)
            return True
        except Exception:  # noqa: BLE001 - an unknown frame raises
            return False

    def set_obstacles(self, obstacles: list[dict[str, Any]]) -> None:
        """Replace the obstacles: each added at its pose (base frame) to the root frame, collisions between
        obstacles and between an obstacle and a static link off."""
        np, core, scene = self.np, self.core, self.scene
        for name in self.obstacles:
            scene.removeGeometry(name)
        self.obstacles = []
        color = np.asarray(_COLOR)
        for k, obj in enumerate(obstacles):
            name = f"obstacle{k}_{obj['name']}"
            T = self.base @ np.asarray(obj["pose"], dtype=float)
            size = [float(x) for x in obj["size"]]
            if obj["shape"] == "box":
                scene.addBoxGeometry(name, "universe", core.Box(*size), T, color)
            elif obj["shape"] == "cylinder":
                scene.addCylinderGeometry(name, "universe", core.Cylinder(size[0], size[1]), T, color)
            elif obj["shape"] == "sphere":
                scene.addSphereGeometry(name, "universe", core.Sphere(size[0]), T, color)
            else:
                raise SystemExit(f"obstacle {obj['name']}: unsupported shape {obj['shape']!r}")
            self.obstacles.append(name)
        off = list(itertools.combinations(self.obstacles, 2))  # coal checks every pair unless told
        off += [(s, o) for s in self.static for o in self.obstacles]
        if off:
            scene.setCollisions(off, False)

    def full_q(self, q: Any) -> Any:
        full = self.full.copy()
        full[self.arm_idx] = q
        return full

    def valid(self, q: Any) -> bool:
        full = self.full_q(q)
        return bool(self.scene.isValidConfiguration(full)) and not self.scene.hasCollisions(full)


def plan(spec: dict[str, Any]) -> dict[str, Any]:
    import numpy as np
    from roboplan import core, rrt

    t0 = time.perf_counter()
    world = World(spec)
    setup_s = time.perf_counter() - t0
    options = dict(RRT_DEFAULTS, **spec.get("rrt", {}))
    shortcut = bool(spec.get("shortcut", False))
    results = []
    shared = spec.get("obstacles", [])
    current: Any = None
    for i, prob in enumerate(spec["problems"]):
        t = time.perf_counter()
        obstacles = prob.get("obstacles", shared)
        if obstacles is not current:
            world.set_obstacles(obstacles)
            current = obstacles
        opts = rrt.RRTOptions(
            group_name="arm",
            max_planning_time=float(prob.get("time_limit_s", spec.get("time_limit_s", 10.0))),
            **options,
        )
        planner = rrt.RRT(world.scene, opts)
        planner.setRngSeed(int(prob.get("seed", spec.get("seed", 0))))
        start, goal = np.asarray(prob["start"], dtype=float), np.asarray(prob["goal"], dtype=float)
        row: dict[str, Any] = {
            "id": prob.get("id", i),
            "ok": False,
            "status": "",
            "planning_time_s": 0.0,
            "shortcut_s": 0.0,
            "start_valid": world.valid(start),
            "goal_valid": world.valid(goal),
            "path": [],
        }
        row["setup_s"] = time.perf_counter() - t
        if not row["start_valid"]:
            row["status"] = "start_in_collision"
        elif not row["goal_valid"]:
            row["status"] = "goal_in_collision"
        else:
            a, b = core.JointConfiguration(world.arm, start), core.JointConfiguration(world.arm, goal)
            t1 = time.perf_counter()
            try:
                path = planner.plan(a, b)
                row["planning_time_s"] = time.perf_counter() - t1
                row["ok"], row["status"] = True, "solved"
            except Exception as e:  # noqa: BLE001 - roboplan raises RuntimeError when it finds no path
                row["planning_time_s"] = time.perf_counter() - t1
                row["status"] = f"failed: {e}"
                path = None
            if path is not None and shortcut:
                t2 = time.perf_counter()
                sc = core.PathShortcutter(world.scene, core.PathShortcuttingOptions(group_name="arm", seed=0))
                path = sc.shortcut(path)
                row["shortcut_s"] = time.perf_counter() - t2
            if path is not None:
                row["path"] = [np.asarray(q, dtype=float).tolist() for q in path.positions]
        results.append(row)
    return {"roboplan_version": _version(), "setup_s": setup_s, "rrt": options, "results": results}


def check_cost(spec: dict[str, Any], n: int) -> dict[str, Any]:
    import numpy as np

    world = World(spec)
    rng = np.random.default_rng(int(spec.get("seed", 0)))
    lo, hi = world.lo, world.hi
    results = []
    shared = spec.get("obstacles", [])
    for i, prob in enumerate(spec["problems"]):
        obstacles = prob.get("obstacles", shared)
        world.set_obstacles(obstacles)
        qs = [world.full_q(rng.uniform(lo, hi)) for _ in range(n)]
        check = world.scene.hasCollisions
        check(qs[0])  # warm
        times, hits = [], 0
        for q in qs:
            t = time.perf_counter()
            hit = check(q)
            times.append(time.perf_counter() - t)
            hits += bool(hit)
        row = {
            "id": prob.get("id", i),
            "obstacles": len(obstacles),
            "checks": n,
            "median_us": 1e6 * statistics.median(times),
            "mean_us": 1e6 * statistics.fmean(times),
            "colliding": hits,
        }
        if spec.get("return_samples"):  # for a comparison with another collision model on the same configurations
            row["samples"] = [q[world.arm_idx].tolist() for q in qs]
            row["hits"] = [bool(world.scene.hasCollisions(q)) for q in qs]
        results.append(row)
    return {"roboplan_version": _version(), "results": results}


def main() -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("spec", nargs="?", default=None, help="the SPEC file (default: stdin)")
    ap.add_argument("--check-cost", type=int, default=0, metavar="N", help="time N collision checks per problem")
    args = ap.parse_args()
    if args.spec:
        with open(args.spec) as f:
            spec = json.load(f)
    else:
        spec = json.load(sys.stdin)
    out_fd = os.dup(1)
    os.dup2(2, 1)  # anything the C++ side prints goes to stderr; the answer alone to stdout
    try:
        answer = check_cost(spec, args.check_cost) if args.check_cost > 0 else plan(spec)
    finally:
        sys.stdout.flush()
        os.dup2(out_fd, 1)
    os.write(1, (json.dumps(answer) + "\n").encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
