"""`gnomon calibrate camera IMAGES... --board COLSxROWS --square S [--model zhang|tsai]`,
`gnomon calibrate points FILE --size WxH --pixel-pitch DX[,DY]` and `gnomon calibrate lamp FIELD_LOG`.

`camera` finds the chessboard in each photo, calibrates (Zhang's method
through OpenCV, or our Tsai implementation), prints per-view reprojection
errors and the parameters with their standard deviations, and writes the
camera file (TOML) that field logs reference. Warnings (a photo without a
board, a rejected outlier view, a degenerate Tsai set-up) go to stderr, one
line each.

`points` is Tsai's method on measured correspondences: a text file with one
point per line, ``xw yw zw Xf Yf`` (world coordinates, then the pixel), as in
Willson's reference implementation's data files; ``#`` starts a comment.
"""

from __future__ import annotations

import argparse
import math
import sys
from functools import partial
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.errors import GnomonError
from gnomon.recording.recorder import add_recording_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "calibrate",
        help=COMMANDS["calibrate"],
        description="Calibrate the camera from chessboard photos, or the lamp from pencil photos.",
    )
    sub = p.add_subparsers(dest="what", metavar="WHAT", required=True)

    c = sub.add_parser(
        "camera",
        help="chessboard photos → camera file (TOML)",
        description=(
            "Find a chessboard in each photo and calibrate the camera: Zhang's method (OpenCV's "
            "5-coefficient model, >= 3 views) or Tsai's two-stage method (one view or several). "
            "A video of the board (filmed in the capture's own video mode) gives its sharp, distinct frames "
            "as views. Writes a camera file for field logs ([camera] file = ...)."
        ),
    )
    c.add_argument("images", nargs="+", metavar="IMAGE", help="chessboard photos (files, directories of images or "
                   "quoted patterns), or videos of the board")
    c.add_argument("--board", required=True, metavar="COLSxROWS", help="inner corners per row and per column, e.g. 9x6")
    c.add_argument("--square", required=True, type=float, metavar="S",
                   help="side of one square, in world units (e.g. mm). It does not change the camera: any "
                   "positive value gives the same intrinsics (they have no length); it only scales the views' "
                   "board poses (the recording)")
    c.add_argument("--video-views", type=int, default=None, metavar="N",
                   help="from each video, at most N distinct views (default 20)")
    c.add_argument("--model", choices=("zhang", "tsai"), default="zhang",
                   help="calibration method and camera model (default: zhang)")
    c.add_argument("--out", "-o", default="camera.toml", metavar="FILE",
                   help="camera file to write (default: camera.toml)")
    c.add_argument(
        "--pixel-pitch",
        metavar="DX[,DY]",
        help="tsai: the sensor's pixel pitch in mm (e.g. 0.0028, or 0.0028,0.0028); Tsai's method needs it a priori",
    )
    c.add_argument("--sx", type=float, default=1.0, help="tsai: horizontal scale factor a priori (default 1)")
    c.add_argument(
        "--full",
        action="store_true",
        help="tsai: also optimise the image centre (Cx, Cy) (and sx with several views), from the two-stage result",
    )
    c.add_argument("--fix-k3", action="store_true", help="zhang: hold k3 at 0 (advisable for narrow fields of view)")
    add_recording_arguments(c, what="a recording of the views with the reprojected board",
                            default="beside --out, .rrd", view=False, frame_stride=False)
    c.add_argument("--force", action="store_true",
                   help="write the camera file even when the calibration is degenerate (a lens model that "
                        "cannot be inverted over the image, or reprojection RMS over 5 px)")
    c.add_argument(
        "--reject",
        type=float,
        default=3.0,
        metavar="FACTOR",
        help="zhang: reject views whose RMS exceeds FACTOR x the median (and 0.5 px); default 3",
    )
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=run)

    pts = sub.add_parser(
        "points",
        help="world ↔ pixel correspondences (one view) → camera file, by Tsai's method",
        description=(
            "Calibrate one view by Tsai's two-stage method from measured correspondences: a text file "
            "with one point per line, 'xw yw zw Xf Yf' (world units, then pixels; '#' comments). "
            "Coplanar or not according to the points."
        ),
    )
    pts.add_argument("points", type=Path, metavar="FILE", help="correspondences, 'xw yw zw Xf Yf' per line")
    pts.add_argument("--size", required=True, metavar="WxH", help="image size in pixels, e.g. 1280x960")
    pts.add_argument("--pixel-pitch", required=True, metavar="DX[,DY]", help="the sensor's pixel pitch in mm")
    pts.add_argument("--sx", type=float, default=1.0,
                     help="horizontal scale factor a priori for a planar target (default 1)")
    pts.add_argument("--full", action="store_true",
                     help="also optimise every parameter (Cx, Cy included) from the two-stage result")
    pts.add_argument("--out", "-o", default="camera.toml", metavar="FILE",
                     help="camera file to write (default: camera.toml)")
    pts.set_defaults(func=run_points)

    focal = sub.add_parser(
        "focal",
        help="a field log's marked planes → its camera file with the focal length that fits them",
        description=(
            "When the marks on the reference planes fit their plane coordinates far better at another focal "
            "length than the camera file's (a zoom, a refocus, another crop since the calibration; gnomon "
            "regions, preview and scan say so), fit that focal length to the marks of all the field log's "
            "marked planes (or --planes), holding the principal point, aspect and distortion, print the "
            "evidence per plane and write a camera file with it, for [camera] file = ... ."
        ),
    )
    focal.add_argument("field_log", type=Path, metavar="FIELD_LOG",
                       help="field log with a camera and marked planes")
    focal.add_argument("--planes", metavar="NAMES", help="comma-separated planes to fit (default: every marked plane)")
    focal.add_argument("--out", "-o", required=True, type=Path, metavar="FILE", help="camera file to write")
    focal.set_defaults(func=run_focal)

    lamp = sub.add_parser(
        "lamp",
        help="pencil photos → lamp position ± uncertainty",
        description="Locate the lamp from 2+ photos of a standing pencil and its shadow (described in the field log).",
    )
    lamp.add_argument("field_log", type=Path, metavar="FIELD_LOG", help="field log describing the pencil photos")
    lamp.add_argument("--force", action="store_true",
                      help="write lamp.toml even when the estimate is degenerate (the pencils' shadow lines "
                           "nearly parallel or collinear)")
    lamp.set_defaults(func=run_lamp)


