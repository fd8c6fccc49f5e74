"""Scan a second public set of real captures end to end, as a user has them (a script, not a test).

    PYTHONPATH=python python benchmarks/slow_sweep_captures.py MIRROR_DIR [--out DIR] [--only cup,slipper]

MIRROR_DIR is a checkout of the GitHub repository
xinyu-evolutruster/cmu_15663_assignment6 (never committed here, never
downloaded by tests): ``data/cup_holder2_2`` (299 frames) and
``data/slipper3_3`` (400 frames) are 1920×1080 JPEG frames of a phone video,
a desk and a wall in a box, each carrying four home-made 2×2 checker
markers, a wide stick swept slowly (the shadow stays 33–53 frames on a
pixel); the only camera calibration is 8 chessboard photos at 1500×1000
(``data/self_calib_lr``, 6×8 inner corners), a 3:2 image against the
video's 16:9. The author's scripts use the course board's marker rectangle
(558.8 × 303.2125 mm) for both planes; that is what a user would type, and
the markers' fit (printed by ``gnomon preview``) shows how well it holds.

For each capture the script calibrates the camera from the photos, writes a
field log with ``[camera] crop = "centre"`` (the video taken as the photos'
centred crop, as ``gnomon init --camera`` writes it), the markers (hints for
the six that are 2×2 checkers in the image; clicked pixels for the two desk
markers whose squares overlap into a Z at the desk's grazing angle, which
the checker detector rightly refuses), runs ``gnomon regions``, ``gnomon
preview``, ``gnomon scan`` and scores the planes (``benchmarks/score.py``:
planarity against the markers' planes and coverage of the proposed bare,
swept regions). There is no object outline, so no object coverage or false
points.
"""

from __future__ import annotations

import argparse
import glob
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gnomon.camera.calibration import fit_camera_to_frames, load_camera_file, write_camera_file
from gnomon.camera.models import Pose
from gnomon.util import toml_io
from real_captures import FROG_RECT, plane_table, regions_preview_scan, run
from score import score_scan

SEQUENCES = {"cup": "cup_holder2_2", "slipper": "slipper3_3"}
# First-frame pixels of the markers (bottom-left, bottom-right, top-right, top-left of each plane's
# rectangle), read by eye; the desk's two left ones are clicked centres (their squares overlap into a Z).
HINTS = {"desk": [(147, 1020), (1593, 1013), (1447, 820), (453, 847)],
         "wall": [(523, 637), (1403, 607), (1387, 123), (500, 177)]}
CLICKED = {"cup": {0: (147.0, 1019.0), 3: (453.0, 845.0)}, "slipper": {0: (144.0, 1017.0), 3: (451.0, 847.0)}}


def field_log(name: str, folder: Path, camera: Path) -> Path:
    planes = [plane_table(p, FROG_RECT, HINTS[p], exact=False) for p in ("desk", "wall")]
    for k, pixel in CLICKED[name].items():
        marker = planes[0]["markers"][k]
        marker.pop("pixel_hint")
        marker["pixel"] = list(pixel)
    log = {"capture": {"frames": "frames/*.jpg", "gamma": "srgb"},
           "camera": {"file": camera.name, "crop": "centre"}, "planes": planes, "light": {"kind": "two-plane"}}
    path = folder / "field_log.toml"
    toml_io.dump(log, path)
    return path


def scan_sequence(mirror: Path, out: Path, name: str, camera: Path) -> None:
    folder = out / name
    folder.mkdir(parents=True, exist_ok=True)
    frames = folder / "frames"
    if not frames.exists():
        frames.symlink_to((mirror / "data" / SEQUENCES[name]).resolve(), target_is_directory=True)
    (folder / camera.name).write_bytes(camera.read_bytes())
    scan = regions_preview_scan(field_log(name, folder, folder / camera.name))
    # the scorer's camera: the photos' camera as the frames' centred crop (what the scan used)
    first = sorted(glob.glob(str(frames / "*.jpg")))[0]
    h, w = cv2.imread(first, cv2.IMREAD_GRAYSCALE).shape
    video, _ = fit_camera_to_frames(load_camera_file(camera), w, h, "photos' camera", crop="centre")
    write_camera_file(folder / "video_camera.toml", video)
    masks = {p: cv2.imread(str(folder / "regions" / f"{p}_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
             for p in ("desk", "wall")}
    score = score_scan(name, scan, folder / "video_camera.toml", None, region_masks=masks)
    rep = json.loads((scan / "report.json").read_text())
    settings, coverage = rep["settings"], rep["coverage"]
    print(f"{name}: dip width {settings['max_dip_frames']} frames ({settings['max_dip_frames_from']}); "
          f"{coverage['points']} points ({100 * coverage['fraction_of_image']:.1f} % of the image), "
          f"{coverage['ambiguous']} ambiguous pixels")
    print(score.summary())
    far_points(scan, folder / "video_camera.toml", masks)


def far_points(scan: Path, camera: Path, masks: dict[str, np.ndarray], far_mm: float = 10.0) -> None:
    """Per plane, its region's points more than ``far_mm`` off the markers' plane: their share, where they
    were timed, their predicted σ against the others', and how many of their σ they lie off."""
    rep = json.loads((scan / "report.json").read_text())
    depth, sigma = np.load(scan / "depth.npy"), np.load(scan / "sigma.npy")
    shadow_time = np.load(scan / "shadow_time.npy")
    rays = load_camera_file(camera).ray_map().astype(np.float64)
    pts = rays * (depth / rays[..., 2])[..., None]
    for plane in rep["reference_planes"]:
        name = plane.get("name", plane.get("plane"))
        R = Pose.from_rvec_tvec(np.array(plane["rvec"]), np.array(plane["tvec"])).R
        d = np.abs((pts - np.array(plane["tvec"])) @ R[:, 2])
        sel = masks[name] & np.isfinite(d)
        far = sel & (d > far_mm)
        if not far.any():
            continue
        print(f"  {name}: {100 * far.sum() / sel.sum():.1f} % of its points over {far_mm:g} mm off, timed at "
              f"frames {' / '.join(f'{t:.0f}' for t in np.percentile(shadow_time[far], [5, 50, 95]))} (p5/50/95); "
              f"their sigma median {np.median(sigma[far]):.1f} mm (the others' {np.median(sigma[sel & ~far]):.2f}), "
              f"off by {np.median(d[far] / sigma[far]):.2f} of it (median)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mirror", type=Path, help="checkout of xinyu-evolutruster/cmu_15663_assignment6")
    ap.add_argument("--out", type=Path, default=Path("slow_sweep_captures"))
    ap.add_argument("--only", default=",".join(SEQUENCES))
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    camera = args.out / "photos_camera.toml"
    run(["calibrate", "camera", *sorted(glob.glob(str(args.mirror / "data" / "self_calib_lr" / "*.jpg"))),
         "--board", "6x8", "--square", "25", "--out", str(camera), "--no-rrd"])
    for name in args.only.split(","):
        scan_sequence(args.mirror, args.out, name, camera)
    print(f"done in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
