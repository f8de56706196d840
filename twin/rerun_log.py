"""A run as a Rerun recording (`twin run CONFIG --rerun OUT.rrd`): the cell in 3-D on the simulated-time timeline
`sim`, what was planned and done, and the judge's verdicts, in one file a user opens later (`rerun OUT.rrd`).

The only module that imports `rerun` (extra `twin[viz]`); a missing SDK is a one-line DependencyMissing.
Rerun sends usage statistics unless told not to (`rerun analytics disable`, a per-user setting, which
setup.sh and CI run; the SDK reads no environment switch for it but `CI`).

What goes where (entity paths):
- `world/robot/<link>`: each robot link's pose over time (ground truth; the world's observer, `POSE_RATE_HZ`),
  its collision primitives as static boxes, cylinders and spheres in the link's frame;
- `world/fixtures/<name>`: the cell's fixtures (table, bins, obstacles), static;
- `world/objects/<name>`: each object's pose over time and its box;
- `world/plans/<n>_<stage>`: each stage's planned TCP path (from the planned joints, the project's kinematics);
- `world/camera` (and `/image/rgb`, `/image/depth`): each capture, where the task believed the camera was;
  `world/perceived/objects` and `/boxes`: what perception made of it (labels, positions, obstacle boxes);
- `robot/joints/<joint>`, `robot/gripper_opening_m`: measured joint positions and finger opening over time;
- `events`: a text line per stage (stage, planner, status, reason), per capture and per object's verdict;
- a comparison query (`twin replay`, `query`): `world/query/start_goal`, `/straight`, `/refused` (a refused motion)
  and `/first_collision`, the robot moving along the plan (or the refused motion up to its first collision).

It opens with a saved layout (`_layout`): the cell in 3-D, the camera image (a tab: the depth), the joint plot,
the stage log.

Why the world's observer and the cell's trace: the recorder sees the world only through the read-only
`WorldView` an observer gets, and the stages through `RunTrace.motion`, so a recorded run is the run without it.
"""

from __future__ import annotations

import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

import numpy as np

from twin.errors import ConfigError, DependencyMissing
from twin.planning import densify_path
from twin.transforms import matrix_to_quat
from twin.types import JointGoal, MotionRequest, MotionResult, ObjectOutcome

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.robot.kinematics import URArm
    from twin.tasks.cell import Sighting
    from twin.world import World, WorldView

__all__ = ["POSE_RATE_HZ", "LiveView", "RerunRecording", "rerun_module"]

POSE_RATE_HZ = 30.0  # body poses and joint states per simulated second (the physics runs at 480 Hz)
_PATH_POINTS = 60  # points of a planned TCP path
_JPEG_QUALITY = 80  # a capture's colour image


def rerun_module() -> Any:
    """`rerun`; DependencyMissing naming the extra when it is not installed."""
    try:
        import rerun
    except ImportError:
        raise DependencyMissing(
            "recording a run needs the Rerun SDK: pip install 'twin[viz]' (setup.sh installs it)"
        ) from None
    return rerun


