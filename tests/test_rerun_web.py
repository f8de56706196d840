"""A recording opens in Rerun's web viewer: `rerun --serve-web FILE.rrd --bind 127.0.0.1` serves it, headless Chromium
(software WebGL, no GPU) driven by playwright-core loads the page, and after the viewer has had time to load the
recording the screenshot shows it, not the loading screen: the saved layout's panels are drawn (many colours, most
of the page not background). The screenshot is kept in out/test-artifacts/ to look at.

Needs Debian's chromium and playwright-core (`.ci/run` installs both: npm into .venv/node); skipped, with the
reason, where either is missing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun")

from twin.config import PROJECT_ROOT

NODE_MODULES = PROJECT_ROOT / ".venv" / "node" / "node_modules"
ARTIFACTS = PROJECT_ROOT / "out" / "test-artifacts"
_WAIT_MS = 30_000  # the viewer's wasm, its shaders under SwiftShader and the recording: ~15 s here


@pytest.fixture(scope="module")
def browser() -> tuple[str, str]:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    node = shutil.which("node")
    if chromium is None:
        pytest.skip("no chromium on this machine (Debian: apt-get install chromium; .ci/run installs it)")
    if node is None or not (NODE_MODULES / "playwright-core").is_dir():
        pytest.skip(
            f"no playwright-core in {NODE_MODULES} (npm install --prefix .venv/node playwright-core; .ci/run does)"
        )
    return chromium, node


def test_the_web_viewer_shows_a_recording(browser, tmp_path):
    chromium, node = browser
    rrd = tmp_path / "run.rrd"
    from twin.config import load_config
    from twin.tasks import run_task

    pytest.importorskip("crocoddyl")  # a short warehouse run
    run_task(load_config("warehouse"), seed=0, planner="croc", rerun=str(rrd))
    from twin.rerun_log import LiveView

    server = LiveView.start(rrd)
    try:
        url = server.web_url
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        shot = ARTIFACTS / "rerun-web-viewer.png"
        env = dict(os.environ, NODE_PATH=str(NODE_MODULES))
        script = Path(__file__).parent / "browser" / "screenshot.js"
        done = subprocess.run(
            [node, str(script), url, str(shot), str(_WAIT_MS), chromium],
            env=env,
            capture_output=True,
            text=True,
            timeout=180,
            check=False,
        )
        assert done.returncode == 0, done.stderr
        assert json.loads(done.stdout.strip().splitlines()[-1])["title"] == "Rerun Viewer"
    finally:
        server.stop()
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB"))
    # measured here: the loading screen 2 colours and 94 % background; the warehouse recording ~23 000 colours and
    # 70 % (the 3-D view's light background counts)
    colours = len(np.unique(img.reshape(-1, 3), axis=0))
    background = np.all(img == img[img.shape[0] // 2, 2], axis=-1).mean()  # the colour at the left edge's middle
    assert colours > 1000, f"{colours} colours: the loading screen, not the recording ({shot})"
    assert background < 0.9, f"{background:.0%} of the page is background ({shot})"
