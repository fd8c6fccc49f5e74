"""`gnomon scan FIELD_LOG [--out DIR]`: the main job."""

from __future__ import annotations

import argparse
from pathlib import Path

from gnomon.errors import GnomonError


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
    tiles = p.add_argument_group("tiled scan on Dask (pip install \"gnomon[dask]\"; see docs/batch.md)")
    tiles.add_argument("--tiles", default=None, metavar="RxC",
                       help="track R x C image tiles on Dask workers and stitch the maps (same result)")
    tiles.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    tiles.add_argument("--workers", type=int, default=None, metavar="N", help="local cluster size")
    p.set_defaults(func=run)


def _run_tiled(args: argparse.Namespace, out: Path, opts):
    from gnomon.batch import close_client, connect_client
    from gnomon.fieldlog import load_field_log
    from gnomon.pipeline import run_scan
    from gnomon.tiles import TiledTracker, TileGrid

    grid = TileGrid.parse(args.tiles)
    if args.workers is not None and (args.workers < 1 or args.scheduler):
        raise GnomonError("--workers N (N >= 1) sizes a local cluster; not with --scheduler")
    cam = load_field_log(args.field_log).camera
    grid.bounds((cam.height, cam.width))  # a bad tiling fails here, before any cluster starts
    client, cluster = connect_client(args.scheduler, args.workers)
    try:
        opts.track = TiledTracker(client, grid, frame_stride=opts.frame_stride)
        result = run_scan(args.field_log, out, opts)
    finally:
        close_client(client, cluster)
    info = result.report["tracking"]
    peaks = [p for p in info["worker_peak_rss_bytes"] if p is not None]
    print(f"{info['tiles']} tiles on {len(set(info['workers']))} workers"
          + (f", peak worker memory {max(peaks) / 2**20:.0f} MiB" if peaks else ""))
    return result


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from gnomon.pipeline import ScanOptions, run_scan

    out = args.out if args.out is not None else args.field_log.parent / "scan"
    opts = ScanOptions(rrd=not args.no_rrd, rrd_path=args.rrd, view=args.view,
                       progress=not args.quiet, frame_stride=max(1, args.frame_stride))
    if args.tiles is None:
        if args.scheduler or args.workers is not None:
            raise GnomonError("--scheduler and --workers are for tiled scans: add --tiles RxC")
        result = run_scan(args.field_log, out, opts)
    else:
        result = _run_tiled(args, out, opts)
    cov = result.report["coverage"]
    planes = ", ".join(f"{e.name} edge {int(np.isfinite(e.planes[:, 0]).sum())}" for e in result.edges)
    print(f"{cov['points']} points ({100 * cov['fraction_of_image']:.1f} % of the image), "
          f"shadow planes: {planes}; {cov['mesh_faces']} mesh faces -> {out}")
    for w in result.warnings:
        print(f"warning: {w}")
    return 0