def _pitch(text: str) -> tuple[float, float]:
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise GnomonError(f"--pixel-pitch '{text}': expected DX or DX,DY in mm") from None
    if len(vals) == 1:
        vals = vals * 2
    if len(vals) != 2 or not all(math.isfinite(v) and v > 0 for v in vals):
        raise GnomonError(f"--pixel-pitch '{text}': expected one or two positive numbers (mm)")
    return vals[0], vals[1]


def _degenerate_camera(cal) -> str | None:
    """Why a calibration result must not replace a camera file without --force, or None."""
    from gnomon.util import validate

    if not math.isfinite(cal.rms_px) or cal.rms_px > 5.0:
        return f"reprojection RMS {cal.rms_px:.3g} px"
    try:
        validate.check_camera(cal.camera, "calibrated camera")
    except GnomonError as exc:
        return str(exc).removeprefix("calibrated camera: ")
    return None


def _fmt(v: float, s: float | None) -> str:
    return f"{v:.6g}" if s is None else f"{v:.6g} ± {s:.2g}"


def _open_recording(path: Path):
    """The calibration's recording, opened on its own thread (:class:`~gnomon.recording.worker.RecordingWorker`:
    rerun's import and the viewer's layout, ≈ 1 s of CPU, while the boards are found)."""
    from gnomon.recording.recorder import ScanRecording
    from gnomon.recording.worker import RecordingWorker

    return RecordingWorker(lambda: ScanRecording(path, recording_name="calibrate camera", frame_stride=1,
                                                 image_scale=1.0))


