"""Points only where the light reached: a scan of the simulated room against its truth (a script, not a test).

    PYTHONPATH=python python benchmarks/room_light.py [--capture DIR] [--out DIR] [--small] [--json FILE]

Renders ``gnomon simulate room`` (one bounce of interreflection between desk, wall
and the four solids, a 3 mm lamp for every shadow, shot and read noise: 640×480, 150
PNG frames; ``--small`` 400×300, 100 frames) into ``--capture`` unless a capture is
already there, scans it in memory (two-plane mode, the field log as written, or with
``--min-contrast DN``: 0 for the image noise's floor alone) and
prints, against the capture's ``ground_truth.npz``:

* false points: the share of output points on a pixel the shadow never crossed while
  it was lit, or more than 5 σ and 1 % of the distance off
  (:func:`gnomon.runs.accuracy.depth_accuracy`);
* points on pixels the lamp never lights directly (truth ``lit_directly`` false), and
  among them on those whose radiance only bounced light changes (``bounce_only``),
  with their median error (% of the distance);
* coverage of the directly lit swept pixels (truth ``swept``), over all and over
  those lit mostly by bounced light (``direct_share`` < 0.5);
* depth RMS and median (% of the distance) over the swept pixels;
* σ calibration: the RMS and median of |error| / σ over the swept pixels with a point;
* the scan's coverage classes (``coverage.npy``) on the never-lit pixels.

"Before" figures: run the script with main's package on the path
(``PYTHONPATH=/work/main/python``) on the same capture.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from gnomon import api
from gnomon.outputs.images import COVERAGE_CLASSES
from gnomon.runs.accuracy import depth_accuracy


def figures(scan: api.Scan, gt: dict) -> dict:
    truth = gt["depth"].astype(np.float64)
    dist = float(gt["camera_distance_mm"])
    depth = scan.depth.astype(np.float64)
    acc = depth_accuracy(depth, truth, gt["swept"], dist, sigma=scan.sigma, swept_surface=gt["swept_surface"])
    points = np.isfinite(depth)
    hit = np.isfinite(truth)
    never = hit & ~gt["lit_directly"]
    bounce = gt["bounce_only"]
    swept = gt["swept"]
    mostly_bounce = swept & (gt["direct_share"] < 0.5)
    with np.errstate(invalid="ignore"):
        err_pct = 100.0 * np.abs(depth - truth) / dist
        z = (depth - truth) / scan.sigma
    on = swept & points & np.isfinite(z)
    classes = {}
    if scan.coverage is not None:
        for k, (name, _) in COVERAGE_CLASSES.items():
            n = int((never & (scan.coverage == k)).sum())
            if n:
                classes[name] = n
    return {
        "output_points": acc.output_points,
        "false_points": acc.false_points,
        "false_point_pct": 100.0 * acc.false_point_rate,
        "never_lit_pixels": int(never.sum()),
        "points_never_lit": int((points & never).sum()),
        "points_never_lit_median_err_pct": float(np.median(err_pct[points & never])) if (points & never).any()
        else None,
        "bounce_only_pixels": int(bounce.sum()),
        "points_bounce_only": int((points & bounce).sum()),
        "swept_pixels": int(swept.sum()),
        "coverage_swept_pct": 100.0 * acc.coverage,
        "mostly_bounce_swept": int(mostly_bounce.sum()),
        "coverage_mostly_bounce_pct": 100.0 * float((points & mostly_bounce).sum() / max(mostly_bounce.sum(), 1)),
        "depth_rms_pct": acc.rms_pct,
        "depth_median_pct": acc.median_pct,
        "sigma_rms_ratio": float(np.sqrt(np.mean(z[on] ** 2))) if on.any() else None,
        "sigma_median_ratio": float(np.median(np.abs(z[on]))) if on.any() else None,
        "never_lit_by_class": classes,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--capture", type=Path, default=Path("room_capture"), help="the room capture (rendered if absent)")
    ap.add_argument("--small", action="store_true", help="render 400x300, 100 frames")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    ap.add_argument("--min-contrast", type=float, default=None, metavar="DN",
                    help="scan with this [scan] min_contrast instead of the field log's (0: none, the noise's floor)")
    args = ap.parse_args(argv)
    log = args.capture / "field_log.toml"
    if not log.is_file():
        t0 = time.perf_counter()
        opts = {"width": 400, "height": 300, "frames": 100} if args.small else {}
        api.simulate("room", args.capture, **opts)
        print(f"rendered {args.capture} in {time.perf_counter() - t0:.1f} s")
    gt = dict(np.load(args.capture / "ground_truth.npz"))
    if args.min_contrast is not None:
        from gnomon.util import toml_io

        table = toml_io.load(log)
        table["scan"].pop("min_contrast", None)
        if args.min_contrast > 0:
            table["scan"]["min_contrast"] = args.min_contrast
        log = args.capture / "field_log_min_contrast.toml"
        toml_io.dump(table, log)
    t0 = time.perf_counter()
    scan = api.scan(log)
    seconds = time.perf_counter() - t0
    f = figures(scan, gt)
    f["scan_s"] = seconds
    print(f"room scan of {args.capture} ({seconds:.1f} s)")
    print(f"  false points              {f['false_point_pct']:6.2f} % of {f['output_points']} points")
    print(f"  points never lit directly {f['points_never_lit']} of {f['never_lit_pixels']} pixels"
          + (f" (median {f['points_never_lit_median_err_pct']:.2f} % off)" if f['points_never_lit'] else ""))
    print(f"    of them bounce only     {f['points_bounce_only']} of {f['bounce_only_pixels']} pixels")
    print(f"  coverage, lit swept       {f['coverage_swept_pct']:6.2f} % of {f['swept_pixels']} pixels")
    print(f"    lit mostly by bounce    {f['coverage_mostly_bounce_pct']:6.2f} % of {f['mostly_bounce_swept']}")
    print(f"  depth RMS / median        {f['depth_rms_pct']:.3f} / {f['depth_median_pct']:.3f} % of the distance")
    print(f"  error/σ RMS / median|.|   {f['sigma_rms_ratio']:.2f} / {f['sigma_median_ratio']:.2f}")
    print(f"  never-lit pixels by class {f['never_lit_by_class']}")
    for w in scan.warnings:
        print(f"  warning: {w}")
    if args.json:
        args.json.write_text(json.dumps(f, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
