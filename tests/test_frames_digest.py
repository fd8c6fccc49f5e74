"""`report.json`'s ``inputs.frames_sha256`` is the sha256 of the frame files, whatever reads them first."""

from __future__ import annotations

import hashlib
import json
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from gnomon.capture.frames import FrameSource
from gnomon.cli import main
from gnomon.util import toml_io


def independent_digest(files: list[Path]) -> str:
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()


def test_a_peek_at_the_first_frame_does_not_change_the_digest(tiny_capture: Path) -> None:
    files = sorted((tiny_capture.parent / "frames").glob("*.png"))
    source = FrameSource(tuple(files))
    expected = independent_digest(files)
    assert source.frames_digest() == expected  # before any pass: from the files
    for _ in source:  # a peek: the reader thread has decoded (and hashed) frames ahead
        break
    assert source.frames_digest() == expected
    assert sum(1 for _ in source) == len(files)
    assert source.frames_digest() == expected


@pytest.mark.slow
def test_a_chessboard_scan_reports_the_digest_of_its_frames(tmp_path: Path) -> None:
    """The chessboard is found in the capture's first frame (the peek), then the scan reads every frame."""
    assert main(["simulate", "chessboard", "--out", str(tmp_path / "cb"), "--width", "640", "--height", "480"]) == 0
    truth = tomllib.loads((tmp_path / "cb" / "truth.toml").read_text())
    board = cv2.imread(str(tmp_path / "cb" / "view_00.png"), cv2.IMREAD_GRAYSCALE)
    frames = tmp_path / "cap" / "frames"
    frames.mkdir(parents=True)
    u = np.arange(board.shape[1])
    for i in range(16):  # a soft dark band sweeping across the top rows, the board untouched below
        centre = -40 + 720 * i / 15
        lit = np.clip((np.abs(u - centre) - 20.0) / 10.0, 0.3, 1.0)
        frame = board.copy()
        frame[:40] = (frame[:40] * lit[None, :]).astype(np.uint8)
        cv2.imwrite(str(frames / f"frame_{i:03d}.png"), frame)
    view = truth["views"][0]
    toml_io.dump({
        "capture": {"frames": "frames/*.png", "units": "mm", "gamma": 1.0},
        "camera": {**truth["camera"]},
        "planes": [{"name": "desk", "point": [0, 0, 0], "normal": [0, 0, 1], "regions": [[0, 0, 640, 40]],
                    "chessboard": "9x6", "square": 25.0}],
        "light": {"kind": "lamp", "position": [0.0, 0.0, 400.0]},  # the board's z: up, towards the camera
        "scan": {"min_contrast": 10},
    }, tmp_path / "cap" / "field_log.toml")
    assert view  # the board's pose is measured from frame 0, not declared
    main(["scan", str(tmp_path / "cap" / "field_log.toml"), "--out", str(tmp_path / "out"), "--quiet", "--no-rrd"])
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["reference_planes"][0]["method"] == "chessboard"
    assert report["inputs"]["frames_sha256"] == independent_digest(sorted(frames.glob("*.png")))
