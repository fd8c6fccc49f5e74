"""Reference planes from ArUco markers and ChArUco boards, found by their IDs (gnomon.camera.aruco).

Ground truth from gnomon.simulate.marker_images (own ray casting and projection; the
marker bitmaps and the ChArUco layout are OpenCV's published definitions).
Scene: the desk-and-wall scene of tests/test_markers.py, with 4 ArUco
markers (DICT_4X4_50, 50 mm, ids 0–3 desk, 10–13 wall) instead of the 2×2
checkers; rendered in linear intensity (no gamma; 2×2 samples per pixel), 1 DN noise, blur σ 0.7 px.
Bars: the plane's normal within 0.2° and its offset within 0.2 %, as for the
checker markers.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gnomon.camera import aruco
from gnomon.camera.models import OpenCVCamera
from gnomon.errors import GnomonError
from gnomon.simulate import chessboard as simcb
from gnomon.simulate import marker_images as simmk

SIZE = 50.0


def angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(abs(np.dot(a, b)) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def as_opencv(t: simcb.TruthPinhole) -> OpenCVCamera:
    return OpenCVCamera(t.width, t.height, t.fx, t.fy, t.cx, t.cy, t.dist)


BOARD = simmk.CharucoPrint("DICT_5X5_50", (7, 5), 40.0, 30.0, origin=(-140.0, 100.0))


@pytest.fixture(scope="module")
def scene():
    """One frame: ArUco markers on desk and wall, a ChArUco board (another dictionary) on the desk
    between them, and a card standing on the board's right-hand part."""
    truth = simcb.default_truth_camera(960, 720)
    sc = simmk.desk_and_wall_scene(truth)
    planes = []
    for base, plane in zip((0, 10), sc.planes, strict=True):
        ms = tuple(dataclasses.replace(m, size=SIZE, aruco_id=base + k) for k, m in enumerate(plane.markers))
        planes.append(dataclasses.replace(plane, markers=ms, charuco=BOARD if base == 0 else None))
    card = simmk.ScenePlane("card", origin=(60.0, -120.0, 0.0), x_axis=(1.0, 0.0, 0.0), y_axis=(0.0, 0.0, 1.0),
                            extent=(0.0, 120.0, 0.0, 90.0), albedo=0.3)
    sc = dataclasses.replace(sc, planes=(*planes, card))
    img = simmk.render(sc, simcb.SampleRays(truth, 2), seed=1)
    return sc, img


def _markers(plane):
    return {m.aruco_id: m.ab for m in plane.markers}


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
@pytest.mark.parametrize("name", ["desk", "wall"])
def test_plane_from_aruco_markers_without_hints(scene, name):
    sc, img = scene
    plane = next(p for p in sc.planes if p.name == name)
    pp = aruco.plane_pose_from_aruco(img, as_opencv(sc.camera), _markers(plane), "DICT_4X4_50", SIZE,
                                     linear=img.astype(np.float64), source="frame.png")
    n_true, d_true = sc.plane_in_camera(plane)
    truth_px = np.concatenate([
        sc.camera.project(plane.to_world(simmk.aruco_corners(m.ab, SIZE)) @ sc.R.T + sc.t) for m in plane.markers
    ])
    corner_err = np.linalg.norm(pp.pixels - truth_px, axis=1)
    print(f"\n[{name} from 4 ArUco markers] normal {angle_deg(pp.normal_cam, n_true):.4f}° "
          f"(σ {pp.std_normal_deg:.3f}°)  "
          f"offset {100 * (pp.offset_cam / d_true - 1):+.4f} %  corners RMS {np.sqrt(np.mean(corner_err**2)):.3f} px  "
          f"fit RMS {pp.rms_px:.3f} px")
    assert angle_deg(pp.normal_cam, n_true) < 0.2
    assert abs(pp.offset_cam / d_true - 1) < 0.002
    assert np.sqrt(np.mean(corner_err**2)) < 0.25  # blur σ 0.7 px, 1 DN noise; markers 20–40 px wide
    assert pp.method == "aruco" and len(pp.pixels) == 16 and pp.names[0].startswith("id ")
    # the other plane's markers are ignored; a world mapping gives the camera pose
    assert pp.warnings == ()


@pytest.mark.slow  # its fixture renders the scene: seconds (the fast loop stays under a minute)
def test_edge_fit_beats_opencvs_corners_under_gamma(scene):
    """Gamma-encoded input: OpenCV's corners sit inside the squares; the edge fit on linear values does not."""
    sc, img = scene
    enc = np.clip(np.rint(255.0 * (img / 255.0) ** (1 / 2.2)), 0, 255).astype(np.uint8)
    lin = (enc / 255.0) ** 2.2
    truth = {m.aruco_id: sc.camera.project(p.to_world(simmk.aruco_corners(m.ab, SIZE)) @ sc.R.T + sc.t)
             for p in sc.planes[:2] for m in p.markers}
    plain = aruco.detect_aruco(enc, "DICT_4X4_50")
    fitted = aruco.detect_aruco(enc, "DICT_4X4_50", linear=lin)
    assert set(plain.corners) == set(truth) == set(fitted.corners)
    e_plain = np.concatenate([plain.corners[i] - truth[i] for i in truth])
    e_fit = np.concatenate([fitted.corners[i] - truth[i] for i in truth])
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e * e, axis=1))))  # noqa: E731
    print(f"\n[ArUco corners, gamma 2.2] OpenCV {rms(e_plain):.3f} px, edge fit on linear values {rms(e_fit):.3f} px")
    assert rms(e_fit) < 0.25 and rms(e_fit) < 0.5 * rms(e_plain)


