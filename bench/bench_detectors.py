"""Detection measured like a vision paper (issue 42): mAP50 and mAP50-95 per class (pycocotools' COCOeval)
of every detector on held-out scene seeds, per condition, with inference time per frame. A plain script:
it prints tables, writes a few frames with boxes drawn, and asserts nothing.

    python bench/bench_detectors.py [--config configs/robocup.yaml] [--seeds 900000-900019]
                                    [--detectors geometric,oracle] [--visuals flat,realistic]
                                    [--noise 1,3] [--clutter 0] [--min-objects N]
                                    [--min-visible 0.3] [--out out/bench-detectors]

Each scene is captured as a run captures it (`twin.perception.capture.capture_frame`: the arm at the capture
pose, the settling pause, the sensor model at `camera.noise.scale` x the condition's factor, the depth filter)
and handed to the detector with the camera pose the robot's kinematics predicts. The ground truth is
`twin dataset`'s: the box of each object's visible pixels in the renderer's segmentation of the same view,
for the objects at least `--min-visible` of which shows (`twin.dataset`). A detection's score is its
confidence. `oracle` reads the simulator: the ceiling. `--clutter N` adds up to N objects per scene as the
dataset does (crowding and occlusion); `--min-objects N` keeps N..all of the config's objects per scene, as the
dataset does (the nearly empty tables a run ends on).

The default seeds lie far from the dataset's (`twin dataset --seed`, 0 upwards), so a model trained on a
dataset made with default seeds never saw them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from twin.camera import Intrinsics, true_camera_pose
from twin.config import Settings, load_config
from twin.dataset import class_names, scene_world, visible_boxes
from twin.perception.capture import capture_frame
from twin.perception.detection import scene_cloud, with_ground_truth
from twin.perception.pipeline import make_detector
from twin.planning import make_context
from twin.tasks.robocup.perception import table_color

_DRAWN = 3  # frames with boxes drawn kept per detector and condition


def _condition(settings: Settings, visuals: str, noise: float) -> Settings:
    cam = settings.camera
    scaled = cam.noise.model_copy(update={"scale": cam.noise.scale * noise})
    world = settings.world.model_copy(update={"visuals": visuals})
    return settings.model_copy(update={"world": world, "camera": cam.model_copy(update={"noise": scaled})})


def _frames(
    settings: Settings, seeds: list[int], clutter: int, min_objects: int | None, min_visible: float
) -> list[dict[str, Any]]:
    """Per seed: the captured frame, the kinematic camera pose, the ground-truth boxes and objects."""
    cam = settings.camera
    intr = Intrinsics.from_settings(cam)
    context = make_context(settings)
    out = []
    for seed in seeds:
        with scene_world(settings, seed, clutter, context.robot, min_objects=min_objects) as world:
            cap = capture_frame(world, settings)
            T = true_camera_pose(cam, seed, world.link_matrix("tool0") if cam.mount == "wrist" else None)
            _, ids = world.render_labelled(T, intr, near_m=cam.near_m, far_m=cam.far_m)
            assert ids is not None
            boxes, _ = visible_boxes(world, ids, T, intr, settings, min_visible)
            out.append({"seed": seed, "cap": cap, "boxes": boxes, "truth": world.objects()})
    return out


def _evaluate(
    settings: Settings, frames: list[dict[str, Any]], name: str, classes: list[str], draw_dir: Path | None
) -> dict[str, Any]:
    """COCOeval of one detector on the frames: mAP50, mAP50-95 overall and per class, ms per frame."""
    context = make_context(settings)
    detector = make_detector(settings, name=name, params={}, context=context)
    cid = {c: i for i, c in enumerate(classes)}
    images: list[dict[str, Any]] = []
    gts: list[dict[str, Any]] = []
    dets: list[dict[str, Any]] = []
    ms: list[float] = []
    for k, f in enumerate(frames):
        cap = f["cap"]
        h, w = cap.frame.rgb.shape[:2]
        images.append({"id": k, "width": w, "height": h, "file_name": f"s{f['seed']}"})
        for b in f["boxes"]:
            x0, y0, x1, y1 = b["box"]
            bbox = [x0, y0, x1 - x0, y1 - y0]
            gts.append({"id": len(gts) + 1, "image_id": k, "category_id": cid[b["class"]], "bbox": bbox})
            gts[-1].update(area=bbox[2] * bbox[3], iscrowd=0)
        cloud = scene_cloud(
            cap.frame,
            cap.T_base_camera_nominal,
            settings.perception.robocup,
            seed=f["seed"],
            table_rgb=table_color(settings),
        )
        fed = with_ground_truth(detector, f["truth"])
        t = time.perf_counter()
        found = fed.detect(cap.frame, cap.T_base_camera_nominal, cloud=cloud)
        ms.append(1e3 * (time.perf_counter() - t))
        for d in found:
            if d.label not in cid:
                continue
            u0, v0, u1, v1 = d.bbox
            dets.append(
                {
                    "image_id": k,
                    "category_id": cid[d.label],
                    "bbox": [float(u0), float(v0), float(u1 - u0 + 1), float(v1 - v0 + 1)],
                    "score": float(d.confidence),
                }
            )
        if draw_dir is not None and k < _DRAWN:
            _draw(draw_dir / f"{name}_s{f['seed']}.png", cap.frame.rgb, f["boxes"], found)
    gt = COCO()
    gt.dataset = {"images": images, "annotations": gts, "categories": [{"id": i, "name": c} for c, i in cid.items()]}
    with contextlib.redirect_stdout(io.StringIO()):
        gt.createIndex()
        if not dets:
            return {"map50": 0.0, "map": 0.0, "per_class": dict.fromkeys(classes, (0.0, 0.0)), "ms": ms}
        dt = gt.loadRes(dets)
        ev = COCOeval(gt, dt, "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    per_class = {}
    prec = ev.eval["precision"]  # (iou thresholds, recall, classes, areas, max dets)
    for c, i in cid.items():
        p = prec[:, :, i, 0, -1]
        p50 = prec[0, :, i, 0, -1]
        per_class[c] = (
            float(np.mean(p50[p50 > -1])) if (p50 > -1).any() else float("nan"),
            float(np.mean(p[p > -1])) if (p > -1).any() else float("nan"),
        )
    return {"map50": float(ev.stats[1]), "map": float(ev.stats[0]), "per_class": per_class, "ms": ms}


def _draw(path: Path, rgb: np.ndarray, truth: list[dict[str, Any]], found: list[Any]) -> None:
    """The frame with the ground-truth boxes (green) and the detections (red, with class and confidence)."""
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    for b in truth:
        x0, y0, x1, y1 = b["box"]
        cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), (0, 200, 0), 1)
    for d in found:
        u0, v0, u1, v1 = d.bbox
        cv2.rectangle(img, (int(u0), int(v0)), (int(u1), int(v1)), (0, 0, 255), 1)
        cv2.putText(img, f"{d.label} {d.confidence:.2f}", (int(u0), max(10, int(v0) - 3)), 0, 0.35, (0, 0, 255), 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = (int(x) for x in text.split("-"))
        return list(range(a, b + 1))
    return [int(x) for x in text.split(",")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/robocup.yaml")
    ap.add_argument("--seeds", default="900000-900019")
    ap.add_argument("--detectors", default="geometric,oracle")
    ap.add_argument("--visuals", default="flat,realistic")
    ap.add_argument("--noise", default="1,3", help="depth-noise factors (x camera.noise.scale)")
    ap.add_argument("--clutter", type=int, default=0)
    ap.add_argument("--min-objects", type=int, default=None, help="keep N..all of the config's objects per scene")
    ap.add_argument("--min-visible", type=float, default=0.3)
    ap.add_argument("--out", default="out/bench-detectors")
    args = ap.parse_args(argv)
    base = load_config(args.config)
    classes = class_names(base)
    seeds = _seeds(args.seeds)
    detectors = [d.strip() for d in args.detectors.split(",") if d.strip()]
    print(
        f"{args.config}: {len(seeds)} held-out seeds ({seeds[0]}..{seeds[-1]}), clutter {args.clutter}, "
        f"objects {'all' if args.min_objects is None else f'{args.min_objects}..all'}, "
        f"ground truth = objects at least {args.min_visible:g} visible; COCOeval bbox"
    )
    header = f"{'visuals':10} {'noise':>5} {'detector':10} {'mAP50':>6} {'mAP50-95':>8} {'ms/frame':>8}  " + " ".join(
        f"{c[:10]:>10}" for c in classes
    )
    rows = []
    for visuals in args.visuals.split(","):
        for noise in (float(x) for x in args.noise.split(",")):
            settings = _condition(base, visuals, noise)
            t = time.perf_counter()
            frames = _frames(settings, seeds, args.clutter, args.min_objects, args.min_visible)
            print(
                f"[{visuals}, noise x{noise:g}: {len(frames)} frames captured in {time.perf_counter() - t:.0f} s]",
                file=sys.stderr,
            )
            for name in detectors:
                draw = Path(args.out) / f"{visuals}_noise{noise:g}"
                r = _evaluate(settings, frames, name, classes, draw)
                rows.append((visuals, noise, name, r))
    print(header + "   (per class: mAP50)")
    for visuals, noise, name, r in rows:
        per = " ".join(f"{r['per_class'][c][0]:10.3f}" for c in classes)
        print(f"{visuals:10} {noise:5g} {name:10} {r['map50']:6.3f} {r['map']:8.3f} {np.median(r['ms']):8.1f}  {per}")
    print(f"frames with boxes drawn (green: truth, red: detections): {args.out}/")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
