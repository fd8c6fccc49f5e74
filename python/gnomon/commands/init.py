"""`gnomon init FRAMES... [--camera FILE] [--light KIND]`: a commented field-log template for a capture.

Reads the first frame for its size, writes ``field_log.toml`` beside the
frames (or ``--out``) with the capture's frames glob (or video), the camera
(the file given, or inline keys to fill in), the reference planes, the light
and the scan settings, each with a comment saying what it means. The set-up
(``--light``) decides the rest:

* ``two-plane`` (the default): a desk and a wall, each with markers to fill
  in; no light to measure.
* ``lamp``: one desk, placed by a chessboard lying on it (``--board``,
  ``--square``, ``--board-image``) or by markers; a ``[pencil]`` table listing
  the pencil photos (``--pencil``) whose base and shadow tip are to be filled
  in for ``gnomon calibrate lamp``, and a light read from the ``lamp.toml``
  that command writes.
* ``sun``: the ground and a facade with markers, a ``[site]`` to fill in (its
  latitude, longitude and heading are NaN until then, so the log does not
  load unfilled), illumination normalised, and the frames' times: EXIF when
  the first frame has them, else the file names' pattern when every name
  parses with it, else a start and frame rate to fill in.
"""

from __future__ import annotations

import argparse
import os
import re
from collections import Counter
from pathlib import Path

from gnomon.capture.frames import VIDEO_SUFFIXES
from gnomon.commands import COMMANDS

LIGHTS = ("two-plane", "lamp", "sun")

HEADER = '''\
# Gnomon field log for a {setup}, written by `gnomon init` (format: field_logs/README.md).
{steps}
# Paths are relative to this file. Lengths in [capture] units; pixels with the
# top-left pixel's centre at (0, 0).

'''

STEPS = {
    "two-plane": "# Next: fill in the markers below, check with `gnomon preview {name}`,\n"
                 "# propose the regions with `gnomon regions {name}` (from the markers, or grown from rough\n"
                 "# rectangles of bare desk and wall given as regions), then `gnomon scan {name}`.",
    "two-plane-found": "# Next: check the marks found (drawn in {drawing}) with `gnomon preview {name}`,\n"
                       "# propose the regions with `gnomon regions {name}` (it switches on each plane's mask\n"
                       "# below), then `gnomon scan {name}`.",
    "lamp": "# Next: fill in the desk's board (or markers) and the pencil's length (each photo's base and tip\n"
            "# are found; give them where `gnomon calibrate lamp` asks), "
            "locate the lamp with\n# `gnomon calibrate lamp {name}` (it writes lamp.toml, lamp_tips.png), check with\n"
            "# `gnomon preview {name}`, propose the bare desk with `gnomon regions {name}` (from two bands\n"
            "# of the image's top and bottom rows, or the regions you give), then `gnomon scan {name}`.",
    "sun": "# Next: fill in [site] (every NaN), the frames' times if asked below and the markers,\n"
           "# check with `gnomon preview {name}`, propose the regions with `gnomon regions {name}`,\n"
           "# then `gnomon scan {name}`.",
}

CAPTURE = '''\
[capture]
frames = "{frames}"  # {count} {what}, {width}x{height}
units = "{units}"
gamma = "srgb"  # how the camera encoded intensity: "srgb", a decoding exponent (2.2), or 1.0 for linear data
'''

INLINE_CAMERA = '''\
# No camera file given: calibrate with `gnomon calibrate camera IMAGES... --board COLSxROWS --square S`
# and write file = "camera.toml" instead, or fill in the intrinsics (pixels):
model = "opencv"
width = {width}
height = {height}
fx = {f}  # a guess (a 50 degree horizontal field of view): replace
fy = {f}
cx = {cx}
cy = {cy}
dist = [0.0, 0.0, 0.0, 0.0, 0.0]  # k1, k2, p1, p2, k3
'''

MARKERS_HOWTO = '''\
# Give at least 4 markers: their centres in this frame (plane_xy, in {units}) and, in the first frame,
# pixel_hint = [u, v] for a printed 2x2 checker (found within 30 px and refined), or
# pixel = [u, v] for the exact pixel of any other mark (a clicked cross).
'''

