"""`gnomon calibrate camera` against OpenCV's own detector and calibration, on the same photos, in one run
(a script, not a test).

    PYTHONPATH=python python benchmarks/calibrate_speed.py [--views DIR] [--n 18] [--width 1920 --height 1080] [--png]
    PYTHONPATH=python python benchmarks/calibrate_speed.py --photos 'calib/*.jpg' --board 6x8 --square 25

Without ``--photos`` it renders ``--n`` views of a 9x6 board (25 mm squares) with the simulator's camera at
1920x1080 into ``--views`` (kept there: rendering takes longer than calibrating; a folder that already
holds them is reused), and uses them as JPEG (quality 95, as a phone saves photos) or, with ``--png``, as
rendered. Then, on the same files:

* OpenCV, as its tutorial does it: ``cv2.imread`` (grey), ``cv2.findChessboardCorners``, ``cv2.cornerSubPix``
  (11x11 window), ``cv2.calibrateCamera``;
* ``gnomon calibrate camera`` run as a user runs it (a subprocess: start-up, the rerun recording of the views
  and the camera file included), and again with ``--no-rrd``.

Prints each one's wall time, the ratio, and both focal lengths (with the truth for rendered views).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from gnomon.camera.calibration import expand_image_args, parse_board  # noqa: E402


def render_views(folder: Path, n: int, width: int, height: int) -> None:
    from gnomon.simulate.chessboard import default_truth_camera, write_chessboard_views

    if (folder / "truth.toml").is_file() and len(list(folder.glob("view_*.png"))) == n:
        return
    t = time.perf_counter()
    write_chessboard_views(folder, camera=default_truth_camera(width, height), n_views=n, seed=1)
    print(f"rendered {n} views of {width}x{height} into {folder} in {time.perf_counter() - t:.0f} s")


def opencv_tutorial(paths: list[Path], board: tuple[int, int], square: float) -> tuple[float, np.ndarray, int]:
    """OpenCV's detection and calibration as its tutorial writes them: (seconds, K, views found)."""
    t = time.perf_counter()
    obj = np.zeros((board[0] * board[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:board[0], 0:board[1]].T.reshape(-1, 2) * square
    objs, pixs, size = [], [], None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    for p in paths:
        grey = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        size = grey.shape[::-1]
        ok, corners = cv2.findChessboardCorners(grey, board, None)
        if ok:
            objs.append(obj)
            pixs.append(cv2.cornerSubPix(grey, corners, (11, 11), (-1, -1), criteria))
    _, K, _, _, _ = cv2.calibrateCamera(objs, pixs, size, None, None)
    return time.perf_counter() - t, K, len(objs)


def gnomon_cli(paths: list[Path], board: str, square: float, out: Path, *extra: str) -> tuple[float, dict]:
    """``gnomon calibrate camera`` in a subprocess: (wall seconds, the camera file)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "python")}
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "gnomon", "calibrate", "camera", *map(str, paths), "--board", board,
                    "--square", str(square), "--out", str(out), "--quiet", *extra], check=True, env=env,
                   capture_output=True)
    return time.perf_counter() - t, tomllib.loads(out.read_text())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photos", help="the photos (a folder or a quoted pattern); default: rendered views")
    ap.add_argument("--board", default="9x6", help="inner corners COLSxROWS (default 9x6, the rendered board)")
    ap.add_argument("--square", type=float, default=25.0)
    ap.add_argument("--views", type=Path, default=Path(tempfile.gettempdir()) / "gnomon-calibrate-speed-views")
    ap.add_argument("--n", type=int, default=18)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--png", action="store_true", help="the rendered PNG views themselves, not as JPEG")
    args = ap.parse_args()
    truth = None
    if args.photos is None:
        render_views(args.views, args.n, args.width, args.height)
        paths = sorted(args.views.glob("view_*.png"))
        if not args.png:
            jpeg = args.views / "jpeg"
            jpeg.mkdir(exist_ok=True)
            for p in paths:
                cv2.imwrite(str(jpeg / f"{p.stem}.jpg"), cv2.imread(str(p)), [cv2.IMWRITE_JPEG_QUALITY, 95])
            paths = [jpeg / f"{p.stem}.jpg" for p in paths]
        truth = tomllib.loads((args.views / "truth.toml").read_text())["camera"]
    else:
        paths = expand_image_args([args.photos])
    board = parse_board(args.board)
    h, w = cv2.imread(str(paths[0]), cv2.IMREAD_GRAYSCALE).shape
    print(f"{len(paths)} photos of {w}x{h}, board {args.board}")
    with tempfile.TemporaryDirectory() as tmp:
        t_cv, K, found = opencv_tutorial(paths, board, args.square)
        t_g, cam = gnomon_cli(paths, args.board, args.square, Path(tmp) / "camera.toml")
        t_n, _ = gnomon_cli(paths, args.board, args.square, Path(tmp) / "camera_norrd.toml", "--no-rrd")
    print(f"OpenCV (findChessboardCorners + cornerSubPix + calibrateCamera): {t_cv:6.2f} s, board in {found} "
          f"photos, fx {K[0, 0]:.2f} fy {K[1, 1]:.2f}")
    print(f"gnomon calibrate camera (with its recording):                   {t_g:6.2f} s  (x{t_g / t_cv:.2f}), "
          f"{cam['calibration']['n_views']} views, fx {cam['fx']:.2f} fy {cam['fy']:.2f}")
    print(f"gnomon calibrate camera --no-rrd:                               {t_n:6.2f} s  (x{t_n / t_cv:.2f})")
    if truth is not None:
        print(f"truth: fx {truth['fx']:.2f} fy {truth['fy']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
