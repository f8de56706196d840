"""The wrist camera's hand-eye calibration, never a single point of failure.

With `perception.extrinsics: aruco` the run views the base marker from `camera.calibration_pose` and measures
where the camera sits on the wrist. One view is not enough on every scene: a standing bottle at the near edge
of the objects' region hides a corner of the marker from that pose (stress seeds 100-399: 1 of 300, "ids
seen: []" with a clean render too), and a camera left with its configured hand-eye transform then misplaces
every object by a mount error's worth (13-23 mm under 1 cm / 1 deg). So:

1. the first view's estimate is checked against the table plane in its own depth image (it fixes the
   camera's height and tilt over the table top, z = 0 in the base frame): one that disagrees is not used;
2. when the marker is not found there (or the estimate disagrees), the camera looks again from a few
   deterministic variations of that view, each aimed at the marker's nominal position (from the cell
   layout): steeper (over what stands in front of it), from either side, and closer. A view out of reach,
   or with its gripper low over the table, is not taken; up to two good views are combined (averaged when
   they agree, else the one with the smaller reprojection error);
3. only then does the run fall back to the configured transform, levelled on the table plane at every
   capture (tilt and height measured, the rest trusted to `camera.mount_tolerance`), and says so in the run
   summary (`CalibrationOutcome`) with the error bound that implies.

The task decides only with what the cell senses: camera frames and joint encoders.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.config import Settings
from twin.perception.aruco import MarkerNotFound, calibrate, transform_error
from twin.perception.capture import Capture, capture_frame, prefetch_next_capture, wrist_camera_offset
from twin.perception.mount import error_bound_m, level_on_table, table_disagreement, table_plane
from twin.perception.pipeline import camera_extrinsics
from twin.robot.kinematics import URArm
from twin.scene_layout import OBJECT_TEMPLATES, find_marker_plate, marker_pose_in_base
from twin.tasks.cell import Cell
from twin.tasks.stage_failure import StageFailed
from twin.tasks.ways import OVER_MARGIN_M
from twin.types import CalibrationOutcome

if TYPE_CHECKING:
    from twin.tasks.robocup.perception import ObjectEstimate

__all__ = [
    "HandEye",
    "calibrate_hand_eye",
    "error_bound_m",
    "relook",
    "relook_joints",
    "relook_target",
    "table_disagreement",
    "view_candidates",
]

log = logging.getLogger("twin")

# An estimate agrees with the table plane when the camera's tilt and height it implies are within these of
# what the depth image says: the plane from thousands of points is good to ~0.05 deg / 1 mm, the marker's
# plane-constrained estimate to ~1 mm / 0.05 deg (`twin calibrate`); a wrong estimate is off by far more
_AGREE_TILT_DEG = 0.5
_AGREE_HEIGHT_M = 0.005
# two views' hand-eye estimates are the same measurement when they agree this well: averaged
_SAME_T_M = 0.005
_SAME_R_DEG = 0.5
_GOOD_VIEWS = 2  # after a failed first view, stop looking once this many views measured it
_SAME_PLACE_M = 0.04  # an estimate this near where a failed grasp's object was seen is that object


@dataclass(frozen=True)
class HandEye:
    """The camera's mount as the run knows it, and how (`outcome`, the run summary's `calibration`).

    `T_tool0_camera` (4, 4): the measured hand-eye transform ("measured"); None otherwise. "fallback" levels
    the configured transform on the table plane of each capture (`camera_pose`).
    """

    outcome: CalibrationOutcome
    T_tool0_camera: np.ndarray | None = None

    @property
    def uncalibrated(self) -> bool:
        """A calibration was asked for and not measured: poses are good to `outcome.error_bound_m` only."""
        return self.outcome.status == "fallback"

    def camera_pose(self, settings: Settings, cap: Capture, arm: URArm) -> np.ndarray:
        """(4, 4) T_base_camera perception uses for `cap`, taken by the wrist of `arm` (the run's)."""
        if self.T_tool0_camera is not None:
            return arm.fk(cap.q, "flange") @ self.T_tool0_camera
        if cap.mount == "wrist":
            if self.uncalibrated:
                return level_on_table(cap, settings)
            return cap.T_base_camera_nominal  # forward kinematics and the configured hand-eye transform
        return camera_extrinsics(settings, cap, None, arm=arm)


def calibrate_hand_eye(cell: Cell, reach: Callable[[Cell, np.ndarray], None]) -> HandEye:
    """Measure the wrist camera's hand-eye transform on the base marker (module docstring), at the start of
    a run; `reach(cell, q)` moves the arm to a view's joints (StageFailed when it cannot)."""
    settings = cell.settings
    cam = settings.camera
    if settings.perception.extrinsics != "aruco" or cam.mount != "wrist":
        reason = f"perception.extrinsics is {settings.perception.extrinsics} ({cam.mount} camera)"
        return HandEye(CalibrationOutcome("configured", error_bound_m=error_bound_m(settings, cell.kin), reason=reason))
    cell.current = "hand-eye"
    q_first = np.asarray(cam.calibration_pose if cam.calibration_pose is not None else cam.capture_pose, dtype=float)
    views: list[tuple[str, np.ndarray]] = [("the calibration pose", q_first)]
    good: list[tuple[np.ndarray, float]] = []  # (T_tool0_camera, reprojection px) per view that measured it
    reasons: list[str] = []
    taken = 0
    levelled = False
    i = 0
    while i < len(views) and len(good) < (1 if i == 0 else _GOOD_VIEWS):
        name, q = views[i]
        i += 1
        try:
            reach(cell, q)
        except StageFailed as e:
            reasons.append(f"{name}: not reached ({e})")
            cell.recover()
        else:
            taken += 1
            cap = capture_frame(cell.world, settings, pose="calibration", move=False)
            prefetch_next_capture(cell.world, settings)
            found, why, plane_ok = _measure(cell, cap)
            levelled |= plane_ok
            if found is not None:
                good.append(found)
            else:
                reasons.append(f"{name}: {why}")
        if i == 1 and not good:
            log.warning("robocup: hand-eye calibration: %s; looking again from other poses", reasons[-1])
            views += view_candidates(settings, cell.kin, q_first)
    if good:
        T, rep = _combine(good)
        note = "; ".join(reasons)
        if reasons:
            log.info("robocup: hand-eye measured in %d of %d views (%s)", len(good), taken, note)
        return HandEye(CalibrationOutcome("measured", views=taken, reprojection_px=rep, reason=note), T)
    bound = error_bound_m(settings, cell.kin, levelled=levelled)
    reason = "; ".join(reasons) or "no view of the marker was reachable"
    log.warning(
        "robocup: no hand-eye calibration in %d views (%s); using the configured camera.wrist_offset_m%s, "
        "good to %.0f mm on the table",
        taken,
        reason,
        ", levelled on the table plane" if levelled else "",
        1e3 * bound,
    )
    return HandEye(CalibrationOutcome("fallback", views=taken, error_bound_m=bound, reason=reason))


def _measure(cell: Cell, cap: Capture) -> tuple[tuple[np.ndarray, float] | None, str, bool]:
    """One view: ((T_tool0_camera, reprojection px) or None, why not, whether the table plane was seen)."""
    try:
        cal = calibrate(cap.frame, cell.settings)
    except MarkerNotFound as e:
        return None, str(e), table_plane(cap) is not None
    off = table_disagreement(cap, cal.T_base_camera)
    if off is None:
        return None, "the marker was found, but no table plane to check it against", False
    tilt_deg, height_m = off
    if tilt_deg > _AGREE_TILT_DEG or abs(height_m) > _AGREE_HEIGHT_M:
        why = "the marker's estimate disagrees with the table plane"
        why += f" (tilt {tilt_deg:.2f} deg, height {1e3 * height_m:+.1f} mm)"
        return None, why, True
    T_tool0_camera = np.linalg.inv(cell.kin.fk(cap.q, "flange")) @ cal.T_base_camera
    return (T_tool0_camera, cal.marker.reprojection_px), "", True


def _combine(good: list[tuple[np.ndarray, float]]) -> tuple[np.ndarray, float]:
    """One hand-eye transform from the views that measured it: the mean of those that agree with the best
    (smallest reprojection) one, rotations averaged by projecting their mean onto SO(3)."""
    best = min(range(len(good)), key=lambda k: good[k][1])
    T0 = good[best][0]
    same = [T for T, _ in good if _agree(T, T0)]
    if len(same) == 1:
        return T0, good[best][1]
    T = np.eye(4)
    T[:3, 3] = np.mean([S[:3, 3] for S in same], axis=0)
    U, _, Vt = np.linalg.svd(np.mean([S[:3, :3] for S in same], axis=0))
    T[:3, :3] = U @ np.diag([1.0, 1.0, float(np.linalg.det(U @ Vt))]) @ Vt
    return T, good[best][1]


def _agree(A: np.ndarray, B: np.ndarray) -> bool:
    dt, dr = transform_error(A, B)
    return dt <= _SAME_T_M and dr <= _SAME_R_DEG


# ---- the other views --------------------------------------------------------------------------------
# (name, azimuth change deg, elevation change deg, range factor) from the calibration view, as seen from the
# marker: steeper looks over what stands in front of the plate, the sides past it, closer under it
_VARIATIONS: tuple[tuple[str, float, float, float], ...] = (
    ("steeper", 0.0, 20.0, 1.0),
    ("from the left", 50.0, 0.0, 1.0),
    ("from the right", -50.0, 0.0, 1.0),
    ("closer and steeper", 0.0, 15.0, 0.8),
    ("from the left, steeper", 40.0, 15.0, 1.0),
    ("from the right, steeper", -40.0, 15.0, 1.0),
)
_MAX_ELEVATION_DEG = 85.0


def view_candidates(settings: Settings, kin: URArm, q_first: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """(name, joints) of the other views of the marker, in the order tried: each looks at the marker's
    nominal centre (the cell layout's) from a variation of the calibration view's direction and distance;
    an IK branch of the camera pose nearest the calibration pose, within the joint limits, with the tcp at
    least `min_tcp_z` above the table (above every catalogued object standing, with a margin: what stands
    there is not known yet). Views out of reach are left out."""
    if find_marker_plate(settings) is None:
        return []
    target = marker_pose_in_base(settings)[:3, 3]
    offset_inv = np.linalg.inv(wrist_camera_offset(settings))
    eye0 = (kin.fk(q_first, "flange") @ wrist_camera_offset(settings))[:3, 3]
    v = eye0 - target
    r0 = float(np.linalg.norm(v))
    az0, el0 = math.atan2(v[1], v[0]), math.asin(float(np.clip(v[2] / r0, -1.0, 1.0)))
    out = []
    z_min = min_tcp_z(settings)
    for name, daz, del_, k in _VARIATIONS:
        az = az0 + math.radians(daz)
        el = min(el0 + math.radians(del_), math.radians(_MAX_ELEVATION_DEG))
        eye = target + k * r0 * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        best: np.ndarray | None = None
        for roll in (0.0, math.pi):
            sols = kin.ik(_look_at(eye, target, roll) @ offset_inv, "flange")
            for q in sols:
                if kin.fk(q, "tcp")[2, 3] < z_min:
                    continue
                if best is None or np.abs(q - q_first).sum() < np.abs(best - q_first).sum():
                    best = q
        if best is not None:
            out.append((f"the view {name}", best))
    return out


def min_tcp_z(settings: Settings) -> float:
    """The lowest tcp height (m) of a marker view: over the tallest object the config places, standing."""
    items = settings.world.objects.items
    heights = [max(OBJECT_TEMPLATES[i.cls].extents(lying)[2] for lying in (False, True)) for i in items]
    return max(heights, default=0.0) + OVER_MARGIN_M


def _look_at(eye: np.ndarray, target: np.ndarray, roll: float) -> np.ndarray:
    """(4, 4) an OpenCV camera at `eye` whose optical axis (z) points at `target`, its x axis level (then
    turned by `roll` about the axis)."""
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:  # looking straight down: any level x
        x = np.array([0.0, -1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = c * x + s * y, -s * x + c * y, z
    T[:3, 3] = eye
    return T


# ---- the table plane ----------------------------------------------------------------------------------
# ---- a re-look at an object a grasp found the wrong width ---------------------------------------------------
def relook_joints(cell: Cell, xy: np.ndarray, q_capture: np.ndarray) -> np.ndarray | None:
    """Joints that put the camera straight above base-frame point `xy` (2,), at the capture pose's height and
    with its image orientation: the object then sits at the image centre, where a turn of the mount about
    the vertical misplaces nothing (levelled, only the level shift is left). The IK branch nearest the
    capture pose; None when out of reach."""
    offset = wrist_camera_offset(cell.settings)
    T = cell.kin.fk(q_capture, "flange") @ offset
    T[:2, 3] = np.asarray(xy, dtype=float)[:2]
    sols = cell.kin.ik(T @ np.linalg.inv(offset), "flange")
    if len(sols) == 0:
        return None
    return np.asarray(sols[int(np.argmin(np.abs(sols - q_capture).sum(axis=1)))])


def relook(
    cell: Cell,
    hand_eye: HandEye,
    xy: np.ndarray,
    q_capture: np.ndarray,
    reach: Callable[[Cell, np.ndarray], None],
) -> tuple[Capture, np.ndarray] | None:
    """After a grasp found the wrong width (or nothing) with an uncalibrated camera: a fresh capture from
    straight above where the object was seen (`relook_joints`), and the camera pose to perceive it with;
    None when that view is out of reach or not reached (the next capture is the usual one)."""
    q = relook_joints(cell, xy, q_capture)
    if q is None:
        return None
    try:
        reach(cell, q)
    except StageFailed as e:
        log.info("robocup: no re-look from above (%s)", e)
        return None
    cap = capture_frame(cell.world, cell.settings, move=False)
    prefetch_next_capture(cell.world, cell.settings)
    return cap, hand_eye.camera_pose(cell.settings, cap, cell.kin)


def relook_target(
    cell: Cell,
    hand_eye: HandEye,
    est: ObjectEstimate,
    objects: tuple[ObjectEstimate, ...],
    seen_at: np.ndarray,
    q_capture: np.ndarray,
    reach: Callable[[Cell, np.ndarray], None],
    perceive: Callable[[Capture, np.ndarray], Sequence[ObjectEstimate]],
) -> tuple[ObjectEstimate, tuple[ObjectEstimate, ...]]:
    """The target and the scene's objects to plan with after a re-look: when `est` is the object whose grasp
    found the wrong width (seen at `seen_at` (2,) then), the same class's estimate from straight above that
    is nearest it, within the error bound, replaces it (the other objects stay as the full view saw them);
    otherwise, or when the re-look sees no such estimate, unchanged."""
    if float(np.linalg.norm(est.position[:2] - np.asarray(seen_at)[:2])) > _SAME_PLACE_M:
        return est, objects
    looked = relook(cell, hand_eye, est.position[:2], q_capture, reach)
    if looked is None:
        return est, objects
    near = max(_SAME_PLACE_M, 2.0 * (hand_eye.outcome.error_bound_m or 0.0))
    same = [o for o in perceive(*looked) if o.label == est.label]
    same = [o for o in same if float(np.linalg.norm(o.position[:2] - est.position[:2])) <= near]
    if not same:
        log.info("robocup: the re-look from above did not see %s again; keeping the first estimate", est.label)
        return est, objects
    better = min(same, key=lambda o: float(np.linalg.norm(o.position[:2] - est.position[:2])))
    log.info(
        "robocup: %s re-looked from above: %.1f mm from the first estimate",
        est.label,
        1e3 * float(np.linalg.norm(better.position[:2] - est.position[:2])),
    )
    return better, tuple(better if o is est else o for o in objects)
