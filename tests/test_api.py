"""The Python API: gnomon.scan in-process against the CLI's files, load_scan, simulate."""

from __future__ import annotations

import json

import cv2
import numpy as np
import plyfile
import pytest

import gnomon
from gnomon.cli import main
from gnomon.errors import GnomonError


@pytest.fixture(scope="module")
def in_memory(desk_scan):
    return gnomon.scan(desk_scan / "capture" / "field_log.toml")


@pytest.mark.slow
def test_scan_in_process_matches_the_files_the_cli_wrote(desk_scan, in_memory) -> None:
    s, files = in_memory, desk_scan / "scan"
    assert s.folder is None
    for name, arr in (("depth", s.depth), ("sigma", s.sigma), ("shadow_time", s.shadow_time),
                      ("undersampled", s.undersampled)):
        np.testing.assert_array_equal(arr, np.load(files / f"{name}.npy"), err_msg=name)
    v = plyfile.PlyData.read(str(files / "points.ply"))["vertex"].data
    np.testing.assert_array_equal(s.points, np.stack([v["x"], v["y"], v["z"]], axis=1))
    np.testing.assert_array_equal(s.normals, np.stack([v["nx"], v["ny"], v["nz"]], axis=1))
    np.testing.assert_array_equal(s.colors, np.stack([v["red"], v["green"], v["blue"]], axis=1))
    np.testing.assert_array_equal(s.point_sigma, v["scalar_sigma"])
    m = plyfile.PlyData.read(str(files / "mesh.ply"))
    np.testing.assert_array_equal(s.mesh.faces, np.stack(m["face"].data["vertex_indices"]))
    report = json.loads((files / "report.json").read_text())
    assert s.report["coverage"] == report["coverage"]
    assert s.warnings == report["warnings"]


@pytest.mark.slow
def test_depth_npz_carries_the_camera_that_reprojects_the_points(desk_scan, in_memory) -> None:
    with np.load(desk_scan / "scan" / "depth.npz") as z:
        np.testing.assert_array_equal(z["depth"], in_memory.depth)
        np.testing.assert_array_equal(z["sigma"], in_memory.sigma)
        assert str(z["units"]) == "mm" and tuple(z["image_size"]) == (400, 300)
        K, dist, R, t = z["K"], z["dist"], z["R"], z["t"]
        gt = np.load(desk_scan / "capture" / "ground_truth.npz")
        np.testing.assert_allclose(K, gt["K"], rtol=1e-12)
        np.testing.assert_allclose(R, gt["R"], atol=1e-12)
        # world points → camera: Z is the depth map; → image: the pixel the point came from
        cam = in_memory.points.astype(np.float64) @ R.T + t
        u, v = in_memory.pixels[:, 0].astype(int), in_memory.pixels[:, 1].astype(int)
        np.testing.assert_allclose(cam[:, 2], z["depth"][v, u], rtol=1e-6)
        px, _ = cv2.projectPoints(in_memory.points.astype(np.float64), z["rvec"], t, K, dist)
        assert np.max(np.abs(px[:, 0] - in_memory.pixels)) < 0.01  # pixels (float32 points)


@pytest.mark.slow
def test_load_scan_reads_a_folder_back(desk_scan, in_memory) -> None:
    back = gnomon.load_scan(desk_scan / "scan")
    assert back.folder == desk_scan / "scan"
    np.testing.assert_array_equal(back.depth, in_memory.depth)
    np.testing.assert_array_equal(back.points, in_memory.points)
    np.testing.assert_array_equal(back.normals, in_memory.normals)
    np.testing.assert_array_equal(back.rgb, in_memory.rgb)
    np.testing.assert_array_equal(back.mesh.faces, in_memory.mesh.faces)
    np.testing.assert_array_equal(back.coverage, in_memory.coverage)  # coverage.npy: why a pixel has no point
    np.testing.assert_allclose(back.camera_centre, in_memory.camera_centre)
    assert back.valid.sum() == len(back.points)


def test_load_scan_names_what_is_missing(tmp_path) -> None:
    with pytest.raises(GnomonError, match="not a scan output folder"):
        gnomon.load_scan(tmp_path / "nowhere")
    with pytest.raises(GnomonError, match="report.json"):
        gnomon.load_scan(tmp_path)


def test_the_package_exposes_a_small_documented_api() -> None:
    assert sorted(gnomon.__all__) == sorted(["GnomonError", "Scan", "ScanMesh", "__version__", "fuse", "load_scan",
                                             "scan", "simulate"])
    for name in ("scan", "load_scan", "Scan"):
        assert getattr(gnomon, name).__doc__
    # gnomon.fuse is the fusion package and the function (several scans into one model)
    assert callable(gnomon.fuse) and gnomon.fuse.register_views.__doc__
    # gnomon.simulate is the simulator package and the function
    assert callable(gnomon.simulate) and gnomon.simulate.DeskLampConfig is not None
    with pytest.raises(GnomonError, match="unknown scene"):
        gnomon.simulate("moon", "x")
    with pytest.raises(GnomonError, match="unexpected keyword"):
        gnomon.simulate("desk_lamp", "x", wobble=3)


