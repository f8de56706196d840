"""Run throughput (issue 15): each speed-up either changes no number at all (prefetched noise draws, the
deferred pyplot import) or, for sleeping objects, changes what it should and nothing else."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from twin.camera import Intrinsics, RGBDFrame
from twin.config import DepthNoiseSettings, load_config
from twin.perception.capture import capture_frame, prefetch_next_capture
from twin.perception.noise import PrefetchedDraws, burst_draws, sensor_burst
from twin.world import World

INTR = Intrinsics(64, 48, 60.0, 60.0)


def _frame(depth: np.ndarray) -> RGBDFrame:
    rgb = np.random.default_rng(5).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    return RGBDFrame(rgb, depth, INTR)


def _scene_depth() -> np.ndarray:
    """A table at 0.7 m with a box on it: depth edges, so the edge dropouts draw something."""
    d = np.full((48, 64), 0.7)
    d[10:30, 20:40] = 0.6
    return d


NOISES = {
    "robocup": load_config("robocup").camera.noise,
    "static share": DepthNoiseSettings(static_fraction=0.5, scale=2.0),
    "no colour noise": DepthNoiseSettings(rgb_noise_std=0.0, dropout_fraction=0.05),
}


@pytest.mark.parametrize("name", list(NOISES))
@pytest.mark.parametrize("frames", [1, 8])
def test_a_prefetched_burst_is_the_burst_drawn_directly_number_for_number(name: str, frames: int) -> None:
    noise, frame = NOISES[name], _frame(_scene_depth())
    direct_rng, ahead_rng = np.random.default_rng(11), np.random.default_rng(11)
    direct = sensor_burst(frame, noise, direct_rng, frames)
    draws = PrefetchedDraws(ahead_rng, burst_draws(noise, (48, 64), frames))
    ahead = sensor_burst(frame, noise, draws, frames)
    draws.finish()
    for a, b in zip(direct, ahead, strict=True):
        assert np.array_equal(a.depth_m, b.depth_m) and np.array_equal(a.rgb, b.rgb)
    assert direct_rng.random() == ahead_rng.random()  # the generator is left where it would have been


def test_a_frame_with_missing_depth_leaves_the_prefetched_plan_and_still_draws_the_same_numbers() -> None:
    depth = _scene_depth()
    depth[0:5, 0:7] = 0.0  # no depth: the sensor model draws for the valid pixels only, not the planned count
    noise, frame = NOISES["robocup"], _frame(depth)
    direct_rng, ahead_rng = np.random.default_rng(3), np.random.default_rng(3)
    direct = sensor_burst(frame, noise, direct_rng, 4)
    draws = PrefetchedDraws(ahead_rng, burst_draws(noise, (48, 64), 4))
    ahead = sensor_burst(frame, noise, draws, 4)
    draws.finish()
    for a, b in zip(direct, ahead, strict=True):
        assert np.array_equal(a.depth_m, b.depth_m) and np.array_equal(a.rgb, b.rgb)
    assert direct_rng.random() == ahead_rng.random()


def test_captures_with_prefetched_noise_are_the_captures_without() -> None:
    """The first capture's draws are made while it settles, the second's after the first was perceived."""
    settings = load_config("robocup")
    runs = []
    for prefetch in (True, False):
        with World(settings, seed=3, renderer="tiny") as world:
            first = capture_frame(world, settings, prefetch_noise=prefetch).frame
            if prefetch:
                prefetch_next_capture(world, settings)
            runs.append([first, capture_frame(world, settings, prefetch_noise=prefetch).frame])
    for a, b in zip(*runs, strict=True):
        assert np.array_equal(a.depth_m, b.depth_m) and np.array_equal(a.rgb, b.rgb)
    assert not np.array_equal(runs[0][0].depth_m, runs[0][1].depth_m)  # each capture its own noise


def _still(world: World, body: int) -> bool:
    lin, ang = world.object_velocity(body)
    return not np.any(lin) and not np.any(ang)  # asleep: the engine holds it exactly still


def test_an_object_at_rest_sleeps_and_wakes_when_something_lands_on_it() -> None:
    settings = load_config("robocup")
    with World(settings, seed=1, renderer="tiny") as world:
        cube, other = (world.body_ids()[n] for n in ("cube_red_0", "cube_blue_0"))
        world.step(round(3.0 / world.dt))  # Bullet puts a body to sleep after 2 s below the threshold
        assert _still(world, cube)
        pos, quat = world.object_pose(cube)
        world.set_object_pose(other, pos + np.array([0.0, 0.0, 0.12]), quat)  # dropped onto it from 12 cm
        world.step(round(0.15 / world.dt))
        assert not _still(world, cube)  # hit: awake and moving again
        before = world.object_pose(cube)[0]
        world.step(round(5.0 / world.dt))
        assert np.linalg.norm(world.object_pose(cube)[0] - before) < 0.05  # and settled again, nearby
        assert _still(world, cube)


def test_with_sleep_at_rest_off_every_object_keeps_being_integrated() -> None:
    settings = load_config("robocup", overrides=["world.sleep_at_rest=false"])
    with World(settings, seed=1, renderer="tiny") as world:
        world.step(round(3.0 / world.dt))
        assert not all(_still(world, b) for b in world.object_ids())  # contact jitter: never exactly zero


def test_retiming_with_toppra_does_not_import_pyplot_and_pyplot_still_works() -> None:
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from twin.plugin import Limits\n"
        "from twin_motion.retimers import toppra_time_spline\n"
        "q = np.linspace(0, 0.5, 3)[:, None] * np.ones(6)\n"
        "toppra_time_spline(np.linspace(0, 1, 3), q, Limits.uniform(1, 2, 10))\n"
        "print('pyplot loaded' if 'matplotlib.figure' in sys.modules else 'pyplot deferred')\n"
        "print('matplotlib loaded' if 'matplotlib' in sys.modules else 'matplotlib deferred')\n"
        "import matplotlib\n"
        "matplotlib.use('Agg')\n"
        "print(hasattr(matplotlib, '__path__'), hasattr(matplotlib, 'rcParams'))\n"
        "import matplotlib.pyplot as plt\n"
        "print(type(plt.figure()).__name__)\n"
        "import toppra.parametrizer\n"
        "print(type(toppra.parametrizer.plt.figure()).__name__)\n"  # TOPP-RA's own plotting
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["pyplot", "deferred", "matplotlib", "deferred", "True", "True", "Figure", "Figure"]


def test_open3d_loads_without_dash_and_its_plotly_drawing_still_works() -> None:
    code = (
        "import sys\n"
        "from twin.perception.open3d_import import load_open3d\n"
        "o3d = load_open3d()\n"
        "print('dash loaded' if 'dash' in sys.modules else 'dash deferred')\n"
        "pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))\n"
        "print(type(o3d.visualization.get_plotly_fig([pc])).__name__, 'dash' in sys.modules)\n"
        "module = sys.modules['open3d.visualization.draw_plotly']\n"
        "print(callable(o3d.visualization.draw_plotly), type(module).__name__)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["dash", "deferred", "Figure", "True", "True", "module"]


def _release_spot_reference(bin_, placed, obj_half_tcp, reach_half_tcp, grasp_yaw):
    """The RoboCup release-spot search before issue 41, one candidate at a time (kept to compare)."""
    import math

    from twin.robot.kinematics import wrap_to_pi
    from twin.tasks.robocup.task import _SPOT_STEP_M, _WALL_MARGIN_M, _Footprint, _turned

    centre = (bin_.inner_lo[:2] + bin_.inner_hi[:2]) / 2.0
    square = grasp_yaw - float(wrap_to_pi(4.0 * (grasp_yaw - bin_.yaw))) / 4.0
    best = None
    for turn in (0.0, math.pi / 2):
        yaw = square + turn
        reach = _turned(reach_half_tcp, yaw - bin_.yaw)
        lo = bin_.inner_lo[:2] + reach + _WALL_MARGIN_M
        hi = bin_.inner_hi[:2] - reach - _WALL_MARGIN_M
        lo, hi = np.minimum(lo, centre), np.maximum(hi, centre)
        xs = np.arange(lo[0], hi[0] + 1e-9, _SPOT_STEP_M) if hi[0] > lo[0] else np.array([centre[0]])
        ys = np.arange(lo[1], hi[1] + 1e-9, _SPOT_STEP_M) if hi[1] > lo[1] else np.array([centre[1]])
        for x in xs:
            for y in ys:
                p = np.array([x, y])
                overlap = 0.0
                for f in placed:
                    d = f.half + reach + _WALL_MARGIN_M - np.abs(p - f.centre)
                    overlap += float(max(d[0], 0.0) * max(d[1], 0.0))
                key = (overlap, turn, -float(np.linalg.norm(p - centre)))
                if best is None or key < best[0]:
                    best = (key, p, yaw, _Footprint(p, _turned(obj_half_tcp, yaw - bin_.yaw)))
    return best[1], best[2], best[3]


def test_release_spot_search_on_the_whole_grid_picks_what_the_one_by_one_search_picked() -> None:
    from twin.tasks.robocup.bins import bin_geometries
    from twin.tasks.robocup.task import _release_spot

    bins = list(bin_geometries(load_config("robocup")).values())
    rng = np.random.default_rng(41)
    for trial in range(60):
        bin_ = bins[trial % len(bins)]
        placed = []
        for _ in range(int(rng.integers(0, 6))):  # what the task placed before: its own answers, as in a run
            obj, reach = rng.uniform(0.01, 0.06, 2), rng.uniform(0.03, 0.14, 2)
            if trial % 5 == 0:
                obj, reach = np.array([0.03, 0.03]), np.array([0.05, 0.05])  # squares: mirror-image ties
            _spot, _yaw, footprint = _release_spot(bin_, placed, obj, reach, float(rng.uniform(-3.2, 3.2)))
            placed.append(footprint)
        obj, reach, grasp_yaw = rng.uniform(0.01, 0.06, 2), rng.uniform(0.03, 0.2, 2), float(rng.uniform(-3.2, 3.2))
        got = _release_spot(bin_, placed, obj, reach, grasp_yaw)
        ref = _release_spot_reference(bin_, placed, obj, reach, grasp_yaw)
        assert np.array_equal(got[0], ref[0]) and got[1] == ref[1]
        assert np.array_equal(got[2].centre, ref[2].centre) and np.array_equal(got[2].half, ref[2].half)
