"""A camera that drifts during a sun scan: the scan still, drifted and not compensated, drifted and registered.

    PYTHONPATH=python python benchmarks/camera_drift.py [--out DIR] [--small] [--drift PX] [--bump PX] [--seed N]

Simulates the facade_sun scene twice with the same seed (``gnomon.simulate.facade_sun``; 800×600 and
200 frames, or 400×300 and 100 with ``--small``): with a still camera, and with a camera that drifts
(x linear and y quadratic in time, ``--drift`` px by the last frame) and is knocked once (``--bump`` px
at 60 % of the way), its exact motion per frame in the ground truth (``camera_motion_px``). Then scans:

* the still capture as shipped (registration on, the sun's default) and with ``[capture] register =
  "off"``: the two must be the same files (registration found no motion);
* the drifted capture with ``register = "off"`` (what Gnomon did before) and as shipped.

Prints, per scan, the depth error over the truth's swept pixels (RMS, median, % of the camera
distance), the gross errors (> 1 % of the distance) and false points over all output points, the
coverage, the tracking's wall time; for the registered scans the motion's error against the truth
(largest and RMS over the frames, px) and the registration's cost per frame (measuring, resampling).
Captures already in ``--out`` are reused.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import sys
from pathlib import Path

import numpy as np

from gnomon.runs.accuracy import depth_accuracy
from gnomon.runs.scan import ScanOptions, run_scan
from gnomon.simulate import FacadeSunConfig, simulate_facade_sun
from gnomon.util import toml_io


def capture(folder: Path, config: FacadeSunConfig) -> Path:
    if not (folder / "field_log.toml").is_file():
        print(f"simulating {folder.name} …", file=sys.stderr, flush=True)
        simulate_facade_sun(folder, config)
    return folder


def with_register(folder: Path, mode: str) -> Path:
    log = toml_io.load(folder / "field_log.toml")
    log["capture"]["register"] = mode
    path = folder / f"field_log_register_{mode}.toml"
    toml_io.dump(log, path)
    return path


def scan(name: str, log: Path, out: Path) -> dict:
    result = run_scan(log, out, ScanOptions(progress=False, rrd=False))
    truth = dict(np.load(log.parent / "ground_truth.npz"))
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], float(truth["camera_distance"]), "m",
                         sigma=result.sigma, swept_surface=truth["swept_surface"])
    row = {"scan": name, "rms_pct": acc.rms_pct, "median_pct": acc.median_pct, "gross_pct": 100 * acc.gross_rate,
           "false_pct": 100 * acc.false_point_rate, "coverage_pct": 100 * acc.coverage,
           "tracking_s": result.report["timings_s"]["tracking_s"], "frames": len(truth["frame_times_utc"])}
    reg = result.report.get("registration")
    if reg is not None:
        motion = np.array([[np.nan, np.nan] if m is None else m for m in reg["motion_px"]], dtype=float)
        error = np.hypot(*(motion - truth["camera_motion_px"]).T)
        row.update(motion_error_max_px=float(np.nanmax(error)),
                   motion_error_rms_px=float(np.sqrt(np.nanmean(error**2))),
                   compensated=reg["frames_compensated"], measure_ms=reg["ms_per_frame"]["measure"],
                   resample_ms=reg["ms_per_frame"]["resample"], border=reg["border_pixels_left_out"],
                   non_translation_max_px=reg["max_non_translation_px"])
    return row


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, default=Path("camera_drift_bench"))
    p.add_argument("--small", action="store_true", help="400x300, 100 frames (default 800x600, 200 frames)")
    p.add_argument("--drift", type=float, default=2.0, help="the slow drift by the last frame, px (default 2)")
    p.add_argument("--bump", type=float, default=1.0, help="the sudden shift, px (default 1)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    size = dict(width=400, height=300, frames=100) if args.small else {}
    tag = "small" if args.small else "full"
    still = capture(args.out / f"still_{tag}_{args.seed}", FacadeSunConfig(seed=args.seed, **size))
    drifted = capture(args.out / f"drift_{tag}_{args.seed}_{args.drift:g}_{args.bump:g}",
                      FacadeSunConfig(seed=args.seed, drift_px=args.drift, bump_px=args.bump, **size))
    rows = [scan("still", still / "field_log.toml", args.out / "scan_still"),
            scan("still, register off", with_register(still, "off"), args.out / "scan_still_off"),
            scan("drifted, register off", with_register(drifted, "off"), args.out / "scan_drift_off"),
            scan("drifted, registered", drifted / "field_log.toml", args.out / "scan_drift")]
    same = all(filecmp.cmp(args.out / "scan_still" / f, args.out / "scan_still_off" / f, shallow=False)
               for f in ("depth.npy", "sigma.npy", "shadow_time.npy", "points.ply", "mesh.ply"))
    print(f"facade_sun {tag} (seed {args.seed}), drift {args.drift:g} px + bump {args.bump:g} px")
    print(f"{'scan':24s} {'RMS %':>7s} {'median %':>8s} {'gross %':>7s} {'false %':>7s} {'cover %':>7s} "
          f"{'track s':>7s}  motion error max / RMS px   registration CPU ms/frame (measure, resample)")
    for r in rows:
        line = (f"{r['scan']:24s} {r['rms_pct']:7.3f} {r['median_pct']:8.3f} {r['gross_pct']:7.2f} "
                f"{r['false_pct']:7.2f} {r['coverage_pct']:7.1f} {r['tracking_s']:7.2f}")
        if "motion_error_max_px" in r:
            line += (f"  {r['motion_error_max_px']:.3f} / {r['motion_error_rms_px']:.3f}"
                     f"{'':15s}{r['measure_ms']:.1f}, {r['resample_ms']:.1f} ({r['compensated']} frames resampled)")
        print(line)
    ratio = rows[3]["rms_pct"] / rows[0]["rms_pct"]
    print(f"drifted-registered RMS / still RMS = {ratio:.2f}; "
          f"still scan the same with and without registration: {same}")
    (args.out / f"camera_drift_{tag}.json").write_text(json.dumps({"rows": rows, "still_identical": same}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
