"""`twin dataset`: labelled images from the task's own camera, the one thing a simulator gives for free
(issue 42). Seed 002 trained its detector on 1001 hand-labelled images; here any number are labelled by the
renderer.

For each scene seed (`seed`, `seed + 1`, ...) the config's world is built and settled, then photographed from
`views` camera poses: the wrist camera at and around its capture pose (each joint moved by up to
`joint_jitter_rad`), a fixed camera around its mount (`fixed_jitter_m`, `fixed_jitter_deg`). Everything varies
with the seed (domain randomisation): where the objects lie and how they are turned (the layout, lying ones
included), how full the table is (`min_objects`: each scene keeps that many to all of the config's objects,
so the few left as a run ends are seen too; `clutter`: up to that many extra objects of its classes),
their looks (with `world.visuals: realistic`), the light (direction within `light_cone_deg` of above, colour
within `light_color_jitter`), the camera's pose and white balance, and the config's sensor noise on the
colour image.

Labels come from the renderer's segmentation: an object is boxed (the box of its visible pixels) when at
least `min_visible` of it can be seen, the fraction being its visible pixels over its pixels with every other
object taken away (`_solo_pixels`); objects seen less are left unlabelled and counted. Images go to one split
by their scene seed (`split_of`: every 10 seeds, 8 train, 1 val, 1 test), so no scene is in two splits.

Written in YOLO's layout (`images/<split>/*.png`, `labels/<split>/*.txt`, `data.yaml`) and COCO's
(`coco/<split>.json`), with a dataset card (`card.json`, `card.md`) beside seed 002's figures.
Deterministic per seed: the same command writes the same files.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from twin.camera import Intrinsics, true_camera_pose
from twin.config import ObjectSpec, Settings
from twin.errors import ConfigError, WorldError
from twin.perception.noise import apply_sensor_noise
from twin.robot import Robot
from twin.world import World
from twin.world.rendering import Light, jittered_light

__all__ = [
    "SEED_002",
    "DatasetCard",
    "DatasetOptions",
    "class_names",
    "make_dataset",
    "scene_world",
    "split_of",
    "visible_boxes",
]

SPLITS = ("train", "val", "test")
# seed 002's hand-labelled set (its report): images, annotations, objects per image, classes, mAP@0.5
SEED_002 = {"images": 1001, "annotations": 5915, "objects_per_image": 5.9, "classes": 8, "map50": 0.981}


@dataclass(frozen=True)
class DatasetOptions:
    """What `make_dataset` varies and keeps (the module docstring says how each is used)."""

    images: int
    seed: int = 0
    views: int = 4
    min_visible: float = 0.3
    clutter: int = 4
    min_objects: int = 1
    joint_jitter_rad: float = 0.08
    fixed_jitter_m: float = 0.03
    fixed_jitter_deg: float = 3.0
    light_cone_deg: float = 50.0
    light_color_jitter: float = 0.15
    white_balance_jitter: float = 0.1
    settle_s: float = 1.0

    def __post_init__(self) -> None:
        if self.images < 1 or self.views < 1:
            raise ConfigError(f"a dataset needs at least 1 image and 1 view per scene, got {self.images}, {self.views}")
        if not 0.0 < self.min_visible <= 1.0:
            raise ConfigError(f"min_visible must be in (0, 1], got {self.min_visible}")
        if min(self.seed, self.clutter, self.min_objects) < 0:
            raise ConfigError(
                "seed, clutter and min_objects must be non-negative, got "
                f"{self.seed}, {self.clutter}, {self.min_objects}"
            )


@dataclass
class DatasetCard:
    """What a dataset holds: images and annotations per split and class, objects per image, box sizes (px)
    and visible fractions, the objects left unlabelled as too hidden, and seed 002's figures beside."""

    config: str
    classes: list[str]
    images: dict[str, int] = field(default_factory=dict)
    annotations: dict[str, int] = field(default_factory=dict)
    per_class: dict[str, int] = field(default_factory=dict)
    objects_per_image: float = 0.0
    box_width_px: dict[str, float] = field(default_factory=dict)
    box_height_px: dict[str, float] = field(default_factory=dict)
    visible_fraction: dict[str, float] = field(default_factory=dict)
    too_hidden: int = 0
    scenes: int = 0
    image_size: tuple[int, int] = (0, 0)
    options: dict[str, Any] = field(default_factory=dict)
    seed_002: dict[str, float] = field(default_factory=lambda: dict(SEED_002))

    def markdown(self) -> str:
        """The card as a Markdown table beside seed 002's figures."""
        n_img, n_ann = sum(self.images.values()), sum(self.annotations.values())
        lines = [
            f"# Dataset card: {self.config}",
            "",
            "| | this dataset | seed 002 (hand-labelled) |",
            "|---|---|---|",
            f"| images | {n_img} ({', '.join(f'{k} {v}' for k, v in self.images.items())}) | {SEED_002['images']} |",
            f"| annotations | {n_ann} | {SEED_002['annotations']} |",
            f"| objects per image | {self.objects_per_image:.2f} | {SEED_002['objects_per_image']} |",
            f"| classes | {len(self.classes)} | {SEED_002['classes']} |",
            f"| image size | {self.image_size[0]} x {self.image_size[1]} px | - |",
            f"| scenes (seeds) | {self.scenes} | - |",
            "",
            "| class | annotations |",
            "|---|---|",
            *(f"| {c} | {self.per_class.get(c, 0)} |" for c in self.classes),
            "",
            "box size px (min / median / max): width "
            + " / ".join(f"{self.box_width_px.get(k, 0):.0f}" for k in ("min", "median", "max"))
            + ", height "
            + " / ".join(f"{self.box_height_px.get(k, 0):.0f}" for k in ("min", "median", "max")),
            f"visible fraction of the boxed objects (min / median): {self.visible_fraction.get('min', 0):.2f} / "
            f"{self.visible_fraction.get('median', 0):.2f}; objects seen but under min_visible, unlabelled: "
            f"{self.too_hidden}",
        ]
        return "\n".join(lines) + "\n"


