"""Camera-to-base calibration from the ArUco marker on the robot base (seed 000).

The marker is found with OpenCV's `ArucoDetector` (sub-pixel corner refinement) and its pose in the
camera frame comes from `solvePnP(SOLVEPNP_IPPE_SQUARE)` on the four corners. The marker's pose in the
base frame is known from the cell layout (`scene_layout.marker_pose_in_base`: it is part of the robot's
mounting, not a measurement), so T_base_camera = T_base_marker @ inv(T_camera_marker).

Measured here: at the warehouse camera (~1.2 m, seen at ~27 deg elevation) the marker spans ~50 x 22 px
and the rendered, filtered texture pulls the sub-pixel corners ~0.8 px inwards, so four-corner PnP is
~3 cm / 0.6 deg off (range and tilt). Two refinements, both configurable (`aruco.method`,
`aruco.refine_grid`):
- the marker's plane from the depth image ("pnp+plane", default): the table plane, fitted to tens of
  thousands of depth points and lifted by the marker's height above the table, fixes tilt and range;
  the corners' pixel rays cut with that plane fix the in-plane position and the rotation about the
  normal (~1 mm / 0.05 deg at the warehouse camera);
- the marker's interior grid corners: the known bit pattern says where the grid has corners, the first
  pose predicts them, `cornerSubPix` measures them and `solvePnPRefineLM` fits all of them (~19 points
  instead of 4) - used when the cells are at least 5 px, as from the wrist camera's calibration view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from twin.camera import Intrinsics, RGBDFrame, point_cloud
from twin.config import ArucoSettings, Settings
from twin.errors import TwinError
from twin.scene_layout import marker_pose_in_base
from twin.timing import stage

__all__ = ["Calibration", "MarkerNotFound", "MarkerPose", "calibrate", "detect_marker", "transform_error"]

log = logging.getLogger("twin")


class MarkerNotFound(TwinError):
    """The base marker is not visible in the frame (or another id/dictionary was configured)."""


@dataclass(frozen=True)
class MarkerPose:
    """The marker seen in one image: corners (4, 2) px (TL, TR, BR, BL), pose (4, 4) in the camera frame."""

    marker_id: int
    corners_px: np.ndarray
    T_camera_marker: np.ndarray
    reprojection_px: float
    n_points: int


@dataclass(frozen=True)
class Calibration:
    """The estimated camera pose in the base frame (4, 4) and the marker observation it came from."""

    T_base_camera: np.ndarray
    marker: MarkerPose
    method: str


def _dictionary(a: ArucoSettings) -> cv2.aruco.Dictionary:
    dict_id = getattr(cv2.aruco, a.dictionary, None)
    if not isinstance(dict_id, int) or not a.dictionary.startswith("DICT_"):
        raise MarkerNotFound(f"aruco.dictionary {a.dictionary!r} is not a cv2.aruco dictionary (e.g. DICT_4X4_50)")
    return cv2.aruco.getPredefinedDictionary(dict_id)


def _to_matrix(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = np.asarray(tvec, dtype=float).reshape(3)
    return T


def _grid_corners(dictionary: cv2.aruco.Dictionary, marker_id: int, size_m: float) -> np.ndarray:
    """(n, 3) interior corners of the marker's cell grid (marker frame) where the pattern has a corner.

    The marker is (bits + 2) cells wide including its black border. A grid vertex is a usable corner when
    its four cells are not all one colour and do not form two straight halves (an edge, not a corner):
    exactly one or three white cells, or a checkerboard pair.
    """
    bits = dictionary.markerSize
    cells = bits + 2
    img = (cv2.aruco.generateImageMarker(dictionary, marker_id, cells, borderBits=1) > 127).astype(np.uint8)
    cell = size_m / cells
    pts = []
    for r in range(1, cells):
        for c in range(1, cells):
            quad = img[r - 1 : r + 1, c - 1 : c + 1]
            white = int(quad.sum())
            checker = white == 2 and quad[0, 0] == quad[1, 1]
            if white in (1, 3) or checker:
                # image row r runs downwards; the marker frame's y points to the image top
                pts.append((-size_m / 2 + c * cell, size_m / 2 - r * cell, 0.0))
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def detect_marker(rgb: np.ndarray, intrinsics: Intrinsics, aruco: ArucoSettings, *, refine: bool = True) -> MarkerPose:
    """Find marker `aruco.id` in an RGB image and estimate its pose by PnP; MarkerNotFound when not seen."""
    return _detect(rgb, intrinsics, aruco, refine=refine)[0]


def _detect(
    rgb: np.ndarray, intrinsics: Intrinsics, aruco: ArucoSettings, *, refine: bool
) -> tuple[MarkerPose, np.ndarray, np.ndarray]:
    """The PnP marker pose plus the object/image point pairs it used."""
    dictionary = _dictionary(aruco)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    gray = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY)
    corners, ids, _ = cv2.aruco.ArucoDetector(dictionary, params).detectMarkers(gray)
    if ids is None or aruco.id not in ids.ravel().tolist():
        seen = [] if ids is None else sorted(ids.ravel().tolist())
        raise MarkerNotFound(f"ArUco marker {aruco.id} ({aruco.dictionary}) not found in the image (ids seen: {seen})")
    k = ids.ravel().tolist().index(aruco.id)
    img_pts = corners[k].reshape(4, 2).astype(np.float64)
    s = aruco.size_m / 2.0
    obj_pts = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])
    K = intrinsics.matrix()
    dist = np.zeros(5)
    ok, rvec, tvec = cv2.solvePnP(obj_pts, img_pts, K, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    if not ok:
        raise MarkerNotFound(f"solvePnP failed on ArUco marker {aruco.id}")
    all_obj, all_img = obj_pts, img_pts
    if refine:
        grid = _grid_corners(dictionary, aruco.id, aruco.size_m)
        if len(grid):
            guess, _ = cv2.projectPoints(grid, rvec, tvec, K, dist)
            guess = guess.reshape(-1, 2).astype(np.float32)
            sides = np.linalg.norm(img_pts - np.roll(img_pts, 1, axis=0), axis=1)
            cell_px = float(sides.min()) / (dictionary.markerSize + 2)
            win = int(max(2, min(8, round(cell_px * 0.4))))
            inside = (guess[:, 0] > win + 1) & (guess[:, 1] > win + 1)
            inside &= (guess[:, 0] < gray.shape[1] - win - 2) & (guess[:, 1] < gray.shape[0] - win - 2)
            if inside.sum() >= 4 and cell_px >= 5.0:
                crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
                meas = cv2.cornerSubPix(gray, guess[inside].copy().reshape(-1, 1, 2), (win, win), (-1, -1), crit)
                meas = meas.reshape(-1, 2).astype(np.float64)
                moved = np.linalg.norm(meas - guess[inside], axis=1)
                good = moved < max(1.5, 0.35 * cell_px)  # a corner that ran away locked onto something else
                all_obj = np.vstack([obj_pts, grid[inside][good]])
                all_img = np.vstack([img_pts, meas[good]])
                rvec, tvec = cv2.solvePnPRefineLM(all_obj, all_img, K, dist, rvec, tvec)
    proj, _ = cv2.projectPoints(all_obj, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - all_img) ** 2, axis=1))))
    return MarkerPose(aruco.id, img_pts, _to_matrix(rvec, tvec), rms, len(all_obj)), all_obj, all_img


def _plane_constrained_pose(
    marker: MarkerPose, obj_pts: np.ndarray, img_pts: np.ndarray, frame: RGBDFrame, height_m: float
) -> np.ndarray | None:
    """T_camera_marker with the marker's plane from the depth image, position and yaw from the corners.

    The table plane is fitted to the whole depth image (RANSAC, then least squares over its inliers);
    the marker plane is that plane lifted by `height_m` (the marker's height above the table top, from
    the cell layout). Each corner's pixel ray is cut with the marker plane and a 2D rigid fit of the
    nominal corners onto those points gives the in-plane position and the rotation about the normal.
    Returns None when the dominant plane does not hold the marker (then PnP alone is used).
    """
    from twin.perception.cloud_geometry import fit_plane_ransac  # lazy: scipy

    pts, _ = point_cloud(frame, stride=2)
    if len(pts) < 500:
        return None
    plane = fit_plane_ransac(pts, 0.01, iterations=300, rng=np.random.default_rng(0))
    plane = plane.oriented(np.zeros(3))  # normal towards the camera
    centre = marker.T_camera_marker[:3, 3]
    if abs(plane.distance(centre[None])[0] - height_m) > 0.03 or plane.inliers.sum() < 0.1 * len(pts):
        return None
    n = plane.normal
    d = plane.offset + height_m
    K_inv = np.linalg.inv(frame.intrinsics.matrix())
    rays = (K_inv @ np.c_[img_pts, np.ones(len(img_pts))].T).T
    P = rays * (d / (rays @ n))[:, None]  # ray-plane intersections, camera frame
    # in-plane basis: e1 from the PnP marker x axis projected onto the plane
    e1 = marker.T_camera_marker[:3, 0] - n * (marker.T_camera_marker[:3, 0] @ n)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    p2 = np.c_[P @ e1, P @ e2]
    q2 = obj_pts[:, :2]
    pc, qc = p2.mean(axis=0), q2.mean(axis=0)
    H = (q2 - qc).T @ (p2 - pc)
    theta = np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
    c, s = np.cos(theta), np.sin(theta)
    R2 = np.array([[c, -s], [s, c]])
    t2 = pc - R2 @ qc
    T = np.eye(4)
    T[:3, 0] = c * e1 + s * e2
    T[:3, 1] = -s * e1 + c * e2
    T[:3, 2] = n
    T[:3, 3] = t2[0] * e1 + t2[1] * e2 + d * n
    return T


def calibrate(
    frame: RGBDFrame,
    settings: Settings,
    *,
    method: Literal["pnp+plane", "pnp"] | None = None,
    refine: bool | None = None,
) -> Calibration:
    """T_base_camera from the base marker: T_base_marker (cell layout) @ inv(T_camera_marker).

    `method` (None: `aruco.method`): "pnp" is the seed's solvePnP(IPPE_SQUARE) on the corners (plus the
    grid refinement when `refine`, None: `aruco.refine_grid`); "pnp+plane" takes the marker's plane from
    the depth image instead, which removes the tilt and range errors of a small, far, obliquely seen
    marker (see `_plane_constrained_pose`), and falls back to "pnp" when the plane does not fit.
    MarkerNotFound when the marker is not visible.
    """
    with stage("perception.calibration"):
        return _calibrate(frame, settings, method=method, refine=refine)


def _calibrate(frame: RGBDFrame, settings: Settings, *, method: str | None, refine: bool | None) -> Calibration:
    method = settings.aruco.method if method is None else method
    refine = settings.aruco.refine_grid if refine is None else refine
    marker, obj_pts, img_pts = _detect(frame.rgb, frame.intrinsics, settings.aruco, refine=refine)
    T_base_marker = marker_pose_in_base(settings)
    used = "pnp"
    T_cm = marker.T_camera_marker
    if method == "pnp+plane" and abs(T_base_marker[2, 2]) > 1.0 - 1e-6:  # the marker lies level, like the table
        T_plane = _plane_constrained_pose(marker, obj_pts, img_pts, frame, float(T_base_marker[2, 3]))
        if T_plane is not None:
            T_cm, used = T_plane, "pnp+plane"
        else:
            log.warning("ArUco calibration: no table plane under the marker in the depth image, using PnP alone")
    T_base_camera = T_base_marker @ np.linalg.inv(T_cm)
    log.debug("ArUco calibration (%s): %d points, reprojection %.3f px", used, marker.n_points, marker.reprojection_px)
    return Calibration(T_base_camera, marker, used)


def transform_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(translation error m, rotation error deg) between two poses of the same frame."""
    dt = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    R = T_est[:3, :3].T @ T_true[:3, :3]
    ang = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return dt, ang
