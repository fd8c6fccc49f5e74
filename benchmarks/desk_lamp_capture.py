"""Scan a public real capture of the paper's own set-up end to end: desk, lamp, pencil (a script, not a test).

    PYTHONPATH=python python benchmarks/desk_lamp_capture.py MIRROR_DIR [--out DIR]

MIRROR_DIR is a checkout of the GitHub repository
Leeiieeo/3D-photography-on-your-desk (never committed here, never downloaded
by tests): ``bowl/`` 100 frames (1920×1080 JPEG, a phone looking down at a
bowl upside down on a white desk, a stick's shadow swept across it, a phone's
torch as the lamp), ``calib/`` 20 chessboard photos (9×6 inner corners, 28 mm
squares; ``calib_1.jpg`` taken from the scan's place, the board lying on the
desk), ``light/`` 12 photos of a 132.8 mm pencil standing on the desk, whose
bases and shadow tips its author clicked (read here from its ``src/light.py``,
not copied into this repository).

The script runs what a user runs: ``gnomon calibrate camera`` on the board
photos; a field log whose desk is measured from the board in ``calib_1.jpg``
(no pose typed) and whose regions are two bands above and below the bowl
(read off the first frame, as the paper's two reference rows); ``gnomon
calibrate lamp`` on the pencils; the lamp's ``[light]`` into the field log;
``gnomon regions`` grown from the bands (its mask replaces them: the whole
bare desk the shadow crosses; started from the board's outline instead, it
takes the bowl's flat top for the desk in the frames the shadow crosses it);
``gnomon preview`` and ``gnomon scan``. Before the clicked lamp, the lamp
once more with the shadows' tips found by Gnomon (each clicked base as the
hint, no tip, the photos' median as the empty desk): each tip's distance to
the author's click, and that lamp. It scores the scan against the desk
measured from the board: planarity of the swept bare desk (outside the bowl
and its cast shadow, circles read off the first frame; swept: a shadow time
at 80 % of the 15×15 pixels around, not the desk's sparse noise dips outside
the sweep), coverage, and false points (outside those circles, more than
5 mm off the desk), and prints the bowl's heights above the desk.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gnomon.camera.calibration import load_camera_file
from gnomon.camera.models import Pose
from gnomon.cli import main as gnomon
from gnomon.util import toml_io
from real_captures import regions_preview_scan, run

# Read off bowl_00.jpg (pixels): the bowl's rim and its cast shadow (circles), and two bare bands of desk
# above and below them that the shadow crosses in every frame of the sweep.
BOWL = ((862.0, 578.0), 262.0)
CAST = ((850.0, 440.0), 250.0)
BANDS = [[0, 100, 1920, 240], [0, 900, 1920, 1080]]
PENCIL_MM, BOARD, SQUARE_MM = 132.8, "9x6", 28.0


def clicked(mirror: Path) -> tuple[list, list]:
    """The author's clicked pencil tips' shadows and bases (pixels), from its src/light.py."""
    text = (mirror / "src" / "light.py").read_text()
    out = []
    for name in ("tip", "base"):
        body = re.search(name + r"\s*=\s*np\.array\(\[(.*?)\]\s*,\s*dtype", text, re.S)
        if body is None:
            raise SystemExit(f"{mirror / 'src' / 'light.py'}: no '{name} = np.array([...])'")
        out.append([[float(u), float(v)] for u, v in re.findall(r"\[\s*(\d+)\s*,\s*(\d+)\s*\]", body.group(1))])
    return out[0], out[1]


def circle(shape: tuple[int, int], c: tuple[tuple[float, float], float]) -> np.ndarray:
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    (u, v), r = c
    return (xx - u) ** 2 + (yy - v) ** 2 < r**2


def score(folder: Path) -> None:
    scan = folder / "scan"
    rep = json.loads((scan / "report.json").read_text())
    depth, sigma = np.load(scan / "depth.npy"), np.load(scan / "sigma.npy")
    shadow_time = np.load(scan / "shadow_time.npy")
    cam = load_camera_file(folder / "camera.toml")
    rays = cam.ray_map().astype(np.float64)
    points = rays * (depth / rays[..., 2])[..., None]
    desk = rep["reference_planes"][0]
    R = Pose.from_rvec_tvec(np.array(desk["rvec"]), np.array(desk["tvec"])).R
    d = (points - np.array(desk["tvec"])) @ R[:, 2]  # height above the board's plane (mm; its z is up, out of the desk)
    has = np.isfinite(depth)
    obj = circle(depth.shape, BOWL) | circle(depth.shape, CAST)
    # swept: a shadow time, with one at 80 % of the pixels around (not the sparse noise dips of the desk
    # the shadow never crossed, right and left of the sweep)
    timed = np.isfinite(shadow_time).astype(np.float32)
    swept = (timed > 0) & (cv2.blur(timed, (15, 15)) >= 0.8)
    bare = swept & ~obj
    on = bare & has
    a = np.abs(d[on])
    print(f"desk: planarity median {np.median(a):.3f} mm, RMS {np.sqrt(np.mean(a ** 2)):.3f} mm, p99 "
          f"{np.percentile(a, 99):.2f} mm; coverage {100 * on.sum() / bare.sum():.1f} % of {bare.sum()} swept bare "
          f"pixels; robust z {1.4826 * np.median(a / sigma[on]):.2f}")
    false = has & ~obj & (np.abs(d) > 5.0)
    print(f"false points (outside the bowl and its shadow, > 5 mm off the desk) {100 * false.sum() / has.sum():.2f} % "
          f"of {has.sum()}")
    bowl = circle(depth.shape, BOWL) & has
    print(f"bowl: points on {100 * bowl.sum() / circle(depth.shape, BOWL).sum():.1f} % of its disc; height above "
          f"the desk p5 / p50 / p95 {' / '.join(f'{h:.1f}' for h in np.percentile(d[bowl], [5, 50, 95]))} mm")


def auto_tips(mirror: Path, folder: Path, log: dict, tips: list, bases: list) -> None:
    """The lamp with the shadows' tips found by Gnomon instead of clicked: each clicked base (the hint)
    in its photo (the one darkest there against the photos' median), no tip, no empty-desk photo (the
    photos' median stands for it). Prints each found tip's distance to the author's click and the lamp."""
    files = sorted((mirror / "light").glob("*.jpg"))
    greys = np.stack([cv2.imread(str(f), cv2.IMREAD_GRAYSCALE).astype(np.float32) for f in files])
    ratio = (greys + 1.0) / (np.median(greys, axis=0) + 1.0)
    photos = []
    for b in bases:
        u, v = int(round(b[0])), int(round(b[1]))
        k = int(np.argmin(ratio[:, v - 3:v + 4, u - 3:u + 4].mean(axis=(1, 2))))
        photos.append({"image": str(files[k].resolve()), "base": b})
    if len({p["image"] for p in photos}) != len(photos):
        raise SystemExit("two clicked bases fall in one photo: cannot tell which photo each click is from")
    auto = dict(log, pencil=dict(log["pencil"], photos=photos))
    path = folder / "field_log_auto_tips.toml"
    toml_io.dump(auto, path)
    print(f"$ gnomon calibrate lamp {path}", flush=True)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = gnomon(["calibrate", "lamp", str(path)])
    text = out.getvalue()
    print(text, end="", flush=True)
    if code != 0:
        raise SystemExit(f"gnomon calibrate lamp (automatic tips) failed with code {code}")
    found = [line for line in text.splitlines() if "found against" in line]
    off = np.array([np.hypot(*(np.array([float(x) for x in re.findall(r"-?\d+\.\d+", line)][2:4]) - t))
                    for line, t in zip(found, tips, strict=True)])
    lamp = toml_io.load(folder / "lamp.toml")
    height = re.search(r"([\d.]+) mm above the plane", text)
    print(f"automatic tips: {len(off)} found, {np.median(off):.2f} px from the author's clicks (median, max "
          f"{off.max():.1f}); the lamp {height.group(1) if height else '?'} mm above the desk "
          f"(chi2 {lamp['lamp_calibration']['chi2']:.3g} for {lamp['lamp_calibration']['dof']} dof)", flush=True)


def clicked_photos(mirror: Path, bases: list) -> dict[str, list]:
    """Each clicked base's photo (the one darkest there against the photos' median: the author's script
    does not say which click is which photo), by file name."""
    files = sorted((mirror / "light").glob("*.jpg"))
    greys = np.stack([cv2.imread(str(f), cv2.IMREAD_GRAYSCALE).astype(np.float32) for f in files])
    ratio = (greys + 1.0) / (np.median(greys, axis=0) + 1.0)
    out = {}
    for b in bases:
        u, v = int(round(b[0])), int(round(b[1]))
        out[files[int(np.argmin(ratio[:, v - 3:v + 4, u - 3:u + 4].mean(axis=(1, 2))))].name] = b
    if len(out) != len(bases):
        raise SystemExit("two clicked bases fall in one photo: cannot tell which photo each click is from")
    return out


def walkthrough(mirror: Path, out: Path, clicked_bases: bool = False) -> None:
    """The README's lamp walk-through, as a user runs it: `gnomon calibrate camera` on the board photos,
    `gnomon init --light lamp` (the board photo from the scan's place, the pencil photos), then the only
    edit: the pencil's length (with ``clicked_bases``, also each photo's base: the author's clicks);
    `gnomon calibrate lamp` (the pencils' feet and the shadows' tips found; the feet found printed against
    the author's clicks), `gnomon regions` (from the two bands it starts from when none are given),
    `gnomon scan`; scored as the scripted run is."""
    folder = out / "walkthrough"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("bowl", "calib", "light"):
        link = folder / name
        if not link.exists():
            link.symlink_to((mirror / name).resolve(), target_is_directory=True)
    t0 = time.perf_counter()
    run(["calibrate", "camera", str(folder / "calib"), "--board", BOARD, "--square", str(SQUARE_MM), "--out",
         str(folder / "camera.toml"), "--quiet"])
    path = folder / "field_log.toml"
    run(["init", str(folder / "bowl"), "--camera", str(folder / "camera.toml"), "--light", "lamp", "--board", BOARD,
         "--square", str(SQUARE_MM), "--board-image", str(folder / "calib" / "calib_1.jpg"), "--pencil",
         str(folder / "light" / "*.jpg"), "--out", str(path), "--force"])
    _, bases = clicked(mirror)
    base_of = clicked_photos(mirror, bases)
    text = path.read_text()
    edited = text.replace("height = nan  # the pencil's length in mm: measure it", f"height = {PENCIL_MM}")

    def fill(m: re.Match) -> str:
        b = base_of[Path(m.group(1)).name]
        return f'image = "{m.group(1)}"\nbase = [{b[0]:.0f}, {b[1]:.0f}]'

    if clicked_bases:
        edited = re.sub(r'image = "(light/[^"]+)"\n# base = \[u, v\]  # the pencil\'s foot: found if left out',
                        fill, edited)
    lines = sum(a != b for a, b in zip(text.splitlines(), edited.splitlines(), strict=True))
    path.write_text(edited)
    print(f"the field log's lines edited by hand: {lines} (the pencil's length"
          + (f" and {len(base_of)} bases)" if clicked_bases else ")"))
    out_lamp = io.StringIO()
    with contextlib.redirect_stdout(out_lamp):
        run(["calibrate", "lamp", str(path)])
    print(out_lamp.getvalue(), end="")
    if not clicked_bases:  # each foot found against the author's click for the same photo
        found = dict(re.findall(r"\((light/\S+\.jpg)\): base \[([-\d.]+, [-\d.]+)\]", out_lamp.getvalue()))
        misses = [float(np.hypot(*(np.array([float(x) for x in found[k].split(",")]) - base_of[Path(k).name])))
                  for k in sorted(found)]
        print(f"feet found: {len(misses)} of {len(base_of)}, against the author's clicks: median "
              f"{np.median(misses):.1f} px, max {max(misses):.1f} px")
    run(["regions", str(path), "--quiet"])
    run(["scan", str(path), "--out", str(folder / "scan"), "--no-rrd", "--quiet"])
    print(f"commands: {time.perf_counter() - t0:.0f} s")
    score(folder)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mirror", type=Path, help="checkout of Leeiieeo/3D-photography-on-your-desk")
    ap.add_argument("--out", type=Path, default=Path("desk_lamp_capture"))
    ap.add_argument("--walkthrough", action="store_true", help="the README's walk-through instead (see walkthrough)")
    ap.add_argument("--clicked-bases", action="store_true",
                    help="with --walkthrough: type the author's clicked pencil feet instead of having them found")
    args = ap.parse_args(argv)
    if args.walkthrough:
        walkthrough(args.mirror, args.out, args.clicked_bases)
        return 0
    t0 = time.perf_counter()
    folder = args.out
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("bowl", "calib"):
        link = folder / name
        if not link.exists():
            link.symlink_to((args.mirror / name).resolve(), target_is_directory=True)
    run(["calibrate", "camera", *sorted(map(str, (args.mirror / "calib").glob("*.jpg"))), "--board", BOARD,
         "--square", str(SQUARE_MM), "--out", str(folder / "camera.toml"), "--no-rrd"])
    tips, bases = clicked(args.mirror)
    log = {"capture": {"frames": "bowl/*.jpg", "units": "mm", "gamma": "srgb"},
           "camera": {"file": "camera.toml"},
           "planes": [{"name": "desk", "chessboard": BOARD, "square": SQUARE_MM, "image": "calib/calib_1.jpg",
                       "regions": BANDS}],
           "pencil": {"height": PENCIL_MM, "sigma_px": 3.0,
                      "photos": [{"base": b, "tip": t} for b, t in zip(bases, tips, strict=True)]}}
    path = folder / "field_log.toml"
    toml_io.dump(log, path)
    auto_tips(args.mirror, folder, log, tips, bases)  # before the clicked lamp: both write lamp.toml
    run(["calibrate", "lamp", str(path)])
    log["light"] = toml_io.load(folder / "lamp.toml")["light"]
    toml_io.dump(log, path)
    regions_preview_scan(path)  # gnomon regions from the bands, its mask into the field log, preview, scan
    score(folder)
    print(f"done in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
