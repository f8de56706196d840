"""The finger jam: an object wedged between the opened fingers after a release, sensed and undone.

An object can stay between the fingers after they open: a lying spam gripped across its 83 mm side has 2 mm
to spare in the 85 mm stroke, and tilted a few degrees it spans the pads and locks there by friction (the
pads' friction is 1.5; squeezed by the finger motors, the wedge holds many times the object's weight, so
no shake or acceleration of the arm frees it). The fingers then read open, the object rides along, and
every later move is stopped by the finger touching it. This module senses that from what a real 2F-85 cell
senses, and frees it with a bounded number of tries.

Sensing (`sense_jam`), three signals a real cell has:

- **the finger encoders** (`Cell.read_gripper`): the 2F-85 reports its finger position; fingers commanded
  open that stop short of the commanded opening are held apart by something between them;
- **the wrist camera** (`camera.mount: wrist`, the RoboCup cell's D435 rides on the wrist beside the
  gripper): a depth frame shows the space below and between the fingers. Only the pixels whose rays pass
  through that space are read, and only as far as the gripper's own parts (its URDF boxes at the measured
  opening) leave them free: this is the robot self-filter a real cell applies to a wrist camera, i.e. what
  the empty gripper shows, computed from the robot's model. An empty gripper shows the background beyond
  that space; an object between the fingers shows there, or, closer than the sensor's minimum range, as
  pixels without depth. The frame is rendered small (a quarter of the resolution), with the camera's
  sensor model, from the camera's real pose and read with the configured hand-eye transform;
- **the protective stop's report**: a move stopped by a finger touching a loose object (not a fixture of
  the cell) while the gripper should be empty names the object stuck to it. It is the trigger where no
  wrist camera can look; with one, the camera decides (a stop can also be a finger brushing an object on
  the table).

The task never decides with the simulator's ground truth (`body_between_fingers`, object poses).

Freeing (`free_jam`): set the object down on the surface it was released over (the bin floor, the drop
zone, the table under the gripper: pressing it onto a surface turns it out of the wedge), close and open
there, rise; then the same with the fingertips just above the surface; then shake the wrist. After each
try the arm rises back to where it looks and senses again; it stops as soon as the fingers are clear. Every
move is a stage move through the checked planners (`Cell.move_pose` / `move_joints`); the moves off an
object the fingers touch are retreats (`retreat=True`), which the protective stop allows.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.camera import Intrinsics, true_camera_pose
from twin.perception.noise import apply_sensor_noise
from twin.robot.urdf_model import primitive_half_extents
from twin.tasks.grasping import top_down
from twin.tasks.judge import body_between_fingers  # the simulated contact monitor's, as at a grasp
from twin.tasks.stage_failure import StageFailed
from twin.timing import stage

if TYPE_CHECKING:
    from twin.tasks.cell import Cell

__all__ = [
    "JamReading",
    "clear_after_release",
    "free_jam",
    "sense_jam",
    "stop_names_finger_contact",
    "surface_below",
]

log = logging.getLogger("twin")

FINGER_LINKS = ("left_finger", "right_finger")
GRIPPER_LINKS = (*FINGER_LINKS, "gripper_base")

# Encoders: fingers commanded open that stop this much short of the commanded opening hold something apart
# (settled free fingers reach their target within a fraction of a millimetre).
OPEN_TOLERANCE_M = 0.005
# Wrist camera: a quarter of the camera's resolution is plenty to see an object 10-20 cm away, and renders
# in a fraction of the time of a full frame.
VIEW_DOWNSCALE = 4
# The space between and below the fingers the camera reads, in the tcp frame (z along the fingers, away
# from the flange; +y towards the wrist camera): inside the pads by X_MARGIN, from just below the gripper
# body (BODY_MARGIN) to SPACE_BELOW_TIPS past the fingertips, and across Y_RANGE. An object wedged across
# the 85 mm stroke is at least ~60 mm wide the other way (the 50 mm warehouse cube wedges along its body
# diagonal, the RoboCup objects across a side), so it fills the space out to 35 mm on the camera's side;
# what the camera sees of it there is the band just below and at the fingertips (its view of the pads
# themselves is blocked by the gripper body). The background after a rise lies well below.
X_MARGIN_M = 0.005
BODY_MARGIN_M = 0.005
SPACE_BELOW_TIPS_M = 0.015
Y_RANGE_M = (-0.02, 0.035)
# A pixel shows something in that space when its depth is this much short of where its ray leaves the
# space (or meets the gripper), or it has no depth at all (closer than the sensor's minimum range).
DEPTH_TOLERANCE_M = 0.005
# Rays that cross less of the space than this are not read (grazing rays at its edges).
MIN_RAY_SPAN_M = 0.005
# Share of the space's pixels that must show something for the camera to call it a jam. An empty gripper
# shows a few per cent (dropouts, edges of what lies far below; ~10 % with the 10 % dropout fault model);
# an object wedged between the fingers 70-100 %, also with a 1 cm / 1 deg hand-eye error.
FILLED_SHARE = 0.4
MIN_PIXELS = 30
# Freeing
TRIES = 3
PRESS_M = 0.015  # the object's bottom is set this far below the surface it is pressed onto (pushed up in the pads)
TIP_GAP_M = 0.006  # the fingertips stay this far above the surface
SHAKE_RAD = 0.35  # wrist turns of the shake, each way
SET_DOWN_RAISES = 3  # a set-down refused in planning is tried this many more times, a centimetre higher each
_STOP = re.compile(r"(\w+) with ([\w.\-]+)")


@dataclass(frozen=True)
class JamReading:
    """What the cell's sensors say about the space between the fingers.

    `jammed`: something is stuck there; `signals`: each sensor that said so, in words; `opening_m`: the
    encoders' opening; `commanded_m`: the opening they were told; `camera_share`: the share of the space's
    pixels the wrist camera saw filled (None: no wrist camera, or it did not look); `camera_pixels`: how
    many pixels it read."""

    jammed: bool
    signals: tuple[str, ...]
    opening_m: float
    commanded_m: float
    camera_share: float | None = None
    camera_pixels: int = 0

    @property
    def reason(self) -> str:
        return "; ".join(self.signals) if self.signals else "the fingers are clear"


def stop_names_finger_contact(cell: Cell, reason: str | None) -> tuple[str, str] | None:
    """(finger link, body) when a protective stop's `reason` ("unexpected contact: left_finger with can_0,
    ...") names only gripper links and among them a finger touching a loose object (a body that is not one
    of the cell's fixtures); None otherwise (no stop, or an arm link hit something: a collision, not a jam)."""
    if not reason or "unexpected contact" not in reason:
        return None
    pairs = _STOP.findall(reason.split("unexpected contact", 1)[1])
    if not pairs or any(link not in GRIPPER_LINKS for link, _ in pairs):
        return None
    fixtures = {f.name for f in cell.settings.world.fixtures} | {"robot", "aruco_marker"}
    for link, body in pairs:
        if link in FINGER_LINKS and body not in fixtures:
            return link, body
    return None


