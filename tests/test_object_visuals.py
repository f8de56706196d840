"""Realistic object looks (issue 42, `twin.object_visuals`, `world.visuals`): generated meshes that stay
inside the collision shape and fill it, textures that parse, looks drawn from the seed, and physics that does
not change with the look."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from twin.config import load_config
from twin.errors import ConfigError
from twin.object_visuals import REALISTIC_CLASSES, VARIANTS, realistic_urdf, visual_mesh
from twin.scene_layout import OBJECT_TEMPLATES
from twin.world import World

ROOT = Path(__file__).resolve().parents[1]


def _obj(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, texture coordinates and 0-based triangles of an OBJ written by `visual_mesh`."""
    v, vt, f = [], [], []
    for line in path.read_text().splitlines():
        head, *rest = line.split()
        if head == "v":
            v.append([float(x) for x in rest])
        elif head == "vt":
            vt.append([float(x) for x in rest])
        elif head == "f":
            f.append([int(x.split("/")[0]) - 1 for x in rest])
    return np.array(v), np.array(vt), np.array(f)


def _collision(cls: str) -> tuple[str, tuple[float, ...]]:
    text = (ROOT / OBJECT_TEMPLATES[cls].urdf).read_text()
    kind, attrs = re.search(r"<collision>\s*<geometry>\s*<(cylinder|box)\s+([^/]*)/>", text).groups()  # type: ignore[union-attr]
    a = dict(re.findall(r'(\w+)="([^"]*)"', attrs))
    return (
        (kind, (float(a["radius"]), float(a["length"])))
        if kind == "cylinder"
        else (kind, tuple(map(float, a["size"].split())))
    )


@pytest.mark.parametrize("cls", REALISTIC_CLASSES)
def test_every_look_lies_inside_its_collision_shape_and_fills_it(cls: str) -> None:
    """The camera must see the object where physics has it: every vertex inside the collision shape (to
    0.1 mm), and the look as long and as wide as the shape to within 10 %, so a detector sized on the
    flat primitives measures the same object."""
    kind, dims = _collision(cls)
    for variant in range(VARIANTS):
        v, vt, f = _obj(visual_mesh(cls, variant, dims))
        assert f.min() >= 0 and f.max() < v.shape[0] and vt.shape[0] == v.shape[0]
        assert ((vt >= 0) & (vt <= 1)).all()
        if kind == "cylinder":
            r, length = dims
            radial = np.hypot(v[:, 0], v[:, 1])
            assert radial.max() <= r + 1e-4 and np.abs(v[:, 2]).max() <= length / 2 + 1e-4
            assert radial.max() >= 0.9 * r and np.ptp(v[:, 2]) >= 0.9 * length
        else:
            half = np.array(dims) / 2
            assert (np.abs(v) <= half + 1e-4).all()
            assert (np.ptp(v, axis=0) >= 0.9 * np.array(dims)).all()


@pytest.mark.parametrize("cls", REALISTIC_CLASSES)
def test_looks_differ_and_their_textures_are_images(cls: str) -> None:
    _, dims = _collision(cls)
    textures = []
    for variant in range(VARIANTS):
        obj = visual_mesh(cls, variant, dims)
        png = obj.with_suffix(".png")
        assert f"map_Kd {png.name}" in obj.with_suffix(".mtl").read_text()
        img = cv2.imread(str(png))
        assert img is not None and img.shape == (256, 256, 3)
        textures.append(img)
    assert len({t.tobytes() for t in textures}) == VARIANTS


def test_a_realistic_urdf_keeps_everything_but_the_visual_byte_for_byte() -> None:
    urdf = ROOT / OBJECT_TEMPLATES["can"].urdf
    out = realistic_urdf("can", 3, urdf).read_text()
    visual = re.compile(r"<visual>.*?</visual>", re.DOTALL)
    assert visual.sub("", out) == visual.sub("", urdf.read_text())
    assert "<mesh filename=" in out and "cylinder radius" in out  # the collision is still the cylinder


