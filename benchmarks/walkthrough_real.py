"""The README's walk-through on public real captures, as a newcomer runs it: no field log typed, no file
edited but the marks `gnomon init` asks for (a script, not a test).

    PYTHONPATH=python python benchmarks/walkthrough_real.py [--brandonhung DIR] [--afiretony DIR] [--man DIR]
        [--out DIR]

The checkouts are never committed here and never downloaded by tests. For each capture, in its own folder,
with copies of its frames and board photos, each command timed:

    gnomon calibrate camera board --board 8x6 --square 25 --out camera.toml   # the square: any (scale-free)
    gnomon init frames --camera camera.toml       # the marks found in the first frame, units "relative"
    gnomon regions field_log.toml                 # the object cut out, the masks switched on in the log
    gnomon scan field_log.toml --out scan

A command that refuses (exit code 2) ends that capture; its one line is printed as the outcome.

* ``--brandonhung``: BrandonHung343/15-463-HW-6, ``data/frog/v2`` (200 frames 1024x768 of the CMU course's
  frog set-up, a second sweep the other benchmarks do not use: benchmarks/real_captures.py scans the first)
  with ``data/calib``. Scored like benchmarks/real_captures.py's frog (its outlines of the boxes' faces: the
  camera did not move between the sweeps, the marks are within 4 px of the first's; the frog, turned, and its
  shadows outlined anew below), inside each plane's four marks, in mm: the relative unit (the desk's
  distance from the camera) turned into mm with the course's measured desk rectangle (558.8 mm long; the
  scan never sees it). Printed: each plane's planarity (median / RMS distance to its marks' plane, mm and
  per mille of the desk's distance) and coverage of its bare swept pixels, the object's coverage, the false
  points, the desk-wall angle, and each fitted rectangle's proportions against the measured ones.
* ``--afiretony``: afiretony/Computational-Photography, a student's own 1080p captures (see AFIRETONY).
  No outline of the objects: each plane scored inside the mask `gnomon regions` proposed (the bare plane
  the scan used), per mille of the desk's distance, with the desk-wall angle.
* ``--man``: Vincent-2017/mlShadowScan, ``data/man/v1`` (200 frames 1024x768 of a plaster bust in the set-up
  the CMU frog comes from: Lanman & Taubin's swept-plane course data, with its ``data/calib`` photos, the same
  files as the frog's); no benchmark uses it. Scored as the frog's second sweep is (the bust and its
  shadows outlined by hand on its first frame, the boxes' faces of real_captures.py: the marks lie within 5 px
  of the frog's), and also inside the masks `gnomon regions` proposed.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from real_captures import FROG_OTHER_FACES, FROG_RECT  # noqa: E402
from score import _polygon_mask, score_scan  # noqa: E402

# The second sweep's frog lies otherwise than the first's: its outline and its cast shadows, hand-drawn on the
# first frame of data/frog/v2 (pixels), for scoring only (grown by score_scan's keep-out margin).
V2_FROG = [(283, 440), (300, 405), (360, 370), (410, 355), (445, 365), (470, 405), (560, 380), (600, 345),
           (640, 328), (700, 342), (748, 345), (760, 385), (756, 435), (740, 475), (732, 530), (722, 582),
           (680, 602), (640, 600), (600, 612), (575, 602), (480, 597), (420, 572), (385, 545), (350, 556),
           (330, 532), (300, 500), (290, 470)]
V2_SHADOWS = [[(190, 498), (270, 505), (330, 518), (400, 540), (470, 598), (420, 606), (300, 602), (230, 602),
               (188, 590)],
              [(560, 600), (640, 594), (702, 600), (706, 662), (650, 672), (580, 652), (558, 630)]]


class Refused(Exception):
    """A command exited with code 2: its one line is the capture's outcome."""


def gnomon(args: list[str], cwd: Path, output: list[str] | None = None) -> float:
    """Run ``gnomon ARGS`` in ``cwd`` as a user does (a process); its wall time in seconds (its output lines
    appended to ``output``). Exit code 2 raises :class:`Refused` with the command's error line."""
    print("$ gnomon " + " ".join(args), flush=True)
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "gnomon", *args], cwd=cwd, env=_env(), text=True,
                          capture_output=True)
    elapsed = time.perf_counter() - t
    tail = [line for line in (done.stdout + done.stderr).splitlines() if not line.startswith(("tracking:", "scan:"))]
    print("\n".join("  " + line for line in tail[-12:]), flush=True)
    if output is not None:
        output.extend(tail)
    if done.returncode == 2:
        raise Refused(next((line for line in tail if line.startswith("gnomon: error")), tail[-1] if tail else ""))
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


