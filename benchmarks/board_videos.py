"""Calibrate cameras from videos of a chessboard, and judge the result on the videos' other frames.

For each ``VIDEO:COLSxROWS`` (a phone's video of a board, mirrored from a public
repository; never committed), ``gnomon calibrate camera VIDEO --board COLSxROWS
--square S --fix-k3`` picks its sharp, distinct frames as views and writes a
camera file. The reference is independent of Gnomon's picking: OpenCV's
classic detector (``findChessboardCorners`` and ``cornerSubPix``) on every 2nd
frame, ``calibrateCamera`` on every 6th of those (22–35 views on these videos,
about what a script that keeps every frame it finds the board in uses), and
the rest held out. Both calibrations are judged on the held-out frames: each
posed by ``solvePnP`` with the calibration held fixed, its corners' RMS
reprojection error. (Gnomon's own picks may be among those frames.)

    python benchmarks/board_videos.py yunee.mp4:10x7 young.mp4:10x7 yubin.mp4:8x6 hye.mp4:7x5 --out DIR
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np

from gnomon.cli import main as gnomon

HELD_OUT_STRIDE = 6  # the reference calibrates on every 6th detected frame, the others are held out


def detections(video: Path, cols: int, rows: int) -> tuple[list[np.ndarray], tuple[int, int]]:
    """Every 2nd frame's board corners by OpenCV's classic detector, refined by ``cornerSubPix``."""
    cap = cv2.VideoCapture(str(video))
    found: list[np.ndarray] = []
    size = (0, 0)
    k = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        if k % 2 == 1:
            grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            size = (grey.shape[1], grey.shape[0])
            ok, corners = cv2.findChessboardCorners(grey, (cols, rows), None)
            if ok:
                crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3)
                found.append(cv2.cornerSubPix(grey, corners, (11, 11), (-1, -1), crit).reshape(-1, 2))
        k += 1
    cap.release()
    return found, size


def held_out_rms(board: np.ndarray, views: list[np.ndarray], K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Each held-out view's RMS reprojection error (px) with the camera (K, dist) held fixed."""
    out = []
    for k, corners in enumerate(views):
        if k % HELD_OUT_STRIDE == 0:
            continue
        _, rvec, tvec = cv2.solvePnP(board, corners, K, dist, flags=cv2.SOLVEPNP_IPPE)
        _, rvec, tvec = cv2.solvePnP(board, corners, K, dist, rvec, tvec, useExtrinsicGuess=True)
        projected = cv2.projectPoints(board, rvec, tvec, K, dist)[0].reshape(-1, 2)
        out.append(np.sqrt(np.mean(np.sum((projected - corners) ** 2, axis=1))))
    return np.array(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("videos", nargs="+", metavar="VIDEO:COLSxROWS")
    ap.add_argument("--square", type=float, default=25.0, help="the board's square (mm)")
    ap.add_argument("--out", type=Path, default=Path("board_videos"))
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for item in args.videos:
        path, board = item.rsplit(":", 1)
        cols, rows = (int(x) for x in board.split("x"))
        video = Path(path)
        camera = args.out / f"{video.stem}.toml"
        cmd = ["calibrate", "camera", str(video), "--board", board, "--square", str(args.square), "--out",
               str(camera), "--no-rrd", "--fix-k3"]
        print("$ gnomon " + " ".join(cmd), flush=True)
        if gnomon(cmd) != 0:
            print(f"{video.name}: refused by gnomon calibrate camera (above)", flush=True)
            continue
        cam = tomllib.loads(camera.read_text())
        K = np.array([[cam["fx"], 0.0, cam["cx"]], [0.0, cam["fy"], cam["cy"]], [0.0, 0.0, 1.0]])
        dist = np.array(cam["dist"], dtype=np.float64)
        views, size = detections(video, cols, rows)
        board_xyz = np.zeros((cols * rows, 3), np.float32)
        board_xyz[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * args.square
        used = views[::HELD_OUT_STRIDE]
        rms, K0, d0, _, _ = cv2.calibrateCamera([board_xyz] * len(used), used, size, None, None,
                                                flags=cv2.CALIB_FIX_K3)
        mine, theirs = held_out_rms(board_xyz, views, K, dist), held_out_rms(board_xyz, views, K0, d0)
        print(f"{video.name}: gnomon {cam['calibration']['n_views']} views, RMS {cam['calibration']['rms_px']:.3f} px, "
              f"fx {cam['fx']:.1f}; held-out median {np.median(mine):.3f} px (p90 {np.percentile(mine, 90):.3f}) | "
              f"reference {len(used)} views, RMS {rms:.3f} px, fx {K0[0, 0]:.1f}; held-out median "
              f"{np.median(theirs):.3f} px (p90 {np.percentile(theirs, 90):.3f}); {len(views) - len(used)} frames "
              "held out", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