def test_the_cli_scan_is_the_api_scan(tiny_capture, tmp_path, monkeypatch, capsys) -> None:
    """`gnomon scan` calls gnomon.api.scan with its options (a pass-through wrapper records the call;
    the real function runs) and prints that call's result: the files are the returned Scan's."""
    import gnomon.api

    calls = []
    real = gnomon.api.scan

    def recorded(*args, **kwargs):
        calls.append([args, kwargs, None])
        calls[-1][2] = real(*args, **kwargs)
        return calls[-1][2]

    monkeypatch.setattr(gnomon.api, "scan", recorded)
    out = tmp_path / "out"
    assert main(["scan", str(tiny_capture), "--out", str(out), "--no-rrd", "--quiet", "--frame-stride", "3"]) == 0
    assert len(calls) == 1
    args, kwargs, s = calls[0]
    assert args == (tiny_capture, out)
    assert kwargs == {"rrd": False, "rrd_path": None, "view": False, "progress": False, "frame_stride": 3,
                      "tiles": None, "scheduler": None, "workers": None, "mesh_formats": None,
                      "cloud_formats": None, "crs": None, "rrd_full": False}
    assert s.folder == out and not (out / "scan.rrd").exists()
    v = plyfile.PlyData.read(str(out / "points.ply"))["vertex"].data
    np.testing.assert_array_equal(s.points, np.stack([v["x"], v["y"], v["z"]], axis=1))
    assert f"{len(s.points)} points" in capsys.readouterr().out
    # the options' checks are the API's: a misplaced --workers fails inside gnomon.api.scan
    assert main(["scan", str(tiny_capture), "--out", str(out), "--workers", "2"]) == 2
    assert len(calls) == 2 and calls[1][1]["workers"] == 2 and calls[1][2] is None
    assert "are for tiled scans" in capsys.readouterr().err


@pytest.mark.slow
def test_simulate_knows_every_scene_of_the_cli(tmp_path) -> None:
    """gnomon.simulate renders each scene `gnomon simulate` offers, with the scene's own settings."""
    import tomllib

    from gnomon.api import SCENES
    from gnomon.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["simulate"]
    assert set(next(a for a in sub._actions if a.dest == "scene").choices) == set(SCENES)
    small = {"width": 160, "height": 120, "frames": 16}

    day = gnomon.simulate("facade_day", tmp_path / "day", **small, clouds=2)
    truth = json.loads((day.parent / "ground_truth.json").read_text())
    assert truth["scene"] == "facade_day" and truth["frame_count"] == 16
    assert truth["config"]["full_day"] and truth["config"]["post"] and truth["config"]["clouds"] == 2
    # FacadeSunConfig.day(): 06:40 local in Zurich (UTC+1 in November) for 11 h
    assert truth["first_frame_utc"].startswith("2026-11-12T05:40") and truth["last_frame_utc"].startswith(
        "2026-11-12T16:40")

    aruco = gnomon.simulate("two_plane", tmp_path / "aruco", **small, markers="aruco")
    log = tomllib.loads(aruco.read_text())
    assert [m["id"] for p in log["planes"] for m in p.get("aruco", {}).get("markers", [])]

    left = json.loads((gnomon.simulate("desk_lamp", tmp_path / "l", **small, pencil_photos=0).parent
                       / "ground_truth.json").read_text())
    right = json.loads((gnomon.simulate("desk_lamp_right", tmp_path / "r", **small, pencil_photos=0).parent
                        / "ground_truth.json").read_text())
    def lamp_x_in_camera(t: dict) -> float:  # the lamp's x in the camera frame (x to the image's right)
        R = cv2.Rodrigues(np.asarray(t["rvec"], float))[0]
        return float((R @ np.asarray(t["lamp"], float) + np.asarray(t["tvec"], float))[0])

    assert right["lamp_side"] == "right" and lamp_x_in_camera(left) < 0 < lamp_x_in_camera(right)

    board = gnomon.simulate("chessboard", tmp_path / "board", width=320, height=240, seed=1)
    assert board == tmp_path / "board" and len(list(board.glob("view_*.png"))) == 12
    assert cv2.imread(str(board / "view_00.png")).shape[:2] == (240, 320)
    with pytest.raises(GnomonError, match="--seed"):
        gnomon.simulate("desk_lamp", tmp_path / "x", seed=-1)


def test_a_scan_prints_a_short_summary_and_every_stage_shows_progress(tiny_capture, tmp_path, capsys) -> None:
    """print(scan) is a summary, not the arrays; `gnomon scan` says each stage on stderr (tracking has its bar)."""
    out = tmp_path / "s"
    assert main(["scan", str(tiny_capture), "--out", str(out), "--no-rrd"]) == 0
    err = capsys.readouterr().err
    stages = [line.split(": ", 1)[1].rsplit(" ", 2)[0] for line in err.splitlines() if line.startswith("scan: ")]
    assert stages == ["set-up (field log, camera, reference planes)", "shadow planes and triangulation",
                      "fusion and mesh", "output files", "report"]
    s = gnomon.load_scan(out)
    text = repr(s)
    assert len(text) < 400 and f"{len(s.points):,} of 48×36 pixels" in text and "array" not in text
    assert "<table>" in s._repr_html_()
