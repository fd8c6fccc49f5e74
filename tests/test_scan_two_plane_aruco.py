"""Two-plane capture with ArUco markers (``gnomon simulate two_plane --markers aruco``): scanned with no hints.

The field log names each plane's markers by ID and centre only; the planes'
poses, and the camera's, come from the markers found in the first frame
(gnomon.camera.aruco). Bars as for the checker markers with hints
(tests/test_scan_two_plane.py): each plane within 0.2° and 0.2 % of its true
normal and distance in the camera frame; the camera pose within 0.1° and
0.2 % of the camera distance; depth RMS ≤ 0.15 % of the camera distance over
the swept pixels, coverage ≥ 90 %.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from gnomon.runs.accuracy import depth_accuracy
from gnomon.runs.scan import ScanOptions, run_scan
from gnomon.simulate import TwoPlaneConfig, simulate_two_plane
from gnomon.util import toml_io


@pytest.fixture(scope="module")
def aruco_scan(tmp_path_factory):
    root = tmp_path_factory.mktemp("two_plane_aruco")
    simulate_two_plane(root / "capture", TwoPlaneConfig(seed=4, markers="aruco"))
    log_path = root / "capture" / "field_log.toml"
    log = tomllib.loads(log_path.read_text())
    log["camera"].pop("pose")  # the markers set it
    toml_io.dump(log, log_path)
    result = run_scan(log_path, root / "scan", ScanOptions(progress=False, rrd=False))
    return root, log, result, dict(np.load(root / "capture" / "ground_truth.npz"))


@pytest.mark.slow
def test_the_field_log_has_ids_and_no_pixels(aruco_scan) -> None:
    _, log, _, _ = aruco_scan
    for plane in log["planes"]:
        assert "markers" not in plane
        assert plane["aruco"]["dictionary"] == "DICT_4X4_50" and len(plane["aruco"]["markers"]) == 4
        assert all(set(m) == {"id", "plane_xy"} for m in plane["aruco"]["markers"])


@pytest.mark.slow
def test_planes_and_camera_pose_from_aruco_markers(aruco_scan) -> None:
    _, _, result, truth = aruco_scan
    R, t = truth["R"], truth["t"].ravel()
    planes = {p["plane"]: p for p in result.report["reference_planes"]}
    assert set(planes) == {"desk", "wall"}
    for k, name in enumerate(("desk", "wall")):
        n_true = R @ truth["plane_normals"][k]
        d_true = float(n_true @ (R @ truth["plane_points"][k] + t))
        if d_true < 0:
            n_true, d_true = -n_true, -d_true
        p = planes[name]
        ang = float(np.degrees(np.arccos(min(1.0, abs(float(np.dot(p["normal_cam"], n_true)))))))
        off = p["offset_cam"] / d_true - 1
        print(f"\n[two_plane aruco, {name}] normal {ang:.4f}°  offset {100 * off:+.4f} %  "
              f"RMS {p['rms_px']:.3f} px over {p['n_points']} corners")
        assert p["method"] == "aruco" and p["n_points"] == 16
        assert ang < 0.2 and abs(off) < 0.002
        assert p["rms_px"] < 0.3
    rvec = np.array(result.report["camera"]["pose"]["rvec"])
    tvec = np.array(result.report["camera"]["pose"]["tvec"])
    assert np.linalg.norm(tvec - truth["tvec"].ravel()) < 0.002 * float(truth["camera_distance_mm"])
    assert np.degrees(np.linalg.norm(rvec - truth["rvec"].ravel())) < 0.1


@pytest.mark.slow
def test_depth_and_coverage(aruco_scan) -> None:
    _, _, result, truth = aruco_scan
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], float(truth["camera_distance_mm"]))
    print(acc.table("two_plane aruco"))
    assert acc.rms_pct <= 0.15
    assert acc.coverage >= 0.90
