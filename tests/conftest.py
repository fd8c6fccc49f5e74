"""Shared fixtures: captures written to a temporary folder.

The simulated scenes are rendered once per session and shared by every test that
uses them; they are read-only: a test that changes a capture works on a copy
(:func:`copy_capture`).
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from gnomon.util import toml_io

# Tests never talk to the network and never open a viewer: rerun 0.41 turns its
# analytics off when CI is set, and a viewer can only start with a display.
os.environ.setdefault("CI", "1")
os.environ["TELEMETRY_ENABLED"] = "false"
os.environ.pop("DISPLAY", None)
os.environ.pop("WAYLAND_DISPLAY", None)


@pytest.fixture(autouse=True)
def _sys_path_as_it_was():
    """Whatever a test puts on sys.path (a benchmark script it loads puts the source tree first) is taken
    off after it: the subprocesses later tests start inherit sys.path as PYTHONPATH, and in a clean clone
    the source tree's gnomon has no compiled kernel (the installed one has)."""
    saved = list(sys.path)
    yield
    sys.path[:] = saved


def write_tiny_capture(folder: Path, *, n_frames: int = 24, width: int = 48, height: int = 36,
                       lamp=(-200.0, 0.0, 400.0), extra: dict | None = None, band_half_width: float = 5.0,
                       noise_dn: float = 0.0, time_jitter_frames: float = 0.0, dip_dn: float = 160.0,
                       min_contrast: float | None = 20.0) -> Path:
    """A minimal, valid capture: a dark band (its dark core ``2·band_half_width`` px wide, 6 px soft
    edges, ``dip_dn`` DN below the lit 200 DN) sweeping left→right from outside the image to outside it,
    a camera looking straight down at the desk from 500 mm, and its field log (``[scan] min_contrast``,
    None: none); ``noise_dn``: Gaussian noise (DN, seeded);
    ``time_jitter_frames``: each pixel sees the band that many frames late or early (Gaussian, fixed per
    pixel, seeded: a time error no image noise explains). Returns the log's path."""
    frames = folder / "frames"
    frames.mkdir(parents=True, exist_ok=True)
    u = np.arange(width)
    rng = np.random.default_rng(7)
    travel = band_half_width + 7.0  # the band starts and ends this far outside the image
    speed = (width + 2 * travel) / (n_frames - 1)  # px per frame
    late = rng.normal(0.0, time_jitter_frames, (height, width)) * speed if time_jitter_frames > 0 else 0.0
    for i in range(n_frames):
        centre = -travel + (width + 2 * travel) * i / (n_frames - 1) - late
        shadow = np.clip((np.abs(u - centre) - band_half_width) / 6.0, 0, 1)  # 1 = lit, soft edges
        image = (200 - dip_dn) + dip_dn * np.broadcast_to(shadow, (height, width))
        if noise_dn > 0:
            image = np.round(image + rng.normal(0.0, noise_dn, image.shape))
        cv2.imwrite(str(frames / f"frame_{i:04d}.png"), np.clip(image, 0, 255).astype(np.uint8))
    log = {
        "capture": {"frames": "frames/*.png", "units": "mm", "gamma": 1.0},
        "camera": {
            "model": "opencv", "width": width, "height": height,
            "fx": 60.0, "fy": 60.0, "cx": (width - 1) / 2, "cy": (height - 1) / 2,
            "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
            # Camera at z = 500 looking down: world z up maps to camera -z.
            "pose": {"rvec": [np.pi, 0.0, 0.0], "tvec": [0.0, 0.0, 500.0]},
        },
        "planes": [{"name": "desk", "point": [0, 0, 0], "normal": [0, 0, 1],
                    "regions": [[0, 0, width, 6], [0, height - 6, width, height]]}],
        "light": {"kind": "lamp", "position": list(lamp)},
        "scan": {} if min_contrast is None else {"min_contrast": min_contrast},
    }
    for section, values in (extra or {}).items():
        log.setdefault(section, {}).update(values)
    path = folder / "field_log.toml"
    toml_io.dump(log, path)
    return path


@pytest.fixture
def tiny_capture(tmp_path: Path) -> Path:
    return write_tiny_capture(tmp_path / "capture")


@pytest.fixture(scope="session")
def desk_scan(tmp_path_factory) -> Path:
    """A small desk_lamp capture (400×300, 120 frames) scanned by the CLI with every mesh format:
    ROOT/capture, ROOT/scan."""
    from gnomon.cli import main
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    root = tmp_path_factory.mktemp("desk_scan")
    simulate_desk_lamp(root / "capture", DeskLampConfig(width=400, height=300, frames=120, seed=5, pencil_photos=0))
    assert main(["scan", str(root / "capture" / "field_log.toml"), "--out", str(root / "scan"), "--quiet",
                 "--frame-stride", "10", "--mesh-formats", "all"]) == 0
    return root


@pytest.fixture(scope="session")
def two_plane_small(tmp_path_factory) -> Path:
    """A small two_plane capture (400×300, 120 frames; desk and wall with printed markers): its folder."""
    from gnomon.simulate import TwoPlaneConfig, simulate_two_plane

    root = tmp_path_factory.mktemp("two_plane_small")
    simulate_two_plane(root / "capture", TwoPlaneConfig(width=400, height=300, frames=120, seed=4))
    return root / "capture"


def encode_h264(frames, path: Path, *, fps: int, crf: int) -> None:
    """Write ``frames`` (uint8 arrays, RGB (H, W, 3) or grey (H, W)) as an H.264 video with PyAV
    (the ``test`` extra); ``crf`` 0 keeps the luma lossless."""
    import av

    out = av.open(str(path), "w")
    stream = out.add_stream("libx264", rate=fps)
    stream.pix_fmt = "yuv420p"
    stream.options = {"crf": str(crf)}
    for i, f in enumerate(frames):
        rgb = np.repeat(f[:, :, None], 3, axis=2) if f.ndim == 2 else f
        if i == 0:
            stream.height, stream.width = rgb.shape[:2]
        for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")):
            out.mux(packet)
    for packet in stream.encode():
        out.mux(packet)
    out.close()


def copy_capture(capture: Path, to: Path) -> Path:
    """A copy of a shared capture folder that a test may change; returns the copy's folder."""
    shutil.copytree(capture, to)
    return to


@pytest.fixture(scope="session")
def desk_lamp_full(tmp_path_factory) -> Path:
    """The full desk_lamp capture (800×600, 240 frames, seed 3, three pencil photos): its folder."""
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    root = tmp_path_factory.mktemp("desk_lamp_full")
    simulate_desk_lamp(root / "capture", DeskLampConfig(seed=3))
    return root / "capture"


@pytest.fixture(scope="session")
def desk_lamp_full_scan(desk_lamp_full, tmp_path_factory):
    """``desk_lamp_full`` scanned with the default options (no recording):
    ``(root, ScanResult, ground truth arrays)``; the scan is in ROOT/scan."""
    import numpy as np

    from gnomon.runs.scan import ScanOptions, run_scan

    root = tmp_path_factory.mktemp("desk_lamp_full_scan")
    result = run_scan(desk_lamp_full / "field_log.toml", root / "scan", ScanOptions(progress=False, rrd=False))
    return root, result, dict(np.load(desk_lamp_full / "ground_truth.npz"))
