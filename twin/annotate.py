"""Pictures for people: a rendered view framed on what matters, names written at the 3-D points they
belong to, circles on the table (a drop zone), a caption banner. Used by `twin scene --snapshot` and the
`--record` video; pure image work on RGB arrays (OpenCV), nothing here touches the simulation."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from twin.camera import OVERVIEW_EYE, OVERVIEW_TARGET, Intrinsics, look_at
from twin.types import Landmark

__all__ = ["banner", "cell_points", "draw_circle_on_table", "draw_label", "framed_overview", "project"]

_MARGIN = 1.0  # the framed points' bounding sphere fills the view up to this factor
_FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX


def cell_points(view: Any) -> np.ndarray:
    """(N, 3) points a picture of the cell frames: every body's origin but the table's (fixtures and
    objects: the table is larger than what happens on it) and every robot link's (a `World` or its
    `WorldView`)."""
    bodies = [view.object_pose(i)[0] for name, i in view.body_ids().items() if name not in ("robot", "table")]
    links = [view.link_matrix(name)[:3, 3] for name in view.link_indices()]
    return np.array([*bodies, *links, np.zeros(3)])


def framed_overview(points: Sequence[Sequence[float]] | np.ndarray, intr: Intrinsics) -> np.ndarray:
    """The overview camera's pose (looking from the usual side and height, OVERVIEW_EYE - OVERVIEW_TARGET)
    moved so that the bounding sphere of `points` (base frame: the robot, fixtures, objects) just fits
    the narrower of the view's two angles."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = (lo + hi) / 2.0
    radius = max(float(np.max(np.linalg.norm(p - centre, axis=1))), 0.2)
    half = min(np.arctan2(intr.width / 2.0, intr.fx), np.arctan2(intr.height / 2.0, intr.fy))
    direction = OVERVIEW_EYE - OVERVIEW_TARGET
    direction = direction / np.linalg.norm(direction)
    return look_at(centre + direction * (_MARGIN * radius / np.sin(half)), centre)


def project(
    T_world_camera: np.ndarray, intr: Intrinsics, point: Sequence[float] | np.ndarray
) -> tuple[int, int] | None:
    """Pixel (u, v) of a base-frame point in an OpenCV camera at `T_world_camera`; None behind it."""
    p = np.linalg.inv(T_world_camera) @ np.append(np.asarray(point, dtype=float), 1.0)
    if p[2] <= 1e-6:
        return None
    return int(round(intr.fx * p[0] / p[2] + intr.cx)), int(round(intr.fy * p[1] / p[2] + intr.cy))


def _text(image: np.ndarray, text: str, org: tuple[int, int], scale: float, color: tuple[int, int, int]) -> None:
    import cv2

    thick = max(1, int(round(scale * 2)))
    for dx, dy in ((-1, -1), (1, -1), (-1, 1), (1, 1)):  # a dark rim (same strokes, shifted): legible anywhere
        cv2.putText(image, text, (org[0] + dx, org[1] + dy), _FONT, scale, (0, 0, 0), thick, cv2.LINE_AA)
    cv2.putText(image, text, org, _FONT, scale, color, thick, cv2.LINE_AA)


def draw_label(
    image: np.ndarray,
    T_world_camera: np.ndarray,
    intr: Intrinsics,
    point: Sequence[float] | np.ndarray,
    text: str,
    *,
    scale: float = 0.4,
    color: tuple[int, int, int] = (255, 255, 255),
) -> bool:
    """Write `text` beside the pixel of a 3-D point (a dot marks the point); False when it is out of view."""
    import cv2

    uv = project(T_world_camera, intr, point)
    h, w = image.shape[:2]
    if uv is None or not (0 <= uv[0] < w and 0 <= uv[1] < h):
        return False
    cv2.circle(image, uv, 2, color, -1, cv2.LINE_AA)
    _text(image, text, (min(uv[0] + 4, w - 8), max(uv[1] - 4, 10)), scale, color)
    return True


def draw_circle_on_table(
    image: np.ndarray,
    T_world_camera: np.ndarray,
    intr: Intrinsics,
    landmark: Landmark,
    *,
    color: tuple[int, int, int] = (255, 255, 255),
    scale: float = 0.4,
) -> None:
    """The landmark's circle (horizontal, at its height) as the camera sees it, with its name."""
    import cv2

    c = np.asarray(landmark.position, dtype=float)
    angles = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    ring = c + landmark.radius_m * np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    pixels = [uv for p in ring if (uv := project(T_world_camera, intr, p)) is not None]
    if len(pixels) == len(ring):
        cv2.polylines(image, [np.array(pixels, dtype=np.int32)], True, color, 1, cv2.LINE_AA)
    draw_label(image, T_world_camera, intr, c, landmark.name, scale=scale, color=color)


def banner(image: np.ndarray, text: str, *, height: int = 26, scale: float = 0.5) -> np.ndarray:
    """`image` with a dark strip above it carrying `text` (a panel's title or a video frame's caption)."""
    strip = np.full((height, image.shape[1], 3), 32, dtype=np.uint8)
    _text(strip, text, (8, int(height * 0.7)), scale, (255, 255, 255))
    return np.concatenate([strip, image], axis=0)
