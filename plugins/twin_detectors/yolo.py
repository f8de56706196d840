"""The `yolo` detector: a YOLOv8 model trained on twin's labelled renders (`bench/train_detector.py`), run
from its ONNX export by onnxruntime (issue 42), as seed 002's pipeline starts: boxes and classes from the
colour image, then the object's depth region in each box for pose estimation.

Per frame: letterbox the colour image to the model's square input (scale to fit, pad grey), run the model,
keep the boxes whose best class score reaches `confidence` (seed 002 took only detections over its
confidence threshold), non-maximum suppression per class (`iou`), boxes back to image pixels. The mask
handed on (`Detection.pixels`) is the box's depth region: its pixels whose point stands above the table,
and of those the largest 4-connected region, so a neighbour reaching into the box is left out. The
existing PCA + ICP path estimates the pose from it, as it does for every detector.

The model and its class names: `model` (an ONNX file), by default the one shipped beside this module
(`models/yolov8n_twin.onnx`, with its card `models/yolov8n_twin.json`); the names are read from the file's
metadata (ultralytics writes them there) or its card. ultralytics (AGPL-3.0) trains it; it is not needed,
or imported, here.
"""

from __future__ import annotations

import ast
import json
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import onnxruntime as ort
from pydantic import BaseModel, ConfigDict, Field

from twin.plugin import ConfigError, Detection, RGBDFrame, SceneCloud, scene_cloud

__all__ = ["SHIPPED_MODEL", "YoloDetector", "decode", "letterbox"]

SHIPPED_MODEL = Path(__file__).resolve().parent / "models" / "yolov8n_twin.onnx"
_PAD = 114  # ultralytics' letterbox grey


def letterbox(rgb: np.ndarray, size: int) -> tuple[np.ndarray, float, tuple[int, int]]:
    """The image scaled to fit a size x size square and padded grey around the centre: (NCHW float32 in
    [0, 1], the scale, the (left, top) padding in pixels)."""
    h, w = rgb.shape[:2]
    scale = min(size / h, size / w)
    nh, nw = round(h * scale), round(w * scale)
    top, left = (size - nh) // 2, (size - nw) // 2
    canvas = np.full((size, size, 3), _PAD, np.uint8)
    canvas[top : top + nh, left : left + nw] = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(canvas.transpose(2, 0, 1)[None], dtype=np.float32) / 255.0, scale, (left, top)


def decode(
    out: np.ndarray, scale: float, pad: tuple[int, int], shape: tuple[int, int], confidence: float, iou: float
) -> list[tuple[int, float, tuple[int, int, int, int]]]:
    """YOLOv8's output (1, 4 + classes, anchors) as [(class, score, (u0, v0, u1, v1) inclusive px)] in the
    original image (`shape` = (h, w)), over `confidence`, after non-maximum suppression per class."""
    pred = out[0].T  # (anchors, 4 + classes): cx, cy, w, h in the letterboxed square, then class scores
    scores = pred[:, 4:]
    cls = scores.argmax(axis=1)
    best = scores[np.arange(len(cls)), cls]
    keep = best >= confidence
    if not keep.any():
        return []
    pred, cls, best = pred[keep], cls[keep], best[keep]
    xywh = pred[:, :4].astype(float)
    xywh[:, 0] = (xywh[:, 0] - xywh[:, 2] / 2 - pad[0]) / scale
    xywh[:, 1] = (xywh[:, 1] - xywh[:, 3] / 2 - pad[1]) / scale
    xywh[:, 2:] /= scale
    chosen = cv2.dnn.NMSBoxesBatched(xywh.tolist(), best.tolist(), cls.tolist(), confidence, iou)
    h, w = shape
    found = []
    for i in np.asarray(chosen, dtype=int).reshape(-1):
        x, y, bw, bh = xywh[i]
        u0, v0 = int(np.clip(np.floor(x), 0, w - 1)), int(np.clip(np.floor(y), 0, h - 1))
        u1, v1 = int(np.clip(np.ceil(x + bw) - 1, 0, w - 1)), int(np.clip(np.ceil(y + bh) - 1, 0, h - 1))
        if u1 >= u0 and v1 >= v0:
            found.append((int(cls[i]), float(best[i]), (u0, v0, u1, v1)))
    return found


