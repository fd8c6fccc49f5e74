"""`gnomon bench`: throughput of the streaming kernel against the numpy
reference implementation of the same algorithm, and its peak memory for two
sequence lengths (it must not grow with the number of frames).

See :mod:`gnomon.runs.bench` for how the figures are taken.
"""

from __future__ import annotations

import argparse
import json

from gnomon.commands import COMMANDS
from gnomon.commands.scan import mesh_formats_option
from gnomon.errors import GnomonError
from gnomon.runs.bench import format_table, run_bench
from gnomon.util.atomic import write_text


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "bench",
        help=COMMANDS["bench"],
        description="Synthesise grey frames of a sweeping shadow, time the Rust tracker and the numpy "
        "tracker on them, and measure the kernel's peak memory (RSS of a fresh process) for 100 and "
        "for --frames frames. With --scan FIELD_LOG: time decoding that capture's frames alone, one "
        "tracking pass alone (decoding and the kernel tracker, nothing after), then its whole scan (with each "
        "stage's share and the ratio to that floor) and the same scan without its recording, in one run.",
    )
    p.add_argument("--frames", type=int, default=1000, metavar="N", help="frames for the kernel (default 1000)")
    p.add_argument("--numpy-frames", type=int, default=30, metavar="M",
                   help="frames for the numpy tracker (default 30)")
    p.add_argument("--width", type=int, default=1920, help="frame width, pixels (default 1920)")
    p.add_argument("--height", type=int, default=1080, help="frame height, pixels (default 1080)")
    p.add_argument("--window", type=int, default=4, help="tracker window half-width m (default 4)")
    p.add_argument("--max-width", type=int, default=32, help="tracker dip width W, frames (default 32)")
    p.add_argument("--scan", metavar="FIELD_LOG",
                   help="instead: time decoding this capture's frames alone, decoding and tracking alone, then its "
                   "whole scan and the same scan without its recording")
    p.add_argument("--scan-out", metavar="DIR", help="output folder of the --scan run (default: a temporary one)")
    p.add_argument("--mesh-formats", type=mesh_formats_option, default=None, metavar="LIST",
                   help="with --scan: the mesh's files, as gnomon scan --mesh-formats ('all': every format)")
    p.add_argument("--no-memory", action="store_true", help="skip the peak-memory subprocesses")
    p.add_argument("--json", metavar="PATH", help="also write the figures as JSON to PATH")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.scan:
        return _run_scan(args)
    for name in ("frames", "numpy_frames", "width", "height", "window", "max_width"):
        if getattr(args, name) < 1:
            raise GnomonError(f"--{name.replace('_', '-')} must be ≥ 1, got {getattr(args, name)}")
    from gnomon.util.validate import MAX_WINDOW

    if args.window > MAX_WINDOW:
        raise GnomonError(f"--window must be ≤ {MAX_WINDOW}, got {args.window}")
    if args.json:
        from gnomon.util.validate import check_output_file

        check_output_file(args.json, "--json")
    memory_frames = () if args.no_memory else tuple(sorted({100, args.frames}))
    try:
        result = run_bench(
            frames=args.frames,
            numpy_frames=args.numpy_frames,
            width=args.width,
            height=args.height,
            window=args.window,
            max_width=args.max_width,
            memory_frames=memory_frames,
        )
    except ValueError as exc:  # the kernel's parameter checks
        raise GnomonError(str(exc)) from None
    print(format_table(result))
    if args.json:
        write_text(args.json, json.dumps(result.to_dict(), indent=2) + "\n")
    return 0


def _run_scan(args: argparse.Namespace) -> int:
    import tempfile

    from gnomon.runs.bench import format_scan_table, run_scan_bench

    with tempfile.TemporaryDirectory(prefix="gnomon-bench-") as tmp:
        result = run_scan_bench(args.scan, args.scan_out or f"{tmp}/scan", args.mesh_formats, f"{tmp}/no-rrd")
    print(format_scan_table(result))
    if args.json:
        write_text(args.json, json.dumps(result.to_dict(), indent=2) + "\n")
    return 0