def _poses(world: World) -> np.ndarray:
    return np.array([np.r_[o.position, o.orientation_xyzw] for o in world.objects()])


def test_the_look_changes_no_physics_and_is_drawn_from_the_seed() -> None:
    """Flat and realistic worlds of one seed evolve bit for bit alike (2 s, objects settling, some lying),
    the realistic one showing the generated meshes; the looks repeat per seed and differ between seeds."""
    import pybullet as pb

    flat = load_config(ROOT / "configs/robocup.yaml")
    real = flat.model_copy(update={"world": flat.world.model_copy(update={"visuals": "realistic"})})
    out, meshes = {}, {}
    for name, settings in (("flat", flat), ("real", real)):
        with World(settings, seed=5, renderer="tiny") as world:
            shown = [pb.getVisualShapeData(b, physicsClientId=world.client_id)[0] for b in world.object_ids()]
            meshes[name] = sum(d[2] == pb.GEOM_MESH and b"look_" in d[4] for d in shown)
            world.step(round(2.0 / world.dt))
            out[name] = _poses(world)
    np.testing.assert_array_equal(out["flat"], out["real"])
    assert meshes == {"flat": 0, "real": 4}  # bottle, can, spam, marker; the four cubes stay flat

    from twin.world.scene_builder import _SceneBuilder  # the draw alone, without a world

    def looks(seed: int) -> dict[str, int]:
        from twin.scene_layout import sample_layout

        builder = _SceneBuilder(0, real, seed, None)  # type: ignore[arg-type]
        return builder._looks(sample_layout(real.world.objects, seed, []))

    assert looks(5) == looks(5)
    assert set(looks(5)) == {"bottle_0", "can_0", "spam_0", "marker_0"}
    assert len({tuple(looks(s).values()) for s in range(6)}) > 1


def test_an_unknown_visual_style_is_a_config_error_naming_the_allowed_ones(tmp_path: Path) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("world:\n  visuals: photoreal\n")
    with pytest.raises(ConfigError, match=r"flat.*realistic"):
        load_config(cfg)


def test_the_scene_light_is_off_by_default_and_drawn_per_seed_within_its_cone() -> None:
    from twin.config import LightSettings
    from twin.world.rendering import scene_light

    assert scene_light(LightSettings(), 3) is None  # PyBullet's own light: images as before
    cfg = LightSettings(direction=(0.0, 0.0, 2.0), direction_jitter_deg=30.0, color_jitter=0.2)
    lights = [scene_light(cfg, s) for s in range(50)]
    dirs = np.array([li.direction for li in lights if li is not None])
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    tilt = np.degrees(np.arccos(np.clip(dirs[:, 2], -1, 1)))
    assert tilt.max() <= 30.0 + 1e-9 and tilt.max() > 20.0  # fills the cone, never beyond it
    colors = np.array([li.color for li in lights if li is not None])
    assert colors.min() >= 0.8 - 1e-12 and colors.max() <= 1.2 + 1e-12 and np.ptp(colors) > 0.2
    again = scene_light(cfg, 7)
    assert again is not None and np.array_equal(again.direction, dirs[7])


def test_a_light_from_the_side_renders_other_pixels_than_one_from_above() -> None:
    from twin.camera import Intrinsics, look_at
    from twin.world.rendering import Light

    settings = load_config(ROOT / "configs/robocup.yaml")
    with World(settings, seed=1) as world:
        T = look_at((-0.45, 0.0, 0.8), (-0.45, 0.0, 0.0))
        K = Intrinsics(96, 72, 90.0, 90.0)
        above = Light(np.array([0.0, 0.0, 1.0]), np.ones(3))
        side = Light(np.array([1.0, 0.0, 0.2]) / np.hypot(1.0, 0.2), np.array([1.0, 0.8, 0.6]))
        a, a2 = (world.render(T, K, near_m=0.05, far_m=3.0, light=above).rgb for _ in range(2))
        b = world.render(T, K, near_m=0.05, far_m=3.0, light=side).rgb
    assert np.array_equal(a, a2)
    assert np.abs(a.astype(float) - b).mean() > 5.0
