"""Plan motion queries with mplib (OMPL RRTConnect + FCL + TOPP-RA in C++): for bench_ompl.py, and for anyone
who wants to plan a twin problem-set file with another planner.

Runs inside mplib's own virtual environment (mplib pins numpy < 2), so it imports nothing from twin.

    python mplib_driver.py < SPEC.json                  # bench_ompl.py's queries (below)
    python mplib_driver.py --problems FILE.json [--urdf PATH] [--rrt-range R] [--describe]

With `--problems`, the queries, the world and the robot's collision rules come from a twin problem-set
file (`twin problems export`, format in twin/data/schemas/problem-set.schema.json): the same starts,
goals, obstacles (boxes, cylinders, spheres), held box, self-collision exclusions and time limits twin
plans. Joint goals are planned as given; pose goals through mplib's IK of the TCP pose (a `position`
goal, orientation free, is planned to its full pose: stricter than it asks, and said so in the answer).
`--describe` prints the problems and obstacles as read, without mplib: what a test compares with twin.

The stdin SPEC is one JSON object:

    {"urdf": path, "move_group": "tcp", "excluded_pairs": [[link, link], ...],
     "arm_joints": [6 names], "fixed_qpos": {joint: value, ...},      # e.g. the fingers, open
     "static_links": [link, ...],     # fixed to the world (base_link): not checked against the obstacles
     "boxes": [{"name": str, "size": [3], "pose": 4x4}, ...],         # environment, base frame
     "objects": [{"name": str, "shape": "box"|"cylinder"|"sphere", "size": [...], "pose": 4x4}, ...],
                                      # more environment (sizes: box x,y,z; cylinder radius, length; sphere radius)
     "attached_box": {"size": [3], "pose": 4x4 in the move_group frame} | null,
     "vel": [6], "acc": [6], "time_limit_s": float, "time_step_s": float, "rrt_range": float,
     "queries": [{"start": [6], "goals": [[6], ...]} | {"start": [6], "goal_pose": 4x4}, ...]}

and writes one JSON object on stdout: {"mplib_version", "setup_s", "results": [{"ok", "status", "time_s",
"ompl_s", "topp_s", "q": [[6], ...]}, ...]}: the steps of `Planner.plan_qpos` (OMPL RRTConnect with
shortcutting, then TOPP-RA), timed apart. mplib and its C++ core print to stdout, so fd 1 is pointed at stderr while
planning and restored for the answer.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from typing import Any


def _srdf(robot_name: str, pairs: list[list[str]]) -> str:
    lines = [f'<robot name="{robot_name}">']
    lines += [f'  <disable_collisions link1="{a}" link2="{b}" reason="Never"/>' for a, b in pairs]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def _quat_matrix(position: list[float], q: list[float]) -> list[list[float]]:
    """(4, 4) pose as nested lists from a position and a unit quaternion x, y, z, w."""
    x, y, z, w = q
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), position[0]],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), position[1]],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), position[2]],
        [0.0, 0.0, 0.0, 1.0],
    ]


def spec_from_problems(ps: dict[str, Any], urdf: str, rrt_range: float) -> dict[str, Any]:
    """The stdin SPEC of a twin problem-set document (see the module docstring)."""
    if ps.get("format") != "twin-problem-set" or ps.get("version") != 1:
        raise SystemExit(
            f"not a twin problem set, version 1: format {ps.get('format')!r}, version {ps.get('version')!r}"
        )
    robot, world = ps["robot"], ps["world"]
    objects = []
    for obj in world["objects"]:
        for i, prim in enumerate(obj["primitives"]):
            shape = prim["shape"]
            size = {
                "box": lambda p: p["size"],
                "cylinder": lambda p: [p["radius"], p["length"]],
                "sphere": lambda p: [p["radius"]],
            }
            if shape not in size:
                raise SystemExit(f"object {obj['name']}: unsupported shape {shape!r}")
            pose = _quat_matrix(prim["pose"]["position"], prim["pose"]["orientation"])
            objects.append(
                {"name": f"{obj['name']}_{i}", "shape": shape, "size": list(size[shape](prim)), "pose": pose}
            )
    held = world.get("held_object")
    queries = []
    for p in ps["problems"]:
        g = p["goal"]
        if g["kind"] == "joint":
            queries.append({"id": p["id"], "start": p["start"], "goals": [g["joints"]], "goal_kind": "joint"})
        else:
            if g.get("frame", "tcp") != robot.get("tcp_frame", "tcp"):
                raise SystemExit(f"problem {p['id']}: goals of frame {g.get('frame')!r} are not supported here")
            T = _quat_matrix(g["pose"]["position"], g["pose"]["orientation"])
            queries.append({"id": p["id"], "start": p["start"], "goal_pose": T, "goal_kind": g["kind"]})
    half = (robot.get("gripper_opening_m") or 0.0) / 2.0  # each finger moves half the opening
    limits = {p["time_limit_s"] for p in ps["problems"]}
    return {
        "urdf": urdf,
        "move_group": robot.get("tcp_frame", "tcp"),
        "excluded_pairs": [list(pair) for pair in robot.get("allowed_self_collisions", [])],
        "arm_joints": robot["joint_names"],
        "fixed_qpos": {"left_finger_joint": half, "right_finger_joint": half},
        "static_links": robot.get("static_links", []),
        "boxes": [],
        "objects": objects,
        "attached_box": None
        if not held
        else {
            "size": held["size"],
            "pose": _quat_matrix(held["pose_in_tcp"]["position"], held["pose_in_tcp"]["orientation"]),
        },
        "vel": [3.141592653589793] * 6,
        "acc": [8.0] * 6,
        "time_limit_s": max(limits),
        "time_limits_s": [p["time_limit_s"] for p in ps["problems"]],
        "time_step_s": 0.01,
        "rrt_range": rrt_range,
        "queries": queries,
    }


def main() -> int:
    import argparse
    from pathlib import Path

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", default=None, help="a twin problem-set file instead of a SPEC on stdin")
    ap.add_argument("--urdf", default=None, help="the robot URDF (default: the file's robot.urdf beside this checkout)")
    ap.add_argument("--rrt-range", type=float, default=0.1, help="RRTConnect range (mplib's default 0.1)")
    ap.add_argument("--describe", action="store_true", help="print the problems and obstacles as read; plan nothing")
    args = ap.parse_args()
    if args.problems:
        ps = json.loads(Path(args.problems).read_text())
        urdf = args.urdf or str(Path(__file__).resolve().parents[1] / ps["robot"]["urdf"])
        spec: dict[str, Any] = spec_from_problems(ps, urdf, args.rrt_range)
        if args.describe:
            print(json.dumps({"objects": spec["objects"], "queries": spec["queries"], "robot": ps["robot"]}))
            return 0
    else:
        spec = json.load(sys.stdin)
    out_fd = os.dup(1)
    os.dup2(2, 1)  # everything printed while planning goes to stderr
    try:
        answer = run(spec)
    finally:
        sys.stdout.flush()
        os.dup2(out_fd, 1)
    os.write(1, (json.dumps(answer) + "\n").encode())
    return 0


def run(spec: dict[str, Any]) -> dict[str, Any]:
    import mplib
    import numpy as np
    from mplib import Pose
    from mplib.collision_detection import fcl

    t0 = time.perf_counter()
    with tempfile.NamedTemporaryFile("w", suffix=".srdf", delete=False) as f:
        f.write(_srdf("ur5e", spec["excluded_pairs"]))
        srdf = f.name
    planner = mplib.Planner(
        spec["urdf"],
        move_group=spec["move_group"],
        srdf=srdf,
        joint_vel_limits=np.asarray(spec["vel"], dtype=float),
        joint_acc_limits=np.asarray(spec["acc"], dtype=float),
    )
    names = list(planner.user_joint_names)
    full = np.asarray(planner.robot.get_qpos(), dtype=float).copy()
    for joint, value in spec.get("fixed_qpos", {}).items():
        if joint in names:
            full[names.index(joint)] = value
    arm_idx = [names.index(j) for j in spec["arm_joints"]]
    group_idx = list(planner.move_group_joint_indices)
    if group_idx != arm_idx:
        raise SystemExit(f"mplib move group joints {group_idx} are not the arm joints {arm_idx} ({names})")
    planner.robot.set_qpos(full, True)
    env = [dict(b, shape="box") for b in spec["boxes"]] + list(spec.get("objects", []))
    for obj in env:
        size = np.asarray(obj["size"], dtype=float)
        if obj["shape"] == "box":
            geom = fcl.Box(size)
        elif obj["shape"] == "cylinder":
            geom = fcl.Cylinder(float(size[0]), float(size[1]))
        else:
            geom = fcl.Sphere(float(size[0]))
        shape = fcl.CollisionObject(geom)
        planner.planning_world.add_object(
            fcl.FCLObject(obj["name"], Pose(np.asarray(obj["pose"], dtype=float)), [shape], [Pose()])
        )
    static = list(spec.get("static_links", []))
    if static and env:
        planner.acm.set_entry(static, [o["name"] for o in env], True)  # as our scene does
    if spec.get("attached_box"):
        ab = spec["attached_box"]
        planner.update_attached_box(np.asarray(ab["size"], dtype=float), Pose(np.asarray(ab["pose"], dtype=float)))
    setup_s = time.perf_counter() - t0

    results = []
    limits = spec.get("time_limits_s") or [spec["time_limit_s"]] * len(spec["queries"])
    for query, time_limit in zip(spec["queries"], limits, strict=True):
        start = np.asarray(query["start"], dtype=float)
        full_start = full.copy()
        full_start[arm_idx] = start
        if "goal_pose" in query:  # mplib's IK of the move_group pose, seeded from the start
            status, sols = planner.IK(Pose(np.asarray(query["goal_pose"], dtype=float)), full_start)
            goals = [np.asarray(g, dtype=float)[arm_idx] for g in (sols or [])]
            if not goals:
                results.append(
                    {"ok": False, "status": f"IK: {status}", "time_s": 0.0, "ompl_s": 0.0, "topp_s": 0.0, "q": []}
                )
                continue
        else:
            goals = [np.asarray(g, dtype=float) for g in query["goals"]]
        full_goals = []
        for g in goals:
            fg = full.copy()
            fg[arm_idx] = g
            full_goals.append(fg)
        # plan_qpos's steps, timed apart: OMPL RRTConnect + shortcutting in C++, then its TOPP-RA
        t = time.perf_counter()
        t_ompl = t_topp = 0.0
        q: list[Any] = []
        try:
            planner.robot.set_qpos(full_start, True)
            status, path = planner.planner.plan(
                full_start[arm_idx],
                [fg[arm_idx] for fg in full_goals],
                time=time_limit,
                range=spec["rrt_range"],
                simplify=True,
            )
            t_ompl = time.perf_counter() - t
            status = str(status)
            ok = status.startswith("Exact solution")
            if ok:
                t1 = time.perf_counter()
                _, pos, _, _, _ = planner.TOPP(path, spec["time_step_s"])
                t_topp = time.perf_counter() - t1
                q = np.asarray(pos, dtype=float)[:, : len(arm_idx)].tolist()
        except Exception as e:  # noqa: BLE001 - a failure of one query is a result, not a crash
            ok, status = False, f"exception: {e!r}"
        dt = time.perf_counter() - t
        results.append({"ok": ok, "status": status, "time_s": dt, "ompl_s": t_ompl, "topp_s": t_topp, "q": q})
    os.unlink(srdf)
    return {"mplib_version": getattr(mplib, "__version__", "?"), "setup_s": setup_s, "results": results}


if __name__ == "__main__":
    sys.exit(main())
