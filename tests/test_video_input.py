"""A video capture's recording stores the video itself (AssetVideo) with a frame reference per frame."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import cv2
import pytest

from conftest import encode_h264
from gnomon import toml_io

av = pytest.importorskip("av")  # PyAV: an H.264 encoder to make the test video (the `test` extra)


def test_video_capture_is_recorded_as_a_video(tiny_capture: Path) -> None:
    from rerun.chunk import RrdReader

    from gnomon.cli import main

    folder = tiny_capture.parent
    frames = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted((folder / "frames").glob("*.png"))]
    encode_h264(frames, folder / "capture.mp4", fps=10, crf=0)  # crf 0: lossless luma
    data = tomllib.loads(tiny_capture.read_text())
    data["capture"]["frames"] = "capture.mp4"
    toml_io.dump(data, folder / "video.toml")
    assert main(["scan", str(folder / "video.toml"), "--out", str(folder / "scan"), "--quiet"]) == 0
    rrd = folder / "scan" / "scan.rrd"
    proc = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(rrd)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    blobs, refs, jpegs, resolution = [], [], 0, None
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if chunk.entity_path == "/world/camera/image":
            if "AssetVideo:blob" in names:
                blobs += [b for b in batch.column("AssetVideo:blob").to_pylist() if b]
            if "VideoFrameReference:timestamp" in names:
                refs += [(f, t[0]) for f, t in zip(batch.column("frame").to_pylist(),
                                                    batch.column("VideoFrameReference:timestamp").to_pylist(),
                                                    strict=True) if t]
            jpegs += "EncodedImage:blob" in names
        if chunk.entity_path == "/world/camera" and "Pinhole:resolution" in names:
            resolution = batch.column("Pinhole:resolution").to_pylist()[0][0]
    assert len(blobs) == 1 and bytes(blobs[0][0]) == (folder / "capture.mp4").read_bytes()
    assert jpegs == 0
    # one reference per frame, at the frame's own time in the video (10 fps)
    assert sorted(f for f, _ in refs) == list(range(len(frames)))
    assert all(t == f * 100_000_000 for f, t in refs)
    assert list(resolution) == [48, 36]  # the video's own size: the pinhole matches it
    from gnomon.review import summarize

    assert summarize(rrd).to_dict()["frames_stored"] == len(frames)