def _log_calibration(cal, rec) -> None:
    """Log the calibration into the recording ``rec``: every used view, the board reprojected with the
    calibrated camera and that view's pose, the per-view RMS, and the warnings."""
    import numpy as np

    from gnomon.camera import calibration
    from gnomon.camera.models import Pose

    cam = cal.camera
    board = calibration.board_points(cal.board[0], cal.board[1], cal.square)
    rec.log_camera(cam.K, cam.width, cam.height, np.eye(3), np.zeros(3), "board units")
    for i, (name, pose, rms) in enumerate(zip(cal.names, cal.poses, cal.per_view_rms_px, strict=True)):
        image = cal.photos.get(name, cal.video_frames.get(name))
        rec.log_frame(i, image if image is not None else calibration.read_grey(name))
        rec.log_image_points(i, cam.project(Pose(pose.R, pose.t).world_to_camera(board)), name="board")
        rec.log_metrics({"view_rms_px": float(rms)}, index=i)
    for w in [f"method: {cal.method}", *cal.warnings]:
        rec.log_warning(w)
    rec.log_metrics({"rms_px": float(cal.rms_px), "views": float(cal.n_views)})


def run(args: argparse.Namespace) -> int:
    from gnomon.camera import calibration
    from gnomon.util import validate
    from gnomon.util.progress import Progress

    try:
        board = calibration.parse_board(args.board)
    except GnomonError as exc:
        raise GnomonError(f"--board {exc}") from None
    if min(board) < validate.MIN_CHESSBOARD:
        raise GnomonError(f"--board {args.board}: a chessboard needs at least "
                          f"{validate.MIN_CHESSBOARD}x{validate.MIN_CHESSBOARD} inner corners")
    validate.number(args.square, "--square")  # finite; the sign is calibrate_images' to check
    validate.number(args.reject, "--reject", minimum=1.0)
    validate.number(args.sx, "--sx", positive=True)
    validate.check_output_file(args.out, "--out")
    if args.rrd and not args.no_rrd:
        validate.check_output_file(args.rrd, "--rrd")
    pitch = None if args.pixel_pitch is None else _pitch(args.pixel_pitch)
    if args.model == "zhang" and (pitch is not None or args.full or args.sx != 1.0):
        raise GnomonError("--pixel-pitch, --sx and --full apply to --model tsai only")
    video_views = calibration.VIDEO_VIEWS if args.video_views is None else args.video_views
    if video_views < calibration.MIN_ZHANG_VIEWS:
        raise GnomonError(f"--video-views {video_views}: must be ≥ {calibration.MIN_ZHANG_VIEWS}")
    paths = calibration.expand_image_args(args.images)
    # the recording is opened (rerun's import and layout) on its own thread while the boards are found
    recording = None if args.no_rrd else _open_recording(Path(args.rrd) if args.rrd
                                                          else Path(args.out).with_suffix(".rrd"))
    try:
        with Progress("boards", len(paths), enabled=not args.quiet) as bar:

            def progress(done: int, total: int, name: str) -> None:
                bar.total = total  # an image counts one, a video its frames (known once the videos are opened)
                bar.update(done)

            cal = calibration.calibrate_images(
                paths,
                board,
                args.square,
                model=args.model,
                pixel_pitch_mm=pitch,
                sx=args.sx,
                full=args.full,
                fix_k3=args.fix_k3,
                reject_factor=args.reject,
                progress=progress,
                max_video_views=video_views,
                keep_photos=not args.no_rrd,
            )
    except BaseException:
        if recording is not None:
            recording.abort()  # no recording of a calibration that did not happen
        raise
    for w in cal.warnings:
        print(f"gnomon: warning: {w}", file=sys.stderr)
    if recording is not None:
        recording.submit(partial(_log_calibration, cal))
        recording.finish()

    print(f"{'view':40s} {'RMS px':>8s}  status")
    rms = dict(zip(cal.names, cal.per_view_rms_px, strict=True))
    rejected = dict(cal.rejected)
    for note in cal.video_notes:
        print(note)
    of_video: dict[str, list[str]] = {}  # a video → its picked views, in frame order
    for name in cal.video_frames:
        of_video.setdefault(name.rsplit("#", 1)[0], []).append(name)
    for key in (v for p in paths for v in of_video.get(str(p), [str(p)])):
        if key in rms:
            extra = ""
            if cal.per_view_tsai:
                r = cal.per_view_tsai[cal.names.index(key)]
                extra = f"  (own Tsai: f {r.camera.f_mm:.5g} mm, kappa1 {r.camera.kappa1:.4g}, RMS {r.rms_px:.3f} px)"
            print(f"{Path(key).name:40s} {rms[key]:8.3f}  used{extra}")
        elif key in rejected:
            print(f"{Path(key).name:40s} {rejected[key]:8.3f}  rejected (see the warning)")
        else:
            print(f"{Path(key).name:40s} {'-':>8s}  no board")
    cam = calibration.camera_to_table(cal.camera)
    std = cal.std
    print(f"method {cal.method}: {cal.n_views} views, reprojection RMS {cal.rms_px:.3f} px")
    for k, v in cam.items():
        if k in ("model", "width", "height"):
            continue
        if k == "dist":
            names = ("k1", "k2", "p1", "p2", "k3")
            print("  dist " + ", ".join(f"{n} {_fmt(x, std.get(n))}" for n, x in zip(names, v, strict=True)))
        else:
            print(f"  {k} {_fmt(v, std.get(k))}")
    problem = _degenerate_camera(cal)
    if problem is not None and not args.force:
        raise GnomonError(f"{args.out}: not written: the calibration is degenerate ({problem}); "
                          "check the views, or write it anyway with --force")
    calibration.write_camera_file(args.out, cal)
    print(f"wrote {args.out}")
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().replace("×", "x").split("x"))
    except ValueError:
        raise GnomonError(f"--size '{text}': expected WIDTHxHEIGHT in pixels, e.g. 1280x960") from None
    if w <= 0 or h <= 0:
        raise GnomonError(f"--size '{text}': width and height must be positive")
    return w, h


