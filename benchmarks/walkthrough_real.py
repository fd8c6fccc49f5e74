"""The README's walk-through on a public real capture, as a newcomer runs it: no field log typed, no file
edited (a script, not a test).

    PYTHONPATH=python python benchmarks/walkthrough_real.py MIRROR_DIR [--out DIR]

MIRROR_DIR is a checkout of BrandonHung343/15-463-HW-6 (never committed here, never downloaded by tests):
``data/frog/v2`` (200 frames 1024x768 of the CMU course's frog set-up, a second sweep the other benchmarks
do not use: benchmarks/real_captures.py scans ``data/frog``'s first, 166 frames) and ``data/calib`` (its
10 photos of a chessboard of 8x6 inner corners). The commands, each timed:

    gnomon calibrate camera calib --board 8x6 --square 25 --out camera.toml   # the square: any (scale-free)
    gnomon init frames --camera camera.toml       # the marks found in the first frame, units "relative"
    gnomon regions field_log.toml                 # the object cut out, the masks switched on in the log
    gnomon scan field_log.toml --out scan

Scored like benchmarks/real_captures.py's frog (its outlines of the boxes' faces: the camera did not move
between the two sweeps, the marks are within 4 px of the first's; the frog, turned, and its shadows
outlined anew below), inside each plane's four marks, in mm:
the relative unit (the desk's distance from the camera) is turned into mm with the course's measured
rectangle of the desk marks (558.8 mm long; used for the report only, the scan never sees it). Printed:
each plane's planarity (median / RMS distance to its marks' plane, mm and per mille of the desk's
distance) and coverage of its bare swept pixels, the object's coverage, the false points, the desk-wall
angle, and each fitted rectangle's proportions against the measured ones (the marks' evidence).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from real_captures import FROG_OTHER_FACES, FROG_RECT  # noqa: E402
from score import score_scan  # noqa: E402

# The second sweep's frog lies otherwise than the first's: its outline and its cast shadows, hand-drawn on the
# first frame of data/frog/v2 (pixels), for scoring only (grown by score_scan's keep-out margin).
V2_FROG = [(283, 440), (300, 405), (360, 370), (410, 355), (445, 365), (470, 405), (560, 380), (600, 345),
           (640, 328), (700, 342), (748, 345), (760, 385), (756, 435), (740, 475), (732, 530), (722, 582),
           (680, 602), (640, 600), (600, 612), (575, 602), (480, 597), (420, 572), (385, 545), (350, 556),
           (330, 532), (300, 500), (290, 470)]
V2_SHADOWS = [[(190, 498), (270, 505), (330, 518), (400, 540), (470, 598), (420, 606), (300, 602), (230, 602),
               (188, 590)],
              [(560, 600), (640, 594), (702, 600), (706, 662), (650, 672), (580, 652), (558, 630)]]


def gnomon(args: list[str], cwd: Path) -> float:
    """Run ``gnomon ARGS`` in ``cwd`` as a user does (a process); its wall time in seconds."""
    print("$ gnomon " + " ".join(args), flush=True)
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "gnomon", *args], cwd=cwd, env=_env(), text=True,
                          capture_output=True)
    elapsed = time.perf_counter() - t
    tail = [line for line in (done.stdout + done.stderr).splitlines() if not line.startswith(("tracking:", "scan:"))]
    print("\n".join("  " + line for line in tail[-12:]), flush=True)
    if done.returncode != 0:
        raise SystemExit(f"gnomon {args[0]} failed with code {done.returncode}")
    return elapsed


def _env() -> dict:
    import os

    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "python") + os.pathsep + env.get("PYTHONPATH", "")
    return env


def in_mm(scan: Path, scale: float, into: Path) -> Path:
    """A copy of the scan's depth, σ and planes with lengths × ``scale`` (relative units to mm)."""
    into.mkdir(parents=True, exist_ok=True)
    for name in ("depth.npy", "sigma.npy"):
        np.save(into / name, np.load(scan / name) * scale)
    for name in ("shadow_time.npy", "coverage.npy"):
        shutil.copy(scan / name, into / name)
    report = json.loads((scan / "report.json").read_text())
    for p in report["reference_planes"]:
        p["tvec"] = [scale * x for x in p["tvec"]]
    (into / "report.json").write_text(json.dumps(report))
    return into


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mirror", type=Path)
    ap.add_argument("--out", type=Path, default=Path("walkthrough_real"))
    args = ap.parse_args(argv)
    work = args.out / "frog_v2"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    shutil.copytree(args.mirror / "data" / "frog" / "v2", work / "frames")
    shutil.copytree(args.mirror / "data" / "calib", work / "calib", ignore=shutil.ignore_patterns("*.npz"))
    times = {
        "calibrate camera": gnomon(["calibrate", "camera", "calib", "--board", "8x6", "--square", "25", "--out",
                                    "camera.toml", "--quiet"], work),
        "init": gnomon(["init", "frames", "--camera", "camera.toml"], work),
        "regions": gnomon(["regions", "field_log.toml", "--quiet"], work),
        "scan": gnomon(["scan", "field_log.toml", "--out", "scan", "--quiet"], work),
    }
    print("commands' wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
          + f"; {sum(times.values()):.1f} s in all")
    report = json.loads((work / "scan" / "report.json").read_text())
    planes = {p["plane"]: p for p in report["reference_planes"]}
    measured = FROG_RECT[1] / FROG_RECT[0]
    for name, p in planes.items():
        a, b = sorted(p["rectangle"], reverse=True)
        print(f"{name}: its marks' rectangle {a:.4f} x {b:.4f} (relative units): proportions {b / a:.4f}, "
              f"measured {measured:.4f} ({100 * (b / a / measured - 1):+.2f} %); normal ± {p['std_normal_deg']:.2f}°")
    scale = FROG_RECT[0] / max(planes["desk"]["rectangle"])
    print(f"mm per relative unit (the desk marks' measured 558.8 mm): {scale:.1f}; the wall's marks' long side "
          f"then {scale * max(planes['wall']['rectangle']):.1f} mm (measured 558.8)")
    print(f"desk-wall angle {planes['wall']['angle_to_first_deg']:.2f}°")
    # the bare planes scored: inside each plane's four marks, as the image shows them (independent of the
    # regions the scan used), less the object, its shadows, the marks and the boxes' faces (score_scan)
    shape = np.load(work / "scan" / "depth.npy").shape
    masks = {}
    for name, p in planes.items():
        hull = cv2.convexHull(np.round(np.array(p["pixels"])).astype(np.int32))
        masks[name] = cv2.fillConvexPoly(np.zeros(shape, np.uint8), hull, 1).astype(bool)
    with tempfile.TemporaryDirectory() as tmp:
        scored = score_scan("frog v2 (walk-through)", in_mm(work / "scan", scale, Path(tmp)), work / "camera.toml",
                            None, V2_FROG, V2_SHADOWS, other_faces=FROG_OTHER_FACES, region_masks=masks)
    print("\n".join(scored.lines()))
    for p in scored.planes:
        print(f"  {p.name} planarity per mille of the desk's distance ({scale:.0f} mm): median "
              f"{1000 * p.median_abs / scale:.2f}, RMS {1000 * p.rms / scale:.2f}; RMS / (1.4826 median) "
              f"{p.rms / (1.4826 * p.median_abs):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
