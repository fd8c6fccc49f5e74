"""`gnomon batch FIELD_LOG... --out DIR`: many scans (and merges) as tasks on Dask."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.recording.recorder import add_recording_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "batch",
        help=COMMANDS["batch"],
        description="One task per scan, one per merge (run once both its scans are done), on a local "
        "cluster or an existing Dask scheduler. Scan NAME (the field log's folder, or the file's stem) "
        "is written to OUT/NAME, a merge of A and B to OUT/A+B. A scan whose outputs are complete and "
        "whose inputs are unchanged (digests in its report.json) is skipped. A failed scan is reported "
        "on one line and the others go on. Writes OUT/summary.csv, OUT/summary.json and OUT/batch.rrd. "
        "Paths must be the same on every worker (a shared file system on a cluster). "
        "Needs Dask: pip install \"gnomon[dask]\".",
    )
    p.add_argument("field_logs", type=Path, nargs="*", metavar="FIELD_LOG", help="field logs to scan")
    p.add_argument("--out", type=Path, required=True, help="output folder (one sub-folder per scan)")
    p.add_argument("--batch-file", type=Path, default=None, metavar="TOML",
                   help='[[scan]] field_log = "...", name = "..." and [[merge]] scans = ["A", "B"] tables '
                        "(paths relative to the file)")
    p.add_argument("--merge", action="append", default=[], metavar="A,B",
                   help="also merge scans A and B (names) into OUT/A+B; repeatable")
    p.add_argument("--weights", choices=("gaussian", "sigmoid"), default="gaussian", help="merge weights")
    p.add_argument("--beta", type=float, default=10.0, help="sigmoid merge steepness")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local cluster size (processes, one thread each; default: CPUs, at most 4)")
    p.add_argument("--retries", type=int, default=2, help="extra attempts of a task that crashed")
    p.add_argument("--force", action="store_true", help="rescan even when the outputs are up to date")
    add_recording_arguments(p, what="the recordings (scan.rrd, merge.rrd, batch.rrd)", rrd_path=False, view=False)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gnomon.errors import GnomonError
    from gnomon.runs.batch import plan_batch, run_batch, summary_markdown, write_summary

    if args.workers is not None and args.workers < 1:
        raise GnomonError(f"--workers {args.workers}: expected at least 1")
    if args.scheduler and args.workers is not None:
        raise GnomonError("--workers sizes the local cluster; with --scheduler the cluster has its own workers")
    plan = plan_batch(args.field_logs, args.out, merges=args.merge, batch_file=args.batch_file,
                      rrd=not args.no_rrd, frame_stride=max(1, args.frame_stride), force=args.force,
                      weights=args.weights, beta=args.beta)
    t0 = time.perf_counter()
    results = run_batch(plan, scheduler=args.scheduler, workers=args.workers, retries=max(0, args.retries),
                        progress=not args.quiet)
    wall = time.perf_counter() - t0
    write_summary(results, args.out, rrd=not args.no_rrd, wall_s=wall)
    print(summary_markdown(results), end="")
    counts = {s: sum(r.status == s for r in results) for s in ("ok", "skipped", "failed")}
    print(f"{counts['ok']} done, {counts['skipped']} up to date, {counts['failed']} failed in {wall:.1f} s "
          f"-> {args.out / 'summary.csv'}")
    for r in results:
        if r.status == "failed":
            print(f"gnomon: error: {r.error}", file=sys.stderr)
    return 2 if counts["failed"] else 0