PLANE_HEAD = '''\
[[planes]]
# {what}
{howto}name = "{name}"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
x_axis = [1.0, 0.0, 0.0]
'''

MARKED_PLANE = PLANE_HEAD + '''\
markers = [
  # {{ id = {first_id}, plane_xy = [0.0, 0.0], pixel_hint = [u, v] }},
]
{regions}
'''

FOUND_MARKERS_HOWTO = '''\
# Its marks: printed 2x2 checkers found in the first frame by `gnomon init` (drawn in {drawing}), taken
# as a rectangle's corners of unknown size (field_logs/README.md, "Marks nobody measured"). Measured
# positions, if you have them, go in as plane_xy = [x, y] on every mark.
'''

FOUND_PLANE = PLANE_HEAD + '''\
# off_rectangle_px = {off}  # how far (px, 1 sigma) the marks may lie off a true rectangle (the default): 0.5-1
                          # placed with a ruler and a square, 3-5 by eye
{distance}markers = [
{marks}
]
{regions}
'''

REGIONS_MASK = '''\
# regions: where only this plane is seen, bare and swept; `gnomon regions` writes a mask:
# mask = "regions/{name}_mask.png"
# regions = [[u0, v0, u1, v1], {{ polygon = [[u, v], [u, v], [u, v]] }}]'''

LAMP_DESK = '''\
[[planes]]
# The desk, the world frame: origin at the board's first inner corner, x along its row of corners,
# z up from the desk (towards the camera), y = z × x.
# Its pose from a chessboard lying flat on it (COLSxROWS inner corners, `square` in {units}),
# photographed from the scan's own place (`image`; by default the capture's first frame). The board
# may be taken away before the sweep; the camera may not move. Or give markers instead, as
# in a two-plane field log (field_logs/README.md).
name = "desk"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
x_axis = [1.0, 0.0, 0.0]
{board}
# regions: rough bands of bare desk that the shadow crosses (above and below the object), for
# `gnomon regions` to grow into a mask of the bare, swept desk; left empty, it starts from two bands
# of the image's top and bottom rows (5-20 % and 80-95 % of its height), as the paper does:
regions = [
  # [u0, v0, u1, v1],
]
# mask = "regions/desk_mask.png"
'''

PENCIL = '''\
[pencil]
# For `gnomon calibrate lamp`: photos (from the scan's place, the lamp where it is for the sweep)
# of a pencil standing upright on the desk, moved between photos to places spread around the
# scene. For each: its base (foot) and the tip of its shadow, in pixels. Both may be left out and
# found for you (or the tip alone, the base then a rough pixel) against `empty`, a photo of the desk
# without the pencil, or, with 3 or more photos, against their median.
height = {height}  # the pencil's length in {units}: measure it
sigma_px = 1.0  # how well the base and tip are placed, pixels
# empty = "light/empty.jpg"

{photos}
'''

LIGHT = {
    "two-plane": '''\
[light]
kind = "two-plane"  # the shadow planes from the lines on the two planes; or "lamp" with position = [x, y, z]
''',
    "lamp": '''\
[light]
kind = "lamp"
file = "lamp.toml"  # written by `gnomon calibrate lamp {name}` from the [pencil] table
''',
    "sun": '''\
[light]
kind = "sun"  # the sun's direction at each frame's time, from [site] (pvlib's NREL SPA)
''',
}

SITE = '''\
[site]
# Where the world origin is (the ground's first marker), and how the world frame is turned.
latitude = nan  # degrees north: fill in
longitude = nan  # degrees east: fill in
altitude = 0.0  # m above sea level (the geoid: EGM2008; altitude_datum = "ellipsoidal" for a GNSS height)
timezone = "UTC"  # IANA name (e.g. "Europe/Zurich") or offset, for timestamps without one
heading_deg = nan  # the heading of the world x axis (the ground markers' x), degrees clockwise from TRUE
                   # north: fill in (from a compass: add heading_north = "magnetic" and declination_deg),
                   # or delete it and measure it from a vertical pole's shadow with [gnomon] below

# [gnomon]  # the heading from a vertical pole seen in one frame (instead of heading_deg)
# frame = "frames/IMG_0001.jpg"
# base_px = [u, v]  # its foot
# shadow_px = [u, v]  # a point on its shadow's centre line on the ground
# top_px = [u, v]  # its top (informational)

# [pole]  # a fixed pole whose shadow the sun sweeps: its shadow's centre then needs no reference plane
# base = [x, y, z]  # world coordinates (m)
# top = [x, y, z]
# radius = 0.05
'''