def read_points_file(path: Path):
    """``xw yw zw Xf Yf`` per line → (world (N, 3), pixels (N, 2)); a bad line is an error naming it."""
    import numpy as np

    if not path.is_file():
        raise GnomonError(f"{path}: file not found")
    rows = []
    for k, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            vals = [float(x) for x in text.replace(",", " ").split()]
        except ValueError:
            vals = []
        if len(vals) != 5 or not all(np.isfinite(vals)):
            raise GnomonError(f"{path}:{k}: expected five numbers 'xw yw zw Xf Yf', got {text!r}")
        rows.append(vals)
    if not rows:
        raise GnomonError(f"{path}: no points")
    a = np.array(rows)
    return a[:, :3], a[:, 3:]


def run_points(args: argparse.Namespace) -> int:
    from gnomon.camera import calibration, tsai
    from gnomon.util import toml_io
    width, height = _size(args.size)
    dx, dy = _pitch(args.pixel_pitch)
    if not args.sx > 0:
        raise GnomonError(f"--sx {args.sx}: the scale factor must be positive")
    world, pix = read_points_file(args.points)
    r = tsai.calibrate(world, pix, width, height, dx, dy, sx=args.sx, full=args.full, where=str(args.points))
    for w in r.warnings:
        print(f"gnomon: warning: {w}", file=sys.stderr)
    print(f"method tsai-{r.method}: {r.n_points} points, reprojection RMS {r.rms_px:.3f} px")
    for k, v in calibration.camera_to_table(r.camera).items():
        if k not in ("model", "width", "height"):
            print(f"  {k} {_fmt(v, r.std.get(k))}")
    print(f"  pose: rvec {' '.join(f'{x:.6g}' for x in r.pose.rvec)}, T {' '.join(f'{x:.6g}' for x in r.pose.t)}"
          + (f" (σTz {r.std['tz']:.2g})" if "tz" in r.std else ""))
    table = calibration.camera_to_table(r.camera)
    table["calibration"] = {
        "method": f"tsai-{r.method}",
        "rms_px": float(r.rms_px),
        "n_points": int(r.n_points),
        "points": args.points.name,
        "std": {k: float(v) for k, v in r.std.items()},
    }
    toml_io.dump(table, args.out, header=calibration._HEADER)
    print(f"wrote {args.out}")
    return 0


