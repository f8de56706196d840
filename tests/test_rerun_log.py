"""`twin run --rerun OUT.rrd`: a warehouse run written as a Rerun recording and read back with the SDK (no
viewer): the cell's entity tree (robot links, fixtures, objects), the simulated-time timeline spanning the run,
one planned path per stage that planned one, the stage events in the order the run planned them, and the
judge's verdict per object; a bad path or a missing SDK is a one-line error."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun")  # (usage statistics: setup.sh, and so CI, runs `rerun analytics disable`)

import rerun as rr

from twin.config import load_config
from twin.errors import ConfigError
from twin.tasks import run_task


def _read(path: Path) -> dict[str, list]:
    """entity path -> its chunks' record batches."""
    out: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(str(path)).store().stream():
        out.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return out


def _events(ents: dict[str, list]) -> tuple[list[str], np.ndarray]:
    """The event lines in the order they were logged (rerun's row ids are time-ordered; chunks are not) and
    their simulated times, s."""
    rows = []
    for b in ents["/events"]:
        ids = b.column("rerun.controls.RowId").to_pylist()
        sims = b.column("sim").cast("int64").to_pylist()
        texts = [t[0] for t in b.column("TextLog:text").to_pylist()]  # (one text per row, as a list of one)
        rows += list(zip(ids, sims, texts, strict=True))
    rows.sort()
    return [t for _, _, t in rows], np.array([s for _, s, _ in rows], dtype=float) / 1e9


def _seconds(batches: list) -> np.ndarray:
    """The `sim` timeline's values (durations, ns) in seconds."""
    return np.concatenate([b.column("sim").cast("int64").to_numpy() for b in batches]) / 1e9


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    pytest.importorskip("crocoddyl")  # the fast transfer planner keeps the run short
    path = tmp_path_factory.mktemp("rerun") / "run.rrd"
    events: list[str] = []
    summary = run_task(load_config("warehouse"), seed=0, planner="croc", rerun=str(path), on_stage=events.append)
    return path, summary, events


def test_the_recording_holds_the_cell_over_the_runs_simulated_time(recorded):
    path, summary, _ = recorded
    ents = _read(path)
    links = {e.split("/")[3] for e in ents if e.startswith("/world/robot/")}
    assert {"base_link", "upper_arm_link", "forearm_link", "wrist_3_link", "left_finger"} <= links
    assert {"/world/fixtures/table/shape0", "/world/fixtures/obstacle/shape0"} <= set(ents)
    objects = {o.id for o in summary.objects}
    assert {e.split("/")[3] for e in ents if e.startswith("/world/objects/")} == objects
    times = _seconds(ents["/robot/joints/elbow_joint"])
    assert times.min() == pytest.approx(0.0, abs=1e-9)
    assert times.max() == pytest.approx(summary.sim_time_s, abs=0.05)  # sampled at 30 Hz to the end
    assert np.all(np.diff(np.sort(times)) > 0)


def test_the_recording_has_a_path_per_planned_stage_the_events_in_order_and_the_verdicts(recorded):
    path, summary, stages = recorded
    ents = _read(path)
    text, when = _events(ents)
    assert np.all(np.diff(when) >= 0)  # logged as the run went
    planned = [t for t in text if not t.startswith(("verdict", "capture"))]
    # one event per stage the cell planned, in the order the progress display showed them
    assert [t.split(":")[0] for t in planned] == [s.split(": ")[-1] for s in stages]
    plans = sorted(e for e in ents if e.startswith("/world/plans/"))
    assert len(plans) == len([t for t in planned if ": success" in t])  # a refused plan has no trajectory
    assert all(p.split("_", 1)[1] in {s.split(": ")[-1] for s in stages} for p in plans)
    verdicts = [t for t in text if t.startswith("verdict")]
    assert len(verdicts) == len(summary.objects)
    for o in summary.objects:
        assert any(t.startswith(f"verdict {o.id}: {'placed' if o.placed else 'not placed'}") for t in verdicts)


def test_a_recording_path_that_is_not_rrd_is_a_one_line_error(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "twin", "run", "warehouse", "--rerun", str(tmp_path / "run.mp4")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 2 and "--rerun must name an .rrd file" in r.stderr
    assert "Traceback" not in r.stderr


def test_the_recorder_refuses_a_bad_path_before_anything_runs(tmp_path):
    from twin.collision import PlanningScene
    from twin.rerun_log import RerunRecording
    from twin.robot.kinematics import URArm

    scene = PlanningScene.from_settings(load_config("warehouse"))
    with pytest.raises(ConfigError, match=r"\.rrd"):
        RerunRecording(tmp_path / "run.txt", scene=scene, kin=URArm(), recording_id="x")


def test_a_recorded_run_is_the_plain_run(recorded):
    """The recorder reads the world through the observer's view and the stages through the cell's trace: the run's
    results are the same with and without it."""
    _, summary, _ = recorded
    plain = run_task(load_config("warehouse"), seed=0, planner="croc")
    a, b = summary.to_json(), plain.to_json()
    for d in (a, b):
        for key in ("wall_time_s", "timings", "metrics"):
            d.pop(key, None)
    assert a == b

    def untimed(m: dict) -> dict:
        return {p: {k: v for k, v in d.items() if "time" not in k} for p, d in m.items()}

    assert untimed(summary.metrics) == untimed(plain.metrics)


def test_every_capture_has_its_image_depth_camera_and_what_perception_saw(recorded):
    path, summary, _ = recorded
    ents = _read(path)
    text, _ = _events(ents)
    captures = [t for t in text if t.startswith("capture")]
    assert captures  # the warehouse looks at least once
    for entity in ("/world/camera/image/rgb", "/world/camera/image/depth", "/world/camera", "/world/perceived/objects"):
        assert sum(b.num_rows for b in ents[entity]) == len(captures), entity
    first = captures[0]
    assert f"{len(summary.objects)} objects" in first  # the first look sees every cube (none is placed yet)


def test_a_run_that_raises_keeps_what_it_recorded(tmp_path, monkeypatch):
    import twin.tasks as tasks

    class Breaks:
        def run(self, cell):
            cell.world.step(120)  # a quarter of a second of the cell, then the task fails
            raise RuntimeError("the task broke")

    monkeypatch.setattr(tasks, "make_task", lambda settings, context=None: Breaks())
    path = tmp_path / "broken.rrd"
    with pytest.raises(RuntimeError, match="broke"):
        run_task(load_config("warehouse"), seed=0, rerun=str(path))
    ents = _read(path)
    times = _seconds(ents["/robot/joints/elbow_joint"])
    assert times.max() == pytest.approx(0.25, abs=0.04)  # the observer's samples up to the failure
    assert "/world/robot/forearm_link" in ents


def test_a_run_can_be_watched_live_and_its_server_outlives_it():
    """`--rerun-serve`: the address of the web viewer is printed, bound to 127.0.0.1; after the run the server still
    answers (a user keeps looking), and the printed pid stops it (the viewer binary with it)."""
    import os
    import re
    import signal
    import urllib.request

    pytest.importorskip("crocoddyl")  # a short warehouse run
    r = subprocess.run(
        [sys.executable, "-m", "twin", "run", "warehouse", "--planner", "croc", "--rerun-serve"],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-500:]
    m = re.search(r"live view: (http://127\.0\.0\.1:\d+/\S+) .*pid (\d+)", r.stderr)
    assert m, r.stderr[-500:]
    url, pid = m.group(1), int(m.group(2))
    try:
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200 and b"rerun" in page.read().lower()
    finally:
        os.killpg(pid, signal.SIGTERM)
