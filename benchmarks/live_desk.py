"""Benchmark of `gnomon live` (issue 17) on the demo desk capture encoded as a video.

For a simulated desk_lamp capture (``gnomon simulate desk_lamp --out CAPTURE``,
any size), this script

1. encodes its frames as a 30 fps video beside the capture (Motion JPEG with
   OpenCV, or H.264 CRF 12 with PyAV) and writes a field log pointing at it;
2. runs ``gnomon scan`` on that field log (``gnomon.api.scan``);
3. runs ``gnomon live`` on it (``gnomon.runs.live.run_live``), with ``--realtime``
   pacing at the video's 30 fps unless ``--no-realtime``;
4. prints: frames dropped; the latency, per pixel, from the frame in which the
   shadow leaves it (ground truth: the first frame after ``leave_time``) to the
   frame being processed when its live point was logged, and (real time) to the
   frame the camera was delivering at that moment (median, p90); the CPU and
   wall time of the live work per frame; and the final outputs against the
   scan's: depth RMS difference against the scan's own RMS error (vs ground
   truth), coverage difference.

Not a test: figures depend on the machine and its load. Usage::

    PYTHONPATH=python python benchmarks/live_desk.py CAPTURE [--codec mjpg|h264] [--out DIR] [--no-realtime]
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import time
from pathlib import Path

import numpy as np

FPS = 30


def encode_video(capture: Path, codec: str) -> Path:
    """The capture's frames as a 30 fps video: Motion JPEG (the format USB webcams deliver at 1080p)
    with OpenCV, or H.264 (CRF 12) with PyAV."""
    import cv2

    frames = sorted((capture / "frames").glob("*.*"), key=lambda p: [int(t) if t.isdigit() else t
                                                                      for t in re.split(r"(\d+)", p.name)])
    path = capture / ("capture_mjpg.avi" if codec == "mjpg" else "capture.mp4")
    if path.exists():
        return path
    first = cv2.imread(str(frames[0]), cv2.IMREAD_COLOR)
    h, w = first.shape[:2]
    if codec == "mjpg":
        vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (w, h))
        vw.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
        for f in frames:
            vw.write(cv2.imread(str(f), cv2.IMREAD_COLOR))
        vw.release()
        return path
    import av

    out = av.open(str(path), "w")
    stream = out.add_stream("libx264", rate=FPS)
    stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
    stream.options = {"crf": "12", "preset": "fast"}
    for f in frames:
        rgb = cv2.cvtColor(cv2.imread(str(f), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        for packet in stream.encode(av.VideoFrame.from_ndarray(rgb, format="rgb24")):
            out.mux(packet)
    for packet in stream.encode():
        out.mux(packet)
    out.close()
    return path


def video_field_log(capture: Path, video: Path) -> Path:
    text = (capture / "field_log.toml").read_text()
    text = re.sub(r'^frames = ".*"$', f'frames = "{video.name}"', text, count=1, flags=re.MULTILINE)
    path = capture / f"field_log_{video.stem}.toml"
    path.write_text(text)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--no-realtime", action="store_true")
    ap.add_argument("--codec", choices=("mjpg", "h264"), default="mjpg")
    args = ap.parse_args()

    import gnomon
    from gnomon.runs.accuracy import depth_accuracy
    from gnomon.runs.live import LiveOptions, run_live

    out = args.out or args.capture / "bench_live"
    shutil.rmtree(out, ignore_errors=True)
    video = encode_video(args.capture, args.codec)
    log = video_field_log(args.capture, video)
    truth = np.load(args.capture / "ground_truth.npz")
    distance = float(truth["camera_distance_mm"])

    t = time.perf_counter()
    s = gnomon.scan(log, out / "scan", rrd=False, progress=False)
    scan_s = time.perf_counter() - t

    t = time.perf_counter()
    opts = LiveOptions(realtime=not args.no_realtime, fps=None, rrd=True, view=False, progress=False)
    _result, stats = run_live(log, out / "live", opts)
    live_s = time.perf_counter() - t

    depth_scan = np.load(out / "scan" / "depth.npy")
    depth_live = np.load(out / "live" / "depth.npy")
    acc_scan = depth_accuracy(depth_scan, truth["depth"], truth["swept"], distance,
                              swept_surface=truth["swept_surface"])
    acc_live = depth_accuracy(depth_live, truth["depth"], truth["swept"], distance,
                              swept_surface=truth["swept_surface"])
    both = np.isfinite(depth_scan) & np.isfinite(depth_live)
    diff_rms = float(np.sqrt(np.mean((depth_scan[both] - depth_live[both]) ** 2))) if both.any() else float("nan")
    identical = bool(np.array_equal(depth_scan, depth_live, equal_nan=True))

    # latency: the shadow leaves a pixel in the first frame after its true leave time
    leave_frame = np.ceil(truth["leave_time"])
    logged = stats.logged_at
    ok = (logged >= 0) & np.isfinite(leave_frame)
    latency = (logged - leave_frame)[ok]
    wall = stats.logged_wall
    ok_wall = (wall >= 0) & np.isfinite(leave_frame)
    latency_wall = (wall - leave_frame)[ok_wall]
    # the live points' own error (the provisional cloud): depth of the logged points vs truth
    report = json.loads((out / "live" / "report.json").read_text())

    summary = {
        "image": list(depth_scan.shape[::-1]), "video": video.name,
        "frames": stats.frames, "dropped_frames": len(stats.dropped), "realtime_fps": stats.fps,
        "live_run_s": round(live_s, 1), "scan_run_s": round(scan_s, 1),
        "live_step_ms_median": report["tracking"]["live"]["live_step_ms_median"],
        "live_step_ms_p95": report["tracking"]["live"]["live_step_ms_p95"],
        "live_step_cpu_ms_median": report["tracking"]["live"]["live_step_cpu_ms_median"],
        # the whole pass (decode, tracking, live work, recording), CPU of all threads, per frame
        "pass_cpu_ms_per_frame": 1e3 * report["tracking"]["live"]["pass_cpu_s"] / max(stats.frames, 1),
        "pass_wall_ms_per_frame": 1e3 * report["tracking"]["live"]["pass_wall_s"] / max(stats.frames, 1),
        "points_logged_live": stats.points_logged,
        "latency_frames_median": float(np.median(latency)) if latency.size else None,
        "latency_frames_p90": float(np.percentile(latency, 90)) if latency.size else None,
        # with --realtime: counted in the frames the camera delivered meanwhile (wall clock)
        "latency_wall_frames_median": float(np.median(latency_wall)) if latency_wall.size else None,
        "latency_wall_frames_p90": float(np.percentile(latency_wall, 90)) if latency_wall.size else None,
        "scan_rms_error": acc_scan.rms, "live_final_rms_error": acc_live.rms,
        "final_depth_rms_difference": diff_rms,
        "difference_over_scan_rms": diff_rms / acc_scan.rms if acc_scan.rms else None,
        "final_identical_to_scan": identical,
        "coverage_scan_pct": 100 * acc_scan.coverage, "coverage_live_pct": 100 * acc_live.coverage,
        "coverage_difference_pt": 100 * (acc_live.coverage - acc_scan.coverage),
    }
    print(json.dumps(summary, indent=2))
    del s


if __name__ == "__main__":
    main()
