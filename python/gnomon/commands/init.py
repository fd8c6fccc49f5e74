"""`gnomon init FRAMES... [--camera FILE]`: a commented field-log template for a capture.

Reads the first frame for its size, writes ``field_log.toml`` beside the
frames (or ``--out``) with the capture's frames glob (or video), the camera
(the file given, or inline keys to fill in), two reference planes (desk and
wall) with marker tables to fill in, a two-plane light and the scan
settings, each with a comment saying what it means. Then: fill in the
markers, check with ``gnomon preview``, propose the regions with
``gnomon regions``, and scan.
"""

from __future__ import annotations

import argparse
import os
from collections import Counter
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.fieldlog import VIDEO_SUFFIXES

TEMPLATE = '''\
# Gnomon field log, written by `gnomon init` (format: field_logs/README.md).
# Next: fill in the markers below, check with `gnomon preview {name}`,
# propose the regions with `gnomon regions {name}`, then `gnomon scan {name}`.
# Paths are relative to this file. Lengths in [capture] units; pixels with the
# top-left pixel's centre at (0, 0).

[capture]
frames = "{frames}"  # {count} {what}, {width}x{height}
units = "mm"
gamma = "srgb"  # how the camera encoded intensity: "srgb", a decoding exponent (2.2), or 1.0 for linear data

[camera]
{camera}
[[planes]]
# The desk. Its markers' frame is the world frame: origin `point`, axes `x_axis` and normal x x_axis.
# Give at least 4 markers: their centres in this frame (plane_xy, in mm) and, in the first frame,
# pixel_hint = [u, v] for a printed 2x2 checker (found within 30 px and refined), or
# pixel = [u, v] for the exact pixel of any other mark (a clicked cross).
name = "desk"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
x_axis = [1.0, 0.0, 0.0]
markers = [
  # {{ id = 0, plane_xy = [0.0, 0.0], pixel_hint = [u, v] }},
]
# regions: where only this plane is seen, bare and swept; `gnomon regions` writes a mask:
# mask = "regions/desk_mask.png"
# regions = [[u0, v0, u1, v1], {{ polygon = [[u, v], [u, v], [u, v]] }}]

[[planes]]
# The wall, in its own frame (placed in the world by its own markers: no pose to type).
name = "wall"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
x_axis = [1.0, 0.0, 0.0]
markers = [
  # {{ id = 4, plane_xy = [0.0, 0.0], pixel_hint = [u, v] }},
]
# mask = "regions/wall_mask.png"

[light]
kind = "two-plane"  # the shadow planes from the lines on the two planes; or "lamp" with position = [x, y, z]

[scan]
# min_contrast = 20  # DN: pixels whose lit and shadowed values differ less are left out
                    # (without it: 8 σ of the image noise measured between the first frames)
edge = "both"  # triangulate the entering and the leaving shadow edge and fuse them

# [output]  # what the written files keep (all optional)
# crop_above = "desk"
# crop_min_height = 2.0  # the object without the desk: points at least this high above it
# max_sigma = 1.5  # drop the points whose predicted depth sigma exceeds this: fewer points, fewer wrong ones
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


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "init",
        help=COMMANDS["init"],
        description="Write a field log for the given frames (image files, or one video) with every "
        "section commented: the frames glob, the camera (--camera FILE, or inline keys to fill in), a desk "
        "and a wall with markers to fill in, a two-plane light and the scan settings.",
    )
    p.add_argument("frames", nargs="+", type=Path, help="the frames (image files, or a quoted pattern such as "
                   "\"frames/*.jpg\") or one video")
    p.add_argument("--camera", type=Path, default=None, help="a camera file from `gnomon calibrate camera`")
    p.add_argument("--out", type=Path, default=None, help="field log to write (default: field_log.toml "
                   "beside the frames' folder)")
    p.add_argument("--force", action="store_true", help="overwrite an existing field log")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gnomon import atomic
    from gnomon.errors import GnomonError
    from gnomon.frames import FrameSource, expand_glob_argument, natural_key
    from gnomon.publish import check_output_file
    from gnomon.validate import input_file

    files = sorted((f for a in args.frames for f in (expand_glob_argument(a, "frame") or (a,))), key=natural_key)
    for f in files:
        input_file(f, "frame")
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
        frames, what = Path(os.path.relpath(os.path.abspath(files[0]), base)).as_posix(), "video"
        count = str(source.count) if source.count else "a"
    else:
        if len({f.parent.resolve() for f in files}) != 1:
            raise GnomonError(f"{files[0]}: the frames must be in one folder")
        # the frames glob matches a suffix in any case: written as most of the files spell it
        spellings = Counter(f.suffix for f in files)
        one = len({s.lower() for s in spellings}) == 1
        suffix = max(spellings, key=lambda s: (spellings[s], s)) if one else ".*"
        rel = Path(os.path.relpath(os.path.abspath(folder), base)).as_posix()
        frames, count, what = f"{rel}/*{suffix}", str(len(files)), "frames"
    if args.camera is not None:
        if not args.camera.is_file():
            raise GnomonError(f"{args.camera}: camera file not found")
        from gnomon.calibration import load_camera_file, other_aspect

        rel = Path(os.path.relpath(os.path.abspath(args.camera), base)).as_posix()
        camera = f'file = "{rel}"  # from `gnomon calibrate camera`\n'
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
    text = TEMPLATE.format(name=out.name, frames=frames, count=count, what=what, width=width, height=height,
                           camera=camera)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_text(out, text)
    print(f"wrote {out}: {count} {what} of {width}x{height}; fill in the markers, then `gnomon preview {out}`")
    return 0
