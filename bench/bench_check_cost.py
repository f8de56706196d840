"""The cost of checking ONE configuration on MotionBenchMaker's UR5 scenes, every way twin (and its peer) can
check it, side by side in one run (issue 41). A plain script: it prints a table and asserts nothing.

    python bench/bench_check_cost.py [--scenes box,cage] [--n 20000] [--n-python 2000] [--problem 0]
                                     [--robot-urdf twin|spherized] [--no-roboplan] [--seed 0]

Per scene (the world of its problem `--problem`, in the cell `twin compare` plans it in), the same random
configurations drawn uniformly inside the arm's joint limits:

- compiled: the planning model (`PlanningScene.sphere_model()`, 0 clearance) from compiled code, a numba loop
  over N configurations calling `twin.plugin.sphere_evaluate(model.kernel, model.scratch, q)`, as
  compiled.rrtconnect's search does: loop time / N (a mean; one configuration is too short to time alone),
  the fastest of 5 loops;
- batch: the same through `model.in_collision_batch` (one Python call for all N), per configuration, the
  fastest of 5;
- model/py: `model.in_collision(q)`, one Python call per configuration (median of each call timed alone);
- FCL: python-fcl as twin's scene checks, `scene.in_collision(q)` with the sphere filter off
  (`scene.sphere_filter = False`), and with it on (the default: spheres first, FCL where they cannot decide);
- coal: roboplan's `Scene.hasCollisions` through `roboplan_peer.check_cost` (its own seeded configurations in
  the same limits, the Python call included; skipped with one line when its venv cannot be made).

Also per scene: the fraction of configurations FCL calls colliding, and the cover's price: of those FCL
calls free, the fraction the model refuses (touching with 0 clearance). A model that frees what FCL refuses
would be unsound; that count is printed too (it must be 0). Medians over the scenes in the last line.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from twin.plugin import no_runtime_njit, sphere_evaluate
from twin.problems.mbm import SCENES, mbm_problem_set, mbm_spherized_urdf

sys.path.insert(0, str(Path(__file__).resolve().parent))
import roboplan_peer

_REPEATS = 5  # timings of the compiled loop and the batch, the fastest reported


@no_runtime_njit()
def _loop(kernel: tuple, scratch: tuple, qs: np.ndarray) -> int:  # type: ignore[type-arg]
    """How many of qs (n, 6) the planning model flags, one sphere_evaluate per configuration (compiled as
    compiled.rrtconnect's search is: without numba's runtime)."""
    n = 0
    for i in range(qs.shape[0]):
        if sphere_evaluate(kernel, scratch, qs[i])[0]:
            n += 1
    return n


def _each_us(check: Any, qs: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(median us, mean us, verdicts) of `check(q)` timed alone for each configuration."""
    times = np.empty(qs.shape[0])
    hits = np.empty(qs.shape[0], dtype=bool)
    for i, q in enumerate(qs):
        t = time.perf_counter()
        hits[i] = check(q)
        times[i] = time.perf_counter() - t
    return 1e6 * float(np.median(times)), 1e6 * float(times.mean()), hits


