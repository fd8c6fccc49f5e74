"""A video capture's recording stores the video itself (AssetVideo) with a frame reference per frame."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import cv2
import pytest

from conftest import encode_h264
from gnomon.util import toml_io

av = pytest.importorskip("av")  # PyAV: an H.264 encoder to make the test video (the `test` extra)


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
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
    from gnomon.recording.review import summarize

    assert summarize(rrd).to_dict()["frames_stored"] == len(frames)


@pytest.mark.parametrize("suffix, fmt, codec", [(".webm", "webm", "libvpx"), (".mkv", "matroska", "libx264")])
def test_a_variable_frame_rate_video_in_any_container_has_all_its_frames(tmp_path: Path, suffix, fmt, codec) -> None:
    """Matroska and WebM carry no frame count: OpenCV estimates it from the duration and the nominal rate,
    which a variable frame rate (a browser's or a webcam app's recording) puts off by many frames. The
    source counts them: every frame, in order, and the capture is not taken for a truncated one."""
    import fractions

    import numpy as np

    from gnomon.capture.frames import FrameSource
    from gnomon.cli import main

    path, n = tmp_path / f"vfr{suffix}", 45
    out = av.open(str(path), "w", format=fmt)
    stream = out.add_stream(codec, rate=30)
    stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
    stream.codec_context.time_base = fractions.Fraction(1, 1000)
    t = 0
    for i in range(n):
        image = np.full((48, 64, 3), 200, np.uint8)
        image[:, i : i + 8] = 40  # a dark band one column further right in each frame
        frame = av.VideoFrame.from_ndarray(image, format="rgb24")
        frame.pts, frame.time_base = t, fractions.Fraction(1, 1000)
        t += 20 if i % 3 else 80  # 20 ms, 20 ms, 80 ms: 30 fps on average, never at 30 fps
        for packet in stream.encode(frame):
            out.mux(packet)
    for packet in stream.encode():
        out.mux(packet)
    out.close()
    source = FrameSource((), path)
    assert source.count == n
    frames = list(source)
    assert [f.index for f in frames] == list(range(n))
    centre = [float(np.mean(np.flatnonzero(f.grey[24] < 120))) for f in frames]  # the band's middle column
    assert all(abs(c - (i + 3.5)) <= 1.0 for i, c in enumerate(centre))  # each frame in its place
    assert main(["init", str(path), "--out", str(tmp_path / "field_log.toml")]) == 0
    assert f"# {n} video" in (tmp_path / "field_log.toml").read_text()


def test_a_video_opencv_cannot_decode_is_one_line_naming_its_codec(tmp_path: Path, monkeypatch) -> None:
    """AV1 (some phones', some browsers' recordings): the FFmpeg inside OpenCV's wheels has no AV1 decoder
    but opens the file. Not 'the video ended after 0 frames': one line naming the file and its codec, and
    no FFmpeg log lines on the process's stderr. (Where OpenCV does read AV1, the video must simply work.)"""
    import os

    import numpy as np

    monkeypatch.setenv("SVT_LOG", "1")  # the AV1 encoder's banner: errors only
    path = tmp_path / "av1.mp4"
    out = av.open(str(path), "w", format="mp4")
    stream = out.add_stream("libsvtav1", rate=30)
    stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
    for i in range(10):
        image = np.full((48, 64, 3), 200, np.uint8)
        image[:, 4 * i : 4 * i + 8] = 40
        for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")):
            out.mux(packet)
    for packet in stream.encode():
        out.mux(packet)
    out.close()
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    # a process of its own: FFmpeg's log level is fixed by the first video a process opens
    proc = subprocess.run([sys.executable, "-m", "gnomon", "init", str(path), "--out", str(tmp_path / "log.toml")],
                          capture_output=True, text=True, timeout=120, env=env)
    if cv2.VideoCapture(str(path)).read()[0]:
        assert proc.returncode == 0, proc.stderr
        return
    assert proc.returncode == 2 and not (tmp_path / "log.toml").exists()
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    assert "av1.mp4: no frame could be decoded" in lines[0] and "'AV01'" in lines[0]
