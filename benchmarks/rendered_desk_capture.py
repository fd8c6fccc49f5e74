"""Scan an independent renderer's desk capture with its exact camera and lamp (a script, not a test).

    PYTHONPATH=python python benchmarks/rendered_desk_capture.py MIRROR_DIR [--out DIR] [--gamma G]

MIRROR_DIR is a checkout of the GitHub repository
pusacaspica/3d-photography-on-your-desk (never committed here, never downloaded
by tests). Its ``teste00/`` holds 100 frames (1024×768 JPEG) that Blender
rendered of a monkey's head, a sphere on a post and a short cylinder standing
on a bare white ground, a thin stick's shadow swept across them by a point
lamp; one photo of an 8×8 chessboard lying on that ground
(``camera_calibration_0.jpg``); and ``calib.txt``, where its authors wrote the
renderer's camera (position, Euler angles, 50 mm lens) and, for four cones
standing on the ground, the world coordinates of each cone's tip and of its
shadow's tip (cm).

What the script checks, and how:

* **Gnomon's calibration from the one board photo.** ``gnomon calibrate
  camera --model tsai`` with Blender's default sensor (36 mm over 1024 px);
  its focal length against the renderer's 50 mm, and the board's tilt to the
  optical axis (``cv2.solvePnP`` with that camera) against the camera's 42°
  Euler tilt.
* **The scan itself, with the renderer's own calibration**: the camera from
  ``calib.txt`` (centred, no distortion), the ground plane at the height of
  the cones' shadow tips, the lamp where the four tip-to-shadow lines meet
  (least squares). ``gnomon regions`` proposes the bare swept ground, then
  ``gnomon scan``. The board's square size is not given anywhere, so Gnomon's
  own board pose sets no scale here.
* **Scored against the renderer's ground plane**: every point off the magenta
  objects (their colour, dilated 3 px) against the plane (median and RMS of
  its height error), coverage of the proposed bare ground, false points (off
  the objects and more than 5 mm off the ground, or below it), those beyond 5
  of their own σ, and the sphere (a robust sphere fit on its points: radius
  and residual). The scan's warnings are printed: the lamp stands nearly in
  line with the camera, 2.2 m away, and the rays meet the shadow planes at a
  median 4.7°, under 1° near the image's centre column, where the planes pass
  through the camera (``report.json`` ``grazing_share``).
* **Gnomon's own calibration**: the same scan with the Tsai camera and the
  ground from the board photo (a plane with ``chessboard`` and ``image``); its
  square size, which the authors do not give, set from the renderer's camera
  height, and the lamp carried into the board's frame.
* **The timing alone**: each edge's times on the bare ground against the time
  at which its own shadow planes (interpolated between frames, as the
  triangulation does) pass through the renderer's ground point of the pixel.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gnomon.camera.calibration import load_camera_file
from gnomon.camera.plane_pose import PlanePose, plane_pose_from_chessboard
from gnomon.outputs.ply import read_ply
from gnomon.runs.scan import ScanOptions, ScanResult, run_scan
from gnomon.util import toml_io
from real_captures import run

SENSOR_MM = 36.0  # Blender's default sensor width (its "auto" fit: the width of a landscape image)
BOARD = (7, 7)  # inner corners of the 8×8 board


def numbers(text: str) -> list[float]:
    """The numbers of a line of calib.txt (a decimal comma, as in '-3,8839', read as a point)."""
    return [float(x.replace(",", ".")) for x in re.findall(r"-?\d+(?:[.,]\d+)?", text)]


def read_calib(path: Path) -> dict:
    """Camera position (mm), Euler angles (deg), focal length (mm), and the cones' tips and shadows (mm)."""
    text = path.read_text(encoding="utf-8", errors="replace")
    lines = text.splitlines()
    found: dict = {"tips": [], "shadows": []}
    for i, line in enumerate(lines):
        if line.startswith("CAMERA WORLD POSITION"):
            found["position_mm"] = np.array(numbers(line)) * 10.0
        elif line.startswith("CAMERA ROTATION"):
            found["euler_deg"] = np.array(numbers(line))
        elif line.startswith("FOCAL LENGTH"):
            found["focal_mm"] = numbers(line)[0]
        elif line.strip() == "real coord.":
            found["shadows"].append(np.array(numbers(lines[i + 1])) * 10.0)
            found["tips"].append(np.array(numbers(lines[i + 2])) * 10.0)
    return found