SCAN = '''\
[scan]
# min_contrast = 20  # DN: pixels whose lit and shadowed values differ less are left out
                    # (without it: 8 σ of the image noise measured between the first frames)
edge = "both"  # triangulate the entering and the leaving shadow edge and fuse them
{extra}
# [output]  # what the written files keep (all optional)
# crop_above = "{first}"
# crop_min_height = {crop}  # the object without the {first}: points at least this high above it
# max_sigma = {sigma}  # drop the points whose predicted depth sigma exceeds this: fewer points, fewer wrong ones
'''

# A date and a time of day in a file name's stem: 20261112T112020Z, IMG_20261112_112020,
# 2026-11-12 11-20-20, 2026-11-12T11:20:20 (groups: date separator, date-time separator,
# time separator, a UTC mark).
STAMP = re.compile(r"\d{4}(-?)\d{2}\1\d{2}([T_ ])\d{2}([-:]?)\d{2}\3\d{2}(Z?)")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "init",
        help=COMMANDS["init"],
        description="Write a field log for the given frames (image files, or one video) with every "
        "section commented: the frames glob, the camera (--camera FILE, or inline keys to fill in), the "
        "reference planes and the light of the set-up (--light: a desk and a wall with markers and no light "
        "to measure; a desk lamp located from pencil photos; or the sun from the site and the frames' "
        "times), and the scan settings.",
    )
    p.add_argument("frames", nargs="+", type=Path, help="the frames: image files, their folder, or a quoted "
                   "pattern such as \"frames/*.jpg\" (in natural order: frame_2 before frame_10), or one video")
    p.add_argument("--camera", type=Path, default=None, help="a camera file from `gnomon calibrate camera`")
    p.add_argument("--light", choices=LIGHTS, default="two-plane",
                   help="the set-up: two planes and no light to measure (default), a desk lamp, or the sun")
    p.add_argument("--pencil", nargs="+", default=None, metavar="PHOTO",
                   help="lamp: the pencil photos (files or a quoted pattern), listed in [pencil]")
    p.add_argument("--board", default=None, metavar="COLSxROWS",
                   help="lamp: the chessboard lying on the desk, inner corners (e.g. 9x6)")
    p.add_argument("--square", type=float, default=None,
                   help="lamp: the board's square, measured, in the field log's units. It matters: the board "
                   "places the desk, the pencil's length places the lamp, and the two must share one scale (a "
                   "wrong square moves the desk against the lamp, which no rescaling of the result undoes)")
    p.add_argument("--board-image", type=Path, default=None, metavar="PHOTO",
                   help="lamp: the photo of the board on the desk (default: the capture's first frame)")
    p.add_argument("--out", type=Path, default=None, help="field log to write (default: field_log.toml "
                   "beside the frames' folder)")
    p.add_argument("--force", action="store_true", help="overwrite an existing field log")
    p.set_defaults(func=run)


def _regions_lines(name: str, regions_help: bool) -> str:
    """A plane table's commented mask line (``regions_help``: with the regions' keys explained)."""
    return REGIONS_MASK.format(name=name) if regions_help else f'# mask = "regions/{name}_mask.png"'


def _marked_plane(name: str, what: str, howto: str, first_id: int, regions_help: bool) -> str:
    """A [[planes]] table with markers to fill in (``regions_help``: with the regions' keys explained)."""
    regions = _regions_lines(name, regions_help)
    return MARKED_PLANE.format(what=f"The {name}. {what}", howto=howto, name=name, first_id=first_id,
                               regions=regions)