def scene_costs(path: Path, index: int, urdf: str | None, n: int, n_python: int, seed: int) -> dict[str, Any]:
    """The costs and verdicts of one scene's world (module docstring)."""
    cell = roboplan_peer.twin_cell(path, index, urdf)
    scene = cell.scene
    lim = np.asarray(cell.kin.joint_limits, dtype=float)
    rng = np.random.default_rng(seed)
    qs = np.ascontiguousarray(rng.uniform(lim[:, 0], lim[:, 1], size=(n, 6)))
    model = scene.sphere_model()
    out: dict[str, Any] = {"obstacles": None}
    _loop(model.kernel, model.scratch, qs[:10])  # compiled before it is timed
    model.in_collision_batch(qs[:10])
    loop_s, batch_s = [], []
    for _ in range(_REPEATS):  # interleaved, the fastest of each: a shared machine's noise only adds time
        t = time.perf_counter()
        flagged = _loop(model.kernel, model.scratch, qs)
        loop_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        batch = model.in_collision_batch(qs)
        batch_s.append(time.perf_counter() - t)
    out["compiled_ns"] = 1e9 * min(loop_s) / n
    out["model_flagged"] = flagged / n
    out["batch_ns"] = 1e9 * min(batch_s) / n
    few = qs[:n_python]
    out["model_py_us"], _, model_hits = _each_us(model.in_collision, few)
    was = scene.sphere_filter
    try:
        scene.sphere_filter = False
        out["fcl_us"], out["fcl_mean_us"], fcl_hits = _each_us(scene.in_collision, few)
        scene.sphere_filter = True
        out["fcl_filter_us"], out["fcl_filter_mean_us"], filt_hits = _each_us(scene.in_collision, few)
    finally:
        scene.sphere_filter = was
    free = ~fcl_hits
    out["fcl_colliding"] = float(fcl_hits.mean())
    out["price"] = float((model_hits & free).sum() / max(1, free.sum()))
    out["unsound"] = int((~model_hits & fcl_hits).sum())
    out["filter_disagree"] = int((filt_hits != fcl_hits).sum())
    out["batch_disagree"] = int((batch[:n_python] != model_hits).sum())
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(SCENES), help="comma-separated MBM UR5 scenes (default: all seven)")
    ap.add_argument("--n", type=int, default=20000, help="configurations for the compiled loop and the batch")
    ap.add_argument("--n-python", type=int, default=2000, help="configurations checked one Python call at a time")
    ap.add_argument("--problem", type=int, default=0, help="whose world, per scene (index into the scene's set)")
    ap.add_argument("--robot-urdf", choices=("twin", "spherized"), default="twin")
    ap.add_argument("--no-roboplan", action="store_true", help="skip coal through roboplan")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    unknown = [s for s in scenes if s not in SCENES]
    if unknown or not scenes:
        ap.error(f"unknown scene(s) {unknown}; MotionBenchMaker's UR5 scenes: {', '.join(SCENES)}")
    urdf = str(mbm_spherized_urdf()) if args.robot_urdf == "spherized" else None
    py: Path | str | None = None if args.no_roboplan else roboplan_peer.roboplan_python()
    model = "MBM's ur5_spherized.urdf" if urdf else "twin's urdf/ur5.urdf"
    print(
        f"\nCost of one collision check on MotionBenchMaker UR5, {model}, problem #{args.problem}'s world per scene; "
        f"{args.n} random configurations (compiled, batch), {args.n_python} (one call each); "
        f"{os.cpu_count()} CPUs here, load average {os.getloadavg()[0]:.2f}"
    )
    if isinstance(py, str):
        print(f"coal (roboplan) skipped: {py}")
    head = (
        f"{'scene':<18} {'compiled':>9} {'batch':>9} {'model/py':>9} {'FCL':>8} {'FCL+filt':>8} {'coal':>8} "
        f"{'FCL hit':>7} {'price':>6} {'unsound':>7}"
    )
    print(head)
    print(f"{'':<18} {'ns':>9} {'ns':>9} {'us':>9} {'us':>8} {'us':>8} {'us':>8} {'':>7} {'':>6} {'':>7}")
    print("-" * len(head))
    rows = []
    for scene in scenes:
        path = mbm_problem_set(f"ur5/{scene}")
        r = scene_costs(path, args.problem, urdf, args.n, args.n_python, args.seed)
        r["coal_us"] = None
        if isinstance(py, Path):
            try:
                from twin.problems import load_problem_set

                ps = load_problem_set(path)
                one = ps.model_copy(update={"problems": ps.problems[args.problem : args.problem + 1]})
                cost = roboplan_peer.check_cost(one, urdf, checks=args.n_python, first=1, python=py)[0]
                r["coal_us"] = float(cost["median_us"])
            except RuntimeError as e:
                print(f"coal (roboplan) failed on {scene}: {str(e).splitlines()[0][:200]}")
        rows.append(r)
        coal = f"{r['coal_us']:8.2f}" if r["coal_us"] is not None else f"{'-':>8}"
        print(
            f"{scene:<18} {r['compiled_ns']:9.0f} {r['batch_ns']:9.0f} {r['model_py_us']:9.2f} {r['fcl_us']:8.2f} "
            f"{r['fcl_filter_us']:8.2f} {coal} {r['fcl_colliding']:7.1%} {r['price']:6.1%} {r['unsound']:>7}",
            flush=True,
        )
    print("-" * len(head))

    def med(key: str, fmt: str) -> str:
        v = [r[key] for r in rows if r.get(key) is not None]
        return format(float(np.median(v)), fmt) if v else "-"

    print(
        f"{'median of scenes':<18} {med('compiled_ns', '9.0f')} {med('batch_ns', '9.0f')} "
        f"{med('model_py_us', '9.2f')} {med('fcl_us', '8.2f')} {med('fcl_filter_us', '8.2f')} "
        f"{med('coal_us', '>8.2f')} {med('fcl_colliding', '7.1%')} {med('price', '6.1%')} "
        f"{sum(r['unsound'] for r in rows):>7}"
    )
    print(
        "compiled: numba loop of sphere_evaluate, loop time / N (mean, fastest of 5); batch: model.in_collision_batch, "
        "one call "
        "for N; model/py: model.in_collision, one Python call each (median); FCL: scene.in_collision with "
        "sphere_filter off / on (median); coal: roboplan Scene.hasCollisions, one Python call each (median, its own "
        "seeded configurations in the same limits); FCL hit: configurations FCL calls colliding; price: of those FCL "
        "frees, the fraction the model refuses; unsound: configurations the model frees and FCL refuses (sum)"
    )
    fm = [r["fcl_mean_us"] for r in rows]
    ff = [r["fcl_filter_mean_us"] for r in rows]
    print(
        f"means (median of scenes): FCL {np.median(fm):.2f} us, FCL+filter {np.median(ff):.2f} us; "
        f"filter verdicts differing from FCL's: {sum(r['filter_disagree'] for r in rows)}; batch vs one-call "
        f"verdicts differing: {sum(r['batch_disagree'] for r in rows)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
