"""`gnomon init --light lamp|sun`: the templates of a desk-lamp and a sun capture, filled in as a user
would, calibrate and scan; unfilled, they stop at the first key to fill in, in one line.

The desk-lamp template is checked end to end on the committed synthetic capture
``field_logs/desk_lamp_small`` against its ground truth: the desk placed by a
chessboard photo rendered by the simulator's own ray caster
(:mod:`gnomon.simulate.chessboard`) from the capture's true camera and pose, the
lamp located by ``gnomon calibrate lamp`` from the pencil photos' exact pixels.
"""

from __future__ import annotations

import io
import json
import shutil
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from gnomon.cli import main
from gnomon.commands.init import filename_time_pattern
from gnomon.util import toml_io

FIELD_LOGS = Path(__file__).resolve().parents[1] / "field_logs"


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.slow
def test_the_lamp_template_filled_in_calibrates_the_lamp_and_scans(tmp_path: Path) -> None:
    src = FIELD_LOGS / "desk_lamp_small"
    work = shutil.copytree(src, tmp_path / "capture")
    original = tomllib.loads((src / "field_log.toml").read_text())
    truth = np.load(src / "ground_truth.npz")
    cam = original["camera"]
    # a 9x6 board of 20 mm squares lying on the desk, photographed by the capture's camera from its place
    from gnomon.simulate.chessboard import SampleRays, TruthPinhole, render_view

    true_camera = TruthPinhole(width=cam["width"], height=cam["height"], fx=cam["fx"], fy=cam["fy"], cx=cam["cx"],
                               cy=cam["cy"], dist=tuple(cam["dist"]))
    board_origin = np.array([-100.0, -60.0, 0.0])  # world (desk) coordinates, the board's axes the world's
    board = render_view(SampleRays(true_camera, 3), 9, 6, 20.0, truth["R"], truth["R"] @ board_origin + truth["t"],
                        noise_dn=1.5, seed=1)
    cv2.imwrite(str(work / "board.png"), board)
    toml_io.dump({k: v for k, v in cam.items() if k != "pose"}, work / "camera.toml")

    out = work / "scan.toml"
    assert main(["init", str(work / "frames" / "*.jpg"), "--camera", str(work / "camera.toml"), "--light", "lamp",
                 "--pencil", str(work / "pencil" / "*.jpg"), "--board", "9x6", "--square", "20",
                 "--board-image", str(work / "board.png"), "--out", str(out)]) == 0
    text = out.read_text()
    log = tomllib.loads(text)
    assert log["light"] == {"kind": "lamp", "file": "lamp.toml"}
    desk = log["planes"][0]
    assert (desk["chessboard"], desk["square"], desk["image"]) == ("9x6", 20, "board.png")
    assert [p["image"] for p in log["pencil"]["photos"]] == [f"pencil/pencil_{k}.jpg" for k in range(3)]
    # unfilled, the lamp calibration stops at the pencil's height
    assert main(["calibrate", "lamp", str(out)]) == 2

    # what a user fills in: the pencil's length, each photo's base and shadow tip, two bands of bare desk
    clicks = tomllib.loads((src / "pencil_log.toml").read_text())["pencil"]
    log["pencil"].update(height=clicks["height"], sigma_px=0.3)
    for photo, clicked in zip(log["pencil"]["photos"], clicks["photos"], strict=True):
        assert Path(photo["image"]).name == Path(clicked["image"]).name
        photo.update(base=clicked["base"], tip=clicked["tip"])
    desk["regions"] = original["planes"][0]["regions"]
    log["capture"]["gamma"] = original["capture"]["gamma"]
    toml_io.dump(log, out)
    assert main(["calibrate", "lamp", str(out)]) == 0
    # the preview draws the desk's grid over the board's squares, where the board lay
    assert main(["preview", str(out), "--out", str(work / "preview.png")]) == 0
    preview = cv2.imread(str(work / "preview.png")).astype(int)
    b, g, r = preview[..., 0], preview[..., 1], preview[..., 2]
    grid = (r > 200) & (r - g > 80) & (r - b > 80)  # the first plane's grid colour, (60, 60, 255) BGR
    corners = np.array([[-20.0, -20.0, 0.0], [180.0, -20.0, 0.0], [180.0, 120.0, 0.0], [-20.0, 120.0, 0.0]])
    world = corners + board_origin
    px = cv2.projectPoints((world @ truth["R"].T + truth["t"]).reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                           truth["K"], truth["dist"])[0].reshape(-1, 2)
    board_area = np.zeros(grid.shape, np.uint8)
    cv2.fillConvexPoly(board_area, np.round(px).astype(np.int32), 1)
    board_area = cv2.dilate(board_area, np.ones((5, 5), np.uint8)) > 0
    labelled = cv2.dilate(board_area.astype(np.uint8), np.ones((31, 31), np.uint8)) > 0  # its caption too
    bands = np.zeros_like(grid)
    for u0, v0, u1, v1 in original["planes"][0]["regions"]:
        bands[v0:v1, u0:u1] = True
    assert (grid & board_area).sum() > 600  # 7 lines over the board: 1016 px (its 2 corner circles alone: 245)
    assert (grid & ~labelled & ~bands).sum() < 0.01 * (grid & board_area).sum()
    assert main(["scan", str(out), "--out", str(work / "scan"), "--quiet", "--no-rrd"]) == 0

    # the lamp, in the camera frame (free of the board's choice of origin and axes), within 1 % of its
    # distance from the pencils (as test_lamp_calibration bounds the pencils' estimate)
    report = json.loads((work / "scan" / "report.json").read_text())
    plane = report["reference_planes"][0]
    R_board = cv2.Rodrigues(np.array(plane["rvec"]))[0]
    lamp = np.array(tomllib.loads((work / "lamp.toml").read_text())["light"]["position"])
    lamp_cam = R_board @ lamp + np.array(plane["tvec"])
    true_lamp_cam = truth["R"] @ truth["lamp"] + truth["t"]
    reach = np.linalg.norm(truth["lamp"] - truth["pencil_bases_world"].mean(axis=0))
    assert np.linalg.norm(lamp_cam - true_lamp_cam) <= 0.01 * reach
    # the depth (camera Z, free of the world frame): the desk bar of 0.1 % of the distance at 800 px wide,
    # scaled to this capture's 320 px (a pixel sees 2.5 times the desk, so the same time noise costs 2.5 times
    # the depth), on ≥ 95 % of the swept pixels
    from gnomon.runs.accuracy import depth_accuracy

    acc = depth_accuracy(np.load(work / "scan" / "depth.npy"), truth["depth"], truth["swept"],
                         float(truth["camera_distance_mm"]))
    print(acc.table("desk_lamp_small from the lamp template"))
    assert acc.rms_pct <= 0.1 * 800 / 320
    assert acc.coverage >= 0.95
    # the world frame as the template says: z up from the desk. The board's origin and in-plane axes are its
    # own, so compare what they do not change: each point's height above the desk (the truth's world z), the
    # lamp's and the camera's
    R_world = cv2.Rodrigues(np.array(report["camera"]["pose"]["rvec"]))[0]
    t_world = np.array(report["camera"]["pose"]["tvec"])
    assert (-R_world.T @ t_world)[2] == pytest.approx((-truth["R"].T @ truth["t"].ravel())[2], rel=0.01)
    assert lamp[2] == pytest.approx(truth["lamp"][2], rel=0.01)
    depth = np.load(work / "scan" / "depth.npy")
    objects = np.isfinite(depth) & truth["swept"] & (truth["object_id"] > 0)
    from gnomon.camera.calibration import load_camera_file

    v, u = np.nonzero(objects)
    rays = load_camera_file(work / "camera.toml").rays(np.stack([u, v], axis=1).astype(np.float64))
    points = rays / rays[:, 2:3] * depth[objects][:, None]
    height = ((points - t_world) @ R_world)[:, 2]
    assert np.median(np.abs(height - truth["points_world"][objects][:, 2])) < 0.5  # mm

    # the bands left out: `gnomon regions` starts from the image's top and bottom rows, switches the
    # template's mask line on, and the scan is as good
    log["planes"][0].pop("regions")
    log["light"] = {"kind": "lamp", "file": "lamp.toml"}
    no_bands = work / "no_bands.toml"
    toml_io.dump(log, no_bands)
    mask_line = '# mask = "regions/desk_mask.png"'
    no_bands.write_text(no_bands.read_text().replace('name = "desk"\n', f'name = "desk"\n{mask_line}\n'))
    assert mask_line in text  # the template's own line, lost when the test rewrote the log
    assert main(["regions", str(no_bands), "--quiet"]) == 0
    assert tomllib.loads(no_bands.read_text())["planes"][0]["mask"] == "regions/desk_mask.png"
    assert main(["scan", str(no_bands), "--out", str(work / "scan_no_bands"), "--quiet", "--no-rrd"]) == 0
    acc = depth_accuracy(np.load(work / "scan_no_bands" / "depth.npy"), truth["depth"], truth["swept"],
                         float(truth["camera_distance_mm"]))
    print(acc.table("desk_lamp_small, regions from the image's top and bottom rows"))
    assert acc.rms_pct <= 0.1 * 800 / 320
    # the proposed mask stays a few pixels clear of the image's sides, where this 320-px sweep spends 3 of its
    # 80 frames: those frames have no plane (measured 94.6 % against 99.5 % with the log's own full-width bands)
    assert acc.coverage >= 0.95 - 3 / 80


