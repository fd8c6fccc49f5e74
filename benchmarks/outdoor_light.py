"""Realistic outdoor light on the facade (issue 35, item 3): the scan with and without interreflection.

    PYTHONPATH=python python benchmarks/outdoor_light.py [--out DIR] [--width 800 --height 600] [--seed 0]

Renders the ``facade_sun`` capture twice with one seed: as shipped (sky plus a fixed ground-bounce share of the
sky, the same every frame) and with ``bounce=True`` (:mod:`gnomon.simulate.outdoor_bounce`: sun and sky light
bounced twice between the street, the facade, its balconies and ledge, computed per frame, so the pole's shadow on
the street dims what the facade receives). Scans both as shipped and prints for each the scoring of
``benchmarks/building_shadows.py`` (depth RMS % of the distance over the swept pixels, coverage of the pole-swept
surface, gross and false points over the output points), the scan's warnings, and for the bounce capture the
truth's figures: the bounced light's share of the swept pixels' radiance, the dip bounced light alone makes as the
pole's shadow passes (``bounce_dip``), and the output points on pixels only bounced light dims
(``bounce_only``: each one a false point).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from gnomon.runs.accuracy import depth_accuracy  # noqa: E402
from gnomon.runs.scan import ScanOptions, run_scan  # noqa: E402
from gnomon.simulate import FacadeSunConfig, simulate_facade_sun  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--width", type=int, default=800)
    ap.add_argument("--height", type=int, default=600)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="gnomon-outdoor-light-"))
    for bounce in (False, True):
        name = "bounce" if bounce else "shipped"
        capture = root / name
        config = FacadeSunConfig(width=args.width, height=args.height, frames=args.frames, seed=args.seed,
                                 bounce=bounce)
        if not (capture / "field_log.toml").exists():
            sim = simulate_facade_sun(capture, config)
            print(f"{name}: rendered in {sim.seconds:.1f} s")
        truth = dict(np.load(capture / "ground_truth.npz"))
        out = root / f"scan_{name}"
        shutil.rmtree(out, ignore_errors=True)
        result = run_scan(capture / "field_log.toml", out, ScanOptions(progress=False, rrd=False))
        acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], float(truth["camera_distance"]), "m",
                             sigma=result.sigma, swept_surface=truth["swept_surface"])
        print(acc.table(f"facade_sun {args.width}x{args.height} seed {args.seed}, {name}"))
        points = np.isfinite(result.depth)
        if bounce:
            sw = truth["swept"]
            share, dip = truth["bounce_share"], truth["bounce_dip"]
            print(f"  bounced light's share of the swept pixels' radiance: median {np.median(share[sw]):.3f} "
                  f"(p90 {np.percentile(share[sw], 90):.3f}); its dip as the pole's shadow passes, swept pixels: "
                  f"median {100 * np.median(dip[sw]):.3f} %, p99 {100 * np.percentile(dip[sw], 99):.3f} %, "
                  f"max {100 * dip[sw].max():.3f} %")
            only = truth["bounce_only"]
            print(f"  pixels only bounced light dims by >= 1 %: {int(only.sum())}; output points there: "
                  f"{int((points & only).sum())}")
        for w in result.warnings:
            print(f"  warning: {w}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
