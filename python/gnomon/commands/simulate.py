"""``gnomon simulate SCENE --out DIR``: write a synthetic capture, its field log and ground truth."""

from __future__ import annotations

import argparse
import time

from gnomon.errors import GnomonError

SCENE_CHOICES = ("desk_lamp", "desk_lamp_right", "two_plane", "facade_sun", "facade_day", "chessboard")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="write a synthetic capture + field log + ground truth",
        description=(
            "Render a synthetic shadow-sweep capture with exact ground truth. "
            "desk_lamp: a desk with a sphere, a box and a cylinder, a point-like lamp left of the "
            "camera, a stick whose shadow sweeps the view, plus pencil photos for lamp calibration "
            "(DIR/pencil/, DIR/pencil_log.toml). desk_lamp_right: the same scene and pixel grid with "
            "the lamp mirrored to the right of the camera (fuse the two scans). two_plane: a desk and "
            "a wall meeting in a corner, printed 2x2 checker markers on both, a lamp the field log "
            "does not give (the shadow planes come from the lines on both planes). facade_sun: a pole's "
            "shadow swept by the sun over a facade and the street (3 h 19 min). facade_day: the same over "
            "a whole day, night at both ends, six cloud dips and a lamp post's moving shadow besides the "
            "pole's. Writes DIR/frames/, "
            "DIR/ground_truth.npz, DIR/ground_truth.json and (last) DIR/field_log.toml."),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("scene", choices=SCENE_CHOICES, help="which synthetic scene")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--width", type=int, default=800, help="image width, px (the field of view is kept)")
    p.add_argument("--height", type=int, default=600, help="image height, px")
    p.add_argument("--frames", type=int, default=None,
                   help="number of frames (the sweep always covers the view); default 240, facade_sun 200, "
                        "facade_day 400")
    p.add_argument("--noise", type=float, default=1.5, help="sensor noise σ, DN")
    p.add_argument("--jpeg-quality", type=int, default=90, help="JPEG quality; 0 writes PNG")
    p.add_argument("--seed", type=int, default=0, help="random seed (noise, texture, hand wobble)")
    p.add_argument("--no-distortion", action="store_true", help="an ideal lens (all distortion coefficients 0)")
    p.add_argument("--blur", type=float, default=0.7, metavar="SIGMA_PX", help="optical blur σ, px")
    p.add_argument("--lamp-radius", type=float, default=3.0, metavar="MM", help="lamp radius, mm")
    p.add_argument("--stick-radius", type=float, default=2.0, metavar="MM",
                   help="stick radius, mm (the shadow is twice as wide, and more)")
    p.add_argument("--gamma", type=float, default=2.2, help="the camera's encoding gamma")
    p.add_argument("--pencil-photos", type=int, default=3, metavar="N",
                   help="desk_lamp scenes: pencil photos for `gnomon calibrate lamp` (0: none)")
    p.add_argument("--start", default=None, metavar="ISO",
                   help="facade_sun: the first frame's time, local at the site (Zurich) or with an offset "
                        "(default 2026-11-12T11:40:00; the capture lasts 3 h 19 min)")
    p.add_argument("--pole-radius", type=float, default=0.05, metavar="M", help="facade_sun: pole radius, m")
    p.add_argument("--clouds", type=int, default=None, help="facade_sun/facade_day: number of cloud dips (0-10); "
                   "default 3, facade_day 6")
    p.add_argument("--markers", choices=("checker", "aruco"), default="checker",
                   help="two_plane: printed 2x2 checkers (pixel hints in the field log) or ArUco markers (ids only)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run_chessboard(args: argparse.Namespace) -> int:
    """12 views of a 9x6 chessboard (25 mm squares) with a known camera, for `gnomon calibrate camera`."""
    from gnomon.simulate.chessboard import default_truth_camera, write_chessboard_views

    width = args.width if args.width != 800 else 1280
    height = args.height if args.height != 600 else 960
    t0 = time.perf_counter()
    write_chessboard_views(args.out, camera=default_truth_camera(width, height), cols=9, rows=6, square=25.0,
                           n_views=12, seed=args.seed)
    print(f"wrote 12 chessboard views (9x6 inner corners, 25 mm squares) and the true camera to {args.out} "
          f"in {time.perf_counter() - t0:.1f} s; try: gnomon calibrate camera {args.out} --board 9x6 --square 25")
    return 0


def run(args: argparse.Namespace) -> int:
    from gnomon import validate
    from gnomon.progress import Progress
    from gnomon.publish import check_output_folder

    check_output_folder(args.out)
    validate.number(args.seed, "--seed", minimum=0, maximum=2**32 - 1, integer=True)
    # finite numbers here; their ranges are the scene configuration's to check (config.validate)
    for name in ("noise", "blur", "gamma", "lamp_radius", "stick_radius", "pole_radius"):
        validate.number(getattr(args, name), "--" + name.replace("_", "-"))
    if args.scene == "chessboard":
        return run_chessboard(args)
    from gnomon.simulate import DeskLampConfig, TwoPlaneConfig, simulate_desk_lamp, simulate_two_plane

    if args.frames is None:
        args.frames = {"facade_sun": 200, "facade_day": 400}.get(args.scene, 240)
    common = dict(
        width=args.width, height=args.height, frames=args.frames, noise=args.noise,
        jpeg_quality=args.jpeg_quality, seed=args.seed, distortion=not args.no_distortion,
        blur=args.blur, lamp_radius=args.lamp_radius, stick_radius=args.stick_radius,
        gamma=args.gamma,
    )
    if args.scene in ("desk_lamp", "desk_lamp_right"):
        config = DeskLampConfig(**common, lamp_side="left" if args.scene == "desk_lamp" else "right",
                                pencil_photos=args.pencil_photos)
        simulate = simulate_desk_lamp
    elif args.scene == "two_plane":
        config = TwoPlaneConfig(**common, markers=args.markers)
        simulate = simulate_two_plane
    elif args.scene in ("facade_sun", "facade_day"):
        from gnomon.simulate.facade_sun import FacadeSunConfig, simulate_facade_sun

        sun = {k: v for k, v in common.items() if k not in ("lamp_radius", "stick_radius")}
        if args.start is not None:
            sun["start"] = args.start
        if args.clouds is not None:
            sun["clouds"] = args.clouds
        make = FacadeSunConfig.day if args.scene == "facade_day" else FacadeSunConfig
        config = make(**sun, pole_radius=args.pole_radius)
        simulate = simulate_facade_sun
    else:  # pragma: no cover - argparse restricts choices
        raise GnomonError(f"simulate: unknown scene {args.scene!r}")
    config.validate()
    t0 = time.perf_counter()
    with Progress("simulate", config.frames, enabled=not args.quiet) as bar:
        result = simulate(args.out, config, progress=lambda done, total: bar.update(done))
    extra = ""
    if result.pencil_log is not None:
        extra = f", {len(result.pencil_photos)} pencil photos and {result.pencil_log.name}"
    units = getattr(result, "units", "mm")
    distance = result.camera_distance if units == "m" else result.camera_distance_mm
    print(f"wrote {len(result.frames)} frames{extra}, ground truth and {result.field_log} "
          f"({result.swept_fraction:.1%} of pixels swept, camera {distance:.1f} {units} "
          f"from the scene) in {time.perf_counter() - t0:.1f} s")
    return 0
