"""``gnomon simulate SCENE --out DIR``: write a synthetic capture, its field log and ground truth
(a thin wrapper around :func:`gnomon.api.simulate`)."""

from __future__ import annotations

import argparse
import json
import time

from gnomon.api import SCENES
from gnomon.commands import COMMANDS


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help=COMMANDS["simulate"],
        description=(
            "Render a synthetic shadow-sweep capture with exact ground truth. "
            "desk_lamp: a desk with a sphere, a box and a cylinder, a point-like lamp left of the "
            "camera, a stick whose shadow sweeps the view, plus pencil photos for lamp calibration "
            "(DIR/pencil/, DIR/pencil_log.toml). desk_lamp_right: the same scene and pixel grid with "
            "the lamp mirrored to the right of the camera (fuse the two scans). desk_turns: one object (a box with a "
            "barrel roof, a chimney and a sphere) turned on the desk by 360/--views degrees between views, one "
            "desk_lamp capture per view in DIR/view_K/ and DIR/turns.json with every view's exact pose (for "
            "gnomon fuse). two_plane: a desk and "
            "a wall meeting in a corner, printed 2x2 checker markers on both, a lamp the field log "
            "does not give (the shadow planes come from the lines on both planes). "
            "room: the two_plane scene with a cube and a can, one bounce of interreflection, "
            "a lamp of real size for every shadow and shot + read noise (640x480, 150 PNG frames "
            "by default); its truth marks the pixels the lamp never lights directly. facade_sun: a pole's "
            "shadow swept by the sun over a facade and the street (3 h 19 min). facade_day: the same over "
            "a whole day, night at both ends, six cloud dips and a lamp post's moving shadow besides the "
            "pole's. Writes DIR/frames/, "
            "DIR/ground_truth.npz, DIR/ground_truth.json and (last) DIR/field_log.toml."),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("scene", choices=SCENES, help="which synthetic scene")
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
    p.add_argument("--roof-edge", action="store_true",
                   help="facade_sun: no pole; the roof line of the building across the street sweeps its shadow up "
                        "the facade (the field log names it in [edge]; ground_truth.npz edge_time)")
    p.add_argument("--clouds", type=int, default=None, help="facade_sun/facade_day: number of cloud dips (0-10); "
                   "default 3, facade_day 6")
    p.add_argument("--drift", type=float, default=0.0, metavar="PX",
                   help="the camera drifts by this much by the last frame (x linear, y quadratic in time; "
                        "ground_truth.npz camera_motion_px)")
    p.add_argument("--bump", type=float, default=0.0, metavar="PX",
                   help="the camera is knocked by this much 60 %% of the way")
    p.add_argument("--markers", choices=("checker", "aruco"), default="checker",
                   help="two_plane: printed 2x2 checkers (pixel hints in the field log) or ArUco markers (ids only)")
    p.add_argument("--stick", choices=("rocked", "translated"), default="rocked",
                   help="two_plane: the stick rocked as it sweeps (the lamp is a point), or only translated "
                   "parallel to itself (the shadow planes fix the lamp only along a line)")
    p.add_argument("--marks", choices=("measured", "unmeasured"), default="measured",
                   help="two_plane: the checkers' positions on their planes given in the field log, or not "
                   "(at a rectangle's corners of unknown size; no camera pose; units \"relative\")")
    p.add_argument("--marks-off-px", type=float, default=0.0, metavar="PX",
                   help="two_plane with --marks unmeasured: move each mark off the rectangle by up to this (image px)")
    p.add_argument("--mark-distance", action="store_true",
                   help="two_plane with --marks unmeasured: give the desk's first two marks' distance (mm) "
                   "instead of units \"relative\"")
    p.add_argument("--full-well", type=float, default=None, metavar="ELECTRONS",
                   help="room: electrons at full scale (shot noise; 0: none); default 1150 (3.5 DN at 220 DN)")
    p.add_argument("--read-noise", type=float, default=None, metavar="ELECTRONS",
                   help="room: read noise, electrons; default 3")
    p.add_argument("--no-bounce", action="store_true", help="room: no interreflection (direct light and ambient)")
    p.add_argument("--bounce", action="store_true",
                   help="facade_sun/facade_day: sun and sky light bounced twice between the street, the facade and "
                        "its balconies, frame by frame (the pole's shadow on the street dims the facade), instead "
                        "of a fixed ground-bounce share of the sky")
    p.add_argument("--views", type=int, default=4, help="desk_turns: how many places (2-12)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _options(args: argparse.Namespace) -> dict:
    """The scene's settings from the command line (those the scene has; unset ones keep its defaults)."""
    if args.scene == "chessboard":  # its own default size: 1280x960
        return {"seed": args.seed, **({"width": args.width} if args.width != 800 else {}),
                **({"height": args.height} if args.height != 600 else {})}
    opts = {"width": args.width, "height": args.height, "noise": args.noise, "jpeg_quality": args.jpeg_quality,
            "seed": args.seed, "distortion": not args.no_distortion, "blur": args.blur, "gamma": args.gamma,
            "drift_px": args.drift, "bump_px": args.bump}
    if args.frames is not None:
        opts["frames"] = args.frames
    if args.scene in ("facade_sun", "facade_day"):
        opts["pole_radius"] = args.pole_radius
        if args.roof_edge:
            opts["roof_edge"] = True
        if args.start is not None:
            opts["start"] = args.start
        if args.clouds is not None:
            opts["clouds"] = args.clouds
        if args.bounce:
            opts["bounce"] = True
        return opts
    opts.update(lamp_radius=args.lamp_radius, stick_radius=args.stick_radius)
    if args.scene in ("two_plane", "room"):
        opts["markers"] = args.markers
        opts["stick"] = args.stick
        opts.update(marks=args.marks, marks_off_px=args.marks_off_px, mark_distance=args.mark_distance)
    elif args.scene == "desk_turns":
        opts["views"] = args.views
    else:
        opts["pencil_photos"] = args.pencil_photos
    if args.scene == "room":
        opts = _room_options(args, opts)
    return opts


def _room_options(args: argparse.Namespace, opts: dict) -> dict:
    """The room keeps its own defaults (640x480, PNG, shot noise, a 10 mm rod) where an option was not given."""
    for key, default in (("width", 800), ("height", 600), ("noise", 1.5), ("jpeg_quality", 90),
                         ("stick_radius", 2.0)):
        if opts[key] == default:
            del opts[key]
    if args.full_well is not None:
        opts["full_well"] = args.full_well
    if args.read_noise is not None:
        opts["read_noise_e"] = args.read_noise
    opts["bounce"] = not args.no_bounce
    return opts


def run(args: argparse.Namespace) -> int:
    from gnomon import api

    # finite numbers here; their ranges are the scene configuration's to check
    from gnomon.util import validate
    for name in ("noise", "blur", "gamma", "lamp_radius", "stick_radius", "pole_radius", "marks_off_px", "drift",
                 "bump"):
        validate.number(getattr(args, name), "--" + name.replace("_", "-"))
    t0 = time.perf_counter()
    field_log = api.simulate(args.scene, args.out, progress=not args.quiet, **_options(args))
    seconds = time.perf_counter() - t0
    if args.scene == "chessboard":
        print(f"wrote 12 chessboard views (9x6 inner corners, 25 mm squares) and the true camera to {args.out} "
              f"in {seconds:.1f} s; try: gnomon calibrate camera {args.out} --board 9x6 --square 25")
        return 0
    if args.scene == "desk_turns":
        turns = json.loads((field_log / "turns.json").read_text())
        angles = ", ".join(f"{v['angle_deg']:g}" for v in turns["views"])
        print(f"wrote {len(turns['views'])} captures of the object turned by {angles} deg and "
              f"{field_log / 'turns.json'} in {seconds:.1f} s; scan each view_K/field_log.toml, then: "
              "gnomon fuse SCAN_0 SCAN_1 ... --out MODEL")
        return 0
    truth = json.loads((field_log.parent / "ground_truth.json").read_text())
    extra = ""
    if (field_log.parent / "pencil_log.toml").is_file():
        extra = f", {truth['pencil']['photos']} pencil photos and pencil_log.toml"
    units = truth.get("units", "mm")
    distance = truth["camera_distance"] if units == "m" else truth["camera_distance_mm"]
    print(f"wrote {truth['frame_count']} frames{extra}, ground truth and {field_log} "
          f"({truth['swept_fraction']:.1%} of pixels swept, camera {distance:.1f} {units} "
          f"from the scene) in {seconds:.1f} s")
    return 0
