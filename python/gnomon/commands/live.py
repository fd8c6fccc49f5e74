"""`gnomon live FIELD_LOG [--source CAMERA|VIDEO|URL] [--realtime] [--connect URL] [--out DIR]`."""

from __future__ import annotations

import argparse
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.recording.recorder import add_recording_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "live",
        help=COMMANDS["live"],
        description="Track the shadow frame by frame and show depth as soon as the shadow has passed "
        "(rerun: the frame and its shadow edges, the shadow-time map filling in, points coloured by σ, "
        "coverage). When the source ends, on Ctrl-C or when the sweep is complete, writes what "
        "`gnomon scan` writes, all at once, from the same final pass.",
    )
    p.add_argument("field_log", type=Path, help="the capture's field log (TOML): camera, planes, light")
    p.add_argument("--source", default=None, metavar="CAMERA|VIDEO|URL",
                   help="frames from a camera index (0), a video file or a stream URL "
                        "(default: the field log's frames)")
    p.add_argument("--realtime", action="store_true",
                   help="pace a file at its frame rate, as a camera would deliver it (dropped frames are counted)")
    p.add_argument("--fps", type=float, default=None, help="frame rate for --realtime (default: the video's, "
                   "the field log's fps, else 30)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: live/ beside the field log)")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--connect", default=None, metavar="URL",
                      help="stream to a running rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    view.add_argument("--no-view", action="store_true", help="do not spawn a viewer (only OUT/scan.rrd)")
    p.add_argument("--until-complete", action="store_true",
                   help="stop when the sweep is complete also for a file (always for a camera or a stream)")
    p.add_argument("--recover", type=int, default=3,
                   help="frames back above the mid-level after which a pixel's shadow has passed (default 3)")
    p.add_argument("--max-frames", type=int, default=100000, help="longest run from a camera or a stream")
    add_recording_arguments(p, what="OUT/scan.rrd", rrd_path=False, view=False)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gnomon.recording.recorder import display_available
    from gnomon.runs.live import LiveOptions, run_live
    from gnomon.util import validate

    validate.number(args.recover, "--recover", minimum=1, maximum=255, integer=True)
    validate.number(args.max_frames, "--max-frames", minimum=2, maximum=10**9, integer=True)
    validate.number(args.frame_stride, "--frame-stride", minimum=1, maximum=10**6, integer=True)
    if args.fps is not None:
        validate.number(args.fps, "--fps", minimum=0.001, maximum=10000)
    out = args.out if args.out is not None else args.field_log.parent / "live"
    opts = LiveOptions(source=args.source, realtime=args.realtime, fps=args.fps, recover=args.recover,
                       stop_when_complete=True if args.until_complete else None, max_frames=args.max_frames,
                       view=not args.no_view and args.connect is None and display_available(),
                       connect=args.connect, rrd=not args.no_rrd, frame_stride=args.frame_stride,
                       progress=not args.quiet)
    result, stats = run_live(args.field_log, out, opts)
    cov = result.report["coverage"]
    summary = stats.summary()
    print(f"live: {summary['frames']} frames ({summary['dropped_frames']} dropped), {stats.points_logged} points "
          f"shown while the shadow moved; {stats.stopped}")
    print(f"{cov['points']} points ({100 * cov['fraction_of_image']:.1f} % of the image); "
          f"{cov['mesh_faces']} mesh faces -> {out}")
    for n in result.notes:
        print(f"note: {n}")
    for w in result.warnings:
        print(f"warning: {w}")
    return 0
