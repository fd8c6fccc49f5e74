"""`gnomon calibrate camera ...` and `gnomon calibrate lamp ...` on the command line.

Rendered chessboard views (gnomon.simulate.chessboard, 640×480, 9×6 board)
plus a blank image; user errors must exit 2 with one line naming the image,
key or option.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np
import pytest

from gnomon.camera import calibration
from gnomon.errors import GnomonError
from gnomon.simulate import chessboard as sim


def run_cli(argv: list[str]) -> int:
    """The real CLI when every command module imports; else the same wiring for `calibrate` alone."""
    try:
        from gnomon.cli import main
    except ImportError:  # pragma: no cover - another command's module is missing
        main = None
    if main is not None:
        try:
            return main(argv)
        except SystemExit as exc:  # argparse errors
            return int(exc.code)
    from gnomon.commands import calibrate

    parser = argparse.ArgumentParser(prog="gnomon")
    calibrate.register(parser.add_subparsers(dest="command", required=True))
    try:
        args = parser.parse_args(argv)
        return int(args.func(args) or 0)
    except GnomonError as exc:
        import sys

        print(f"gnomon: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:
        return int(exc.code)


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli_views")
    cam = sim.default_truth_camera(640, 480)
    truth = sim.write_chessboard_views(folder, camera=cam, cols=9, rows=6, square=25.0, n_views=12, seed=5)
    cv2.imwrite(str(folder / "blank.png"), np.full((480, 640), 120, np.uint8))
    return folder, cam, [folder / v["image"] for v in truth["views"]]


def error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("gnomon: error:")]


@pytest.mark.slow
def test_calibrate_camera_zhang(views, tmp_path, capsys):
    folder, cam, images = views
    out = tmp_path / "camera.toml"
    code = run_cli(["calibrate", "camera", *map(str, images), str(folder / "blank.png"), "--board", "9x6", "--square",
                    "25", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    # the warning: one line, naming the image
    warns = [line for line in captured.err.splitlines() if line.startswith("gnomon: warning:")]
    assert len(warns) == 1 and "blank.png: no 9x6 chessboard found" in warns[0]
    # the per-view table and the parameters with their σ
    assert "blank.png" in captured.out and "no board" in captured.out
    assert captured.out.count(" used") == 12
    assert "fx " in captured.out and "±" in captured.out and f"wrote {out}" in captured.out
    c = calibration.load_camera_file(out)
    assert abs(c.fx / cam.fx - 1) < 0.002 and abs(c.fy / cam.fy - 1) < 0.002
    assert np.hypot(c.cx - cam.cx, c.cy - cam.cy) < 1.0
    info = calibration.load_calibration_info(out)
    assert info["method"] == "zhang" and info["skipped"] == ["blank.png"] and info["n_views"] == 12


@pytest.mark.slow
def test_calibrate_camera_directory_and_tsai(views, tmp_path, capsys):
    folder, cam, images = views
    out = tmp_path / "tsai.toml"
    code = run_cli(["calibrate", "camera", str(images[0]), "--board", "9x6", "--square", "25", "--model", "tsai",
                    "--pixel-pitch", "0.006", "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    c = calibration.load_camera_file(out)
    assert type(c).__name__ == "TsaiCamera" and c.dx_mm == c.dy_mm == 0.006
    assert c.fy == pytest.approx(cam.fy, rel=0.02)
    assert calibration.load_calibration_info(out)["method"] == "tsai-coplanar"
    # several views, with the centre optimised too
    out2 = tmp_path / "tsai_full.toml"
    code = run_cli(["calibrate", "camera", *map(str, images[:6]), "--board", "9x6", "--square", "25", "--model",
                    "tsai", "--pixel-pitch", "0.006,0.006", "--full", "-o", str(out2)])
    assert code == 0, capsys.readouterr().err
    c2 = calibration.load_camera_file(out2)
    assert calibration.load_calibration_info(out2)["method"] == "tsai-views+full"
    assert np.hypot(c2.cx - cam.cx, c2.cy - cam.cy) < 2.0


@pytest.mark.slow
@pytest.mark.parametrize(
    "extra,message",
    [
        (["--board", "9x6", "--square", "25", "--model", "tsai"], "needs the sensor's pixel pitch"),
        (["--board", "9by6", "--square", "25"], "board '9by6': expected COLSxROWS"),
        (["--board", "9x6", "--square", "25", "--pixel-pitch", "0.006"], "apply to --model tsai only"),
        (["--board", "9x6", "--square", "25", "--model", "tsai", "--pixel-pitch", "-1"], "--pixel-pitch '-1'"),
        (["--board", "9x6", "--square", "0"], "square 0.0: the square's side must be positive"),
    ],
)
def test_bad_options_exit_2_with_one_line(views, tmp_path, capsys, extra, message):
    _, _, images = views
    code = run_cli(["calibrate", "camera", str(images[0]), *extra, "-o", str(tmp_path / "c.toml")])
    err = capsys.readouterr().err
    assert code == 2
    lines = error_lines(err)
    assert len(lines) == 1 and message in lines[0]
    assert "Traceback" not in err
    assert not (tmp_path / "c.toml").exists()


@pytest.mark.slow
def test_bad_images_exit_2_with_one_line(views, tmp_path, capsys):
    folder, _, images = views
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((100, 120), np.uint8))
    empty = tmp_path / "empty"
    empty.mkdir()
    cases = [
        ([images[0], small], "small.png: image size 120x100 differs from 640x480"),
        ([images[0], folder / "blank.png", images[1]],
         "only 2 of 3 images show the 9x6 chessboard (none in blank.png)"),
        ([tmp_path / "missing.png"], "missing.png: image not found"),
        ([empty], "empty: directory holds no images"),
    ]
    for paths, message in cases:
        code = run_cli(["calibrate", "camera", *map(str, paths), "--board", "9x6", "--square", "25", "-o",
                        str(tmp_path / "c.toml")])
        err = capsys.readouterr().err
        assert code == 2, message
        lines = error_lines(err)
        assert len(lines) == 1 and message in lines[0], err
    assert not (tmp_path / "c.toml").exists()


def test_calibrate_lamp_is_wired(tmp_path, capsys):
    code = run_cli(["calibrate", "lamp", str(tmp_path / "nope.toml")])
    err = capsys.readouterr().err
    assert code == 2
    assert len(error_lines(err)) == 1 and ("nope.toml" in err or "not available" in err)


@pytest.mark.slow  # the boards sought on blank photos by every detector, and rerun opened: seconds
def test_a_calibration_that_fails_leaves_no_recording(tmp_path, capsys) -> None:
    """Photos without a board: exit 2 in one line, and neither the camera file nor the recording (opened
    while the boards were sought) is left behind."""
    rng = np.random.default_rng(0)
    for k in range(3):
        cv2.imwrite(str(tmp_path / f"blank_{k}.png"), rng.integers(100, 140, (240, 320), dtype=np.uint8))
    out = tmp_path / "camera.toml"
    assert run_cli(["calibrate", "camera", str(tmp_path), "--board", "9x6", "--square", "25", "--out", str(out),
                    "--quiet"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists() and not out.with_suffix(".rrd").exists()
    assert not [p for p in tmp_path.iterdir() if p.suffix not in (".png",)], list(tmp_path.iterdir())