def split_of(scene_seed: int) -> str:
    """The split of every image of a scene: seeds ending in 0-7 train, 8 val, 9 test."""
    last = scene_seed % 10
    return "train" if last < 8 else ("val" if last == 8 else "test")


def class_names(settings: Settings) -> list[str]:
    """The detection classes of a config: each object class, cubes (and warehouse cubes) per colour, in the
    order of the config's items."""
    names = [_label(spec.cls, spec.color) for spec in settings.world.objects.items if spec.cls != "obstacle"]
    return list(dict.fromkeys(names))


def _label(cls: str, color: str | None) -> str:
    return f"{cls}_{color}" if color else cls


def scene_items(settings: Settings, scene_seed: int, clutter: int, min_objects: int | None = None) -> list[ObjectSpec]:
    """The objects of one scene seed: of the config's own (obstacles always kept), a random `min_objects`..all
    of them (all: None), so a table with a few objects left, as a run ends, is seen too; then up to `clutter`
    extra objects of the config's classes. Drawn from the scene seed."""
    own, extras = _own_and_extras(settings, scene_seed, clutter, min_objects)
    return [*own, *extras]


def _own_and_extras(
    settings: Settings, scene_seed: int, clutter: int, min_objects: int | None
) -> tuple[list[ObjectSpec], list[ObjectSpec]]:
    """`scene_items` in its two parts: the config's objects kept, and the extras."""
    items = list(settings.world.objects.items)
    if min_objects is not None:
        single = [ObjectSpec(cls=s.cls, color=s.color) for s in items if s.cls != "obstacle" for _ in range(s.count)]
        rng = np.random.default_rng([scene_seed, 4245])
        keep = int(rng.integers(min(min_objects, len(single)), len(single) + 1))
        chosen = sorted(rng.choice(len(single), size=keep, replace=False).tolist())
        items = [s for s in items if s.cls == "obstacle"] + [single[i] for i in chosen]
    classes = [s for s in settings.world.objects.items if s.cls != "obstacle" and s.count > 0]
    if clutter == 0 or not classes:
        return items, []
    rng = np.random.default_rng([scene_seed, 4243])
    extras = [
        ObjectSpec(cls=classes[k].cls, color=classes[k].color)
        for k in (int(rng.integers(len(classes))) for _ in range(int(rng.integers(clutter + 1))))
    ]
    return items, extras


def scene_world(
    settings: Settings, scene_seed: int, clutter: int, robot: Robot, *, min_objects: int | None = None
) -> World:
    """The world of one scene seed with its objects (`scene_items`); as many of the extras as the table's
    free space takes (the layout refuses a crowd it cannot place without overlaps: the last extra is dropped
    until it fits)."""
    own, extras = _own_and_extras(settings, scene_seed, clutter, min_objects)
    while True:
        objects = settings.world.objects.model_copy(update={"items": [*own, *extras]})
        crowded = settings.model_copy(update={"world": settings.world.model_copy(update={"objects": objects})})
        try:
            return World(crowded, seed=scene_seed, robot=robot)
        except WorldError:
            if not extras:
                raise
            extras = extras[:-1]


