"""The focal length from the reference planes' marks (gnomon.config.setup.fit_focal, gnomon calibrate focal).

Synthetic marks: the corners of a 152 × 121 mm rectangle on a desk and on a wall 90° to it (as the
phone captures of the CMU 15-463 assignment), filmed by a 1920×1080 camera at 1400 px whose camera file
says 1000 px (a zoom since the calibration), the pixels with 0.5 px of Gaussian noise.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gnomon.camera.models import OpenCVCamera
from gnomon.cli import main as gnomon
from gnomon.config.setup import fit_focal
from gnomon.util import toml_io

RECT = np.array([[0.0, 0.0], [152.0, 0.0], [152.0, 121.0], [0.0, 121.0]])
# plane → camera: the desk tilted 55° away below the optical axis, the wall above it turned 30° and 25°
DESK = (cv2.Rodrigues(np.array([np.radians(125.0), 0.0, 0.0]))[0], np.array([-76.0, 90.0, 520.0]))
WALL = (cv2.Rodrigues(np.array([np.radians(150.0), np.radians(25.0), 0.0]))[0], np.array([-76.0, -20.0, 640.0]))
NOISE_PX = 0.5


def film(f: float, pose, marks: np.ndarray = RECT, seed: int = 0) -> np.ndarray:
    R, t = pose
    cam = OpenCVCamera(1920, 1080, f, f, 959.5, 539.5)
    pix = cam.project(np.c_[marks, np.zeros(len(marks))] @ R.T + t)
    return pix + np.random.default_rng(seed).normal(0.0, NOISE_PX, pix.shape)


CALIBRATED = OpenCVCamera(1920, 1080, 1000.0, 1000.0, 959.5, 539.5)


def test_the_focal_length_of_a_zoomed_camera_comes_back_from_two_planes_marks_with_its_sigma() -> None:
    """Both planes at 1400 px: the fit finds × 1.4 within 3 of its own σ, the σ (from the χ² at the marks'
    0.5 px) small enough to tell a zoom (a few %), and each plane's residual falls from tens of px at the
    calibrated focal length to the noise at the fitted one."""
    sig = np.full(4, NOISE_PX)
    fit = fit_focal(CALIBRATED, [("desk", RECT, film(1400.0, DESK, seed=1), sig),
                                 ("wall", RECT, film(1400.0, WALL, seed=2), sig)])
    assert np.isfinite(fit.sigma_factor) and fit.sigma_factor < 0.05
    assert abs(fit.factor - 1.4) < 3.0 * fit.sigma_factor
    assert abs(fit.focal_px - 1000.0 * fit.factor) < 1e-9
    assert all(r > 4.0 * NOISE_PX for r in fit.rms_camera_px)
    assert all(r < 3.0 * NOISE_PX for r in fit.rms_fit_px)
    assert all(r < 3.0 * NOISE_PX for r in fit.alone_rms_px)
    assert fit.planes == ("desk", "wall")


def test_a_plane_whose_marks_no_focal_length_fits_shows_in_the_fit() -> None:
    """The wall's top-right mark drawn 8 mm off (about 10 px): the joint factor stays within 3 σ of the
    truth, and the wall alone still leaves several px at its best factor while the desk alone fits to the
    noise: the report shows which plane is at fault."""
    sig = np.full(4, NOISE_PX)
    moved = RECT.copy()
    moved[2] += [0.0, 8.0]
    wall_pix = film(1400.0, WALL, moved, seed=4)
    fit = fit_focal(CALIBRATED, [("desk", RECT, film(1400.0, DESK, seed=3), sig), ("wall", RECT, wall_pix, sig)])
    assert abs(fit.factor - 1.4) < 3.0 * fit.sigma_factor
    assert fit.alone_rms_px[0] < 3.0 * NOISE_PX
    assert fit.alone_rms_px[1] > 4.0 * NOISE_PX
    assert fit.rms_fit_px[1] > 4.0 * NOISE_PX


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_calibrate_focal_writes_the_camera_file_with_the_fitted_focal_length(tmp_path) -> None:
    """gnomon calibrate focal on a field log whose planes' marks are given as pixels: it writes the camera
    file with fx, fy scaled by the fit (principal point, size and distortion as the camera's), the evidence
    as its header; --planes restricts the fit; an unknown plane is a one-line error with exit code 2."""
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(2):
        cv2.imwrite(str(frames / f"f_{i}.png"), np.full((1080, 1920), 128, np.uint8))
    toml_io.dump({"model": "opencv", "width": 1920, "height": 1080, "fx": 1000.0, "fy": 1000.0, "cx": 959.5,
                  "cy": 539.5, "dist": [0.0] * 5}, tmp_path / "camera.toml")

    def plane(name: str, pixels: np.ndarray) -> dict:
        return {"name": name, "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "x_axis": [1.0, 0.0, 0.0],
                "markers": [{"id": k, "plane_xy": list(p), "pixel": [float(u), float(v)]}
                            for k, (p, (u, v)) in enumerate(zip(RECT, pixels, strict=True))]}

    log = {"capture": {"frames": "frames/*.png"}, "camera": {"file": "camera.toml"},
           "planes": [plane("desk", film(1400.0, DESK, seed=5)), plane("wall", film(1400.0, WALL, seed=6))],
           "light": {"kind": "two-plane"}}
    toml_io.dump(log, tmp_path / "field_log.toml")
    out = tmp_path / "zoomed.toml"
    assert gnomon(["calibrate", "focal", str(tmp_path / "field_log.toml"), "--out", str(out)]) == 0
    cam = toml_io.load(out)
    factor = cam["fx"] / 1000.0
    assert abs(factor - 1.4) < 0.05 and abs(cam["fy"] / cam["fx"] - 1.0) < 1e-12
    assert (cam["cx"], cam["cy"], cam["width"], cam["height"]) == (959.5, 539.5, 1920, 1080)
    assert "desk: marks fit to" in out.read_text() and "wall: marks fit to" in out.read_text()
    desk_only = tmp_path / "desk.toml"
    assert gnomon(["calibrate", "focal", str(tmp_path / "field_log.toml"), "--planes", "desk",
                   "--out", str(desk_only)]) == 0
    assert "wall: marks" not in desk_only.read_text()
    assert gnomon(["calibrate", "focal", str(tmp_path / "field_log.toml"), "--planes", "floor",
                   "--out", str(tmp_path / "x.toml")]) == 2
    assert not (tmp_path / "x.toml").exists()
    # filmed at the camera's own focal length, one desk mark 12 px off: the best factor (× 1.05 ± 0.06) is
    # within 2 σ of the camera's own, so nothing is written (the marks are off, not the camera)
    off = film(1000.0, DESK, seed=5)
    off[2] += [0.0, 12.0]
    log["planes"] = [plane("desk", off), plane("wall", film(1000.0, WALL, seed=6))]
    toml_io.dump(log, tmp_path / "off.toml")
    assert gnomon(["calibrate", "focal", str(tmp_path / "off.toml"), "--out", str(tmp_path / "y.toml")]) == 2
    assert not (tmp_path / "y.toml").exists()
