"""`gnomon demo [--out DIR]`: synthetic scenes, end to end, with accuracy against ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from gnomon.commands import COMMANDS


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help=COMMANDS["demo"],
        description="Render the built-in synthetic scenes (a desk lit by a lamp; a building facade "
        "swept by a pole's shadow under the sun) with exact ground truth, scan them like real "
        "captures, and print the depth error and coverage against the truth.",
    )
    p.add_argument("--out", type=Path, default=Path("gnomon_demo"), help="output folder (default: ./gnomon_demo)")
    p.add_argument("--small", action="store_true", help="a quick, smaller run (400x300, 120 frames)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def demo_scene(name: str, simulate, cfg, out: Path, *, progress: bool, what: str = "frames"):
    """Simulate one scene into OUT/NAME/capture, scan it into OUT/NAME/scan, compare with the truth.

    The figures (errors over swept pixels, coverage, false points and gross
    errors over all output points) are added to the scan's report.json as
    ``accuracy``.
    """
    from gnomon.runs.accuracy import depth_accuracy
    from gnomon.runs.scan import ScanOptions, run_scan
    from gnomon.util import atomic

    capture = out / name / "capture"
    print(f"simulating {name} ({cfg.width}x{cfg.height}, {cfg.frames} {what}) -> {capture}")
    simulate(capture, cfg)
    result = run_scan(capture / "field_log.toml", out / name / "scan", ScanOptions(progress=progress))
    truth = np.load(capture / "ground_truth.npz")
    units = result.report["units"]
    distance = float(truth["camera_distance_mm"] if units == "mm" else truth["camera_distance"])
    surface = truth["swept_surface"] if "swept_surface" in truth.files else None
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], distance, units, sigma=result.sigma,
                         swept_surface=surface)
    print(acc.table(f"{name}: depth against ground truth (swept pixels; false points over all)"))
    result.report["accuracy"] = acc.as_dict()
    report_path = out / name / "scan" / "report.json"
    report = json.loads(report_path.read_text())
    report["accuracy"] = acc.as_dict()
    atomic.write_text(report_path, json.dumps(report, indent=2))
    return result, truth, acc


def run_desk_lamp(out: Path, *, small: bool, progress: bool) -> dict:
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    cfg = DeskLampConfig(width=400, height=300, frames=120) if small else DeskLampConfig()
    _, _, acc = demo_scene("desk_lamp", simulate_desk_lamp, cfg, out, progress=progress)
    return {"desk_lamp": acc.as_dict()}


def run_facade_sun(out: Path, *, small: bool, progress: bool) -> dict:
    from gnomon.simulate import FacadeSunConfig, simulate_facade_sun

    cfg = FacadeSunConfig(width=400, height=300, frames=100) if small else FacadeSunConfig()
    result, truth, acc = demo_scene("facade_sun", simulate_facade_sun, cfg, out, progress=progress,
                                    what="frames of a sun time-lapse")
    sun = result.report["sun"]
    print(f"  heading             {sun['heading_deg']:.3f}° ({sun['heading_source']}); "
          f"gnomon {sun['gnomon_heading_deg']:.3f}°, truth {float(truth['heading_deg']):.3f}°")
    for n in result.notes:
        print(f"  note: {n}")
    for w in result.warnings:
        print(f"  warning: {w}")
    return {"facade_sun": {**acc.as_dict(), "heading": sun}}


def run(args: argparse.Namespace) -> int:
    from gnomon.util import atomic
    from gnomon.util.validate import check_output_folder

    out: Path = check_output_folder(args.out)
    results = run_desk_lamp(out, small=args.small, progress=not args.quiet)
    results.update(run_facade_sun(out, small=args.small, progress=not args.quiet))
    atomic.write_text(out / "accuracy.json", json.dumps(results, indent=2))
    print(f"accuracy figures -> {out / 'accuracy.json'}")
    return 0
