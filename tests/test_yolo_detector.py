"""The `yolo` detector (issue 42, `twin_detectors.yolo`): letterboxing and decoding YOLOv8's output back to
image pixels, and a clear error without a model. Runs without a trained model; the shipped model's own test
is `test_the_shipped_model_finds_every_object_of_an_unseen_seed` (skipped while none is shipped)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("onnxruntime", reason="the yolo detector needs onnxruntime (extra `detect`, setup.sh installs it)")

from twin.errors import ConfigError
from twin.planning import make_context
from twin_detectors.yolo import SHIPPED_MODEL, _depth_region, decode, letterbox


def _raw(boxes: list[tuple[float, float, float, float, int, float]], classes: int = 3, anchors: int = 50) -> np.ndarray:
    """A YOLOv8 output (1, 4 + classes, anchors): the given (cx, cy, w, h, class, score) first, noise after."""
    out = np.zeros((1, 4 + classes, anchors), np.float32)
    out[0, 4:, :] = 0.01
    for i, (cx, cy, w, h, c, s) in enumerate(boxes):
        out[0, :4, i] = (cx, cy, w, h)
        out[0, 4 + c, i] = s
    return out


def test_letterbox_scales_to_fit_and_pads_around_the_centre() -> None:
    rgb = np.zeros((480, 640, 3), np.uint8)
    rgb[:, :, 0] = 255
    x, scale, (left, top) = letterbox(rgb, 320)
    assert x.shape == (1, 3, 320, 320) and x.dtype == np.float32
    assert scale == pytest.approx(0.5) and (left, top) == (0, 40)
    assert x[0, 0, 40:280].min() == pytest.approx(1.0) and x[0, 0, :40].max() == pytest.approx(114 / 255)


def test_decode_maps_boxes_back_to_the_image_and_suppresses_duplicates() -> None:
    """A box in the letterboxed square comes back where it was in the 640x480 image; a second, overlapping
    box of the same class is suppressed, one of another class is kept; scores under the threshold vanish."""
    scale, pad = 0.5, (0, 40)
    # the object at image pixels u 100..199, v 200..279 -> square cx 75, cy 40 + 120 = 160, w 50, h 40
    out = _raw(
        [(75, 160, 50, 40, 1, 0.9), (76, 161, 50, 40, 1, 0.8), (75, 160, 50, 40, 2, 0.7), (200, 200, 20, 20, 0, 0.3)]
    )
    found = decode(out, scale, pad, (480, 640), confidence=0.5, iou=0.5)
    assert sorted((c, round(s, 2)) for c, s, _ in found) == [(1, 0.9), (2, 0.7)]
    box = next(b for c, _, b in found if c == 1)
    assert box == (100, 200, 199, 279)
    assert decode(out, scale, pad, (480, 640), confidence=0.95, iou=0.5) == []


def test_the_depth_region_keeps_the_largest_connected_part_of_the_box() -> None:
    """Above-table pixels in a box: the object (a 10x10 block) and a neighbour's corner reaching in (3x3,
    not touching it): the mask is the block alone; pixels outside the box never count."""
    W = 100
    block = [(r, c) for r in range(20, 30) for c in range(20, 30)]
    corner = [(r, c) for r in range(35, 38) for c in range(35, 38)]
    outside = [(r, c) for r in range(60, 70) for c in range(60, 70)]
    above = np.array(sorted(r * W + c for r, c in block + corner + outside))
    got = _depth_region(np.divmod(above, W), W, (15, 15, 37, 37))
    assert sorted(got.tolist()) == sorted(r * W + c for r, c in block)


def test_without_a_model_the_detector_says_how_to_get_one(tmp_path: object) -> None:
    from twin.config import load_config

    ctx = make_context(load_config("configs/robocup.yaml"))
    with pytest.raises(ConfigError, match="no model at"):
        ctx.registry.detector("yolo", {"model": "/nonexistent/model.onnx"}, ctx)
    if not SHIPPED_MODEL.is_file():
        with pytest.raises(ConfigError, match=r"train_detector\.py"):
            ctx.registry.detector("yolo", {}, ctx)


@pytest.mark.skipif(not SHIPPED_MODEL.is_file(), reason="no model shipped yet (bench/train_detector.py --ship)")
@pytest.mark.parametrize(
    ("seed", "items"),
    [
        (770001, None),  # the config's eight objects, as a run starts
        (770004, "[{class: marker}, {class: can}]"),  # two left, as a run ends: the marker alone was missed once
    ],
)
def test_the_shipped_model_finds_every_object_of_an_unseen_seed(seed: int, items: str | None) -> None:
    """The shipped model on the captured frame of a realistic scene no dataset made by default trains on
    (training seeds count up from 0): every object mostly in view (>= 0.5 visible) is found once, with the
    right class, its box overlapping the true one (IoU >= 0.5); nothing is found where no object is."""
    from twin.camera import Intrinsics, true_camera_pose
    from twin.config import load_config
    from twin.dataset import visible_boxes
    from twin.perception.capture import capture_frame
    from twin.world import World

    overrides = ["world.visuals=realistic"] + ([f"world.objects.items={items}"] if items else [])
    settings = load_config("configs/robocup.yaml", overrides)
    ctx = make_context(settings)
    detector = ctx.registry.detector("yolo", {}, ctx)
    cam = settings.camera
    with World(settings, seed=seed, robot=ctx.robot) as world:
        cap = capture_frame(world, settings)
        T = true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
        intr = Intrinsics.from_settings(cam)
        _, ids = world.render_labelled(T, intr, near_m=cam.near_m, far_m=cam.far_m)
        assert ids is not None
        seen, _ = visible_boxes(world, ids, T, intr, settings, 0.01)  # every object that shows at all
    truth = [t for t in seen if t["visible"] >= 0.5]
    found = detector.detect(cap.frame, cap.T_base_camera_nominal)

    def iou(a: list[int] | tuple[int, ...], b: list[int] | tuple[int, ...]) -> float:
        w = min(a[2], b[2]) - max(a[0], b[0])
        h = min(a[3], b[3]) - max(a[1], b[1])
        inter = max(0, w) * max(0, h)
        return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)

    assert len(truth) >= (6 if items is None else 2)
    for t in truth:
        hits = [d for d in found if iou(t["box"], (d.bbox[0], d.bbox[1], d.bbox[2] + 1, d.bbox[3] + 1)) >= 0.5]
        assert [d.label for d in hits] == [t["class"]], (t, [(d.label, d.bbox) for d in hits])
    for d in found:  # no detection where no object shows (one under half visible may be found)
        box = (d.bbox[0], d.bbox[1], d.bbox[2] + 1, d.bbox[3] + 1)
        assert any(iou(t["box"], box) >= 0.3 for t in seen), (d.label, d.bbox)