def test_the_sun_template_filled_in_gives_the_captures_times(tmp_path: Path, capsys) -> None:
    src = FIELD_LOGS / "facade_sun_small"
    original = tomllib.loads((src / "field_log.toml").read_text())
    out = tmp_path / "sun.toml"
    assert main(["init", str(src / "frames" / "*.jpg"), "--light", "sun", "--out", str(out)]) == 0
    capsys.readouterr()
    log = tomllib.loads(out.read_text())
    assert log["capture"]["units"] == "m" and log["light"] == {"kind": "sun"}
    # the simulator writes each frame's time into its EXIF and its name; its field log reads the names
    assert log["capture"]["timestamps"] == "exif" and original["capture"]["timestamps"] == "filename"
    assert [p["name"] for p in log["planes"]] == ["ground", "facade"]
    assert log["scan"]["normalize_illumination"] is True
    assert np.isnan(log["site"]["latitude"]) and np.isnan(log["site"]["heading_deg"])
    # unfilled: one line naming the first key to fill in
    assert main(["preview", str(out), "--out", str(tmp_path / "p.png")]) == 2
    assert "[site] latitude: expected a finite number, got nan" in _one_line_error(capsys)
    # the commented [gnomon] and [pole] tables, uncommented, have the keys the simulator's log uses
    text = out.read_text()
    block = text[text.index("# [gnomon]"):text.index("[light]")]
    tables = tomllib.loads("\n".join(line[2:] for line in block.splitlines() if line.startswith("# "))
                           .replace("[u, v]", "[0, 0]").replace("[x, y, z]", "[0, 0, 0]"))
    assert {k: set(v) for k, v in tables.items()} == {k: set(original[k]) for k in ("gnomon", "pole")}
    # filled in with the capture's own site, camera, planes and pole: the same frames at the same times
    from gnomon.config.fieldlog import load_field_log
    from gnomon.light.timestamps import frame_times

    log["site"] = original["site"]
    log["camera"] = original["camera"]
    log["planes"] = original["planes"]
    for key in ("pole", "gnomon"):
        log[key] = original[key]
    log["capture"]["frames"] = str(src / "frames" / "*.jpg")
    toml_io.dump(log, out)
    mine, theirs = load_field_log(out), load_field_log(src / "field_log.toml")
    assert mine.capture.image_files == theirs.capture.image_files
    tz = original["site"]["timezone"]
    from_exif = frame_times(mine.capture.image_files, "exif", site_tz=tz)
    from_names = frame_times(theirs.capture.image_files, "filename", pattern=original["capture"]["time_pattern"],
                             site_tz=tz)
    assert (from_exif == from_names).all()