@pytest.mark.slow  # the rendered scene (module fixture)
def test_missing_and_foreign_markers(scene):
    sc, img = scene
    desk = sc.planes[0]
    cam = as_opencv(sc.camera)
    declared = {**_markers(desk), 7: (0.0, 0.0)}  # id 7 is not printed
    pp = aruco.plane_pose_from_aruco(img, cam, declared, "DICT_4X4_50", SIZE, source="frame.png")
    assert any("not found: ids 7" in w for w in pp.warnings)
    with pytest.raises(GnomonError) as exc:
        aruco.plane_pose_from_aruco(img, cam, {20: (0, 0), 21: (100, 0)}, "DICT_4X4_50", SIZE, source="frame.png")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("frame.png: found 0 of the plane's 2 ArUco markers")
    assert "missing ids 20, 21" in msg and "ids seen in the image: 0, 1, 2, 3, 10, 11, 12, 13" in msg
    with pytest.raises(GnomonError, match="unknown ArUco dictionary 'DICT_9X9_1'"):
        aruco.plane_pose_from_aruco(img, cam, _markers(desk), "DICT_9X9_1", SIZE)


@pytest.mark.slow  # the rendered scene (module fixture)
def test_charuco_board_partly_covered(scene):
    """A ChArUco board on the desk with an object standing on part of it still gives the plane."""
    sc, img = scene
    desk = sc.planes[0]
    pp = aruco.plane_pose_from_charuco(img, as_opencv(sc.camera), "DICT_5X5_50", (7, 5), 40.0, 30.0,
                                       origin=(-140.0, 100.0), source="desk.png")
    n_true, d_true = sc.plane_in_camera(desk)
    print(f"\n[ChArUco 7x5, partly covered] {len(pp.pixels)} of 24 corners; "
          f"normal {angle_deg(pp.normal_cam, n_true):.4f}°  "
          f"offset {100 * (pp.offset_cam / d_true - 1):+.4f} %  RMS {pp.rms_px:.3f} px")
    assert 6 <= len(pp.pixels) < 24
    assert angle_deg(pp.normal_cam, n_true) < 0.2
    assert abs(pp.offset_cam / d_true - 1) < 0.002
    # the points are the board's corners where the simulator put them
    ids = [int(n.split()[-1]) for n in pp.names]
    truth = sc.camera.project(desk.to_world(BOARD.inner_corners()[ids]) @ sc.R.T + sc.t)
    assert np.max(np.linalg.norm(pp.pixels - truth, axis=1)) < 0.5
    with pytest.raises(GnomonError, match=r"desk.png: ChArUco board 5x4 \(DICT_4X4_50\) not found"):
        aruco.plane_pose_from_charuco(np.full_like(img, 200), as_opencv(sc.camera), "DICT_4X4_50", (5, 4), 40.0, 30.0,
                                      source="desk.png")


# --------------------------------------------------------------------------- field log


def _log_with(tmp_path, plane_extra):
    from conftest import write_tiny_capture
    from gnomon.util import toml_io

    log_path = write_tiny_capture(tmp_path / "cap")
    data = toml_io.load(log_path)
    data["planes"][0].update({"x_axis": [1.0, 0.0, 0.0], **plane_extra})
    toml_io.dump(data, log_path)
    return log_path


def test_field_log_reads_aruco_and_charuco(tmp_path):
    from gnomon.config.fieldlog import load_field_log

    aru = {"aruco": {"dictionary": "DICT_5X5_100", "size": 40.0,
                     "markers": [{"id": 3, "plane_xy": [0.0, 0.0]}, {"id": 9, "plane_xy": [100.0, 50.0]}]}}
    plane = load_field_log(_log_with(tmp_path / "a", aru)).planes[0]
    assert plane.aruco.dictionary == "DICT_5X5_100" and plane.aruco.size == 40.0
    assert plane.aruco.markers == ((3, (0.0, 0.0)), (9, (100.0, 50.0)))
    assert np.allclose(plane.plane_to_world(np.array([[100.0, 50.0]])), [[100.0, 50.0, 0.0]])
    ch = {"charuco": {"dictionary": "DICT_4X4_50", "squares": [7, 5], "square": 30.0, "marker": 22.0,
                      "origin": [-100, 80]}}
    plane = load_field_log(_log_with(tmp_path / "c", ch)).planes[0]
    assert plane.charuco.squares == (7, 5) and plane.charuco.origin == (-100.0, 80.0)


@pytest.mark.slow
@pytest.mark.parametrize(
    "extra, needle",
    [
        ({"aruco": {"dictionary": "DICT_9X9_9", "size": 40.0, "markers": [{"id": 1, "plane_xy": [0, 0]}] * 2}},
         "[planes.0.aruco] dictionary: unknown ArUco dictionary 'DICT_9X9_9'"),
        ({"aruco": {"size": 40.0, "markers": [{"id": 1, "plane_xy": [0, 0]}, {"id": 1, "plane_xy": [9, 0]}]}},
         "ArUco id 1 is listed twice"),
        ({"aruco": {"size": 40.0, "markers": [{"id": 1, "plane_xy": [0, 0]}]}}, "at least 2"),
        ({"charuco": {"squares": [7, 5], "square": 30.0, "marker": 30.0}}, "must be smaller than the square"),
        ({"charuco": {"squares": [7, 5], "square": 30.0, "marker": 20.0}, "chessboard": "9x6", "square": 25.0},
         "one of markers, chessboard, aruco or charuco"),
    ],
)
def test_field_log_aruco_mistakes_exit_2_with_one_line(tmp_path, capsys, extra, needle):
    from gnomon.cli import main

    log_path = _log_with(tmp_path, extra)
    code = main(["scan", str(log_path), "--out", str(tmp_path / "out"), "--no-rrd"])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and needle in err[0], err
    assert not (tmp_path / "out").exists()
