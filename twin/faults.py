"""Named fault sets: the faults a robustness campaign (`bench/bench_campaign.py`) or a run (`twin run --faults
NAME`) applies on top of a config, as `--set` overrides of the config's own fault-model keys (each documented
where it lives in `twin.config.schema`). A name keeps a campaign reproducible: the worst seed it prints is
one `twin run CONFIG --seed N --faults NAME` away.

- `nominal`: none; the config as written (its sensor model's best case).
- `stress`: a sensor, a mount, a controller and objects that are all off at once, as in a worn cell: 3x the
  depth noise RMS with 10 % of the pixels dropped and RGB noise 6; a camera 1 cm / 1 deg off its configured
  pose (hand-eye transform on a wrist); objects 1-1.5x their catalogued mass and 0.7-1x their friction; a
  joint controller that lags 50 ms behind its targets with 1 mrad of tracking noise; a 4 x 4 x 15 cm box on
  the table that no config or planning scene describes.
"""

from __future__ import annotations

from typing import Final

from twin.errors import UnknownNameError

__all__ = ["FAULT_PRESETS", "fault_overrides"]

FAULT_PRESETS: Final[dict[str, tuple[str, ...]]] = {
    "nominal": (),
    "stress": (
        "camera.noise.scale=3",
        "camera.noise.dropout_fraction=0.1",
        "camera.noise.rgb_noise_std=6",
        "camera.extrinsic_error.translation_m=0.01",
        "camera.extrinsic_error.rotation_deg=1",
        "world.objects.mass_scale=[1.0, 1.5]",
        "world.objects.friction_scale=[0.7, 1.0]",
        "robot.tracking_time_constant_s=0.05",
        "robot.tracking_noise_rad=0.001",
        "world.unmodelled_obstacle={}",
    ),
}


def fault_overrides(name: str) -> tuple[str, ...]:
    """The `--set` overrides of fault set `name`; UnknownNameError (naming those that exist) otherwise."""
    try:
        return FAULT_PRESETS[name]
    except KeyError:
        raise UnknownNameError("fault set", name, FAULT_PRESETS, hint="They are defined in twin/faults.py.") from None
