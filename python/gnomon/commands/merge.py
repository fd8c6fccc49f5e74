"""`gnomon merge SCAN_A SCAN_B --out DIR`: dual-scan fusion."""

from __future__ import annotations

import argparse
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.recording.recorder import add_recording_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "merge",
        help=COMMANDS["merge"],
        description="Fuse two scan output folders taken with the same fixed camera, per pixel: "
        "inverse-variance (gaussian) weights, or Bouguet & Perona's sigmoid weights with --beta.",
    )
    p.add_argument("scan_a", type=Path, help="output folder of the first `gnomon scan`")
    p.add_argument("scan_b", type=Path, help="output folder of the second `gnomon scan`")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--weights", choices=("gaussian", "sigmoid"), default="gaussian")
    p.add_argument("--beta", type=float, default=10.0, help="sigmoid steepness (large: pick the better scan)")
    add_recording_arguments(p, what="OUT/merge.rrd", rrd_path=False, view=False, frame_stride=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gnomon.errors import GnomonError
    from gnomon.runs.merge import merge_scans
    from gnomon.runs.scan import ScanOptions
    from gnomon.util import validate

    beta = validate.number(args.beta, "--beta", positive=True)
    out = validate.check_output_folder(args.out)
    for name, scan in (("SCAN_A", args.scan_a), ("SCAN_B", args.scan_b)):
        folder = validate.input_folder(scan, f"{name} (a scan output folder)").resolve()
        if out == folder or folder in out.parents or out in folder.parents:
            raise GnomonError(f"--out {args.out}: would write into the input {scan}; choose another folder")

    _, report = merge_scans(args.scan_a, args.scan_b, args.out, method=args.weights, beta=beta,
                            options=ScanOptions(rrd=not args.no_rrd, progress=False))
    c = report["coverage"]
    print(f"{c['points']} points (A {c['scan_a_points']}, B {c['scan_b_points']}; only A {c['only_a']}, "
          f"only B {c['only_b']}, both {c['both']}, conflicts {c['conflicts']}) -> {args.out}")
    return 0
