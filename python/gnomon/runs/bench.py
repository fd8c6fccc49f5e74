"""Throughput and memory of the streaming tracker: the Rust kernel against the
numpy implementation of the same algorithm (:class:`gnomon.capture.tracking.NumpyTracker`).

Frames are synthesised in advance: ``DISTINCT`` grey frames (uint8) of a soft
shadow band sweeping across the image with Gaussian noise, fed in a cycle, so
decoding never enters the timing. Both trackers evaluate blocks of ``W``
(``max_width``) frames, the first once frame ``2W + m − 2`` has arrived: they
are warmed up to there, then timed over the requested number of frames rounded
up to whole blocks; ``finish`` is timed once, separately. The cycle shows every pixel a new dip every ``DISTINCT``
frames, so new deepest dips (and their window captures) keep occurring: a
harder load than a real sweep, where a pixel is shadowed once.

Peak memory (peak RSS: ``VmHWM``, else ``ru_maxrss``) is measured in fresh
subprocesses, before the parent allocates its frames,
``python -m gnomon.runs.bench --child N``, that synthesise the frames, run the
kernel over ``N`` frames and finish: memory must not grow with ``N``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from gnomon import _kernel
from gnomon.capture.tracking import NumpyTracker

DISTINCT = 32
"""Distinct synthetic frames, fed in a cycle."""

MIN_CONTRAST = 20.0


def _logistic(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1 + np.tanh(0.5 * z))


def synthetic_frames(height: int, width: int, count: int = DISTINCT, seed: int = 0) -> list[np.ndarray]:
    """``count`` uint8 frames (height, width): a shadow band a quarter of the width
    wide, with logistic edges (scale 3 px), sweeping left to right over the cycle;
    lit 200 DN, shadow 40 DN, plus Gaussian noise σ = 2 DN."""
    rng = np.random.default_rng(seed)
    x = np.arange(width, dtype=np.float32)
    band = width / 4
    frames = []
    for f in range(count):
        centre = -band / 2 + (f + 0.5) / count * (width + band)
        inside = _logistic((x - (centre - band / 2)) / 3) * _logistic(((centre + band / 2) - x) / 3)
        row = 200 - 160 * inside
        noise = rng.standard_normal((height, width), dtype=np.float32) * 2
        frames.append(np.clip(row[None, :] + noise, 0, 255).round().astype(np.uint8))
    return frames


def _feed(tracker, frames: list[np.ndarray], n: int, start: int = 0) -> Throughput:
    """Feed ``n`` frames of the cycle (from ``start``), timed."""
    t0, c0 = time.perf_counter(), time.process_time()
    for i in range(start, start + n):
        tracker.update(frames[i % len(frames)])
    return Throughput(n, time.perf_counter() - t0, time.process_time() - c0)


@dataclass
class Throughput:
    """``frames`` fed in ``seconds`` of wall-clock time, using ``cpu_seconds``
    of CPU time over all the process's threads (less sensitive than the wall
    clock to other load on the machine)."""

    frames: int
    seconds: float
    cpu_seconds: float

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


@dataclass
class BenchResult:
    """Figures of one ``gnomon bench`` run (times in seconds, memory in MiB)."""

    width: int
    height: int
    dtype: str
    window: int
    max_width: int
    cpus: int
    machine: str
    simd_path: str
    kernel: Throughput
    numpy: Throughput
    kernel_finish_s: float
    numpy_finish_s: float
    memory_mib: dict[int, float]
    load_average: float
    """1-minute load average of the machine when the run ended (other processes skew wall times)."""

    @property
    def speedup(self) -> float:
        return self.kernel.fps / self.numpy.fps

    def to_dict(self) -> dict:
        d = asdict(self)
        d["kernel"]["fps"] = self.kernel.fps
        d["numpy"]["fps"] = self.numpy.fps
        d["speedup"] = self.speedup
        d["memory_mib"] = {str(k): v for k, v in self.memory_mib.items()}
        if len(self.memory_mib) >= 2:
            lo, hi = min(self.memory_mib), max(self.memory_mib)
            d["memory_ratio"] = self.memory_mib[hi] / self.memory_mib[lo]
        return d


def peak_memory_mib(frames: int, height: int, width: int, window: int, max_width: int) -> float:
    """Peak RSS (MiB) of a fresh process that runs the kernel over ``frames`` frames."""
    cmd = [sys.executable, "-m", "gnomon.runs.bench", "--child", str(frames),
           "--height", str(height), "--width", str(width), "--window", str(window), "--max-width", str(max_width)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return float(json.loads(out.strip().splitlines()[-1])["maxrss_mib"])


def run_bench(
    frames: int = 1000,
    numpy_frames: int = 30,
    width: int = 1920,
    height: int = 1080,
    window: int = 4,
    max_width: int = 32,
    memory_frames: tuple[int, ...] = (100, 1000),
) -> BenchResult:
    """Measure the kernel over ``frames`` frames and the numpy tracker over
    ``numpy_frames`` frames of the same synthetic sequence, and the peak memory
    of a kernel run over each of ``memory_frames`` (empty: skip)."""
    memory = {n: peak_memory_mib(n, height, width, window, max_width) for n in memory_frames}
    distinct = synthetic_frames(height, width)

    # Both trackers evaluate blocks of W frames, the first once frame 2W + m − 2 is
    # in: warm up to there, then time whole blocks (frames rounded up to W).
    warm = 2 * max_width + window - 1
    frames, numpy_frames = (-(-n // max_width) * max_width for n in (frames, numpy_frames))
    kernel = _kernel.TemporalTracker(height, width, "uint8", window=window, max_width=max_width)
    _feed(kernel, distinct, warm)
    kernel_t = _feed(kernel, distinct, frames, start=warm)
    t0 = time.perf_counter()
    kernel.finish(MIN_CONTRAST)
    kernel_finish = time.perf_counter() - t0
    del kernel

    reference = NumpyTracker(height, width, "uint8", window=window, max_width=max_width)
    _feed(reference, distinct, warm)
    numpy_t = _feed(reference, distinct, numpy_frames, start=warm)
    t0 = time.perf_counter()
    reference.finish(MIN_CONTRAST)
    numpy_finish = time.perf_counter() - t0
    del reference, distinct
    return BenchResult(
        width=width,
        height=height,
        dtype="uint8",
        window=window,
        max_width=max_width,
        cpus=os.cpu_count() or 1,
        machine=f"{platform.machine()} {platform.processor() or platform.system()}".strip(),
        simd_path=_kernel.simd_path(),
        kernel=kernel_t,
        numpy=numpy_t,
        kernel_finish_s=kernel_finish,
        numpy_finish_s=numpy_finish,
        memory_mib=memory,
        load_average=_load_average(),
    )


def _load_average() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def format_table(r: BenchResult) -> str:
    """A compact plain-text table of the figures."""
    lines = [
        (
            f"gnomon bench: {r.width}x{r.height} {r.dtype}, window {r.window}, max width {r.max_width}, {r.cpus} CPUs, "
            f"kernel SIMD path {r.simd_path} (GNOMON_SIMD forces a lower one), load average {r.load_average:.1f}"
        ),
        f"  {'tracker':<8} {'frames':>7} {'seconds':>9} {'frames/s':>10} {'CPU ms/frame':>13} {'finish':>10}",
        *(
            f"  {name:<8} {t.frames:>7} {t.seconds:>9.3f} {t.fps:>10.0f} "
            f"{t.cpu_seconds / t.frames * 1e3:>13.3f} {finish * 1e3:>7.0f} ms"
            for name, t, finish in (
                ("kernel", r.kernel, r.kernel_finish_s),
                ("numpy", r.numpy, r.numpy_finish_s),
            )
        ),
        f"  speed-up {r.speedup:.1f}x (frames/s), "
        f"{(r.numpy.cpu_seconds / r.numpy.frames) / (r.kernel.cpu_seconds / r.kernel.frames):.1f}x "
        "(CPU time per frame)",
    ]
    if r.memory_mib:
        mem = ", ".join(f"{n} frames {mib:.0f} MiB" for n, mib in sorted(r.memory_mib.items()))
        lines.append(f"  peak RSS (kernel, fresh process): {mem}")
        if len(r.memory_mib) >= 2:
            lo, hi = min(r.memory_mib), max(r.memory_mib)
            lines.append(f"  memory ratio {hi}/{lo} frames: {r.memory_mib[hi] / r.memory_mib[lo]:.3f}")
    return "\n".join(lines)


@dataclass
class ScanBench:
    """One ``gnomon bench --scan`` run: decoding a capture's frames alone, then
    the whole scan of it, in the same process (seconds; the scan's stage
    timings as its ``report.json`` gives them)."""

    field_log: str
    frames: int
    width: int
    height: int
    decode: Throughput
    scan_seconds: float
    scan_cpu_seconds: float
    stages: dict[str, float]
    load_average: float
    stages_cpu: dict[str, float] = field(default_factory=dict)
    """CPU seconds during the stages that report it (the process's threads; the recording: its own thread)."""
    mesh_formats: list[str] = field(default_factory=list)
    """The mesh's files the scan wrote (gnomon.config.fieldlog.MESH_FORMATS)."""
    decode_threads: int = 1
    """Threads that decoded the frames, alone and in the scan (image files: one per core, at most 4;
    a video: one)."""
    decode_one_thread: Throughput | None = None
    """Decoding the image files alone on one thread (as the scan's reader did before it decoded on
    several), when ``decode_threads`` > 1: for comparison with figures taken then."""
    track: Throughput | None = None
    """Decoding and tracking alone: one pass of the scan's own reader and kernel tracker (its settings,
    one dip width) over the frames, and nothing after it: what no scan of the capture can go below."""
    no_rrd_seconds: float | None = None
    no_rrd_cpu_seconds: float | None = None
    """The same scan without its recording (``gnomon scan --no-rrd``), run after it: the recording's cost
    is the difference (its thread, rerun's own threads and its import, which the first scan pays)."""

    @property
    def floor_ratio(self) -> tuple[float, float] | None:
        """Whole scan over the decode+track floor: (wall, CPU), None without the floor."""
        if self.track is None or self.track.seconds <= 0 or self.track.cpu_seconds <= 0:
            return None
        return self.scan_seconds / self.track.seconds, self.scan_cpu_seconds / self.track.cpu_seconds

    @property
    def recording_share(self) -> tuple[float, float] | None:
        """The recording's share of the whole scan, (wall, CPU): one minus the scan without it over the
        scan with it; None without that scan."""
        if self.no_rrd_seconds is None or self.no_rrd_cpu_seconds is None or self.scan_seconds <= 0:
            return None
        return (1.0 - self.no_rrd_seconds / self.scan_seconds,
                1.0 - self.no_rrd_cpu_seconds / self.scan_cpu_seconds if self.scan_cpu_seconds > 0 else 0.0)

    @property
    def ratio(self) -> float:
        """Whole-scan wall time over decode-alone wall time."""
        return self.scan_seconds / self.decode.seconds if self.decode.seconds > 0 else float("inf")

    @property
    def cpu_ratio(self) -> float:
        """Whole-scan CPU time over decode-alone CPU time (all threads; less sensitive to other load)."""
        return self.scan_cpu_seconds / self.decode.cpu_seconds if self.decode.cpu_seconds > 0 else float("inf")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["ratio"] = self.ratio
        d["cpu_ratio"] = self.cpu_ratio
        d["floor_ratio"] = self.floor_ratio
        d["recording_share"] = self.recording_share
        return d


def run_scan_bench(field_log: str, out_dir: str, mesh_formats: tuple[str, ...] | None = None,
                   no_rrd_dir: str | None = None) -> ScanBench:
    """Time decoding the frames of ``field_log``'s capture alone (the scan's own
    reader: its decoding threads, grey conversion), one tracking pass alone, then the whole default scan
    into ``out_dir`` (outputs and recording included; ``mesh_formats`` the mesh's
    files, default the field log's) and, with ``no_rrd_dir``, the same scan without its recording into
    that folder."""
    from gnomon.capture.frames import FrameSource, decode_workers
    from gnomon.config.fieldlog import load_field_log
    from gnomon.runs.scan import ScanOptions, run_scan

    log = load_field_log(field_log)
    source = FrameSource(log.capture.image_files, log.capture.video, log.capture.frame_count,
                         log.capture.on_corrupt_frame)
    threads = decode_workers() if source.video is None else 1
    one_thread = None
    if threads > 1:
        source.decode_threads = 1
        one_thread = _decode_pass(source)[0]
        source.decode_threads = None
    decode, shape = _decode_pass(source)
    track = _track_pass(log, source)
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_scan(field_log, out_dir, ScanOptions(mesh_formats=mesh_formats))
    scan_s, scan_cpu = time.perf_counter() - t0, time.process_time() - c0
    stages = {k: float(v) for k, v in result.report.get("timings_s", {}).items()}
    stages_cpu = {k: float(v) for k, v in result.report.get("cpu_timings_s", {}).items()}
    bench = ScanBench(str(field_log), decode.frames, int(shape[1]), int(shape[0]), decode, scan_s, scan_cpu,
                      stages, _load_average(), stages_cpu, list(result.setup.mesh_formats), threads, one_thread,
                      track)
    del result
    if no_rrd_dir is not None:
        t0, c0 = time.perf_counter(), time.process_time()
        run_scan(field_log, no_rrd_dir, ScanOptions(rrd=False, mesh_formats=mesh_formats))
        bench.no_rrd_seconds, bench.no_rrd_cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
        bench.load_average = _load_average()
    return bench


def _decode_pass(source) -> tuple[Throughput, tuple[int, int]]:
    """Time one pass over ``source``'s frames (a FrameSource); returns it and the frames' (H, W)."""
    t0, c0 = time.perf_counter(), time.process_time()
    count, shape = 0, (0, 0)
    for frame in source:
        count, shape = count + 1, frame.grey.shape
    return Throughput(count, time.perf_counter() - t0, time.process_time() - c0), shape


def _track_pass(log, source) -> Throughput:
    """Time one tracking pass over ``source``'s frames as the scan makes it (its reader, its kernel tracker
    with the field log's settings, the frames the light skips), the shadow times included, nothing after."""
    from gnomon.capture.tracking import track_source
    from gnomon.config.setup import resolve_scan

    setup = resolve_scan(log, source)
    t0, c0 = time.perf_counter(), time.process_time()
    tracked = track_source(source, setup.tracker, (setup.camera.height, setup.camera.width),
                           skip=setup.light.skipped_frames(source.count))
    return Throughput(tracked.n_frames, time.perf_counter() - t0, time.process_time() - c0)


# The scan's stages in their order (report.json's timings_s; those on the recording's thread marked).
SCAN_STAGES = (("setup_s", "set-up (field log, camera, marks)"), ("tracking_s", "decode + track"),
               ("ray_map_s", "ray map (what tracking left)"), ("regions_s", "regions held to their planes"),
               ("planes_and_triangulation_s", "shadow planes, triangulation"),
               ("fusion_and_mesh_s", "fusion, points, mesh"), ("outputs_s", "output files (after the mesh)"),
               ("recording_points_s", "recording: points (its thread)"),
               ("recording_s", "recording: the rest (its thread)"),
               ("recording_wait_s", "waiting for the recording"))


def format_scan_table(r: ScanBench) -> str:
    """The bench's figures: decode, the floor, the whole scan against it (and without the recording), and
    each stage's wall and CPU seconds with their share of the whole scan's."""
    floor = r.floor_ratio
    share = r.recording_share
    lines = [
        (f"gnomon bench --scan {r.field_log}: {r.frames} frames {r.width}x{r.height}, "
         f"kernel SIMD path {_kernel.simd_path()}, load average {r.load_average:.1f}"),
        (f"  decode alone  {r.decode.seconds:8.2f} s wall {r.decode.cpu_seconds:8.2f} s CPU "
         f"({r.decode.fps:.0f} frames/s, {r.decode_threads} decoding thread{'s' if r.decode_threads > 1 else ''})"),
        *([f"  (on 1 thread  {r.decode_one_thread.seconds:8.2f} s wall {r.decode_one_thread.cpu_seconds:8.2f} s CPU: "
           f"the whole scan is {r.scan_seconds / r.decode_one_thread.seconds:.2f}x that wall time)"]
          if r.decode_one_thread is not None and r.decode_one_thread.seconds > 0 else []),
        *([f"  decode+track  {r.track.seconds:8.2f} s wall {r.track.cpu_seconds:8.2f} s CPU: "
           f"{r.track.seconds / r.decode.seconds:.2f}x the decode-alone wall time (the kernel tracker on the "
           "decoded frames, nothing after: the floor of any scan)"]
          if r.track is not None and r.decode.seconds > 0 else []),
        (f"  whole scan    {r.scan_seconds:8.2f} s wall {r.scan_cpu_seconds:8.2f} s CPU: "
         + (f"{floor[0]:.2f}x the floor's wall time, {floor[1]:.2f}x its CPU time; " if floor is not None else "")
         + f"{r.ratio:.2f}x the decode-alone wall time, {r.cpu_ratio:.2f}x its CPU time"
         + (f" (mesh formats {', '.join(r.mesh_formats)})" if r.mesh_formats else "")),
        *([f"  no recording  {r.no_rrd_seconds:8.2f} s wall {r.no_rrd_cpu_seconds:8.2f} s CPU (--no-rrd): the "
           f"recording is {100 * share[0]:.0f} % of the whole scan's wall time, {100 * share[1]:.0f} % of its CPU"]
          if share is not None and r.no_rrd_seconds is not None and r.no_rrd_cpu_seconds is not None else []),
        f"    {'stage':<36} {'wall s':>8} {'share':>6} {'CPU s':>8} {'share':>6}",
    ]
    named = dict(SCAN_STAGES)
    order = [k for k, _ in SCAN_STAGES if k in r.stages] + [k for k in r.stages if k not in named and k != "total_s"]
    for key in order:
        sec, cpu = r.stages[key], r.stages_cpu.get(key)
        wall = f"{sec:8.2f} {100 * sec / r.scan_seconds:5.0f}%" if r.scan_seconds > 0 else f"{sec:8.2f} {'':>6}"
        cpu_part = (f" {cpu:8.2f} {100 * cpu / r.scan_cpu_seconds:5.0f}%" if cpu is not None and r.scan_cpu_seconds > 0
                    else "")
        lines.append(f"    {named.get(key, key):<36} {wall}{cpu_part}")
    return "\n".join(lines)


def _child(frames: int, height: int, width: int, window: int, max_width: int) -> dict:
    distinct = synthetic_frames(height, width)
    tracker = _kernel.TemporalTracker(height, width, "uint8", window=window, max_width=max_width)
    _feed(tracker, distinct, frames)
    tracker.finish(MIN_CONTRAST)
    return {"frames": frames, "maxrss_mib": _peak_rss_kib() / 1024}


def _peak_rss_kib() -> float:
    """Peak resident memory of this process, KiB.

    Linux's ``ru_maxrss`` survives ``exec``: a child started by a big parent
    reports at least the parent's size at fork. ``VmHWM`` in
    ``/proc/self/status`` is the peak of this program's own address space.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1])
    except OSError:
        pass
    return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)  # KiB on Linux


def main(argv: list[str] | None = None) -> int:
    """``python -m gnomon.runs.bench --child N``: one memory measurement (JSON on stdout)."""
    p = argparse.ArgumentParser(prog="python -m gnomon.runs.bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--child", type=int, required=True, metavar="N", help="run the kernel over N frames")
    p.add_argument("--height", type=int, default=1080)
    p.add_argument("--width", type=int, default=1920)
    p.add_argument("--window", type=int, default=4)
    p.add_argument("--max-width", type=int, default=32)
    args = p.parse_args(argv)
    print(json.dumps(_child(args.child, args.height, args.width, args.window, args.max_width)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
