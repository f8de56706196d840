"""Built-in perception detectors (registered through the `twin` entry-point group).

- `geometric`: point-cloud clusters above the table, classified by size, shape and colour.
- `oracle`: ORACLE - reads simulator ground truth handed over by the caller; for ablations only.
- `yolo`: a YOLOv8 model trained on twin's labelled renders, run from ONNX (extra `detect`: onnxruntime).
"""

from __future__ import annotations

from twin.plugin import Registry, hookimpl


@hookimpl
def twin_register_detectors(registry: Registry) -> None:
    registry.add_detector(
        "geometric",
        "twin_detectors.geometric:GeometricDetector",
        description="clusters above the table, classified by size, shape and colour",
        extra="perception",
    )
    registry.add_detector(
        "oracle",
        "twin_detectors.oracle:OracleDetector",
        description="ORACLE: ground-truth classes and masks (ablations only)",
        extra="perception",
    )
    registry.add_detector(
        "yolo",
        "twin_detectors.yolo:YoloDetector",
        description="YOLOv8 trained on twin's labelled renders (ONNX), then each box's depth region",
        extra="detect",
    )
