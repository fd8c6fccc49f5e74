"""What a scan's default recording costs before any of the scan's own work, against the 2x-floor budget
(a script, not a test).

    PYTHONPATH=python python benchmarks/recording_cost.py [--points N] [--runs R] [--bench BENCH.json]

In a fresh interpreter each run (the imports are paid once per process, as `gnomon scan` pays them):
``import rerun``; the first array of strings handed to pyarrow (which imports pandas: rerun's blueprint
and names make one); the opening of :class:`gnomon.recording.recorder.ScanRecording` with its default
layout; ``log_points`` of ``N`` points as a scan logs them (float32 positions, uint8 colours, σ, pixel
uv; random values); and ``close`` (rerun's in-memory encoder, then the file written). Each part's CPU
and wall seconds; the minimum over ``--runs``.

With ``--bench`` (the JSON of ``gnomon bench --scan FIELD_LOG --json BENCH.json``) it also prints that
capture's decode+track floor, the CPU a scan within 2x of it may spend beyond it, and how much of that the
recording's fixed part takes, beside what the scan spent beyond its floor.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

CHILD = textwrap.dedent("""
    import json, sys, time
    n, path = int(sys.argv[1]), sys.argv[2]
    out = {}
    def part(name, fn):
        c, w = time.process_time(), time.perf_counter()
        value = fn()
        out[name] = (time.process_time() - c, time.perf_counter() - w)
        return value
    import numpy as np
    part("import rerun", lambda: __import__("rerun"))
    import pyarrow as pa
    part("pyarrow's first strings (imports pandas)", lambda: pa.array(["a"], type=pa.utf8()))
    from gnomon.recording.recorder import ScanRecording
    rec = part("open the recording (layout, names)",
               lambda: ScanRecording(path, recording_name="cost", log_notes=False, full=False))
    rng = np.random.default_rng(0)
    xyz = rng.random((n, 3), dtype=np.float32)
    rgb = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    sigma = rng.random(n, dtype=np.float32)
    uv = rng.random((n, 2), dtype=np.float32)
    part(f"log {n} points", lambda: rec.log_points(xyz, rgb, sigma, uv=uv))
    part("close (encode, write the file)", rec.close)
    print(json.dumps(out))
""")


def one_run(points: int) -> dict[str, tuple[float, float]]:
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.run([sys.executable, "-c", CHILD, str(points), str(Path(tmp) / "cost.rrd")],
                              capture_output=True, text=True, check=True)
    return {k: tuple(v) for k, v in json.loads(proc.stdout.strip().splitlines()[-1]).items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=1_961_034, help="points logged (default: the synthetic "
                    "1080p capture's scan)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--bench", type=Path, help="gnomon bench --scan --json output of a capture")
    args = ap.parse_args()
    runs = [one_run(args.points) for _ in range(args.runs)]
    best = {k: (min(r[k][0] for r in runs), min(r[k][1] for r in runs)) for k in runs[0]}
    fixed = sum(c for c, _ in best.values())
    print(f"the default recording's own cost, {args.points} points, minimum of {args.runs} fresh processes:")
    for name, (cpu, wall) in best.items():
        print(f"  {name:42s} {cpu:6.3f} s CPU {wall:6.3f} s wall")
    print(f"  {'total':42s} {fixed:6.3f} s CPU")
    if args.bench is not None:
        b = json.loads(args.bench.read_text())
        floor_cpu, floor_wall = b["track"]["cpu_seconds"], b["track"]["seconds"]
        beyond_cpu = b["scan_cpu_seconds"] - floor_cpu
        beyond_wall = b["scan_seconds"] - floor_wall
        print(f"{b['field_log']}: {b['frames']} frames {b['width']}x{b['height']}")
        print(f"  floor (decode+track)  {floor_wall:6.2f} s wall {floor_cpu:6.2f} s CPU: a scan within 2x may spend as "
              "much again beyond it")
        print(f"  the scan beyond it    {beyond_wall:6.2f} s wall {beyond_cpu:6.2f} s CPU "
              f"({beyond_cpu / floor_cpu:.2f}x the floor's CPU)")
        print(f"  the recording's fixed part above: {fixed / floor_cpu:.0%} of the floor's CPU, "
              f"{fixed / beyond_cpu:.0%} of what the scan spent beyond it")
    return 0


if __name__ == "__main__":
    sys.exit(main())
