"""`gnomon preview FIELD_LOG`: check a field log before scanning, in one picture.

Writes a PNG of the capture's first frame with each plane's regions, each
marker as found with its residual, each plane's grid reprojected, the line
where the planes meet and the pencil's pixels (see :mod:`gnomon.runs.setup_preview`).
A wrong number in the field log shows at a glance: a grid that misses the
marks, a residual of pixels instead of tenths, a region over an object.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from gnomon.commands import COMMANDS


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "preview",
        help=COMMANDS["preview"],
        description="Measure the planes' markers in the first frame and draw on it: the regions, each "
        "marker found with its reprojection residual, each plane's grid reprojected through the camera, "
        "the line where the planes meet, and the pencil's pixels. No tracking: it takes seconds.",
    )
    p.add_argument("field_log", type=Path, help="the capture's field log (TOML)")
    p.add_argument("--out", type=Path, default=None, help="PNG to write (default: FIELD_LOG's name + _preview.png)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import cv2

    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import first_frame, frame_source, plane_region_mask, resolve_reference_planes
    from gnomon.errors import FieldLogError
    from gnomon.runs.setup_preview import MarkerMark, PlaneDrawing, setup_preview
    from gnomon.util import atomic, toml_io
    from gnomon.util.validate import check_output_file

    if args.out is not None:
        check_output_file(args.out, "--out")
    log = load_field_log(args.field_log)
    source = frame_source(log)
    log, report = resolve_reference_planes(log, source)
    if log.pose is None:
        raise FieldLogError(f"{log.path}: no [camera.pose] and no plane with markers or a chessboard: "
                            "nothing places the planes")
    first = first_frame(source)
    camera = log.camera
    shape = first.shape[:2]
    measured = {e["plane"]: e for e in report}
    drawings = []
    for plane in log.planes:
        x_axis = plane.x_axis
        if x_axis is None:
            helper = np.array([1.0, 0.0, 0.0]) if abs(plane.normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            x_axis = helper - (helper @ plane.normal) * plane.normal
            x_axis /= np.linalg.norm(x_axis)
        marks, extent = [], None
        entry = measured.get(plane.name)
        if entry is not None and plane.markers:
            for m, pix in zip(plane.markers, entry["pixels"], strict=True):
                name = f"{plane.name} marker {m.id}"
                r = entry["residuals_px"].get(name, [np.nan, np.nan])
                marks.append(MarkerMark(str(m.id), np.asarray(pix), None if m.exact else m.pixel_hint,
                                        float(np.hypot(*r))))
            xy = (np.array(list(entry["marks_xy"].values())) if plane.unmeasured_marks  # as the fit placed them
                  else np.array([m.plane_xy for m in plane.markers]))
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            pad = 0.15 * (hi - lo).max()
            extent = (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad)
        elif entry is not None:  # a chessboard (or ArUco markers, a ChArUco board): its first and last corners
            pix = np.array(entry["pixels"])
            marks = [MarkerMark("", p, None, float(np.hypot(*r))) for p, r in
                     zip(pix[[0, -1]], np.array(list(entry["residuals_px"].values()))[[0, -1]], strict=True)]
            if plane.chessboard is not None and plane.square is not None:  # the grid over the board's squares
                # its corners where their rays meet the plane, in the plane's axes (whichever way they run)
                normal_cam = log.pose.R @ plane.normal
                rays = camera.rays(np.array(entry["pixels"], dtype=np.float64))
                on = rays * ((normal_cam @ log.pose.world_to_camera(plane.point)) / (rays @ normal_cam))[:, None]
                rel = log.pose.camera_to_world(on) - plane.point
                a, b = rel @ x_axis, rel @ np.cross(plane.normal, x_axis)
                sq = plane.square
                extent = (float(a.min()) - sq, float(a.max()) + sq, float(b.min()) - sq, float(b.max()) + sq)
        mask = plane_region_mask(plane, shape) if plane.has_regions else None
        drawings.append(PlaneDrawing(plane.name, plane.point, x_axis, np.cross(plane.normal, x_axis), plane.normal,
                                     mask, marks, extent))
    pencil = []
    raw = toml_io.load(log.path).get("pencil", {})
    for k, photo in enumerate(raw.get("photos", []) if isinstance(raw, dict) else []):
        for key in ("base", "tip"):
            if isinstance(photo, dict) and isinstance(photo.get(key), list) and len(photo[key]) == 2:
                image = photo.get("image")  # named as the user's files are, not by a count from 0
                label = Path(image).name if isinstance(image, str) else f"pencil photo {k + 1}"
                pencil.append((f"{label} {key}", np.asarray(photo[key], dtype=np.float64)))
    image = setup_preview(first, camera, log.pose, drawings, pencil)
    out = args.out if args.out is not None else log.path.with_name(log.path.stem + "_preview.png")
    ok, data = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover
        raise OSError(f"could not encode {out}")
    atomic.write_bytes(out, data.tobytes())
    for e in report:
        print(f"{e['plane']}: {e['n_points']} marks, reprojection RMS {e['rms_px']:.3f} px (max {e['max_px']:.3f})"
              + (f", {e['angle_to_first_deg']:.2f}° to the first plane" if "angle_to_first_deg" in e else "")
              + (f", normal ± {e['std_normal_deg']:.2f}° (1 σ)" if "marks_xy" in e else "")
              + (f", distance ± {100 * e['std_offset_relative']:.2f} %" if e.get("std_offset_relative", 0) > 0 else "")
              + ("; its distance is a first guess (its marks have no plane_xy): the scan measures it where its "
                 "shadow lines meet the first plane's" if e.get("distance") == "provisional" else ""))
        for w in e["warnings"]:
            print(f"warning: {w}")
    print(f"wrote {out}")
    return 0
