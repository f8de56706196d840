"""Perception: from rendered RGB-D frames to a base-frame scene model, without simulator ground truth.

Modules (import what you need; importing this package loads neither open3d nor PyBullet):

- `capture`: take a frame (settle, wrist capture pose, sensor model) and what the robot knows of the
  camera pose; `noise`: the D435i-like depth noise and dropouts.
- `aruco`: camera-to-base calibration from the base marker (`calibrate`).
- `warehouse`: the seed-000/001 cube_detector (`perceive_warehouse` -> BoxBounds + labelled cubes).
- `detection`: the `Detection` type, the `Detector` plugin protocol and the frame-wide `SceneCloud`;
  `robocup`: the seed-002 pose estimation (PCA rules, ICP, grasp vector); `pipeline`: detector + pose
  estimation in one call (`perceive_robocup`), camera extrinsics.
- `evaluate`: scoring against ground truth (`run_perception`, `run_calibration`: `twin perceive`,
  `twin calibrate`) - the only module here that reads ground truth.
- `geometry`, `segmentation`, `colors`: planes, PCA, trimmed ICP, DBSCAN clusters, colour labels.
"""