def walk(work: Path, frames: Path, board: Path, board_size: str, added: dict[str, list] | None = None) -> dict:
    """The README's four commands in ``work`` on copies of ``frames`` and ``board`` (its photos); ``added``: the
    marks a user types after `init` asks for them (plane name -> pixels). Returns each command's time, or
    where it was refused."""
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    shutil.copytree(frames, work / "frames")
    shutil.copytree(board, work / "board", ignore=shutil.ignore_patterns("*.npz"))
    times: dict[str, float] = {}
    try:
        times["calibrate camera"] = gnomon(["calibrate", "camera", "board", "--board", board_size, "--square", "25",
                                            "--out", "camera.toml", "--quiet"], work)
        times["init"] = gnomon(["init", "frames", "--camera", "camera.toml"], work)
        for plane, pixels in (added or {}).items():
            add_marks(work / "field_log.toml", plane, pixels)
        regions_output: list[str] = []
        times["regions"] = gnomon(["regions", "field_log.toml", "--quiet"], work, regions_output)
        times["scan"] = gnomon(["scan", "field_log.toml", "--out", "scan", "--quiet"], work)
    except Refused as refused:
        return {"times": times, "refused": str(refused)}
    print("commands' wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
          + f"; {sum(times.values()):.1f} s in all")
    return {"times": times, "refused": "", "gaps": line_gaps(regions_output)}


def line_gaps(regions_output: list[str]) -> dict[str, list[tuple[int, int]]]:
    """The frames in which `gnomon regions` found no line of a plane's own (its warning "no line in frames
    A–B, C–D of its sweep", the first six spans), plane name -> spans (frame indices from 0, inclusive: the
    files' numbers less one)."""
    gaps = {}
    for line in regions_output:
        found = re.match(r"warning: plane '(\w+)': no line in frames ([0-9–, ]+)", line)
        if found:
            gaps[found[1]] = [(int(a), int(b)) for a, b in re.findall(r"(\d+)–(\d+)", found[2])]
    return gaps


def bare_lines(work: Path, plane: dict, bare: np.ndarray, crossed: np.ndarray) -> np.ndarray:
    """The frames in which the shadow times over ``bare`` (pixels of one plane only) fit a line on that plane
    (:func:`gnomon.geometry.reference_lines.lines_on_plane`, as the scan fits its lines), (n_frames,) bool."""
    from gnomon.camera.calibration import load_camera_file
    from gnomon.camera.models import Pose
    from gnomon.geometry.reference_lines import PlaneInCamera, lines_on_plane

    pose = Pose.from_rvec_tvec(np.array(plane["rvec"]), np.array(plane["tvec"]))
    in_camera = PlaneInCamera.from_world(np.zeros(3), np.array([0.0, 0.0, 1.0]), pose)
    n_frames = len(list((work / "frames").iterdir()))
    lines = lines_on_plane(crossed.astype(np.float64), n_frames, in_camera, bare,
                           load_camera_file(work / "camera.toml"), plane["plane"])
    return lines.found


def add_marks(log: Path, plane: str, pixels: list) -> None:
    """What a user types when `init` asks for a plane's missing mark: ``{ id = N, pixel = [u, v] }`` lines
    appended to that plane's markers."""
    text = log.read_text()
    head = text.index(f'name = "{plane}"')
    end = text.index("\n]", text.index("markers = [", head))
    last_id = max(int(x) for x in re.findall(r"id = (\d+)", text))
    lines = "".join(f",\n  {{ id = {last_id + 1 + k}, pixel = [{u:.1f}, {v:.1f}] }}" for k, (u, v) in enumerate(pixels))
    log.write_text(text[:end] + lines + text[end:])


def planes_of(work: Path) -> dict:
    report = json.loads((work / "scan" / "report.json").read_text())
    return {p["plane"]: p for p in report["reference_planes"]}


def print_planes(planes: dict, measured: float | None) -> None:
    """Each plane's marks' rectangle, its proportions (against the measured ones), its normal's σ, and the
    desk-wall angle."""
    for name, p in planes.items():
        a, b = sorted(p["rectangle"], reverse=True)
        against = f", measured {measured:.4f} ({100 * (b / a / measured - 1):+.2f} %)" if measured else ""
        print(f"{name}: its marks' rectangle {a:.4f} x {b:.4f} (relative units): proportions {b / a:.4f}{against}; "
              f"normal ± {p['std_normal_deg']:.2f}°")
    print(f"desk-wall angle {planes['wall']['angle_to_first_deg']:.2f}°")