def sense_jam(
    cell: Cell,
    *,
    commanded_m: float | None = None,
    stop_reason: str | None = None,
    camera: bool = True,
) -> JamReading:
    """Is something stuck between the opened fingers? From the finger encoders (opened short of
    `commanded_m`, default the full stroke), the wrist camera (when the cell has one and `camera`: call it
    with the gripper risen clear of what it let go) and `stop_reason`, the protective stop of the last move
    if it was one while the gripper should have been empty (decisive only without a wrist camera)."""
    g = cell.settings.gripper
    commanded = g.max_opening_m if commanded_m is None else float(commanded_m)
    r = cell.read_gripper()
    signals: list[str] = []
    jammed = r.opening_m < commanded - OPEN_TOLERANCE_M
    if jammed:
        signals.append(f"finger encoders: the fingers opened to {1000 * r.opening_m:.1f} of {1000 * commanded:.1f} mm")
    share: float | None = None
    pixels = 0
    looked = camera and cell.settings.camera.mount == "wrist"
    if looked:
        share, pixels = _camera_share(cell, min(r.opening_m, g.max_opening_m))
        if pixels >= MIN_PIXELS and share >= FILLED_SHARE:
            jammed = True
            signals.append(
                f"wrist camera: {100 * share:.0f} % of the {pixels} pixels between the fingers show something there"
            )
    contact = stop_names_finger_contact(cell, stop_reason)
    if contact is not None and not looked:
        jammed = True
        signals.append(f"protective stop: {contact[0]} touched {contact[1]} with nothing meant to be in the fingers")
    elif contact is not None:
        log.info("jam check: the stop named %s touching %s; the wrist camera decides", *contact)
    reading = JamReading(jammed, tuple(signals), r.opening_m, commanded, share, pixels)
    log.debug("jam check: %s (opening %.1f mm, camera %s)", reading.reason, 1000 * r.opening_m, share)
    return reading


