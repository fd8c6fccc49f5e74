"""Calibration as users have it: boards in either orientation, intrinsics from stills at another
resolution, EXIF orientation, upper-case suffixes. All on synthetic images.

Boards are rendered by the simulator (gnomon.simulate.chessboard, its own
camera model and ray caster); EXIF orientations are checked against Pillow's
own ``ImageOps.exif_transpose``.
"""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest
from PIL import Image, ImageOps

from conftest import write_tiny_capture
from gnomon.camera import calibration
from gnomon.camera.models import OpenCVCamera, TsaiCamera
from gnomon.capture.frames import FrameSource, decode_image_file, glob_frames, image_size
from gnomon.config.fieldlog import load_field_log
from gnomon.errors import GnomonError
from gnomon.simulate import chessboard as sim
from gnomon.util import toml_io

COLS, ROWS, SQ = 9, 6, 25.0


@pytest.fixture(scope="module")
def turned_views():
    """Four views of a 9x6 board: two as usual, two turned by 90° in its plane (portrait)."""
    cam = sim.default_truth_camera(640, 480)
    rays = sim.SampleRays(cam, 2)
    poses = sim.random_poses(cam, COLS, ROWS, SQ, 4, seed=7, fill=(0.35, 0.5))
    c = np.array([(COLS - 1) * SQ / 2, (ROWS - 1) * SQ / 2, 0.0])
    out = []
    for k, (R, t) in enumerate(poses):
        if k % 2:
            R2 = R @ cv2.Rodrigues(np.array([0.0, 0.0, np.pi / 2]))[0]
            t = t + R @ c - R2 @ c
            R = R2
        img = sim.render_view(rays, COLS, ROWS, SQ, R, t, seed=k)
        truth = cam.project(sim.board_points(COLS, ROWS, SQ) @ R.T + t)
        out.append((img, truth, bool(k % 2)))
    return out


def _err_up_to_half_turn(found, truth):
    # A 9x6 board's origin is fixed up to a half-turn only when cols, rows differ in parity;
    # compare both ways round.
    return min(np.abs(found - truth).max(), np.abs(found[::-1] - truth).max())


@pytest.mark.slow
def test_boards_are_found_in_either_orientation(turned_views):
    for img, truth, turned in turned_views:
        for board in ((COLS, ROWS), (ROWS, COLS)):
            found = calibration.detect_chessboard(img, board)
            assert found is not None, (turned, board)
            if board == (COLS, ROWS):
                assert _err_up_to_half_turn(found, truth) < 0.5


@pytest.mark.slow
def test_a_board_found_with_its_sides_swapped_is_reordered_without_mirroring(turned_views):
    for img, truth, _ in turned_views:
        ok, corners = cv2.findChessboardCornersSB(img, (ROWS, COLS), flags=cv2.CALIB_CB_EXHAUSTIVE)
        assert ok
        pts = calibration._canonical_order(corners.reshape(-1, 2).astype(np.float64), (ROWS, COLS), (COLS, ROWS))
        # A 90° turn of the board: the corners land on the truth (up to the half-turn every
        # 9x6 detection has), with the board's handedness, not its mirror image.
        assert _err_up_to_half_turn(pts, truth) < 0.5
        assert calibration._handedness(pts.reshape(ROWS, COLS, 2)) > 0


# --------------------------------------------------------------------------- rescaling


def _opencv():
    return OpenCVCamera(1280, 960, 1100.0, 1098.0, 645.2, 470.9, (-0.1, 0.05, 1e-4, -2e-4, 0.0))


def _tsai():
    return TsaiCamera(1280, 960, 6.0, 3e-3, 645.2, 470.9, 0.00375, 0.00375, 1.01)


@pytest.mark.parametrize("make", [_opencv, _tsai])
@pytest.mark.parametrize("size", [(640, 480), (1920, 1440), (641, 481)])
def test_intrinsics_rescale_to_frames_of_the_same_aspect(make, size):
    cam = make()
    fitted, note = calibration.fit_camera_to_frames(cam, *size, "cam.toml")
    assert (fitted.width, fitted.height) == size and "rescaled" in note and note.startswith("cam.toml")
    pts = np.random.default_rng(0).uniform([-200, -150, 400], [200, 150, 900], (200, 3))
    sw, sh = size[0] / 1280, size[1] / 960
    expected = (cam.project(pts) + 0.5) * [sw, sh] - 0.5  # the same sensor, pixels resampled
    assert np.max(np.abs(fitted.project(pts) - expected)) < 1e-9
    same, none = calibration.fit_camera_to_frames(cam, 1280, 960, "cam.toml")
    assert same is cam and none is None


