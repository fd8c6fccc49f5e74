"""`gnomon demo [--out DIR]`: synthetic scenes, end to end, with accuracy against ground truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="simulate synthetic captures, scan them, and report accuracy",
        description="Render the built-in synthetic desk scene (exact ground truth), scan it like a "
        "real capture, and print the depth error and coverage against the truth.",
    )
    p.add_argument("--out", type=Path, default=Path("gnomon_demo"), help="output folder (default: ./gnomon_demo)")
    p.add_argument("--small", action="store_true", help="a quick, smaller run (400x300, 120 frames)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run_desk_lamp(out: Path, *, small: bool, progress: bool) -> dict:
    from gnomon.accuracy import depth_accuracy
    from gnomon.pipeline import ScanOptions, run_scan
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    cfg = DeskLampConfig(width=400, height=300, frames=120) if small else DeskLampConfig()
    capture = out / "desk_lamp" / "capture"
    print(f"simulating desk_lamp ({cfg.width}x{cfg.height}, {cfg.frames} frames) -> {capture}")
    simulate_desk_lamp(capture, cfg)
    result = run_scan(capture / "field_log.toml", out / "desk_lamp" / "scan", ScanOptions(progress=progress))
    truth = np.load(capture / "ground_truth.npz")
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], float(truth["camera_distance_mm"]), "mm")
    print(acc.table("desk_lamp: depth against ground truth (swept pixels)"))
    return {"desk_lamp": acc.as_dict()}


def run(args: argparse.Namespace) -> int:
    from gnomon import atomic

    out: Path = args.out
    results = run_desk_lamp(out, small=args.small, progress=not args.quiet)
    atomic.write_text(out / "accuracy.json", json.dumps(results, indent=2))
    print(f"accuracy figures -> {out / 'accuracy.json'}")
    return 0
