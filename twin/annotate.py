"""Pictures for people: a rendered view framed on what matters, names written at the 3-D points they
belong to, circles on the table (a drop zone), a caption banner. Used by `twin scene --snapshot` and the
`--record` video; pure image work on RGB arrays (OpenCV), nothing here touches the simulation.

Many names in a small picture collide (a cube's name written over its neighbour's), so `draw_labels`
places them together: greedily, in screen space, each beside its point where no earlier one is, else a
line further up or down with a leader line back to its point (`place_labels`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.camera import OVERVIEW_EYE, OVERVIEW_TARGET, Intrinsics, look_at
from twin.types import Landmark

__all__ = [
    "Label",
    "banner",
    "cell_points",
    "draw_circle_on_table",
    "draw_label",
    "draw_labels",
    "framed_overview",
    "place_labels",
    "project",
]

_MARGIN = 1.0  # the framed points' bounding sphere fills the view up to this factor
_FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX
_GAP_PX = 2  # the least space between two placed labels
_NUDGE_PX = 4  # a label's corner sits this far right of and above (or below) its point
_STEPS = 8  # a label that fits nowhere beside its point is tried up to this many lines up and down

Box = tuple[int, int, int, int]  # x0, y0, x1, y1 in pixels, x1 and y1 exclusive


@dataclass(frozen=True)
class Label:
    """A name written into a picture: its text, the pixel of its 3-D point (`anchor`, u, v) and the box its
    text covers (its dark rim included)."""

    text: str
    anchor: tuple[int, int]
    box: Box


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


def _overlap(a: Box, b: Box, gap: int = 0) -> int:
    """The area two boxes share once each is grown by `gap` on every side (0: apart)."""
    w = min(a[2], b[2]) - max(a[0], b[0]) + 2 * gap
    h = min(a[3], b[3]) - max(a[1], b[1]) + 2 * gap
    return max(w, 0) * max(h, 0)


def _candidates(anchor: tuple[int, int], size: tuple[int, int]) -> list[Box]:
    """Where a label of `size` (w, h) may go, nearest first: right-above its point, right-below, left-above,
    left-below, then those a line further up and down, ... (`_STEPS` lines)."""
    u, v = anchor
    w, h = size
    right, left = u + _NUDGE_PX, u - _NUDGE_PX - w
    above, below = v - _NUDGE_PX - h, v + _NUDGE_PX
    out = []
    for k in range(_STEPS + 1):
        dy = k * (h + _GAP_PX)
        for x in (right, left):
            out += [(x, above - dy, x + w, above - dy + h), (x, below + dy, x + w, below + dy + h)]
    return out


def place_labels(
    anchors: Sequence[tuple[int, int]], sizes: Sequence[tuple[int, int]], shape: tuple[int, int]
) -> list[Box]:
    """Boxes for labels of `sizes` (w, h) beside their `anchors` (u, v) in an image of `shape` (h, w):
    greedily, top to bottom, each at its first candidate (`_candidates`) inside the image that keeps
    `_GAP_PX` from every label placed before it and off every anchor's dot; where none does, the one that
    overlaps least. Returned in the order given."""
    height, width = shape
    dots = [(u - 3, v - 3, u + 4, v + 4) for u, v in anchors]
    placed: list[Box] = []
    out: dict[int, Box] = {}
    for i in sorted(range(len(anchors)), key=lambda i: (anchors[i][1], anchors[i][0])):
        best: tuple[int, Box] | None = None
        for box in _candidates(anchors[i], sizes[i]):
            if box[0] < 0 or box[1] < 0 or box[2] > width or box[3] > height:
                continue
            cost = sum(_overlap(box, b, _GAP_PX) for b in placed) + sum(_overlap(box, d) for d in dots)
            if best is None or cost < best[0]:
                best = (cost, box)
            if cost == 0:
                break
        if best is None:  # larger than the image allows beside its point: clamp the first candidate into it
            x0, y0, x1, y1 = _candidates(anchors[i], sizes[i])[0]
            dx = max(0, -x0) - max(0, x1 - width)
            dy = max(0, -y0) - max(0, y1 - height)
            best = (0, (x0 + dx, y0 + dy, x1 + dx, y1 + dy))
        out[i] = best[1]
        placed.append(best[1])
    return [out[i] for i in range(len(anchors))]


def _text_size(text: str, scale: float) -> tuple[tuple[int, int], int]:
    """((w, h), baseline) of `text` as `_text` writes it, its one-pixel rim included."""
    import cv2

    (w, h), base = cv2.getTextSize(text, _FONT, scale, max(1, int(round(scale * 2))))
    return (w + 2, h + base + 2), base


def draw_labels(
    image: np.ndarray,
    T_world_camera: np.ndarray,
    intr: Intrinsics,
    items: Sequence[tuple[Sequence[float] | np.ndarray, str, tuple[int, int, int]]],
    *,
    scale: float = 0.4,
) -> list[Label]:
    """Write every (3-D point, text, colour) of `items` that is in view, placed so no two overlap
    (`place_labels`): a dot at each point, its text beside it, a thin line back to the dot where the text
    had to move away. Returns what was written, in the order of `items` (those out of view left out)."""
    import cv2

    h, w = image.shape[:2]
    shown = []
    for point, text, color in items:
        uv = project(T_world_camera, intr, point)
        if uv is not None and 0 <= uv[0] < w and 0 <= uv[1] < h:
            shown.append((uv, text, color))
    sizes = [_text_size(text, scale) for _, text, _ in shown]
    boxes = place_labels([uv for uv, _, _ in shown], [s for s, _ in sizes], (h, w))
    for (uv, _, color), box in zip(shown, boxes, strict=True):
        cv2.circle(image, uv, 2, color, -1, cv2.LINE_AA)
        near = (min(max(uv[0], box[0]), box[2] - 1), min(max(uv[1], box[1]), box[3] - 1))
        if abs(near[0] - uv[0]) + abs(near[1] - uv[1]) > 3 * _NUDGE_PX:  # moved off its place beside the dot
            cv2.line(image, uv, near, color, 1, cv2.LINE_AA)
    for (_, text, color), box, (_, base) in zip(shown, boxes, sizes, strict=True):
        _text(image, text, (box[0] + 1, box[3] - 1 - base), scale, color)
    return [Label(text, uv, box) for (uv, text, _), box in zip(shown, boxes, strict=True)]


def draw_circle_on_table(
    image: np.ndarray,
    T_world_camera: np.ndarray,
    intr: Intrinsics,
    landmark: Landmark,
    *,
    color: tuple[int, int, int] = (255, 255, 255),
    scale: float = 0.4,
    name: bool = True,
) -> None:
    """The landmark's circle (horizontal, at its height) as the camera sees it, with its name unless `name`
    is False (a caller that places all names together, `draw_labels`, writes it)."""
    import cv2

    c = np.asarray(landmark.position, dtype=float)
    angles = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    ring = c + landmark.radius_m * np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    pixels = [uv for p in ring if (uv := project(T_world_camera, intr, p)) is not None]
    if len(pixels) == len(ring):
        cv2.polylines(image, [np.array(pixels, dtype=np.int32)], True, color, 1, cv2.LINE_AA)
    if name:
        draw_label(image, T_world_camera, intr, c, landmark.name, scale=scale, color=color)


def banner(image: np.ndarray, text: str, *, height: int = 26, scale: float = 0.5) -> np.ndarray:
    """`image` with a dark strip above it carrying `text` (a panel's title or a video frame's caption)."""
    strip = np.full((height, image.shape[1], 3), 32, dtype=np.uint8)
    _text(strip, text, (8, int(height * 0.7)), scale, (255, 255, 255))
    return np.concatenate([strip, image], axis=0)
