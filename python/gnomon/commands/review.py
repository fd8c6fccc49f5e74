"""`gnomon review REC.rrd`: summarise a recording, export its cloud, compare two.

    gnomon review scan.rrd                       summary: entities, timelines, points, metrics, warnings
    gnomon review scan.rrd --export points.ply   the final cloud, read back from the recording
    gnomon review a.rrd --compare b.rrd          nearest-neighbour distances from a's cloud to b's
    gnomon review scan.rrd --json                the same as JSON on stdout
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.recording.recorder import ENTITY


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "review",
        help=COMMANDS["review"],
        description=(
            "Summarise a Gnomon rerun recording (.rrd): entities, timeline ranges, point count, "
            "metrics and warnings. Optionally export its final point cloud as PLY, or compare its "
            "cloud with another recording's."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("recording", type=Path, metavar="REC.rrd", help="the recording to review")
    p.add_argument(
        "--export", type=Path, metavar="POINTS.ply",
        help="write the recording's final point cloud (x y z, colour, sigma, u v) as binary PLY",
    )
    p.add_argument(
        "--compare", type=Path, metavar="OTHER.rrd",
        help="report distances from this recording's cloud to OTHER's (nearest neighbour per point)",
    )
    p.add_argument(
        "--entity", default=ENTITY["points"], metavar="PATH",
        help=f"entity holding the cloud for --export/--compare (default: {ENTITY['points']})",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gnomon.recording import review
    from gnomon.util import validate
    validate.input_file(args.recording, "recording")
    if args.compare is not None:
        validate.input_file(args.compare, "recording")
    if args.export is not None:
        validate.check_output_file(args.export, "--export")
    summary = review.summarize(args.recording)
    result: dict = {"summary": summary.to_dict()}
    messages = []
    if args.export is not None:
        n = review.export_points(args.recording, args.export, entity=args.entity)
        result["export"] = {"path": str(args.export), "points": n}
        messages.append(f"exported {n} points to {args.export}")
    if args.compare is not None:
        result["compare"] = review.compare(args.recording, args.compare, entity=args.entity)
        messages.append(review.format_compare(result["compare"]))
    if args.json:
        print(review.to_json(result))
    else:
        print(summary.format())
        for m in messages:
            print(m)
    sys.stdout.flush()
    return 0