@dataclass(frozen=True)
class LiveView:
    """Rerun's web viewer and gRPC server, bound to 127.0.0.1, serving a recording as it is made (`twin run
    --rerun-serve`) or a recording file, in a process group of its own that keeps serving after the run until it is
    stopped (`stop`, or `kill -- -PID`)."""

    pid: int
    web_url: str  # what to open in a browser
    grpc_url: str  # where the recording is sent

    @staticmethod
    def start(rrd: Path | None = None, timeout_s: float = 30.0) -> LiveView:
        """A server (for the recording file `rrd`, or for one sent to it), once it says it is hosting the viewer."""
        import subprocess
        import sys

        web, grpc = _free_port(), _free_port()
        rerun = Path(sys.executable).parent / "rerun"
        args = [str(rerun), "--serve-web", *([str(rrd)] if rrd is not None else [])]
        args += ["--bind", "127.0.0.1", "--web-viewer-port", str(web), "--port", str(grpc)]
        try:
            proc = subprocess.Popen(
                args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
            )
        except OSError as e:
            raise DependencyMissing(f"cannot start Rerun's viewer server ({rerun}): {e.strerror}") from None
        deadline = time.monotonic() + timeout_s
        seen = ""
        while "Hosting a web-viewer" not in seen and time.monotonic() < deadline:
            line = proc.stdout.readline() if proc.stdout else ""
            if not line and proc.poll() is not None:
                break
            seen += line
        if "Hosting a web-viewer" not in seen:
            proc.kill()
            raise DependencyMissing(
                f"Rerun's viewer server did not start: {seen.strip().splitlines()[-1:] or 'no output'}"
            )
        grpc_url = f"rerun+http://127.0.0.1:{grpc}/proxy"
        return LiveView(proc.pid, f"http://127.0.0.1:{web}/?url={quote(grpc_url, safe='')}", grpc_url)

    def stop(self) -> None:
        """Stop the server: its process group (`rerun` is a script that starts the viewer binary)."""
        import os
        import signal

        os.killpg(self.pid, signal.SIGTERM)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class RerunRecording:
    """`RerunRecording(path, scene=..., kin=...)`, `.attach(world)` before the run, `.motion(...)` per stage (the
    cell's trace), `.verdicts(outcomes)` and `.close()` after it."""

    def __init__(
        self, path: str | Path | None, *, scene: PlanningScene, kin: URArm, recording_id: str, serve: bool = False
    ):
        if path is None and not serve:
            raise ConfigError("a recording needs a file (--rerun OUT.rrd) or a live view (--rerun-serve)")
        self.path = None if path is None else Path(path)
        if self.path is not None and self.path.suffix.lower() != ".rrd":
            raise ConfigError(f"--rerun must name an .rrd file, got {str(self.path)!r}")
        rr = rerun_module()
        self._rr = rr
        if self.path is not None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise ConfigError(f"cannot write {self.path}: {e.strerror}") from None
        self.rec = rr.RecordingStream("twin", recording_id=recording_id)
        sinks = [] if self.path is None else [rr.FileSink(str(self.path))]
        self.live: LiveView | None = None
        if serve:
            self.live = LiveView.start()
            sinks.append(rr.GrpcSink(self.live.grpc_url))
        self.rec.set_sinks(*sinks)
        self.rec.send_blueprint(self._layout())
        from twin.collision.fcl_shapes import primitive_shapes  # lazy: fcl

        self._scene, self._kin = scene, kin
        self._names = list(kin.joint_names)
        self._n_motion = 0
        self._n_capture = 0
        self._times: list[float] = []  # the samples of the world's observer (sent as columns by `close`)
        self._link_poses: list[np.ndarray] = []
        self._joints: list[np.ndarray] = []
        self._objects: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {}
        self._robot_shapes = primitive_shapes(scene.model)
        self._links = sorted({s.link for s in self._robot_shapes})
        self._log_static()

    def _layout(self) -> Any:
        """The saved layout a recording opens with: the cell in 3-D beside the camera image, the joint plot and
        the stage log."""
        rrb = self._rr.blueprint
        return rrb.Blueprint(
            rrb.Horizontal(
                # the depth image stays in the camera view: as points in 3-D it hid the robot
                rrb.Spatial3DView(origin="world", name="cell", contents=["+ world/**", "- world/camera/image/depth"]),
                rrb.Vertical(
                    rrb.Tabs(
                        rrb.Spatial2DView(origin="world/camera/image", name="camera", contents=["+ $origin/rgb"]),
                        rrb.Spatial2DView(origin="world/camera/image", name="depth", contents=["+ $origin/depth"]),
                    ),
                    rrb.TimeSeriesView(origin="robot", name="joints (rad) and finger opening (m)"),
                    rrb.TextLogView(origin="events", name="stages and verdicts"),
                ),
                column_shares=[3, 2],
            ),
            collapse_panels=True,
        )

    # ---- static: the cell ------------------------------------------------------------------------
    def _shape(self, kind: str, size: tuple[float, ...], T: np.ndarray | None = None) -> Any:
        """A primitive (twin.robot.urdf_model.Shape kinds) as a rerun archetype at pose T (None: the identity)."""
        rr = self._rr
        centre = [0.0, 0.0, 0.0] if T is None else T[:3, 3].tolist()
        quat = None if T is None else rr.Quaternion(xyzw=matrix_to_quat(T[:3, :3]))
        if kind == "box":
            half = (0.5 * np.asarray(size[:3], dtype=float)).tolist()
            return rr.Boxes3D(half_sizes=[half], centers=[centre], quaternions=None if quat is None else [quat])
        if kind == "sphere":
            r = float(size[0])
            return rr.Ellipsoids3D(half_sizes=[[r, r, r]], centers=[centre])
        r, length = float(size[0]), float(size[1])
        quats = None if quat is None else [quat]
        if kind == "capsule":  # rerun's capsule starts at its translation and runs along +z; twin's is centred
            R = np.eye(3) if T is None else T[:3, :3]
            start = (np.asarray(centre) - R[:, 2] * 0.5 * length).tolist()
            return rr.Capsules3D(lengths=[length], radii=[r], translations=[start], quaternions=quats)
        return rr.Cylinders3D(lengths=[length], radii=[r], centers=[centre], quaternions=quats)

    def _log_static(self) -> None:
        rr, rec = self._rr, self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        by_link: dict[str, list[tuple[str, tuple[float, ...], np.ndarray]]] = {}
        for s in self._robot_shapes:
            by_link.setdefault(s.link, []).append((s.kind, tuple(s.size), s.origin))
        for link, shapes in by_link.items():
            for i, (kind, size, T) in enumerate(shapes):
                rec.log(f"world/robot/{link}/shape{i}", self._shape(kind, size, T), static=True)
        for name, shapes in sorted(self._scene.environment_shapes().items()):
            for i, (kind, size, T) in enumerate(shapes):
                rec.log(f"world/fixtures/{name}/shape{i}", self._shape(kind, size, T), static=True)

    # ---- over time: the world's observer ---------------------------------------------------------------
    def attach(self, world: World) -> RerunRecording:
        world.observe(self._sample, every_s=1.0 / POSE_RATE_HZ)
        self._sample(world.view())
        return self

    def _sample(self, view: WorldView) -> None:
        """Keep the poses and joint states of this instant; they are sent as columns when the recording closes
        (one call per entity: logging each sample, ~25 calls of ~0.1 ms at 30 Hz, made a RoboCup run 1.8x slower)."""
        self._times.append(view.sim_time)
        self._link_poses.append(np.stack([view.link_matrix(link) for link in self._links]))
        for o in view.objects():
            if o.name not in self._objects:
                half = (0.5 * np.asarray(o.size, dtype=float)).tolist()
                self.rec.log(
                    f"world/objects/{o.name}/box", self._rr.Boxes3D(half_sizes=[half], labels=[o.cls]), static=True
                )
                self._objects[o.name] = []
            self._objects[o.name].append((len(self._times) - 1, o.position.copy(), o.orientation_xyzw.copy()))
        self._joints.append(np.append(view.joint_positions(), view.gripper_opening()))

    def configuration(self, t: float, q: np.ndarray) -> None:
        """A sample of the robot at joints `q` (6,) at time `t` without a world: its links placed by the planning
        scene's kinematics at the scene's finger opening (a comparison query's start, plan and goal)."""
        poses = self._scene.link_poses(np.asarray(q, dtype=float))
        self._times.append(float(t))
        self._link_poses.append(np.stack([poses[link] for link in self._links]))
        self._joints.append(np.append(np.asarray(q, dtype=float), self._scene.gripper_opening))

    def _send_samples(self) -> None:
        """Send the observer's samples kept since the last call, as columns (at the end; served live, at every
        stage too)."""
        rr, rec = self._rr, self.rec
        if not self._times:
            return
        t = np.asarray(self._times, dtype=float)
        poses = np.asarray(self._link_poses)  # (m, links, 4, 4)
        for i, link in enumerate(self._links):
            T = poses[:, i]
            quats = np.array([matrix_to_quat(R) for R in T[:, :3, :3]])
            rec.send_columns(
                f"world/robot/{link}",
                indexes=[rr.TimeColumn("sim", duration=t)],
                columns=rr.Transform3D.columns(translation=T[:, :3, 3], quaternion=quats),
            )
        for name, rows in self._objects.items():
            k = np.array([r[0] for r in rows])
            rec.send_columns(
                f"world/objects/{name}",
                indexes=[rr.TimeColumn("sim", duration=t[k])],
                columns=rr.Transform3D.columns(
                    translation=np.array([r[1] for r in rows]), quaternion=np.array([r[2] for r in rows])
                ),
            )
        joints = np.asarray(self._joints)  # (m, 7): the six joints, then the finger opening
        for j, name in enumerate([*(f"joints/{n}" for n in self._names), "gripper_opening_m"]):
            rec.send_columns(
                f"robot/{name}",
                indexes=[rr.TimeColumn("sim", duration=t)],
                columns=rr.Scalars.columns(scalars=joints[:, j]),
            )
        self._times, self._link_poses, self._joints = [], [], []
        self._objects = {name: [] for name in self._objects}

    # ---- the cell's trace: what was planned and done --------------------------------------------------
    def motion(self, sim_time_s: float, stage: str, planner: str, request: MotionRequest, result: MotionResult) -> None:
        """A stage planned at `sim_time_s`: its event line, and its planned TCP path (if it has a trajectory); served
        live, the observer's samples so far go out first (the view follows the run stage by stage; a file gets them
        at the end, in fewer, larger chunks: +15 % wall and 3.4 MB for a RoboCup run instead of +19 % and 5.7 MB)."""
        if self.live is not None:
            self._send_samples()
        rr, rec = self._rr, self.rec
        self._n_motion += 1
        rec.set_time("sim", duration=sim_time_s)
        line = f"{stage}: {planner}: {result.status.value}" + (f" ({result.reason})" if not result.success else "")
        rec.log("events", rr.TextLog(line, level="INFO" if result.success else "WARN"))
        traj = result.trajectory
        if traj is None or traj.q.shape[0] == 0:
            return
        idx = np.unique(np.linspace(0, traj.q.shape[0] - 1, _PATH_POINTS).round().astype(int))
        pts = np.array([self._kin.fk(q)[:3, 3] for q in traj.q[idx]])
        colour = [40, 160, 255] if result.success else [255, 80, 40]
        # (no label: thirty stages' labels covered the cell; the stage log names them)
        rec.log(f"world/plans/{self._n_motion:03d}_{stage}", rr.LineStrips3D([pts], colors=[colour]))

    def perceived(self, sim_time_s: float, sighting: Sighting) -> None:
        """A capture: the camera where the task believed it was, its colour image (JPEG) and depth (mm, points in
        3-D through the camera model where a view shows it), the objects perception saw and the obstacle boxes it
        made."""
        rr, rec = self._rr, self.rec
        frame, T, objects, boxes = sighting.frame, sighting.T_base_camera, sighting.objects, sighting.boxes
        self._n_capture += 1
        rec.set_time("sim", duration=sim_time_s)
        rec.log(
            "world/camera",
            rr.Transform3D(translation=T[:3, 3], quaternion=rr.Quaternion(xyzw=matrix_to_quat(T[:3, :3]))),
        )
        intr = frame.intrinsics
        rec.log(
            "world/camera/image",
            rr.Pinhole(
                image_from_camera=intr.matrix(), resolution=[intr.width, intr.height], camera_xyz=rr.ViewCoordinates.RDF
            ),
        )
        rec.log("world/camera/image/rgb", rr.Image(frame.rgb).compress(jpeg_quality=_JPEG_QUALITY))
        depth_mm = np.clip(np.round(frame.depth_m * 1000.0), 0, np.iinfo(np.uint16).max).astype(np.uint16)
        rec.log("world/camera/image/depth", rr.DepthImage(depth_mm, meter=1000.0))
        labels = [label for label, _ in objects]
        pts = np.array([p for _, p in objects], dtype=float).reshape(-1, 3)
        rec.log("world/perceived/objects", rr.Points3D(pts, labels=labels, radii=0.01, colors=[255, 200, 0]))
        centres = [0.5 * (lo + hi) for _, lo, hi in boxes]
        halves = [0.5 * (hi - lo) for _, lo, hi in boxes]
        rec.log(
            "world/perceived/boxes",
            rr.Boxes3D(centers=centres, half_sizes=halves, labels=[n for n, _, _ in boxes], colors=[255, 120, 0]),
        )
        rec.log("events", rr.TextLog(f"capture {self._n_capture}: {len(objects)} objects, {len(boxes)} obstacle boxes"))

    def verdicts(self, sim_time_s: float, outcomes: list[ObjectOutcome] | tuple[ObjectOutcome, ...]) -> None:
        """The judge's verdict per object, as event lines at the end of the run."""
        rr, rec = self._rr, self.rec
        rec.set_time("sim", duration=sim_time_s)
        for o in outcomes:
            line = f"verdict {o.id}: {'placed' if o.placed else 'not placed'} in {o.target_bin}"
            line += f" ({o.error})" if o.error else ""
            rec.log("events", rr.TextLog(line, level="INFO" if o.placed else "ERROR"))

    def query(self, request: MotionRequest, result: MotionResult, label: str) -> None:
        """A comparison query on the `sim` timeline of its trajectory: the robot at the start (t = 0), then along the
        planned trajectory if the planner returned one, else at the goal joints (a joint goal); the start and goal
        TCP, the planned TCP path, the straight joint motion's (a joint goal), and the verdict line."""
        rr, rec = self._rr, self.rec
        start = np.asarray(request.start, dtype=float)
        self.configuration(0.0, start)
        rec.set_time("sim", duration=0.0)
        goal = request.goal
        goal_q: np.ndarray | None = None
        if isinstance(goal, JointGoal):
            goal_q = np.asarray(goal.q, dtype=float)
            goal_p = self._kin.fk(goal_q)[:3, 3]
        else:
            goal_p = goal.pose.matrix()[:3, 3]
        p0 = self._kin.fk(start)[:3, 3]
        rec.log(
            "world/query/start_goal",
            rr.Points3D([p0, goal_p], labels=["start", "goal"], radii=0.015, colors=[[0, 200, 0], [220, 0, 220]]),
        )
        if goal_q is not None:
            line = np.array(
                [self._kin.fk(start + f * (np.asarray(goal_q) - start))[:3, 3] for f in np.linspace(0, 1, 30)]
            )
            rec.log(
                "world/query/straight",
                rr.LineStrips3D([line], colors=[[160, 160, 160]], labels=["straight joint motion"]),
            )
        traj = result.trajectory
        if traj is not None and traj.q.shape[0] > 1:
            idx = np.unique(np.linspace(0, traj.q.shape[0] - 1, 120).round().astype(int))
            for i in idx[1:]:
                self.configuration(float(traj.t[i]), traj.q[i])
        elif result.path is not None and len(result.path) > 1:
            self._refused(np.asarray(result.path, dtype=float))
        elif goal_q is not None:
            self.configuration(1.0, np.asarray(goal_q, dtype=float))
        self.motion(0.0, "query", label, request, result)

    def _refused(self, path: np.ndarray) -> None:
        """A refused motion (`MotionResult.path`): its TCP path in red, the robot moving along it (one second per
        radian of the largest joint change, densified at 0.01 rad) up to the first configuration in collision in
        the planning scene, which is marked; the robot stays there."""
        rr, rec = self._rr, self.rec
        qs = densify_path(path, 0.01)
        hit = self._scene.first_collision(qs)
        tcp = np.array([self._kin.fk(q)[:3, 3] for q in qs[:: max(1, len(qs) // 120)]])
        rec.log("world/query/refused", rr.LineStrips3D([tcp], colors=[[255, 60, 40]], labels=["refused motion"]))
        end = len(qs) - 1 if hit is None else hit
        step = np.abs(np.diff(qs, axis=0)).max(axis=1)
        times = np.concatenate([[0.0], np.cumsum(step)])
        for i in np.unique(np.linspace(0, end, min(end + 1, 120)).round().astype(int))[1:]:
            self.configuration(float(times[i]), qs[i])
        if hit is not None:
            rec.set_time("sim", duration=float(times[hit]))
            p = self._kin.fk(qs[hit])[:3, 3]
            pair = self._scene.min_distance(qs[hit])
            what = f"first collision: {pair.robot_part} with {pair.other}"
            rec.log("world/query/first_collision", rr.Points3D([p], radii=0.02, colors=[[255, 0, 0]], labels=[what]))
            rec.log("events", rr.TextLog(what, level="WARN"))

    def close(self) -> Path | None:
        """Send the observer's samples, flush and end the recording; its file (None: a live view only)."""
        self._send_samples()
        self.rec.flush()
        self.rec.disconnect()
        return self.path
