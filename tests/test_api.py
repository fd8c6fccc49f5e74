"""The Python API: gnomon.scan in-process against the CLI's files, load_scan, simulate."""

from __future__ import annotations

import json

import cv2
import numpy as np
import plyfile
import pytest

import gnomon
from gnomon.errors import GnomonError


@pytest.fixture(scope="module")
def in_memory(desk_scan):
    return gnomon.scan(desk_scan / "capture" / "field_log.toml")


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
    np.testing.assert_array_equal(s.point_sigma, v["sigma"])
    m = plyfile.PlyData.read(str(files / "mesh.ply"))
    np.testing.assert_array_equal(s.mesh.faces, np.stack(m["face"].data["vertex_indices"]))
    report = json.loads((files / "report.json").read_text())
    assert s.report["coverage"] == report["coverage"]
    assert s.warnings == report["warnings"]


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


def test_load_scan_reads_a_folder_back(desk_scan, in_memory) -> None:
    back = gnomon.load_scan(desk_scan / "scan")
    assert back.folder == desk_scan / "scan"
    np.testing.assert_array_equal(back.depth, in_memory.depth)
    np.testing.assert_array_equal(back.points, in_memory.points)
    np.testing.assert_array_equal(back.normals, in_memory.normals)
    np.testing.assert_array_equal(back.rgb, in_memory.rgb)
    np.testing.assert_array_equal(back.mesh.faces, in_memory.mesh.faces)
    np.testing.assert_allclose(back.camera_centre, in_memory.camera_centre)
    assert back.valid.sum() == len(back.points)


def test_load_scan_names_what_is_missing(tmp_path) -> None:
    with pytest.raises(GnomonError, match="not a scan output folder"):
        gnomon.load_scan(tmp_path / "nowhere")
    with pytest.raises(GnomonError, match="report.json"):
        gnomon.load_scan(tmp_path)


def test_the_package_exposes_a_small_documented_api() -> None:
    assert sorted(gnomon.__all__) == sorted(["GnomonError", "Scan", "ScanMesh", "__version__", "load_scan", "scan",
                                             "simulate"])
    for name in ("scan", "load_scan", "Scan"):
        assert getattr(gnomon, name).__doc__
    # gnomon.simulate is the simulator package and the function
    assert callable(gnomon.simulate) and gnomon.simulate.DeskLampConfig is not None
    with pytest.raises(GnomonError, match="unknown scene"):
        gnomon.simulate("moon", "x")
    with pytest.raises(GnomonError, match="unexpected keyword"):
        gnomon.simulate("desk_lamp", "x", wobble=3)