def _exif_jpeg(path: Path, original: str | None) -> None:
    exif = Image.Exif()
    if original is not None:
        exif.get_ifd(0x8769)[0x9003] = original  # DateTimeOriginal
    buf = io.BytesIO()
    Image.fromarray(np.full((24, 32), 128, np.uint8)).save(buf, format="JPEG", exif=exif.tobytes())
    path.write_bytes(buf.getvalue())


def test_the_sun_template_reads_exif_times_or_file_names_or_asks_for_a_start_and_rate(tmp_path: Path, capsys) -> None:
    stamped, plain = tmp_path / "stamped", tmp_path / "plain"
    stamped.mkdir()
    plain.mkdir()
    named = tmp_path / "named"
    named.mkdir()
    for k in range(3):
        _exif_jpeg(stamped / f"DSC_{k:04d}.jpg", f"2026:06:21 09:{k:02d}:00")
        _exif_jpeg(plain / f"DSC_{k:04d}.jpg", None)
        _exif_jpeg(named / f"IMG_20260621_09{k:02d}00.jpg", None)  # a phone's name, no EXIF time
    assert main(["init", str(stamped / "*.jpg"), "--light", "sun", "--out", str(tmp_path / "a.toml")]) == 0
    assert tomllib.loads((tmp_path / "a.toml").read_text())["capture"]["timestamps"] == "exif"
    assert main(["init", str(named / "*.jpg"), "--light", "sun", "--out", str(tmp_path / "n.toml")]) == 0
    capture = tomllib.loads((tmp_path / "n.toml").read_text())["capture"]
    assert (capture["timestamps"], capture["time_pattern"]) == ("filename", "IMG_%Y%m%d_%H%M%S")
    assert main(["init", str(plain / "*.jpg"), "--light", "sun", "--out", str(tmp_path / "b.toml")]) == 0
    capture = tomllib.loads((tmp_path / "b.toml").read_text())["capture"]
    assert capture["timestamps"] == "start+fps" and capture["start"] == "" and np.isnan(capture["fps"])
    capsys.readouterr()
    assert main(["preview", str(tmp_path / "b.toml"), "--out", str(tmp_path / "p.png")]) == 2
    assert "[capture] fps: expected a finite number, got nan" in _one_line_error(capsys)
    # a video: its own frame rate, a start to fill in
    video = tmp_path / "timelapse.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 12.0, (32, 24))
    for k in range(5):
        writer.write(np.full((24, 32, 3), 100 + k, np.uint8))
    writer.release()
    assert main(["init", str(video), "--light", "sun", "--out", str(tmp_path / "c.toml")]) == 0
    capture = tomllib.loads((tmp_path / "c.toml").read_text())["capture"]
    assert capture["timestamps"] == "start+fps" and capture["fps"] == 12.0 and capture["start"] == ""