def blender_pose(position_mm: np.ndarray, euler_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World → camera (x right, y down, z forward) of a Blender camera at ``position`` with XYZ Euler angles."""
    def rot(axis: int, deg: float) -> np.ndarray:
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        m = np.eye(3)
        m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
        return m
    camera_to_world = rot(2, euler_deg[2]) @ rot(1, euler_deg[1]) @ rot(0, euler_deg[0])
    R = np.diag([1.0, -1.0, -1.0]) @ camera_to_world.T  # Blender's camera looks along −z with y up
    return R, -R @ position_mm


def lamp_from_cones(tips: list[np.ndarray], shadows: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The point closest to every tip-to-shadow line (least squares) and its distance to each line (mm)."""
    a, b, projectors = np.zeros((3, 3)), np.zeros(3), []
    for tip, shadow in zip(tips, shadows, strict=True):
        d = (tip - shadow) / np.linalg.norm(tip - shadow)
        p = np.eye(3) - np.outer(d, d)
        a += p
        b += p @ shadow
        projectors.append((p, shadow))
    lamp = np.linalg.solve(a, b)
    return lamp, np.array([np.linalg.norm(p @ (lamp - s)) for p, s in projectors])


def board_pose(image: Path, camera_file: Path) -> PlanePose:
    """The board's plane from the photo (squares as units), as a field log's ``chessboard`` plane gets it."""
    return plane_pose_from_chessboard(cv2.imread(str(image)), load_camera_file(camera_file), BOARD, 1.0,
                                      source=str(image))


def score(scan: Path, first_frame: Path, ground_z: float, region_mask: Path,
          to_renderer: Callable[[np.ndarray], np.ndarray] | None = None) -> list[str]:
    """The figures of the module docstring, as lines (``to_renderer`` carries the points from the scan's
    world frame into the renderer's first)."""
    ply = read_ply(scan / "points.ply")
    xyz, uv, sigma = ply["xyz"].astype(np.float64), ply["uv"], ply["sigma"]
    if to_renderer is not None:
        xyz = to_renderer(xyz)
    image = cv2.imread(str(first_frame))
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    magenta = ((hsv[..., 0] > 135) & (hsv[..., 0] < 165) & (hsv[..., 1] > 80)).astype(np.uint8)
    n_labels, labels = cv2.connectedComponents(magenta)
    sizes = np.bincount(labels.ravel())
    objects = np.isin(labels, [i for i in range(1, n_labels) if sizes[i] > 500])
    near_objects = cv2.dilate(objects.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, image.shape[1] - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, image.shape[0] - 1)
    off_objects = ~near_objects[v, u]
    dz = xyz[:, 2] - ground_z
    g = dz[off_objects]
    out = [f"  {len(xyz)} points; {off_objects.sum()} off the objects: height above the renderer's ground "
           f"median {np.median(g):+.3f} mm, |median| {np.median(np.abs(g)):.3f} mm, "
           f"RMS {np.sqrt(np.mean(g ** 2)):.3f} mm, p99 {np.percentile(np.abs(g), 99):.2f} mm"]
    region = cv2.imread(str(region_mask), cv2.IMREAD_GRAYSCALE) > 0
    have = np.zeros(region.shape, bool)
    have[v, u] = True
    out.append(f"  points on {100 * have[region].mean():.1f} % of the {region.sum()} proposed bare ground pixels")
    false = (off_objects & (np.abs(dz) > 5.0)) | (dz < -5.0)
    beyond = false & (np.abs(dz) > 5.0 * sigma)
    out.append(f"  false points (off the objects and > 5 mm off the ground, or below it): {100 * false.mean():.2f} % "
               f"({false.sum()}); beyond 5 of their own σ: {100 * beyond.mean():.2f} %")
    # the sphere: the largest magenta component in the upper right half of the image
    candidates = [i for i in range(1, n_labels) if sizes[i] > 500]
    sphere = max(candidates, key=lambda i: sizes[i] if np.mean(np.nonzero(labels == i)[1]) > image.shape[1] / 2
                 else 0)
    inner = cv2.erode((labels == sphere).astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    p = xyz[inner[v, u]]
    a = np.c_[2 * p, np.ones(len(p))]
    b = (p ** 2).sum(axis=1)
    keep = np.ones(len(p), bool)
    for _ in range(4):  # robust: refit on the residuals within 2.5× their median
        c = np.linalg.lstsq(a[keep], b[keep], rcond=None)[0]
        centre, radius = c[:3], math.sqrt(c[3] + c[:3] @ c[:3])
        r = np.linalg.norm(p - centre, axis=1) - radius
        keep = np.abs(r) < 2.5 * np.median(np.abs(r))
    have_inner = have[inner].mean()
    out.append(f"  sphere: points on {100 * have_inner:.1f} % of its disc (7 px in from its outline); robust fit "
               f"radius {radius:.2f} mm, centre {centre[2] - ground_z:.1f} mm above the ground; residual |median| "
               f"{np.median(np.abs(r)):.2f} mm, RMS {np.sqrt(np.mean(r ** 2)):.2f} mm (all its points)")
    return out


def time_errors(result: ScanResult, ground_z: float, first_frame: Path) -> list[str]:
    """Each edge's shadow times on the bare ground against the times its own shadow planes give the
    renderer's ground point of each pixel (the plane table interpolated linearly between frames, as
    the triangulation does): the timing alone, whatever the geometry does with it."""
    rays = result.setup.camera.ray_map().astype(np.float64)
    R, t = result.setup.pose.R, result.setup.pose.t
    normal = R @ np.array([0.0, 0.0, 1.0])
    ground = rays * ((normal @ (R @ np.array([0.0, 0.0, ground_z]) + t)) / (rays @ normal))[..., None]
    hsv = cv2.cvtColor(cv2.imread(str(first_frame)), cv2.COLOR_BGR2HSV)
    magenta = ((hsv[..., 0] > 135) & (hsv[..., 0] < 165) & (hsv[..., 1] > 80)).astype(np.uint8)
    bare = ~cv2.dilate(magenta, np.ones((9, 9), np.uint8)).astype(bool)
    lines = []
    for edge in result.edges:
        v, u = np.nonzero(bare & np.isfinite(edge.times))
        times, x = edge.times[v, u].astype(np.float64), ground[v, u]
        truth = np.full(len(v), np.nan)
        for dk in range(-3, 3):  # the row pair around the scan's time whose planes bracket the point
            k = np.clip(np.floor(times).astype(int) + dk, 0, len(edge.planes) - 2)
            a, b = edge.planes[k], edge.planes[k + 1]
            sa = np.einsum("ij,ij->i", a[:, :3], x) - a[:, 3]
            sb = np.einsum("ij,ij->i", b[:, :3], x) - b[:, 3]
            with np.errstate(divide="ignore", invalid="ignore"):
                f = sa / (sa - sb)
            candidate = k + f
            better = (f >= 0) & (f <= 1) & (np.isnan(truth) | (np.abs(candidate - times) < np.abs(truth - times)))
            truth[better] = candidate[better]
        err = (times - truth)[np.isfinite(truth)]
        a = np.abs(err)
        lines.append(f"  {edge.name} edge's times on the bare ground, against the renderer's ground point on its own "
                     f"planes ({err.size} pixels): median {np.median(err):+.4f}, |median| {np.median(a):.4f}, "
                     f"p90 {np.percentile(a, 90):.4f}, p99 {np.percentile(a, 99):.4f} frame")
    return lines


def own_calibration(out: Path, source: Path, camera: Path, R: np.ndarray, t: np.ndarray, lamp: np.ndarray,
                    height_mm: float, ground_z: float) -> None:
    """The scan with Gnomon's own calibration from the one board photo: the Tsai camera, the ground from
    the board (a field log plane with ``chessboard`` and ``image``), the same regions. The authors give no
    square size: it is set so that the board puts the camera at the renderer's height above the ground;
    the lamp is carried into the board's frame through the renderer's camera."""
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import frame_source, resolve_scan

    folder = out / "own_calibration"
    folder.mkdir(exist_ok=True)
    square = height_mm / board_pose(source / "camera_calibration_0.jpg", camera).offset_cam  # height in squares
    log = {"capture": {"frames": str(source / "0*.jpg"), "units": "mm"}, "camera": {"file": str(camera)},
           "planes": [{"name": "ground", "chessboard": f"{BOARD[0]}x{BOARD[1]}", "square": square,
                       "image": str(source / "camera_calibration_0.jpg"),
                       "mask": str(out / "scan_setup" / "regions" / "ground_mask.png")}],
           "light": {"kind": "lamp", "position": [0.0, 0.0, -1.0e4]}}  # replaced below
    log_path = folder / "field_log.toml"
    toml_io.dump(log, log_path)
    pose = resolve_scan(loaded := load_field_log(log_path), frame_source(loaded)).pose
    log["light"]["position"] = pose.camera_to_world((R @ lamp + t)[None])[0].tolist()
    toml_io.dump(log, log_path)
    run(["scan", str(log_path), "--out", str(folder / "scan"), "--no-rrd", "--quiet"])
    # the board's plane (z = 0 in its frame) against the renderer's ground: its angle, and its height at
    # the board's first inner corner (its frame's origin: the frame's y runs along or against the board's
    # columns, whichever puts its z towards the camera) above the renderer's ground
    def to_renderer(points: np.ndarray) -> np.ndarray:  # board frame -> camera -> the renderer's world
        return (pose.world_to_camera(points) - t) @ R

    centre, normal_end = to_renderer(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    n = normal_end - centre
    angle = math.degrees(math.acos(min(1.0, abs(n[2]) / np.linalg.norm(n))))
    print(f"with Gnomon's own calibration (square {square:.2f} mm from the renderer's camera height; the board's "
          f"plane is {angle:.3f}° off the renderer's ground and {centre[2] - ground_z:+.2f} mm above it at the "
          f"board's first inner corner):")
    print("\n".join(score(folder / "scan", sorted(source.glob("0*.jpg"))[0], ground_z,
                          out / "scan_setup" / "regions" / "ground_mask.png", to_renderer=to_renderer)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mirror", type=Path)
    ap.add_argument("--out", type=Path, default=Path("rendered_desk_capture"))
    ap.add_argument("--gamma", default=None, help="[capture] gamma (default: none, the frames' values)")
    ap.add_argument("--max-sigma", default="", help="comma-separated [output] max_sigma bounds (mm) to scan with too")
    args = ap.parse_args(argv)
    t0 = time.time()
    source = args.mirror / "teste00"
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    calib = read_calib(source / "calib.txt")
    width, height = 1024, 768
    pitch = SENSOR_MM / width

    camera = out / "camera_tsai.toml"
    run(["calibrate", "camera", str(source / "camera_calibration_0.jpg"), "--board", f"{BOARD[0]}x{BOARD[1]}",
         "--square", "1", "--model", "tsai", "--pixel-pitch", f"{pitch!r}", "--out", str(camera), "--no-rrd"])
    fitted = toml_io.load(camera)
    board = board_pose(source / "camera_calibration_0.jpg", camera)
    tilt, rms = math.degrees(math.acos(abs(board.normal_cam[2]))), board.rms_px
    std = fitted["calibration"]["std"]["f_mm"]
    print(f"camera from the one board photo (Tsai): f {fitted['f_mm']:.3f} ± {std:.3f} mm "
          f"(renderer {calib['focal_mm']:g} mm), RMS {fitted['calibration']['rms_px']:.3f} px; the board's tilt to "
          f"the optical axis {tilt:.3f}° (renderer's camera {calib['euler_deg'][0]:g}°), pose RMS {rms:.3f} px")

    R, t = blender_pose(calib["position_mm"], calib["euler_deg"])
    lamp, misses = lamp_from_cones(calib["tips"], calib["shadows"])
    ground_z = float(np.mean([s[2] for s in calib["shadows"]]))
    print(f"lamp from the {len(misses)} cones: {np.round(lamp, 1)} mm (lines pass {np.round(misses, 1)} mm from it); "
          f"ground at z = {ground_z:.2f} mm")
    f_px = calib["focal_mm"] / pitch
    log = {"capture": {"frames": str(source / "0*.jpg"), "units": "mm"},
           "camera": {"model": "opencv", "width": width, "height": height, "fx": f_px, "fy": f_px,
                      "cx": (width - 1) / 2, "cy": (height - 1) / 2, "dist": [0.0] * 5,
                      "pose": {"rvec": cv2.Rodrigues(R)[0].ravel().tolist(), "tvec": t.tolist()}},
           "planes": [{"name": "ground", "point": [0.0, 0.0, ground_z], "normal": [0.0, 0.0, 1.0],
                       "regions": [[0, 0, width, 40], [0, height - 40, width, height]]}],
           "light": {"kind": "lamp", "position": lamp.tolist()}}
    if args.gamma is not None:
        log["capture"]["gamma"] = float(args.gamma) if args.gamma[0].isdigit() else args.gamma
    folder = out / "scan_setup"
    folder.mkdir(exist_ok=True)
    log_path = folder / "field_log.toml"
    toml_io.dump(log, log_path)
    run(["regions", str(log_path), "--out", str(folder / "regions"), "--quiet"])
    log["planes"][0]["mask"] = "regions/ground_mask.png"
    log["planes"][0].pop("regions")
    toml_io.dump(log, log_path)
    own_calibration(out, source, camera, R, t, lamp, calib["position_mm"][2] - ground_z, ground_z)
    bounds = [float(x) for x in args.max_sigma.split(",") if x]
    for bound in [None, *bounds]:
        name = "scan" if bound is None else f"scan_max_sigma_{bound:g}"
        path = log_path
        if bound is not None:
            bounded = dict(log, output={"max_sigma": bound})
            path = folder / f"field_log_max_sigma_{bound:g}.toml"
            toml_io.dump(bounded, path)
        print(f"$ gnomon scan {path} --out {folder / name} --no-rrd --quiet (in this process)", flush=True)
        result = run_scan(path, folder / name, ScanOptions(rrd=False))
        for warning in result.warnings:
            print(f"gnomon: warning: {warning}")
        report = result.report
        print(f"{name}:")
        for edge, e in report["edges"].items():
            if edge != "disagreement" and e.get("ray_plane_angle_deg"):
                a = e["ray_plane_angle_deg"]
                print(f"  {edge}: rays meet their planes at {a['p10']:.2f} / {a['p50']:.2f} / {a['p90']:.2f}° "
                      f"(p10 / 50 / 90), {100 * e['grazing_share']:.1f} % under 2°")
        print("\n".join(score(folder / name, sorted(source.glob("0*.jpg"))[0], ground_z,
                              folder / "regions" / "ground_mask.png")))
        if bound is None:
            print("\n".join(time_errors(result, ground_z, sorted(source.glob("0*.jpg"))[0])))
    print(f"done in {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