@pytest.mark.parametrize("make", [_opencv, _tsai])
def test_intrinsics_of_another_aspect_are_refused_in_one_line(make):
    with pytest.raises(GnomonError) as exc:
        calibration.fit_camera_to_frames(make(), 1920, 1080, "cam.toml", "frame 0 (a.png)")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("frame 0 (a.png) is 1920x1080 but the camera's 1280x960 (cam.toml)")
    assert "crop" in msg and "calibrate the camera from frames" in msg


@pytest.mark.parametrize("make", [_opencv, _tsai])
@pytest.mark.parametrize("size, origin", [
    ((1920, 1080), (0.0, 120.0)),  # 16:9 video from 4:3 stills: 1280x720 rows 120..840, x1.5
    ((1080, 1080), (160.0, 0.0)),  # a square crop: columns 160..1120, x1.125
])
def test_intrinsics_taken_as_the_centred_crop(make, size, origin):
    cam = make()
    fitted, note = calibration.fit_camera_to_frames(cam, *size, "cam.toml", crop="centre")
    assert (fitted.width, fitted.height) == size and "centred" in note
    scale = size[0] / (1280 - 2 * origin[0])
    assert scale == pytest.approx(size[1] / (960 - 2 * origin[1]))
    pts = np.random.default_rng(1).uniform([-200, -150, 400], [200, 150, 900], (200, 3))
    # the calibrated image's pixels (edges at integers + ½) cut at the crop's origin, then resampled
    expected = (cam.project(pts) + 0.5 - np.array(origin)) * scale - 0.5
    assert np.max(np.abs(fitted.project(pts) - expected)) < 1e-9
    with pytest.raises(GnomonError, match="crop: expected"):
        calibration.fit_camera_to_frames(cam, *size, "cam.toml", crop="left")


def test_field_log_camera_file_from_stills_is_rescaled(tmp_path):
    log_path = write_tiny_capture(tmp_path / "cap")  # 48x36 frames, fx = 60
    cam = OpenCVCamera(96, 72, 120.0, 120.0, 47.5, 35.5, (0.0,) * 5)
    calibration.write_camera_file(tmp_path / "cap" / "stills.toml", cam)
    data = toml_io.load(log_path)
    pose = data["camera"]["pose"]
    data["camera"] = {"file": "stills.toml", "pose": pose}
    toml_io.dump(data, log_path)
    log = load_field_log(log_path)
    assert (log.camera.width, log.camera.height) == (48, 36)
    assert log.camera.fx == pytest.approx(60.0) and log.camera.cx == pytest.approx(23.5)
    assert log.calibration["rescaled_from"] == [96, 72]
    # Another aspect ratio (a crop): refused when the field log is read, naming the frame.
    calibration.write_camera_file(tmp_path / "cap" / "stills.toml",
                                  OpenCVCamera(96, 54, 120.0, 120.0, 47.5, 26.5, (0.0,) * 5))
    with pytest.raises(GnomonError, match=r"frame 0 \(frame_0000\.png\) is 48x36 but the camera's 96x54 .*stills|crop"):
        load_field_log(log_path)
    # ... unless the field log says the frames are its centred crop: 72x54 columns 12..84, x2/3.
    data["camera"]["crop"] = "centre"
    toml_io.dump(data, log_path)
    log = load_field_log(log_path)
    assert (log.camera.fx, log.camera.cx, log.camera.cy) == pytest.approx((80.0, 23.5, 17.5))
    assert log.calibration["rescaled_from"] == [96, 54] and log.calibration["crop"] == "centre"


def test_init_takes_frames_of_another_aspect_as_the_centred_crop(tmp_path, capsys):
    from gnomon.cli import main

    write_tiny_capture(tmp_path / "cap")  # 48x36 frames
    frames = sorted(str(p) for p in (tmp_path / "cap" / "frames").glob("*.png"))
    for name, size, crop in (("stills.toml", (96, 54), "centre"), ("same.toml", (96, 72), None)):
        calibration.write_camera_file(tmp_path / name, OpenCVCamera(*size, 120.0, 120.0, 47.5, 26.5, (0.0,) * 5))
        out = tmp_path / f"{name}.field_log.toml"
        assert main(["init", *frames, "--camera", str(tmp_path / name), "--out", str(out)]) == 0
        assert tomllib.loads(out.read_text())["camera"].get("crop") == crop
        said = capsys.readouterr().out
        assert ("96x54 (aspect 1.778), the frames are 48x36 (1.333)" in said) == (crop is not None)