@pytest.mark.parametrize(("stems", "pattern"), [
    (["20261112T104000Z", "20261112T104201Z"], "%Y%m%dT%H%M%SZ"),
    (["IMG_20260621_090000", "IMG_20260621_090030"], "IMG_%Y%m%d_%H%M%S"),
    (["2026-06-21 09-00-00", "2026-06-21 09-00-30"], "%Y-%m-%d %H-%M-%S"),
    (["cam1_2026-06-21T09:00:00_100%", "cam1_2026-06-21T09:00:30_100%"], "cam1_%Y-%m-%dT%H:%M:%S_100%%"),
    (["IMG_20260621_090000", "IMG_20260621_090030_HDR"], None),  # not every name parses
    (["IMG_0001", "IMG_0002"], None),  # no time at all
    (["20261312T104000Z", "20261312T104201Z"], None),  # month 13: digits, not a date
])
def test_a_time_pattern_is_read_off_the_file_names(stems, pattern) -> None:
    assert filename_time_pattern(stems) == pattern


def test_the_lamp_options_need_the_lamp(tiny_capture: Path, capsys) -> None:
    frames = str(tiny_capture.parent / "frames" / "*.png")
    out = tiny_capture.parent / "init.toml"
    assert main(["init", frames, "--board", "9x6", "--out", str(out)]) == 2
    assert _one_line_error(capsys) == "gnomon: error: --board: only with --light lamp"
    assert main(["init", frames, "--light", "lamp", "--board", "9by6", "--out", str(out)]) == 2
    assert "--board: '9by6' is not COLSxROWS" in _one_line_error(capsys)
    assert main(["init", frames, "--light", "lamp", "--pencil", str(tiny_capture.parent / "none*.jpg"),
                 "--out", str(out)]) == 2
    assert "none*.jpg: no pencil photo matches this pattern" in _one_line_error(capsys)
    assert not out.exists()
    # without the board's options, the board keys are commented and the log loads only once filled
    assert main(["init", frames, "--light", "lamp", "--out", str(out)]) == 0
    log = tomllib.loads(out.read_text())
    assert "chessboard" not in log["planes"][0] and "photos" not in log["pencil"]
    assert "# chessboard = \"9x6\"" in out.read_text()


def test_a_folder_of_frames_is_taken_as_its_frames_in_natural_order(tmp_path: Path, capsys) -> None:
    """`gnomon init frames/` writes the same field log as `gnomon init "frames/*.png"` (the folder's
    images; a stray text file is not a frame); the frames glob lists them in natural order
    (frame_2 before frame_10); a folder without frames is one line naming it, exit 2."""
    from gnomon.capture.frames import glob_frames

    frames = tmp_path / "cap" / "frames"
    frames.mkdir(parents=True)
    for i in range(12):
        cv2.imwrite(str(frames / f"frame_{i}.png"), np.full((24, 32), 10 * i, np.uint8))
    (frames / "notes.txt").write_text("taken at noon")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    assert main(["init", str(frames), "--out", str(tmp_path / "a" / "field_log.toml")]) == 0
    assert main(["init", str(frames / "*.png"), "--out", str(tmp_path / "b" / "field_log.toml")]) == 0
    written = (tmp_path / "a" / "field_log.toml").read_text()
    assert written == (tmp_path / "b" / "field_log.toml").read_text() and "/*.png" in written
    pattern = tomllib.loads(written)["capture"]["frames"]  # the template loads once its markers are in
    names = [p.name for p in glob_frames(tmp_path / "a", pattern)]  # as the field log reads it
    assert names == [f"frame_{i}.png" for i in range(12)]
    (tmp_path / "empty").mkdir()
    assert main(["init", str(tmp_path / "empty"), "--out", str(tmp_path / "e.toml")]) == 2
    assert "empty: the folder holds no frames" in _one_line_error(capsys)