def _relative(path: Path, base: str) -> str:
    return Path(os.path.relpath(os.path.abspath(path), base)).as_posix()


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def filename_time_pattern(stems: list[str]) -> str | None:
    """A ``strftime`` pattern every stem parses with (the first stem's date and time, its other
    characters literal), or None. A literal Z after the time marks UTC."""
    import datetime as dt

    if not stems:
        return None
    m = STAMP.search(stems[0])
    if m is None:
        return None
    ds, dts, ts, z = m.groups()
    literal = lambda s: s.replace("%", "%%")  # noqa: E731
    pattern = (literal(stems[0][:m.start()]) + f"%Y{ds}%m{ds}%d{dts}%H{ts}%M{ts}%S{z}"
               + literal(stems[0][m.end():]))
    try:
        for stem in stems:
            dt.datetime.strptime(stem, pattern)
    except ValueError:
        return None
    return pattern


def _sun_times(files: list[Path], video: bool, fps: float | None) -> str:
    """The [capture] lines saying where each frame's time comes from."""
    if not video:
        from gnomon.errors import GnomonError
        from gnomon.light.timestamps import frame_times

        try:
            frame_times(files[:1], "exif", site_tz="UTC")
            return 'timestamps = "exif"  # each photo\'s EXIF DateTimeOriginal (and its offset, if written)\n'
        except GnomonError:
            pass
        pattern = filename_time_pattern([f.stem for f in files])
        if pattern is not None:
            utc = "a UTC time" if pattern.endswith("Z") else "local time in [site] timezone"
            return (f'timestamps = "filename"  # each frame\'s time from its name ({utc})\n'
                    f"time_pattern = {_toml_string(pattern)}\n")
    rate = f"{fps:g}" if fps else "nan"
    return ('timestamps = "start+fps"  # frame 0\'s time and the frame rate'
            + ("" if video else " (no EXIF time, no time in the file names)") + "\n"
            + 'start = ""  # frame 0\'s time, ISO 8601 (e.g. "2026-06-21T09:00:00+02:00"): fill in\n'
            + f"fps = {rate}  # frames per second of capture time"
            + (" (the video's playback rate: for a time-lapse, one over the interval between shots)"
               if video else ": fill in") + "\n")


def _folder_frames(folder: Path) -> tuple[Path, ...]:
    """A folder given as the frames: its image files (any case of their suffix), or the one video in it;
    a one-line error naming it when it holds neither."""
    from gnomon.camera.calibration import IMAGE_SUFFIXES
    from gnomon.errors import GnomonError

    entries = [p for p in folder.iterdir() if p.is_file()]
    images = tuple(p for p in entries if p.suffix.lower() in IMAGE_SUFFIXES)
    videos = tuple(p for p in entries if p.suffix.lower() in VIDEO_SUFFIXES)
    if images:
        return images
    if len(videos) == 1:
        return videos
    raise GnomonError(f"{folder}: " + (f"{len(videos)} videos and no images: give one video" if videos else
                                       f"the folder holds no frames (images: {', '.join(IMAGE_SUFFIXES)}; or "
                                       "one video)"))


def corrupt_frames(files: list[Path]) -> list[tuple[Path, str]]:
    """The frame files whose image data is corrupt inside (decoded as a scan decodes them), with the
    decoder's words; a file that cannot be read at all is an error naming it."""
    from gnomon.capture.frames import decode_frame_file
    from gnomon.errors import CorruptFrameError

    bad = []
    for f in files:
        try:
            decode_frame_file(f)
        except CorruptFrameError as exc:
            bad.append((f, str(exc).split(": ", 1)[-1]))
    return bad


def _mark_pixel(mark) -> str:
    """``key = [u, v]`` of a found mark, with its kind's key and decimals (plane_pose.MARK_KINDS)."""
    from gnomon.camera.plane_pose import MARK_KINDS

    kind = MARK_KINDS[mark.kind]
    return f"{kind.key} = [{mark.pixel[0]:.{kind.digits}f}, {mark.pixel[1]:.{kind.digits}f}]"


