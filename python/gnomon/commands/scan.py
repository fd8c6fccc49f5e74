"""`gnomon scan FIELD_LOG [--out DIR]`: the main job."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "scan",
        help="reconstruct 3D from a field log",
        description="Track the shadow in every pixel, find the shadow planes and triangulate. "
        "Writes points.ply, mesh.ply, depth.npy, shadow_time.npy, report.json and scan.rrd.",
    )
    p.add_argument("field_log", type=Path, help="the capture's field log (TOML)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: scan/ beside the field log)")
    rec = p.add_mutually_exclusive_group()
    rec.add_argument("--no-rrd", action="store_true", help="do not write a rerun recording")
    rec.add_argument("--rrd", type=Path, default=None, help="write the recording here instead of OUT/scan.rrd")
    p.add_argument("--view", action="store_true", help="also stream the recording to a rerun viewer")
    p.add_argument("--frame-stride", type=int, default=10, help="keep every N-th frame in the recording")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from gnomon.pipeline import ScanOptions, run_scan

    out = args.out if args.out is not None else args.field_log.parent / "scan"
    opts = ScanOptions(rrd=not args.no_rrd, rrd_path=args.rrd, view=args.view,
                       progress=not args.quiet, frame_stride=max(1, args.frame_stride))
    result = run_scan(args.field_log, out, opts)
    cov = result.report["coverage"]
    planes = ", ".join(f"{e.name} edge {int(np.isfinite(e.planes[:, 0]).sum())}" for e in result.edges)
    print(f"{cov['points']} points ({100 * cov['fraction_of_image']:.1f} % of the image), "
          f"shadow planes: {planes}; {cov['mesh_faces']} mesh faces -> {out}")
    for w in result.warnings:
        print(f"warning: {w}")
    return 0