# --------------------------------------------------------------------------- EXIF and suffixes


def _asymmetric(h=30, w=40):
    img = np.zeros((h, w), np.uint8)
    img[:5, :10] = 255  # a bright block in the top-left corner
    img[:, -1] = 128  # and a grey right edge
    return img


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_is_applied_like_pillow(tmp_path, orientation):
    stored = _asymmetric()
    path = tmp_path / f"o{orientation}.png"
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(stored).save(path, exif=exif)
    with Image.open(path) as im:
        upright = np.asarray(ImageOps.exif_transpose(im))
    decoded, _ = decode_image_file(path)
    assert np.array_equal(decoded, upright)
    assert np.array_equal(calibration.read_grey(path), upright)
    assert image_size(path) == (upright.shape[1], upright.shape[0])


def test_exif_orientation_in_a_jpeg_frame_sequence(tmp_path):
    exif = Image.Exif()
    exif[0x0112] = 6  # a phone held upright: stored landscape, shown portrait
    for i in range(3):
        Image.fromarray(_asymmetric()).save(tmp_path / f"IMG_{i}.JPG", exif=exif, quality=95)
    files = glob_frames(tmp_path, "*.jpg")
    assert [p.name for p in files] == ["IMG_0.JPG", "IMG_1.JPG", "IMG_2.JPG"]
    frames = list(FrameSource(files))
    assert frames[0].grey.shape == (40, 30)
    assert frames[0].grey[2, -3] > 200 and frames[0].grey[-1, 15] < 200  # the block is now top-right


def test_frames_glob_matches_upper_case_suffixes(tmp_path):
    log_path = write_tiny_capture(tmp_path / "cap", n_frames=6)
    frames = tmp_path / "cap" / "frames"
    for k, p in enumerate(sorted(frames.iterdir())):
        if k % 2:
            p.rename(p.with_suffix(".PNG"))
    log = load_field_log(log_path)  # frames = "frames/*.png"
    assert [p.name for p in log.capture.image_files] == [f"frame_{i:04d}.{'PNG' if i % 2 else 'png'}" for i in range(6)]
    assert glob_frames(frames, "frame_000[0-2].Png") == tuple(sorted(frames.glob("frame_000[0-2].*")))


