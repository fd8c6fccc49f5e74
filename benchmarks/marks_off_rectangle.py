"""Marks nobody measured, placed off a rectangle by hand: what they cost (a script, not a test).

    PYTHONPATH=python python benchmarks/marks_off_rectangle.py [--off 0,1,2,5] [--seed 4] [--out DIR]

For each offset, simulates the two_plane scene (800x600) with its printed checkers at a rectangle's corners
of unknown size, each moved up to that many pixels off it (``--marks-off-px``; the field log declares half of
it as ``off_rectangle_px``, the disc's per-axis σ), scans it as the simulator wrote the field log, and prints
each plane's normal σ (report.json), the depth RMS against the truth over the swept pixels once scaled by
the one factor units "relative" leaves free (% of the distance), the coverage, or the refusal.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from gnomon.runs.accuracy import depth_accuracy  # noqa: E402
from gnomon.simulate import TwoPlaneConfig, simulate_two_plane  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--off", default="0,1,2,5")
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="gnomon-marks-off-"))
    for off in (float(x) for x in args.off.split(",")):
        capture = root / f"off_{off:g}"
        if not (capture / "field_log.toml").exists():
            simulate_two_plane(capture, TwoPlaneConfig(seed=args.seed, marks="unmeasured", marks_off_px=off))
        scan = capture / "scan"
        done = subprocess.run([sys.executable, "-m", "gnomon", "scan", str(capture / "field_log.toml"), "--out",
                               str(scan), "--no-rrd", "--quiet"], capture_output=True, text=True,
                              env={"PYTHONPATH": str(ROOT / "python"), "PATH": "/usr/bin:/bin"})
        if done.returncode != 0:
            print(f"marks up to {off:g} px off: refused: {done.stderr.strip()[:300]}")
            continue
        report = json.loads((scan / "report.json").read_text())
        sigmas = ", ".join(f"{p['plane']} ± {p['std_normal_deg']:.2f}°" for p in report["reference_planes"])
        truth = dict(np.load(capture / "ground_truth.npz"))
        depth = np.load(scan / "depth.npy").astype(np.float64)
        ok = np.isfinite(depth) & truth["swept"]
        k = float(np.median(truth["depth"][ok] / depth[ok]))
        acc = depth_accuracy(depth * k, truth["depth"], truth["swept"], float(truth["camera_distance_mm"]))
        print(f"marks up to {off:g} px off: normals {sigmas}; depth RMS {acc.rms_pct:.3f} %, median "
              f"{acc.median_pct:.3f} % of the distance, coverage {100 * acc.coverage:.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