def _random_rotation(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    """A rotation about a random axis by up to max_deg."""
    axis = rng.normal(size=3)
    angle = math.radians(rng.uniform(0.0, max_deg))
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()


def _view(world: World, settings: Settings, opts: DatasetOptions, rng: np.random.Generator) -> np.ndarray:
    """The camera's pose for one view: the wrist camera after moving the arm near its capture pose, a fixed
    camera moved near its mount."""
    cam = settings.camera
    if cam.mount == "wrist":
        q = np.asarray(cam.capture_pose, dtype=float) + rng.uniform(-opts.joint_jitter_rad, opts.joint_jitter_rad, 6)
        world.reset_joints(q)
        return true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
    T = true_camera_pose(cam, world.seed).copy()
    T[:3, 3] += rng.uniform(-opts.fixed_jitter_m, opts.fixed_jitter_m, 3)
    T[:3, :3] = _random_rotation(rng, opts.fixed_jitter_deg) @ T[:3, :3]
    return T


def _light(rng: np.random.Generator, opts: DatasetOptions) -> Light:
    """A light within `light_cone_deg` of straight above, its colour within `light_color_jitter` of white."""
    return jittered_light((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), opts.light_cone_deg, opts.light_color_jitter, rng)


def _solo_pixels(world: World, oid: int, T: np.ndarray, intr: Intrinsics, near: float, far: float) -> int:
    """How many pixels object `oid` covers with every other object taken away (moved far below the table
    and put back exactly; nothing is stepped in between) in a frame a quarter wider on every side (the same
    camera, so an object cut by the image's edge counts its hidden part): the denominator of its visible
    fraction. The arm and the fixtures stay: what they hide counts as hidden."""
    others = [o for o in world.object_ids() if o != oid]
    saved = {o: world.object_pose(o) for o in others}
    wide = Intrinsics(intr.width + 2 * (intr.width // 4), intr.height + 2 * (intr.height // 4), intr.fx, intr.fy)
    for k, o in enumerate(others):
        world.set_object_pose(o, [50.0 + k, 50.0, -50.0], [0.0, 0.0, 0.0, 1.0])
    try:
        _, ids = world.render_labelled(T, wide, near_m=near, far_m=far)
    finally:
        for o, (p, q) in saved.items():
            world.set_object_pose(o, p, q)
    assert ids is not None
    return int((ids == oid).sum())


def visible_boxes(
    world: World, ids: np.ndarray, T: np.ndarray, intr: Intrinsics, settings: Settings, min_visible: float
) -> tuple[list[dict[str, Any]], int]:
    """The labelled boxes of one view (class, x0, y0, x1, y1 px, inclusive-exclusive; visible pixels and
    fraction) and how many seen objects were too hidden to label."""
    cam = settings.camera
    out, hidden = [], 0
    for st in world.objects():
        if st.cls == "obstacle":
            continue
        mask = ids == st.id
        n = int(mask.sum())
        if n == 0:
            continue
        solo = _solo_pixels(world, st.id, T, intr, cam.near_m, cam.far_m)
        frac = n / max(solo, n)
        if frac < min_visible:
            hidden += 1
            continue
        rows, cols = np.nonzero(mask)
        out.append(
            {
                "class": _label(st.cls, st.color),
                "box": [int(cols.min()), int(rows.min()), int(cols.max()) + 1, int(rows.max()) + 1],
                "pixels": n,
                "visible": round(frac, 4),
            }
        )
    return out, hidden


def make_dataset(
    settings: Settings,
    out: Path,
    opts: DatasetOptions,
    *,
    config_name: str = "",
    progress: Callable[[int, int], None] | None = None,
) -> DatasetCard:
    """Render `opts.images` labelled images of `settings`' task camera into `out` (module docstring)."""
    import cv2  # lazy: only a dataset writes images

    classes = class_names(settings)
    if not classes:
        raise ConfigError("the config has no objects to label (world.objects.items)")
    cid = {c: i for i, c in enumerate(classes)}
    cam = settings.camera
    intr = Intrinsics.from_settings(cam)
    robot = Robot.from_settings(settings)
    coco: dict[str, dict[str, Any]] = {
        s: {"images": [], "annotations": [], "categories": [{"id": i, "name": c} for c, i in cid.items()]}
        for s in SPLITS
    }
    card = DatasetCard(config=config_name, classes=classes, image_size=(intr.width, intr.height), options=asdict(opts))
    widths: list[int] = []
    heights: list[int] = []
    fractions: list[float] = []
    per_class: Counter[str] = Counter()
    done, scene = 0, opts.seed
    while done < opts.images:
        split = split_of(scene)
        with scene_world(settings, scene, opts.clutter, robot, min_objects=opts.min_objects) as world:
            world.step(round(opts.settle_s / world.dt))
            rng = np.random.default_rng([scene, 4244])
            for v in range(min(opts.views, opts.images - done)):
                T = _view(world, settings, opts, rng)
                clean, ids = world.render_labelled(T, intr, near_m=cam.near_m, far_m=cam.far_m, light=_light(rng, opts))
                assert ids is not None
                boxes, hidden = visible_boxes(world, ids, T, intr, settings, opts.min_visible)
                frame = apply_sensor_noise(clean, cam.noise, rng)
                gain = rng.uniform(1.0 - opts.white_balance_jitter, 1.0 + opts.white_balance_jitter, 3)
                rgb = np.clip(frame.rgb.astype(float) * gain, 0, 255).astype(np.uint8)
                name = f"s{scene:06d}_v{v:02d}"
                _write_image(cv2, out / "images" / split / f"{name}.png", rgb)
                _write_yolo(out / "labels" / split / f"{name}.txt", boxes, cid, intr)
                image_id = len(coco[split]["images"])
                coco[split]["images"].append(
                    {
                        "id": image_id,
                        "file_name": f"images/{split}/{name}.png",
                        "width": intr.width,
                        "height": intr.height,
                    }
                )
                for b in boxes:
                    x0, y0, x1, y1 = b["box"]
                    coco[split]["annotations"].append(
                        {
                            "id": len(coco[split]["annotations"]),
                            "image_id": image_id,
                            "category_id": cid[b["class"]],
                            "bbox": [x0, y0, x1 - x0, y1 - y0],
                            "area": (x1 - x0) * (y1 - y0),
                            "iscrowd": 0,
                            "visible_pixels": b["pixels"],
                            "visible_fraction": b["visible"],
                        }
                    )
                    widths.append(x1 - x0)
                    heights.append(y1 - y0)
                    fractions.append(b["visible"])
                    per_class[b["class"]] += 1
                card.images[split] = card.images.get(split, 0) + 1
                card.annotations[split] = card.annotations.get(split, 0) + len(boxes)
                card.too_hidden += hidden
                done += 1
                if progress is not None:
                    progress(done, opts.images)
        card.scenes += 1
        scene += 1
    _finish(out, coco, card, classes, per_class, widths, heights, fractions)
    return card


def _write_image(cv2: Any, path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"could not write {path}")


def _write_yolo(path: Path, boxes: list[dict[str, Any]], cid: dict[str, int], intr: Intrinsics) -> None:
    """YOLO's label file: one line per box, class index and centre/size normalised by the image size."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = []
    for b in boxes:
        x0, y0, x1, y1 = b["box"]
        cx, cy = (x0 + x1) / 2 / intr.width, (y0 + y1) / 2 / intr.height
        lines.append(f"{cid[b['class']]} {cx:.6f} {cy:.6f} {(x1 - x0) / intr.width:.6f} {(y1 - y0) / intr.height:.6f}")
    path.write_text("".join(line + "\n" for line in lines))


def _finish(
    out: Path,
    coco: dict[str, dict[str, Any]],
    card: DatasetCard,
    classes: list[str],
    per_class: Counter[str],
    widths: list[int],
    heights: list[int],
    fractions: list[float],
) -> None:
    """COCO files, YOLO's data.yaml and the card."""
    (out / "coco").mkdir(parents=True, exist_ok=True)
    for split, data in coco.items():
        (out / "coco" / f"{split}.json").write_text(json.dumps(data))
    names = "\n".join(f"  {i}: {c}" for i, c in enumerate(classes))
    (out / "data.yaml").write_text(
        f"# twin dataset ({card.config}); YOLO layout\npath: {out.resolve()}\ntrain: images/train\n"
        f"val: images/val\ntest: images/test\nnames:\n{names}\n"
    )

    def spread(v: list[int] | list[float]) -> dict[str, float]:
        return {"min": float(np.min(v)), "median": float(np.median(v)), "max": float(np.max(v))} if v else {}

    card.per_class = {c: per_class.get(c, 0) for c in classes}
    n_img = sum(card.images.values())
    card.objects_per_image = sum(card.annotations.values()) / n_img if n_img else 0.0
    card.box_width_px, card.box_height_px = spread(widths), spread(heights)
    card.visible_fraction = spread(fractions)
    (out / "card.json").write_text(json.dumps(asdict(card), indent=1))
    (out / "card.md").write_text(card.markdown())