def test_a_quoted_pattern_names_its_files_on_the_command_line(tmp_path, capsys, monkeypatch):
    """`gnomon init "frames/*.png"` and `gnomon calibrate camera "calib/*.jpg"` (a shell that does not
    expand the pattern, or a user who quoted it) take the files it matches as the field log's frames glob
    does: any-case suffix, natural order; a pattern that matches nothing is one line naming it."""
    from gnomon.capture.frames import expand_glob_argument
    from gnomon.cli import main

    write_tiny_capture(tmp_path / "cap", n_frames=12)
    frames = tmp_path / "cap" / "frames"
    for k, p in enumerate(sorted(frames.iterdir())):
        if k % 3 == 0:
            p.rename(p.with_suffix(".PNG"))
    expected = tuple(sorted(frames.iterdir(), key=lambda p: p.stem))
    assert expand_glob_argument(str(frames / "*.png")) == expected  # absolute
    monkeypatch.chdir(tmp_path)
    assert expand_glob_argument("cap/frames/frame_*.png") == tuple(p.relative_to(tmp_path) for p in expected)
    assert expand_glob_argument(str(frames / "frame_0001.png")) is None  # an existing file is itself
    assert calibration.expand_image_args([str(frames / "frame_000[0-3].png")]) == list(expected[:4])
    out = tmp_path / "field_log.toml"
    assert main(["init", str(frames / "*.png"), "--out", str(out)]) == 0
    assert tomllib.loads(out.read_text())["capture"]["frames"] == "cap/frames/*.png"  # as 8 of the 12 spell it
    assert "12 frames of 48x36" in capsys.readouterr().out
    assert main(["init", str(frames / "*.tif"), "--out", str(tmp_path / "other.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "*.tif: no frame matches this pattern" in err[0]
    assert not (tmp_path / "other.toml").exists()


def test_heic_photos_are_named_as_such_with_what_to_do(tmp_path, capsys):
    """An iPhone's photos are HEIC by default, which OpenCV does not read: calibration photos and frames
    in that format are refused in one line that says so (recognised by the file's first bytes)."""
    from gnomon.cli import main

    heic = b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00mif1heic" + bytes(64)  # an ISO base media 'ftyp' box
    folder = tmp_path / "calib"
    folder.mkdir()
    for i in range(3):
        (folder / f"IMG_{i}.HEIC").write_bytes(heic)
    for args in ([str(folder / "IMG_0.HEIC"), str(folder / "IMG_1.HEIC")], [str(folder)]):
        assert main(["calibrate", "camera", *args, "--board", "9x6", "--square", "25",
                     "--out", str(tmp_path / "cam.toml"), "--no-rrd"]) == 2
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("gnomon:")]  # not the progress
        assert len(err) == 1 and "HEIF" in err[0] and "JPEG" in err[0], err
    log = write_tiny_capture(tmp_path / "cap", n_frames=6)
    (tmp_path / "cap" / "frames" / "frame_0003.png").write_bytes(heic)  # one frame saved as HEIC
    assert main(["scan", str(log), "--out", str(tmp_path / "scan"), "--quiet", "--no-rrd"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "frame_0003.png: HEIF/HEIC" in err[0], err
    assert not (tmp_path / "scan").exists()


def test_markers_that_do_not_fit_say_whether_the_camera_or_the_marks_are_at_fault() -> None:
    """Six marks (the corners and mid-points of the long sides of a 152 × 121 mm rectangle) on a plane 45° to
    a 1920×1080 camera 600 mm away. Filmed at f = 1400 px by a camera calibrated at 1000 px (a zoom since the
    calibration): the residuals vanish with the focal length × 1.40 (to the 2.5 % step of the factors
    tried), and the diagnosis names the camera. Filmed at the calibrated 1000 px but with one mark drawn 8 mm
    off its place across the rectangle's long side: no focal length halves the residual, and the diagnosis
    names the marks (with only 4 marks a focal length can mimic one misplaced mark, and the diagnosis says
    so). Exact marks: nothing."""
    from gnomon.config.setup import focal_diagnosis

    marks = np.array([[0.0, 0.0], [76.0, 0.0], [152.0, 0.0], [152.0, 121.0], [76.0, 121.0], [0.0, 121.0]])
    R = cv2.Rodrigues(np.array([np.radians(135.0), 0.0, 0.0]))[0]
    t = np.array([-76.0, 40.0, 600.0])

    def film(f: float, where: np.ndarray) -> np.ndarray:
        cam = OpenCVCamera(1920, 1080, f, f, 959.5, 539.5)
        return cam.project(np.c_[where, np.zeros(len(where))] @ R.T + t)

    calibrated = OpenCVCamera(1920, 1080, 1000.0, 1000.0, 959.5, 539.5)
    zoomed = focal_diagnosis(calibrated, marks, film(1400.0, marks), 2.0)
    factor = float(zoomed.split("× ")[1].split(" ")[0])
    assert "calibration does not fit these frames" in zoomed and abs(factor - 1.4) < 0.025
    assert "4 points cannot tell" not in zoomed
    corners = marks[[0, 2, 3, 5]]
    assert "4 points cannot tell" in focal_diagnosis(calibrated, corners, film(1400.0, corners), 2.0)
    moved = marks.copy()
    moved[3] += [0.0, 8.0]  # 8 mm off (13 px), across the long side
    misdrawn = focal_diagnosis(calibrated, marks, film(1000.0, moved), 2.0)
    assert "not where their plane coordinates put them" in misdrawn
    assert focal_diagnosis(calibrated, marks, film(1000.0, marks), 2.0) == ""
    # the other planes' factors, given as a call, are asked for only when the clause would blame the camera
    # (each costs a search of its own), and then say the same as given at once
    asked: list[int] = []

    def others() -> dict[str, float]:
        asked.append(1)
        return {"wall": 1.0}

    assert focal_diagnosis(calibrated, marks, film(1000.0, moved), 2.0, others) == misdrawn and not asked
    lazily = focal_diagnosis(calibrated, corners, film(1400.0, corners), 2.0, others)
    assert asked == [1] and lazily == focal_diagnosis(calibrated, corners, film(1400.0, corners), 2.0, {"wall": 1.0})
    assert "the other planes' marks do not agree on it (wall × 1.00 alone)" in lazily


def _board_video(path, cam, poses, *, still: int, moving: int, seed: int) -> list[str]:
    """A video of the board held still in each pose for ``still`` frames, moved to the next over ``moving``
    motion-blurred frames (rendered half-way, smeared 15 px along the motion): MJPEG in AVI. Returns each
    frame's kind ("still K" or "moving")."""
    rng = np.random.default_rng(seed)
    rays = sim.SampleRays(cam, 2)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (cam.width, cam.height))
    kinds = []

    def write(image):
        noisy = np.clip(image + rng.normal(0, 1.5, image.shape), 0, 255).astype(np.uint8)
        writer.write(cv2.cvtColor(noisy, cv2.COLOR_GRAY2BGR))

    for k, (R, t) in enumerate(poses):
        image = sim.render_view(rays, COLS, ROWS, SQ, R, t, noise_dn=0.0).astype(np.float64)
        for _ in range(still):
            write(image)
            kinds.append(f"still {k}")
        if k + 1 == len(poses):
            break
        R1, t1 = poses[k + 1]
        for j in range(moving):
            a = (j + 1) / (moving + 1)
            rv = (1 - a) * cv2.Rodrigues(R)[0] + a * cv2.Rodrigues(R1)[0]
            mid = sim.render_view(rays, COLS, ROWS, SQ, cv2.Rodrigues(rv)[0], (1 - a) * t + a * t1, noise_dn=0.0)
            shift = cam.project((R1 @ np.zeros(3) + t1)[None])[0] - cam.project((R @ np.zeros(3) + t)[None])[0]
            kernel = np.zeros((31, 31))
            d = 7.5 * shift / np.linalg.norm(shift)
            cv2.line(kernel, (round(15 - d[0]), round(15 - d[1])), (round(15 + d[0]), round(15 + d[1])), 1.0, 1)
            write(cv2.filter2D(mid.astype(np.float64), -1, kernel / kernel.sum()))
            kinds.append("moving")
    writer.release()
    return kinds


@pytest.mark.slow
def test_a_board_video_gives_its_sharp_distinct_frames_as_views(tmp_path, capsys):
    """A phone user films the board in the capture's own video mode (its crop and scale are then the
    camera's): the board held in 8 poses, moved between them. One view per pose is picked, none of the
    motion-blurred frames, and the camera is the true one (the focal lengths to test_calibration's bar)."""
    from gnomon.cli import main

    cam = sim.default_truth_camera(640, 480)
    poses = sim.random_poses(cam, COLS, ROWS, SQ, n=8, seed=11)
    video = tmp_path / "board.avi"
    kinds = _board_video(video, cam, poses, still=6, moving=3, seed=2)
    out = tmp_path / "camera.toml"
    assert main(["calibrate", "camera", str(video), "--board", f"{COLS}x{ROWS}", "--square", str(SQ),
                 "--out", str(out)]) == 0
    said = capsys.readouterr().out
    used = [line.split()[0] for line in said.splitlines() if line.endswith("used")]
    picked = [kinds[int(name.rsplit("#", 1)[1])] for name in used]
    print(said, picked)
    assert sorted(picked) == [f"still {k}" for k in range(8)]  # each pose once, no blurred frame
    assert f"{video}: {len(kinds)} frames, {len(kinds)} examined" in said
    cal, std = calibration.load_camera_file(out), calibration.load_calibration_info(out)["std"]
    assert abs(cal.fx / cam.fx - 1) < 0.002 and abs(cal.fy / cam.fy - 1) < 0.002
    # 8 views through MJPEG (the photos' test has 12 lossless ones): the principal point within 3 of its σ
    assert abs(cal.cx - cam.cx) < 3 * std["cx"] and abs(cal.cy - cam.cy) < 3 * std["cy"]
    assert out.with_suffix(".rrd").stat().st_size > 0  # the recording shows the picked frames


def test_views_are_picked_sharp_and_distinct():
    """pick_views on corner sets: a view repeated (the board held still) counts once, a blurred view and
    one whose sharpness could not be measured (NaN) are left out, a board turned by 180° (its corners in
    reverse order) is the same view."""
    grid = np.stack(np.meshgrid(np.arange(9.0), np.arange(6.0)), axis=-1).reshape(-1, 2) * 20 + 100
    views = [grid, grid + 0.3, grid[::-1], grid + [200, 0], grid + [0, 150], grid + [300, 300]]
    blur = [2.0, 2.1, 2.0, 2.2, 9.0, float("nan")]  # the 5th smeared by a motion, the 6th unmeasured
    assert calibration.pick_views(views, blur, 10, min_shift_px=5.0) == [0, 3]
    assert calibration.pick_views(views, blur, 1, min_shift_px=5.0) == [0]
    assert calibration.pick_views(views[:2], [float("nan")] * 2, 10, min_shift_px=5.0) == []
    assert calibration.pick_views([], [], 10, min_shift_px=5.0) == []
