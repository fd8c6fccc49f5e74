"""The building's own moving shadows against the pole's (issue 35, item 2): a script, not a test.

    PYTHONPATH=python python benchmarks/building_shadows.py [--out DIR] [--width 800 --height 600] [--seed 0]

The facade_sun scene has two balconies (boxes protruding 1.1 m) and a ledge; over the 3 h 19 min capture
their shadows turn with the sun and sweep the facade, the upper balcony's across the stretch the pole's
shadow climbs. The simulator (never the scanner) says per pixel whether a building shadow's edge crossed
it during the capture: lit past the building (at least half the sun's disc) in some frames and not in
others, every 2nd frame checked (``FacadeSunScene.building_visibility``). The capture is scanned twice:

* with its ``[pole]`` (the pole's geometry: a dip is kept only where and when the pole's shadow can fall,
  lasting as long as it lasts there; between two candidate dips, the pole's);
* without it (the shadow planes from the lines on the reference planes and the sun alone: any dip that
  fits them is taken).

Printed for each: depth RMS, coverage of the pole-swept surface, gross and false points over every output
point, and the points on pixels a building shadow crossed but the pole's never did (each one false).
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
from gnomon.simulate.facade_sun import FacadeSunScene  # noqa: E402
from gnomon.util import toml_io  # noqa: E402


def building_shadow_crossed(config: FacadeSunConfig, step: int = 2) -> np.ndarray:
    """(H, W) bool: a building shadow's edge crossed the pixel's point during the capture (the simulator's
    own visibility of the sun past the building, every ``step``-th frame)."""
    scene = FacadeSunScene(config)
    seen = np.zeros((scene.H, scene.W), dtype=bool)
    hidden = np.zeros((scene.H, scene.W), dtype=bool)
    for k in range(0, scene.N, step):
        v = scene.building_visibility(k)[scene.crop]
        seen |= v >= 0.5
        hidden |= v < 0.5
    return seen & hidden & np.isfinite(scene.depth)


def facade_arguments(description: str) -> argparse.ArgumentParser:
    """The options of a facade benchmark: ``--out`` (a folder to keep the capture and scans in), the image size,
    the scene's seed."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--width", type=int, default=800)
    ap.add_argument("--height", type=int, default=600)
    ap.add_argument("--seed", type=int, default=0)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = facade_arguments(__doc__.split("\n")[0]).parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="gnomon-building-shadows-"))
    config = FacadeSunConfig(width=args.width, height=args.height, seed=args.seed)
    capture = root / "capture"
    if not (capture / "field_log.toml").exists():
        simulate_facade_sun(capture, config)
    truth = dict(np.load(capture / "ground_truth.npz"))
    crossed = building_shadow_crossed(config)
    pole_swept = truth["swept_surface"]
    only_building = crossed & ~pole_swept
    print(f"pixels a building shadow's edge crossed: {int(crossed.sum())} ({100 * crossed.mean():.1f} % of the image); "
          f"of them the pole's shadow swept {int((crossed & pole_swept).sum())}, never {int(only_building.sum())}")
    log = toml_io.load(capture / "field_log.toml")
    no_pole = dict(log)
    no_pole.pop("pole")
    toml_io.dump(no_pole, capture / "field_log_no_pole.toml")
    distance = float(truth["camera_distance"])
    for name, path in (("with [pole]", capture / "field_log.toml"),
                       ("without [pole]", capture / "field_log_no_pole.toml")):
        out = root / f"scan_{'pole' if 'with ' in name else 'lines'}"
        shutil.rmtree(out, ignore_errors=True)
        result = run_scan(path, out, ScanOptions(progress=False, rrd=False))
        acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], distance, "m", sigma=result.sigma,
                             swept_surface=pole_swept)
        points = np.isfinite(result.depth)
        on_building_only = int((points & only_building).sum())
        print(acc.table(f"facade_sun {args.width}x{args.height}, {name}"))
        print(f"  points where only a building shadow passed: {on_building_only} "
              f"({100 * on_building_only / max(int(points.sum()), 1):.2f} % of the output points)")
        for w in result.warnings:
            if "pole" in w:
                print(f"  warning: {w}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