def surface_below(cell: Cell, xy: np.ndarray | tuple[float, float]) -> float:
    """z (m) of the highest top of the planning scene's boxes (fixtures, perceived boxes) under the point
    `xy`: what an object let go there comes to rest on. 0 when nothing is modelled below (the floor)."""
    x, y = float(xy[0]), float(xy[1])
    top = 0.0
    # the scene's environment shapes hold the fixtures and the boxes added at run time alike
    shapes = [s for group in cell.scene.environment_shapes().values() for s in group]
    for kind, dims, T in shapes:
        if kind != "box":
            continue
        half = np.abs(T[:3, :3]) @ primitive_half_extents(kind, dims)
        lo, hi = T[:3, 3] - half, T[:3, 3] + half
        if lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]:
            top = max(top, float(hi[2]))
    return top


def free_jam(
    cell: Cell,
    look_pose: np.ndarray,
    *,
    surface_z: float | None = None,
    hang_m: float | None = None,
    reading: JamReading | None = None,
    tries: int = TRIES,
) -> JamReading:
    """Free an object stuck between the opened fingers; at most `tries` tries (of three: set it down, press
    it down harder, shake the wrist), each followed by a rise
    back to `look_pose` (4, 4; the gripper above where it let go, clear of it) and a new `sense_jam`.
    Returns the last reading (`jammed` False: freed; True: still stuck after every try).

    `surface_z`: what the object is set down on (default: `surface_below` the look pose); `hang_m`: how far
    below the tcp the object's bottom was while it was held (the task knows it from the grasp; None: it is
    pressed with the fingertips just above the surface). `reading`: the reading that found the jam."""
    look_pose = np.asarray(look_pose, dtype=float)
    if surface_z is None:
        surface_z = surface_below(cell, look_pose[:2, 3])
    if reading is None:
        reading = sense_jam(cell)
    actions: list[tuple[str, Callable[[], None]]] = [
        ("set it down and let go", lambda: _set_down(cell, look_pose, surface_z, hang_m)),
        ("press it down with the fingertips at the surface", lambda: _set_down(cell, look_pose, surface_z, None)),
        ("shake the wrist", lambda: _shake(cell)),
    ]
    done = 0
    for name, act in actions[: max(0, tries)]:
        if not reading.jammed:
            break
        done += 1
        log.info("jam: %s; try %d of %d: %s", reading.reason, done, tries, name)
        # what is stuck moves with the gripper: the contact monitor treats it as carried, as after a grasp
        # (a real cell's protective stop is a force threshold, which an object wedged in the gripper, moving
        # with it, does not trip); else a set-down is stopped by the object pressed against the gripper body
        carried, cell.held_body = cell.held_body, body_between_fingers(cell.world)
        try:
            act()
        except StageFailed as e:
            log.info("jam: %s: %s", name, e)
        finally:
            cell.held_body = carried
        try:
            if not _at(cell, look_pose):
                cell.move_pose("ascent", look_pose, retreat=True)
        except StageFailed as e:
            log.info("jam: could not rise back to look: %s", e)
        back = _at(cell, look_pose, tol_m=0.01)
        reading = sense_jam(cell, camera=back)  # not back up, what the camera sees below may be what it let go
        if not back:
            log.info("jam: the camera cannot look from here; the encoders say: %s", reading.reason)
    if reading.jammed:
        log.warning("jam: still stuck after %d tries: %s", done, reading.reason)
    elif done:
        log.info("jam: freed after %d tries", done)
    return reading


