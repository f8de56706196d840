"""The `oracle` detector: ORACLE, reads simulator ground truth. For ablations only.

It returns the true class and colour of every object and a mask of exactly the pixels whose 3D point
lies inside the object's true (slightly grown) box, so a run with it measures the pose-estimation stage
(table removal, PCA, ICP) without detection errors. It never sees PyBullet: the caller hands it the
ground-truth object list (`World.objects()`), because it declares `needs_ground_truth = True`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from twin.plugin import Detection, InvalidRequestError, RGBDFrame, SceneCloud, quat_to_matrix, scene_cloud

__all__ = ["OracleDetector"]


class OracleDetector:
    """ORACLE detector (ground truth): true classes, colours and masks; for ablations, never for results."""

    needs_ground_truth = True

    class Params(BaseModel):
        """margin_m grows each true box (depth noise); objects with fewer than min_pixels are not 'seen'."""

        model_config = ConfigDict(extra="forbid")
        margin_m: float = Field(0.006, ge=0)
        min_pixels: int = Field(20, ge=1)

    def __init__(self, params: OracleDetector.Params | None, context: Any) -> None:
        self.params = params if params is not None else self.Params()
        self.settings = context.settings

    def detect(
        self,
        frame: RGBDFrame,
        T_base_camera: np.ndarray,
        *,
        cloud: SceneCloud | None = None,
        ground_truth: Sequence[Any] | None = None,
    ) -> list[Detection]:
        """One detection per true object with enough visible pixels; `ground_truth`: objects with cls,
        color, position (3,), orientation_xyzw (4,) and size (3,) (`twin.world.ObjectState`)."""
        if ground_truth is None:
            raise InvalidRequestError("the oracle detector needs ground_truth (World.objects()) from the caller")
        rc = self.settings.perception.robocup
        cloud = cloud if cloud is not None else scene_cloud(frame, T_base_camera, rc)
        above = cloud.height > cloud.table_threshold_m
        W = frame.depth_m.shape[1]
        out = []
        for obj in ground_truth:
            R = quat_to_matrix(np.asarray(obj.orientation_xyzw))
            local = (cloud.points - np.asarray(obj.position)) @ R
            inside = np.all(np.abs(local) <= np.asarray(obj.size) / 2.0 + self.params.margin_m, axis=1) & above
            if inside.sum() < self.params.min_pixels:
                continue
            px = cloud.pixels[inside]
            v, u = px // W, px % W
            out.append(
                Detection(
                    obj.cls,
                    obj.color,
                    1.0,
                    px,
                    (int(u.min()), int(v.min()), int(u.max()), int(v.max())),
                    {"oracle": True, "name": getattr(obj, "name", None)},
                )
            )
        return out
