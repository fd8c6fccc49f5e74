"""`gnomon scan FIELD_LOG [--out DIR]`: the main job, a thin wrapper around :func:`gnomon.api.scan`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.recording.recorder import add_recording_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "scan",
        help=COMMANDS["scan"],
        description="Track the shadow in every pixel, find the shadow planes and triangulate. "
        "Writes points.ply, mesh.ply (and mesh.obj, mesh.stl with --mesh-formats), depth.npz (with the "
        "camera), depth.npy, sigma.npy, shadow_time.npy, preview.png, report.json and scan.rrd "
        "(points_enu.ply for a sun scan), all at once on success. The same as gnomon.scan(FIELD_LOG, OUT) "
        "in Python.",
    )
    p.add_argument("field_log", type=Path, help="the capture's field log (TOML)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: scan/ beside the field log)")
    p.add_argument("--mesh-formats", type=mesh_formats_option, default=None, metavar="LIST",
                   help="the mesh's files: 'all', or formats joined by commas among ply (always), obj (with "
                   "its .mtl and .png texture) and stl; default: the field log's [output] mesh_formats, "
                   "else ply only")
    p.add_argument("--cloud-formats", type=cloud_formats_option, default=None, metavar="LIST",
                   help="survey point clouds: 'all', 'none', or formats joined by commas among las and laz (with "
                   "colour, normal, sigma and pixel per point); default: the field log's [output] cloud_formats, else "
                   "laz for a sun scan (in a projected CRS) and none for a desk scan")
    p.add_argument("--crs", default=None, metavar="CRS",
                   help="a sun scan's survey files in this coordinate reference system (e.g. EPSG:2056; anything "
                   "pyproj reads); default: the field log's [output] crs, else the site's UTM zone")
    add_recording_arguments(p)
    p.add_argument("--rrd-full", action="store_true",
                   help="the recording also holds the mesh and the maps at full size (larger and slower to write; "
                   "by default it has the points at full size, the maps at its frames' size and no mesh)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    tiles = p.add_argument_group("tiled scan on Dask (pip install \"gnomon[dask]\"; see docs/batch.md)")
    tiles.add_argument("--tiles", default=None, metavar="RxC",
                       help="track R x C image tiles on Dask workers and stitch the maps (same result)")
    tiles.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    tiles.add_argument("--workers", type=int, default=None, metavar="N", help="local cluster size")
    p.set_defaults(func=run)


def mesh_formats_option(value: str) -> tuple[str, ...]:
    """--mesh-formats: the formats it names (argparse's error otherwise)."""
    from gnomon.outputs.formats import mesh_formats, names_of

    chosen = mesh_formats(value)
    if chosen is None:
        raise argparse.ArgumentTypeError(f"expected 'all' or formats among {', '.join(names_of('mesh'))}, "
                                         f"got {value!r}")
    return chosen


def cloud_formats_option(value: str) -> tuple[str, ...]:
    """--cloud-formats: the formats it names, or none (argparse's error otherwise)."""
    from gnomon.outputs.formats import cloud_formats, names_of

    chosen = () if value.strip().lower() == "none" else cloud_formats(value)
    if chosen is None:
        raise argparse.ArgumentTypeError(f"expected 'all', 'none' or formats among {', '.join(names_of('cloud'))}, "
                                         f"got {value!r}")
    return chosen


def run(args: argparse.Namespace) -> int:
    from gnomon import api

    out = args.out if args.out is not None else args.field_log.parent / "scan"
    s = api.scan(args.field_log, out, rrd=not args.no_rrd, rrd_path=args.rrd, view=args.view,
                 progress=not args.quiet, frame_stride=args.frame_stride, tiles=args.tiles,
                 scheduler=args.scheduler, workers=args.workers, mesh_formats=args.mesh_formats,
                 cloud_formats=args.cloud_formats, crs=args.crs, rrd_full=args.rrd_full)
    if args.tiles is not None:
        info = s.report["tracking"]
        peaks = [p for p in info["worker_peak_rss_bytes"] if p is not None]
        print(f"{info['tiles']} tiles on {len(set(info['workers']))} workers"
              + (f", peak worker memory {max(peaks) / 2**20:.0f} MiB" if peaks else ""))
    cov = s.report["coverage"]
    planes = ", ".join(f"{name} edge {e['shadow_planes']}" for name, e in s.report["edges"].items()
                       if name != "disagreement")
    print(f"{cov['points']} points ({100 * cov['fraction_of_image']:.1f} % of the image), "
          f"shadow planes: {planes}; {cov['mesh_faces']} mesh faces -> {out}")
    for n in s.notes:
        print(f"gnomon: note: {n}", file=sys.stderr)
    for w in s.warnings:
        print(f"gnomon: warning: {w}", file=sys.stderr)
    return 0
