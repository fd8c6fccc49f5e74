"""Field-log parsing: valid logs load; every user mistake names the file and key."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon.config.fieldlog import load_field_log
from gnomon.errors import GnomonError
from gnomon.util import toml_io


def rewrite(path: Path, edit) -> Path:
    data = tomllib.loads(path.read_text())
    edit(data)
    toml_io.dump(data, path)
    return path


def test_valid_log_loads(tiny_capture: Path) -> None:
    log = load_field_log(tiny_capture)
    assert len(log.capture.image_files) == 24
    assert log.capture.units == "mm" and log.capture.gamma == 1.0
    assert log.camera.width == 48 and log.camera.height == 36
    # Camera 500 mm above the desk origin.
    np.testing.assert_allclose(log.pose.camera_centre_world, [0, 0, 500], atol=1e-9)
    assert log.planes[0].regions[1] == (0, 30, 48, 36)
    assert log.scan.edge == "both" and log.scan.min_contrast == 20
    assert log.capture.on_corrupt_frame == "error"  # corrupt frames are refused unless asked otherwise


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["light"].pop("position"), "[light] missing required key 'position'"),
        (lambda d: d["light"].update(postion=[1, 2, 3]), "[light] unknown key 'postion'"),
        (lambda d: d.pop("capture"), "missing required table [capture]"),
        (lambda d: d["camera"].update(fx="wide"), "[camera]: key 'fx' must be a number"),
        (lambda d: d["camera"].update(model="fisheye"), "[camera]: key 'model' must be"),
        (lambda d: d["camera"]["pose"].pop("tvec"), "[camera.pose] missing required key 'tvec'"),
        (lambda d: d["planes"][0].update(regions=[[0, 0, 480, 10]]), "outside the 48x36 image"),
        (lambda d: d["scan"].update(edge="both-ways"), "[scan] edge: expected one of"),
        (lambda d: d["capture"].update(on_corrupt_frame="ignore"), "[capture] on_corrupt_frame: expected one of"),
        (lambda d: d["scan"].update(max_dip_frames=200), "[scan] max_dip_frames: must be in 4..128"),
        (lambda d: d["scan"].update(max_dip_frames=3), "[scan] max_dip_frames: must be in 4..128"),
        (lambda d: d["scan"].update(max_dip_frames="wide"), "[scan] max_dip_frames: expected an integer"),
        (lambda d: d.update(extra={"a": 1}), "[field log] unknown key 'extra'"),
        (lambda d: d["capture"].update(frames="missing/*.png"), "frames folder"),
        (lambda d: d["capture"].update(frames="frames/*.tif"), "no files match"),
        (lambda d: d["light"].update(position=[0, 0, -300]), "below the plane 'desk'"),
        (lambda d: d["planes"][0].update(regions=[{"polygon": [[0, 0], [5, 5]]}]), "polygon: expected at least 3"),
        (lambda d: d["planes"][0].update(mask="nowhere.png"), "[planes.0] mask: "),
        (lambda d: d["planes"][0].update(x_axis=[1, 0, 0], markers=[
            {"plane_xy": [0, 0], "pixel": [1, 1], "pixel_hint": [1, 1]}] * 4), "give either 'pixel_hint'"),
    ],
)
def test_mistakes_name_file_and_key(tiny_capture: Path, edit, message: str) -> None:
    rewrite(tiny_capture, edit)
    with pytest.raises(GnomonError) as info:
        load_field_log(tiny_capture)
    text = str(info.value)
    assert message in text
    assert str(tiny_capture) in text
    assert "\n" not in text


def test_not_toml(tmp_path: Path) -> None:
    bad = tmp_path / "log.toml"
    bad.write_text("[capture\nframes = ")
    with pytest.raises(Exception) as info:
        load_field_log(bad)
    assert "not valid TOML" in str(info.value) and str(bad) in str(info.value)


@pytest.mark.slow
def test_a_tsai_camera_file_flows_into_the_scan(tmp_path: Path) -> None:
    """A camera file from `gnomon calibrate camera --model tsai` is used by `gnomon scan`."""
    import numpy as np

    from conftest import write_tiny_capture
    from gnomon.camera.models import TsaiCamera
    from gnomon.runs.scan import ScanOptions, run_scan

    log_path = write_tiny_capture(tmp_path / "cap")
    pitch = 0.005  # mm per pixel: f = 60 px · pitch
    toml_io.dump({"model": "tsai", "width": 48, "height": 36, "f_mm": 60 * pitch, "kappa1": 0.0,
                  "cx": 23.5, "cy": 17.5, "sx": 1.0, "dx_mm": pitch, "dy_mm": pitch,
                  "calibration": {"method": "tsai coplanar", "rms_px": 0.1}}, tmp_path / "cap" / "camera.toml")
    data = tomllib.loads(log_path.read_text())
    data["camera"] = {"file": "camera.toml", "pose": data["camera"]["pose"]}
    toml_io.dump(data, log_path)
    log = load_field_log(log_path)
    assert isinstance(log.camera, TsaiCamera) and log.calibration["rms_px"] == 0.1
    result = run_scan(log_path, tmp_path / "out", ScanOptions(progress=False, rrd=False))
    assert np.nanmedian(result.depth) == pytest.approx(500.0, rel=0.01)
    assert result.report["calibration"]["method"] == "tsai coplanar"


@pytest.mark.slow
def test_a_chessboard_on_the_plane_sets_the_pose(tmp_path: Path) -> None:
    """[[planes]] chessboard = "9x6", image = ...: the board's frame becomes the world frame, its z towards the
    camera (up from the desk)."""
    import cv2
    import numpy as np

    from conftest import write_tiny_capture
    from gnomon.capture.frames import FrameSource
    from gnomon.cli import main
    from gnomon.config.setup import resolve_reference_planes

    assert main(["simulate", "chessboard", "--out", str(tmp_path / "cb"), "--width", "640", "--height", "480"]) == 0
    truth = tomllib.loads((tmp_path / "cb" / "truth.toml").read_text())
    log_path = write_tiny_capture(tmp_path / "cap")
    data = tomllib.loads(log_path.read_text())
    data["camera"] = truth["camera"]
    # The frames are 48x36 (same aspect as the 640x480 camera, which is rescaled to
    # them); the board's photo is at the camera's own 640x480.
    data["planes"] = [{"name": "desk", "point": [0, 0, 0], "normal": [0, 0, 1], "regions": [[0, 0, 48, 2]],
                       "chessboard": "9x6", "square": 25.0, "image": "../cb/view_00.png"}]
    data["light"]["position"] = [0.0, 0.0, 400.0]  # the board's z points to the camera (up from the desk)
    toml_io.dump(data, log_path)
    log = load_field_log(log_path)
    assert log.pose is None
    log, report = resolve_reference_planes(log, FrameSource(log.capture.image_files))
    view = truth["views"][0]
    # the rendered board's frame (OpenCV's: z away from the camera) turned a half-turn about its x axis
    R_view = cv2.Rodrigues(np.array(view["rvec"]))[0]
    assert R_view[:, 2] @ np.array(view["tvec"]) > 0
    np.testing.assert_allclose(log.pose.t, view["tvec"], atol=0.002 * np.linalg.norm(view["tvec"]))
    np.testing.assert_allclose(log.pose.R, R_view @ np.diag([1.0, -1.0, -1.0]), atol=np.radians(0.1))
    assert log.pose.camera_centre_world[2] > 0
    assert report[0]["method"] == "chessboard" and report[0]["rms_px"] < 0.3


def test_regions_as_rectangles_polygons_and_a_mask(tiny_capture: Path) -> None:
    import cv2

    from gnomon.config.setup import plane_region_mask

    mask = np.zeros((36, 48), dtype=np.uint8)
    mask[20:25, 40:46] = 255
    cv2.imwrite(str(tiny_capture.parent / "desk_mask.png"), mask)
    rewrite(tiny_capture, lambda d: d["planes"][0].update(
        regions=[[0, 0, 10, 4], {"polygon": [[20, 10], [30, 10], [30, 20]]}], mask="desk_mask.png"))
    plane = load_field_log(tiny_capture).planes[0]
    m = plane_region_mask(plane, (36, 48))
    assert m[0:4, 0:10].all() and not m[4, 0]
    assert m[12, 29] and not m[19, 21]  # inside / outside the triangle (pixel centres)
    assert m[20:25, 40:46].all()
    assert m.sum() == 40 + int(m[10:21, 20:31].sum()) + 30
