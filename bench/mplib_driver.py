"""Plan benchmark queries with mplib (OMPL RRTConnect + FCL + TOPP-RA in C++), for bench_ompl.py.

Runs inside mplib's own virtual environment (mplib pins numpy < 2), so it imports nothing from twin.
Reads one JSON object on stdin:

    {"urdf": path, "move_group": "tcp", "excluded_pairs": [[link, link], ...],
     "arm_joints": [6 names], "fixed_qpos": {joint: value, ...},      # e.g. the fingers, open
     "static_links": [link, ...],     # fixed to the world (base_link): not checked against the boxes
     "boxes": [{"name": str, "size": [3], "pose": 4x4}, ...],         # environment, base frame
     "attached_box": {"size": [3], "pose": 4x4 in the move_group frame} | null,
     "vel": [6], "acc": [6], "time_limit_s": float, "time_step_s": float, "rrt_range": float,
     "queries": [{"start": [6], "goals": [[6], ...]}, ...]}

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


def main() -> int:
    spec: dict[str, Any] = json.load(sys.stdin)
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
    for box in spec["boxes"]:
        shape = fcl.CollisionObject(fcl.Box(np.asarray(box["size"], dtype=float)))
        planner.planning_world.add_object(
            fcl.FCLObject(box["name"], Pose(np.asarray(box["pose"], dtype=float)), [shape], [Pose()])
        )
    static = list(spec.get("static_links", []))
    if static and spec["boxes"]:
        planner.acm.set_entry(static, [b["name"] for b in spec["boxes"]], True)  # as our scene does
    if spec.get("attached_box"):
        ab = spec["attached_box"]
        planner.update_attached_box(np.asarray(ab["size"], dtype=float), Pose(np.asarray(ab["pose"], dtype=float)))
    setup_s = time.perf_counter() - t0

    results = []
    for query in spec["queries"]:
        start = np.asarray(query["start"], dtype=float)
        goals = [np.asarray(g, dtype=float) for g in query["goals"]]
        full_start = full.copy()
        full_start[arm_idx] = start
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
                time=spec["time_limit_s"],
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
