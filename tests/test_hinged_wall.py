"""The benchmark's wall hinged on the desk–wall fold (benchmarks/real_captures.py: find_fold, hinged_wall).

Synthetic: a 1920×1080 camera (f = 1800 px) sees a desk whose 152 × 121 mm rectangle of crosses is at
its origin, and a wall standing at 88° to it along the line y = 180 mm; the wall's crosses form the same
rectangle 20 mm above the fold. The real_captures script runs on real data only; these check its geometry.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from gnomon.camera.models import OpenCVCamera
from gnomon.util import toml_io

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from real_captures import find_fold, hinged_wall  # noqa: E402

RECT = np.array([[0.0, 0.0], [152.0, 0.0], [152.0, 121.0], [0.0, 121.0]])
CAM = OpenCVCamera(1920, 1080, 1800.0, 1800.0, 959.5, 539.5)



def _look_at(centre: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """desk → camera (R, t) of a camera at ``centre`` looking at ``target``, its x axis along the desk's x."""
    z = (target - centre) / np.linalg.norm(target - centre)
    x = np.cross(np.array([0.0, 0.0, -1.0]), z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ centre


# the camera 300 mm in front of the desk's crosses and 250 mm above it, looking at the corner's middle
R_DESK, T_DESK = _look_at(np.array([76.0, -300.0, 250.0]), np.array([76.0, 150.0, 40.0]))
ANGLE = np.radians(88.0)
UP = np.array([0.0, np.cos(ANGLE), np.sin(ANGLE)])  # up the wall, leaning 2° away from the camera
FOLD_Y = 180.0


def to_pixels(points_desk: np.ndarray) -> np.ndarray:
    return CAM.project(points_desk @ R_DESK.T + T_DESK)


def wall_points(xy: np.ndarray) -> np.ndarray:
    return np.array([0.0, FOLD_Y, 0.0]) + xy[:, :1] * np.array([1.0, 0.0, 0.0]) + (20.0 + xy[:, 1:]) * UP


def test_the_wall_hinged_on_the_fold_comes_back_at_its_angle(tmp_path) -> None:
    """Crosses with 1 px of noise (their σ), the fold sampled every 10 px: the hinged fit finds the wall at
    88° within 3 of its σ, its crosses' residual at the noise, and the hinge on the desk within 0.5 mm."""
    toml_io.dump({"model": "opencv", "width": 1920, "height": 1080, "fx": 1800.0, "fy": 1800.0, "cx": 959.5,
                  "cy": 539.5, "dist": [0.0] * 5}, tmp_path / "camera.toml")
    rng = np.random.default_rng(3)
    desk_px = to_pixels(np.c_[RECT, np.zeros(4)]) + rng.normal(0.0, 1.0, (4, 2))
    wall_px = to_pixels(wall_points(RECT)) + rng.normal(0.0, 1.0, (4, 2))
    fold_px = to_pixels(np.c_[np.linspace(-20.0, 170.0, 40), np.full(40, FOLD_Y), np.zeros(40)])
    h = hinged_wall(tmp_path / "camera.toml", desk_px, fold_px, wall_px)
    assert abs(h["angle_to_desk_deg"] - 88.0) < 3.0 * h["sigma_theta_deg"] + 0.2
    assert h["sigma_theta_deg"] < 3.0
    assert h["rms_px"] < 2.0
    assert h["hinge_rms_mm"] < 0.5 and abs(h["point"][1] - FOLD_Y) < 3.0


def test_find_fold_follows_a_thin_dark_line_to_a_fraction_of_a_pixel() -> None:
    """A 3-px dark line (30 DN deep, anti-aliased) across a 120-DN image at v = 800.3 + 0.02 (u − 400):
    every searched column finds it within 0.3 px; columns where it is too faint are skipped."""
    h, w = 1080, 1920
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    centre = 800.3 + 0.02 * (uu - 400.0)
    image = 120.0 - 30.0 * np.clip(2.0 - np.abs(vv - centre), 0.0, 1.0)
    image[:, 1500:] = 120.0 - 2.0 * np.clip(2.0 - np.abs(vv - centre), 0.0, 1.0)[:, 1500:]
    found = find_fold(np.round(image).astype(np.uint8), [(400, 600), (1550, 1600)], (760, 860))
    assert len(found) == 21  # the faint columns (2 DN) are skipped
    assert np.all(np.abs(found[:, 1] - (800.3 + 0.02 * (found[:, 0] - 400.0))) < 0.3)