def score_regions(work: Path) -> None:
    """Without outlines of the object: each plane's points inside the mask `gnomon regions` proposed (the
    bare plane the scan used), their distance to the plane of the marks and to their own best plane, per
    mille of the desk's distance (the relative unit), and whether the RMS stays within 2x the median-based
    spread (no band of wrong depth); the mask's coverage."""
    import cv2

    from gnomon.camera.calibration import load_camera_file

    planes = planes_of(work)
    depth = np.load(work / "scan" / "depth.npy").astype(np.float64)
    rays = load_camera_file(work / "camera.toml").ray_map().astype(np.float64)
    points = rays * (depth / rays[..., 2])[..., None]
    for name, p in planes.items():
        mask = cv2.imread(str(work / "regions" / f"{name}_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
        sel = mask & np.isfinite(depth)
        q = points[sel]
        d = q @ np.array(p["normal_cam"]) - p["offset_cam"]
        c = q.mean(axis=0)
        n = np.linalg.svd(q - c, full_matrices=False)[2][2]
        own = (q - c) @ n
        med, rms = np.median(np.abs(d)), np.sqrt(np.mean(d ** 2))
        print(f"  {name}: planarity (per mille of the desk's distance) to its marks' plane median {1000 * med:.2f}, "
              f"RMS {1000 * rms:.2f}; to its own best plane median {1000 * np.median(np.abs(own)):.2f}, RMS "
              f"{1000 * np.sqrt(np.mean(own ** 2)):.2f}; RMS / (1.4826 median) {rms / (1.4826 * med):.2f}; points on "
              f"{100 * sel.sum() / max(mask.sum(), 1):.1f} % of the {int(mask.sum())} mask pixels")


def frog_v2(mirror: Path, out: Path) -> None:
    """BrandonHung343/15-463-HW-6: data/frog/v2 with data/calib, scored as real_captures.py scores the frog."""
    course_setup("frog v2", out / "frog_v2", mirror / "data" / "frog" / "v2", mirror / "data" / "calib", V2_FROG,
                 V2_SHADOWS)


# Vincent-2017/mlShadowScan data/man/v1: the bust (head, chest and the black pedestal) and its cast shadows
# (left of the head on desk and wall, under the chest, below the chest's edge, right of the pedestal),
# hand-drawn on its first frame (pixels), for scoring only.
MAN = [(303, 385), (318, 340), (345, 318), (390, 312), (425, 322), (445, 345), (470, 372), (488, 400), (505, 425),
       (540, 405), (590, 392), (650, 388), (700, 392), (715, 420), (740, 440), (770, 428), (795, 440), (808, 470),
       (805, 530), (790, 585), (760, 615), (725, 628), (690, 622), (660, 590), (640, 575), (580, 575), (520, 600),
       (495, 622), (460, 612), (445, 585), (442, 540), (455, 505), (430, 490), (380, 492), (345, 470), (318, 440)]
MAN_SHADOWS = [[(238, 455), (265, 425), (310, 420), (330, 460), (380, 495), (440, 500), (450, 520), (420, 525),
                (330, 515), (262, 512), (240, 495)],
               [(430, 590), (470, 615), (500, 640), (470, 650), (430, 630)],
               [(500, 600), (520, 585), (560, 578), (640, 578), (660, 590), (680, 615), (690, 645), (670, 648),
                (650, 612), (620, 614), (560, 610), (525, 620), (500, 642)],
               [(650, 600), (700, 628), (760, 622), (790, 600), (800, 620), (770, 650), (700, 652), (660, 635)]]


def man(mirror: Path, out: Path) -> None:
    """Vincent-2017/mlShadowScan: data/man/v1 with data/calib, scored as the frog's second sweep is."""
    course_setup("man", out / "man", mirror / "data" / "man" / "v1", mirror / "data" / "calib", MAN, MAN_SHADOWS)


def course_setup(name: str, work: Path, frames: Path, board: Path, outline: list, shadows: list) -> None:
    """A sweep of the course's desk-and-wall set-up walked through and scored: inside each plane's marks less
    the object and its shadows (``outline``, ``shadows``: pixels of the first frame) and the boxes' faces, in
    mm through the course's measured desk rectangle; then inside the masks `gnomon regions` proposed."""
    import cv2

    result = walk(work, frames, board, "8x6")
    if result["refused"]:
        print(f"{name}: refused: {result['refused']}")
        return
    planes = planes_of(work)
    print_planes(planes, FROG_RECT[1] / FROG_RECT[0])
    scale = FROG_RECT[0] / max(planes["desk"]["rectangle"])
    print(f"mm per relative unit (the desk marks' measured 558.8 mm): {scale:.1f}; the wall's marks' long side "
          f"then {scale * max(planes['wall']['rectangle']):.1f} mm (measured 558.8)")
    # the bare planes scored: inside each plane's four marks, as the image shows them (independent of the
    # regions the scan used), less the object, its shadows, the marks and the boxes' faces (score_scan)
    shape = np.load(work / "scan" / "depth.npy").shape
    masks = {}
    for plane, p in planes.items():
        hull = cv2.convexHull(np.round(np.array(p["pixels"])).astype(np.int32))
        masks[plane] = cv2.fillConvexPoly(np.zeros(shape, np.uint8), hull, 1).astype(bool)
    with tempfile.TemporaryDirectory() as tmp:
        scored = score_scan(f"{name} (walk-through)", in_mm(work / "scan", scale, Path(tmp)), work / "camera.toml",
                            None, outline, shadows, other_faces=FROG_OTHER_FACES, region_masks=masks)
    print("\n".join(scored.lines()))
    for p in scored.planes:
        print(f"  {p.name} planarity per mille of the desk's distance ({scale:.0f} mm): median "
              f"{1000 * p.median_abs / scale:.2f}, RMS {1000 * p.rms / scale:.2f}; RMS / (1.4826 median) "
              f"{p.rms / (1.4826 * p.median_abs):.2f}")
    # where a plane had no line of its own, its shadow planes were completed from the other plane's line and
    # the light (light/two_plane.py): the bare pixels crossed then, scored apart from the rest. The gaps are
    # regions' leaving edge's; shadow_time.npy is the mean of the two edges' times (a few frames earlier)
    crossed = np.load(work / "scan" / "shadow_time.npy")  # frame indices from 0, as the gaps' are
    for plane, spans in result["gaps"].items():
        in_gap = np.zeros(shape, bool)
        for a, b in spans:
            in_gap |= (crossed >= a - 0.5) & (crossed <= b + 0.5)
        with tempfile.TemporaryDirectory() as tmp:
            mm = in_mm(work / "scan", scale, Path(tmp))
            parts = [score_scan(name, mm, work / "camera.toml", None, outline, shadows, other_faces=FROG_OTHER_FACES,
                                region_masks={**masks, plane: masks[plane] & sel}) for sel in (in_gap, ~in_gap)]
        (inside,), (outside,) = ([p for p in part.planes if p.name == plane] for part in parts)
        print(f"  {plane}: its bare pixels whose shadow time falls in the frames where it had no line "
              f"({', '.join(f'{a}-{b}' for a, b in spans)}): {inside.swept} swept, planarity median "
              f"{inside.median_abs:.2f} mm, RMS {inside.rms:.2f} mm; the rest: {outside.swept}, median "
              f"{outside.median_abs:.2f} mm, RMS {outside.rms:.2f} mm")
        bare = masks[plane] & ~_polygon_mask(shape, [outline, *shadows, *FROG_OTHER_FACES.values()], 12)
        found = bare_lines(work, planes[plane], bare, crossed)
        gap_frames = [t for a, b in spans for t in range(a, b + 1)]
        print(f"    the scan's shadow times (the two edges' mean) over the bare {plane} (its marks' outline less the "
              f"outlines) fit a line of its own in {sum(found[t] for t in gap_frames)} of those {len(gap_frames)} "
              "frames")
    print("inside the masks `gnomon regions` proposed:")
    score_regions(work)


# afiretony/Computational-Photography assignments/assgn6/data: a student's own captures (1080p phone video, a
# desk and a wall sheet with four printed 2x2 checkers each, spacing never measured), each with the board photos
# of its folder name or, where none is named, calib-own (both 1080p, 8x6 inner corners). ADDED: the marks
# `init` asks for (not clean checkers), clicked on the first frame and refined by eye to their centre.
AFIRETONY = {"cup": ("cup/v1", "calib-cup"), "dog v1": ("dog/v1", "calib-own"), "dog v3": ("dog/v3", "calib-own"),
             "green": ("green/v1", "calib-own")}
ADDED = {"dog v1": {"desk": [(365.7, 987.3)]}}


def afiretony(mirror: Path, out: Path) -> None:
    data = mirror / "assignments" / "assgn6" / "data"
    for name, (frames, board) in AFIRETONY.items():
        print(f"== {name}")
        work = out / name.replace(" ", "_")
        result = walk(work, data / frames, data / board, "8x6", ADDED.get(name))
        if result["refused"]:
            print(f"{name}: refused: {result['refused']}")
            continue
        print_planes(planes_of(work), None)
        score_regions(work)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--brandonhung", type=Path, help="checkout of BrandonHung343/15-463-HW-6")
    ap.add_argument("--afiretony", type=Path, help="checkout of afiretony/Computational-Photography")
    ap.add_argument("--man", type=Path, help="checkout of Vincent-2017/mlShadowScan")
    ap.add_argument("--out", type=Path, default=Path("walkthrough_real"))
    args = ap.parse_args(argv)
    if args.brandonhung:
        frog_v2(args.brandonhung, args.out)
    if args.afiretony:
        afiretony(args.afiretony, args.out)
    if args.man:
        man(args.man, args.out)
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
