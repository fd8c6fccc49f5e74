"""`gnomon live` (issue 17): driven from a small video file (not real-time), it logs points while the
shadow is still moving and ends with exactly `gnomon scan`'s outputs on the same frames."""

from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import encode_h264, write_tiny_capture
from gnomon.capture.frames import FrameSource
from gnomon.cli import main
from gnomon.outputs import ply
from gnomon.runs.live import LiveFrames, LiveStats, _StopOnInterrupt

av = pytest.importorskip("av")  # PyAV: an H.264 encoder to make the test video (the `test` extra)


def _natural(p: Path) -> list[int | str]:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def _frame_files(capture: Path) -> list[Path]:
    return sorted((capture / "frames").glob("*.jpg"), key=_natural)


@pytest.fixture(scope="module")
def live_run(desk_scan, tmp_path_factory):
    """The desk capture (400×300, 120 frames) as an H.264 video: `gnomon scan` on a field log
    reading it, and `gnomon live --source VIDEO` on the original field log."""
    root = tmp_path_factory.mktemp("live")
    capture = desk_scan / "capture"
    video = root / "desk.mp4"
    encode_h264((cv2.cvtColor(cv2.imread(str(f), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB) for f in _frame_files(capture)),
                video, fps=30, crf=10)
    text = (capture / "field_log.toml").read_text()
    text = re.sub(r'^frames = ".*"$', f'frames = "{video.as_posix()}"', text, count=1, flags=re.MULTILINE)
    log_video = root / "field_log_video.toml"
    log_video.write_text(text)
    assert main(["scan", str(log_video), "--out", str(root / "scan"), "--quiet"]) == 0
    assert main(["live", str(capture / "field_log.toml"), "--source", str(video), "--out", str(root / "live"),
                 "--no-view", "--quiet"]) == 0
    return root


@pytest.mark.slow
def test_live_outputs_are_the_scan_s(live_run):
    scan, live = live_run / "scan", live_run / "live"
    assert sorted(p.name for p in scan.iterdir()) == sorted(p.name for p in live.iterdir())
    for name in ("depth.npy", "sigma.npy", "shadow_time.npy", "undersampled.npy"):
        np.testing.assert_array_equal(np.load(scan / name), np.load(live / name), err_msg=name)
    a, b = ply.read_ply(scan / "points.ply"), ply.read_ply(live / "points.ply")
    np.testing.assert_array_equal(a["xyz"], b["xyz"])
    ra, rb = json.loads((scan / "report.json").read_text()), json.loads((live / "report.json").read_text())
    assert ra["coverage"] == rb["coverage"]
    info = rb["tracking"]["live"]
    assert info["frames"] == 120 and info["dropped_frames"] == 0 and info["stopped"] == "source ended"
    # most of the cloud was shown while the shadow was still moving
    assert info["points_logged"] >= 0.8 * ra["coverage"]["points"]


@pytest.mark.slow
def test_points_are_logged_while_the_shadow_moves(live_run):
    """The recording holds live points at frames before the last one, each near the final point
    of its pixel, and a shadow-time map that fills in over the frames."""
    from rerun.chunk import RrdReader

    live = live_run / "live"
    depth = np.load(live / "depth.npy")
    sigma = np.load(live / "sigma.npy")
    final = ply.read_ply(live / "points.ply")
    by_pixel = {(round(float(u)), round(float(v))): i for i, (u, v) in enumerate(np.asarray(final["uv"]))}
    xyz_final = np.asarray(final["xyz"], dtype=np.float64)
    frames_with_points, xyz, uv, map_frames = [], [], [], []
    for chunk in RrdReader(live / "scan.rrd").stream():
        path = chunk.entity_path
        batch = chunk.to_record_batch()
        if path.startswith("/world/live_points/"):
            frames = batch.column("frame").to_pylist()
            pos = batch.column("Points3D:positions").to_pylist()
            uvs = batch.column("GnomonPoints:uv").to_pylist()
            for f, p, q in zip(frames, pos, uvs, strict=True):
                if p:
                    frames_with_points.append(f)
                    xyz.append(np.asarray(p, dtype=np.float64))
                    uv.append(np.asarray(q, dtype=np.float64).reshape(-1, 2))
        if path == "/live/shadow_time":
            map_frames += batch.column("frame").to_pylist()
    assert len(set(map_frames)) > 10
    # the frame at which each pixel's point first appeared
    first_seen: dict[tuple[int, int], int] = {}
    for f, q in zip(frames_with_points, uv, strict=True):
        for u, v in np.round(q).astype(int):
            first_seen.setdefault((u, v), f)
    seen = np.array(list(first_seen.values()))
    assert len(seen) >= 0.8 * len(xyz_final)
    assert np.mean(seen < 100) > 0.6 and np.mean(seen < 119) > 0.95  # while the shadow still moved
    assert seen.min() < 30  # from early in the sweep
    # compare each pixel's live point (its chunk's last log) with the final point of that pixel
    pts, pix = np.concatenate(xyz), np.round(np.concatenate(uv)).astype(int)
    index = np.array([by_pixel.get((u, v), -1) for u, v in pix])
    found = index >= 0
    assert found.mean() > 0.9
    dist = np.linalg.norm(pts[found] - xyz_final[index[found]], axis=1)
    typical_sigma = float(np.nanmedian(sigma[np.isfinite(depth)]))
    # provisional times use the lit level before the dip only; the final pass both sides: within noise
    assert np.median(dist) < 3 * typical_sigma, (np.median(dist), typical_sigma)


def test_a_paced_source_drops_what_a_slow_consumer_cannot_take(tiny_capture):
    """Paced at 1000 fps with one frame of buffer, a consumer taking 30 ms per frame loses frames,
    and every frame is either delivered or counted as dropped."""
    src = FrameSource(tuple(sorted((tiny_capture.parent / "frames").glob("*.png"))))
    frames = LiveFrames(src, fps=1000.0, buffer=1)
    got = []
    for f in frames:
        got.append(f.index)
        time.sleep(0.03)
    assert frames.dropped
    assert sorted(got + frames.dropped) == list(range(src.count))
    assert frames.expected_count is None  # a run with drops is not a truncated file


def test_ctrl_c_ends_the_stream_not_the_run(tiny_capture):
    src = FrameSource(tuple(sorted((tiny_capture.parent / "frames").glob("*.png"))))
    frames, stats = LiveFrames(src), LiveStats()
    got = []
    with _StopOnInterrupt(frames, stats):
        for f in frames:
            got.append(f.index)
            if f.index == 5:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)
        # a second Ctrl-C interrupts as usual
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)
    assert got == list(range(6)) and stats.stopped == "interrupted" and frames.stopped_early


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_bad_source_is_one_line(desk_scan, capsys):
    log = desk_scan / "capture" / "field_log.toml"
    assert main(["live", str(log), "--source", "no/such/thing.mp4", "--no-view", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no/such/thing.mp4" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_two_plane_scans_show_points_while_the_shadow_moves(two_plane_small, tmp_path):
    """A two-plane light (its planes from the lines on desk and wall, completed from the located light
    where the shadow crossed one plane) gets live points like a lamp, and the same final outputs as
    `gnomon scan`. Its live planes are those of frames with a line on both planes: the simulated sweep
    has them for nearly every pixel's time."""
    log = two_plane_small / "field_log.toml"
    assert main(["scan", str(log), "--out", str(tmp_path / "scan"), "--no-rrd", "--quiet"]) == 0
    assert main(["live", str(log), "--out", str(tmp_path / "live"), "--no-view", "--no-rrd", "--quiet"]) == 0
    for name in ("depth.npy", "sigma.npy"):
        np.testing.assert_array_equal(np.load(tmp_path / "scan" / name), np.load(tmp_path / "live" / name))
    report = json.loads((tmp_path / "live" / "report.json").read_text())
    assert report["tracking"]["live"]["points_logged"] >= 0.8 * report["coverage"]["points"] > 0


def test_the_watch_opens_the_dips_the_scan_keeps(tmp_path):
    """Without a min_contrast in the field log the scan keeps dips of MIN_CONTRAST_SIGMAS σ of the
    measured noise; the live watch opens the same ones (from the frame after the noise is measured),
    not only those deeper than a fixed 20 DN: a band 15 DN deep under 1 DN of noise (floor ≈ 8 DN)
    shows its points while it sweeps."""
    log = write_tiny_capture(tmp_path / "capture", n_frames=40, noise_dn=1.0, dip_dn=15.0, min_contrast=None)
    assert main(["live", str(log), "--out", str(tmp_path / "live"), "--no-view", "--no-rrd", "--quiet"]) == 0
    report = json.loads((tmp_path / "live" / "report.json").read_text())
    final = report["coverage"]["points"]
    assert final > 0.5 * 48 * 36  # the scan keeps the shallow band
    assert report["tracking"]["live"]["points_logged"] >= 0.8 * final


@pytest.mark.slow  # its field log is a simulated, scanned capture's (desk_scan: 2.7 s)
def test_a_camera_that_is_not_there_is_one_line_on_the_process_stderr(desk_scan):
    """OpenCV warns on stderr itself when a camera index cannot be opened ('can't open camera by
    index'); the command's own line is the only one (a process of its own: OpenCV's log level is
    read once per process)."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("OPENCV_LOG_LEVEL", "OPENCV_FFMPEG_LOGLEVEL")}
    proc = subprocess.run([sys.executable, "-m", "gnomon", "live", str(desk_scan / "capture" / "field_log.toml"),
                           "--source", "97", "--no-view", "--quiet", "--out", str(desk_scan / "no_camera")],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert lines == ["gnomon: error: camera 97: cannot be opened as a camera or stream"], lines