def _found_plane(name: str, what: str, marks, first_id: int, drawing: str, regions_help: bool,
                 units_line: bool) -> str:
    """A [[planes]] table whose markers were found in the first frame (pixels as found, no plane_xy)."""
    regions = _regions_lines(name, regions_help)
    lines = ",\n".join(f"  {{ id = {first_id + i}, {_mark_pixel(m)} }}" for i, m in enumerate(marks))
    distance = (f"# mark_distance = {{ between = [{first_id}, {first_id + 1}], length = L }}  # one measured "
                "spacing sets the lengths (then [capture] units = \"mm\")\n") if units_line else ""
    return FOUND_PLANE.format(what=f"The {name}. {what}", howto=FOUND_MARKERS_HOWTO.format(drawing=drawing),
                              name=name, off="1.0", distance=distance, marks=lines, regions=regions)


def draw_found_marks(image, groups, names: tuple[str, str], path: Path) -> None:
    """The first frame with each found mark circled and labelled with its plane and id (a PNG)."""
    import cv2
    import numpy as np

    from gnomon.capture.frames import grey_8bit_scale

    img = cv2.cvtColor(np.clip(grey_8bit_scale(image), 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    size = max(img.shape[:2]) / 800.0
    for (marks, name, colour, first) in ((groups.lower, names[0], (0, 200, 0), 0),
                                         (groups.upper, names[1], (0, 140, 255), len(groups.lower))):
        for i, m in enumerate(marks):
            c = (int(round(m.pixel[0])), int(round(m.pixel[1])))
            cv2.circle(img, c, int(12 * size), colour, max(1, int(2 * size)), cv2.LINE_AA)
            cv2.putText(img, f"{name} {first + i}", (c[0] + int(14 * size), c[1] - int(8 * size)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.5 * size, colour, max(1, int(size)), cv2.LINE_AA)
    from gnomon.util import atomic

    ok, buf = cv2.imencode(".png", img)
    if ok:
        atomic.write_bytes(path, buf.tobytes())


def run(args: argparse.Namespace) -> int:
    from gnomon.capture.frames import FrameSource, expand_glob_argument, natural_key, video_fps
    from gnomon.errors import GnomonError
    from gnomon.util import atomic
    from gnomon.util.validate import check_output_file, input_file

    files = sorted((f for a in args.frames for f in (_folder_frames(a) if Path(a).is_dir()
                                                      else expand_glob_argument(a, "frame") or (a,))), key=natural_key)
    for f in files:
        input_file(f, "frame")
    if args.light != "lamp":
        for flag, value in (("--pencil", args.pencil), ("--board", args.board), ("--square", args.square),
                            ("--board-image", args.board_image)):
            if value is not None:
                raise GnomonError(f"{flag}: only with --light lamp")
    pencils: list[Path] = []
    for a in args.pencil or ():
        pencils += sorted(expand_glob_argument(Path(a), "pencil photo") or (Path(a),), key=natural_key)
    for f in pencils:
        input_file(f, "pencil photo")
    if args.board_image is not None:
        input_file(args.board_image, "--board-image")
    if args.board is not None and not re.fullmatch(r"\d+x\d+", args.board):
        raise GnomonError(f"--board: {args.board!r} is not COLSxROWS (inner corners, e.g. 9x6)")
    if args.square is not None and not args.square > 0:
        raise GnomonError(f"--square: must be > 0, got {args.square:g}")
    if args.out is not None:
        check_output_file(args.out, "--out")
    video = len(files) == 1 and files[0].suffix.lower() in VIDEO_SUFFIXES
    if not video and len(files) < 2:
        raise GnomonError(f"{files[0]}: one image is not a sequence; give every frame (or a video)")
    folder = files[0].parent
    out = args.out if args.out is not None else (folder.parent if not video else folder) / "field_log.toml"
    if out.exists() and not args.force:
        raise GnomonError(f"{out}: exists; use --force to overwrite it")
    source = FrameSource((), files[0], None) if video else FrameSource(tuple(files), None, None)
    first = source.first()
    height, width = first.grey.shape[:2]
    base = os.path.abspath(out.parent)
    if video:
        frames, what = _relative(files[0], base), "video"
        count = str(source.count) if source.count else "a"
    else:
        if len({f.parent.resolve() for f in files}) != 1:
            raise GnomonError(f"{files[0]}: the frames must be in one folder")
        # the frames glob matches a suffix in any case: written as most of the files spell it
        spellings = Counter(f.suffix for f in files)
        one = len({s.lower() for s in spellings}) == 1
        suffix = max(spellings, key=lambda s: (spellings[s], s)) if one else ".*"
        frames, count, what = f"{_relative(folder, base)}/*{suffix}", str(len(files)), "frames"
    if args.camera is not None:
        if not args.camera.is_file():
            raise GnomonError(f"{args.camera}: camera file not found")
        from gnomon.camera.calibration import load_camera_file, other_aspect

        camera = f'file = "{_relative(args.camera, base)}"  # from `gnomon calibrate camera`\n'
        cal = load_camera_file(args.camera)
        if other_aspect((cal.width, cal.height), (width, height)):
            note = (f"the camera was calibrated at {cal.width}x{cal.height} (aspect {cal.width / cal.height:.3f}), "
                    f"the {what} are {width}x{height} ({width / height:.3f})")
            camera += (f"# {note}: taken as the sensor's centred crop (a phone's video against its photos).\n"
                       "# Check the marks' fit with `gnomon preview`; if they are another crop, calibrate from "
                       "frames of the capture.\ncrop = \"centre\"\n")
            print(f"note: {note}; the field log takes them as its centred crop (crop = \"centre\")")
    else:
        import math

        f = round(0.5 * width / math.tan(math.radians(25.0)), 1)
        camera = INLINE_CAMERA.format(width=width, height=height, f=f, cx=(width - 1) / 2, cy=(height - 1) / 2)

    light, name = args.light, out.name
    units = "m" if light == "sun" else "mm"
    capture = CAPTURE.format(frames=frames, count=count, what=what, width=width, height=height, units=units)
    corrupt = [] if video else corrupt_frames(files)
    if corrupt:
        listed = "; ".join(f"{p.name}: {why}" for p, why in corrupt[:5]) + ("; ..." if len(corrupt) > 5 else "")
        capture += (f'on_corrupt_frame = "drop"  # {len(corrupt)} corrupt frame(s) left out (the scan names them): '
                    f"{listed}\n# replace them from the camera's card or a backup and delete this line to use them\n")
        print(f"warning: {len(corrupt)} of the {len(files)} frames are corrupt ({listed}): the field log leaves "
              "them out (on_corrupt_frame = \"drop\"); replace them from the camera's card or a backup to use them")
    if light == "sun":
        fps = video_fps(files[0]) if video else None  # a rate of 10^4 or more is a container's time base
        capture += _sun_times(files, video, fps if fps is not None and fps < 1e4 else None)
    howto = MARKERS_HOWTO.format(units=units)
    found_note, found = "", None  # found: the marks init assigned to the desk and the wall, if any
    if light == "two-plane":
        from gnomon.camera.plane_pose import MARK_KINDS, search_crosses, search_markers, split_marks

        groups = split_marks(search_markers(first.grey))
        if not groups.lower and len(groups.found) < 4:  # no printed checkers: hand-drawn crosses, then
            crosses = split_marks(search_crosses(first.grey))
            if crosses.lower or len(crosses.found) > len(groups.found):
                groups = crosses
        if groups.lower:
            found = groups
            drawing = out.with_name(out.stem + "_marks.png")
            draw_found_marks(first.grey, groups, ("desk", "wall"), drawing)
            units = "relative"
            capture = capture.replace('units = "mm"', 'units = "relative"  # the unit is the desk\'s distance '
                                      'from the camera; or "mm" with a mark_distance')
            planes = [_found_plane("desk", "Its marks' rectangle is the world frame: origin at its centre, z up "
                                   "from the desk, x along its side nearer the image's rows.",
                                   groups.lower, 0, drawing.name, True, True),
                      _found_plane("wall", "Placed by its own marks, its distance from where it meets the desk.",
                                   groups.upper, len(groups.lower), drawing.name, False, False)]
            found_note = (f"; found {len(groups.lower)} marks on the desk and {len(groups.upper)} on the wall "
                          f"(drawn in {drawing.name})")
            if not groups.complete:
                short = "desk" if len(groups.lower) < 4 else "wall"
                found_note += (f"; the {short}'s fourth mark is not a clean {MARK_KINDS[groups.lower[0].kind].singular}"
                               " (or hidden): add it to its markers, pixel = [u, v]")
        else:
            found_note = f"; {groups.why}: give the markers' pixels by hand"
            if groups.found:
                plural = MARK_KINDS[groups.found[0].kind].plural
                found_note += f" (the {plural} found are listed in the desk's table)"
                howto += (f"# {plural[0].upper() + plural[1:]} found in the first frame (copy each into its plane's "
                          "markers):\n" + "".join(f"#   {_mark_pixel(m)}\n" for m in groups.found))
    if light in ("two-plane", "sun"):
        if found is None:
            named = ("desk", "wall") if light == "two-plane" else ("ground", "facade")
            where = ("origin `point`, axes `x_axis` and normal x x_axis" if light == "two-plane"
                     else "z up; its x axis is [site] heading_deg")
            planes = [_marked_plane(named[0], f"Its markers' frame is the world frame ({where}).", howto, 0, True),
                      _marked_plane(named[1], "In its own frame (placed in the world by its own markers: no pose "
                                    "to type).", "", 4, False)]
    else:
        if args.board is not None or args.square is not None or args.board_image is not None:
            # a "COLSxROWS" left in the log is refused by name, a NaN square too: both stop the calibration
            cols_rows = _toml_string(args.board) if args.board else '"COLSxROWS"'
            board = (f"chessboard = {cols_rows}  # inner corners" + ("" if args.board else ": fill in") + "\n"
                     + (f"square = {args.square:g}\n" if args.square is not None
                        else f"square = nan  # its side, in {units}: fill in\n")
                     + (f"image = {_toml_string(_relative(args.board_image, base))}\n" if args.board_image
                        else "# image = \"calib/board_on_desk.jpg\"  # the board's photo, if not the first frame\n"))
        else:
            board = ('# chessboard = "9x6"  # inner corners (COLSxROWS)\n# square = 25.0\n'
                     '# image = "calib/board_on_desk.jpg"\n')
        planes = [LAMP_DESK.format(units=units, board=board.rstrip("\n"))]
        if pencils:
            photos = "\n".join(f"[[pencil.photos]]\nimage = {_toml_string(_relative(p, base))}\n"
                               "# base = [u, v]  # the pencil's foot: found if left out\n"
                               "# tip = [u, v]  # its shadow's tip: found if left out\n"
                               for p in pencils)
        else:
            photos = ('# [[pencil.photos]]  # one table per photo (at least 2; list them with --pencil)\n'
                      '# image = "light/pencil_1.jpg"\n# base = [u, v]\n# tip = [u, v]\n')
        planes.append(PENCIL.format(height="nan", units=units, photos=photos.rstrip("\n")))
    extra = "normalize_illumination = true  # divide out the sun's and the sky's drift and skip clouded frames\n" \
        if light == "sun" else ""
    first_plane = {"two-plane": "desk", "lamp": "desk", "sun": "ground"}[light]
    scan = SCAN.format(extra=extra, first=first_plane, crop="0.05" if units == "m" else "2.0",
                       sigma="0.02" if units == "m" else "1.5")
    setup = {"two-plane": "two-plane capture", "lamp": "desk-lamp capture", "sun": "sun capture"}[light]
    sections = [capture, "[camera]\n" + camera, *planes, *([SITE] if light == "sun" else []),
                LIGHT[light].format(name=name), scan]
    steps = (STEPS["two-plane-found"].format(name=name, drawing=out.stem + "_marks.png")
             if found is not None else STEPS[light].format(name=name))
    text = HEADER.format(setup=setup, steps=steps) + "\n".join(sections)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_text(out, text)
    todo = {"two-plane": "check the marks" if found is not None and found.complete else "fill in the markers",
            "lamp": "fill in the pencil's length" + ("" if args.board and args.square is not None else " and the board")
                    + ("" if pencils else " and list the pencil photos"),
            "sun": "fill in [site] and the markers"}[light]
    print(f"wrote {out}: {count} {what} of {width}x{height}{found_note}; {todo}, then "
          + (f"`gnomon calibrate lamp {out}`" if light == "lamp" else f"`gnomon preview {out}`"))
    return 0