def clear_after_release(
    cell: Cell,
    release_pose: np.ndarray,
    look_pose: np.ndarray,
    *,
    commanded_m: float | None = None,
    surface_z: float | None = None,
    hang_m: float | None = None,
    tries: int = TRIES,
) -> JamReading:
    """After a release at `release_pose` (4, 4; the fingers told to open to `commanded_m`, default fully):
    fingers that stopped short are opened fully; then the arm rises to `look_pose` (an ascent, as after
    every release), senses, and frees what is stuck (`free_jam`). Returns the last reading; StageFailed
    only when the rise itself fails (as the ascent after a release always could)."""
    g = cell.settings.gripper
    commanded = g.max_opening_m if commanded_m is None else float(commanded_m)
    r = cell.read_gripper()
    if r.opening_m < commanded - OPEN_TOLERANCE_M:
        log.info(
            "jam: the fingers opened to %.1f of %.1f mm after the release; opening them fully",
            1000 * r.opening_m,
            1000 * commanded,
        )
        cell.release()
        commanded = g.max_opening_m
    if not _at(cell, look_pose):
        cell.move_pose("ascent", np.asarray(look_pose, dtype=float))
    reading = sense_jam(cell, commanded_m=commanded)
    if not reading.jammed:
        return reading
    if surface_z is None:
        surface_z = surface_below(cell, np.asarray(release_pose, dtype=float)[:2, 3])
    return free_jam(cell, look_pose, surface_z=surface_z, hang_m=hang_m, reading=reading, tries=tries)


# ---- freeing moves ---------------------------------------------------------------------------------
def _tip_below_tcp(cell: Cell) -> float:
    """How far the fingertips reach past the tcp along the fingers (m), from the gripper's URDF boxes."""
    boxes = cell.robot.gripper_boxes(cell.settings.gripper.max_opening_m)
    return max(0.0, *(float(hi[2]) for _, hi in boxes))


def _set_down(cell: Cell, look_pose: np.ndarray, surface_z: float, hang_m: float | None) -> None:
    """Lower straight down from `look_pose` until the object's bottom is PRESS_M into the surface (or, not
    knowing how far it hangs, the fingertips TIP_GAP_M above it), open fully, close and open there (the
    object resting on the surface is let go square). A stop on the way down (the object pushed up against
    the gripper body) lets go where it stopped. The gripper comes down pointing straight down at the yaw
    it looks at (a transfer with its orientation free, stopped on the way, can leave it tilted, and a
    tilted finger reaches below the tips' height)."""
    floor_tcp = surface_z + _tip_below_tcp(cell) + TIP_GAP_M
    z = floor_tcp if hang_m is None else max(floor_tcp, surface_z + hang_m - PRESS_M)
    R = np.asarray(look_pose, dtype=float)[:3, :3]
    T = top_down(look_pose[:3, 3], math.atan2(float(R[1, 0]), float(R[0, 0])))
    try:
        # refused in planning (the fingers' model reaching into the surface at this opening): a little
        # higher, up to SET_DOWN_RAISES steps of a centimetre; nothing moved until one is accepted
        for k in range(SET_DOWN_RAISES + 1):
            T[2, 3] = z + 0.01 * k
            if T[2, 3] >= look_pose[2, 3]:
                return
            try:
                cell.move_pose("place", T)
                return
            except StageFailed as e:
                if e.moved or k == SET_DOWN_RAISES:
                    raise
                log.info("jam: setting it down at %.3f m was refused (%s); a centimetre higher", T[2, 3], e.reason)
    finally:
        cell.release()
        cell.close_gripper()
        cell.release()


def _shake(cell: Cell) -> None:
    """Turn the wrist SHAKE_RAD each way twice and back, then open fully."""
    q0 = cell.world.joint_positions()
    for turn in (SHAKE_RAD, -SHAKE_RAD, SHAKE_RAD, -SHAKE_RAD, 0.0):
        q = q0.copy()
        q[5] += turn
        cell.move_joints("align", q, retreat=True)
    cell.release()


def _at(cell: Cell, T: np.ndarray, tol_m: float = 1e-3) -> bool:
    """Whether the measured tcp (joint encoders + FK) is within `tol_m` of `T`'s position."""
    M = cell.kin.fk(cell.world.joint_positions())
    return float(np.linalg.norm(M[:3, 3] - np.asarray(T)[:3, 3])) <= tol_m


# ---- the wrist camera's look -----------------------------------------------------------------------
_geometry: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray]] = {}