def run_lamp(args: argparse.Namespace) -> int:
    try:
        from gnomon.runs.calibrate_lamp import calibrate_lamp_cli
    except ModuleNotFoundError as exc:
        if exc.name not in ("gnomon.light",):
            raise
        raise GnomonError("calibrate lamp: not available in this build (gnomon.light is missing)") from None
    except ImportError:
        raise GnomonError("calibrate lamp: not available in this build "
                          "(gnomon.light has no calibrate_lamp_cli)") from None
    return int(calibrate_lamp_cli(args) or 0)


def run_focal(args: argparse.Namespace) -> int:
    from gnomon.camera.calibration import camera_to_table
    from gnomon.camera.models import OpenCVCamera
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import fit_focal, frame_source, marked_points
    from gnomon.util import toml_io

    log = load_field_log(args.field_log)
    if not isinstance(log.camera, OpenCVCamera):
        raise GnomonError(f"{args.field_log}: [camera]: calibrate focal needs an OpenCV camera (fx, fy, cx, cy)")
    planes = marked_points(log, frame_source(log))
    if args.planes:
        wanted = [n.strip() for n in args.planes.split(",") if n.strip()]
        missing = [n for n in wanted if n not in {p[0] for p in planes}]
        if missing:
            raise GnomonError(f"{args.field_log}: --planes: no marked plane named {', '.join(missing)} "
                              f"(marked: {', '.join(p[0] for p in planes) or 'none'})")
        planes = [p for p in planes if p[0] in wanted]
    if not planes:
        raise GnomonError(f"{args.field_log}: [[planes]]: no plane with markers to fit a focal length to")
    fit = fit_focal(log.camera, planes)
    for line in fit.lines():
        print(line)
    worse = [name for k, name in enumerate(fit.planes) if fit.rms_fit_px[k] > fit.rms_camera_px[k]]
    why = ""
    if worse:
        why = f"the fitted one fits {', '.join(worse)}'s marks worse than the camera's own"
    elif not math.isfinite(fit.sigma_factor):
        why = "its σ is undefined (the factor is at the end of the range searched)"
    elif abs(fit.factor - 1.0) < 2.0 * fit.sigma_factor:
        why = f"× {fit.factor:.3f} ± {fit.sigma_factor:.3f} is within 2 σ of the camera's own"
    if why:
        raise GnomonError(f"{args.out}: not written: the marks do not call for another focal length ({why}): "
                          "where they misfit, the marks are off, not the camera; measure their positions (plane_xy)")
    table = camera_to_table(log.camera)
    table["fx"], table["fy"] = log.camera.fx * fit.factor, log.camera.fy * fit.factor
    source = log.camera_file.name if log.camera_file is not None else f"{args.field_log.name} [camera]"
    header = "\n".join([f"{source} with its focal length fitted to the marks of {args.field_log.name} "
                         f"(gnomon calibrate focal, planes {', '.join(fit.planes)}):", *fit.lines()])
    toml_io.dump(table, args.out, header=header)
    print(f"wrote {args.out}")
    return 0