def _names(session: Any, model: Path) -> list[str]:
    """Class names by index: the ONNX file's metadata (ultralytics' `names`), else its card's."""
    meta = session.get_modelmeta().custom_metadata_map
    if "names" in meta:
        names = ast.literal_eval(meta["names"])
        return [names[i] for i in sorted(names)]
    card = model.with_suffix(".json")
    if card.is_file():
        names = json.loads(card.read_text())["names"]
        return [names[str(i)] if isinstance(names, dict) else names[i] for i in range(len(names))]
    raise ConfigError(f"{model} names no classes (no 'names' metadata and no card {card.name} beside it)")


class YoloDetector:
    """YOLOv8 on the colour image (ONNX, onnxruntime), then each box's depth region (module docstring)."""

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")

        model: str | None = Field(None, description="ONNX file; None: the model shipped with twin_detectors")
        confidence: float = Field(0.5, gt=0, lt=1, description="keep boxes whose class score reaches this")
        iou: float = Field(0.5, gt=0, lt=1, description="non-maximum suppression overlap, per class")
        threads: int = Field(2, ge=1, le=64, description="onnxruntime intra-op threads")
        min_pixels: int = Field(20, ge=1, description="a box whose depth region is smaller is dropped")

    def __init__(self, params: YoloDetector.Params | None, context: Any) -> None:
        self.params = params if params is not None else self.Params()
        self.settings = context.settings
        model = Path(self.params.model) if self.params.model else SHIPPED_MODEL
        if not model.is_file():
            hint = "train one: python bench/train_detector.py --ship" if self.params.model is None else ""
            raise ConfigError(f"yolo: no model at {model} {hint}".strip())
        options = ort.SessionOptions()
        options.intra_op_num_threads = self.params.threads
        options.inter_op_num_threads = 1
        # no busy-waiting between runs: a spinning pool holds the cores that physics, rendering and any other
        # session in the process need (two sessions in one process: 21 -> 41 ms a frame on 2 cores)
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        self.session = ort.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
        self.input = self.session.get_inputs()[0]
        self.size = int(self.input.shape[2])
        self.names = _names(self.session, model)
        self.last_timings_s: dict[str, float] = {}

    def detect(
        self,
        frame: RGBDFrame,
        T_base_camera: np.ndarray,
        *,
        cloud: SceneCloud | None = None,
        ground_truth: Any = None,
    ) -> list[Detection]:
        """Boxes and classes from the colour image, each with its depth region as the mask."""
        t0 = time.perf_counter()
        x, scale, pad = letterbox(frame.rgb, self.size)
        out = self.session.run(None, {self.input.name: x})[0]
        boxes = decode(out, scale, pad, frame.rgb.shape[:2], self.params.confidence, self.params.iou)
        t1 = time.perf_counter()
        cloud = cloud if cloud is not None else scene_cloud(frame, T_base_camera, self.settings.perception.robocup)
        W = frame.depth_m.shape[1]
        above = np.divmod(cloud.pixels[cloud.height > cloud.table_threshold_m], W)  # (rows, cols), once a frame
        found = []
        for k, score, (u0, v0, u1, v1) in boxes:
            pixels = _depth_region(above, W, (u0, v0, u1, v1))
            if pixels.size < self.params.min_pixels:
                continue
            label = self.names[k]
            cls, _, color = label.partition("_") if label.startswith("cube_") else (label, "", "")
            found.append(Detection(cls, color or None, score, pixels, (u0, v0, u1, v1), {"label": label}))
        self.last_timings_s = {"yolo": t1 - t0, "depth_region": time.perf_counter() - t1}
        return found


def _depth_region(above: tuple[np.ndarray, np.ndarray], width: int, box: tuple[int, int, int, int]) -> np.ndarray:
    """Flat indices of the largest 4-connected region of the above-table pixels (their rows, cols) in the box."""
    u0, v0, u1, v1 = box
    rows, cols = above
    inside = (rows >= v0) & (rows <= v1) & (cols >= u0) & (cols <= u1)
    if not inside.any():
        return np.zeros(0, dtype=np.int64)
    crop = np.zeros((v1 - v0 + 1, u1 - u0 + 1), np.uint8)
    crop[rows[inside] - v0, cols[inside] - u0] = 1
    n, labels, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=4)
    if n <= 1:
        return np.zeros(0, dtype=np.int64)
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    r, c = np.nonzero(labels == biggest)
    return np.sort((r + v0) * width + (c + u0)).astype(np.int64)