def _small_intrinsics(cell: Cell) -> Intrinsics:
    cam = cell.settings.camera
    k = VIEW_DOWNSCALE
    return Intrinsics(max(1, cam.width // k), max(1, cam.height // k), cam.fx / k, cam.fy / k)


def _view_geometry(cell: Cell, opening_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(pixel indices (n,) into the flattened small frame, depth limit (n,) m) of the rays through the space
    between the fingers at this opening, each as far as it runs inside that space before it leaves it or
    meets the gripper's own boxes (the self-filter). Cached per opening (to 1 mm) and camera."""
    cam = cell.settings.camera
    intr = _small_intrinsics(cell)
    key = (
        str(cell.settings.resolve(cell.settings.robot.urdf)),
        tuple(cam.wrist_offset_m),
        intr,
        round(1000 * opening_m),
    )
    hit = _geometry.get(key)
    if hit is not None:
        return hit
    # the camera in the tcp frame: tool0 (= flange) times the hand-eye offset, seen from the tcp
    T_flange_cam = np.eye(4)
    T_flange_cam[:3, 3] = cam.wrist_offset_m
    T_tcp_cam = np.linalg.inv(cell.kin.tool_transform("tcp")) @ T_flange_cam
    v, u = np.mgrid[0 : intr.height, 0 : intr.width]
    d_cam = np.stack(
        [(u.ravel() - intr.cx) / intr.fx, (v.ravel() - intr.cy) / intr.fy, np.ones(u.size)], axis=1
    )  # t along these = depth along the optical axis
    d = d_cam @ T_tcp_cam[:3, :3].T
    o = T_tcp_cam[:3, 3]
    boxes = cell.robot.gripper_boxes(opening_m)
    body_bottom = max(float(hi[2]) for lo, hi in boxes if lo[0] < 0.0 < hi[0])  # the gripper body spans x = 0
    tips = max(float(hi[2]) for _, hi in boxes)
    half_x = max(0.0, opening_m / 2.0 - X_MARGIN_M)
    lo = np.array([-half_x, Y_RANGE_M[0], body_bottom + BODY_MARGIN_M])
    hi = np.array([half_x, Y_RANGE_M[1], tips + SPACE_BELOW_TIPS_M])
    t_in, t_out = _slab(o, d, lo, hi)
    t_grip = np.full(len(d), np.inf)
    for b_lo, b_hi in boxes:
        a, b = _slab(o, d, np.asarray(b_lo), np.asarray(b_hi))
        t_grip = np.where(b > np.maximum(a, 0.0), np.minimum(t_grip, np.maximum(a, 0.0)), t_grip)
    limit = np.minimum(t_out, t_grip)
    ok = limit - np.maximum(t_in, 0.0) >= MIN_RAY_SPAN_M
    out = (np.flatnonzero(ok), limit[ok])
    _geometry[key] = out
    return out


def _slab(o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit parameters (n,) of rays o + t d (d (n, 3)) through the box [lo, hi] (exit < entry: missed)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1, t2 = (lo - o) * inv, (hi - o) * inv
    t1 = np.where(np.isnan(t1), -np.inf, t1)
    t2 = np.where(np.isnan(t2), np.inf, t2)
    return np.minimum(t1, t2).max(axis=1), np.maximum(t1, t2).min(axis=1)


def _camera_share(cell: Cell, opening_m: float) -> tuple[float, int]:
    """(share of the pixels between the fingers that show something there, how many pixels were read):
    a small depth frame from the wrist camera's real pose through the camera's sensor model."""
    world, cam = cell.world, cell.settings.camera
    with stage("perception.jam_check"):
        idx, limit = _view_geometry(cell, opening_m)
        if len(idx) < MIN_PIXELS:
            return 0.0, len(idx)
        if cam.latency_s > 0.0:  # wait for a frame taken at rest here: frames arrive that late
            world.step(round(cam.latency_s / world.dt))
        intr = _small_intrinsics(cell)
        frame = world.render(
            true_camera_pose(cam, world.seed, world.link_matrix("tool0")), intr, near_m=cam.near_m, far_m=cam.far_m
        )
        # noise of its own stream, by the physics step it is taken at: the captures' noise stays as it was, and
        # a reset world sees what a new one does
        rng = np.random.default_rng([int(world.seed), 0x1A3, round(world.sim_time / world.dt)])
        frame = apply_sensor_noise(frame, cam.noise, rng, rgb_noise=False)
        depth = frame.depth_m.reshape(-1)[idx]
        filled = (depth <= 0.0) | (depth < limit - DEPTH_TOLERANCE_M)
        return float(np.count_nonzero(filled)) / len(idx), len(idx)
