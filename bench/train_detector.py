"""Train seed 002's baseline detector, YOLOv8n, on twin's own labelled renders, by one command (issue 42).

    python bench/train_detector.py [--config configs/robocup.yaml] [--images 1500] [--seed 0]
                                   [--epochs 20] [--imgsz 320] [--batch 16] [--time-hours H]
                                   [--device cpu] [--data DIR] [--out out/train-detector] [--ship]

1. The dataset: `twin dataset` of the config with `world.visuals: realistic` (`--images`, scene seeds from
   `--seed`), into OUT/dataset, unless `--data` names one already made.
2. Training, offline, in a venv of its own (`bench/.train-venv`, made here on first use; torch is gigabytes,
   so `setup.sh` does not install it; `bench/yolo_driver.py` runs in it): YOLOv8n from its model definition
   (no pretrained weights are reachable here), then mAP50 / mAP50-95 per class on the val and test splits,
   and an ONNX export.
3. `--ship`: the ONNX file and its card (dataset, epochs, wall time, machine, mAP per class, this command)
   go to `plugins/twin_detectors/models/`, where the `yolo` detector finds them.

Budget (LIBRARY-NOTES: ~15.5 s per 100 images per epoch at 320 px on 2 cores): 1500 images x 20 epochs is
~30 000 image-epochs, ~1.3 h here; a GPU machine takes minutes (`--device 0`).

ultralytics is AGPL-3.0; it is used only here, in its own venv, to train. twin's runtime never imports it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
VENV = HERE / ".train-venv"
# the training stack: the CUDA torch + torchvision pair runs on a CPU too (no CPU torchvision on the index;
# LIBRARY-NOTES); pinned so that a training run repeats
TRAIN_PACKAGES = ["torch==2.14.1", "torchvision==0.29.1", "ultralytics==8.4.190", "onnx", "onnxruntime"]
MODELS = ROOT / "plugins" / "twin_detectors" / "models"
MODEL_NAME = "yolov8n_twin"


def train_python() -> Path:
    """The training venv's python, made on first use."""
    py = VENV / "bin" / "python"
    if not py.is_file():
        print(f"train_detector: creating {VENV} (torch, torchvision, ultralytics: several GB) ...", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", str(VENV)], check=True)
        (VENV / ".gitignore").write_text("*\n")
        subprocess.run([str(py), "-m", "pip", "install", "-q", *TRAIN_PACKAGES], check=True)
    return py


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/robocup.yaml")
    ap.add_argument("--images", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--imgsz", type=int, default=320)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--time-hours", type=float, default=None, help="stop training after this long")
    ap.add_argument("--device", default="cpu", help="cpu, or a CUDA device index such as 0")
    ap.add_argument("--data", default=None, help="a `twin dataset` folder already made (skips step 1)")
    ap.add_argument("--out", default="out/train-detector")
    ap.add_argument("--ship", action="store_true", help="copy the ONNX model and its card into the package")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    command = "python bench/train_detector.py " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))

    card: dict[str, object] = {}
    if args.data is None:
        from twin.config import load_config
        from twin.dataset import DatasetOptions, make_dataset

        settings = load_config(args.config, ["world.visuals=realistic"])
        t = time.perf_counter()
        made = make_dataset(
            settings, out / "dataset", DatasetOptions(images=args.images, seed=args.seed), config_name=args.config
        )
        print(made.markdown(), end="")
        print(f"dataset: {args.images} images in {time.perf_counter() - t:.0f} s", file=sys.stderr)
        data = out / "dataset"
    else:
        data = Path(args.data).resolve()
    card["dataset"] = json.loads((data / "card.json").read_text())

    py = train_python()
    spec = {
        "data": str(data / "data.yaml"),
        "out": str(out / "yolo"),
        "epochs": args.epochs,
        "imgsz": args.imgsz,
        "batch": args.batch,
        "device": args.device,
        "seed": args.seed,
        "time_hours": args.time_hours,
    }
    (out / "spec.json").parent.mkdir(parents=True, exist_ok=True)
    (out / "spec.json").write_text(json.dumps(spec))
    t = time.perf_counter()
    env = dict(os.environ, PYTHONPATH="")  # nothing of twin's venv leaks into the training venv
    subprocess.run(
        [str(py), str(HERE / "yolo_driver.py"), str(out / "spec.json"), str(out / "result.json")], check=True, env=env
    )
    wall = time.perf_counter() - t
    result = json.loads((out / "result.json").read_text())
    card.update(
        model="YOLOv8n (ultralytics, from yolov8n.yaml, no pretrained weights)",
        licence="trained with ultralytics (AGPL-3.0); twin's runtime runs the ONNX export with onnxruntime",
        epochs=args.epochs,
        imgsz=args.imgsz,
        batch=args.batch,
        device=args.device,
        wall_time_s=round(wall, 1),
        train_time_s=round(result["train_s"], 1),
        machine=f"{platform.machine()}, {os.cpu_count()} CPUs ({result.get('machine') or platform.processor()})",
        torch=result["torch"],
        names=result["names"],
        val=result["val"],
        test=result["test"],
        command=command,
    )
    (out / "model_card.json").write_text(json.dumps(card, indent=1))
    print(
        f"trained in {wall / 60:.1f} min; test mAP50 {result['test']['map50']:.3f}, "
        f"mAP50-95 {result['test']['map50_95']:.3f}"
    )
    for name, (m50, m) in sorted(result["test"]["per_class"].items()):
        print(f"  {name:12} mAP50 {m50:.3f}  mAP50-95 {m:.3f}")
    if args.ship:
        MODELS.mkdir(parents=True, exist_ok=True)
        (MODELS / f"{MODEL_NAME}.onnx").write_bytes(Path(result["onnx"]).read_bytes())
        (MODELS / f"{MODEL_NAME}.json").write_text(json.dumps(card, indent=1))
        print(f"shipped {MODELS / (MODEL_NAME + '.onnx')} and its card")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
