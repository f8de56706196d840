"""Files generated from a config for the simulator: the ArUco marker's texture and the quad that shows it.

They are made once per marker (dictionary, id) and kept in twin's cache directory (`twin.resources.
cache_dir`: `$TWIN_CACHE`, else `~/.cache/twin`), never in the package or the checkout. Every file is
written atomically (a temporary file, then a rename), so workers building worlds at the same time never
read a half-written one; the content depends on the marker alone, so whoever writes last writes the same.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from twin.config import ArucoSettings
from twin.errors import ConfigError, WorldError
from twin.resources import cache_dir
from twin.scene_layout import MARKER_MARGIN_FRACTION

__all__ = ["MARKER_PX", "digest", "marker_quad_obj", "write_atomic"]

MARKER_PX = 600  # texture pixels across the black marker square
_MARKER_ASSET_VERSION = "v1"  # bump when the generated marker files change shape


def digest(obj: Any, n: int = 8) -> str:
    """A short stable hash of JSON-able data (key order does not matter): run ids, cached assets' names."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


def write_atomic(path: Path, data: bytes) -> None:
    """Write a cache file so that concurrent workers never read a half-written one."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def marker_quad_obj(aruco: ArucoSettings) -> Path:
    """The OBJ of a unit quad (z = 0, normal +z) textured with the marker `aruco` names, with its white
    quiet zone; its MTL and PNG lie beside it. Generated on first use, then read from the cache.

    Raises ConfigError for a dictionary or id OpenCV does not know.
    """
    import cv2  # only the world needs OpenCV at build time, and only for the marker texture

    dict_id = getattr(cv2.aruco, aruco.dictionary, None)
    if not isinstance(dict_id, int) or not aruco.dictionary.startswith("DICT_"):
        raise ConfigError(f"aruco.dictionary {aruco.dictionary!r} is not a cv2.aruco dictionary (e.g. DICT_4X4_50)")
    cache = cache_dir("generated")
    stem = f"aruco_{aruco.dictionary}_{aruco.id}_{_MARKER_ASSET_VERSION}"
    png, mtl, obj = (cache / f"{stem}.{ext}" for ext in ("png", "mtl", "obj"))
    if png.is_file() and mtl.is_file() and obj.is_file():
        return obj
    dictionary = cv2.aruco.getPredefinedDictionary(dict_id)
    try:
        img = cv2.aruco.generateImageMarker(dictionary, aruco.id, MARKER_PX, borderBits=1)
    except cv2.error as e:
        raise ConfigError(f"aruco.id {aruco.id} is not in {aruco.dictionary}: {' '.join(str(e).split())}") from None
    m = round(MARKER_PX * MARKER_MARGIN_FRACTION)
    img = cv2.copyMakeBorder(img, m, m, m, m, cv2.BORDER_CONSTANT, value=255)
    ok, buf = cv2.imencode(".png", cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    if not ok:
        raise WorldError("could not encode the ArUco marker image")
    write_atomic(png, buf.tobytes())
    write_atomic(mtl, f"newmtl aruco\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd {png.name}\n".encode())
    # unit quad in z = 0, normal +z; image top-left at (-0.5, +0.5) (OBJ v runs bottom to top)
    write_atomic(
        obj,
        (
            f"mtllib {mtl.name}\no aruco_quad\n"
            "v -0.5 -0.5 0\nv 0.5 -0.5 0\nv 0.5 0.5 0\nv -0.5 0.5 0\n"
            "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
            "usemtl aruco\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n"
        ).encode(),
    )
    return obj
