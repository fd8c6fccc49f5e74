"""Shared fixtures: small captures written to a temporary folder."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from gnomon import toml_io

# Tests never talk to the network and never open a viewer: rerun 0.41 turns its
# analytics off when CI is set, and a viewer can only start with a display.
os.environ.setdefault("CI", "1")
os.environ["TELEMETRY_ENABLED"] = "false"
os.environ.pop("DISPLAY", None)
os.environ.pop("WAYLAND_DISPLAY", None)


def write_tiny_capture(folder: Path, *, n_frames: int = 24, width: int = 48, height: int = 36,
                       lamp=(-200.0, 0.0, 400.0), extra: dict | None = None) -> Path:
    """A minimal, valid capture: a dark band sweeping left→right, a camera looking
    straight down at the desk from 500 mm, and its field log. Returns the log's path."""
    frames = folder / "frames"
    frames.mkdir(parents=True, exist_ok=True)
    u = np.arange(width)
    for i in range(n_frames):
        centre = -12 + (width + 24) * i / (n_frames - 1)
        shadow = np.clip((np.abs(u - centre) - 5.0) / 6.0, 0, 1)  # 1 = lit, soft edges
        row = (40 + 160 * shadow).astype(np.uint8)
        cv2.imwrite(str(frames / f"frame_{i:04d}.png"), np.tile(row, (height, 1)))
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
        "scan": {"min_contrast": 20},
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
    """A small desk_lamp capture (400×300, 120 frames) scanned by the CLI: ROOT/capture, ROOT/scan."""
    from gnomon.cli import main
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    root = tmp_path_factory.mktemp("desk_scan")
    simulate_desk_lamp(root / "capture", DeskLampConfig(width=400, height=300, frames=120, seed=5, pencil_photos=0))
    assert main(["scan", str(root / "capture" / "field_log.toml"), "--out", str(root / "scan"), "--quiet",
                 "--frame-stride", "10"]) == 0
    return root


@pytest.fixture(scope="session")
def two_plane_small(tmp_path_factory) -> Path:
    """A small two_plane capture (400×300, 120 frames; desk and wall with printed markers): its folder."""
    from gnomon.simulate import TwoPlaneConfig, simulate_two_plane

    root = tmp_path_factory.mktemp("two_plane_small")
    simulate_two_plane(root / "capture", TwoPlaneConfig(width=400, height=300, frames=120, seed=4))
    return root / "capture"
