"""Train YOLOv8n on a `twin dataset` folder, offline, and export it to ONNX (issue 42). Runs in the training
venv (`bench/.train-venv`: torch, torchvision, ultralytics, onnx; `bench/train_detector.py` makes it and
calls this); imports nothing from twin. JSON in (argv[1]), JSON out (argv[2]).

ultralytics is AGPL-3.0: it trains the model here and is never imported by twin's runtime, which runs the
exported ONNX file (`twin_detectors.yolo`).

Offline, as `../shared/LIBRARY-NOTES.md` measured: YOLO_OFFLINE (ultralytics calls itself online when DNS
answers), YOLO_AUTOINSTALL=0 (no pip at run time; ONNX export without onnxslim), a settings folder of our
own with `sync` off, and a local TTF where ultralytics would download Arial. The model is built from its
definition (`yolov8n.yaml`): no pretrained weights are fetched.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path
from typing import Any

_FONTS = ("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",)


def _offline(config_dir: Path) -> None:
    os.environ["YOLO_OFFLINE"] = "1"
    os.environ["YOLO_AUTOINSTALL"] = "0"
    os.environ["YOLO_CONFIG_DIR"] = str(config_dir)
    font_dir = config_dir / "Ultralytics"
    font_dir.mkdir(parents=True, exist_ok=True)
    for font in _FONTS:
        if Path(font).is_file():
            for name in ("Arial.ttf", "Arial.Unicode.ttf"):
                if not (font_dir / name).exists():
                    shutil.copy(font, font_dir / name)
            break


def main() -> int:
    spec: dict[str, Any] = json.loads(Path(sys.argv[1]).read_text())
    out = Path(spec["out"])
    out.mkdir(parents=True, exist_ok=True)
    _offline(out / "ultralytics-config")
    import torch
    from ultralytics import YOLO, settings

    settings.update({"sync": False})
    torch.set_num_threads(int(spec.get("threads") or os.cpu_count() or 1))
    model = YOLO(spec.get("model", "yolov8n.yaml"))
    t0 = time.perf_counter()
    model.train(
        data=spec["data"],
        epochs=int(spec["epochs"]),
        imgsz=int(spec["imgsz"]),
        batch=int(spec.get("batch", 16)),
        device=spec.get("device", "cpu"),
        workers=0,
        amp=False,
        plots=False,
        seed=int(spec.get("seed", 0)),
        deterministic=True,
        project=str(out),
        name="train",
        exist_ok=True,
        pretrained=False,
        verbose=False,
        **({"time": float(spec["time_hours"])} if spec.get("time_hours") else {}),
    )
    train_s = time.perf_counter() - t0
    best = out / "train" / "weights" / "best.pt"
    trained = YOLO(str(best if best.is_file() else out / "train" / "weights" / "last.pt"))
    result: dict[str, Any] = {"train_s": train_s, "torch": torch.__version__, "machine": platform.processor()}
    for split in ("val", "test"):
        m = trained.val(
            data=spec["data"],
            split=split,
            imgsz=int(spec["imgsz"]),
            device=spec.get("device", "cpu"),
            workers=0,
            plots=False,
            verbose=False,
            project=str(out),
            name=f"val_{split}",
            exist_ok=True,
        )
        names = m.names
        result[split] = {
            "map50": float(m.box.map50),
            "map50_95": float(m.box.map),
            "per_class": {
                names[int(c)]: [float(m.box.ap50[i]), float(m.box.ap[i])] for i, c in enumerate(m.box.ap_class_index)
            },
        }
    onnx = trained.export(format="onnx", imgsz=int(spec["imgsz"]), simplify=False, dynamic=False, device="cpu")
    result["onnx"] = str(onnx)
    result["names"] = trained.names
    result["epochs_done"] = (
        int(getattr(trained, "ckpt", {}).get("epoch", -1)) + 1 if getattr(trained, "ckpt", None) else None
    )
    Path(sys.argv[2]).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
