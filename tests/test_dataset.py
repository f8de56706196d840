"""`twin dataset` (issue 42, `twin.dataset`): labelled images from the task's camera, labels from the
renderer's segmentation, in YOLO's and COCO's formats, deterministic per seed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pycocotools.coco import COCO

from twin.camera import Intrinsics, true_camera_pose
from twin.config import load_config
from twin.dataset import DatasetOptions, class_names, make_dataset, scene_items, split_of, visible_boxes
from twin.errors import ConfigError
from twin.world import World

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def realistic() -> object:
    s = load_config(ROOT / "configs/robocup.yaml")
    return s.model_copy(update={"world": s.world.model_copy(update={"visuals": "realistic"})})


def _yolo(path: Path) -> list[list[float]]:
    return [[float(x) for x in line.split()] for line in path.read_text().splitlines()]


def test_a_small_dataset_parses_in_both_formats_and_repeats_bit_for_bit(realistic: object, tmp_path: Path) -> None:
    """Scene seeds 7 and 8: train and val. Every YOLO line is a class index and a box inside the image;
    pycocotools reads the COCO files and finds the same boxes; the card adds up; the same seed writes the
    same images and labels again."""
    opts = DatasetOptions(images=4, seed=7, views=2, clutter=2)
    card = make_dataset(realistic, tmp_path / "a", opts)  # type: ignore[arg-type]
    make_dataset(realistic, tmp_path / "b", opts)  # type: ignore[arg-type]
    names = class_names(realistic)  # type: ignore[arg-type]
    assert names == ["bottle", "can", "spam", "marker", "cube_red", "cube_blue", "cube_green", "cube_yellow"]
    assert card.images == {"train": 2, "val": 2} and split_of(7) == "train" and split_of(8) == "val"
    total = 0
    for split in ("train", "val"):
        coco = COCO(str(tmp_path / "a" / "coco" / f"{split}.json"))
        assert [coco.cats[i]["name"] for i in sorted(coco.cats)] == names
        for img_id, img in coco.imgs.items():
            label = tmp_path / "a" / img["file_name"].replace("images/", "labels/").replace(".png", ".txt")
            lines = _yolo(label)
            anns = coco.loadAnns(coco.getAnnIds(imgIds=[img_id]))
            assert len(lines) == len(anns) > 0
            for (c, cx, cy, w, h), a in zip(lines, anns, strict=True):
                assert int(c) == a["category_id"] and 0 <= int(c) < len(names)
                assert 0 < w <= 1 and 0 < h <= 1 and -1e-6 <= cx - w / 2 and cx + w / 2 <= 1 + 1e-6  # 6 decimals
                x, y, bw, bh = a["bbox"]
                assert cx * img["width"] == pytest.approx(x + bw / 2, abs=1e-3)
                assert cy * img["height"] == pytest.approx(y + bh / 2, abs=1e-3)
                assert (w * img["width"], h * img["height"]) == pytest.approx((bw, bh), abs=1e-3)
                assert a["visible_fraction"] >= opts.min_visible
            total += len(anns)
    assert total == sum(card.annotations.values()) == sum(card.per_class.values())
    assert json.loads((tmp_path / "a" / "card.json").read_text())["classes"] == names
    for f in sorted((tmp_path / "a").rglob("*")):
        if f.suffix in (".png", ".txt"):
            assert f.read_bytes() == (tmp_path / "b" / f.relative_to(tmp_path / "a")).read_bytes(), f


def test_labels_box_the_visible_pixels_of_objects_seen_enough_and_nothing_else() -> None:
    """One scene seen from the capture pose, then changed on purpose: the marker pushed under the spam tin
    (hidden), a cube moved half out of the image (cut by its edge), the can moved out of sight. Every box is
    the box of its object's pixels in the renderer's segmentation; an object is boxed exactly when at least
    `min_visible` of it shows (the tin, the cubes in full view), never when it is hidden or out of sight."""
    settings = load_config(ROOT / "configs/robocup.yaml")
    cam = settings.camera
    intr = Intrinsics.from_settings(cam)
    with World(settings, seed=2) as world:
        world.reset_joints(np.asarray(cam.capture_pose, dtype=float))
        T = true_camera_pose(cam, world.seed, world.link_matrix("tool0"))
        by_name = {o.name: o for o in world.objects()}
        tin = by_name["spam_0"]
        world.set_object_pose(by_name["marker_0"].id, tin.position - [0, 0, 0.02], [0, 0, 0, 1])
        world.set_object_pose(by_name["can_0"].id, [2.0, 2.0, 0.06], [0, 0, 0, 1])
        # a point on the image's left edge at the table's height: the cube centred there is cut in half
        z = float(by_name["cube_red_0"].position[2])
        ray = T[:3, :3] @ np.array([(0 - intr.cx) / intr.fx, 0.0, 1.0])
        edge = T[:3, 3] + ray * (z - T[2, 3]) / ray[2]
        world.set_object_pose(by_name["cube_red_0"].id, edge, [0, 0, 0, 1])
        _, ids = world.render_labelled(T, intr, near_m=cam.near_m, far_m=cam.far_m)
        assert ids is not None
        boxes, hidden = visible_boxes(world, ids, T, intr, settings, 0.6)
    got = {b["class"]: b for b in boxes}
    assert "marker" not in got and "can" not in got
    assert "cube_red" not in got and hidden >= 1  # about half of it shows: under 0.6
    for name, o in by_name.items():
        mask = ids == o.id
        label = f"{o.cls}_{o.color}" if o.color else o.cls
        if label in got:
            rows, cols = np.nonzero(mask)
            assert got[label]["box"] == [cols.min(), rows.min(), cols.max() + 1, rows.max() + 1], name
            assert got[label]["pixels"] == mask.sum()
    assert {"spam", "cube_blue", "cube_green", "cube_yellow"} <= set(got)


def test_bad_dataset_options_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="min_visible"):
        DatasetOptions(images=3, min_visible=0.0)
    with pytest.raises(ConfigError, match="at least 1 image"):
        DatasetOptions(images=0)
    with pytest.raises(ConfigError, match="min_objects"):
        DatasetOptions(images=3, min_objects=-1)


def test_scenes_hold_from_a_few_to_all_of_the_configs_objects_plus_clutter() -> None:
    """A run ends on a table with one or two objects left, so a dataset shows such tables too: each scene
    keeps `min_objects`..all of the config's objects (distinct ones, a subset), obstacles always; extras come
    on top. None keeps every object (the scene a run starts from)."""
    s = load_config(ROOT / "configs/robocup.yaml")
    own = [(i.cls, i.color) for i in s.world.objects.items]
    counts = []
    for seed in range(40):
        kept = [(i.cls, i.color) for i in scene_items(s, seed, 0, 1)]
        assert len(set(kept)) == len(kept) and set(kept) <= set(own)  # a subset of the 8 distinct objects
        counts.append(len(kept))
        assert scene_items(s, seed, 0, 1) == scene_items(s, seed, 0, 1)  # drawn from the seed
        full = scene_items(s, seed, 3, None)
        assert [(i.cls, i.color) for i in full[: len(own)]] == own and len(full) - len(own) <= 3
        assert len(scene_items(s, seed, 0, 8)) == len(own)  # min_objects >= the count keeps all
    assert min(counts) <= 2 and max(counts) == len(own)  # nearly empty and full tables both occur
    items = "world.objects.items=[{class: obstacle}, {class: can, count: 2}, {class: bottle}]"
    with_obstacle = load_config(ROOT / "configs/robocup.yaml", [items])
    kinds = [tuple(i.cls for i in scene_items(with_obstacle, seed, 0, 0)) for seed in range(20)]
    assert all(k[0] == "obstacle" and "obstacle" not in k[1:] for k in kinds)
    assert {len(k) for k in kinds} == {1, 2, 3, 4}  # the obstacle and 0..3 of the objects (count 2: two cans)
