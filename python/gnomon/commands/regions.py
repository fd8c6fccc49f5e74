"""`gnomon regions FIELD_LOG`: propose each plane's bare, swept areas from a first pass.

Tracks the shadow once, measures every plane with markers (or a chessboard),
and keeps each plane's pixels whose shadow times its own shadow lines predict
(:mod:`gnomon.runs.regions`). Writes, into ``--out`` (default ``regions/`` beside
the field log): one mask image per plane (``<plane>_mask.png``), a field-log
snippet (``regions.toml``: the ``mask`` key of each ``[[planes]]``) and a
drawing (``regions.png``: the first frame with the regions tinted).
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gnomon.commands import COMMANDS

if TYPE_CHECKING:
    from gnomon.capture.frames import FrameSource

# The first lines are fitted inside the hull of a plane's markers grown by this fraction around their centre.
SEED_GROWTH = -0.25
PLANE_COLOURS = ((60, 60, 255), (255, 120, 40), (60, 200, 60), (200, 60, 200))  # BGR


def _files(source: FrameSource, used: np.ndarray, first: int, last: int) -> str:
    """' (files A–B)': the image files of the tracker's frames ``first``..``last`` (0-based, as the warnings
    number them), or '' for a video."""
    files = source.image_files
    if not files or last >= len(used) or int(used[last]) >= len(files):
        return ""
    a, b = files[int(used[first])].name, files[int(used[last])].name
    return f" (file {a})" if a == b else f" (files {a}–{b})"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "regions",
        help=COMMANDS["regions"],
        description="Track the shadow once and keep, for each plane, the pixels whose shadow times the "
        "plane's own shadow lines predict (lines first fitted inside its markers, or inside the regions "
        "the field log already gives). Writes one mask image per plane, a field-log snippet and a drawing.",
    )
    p.add_argument("field_log", type=Path, help="the capture's field log (TOML); planes need markers, a "
                   "chessboard or rough regions to start from")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: regions/ beside the field log)")
    p.add_argument("--tolerance", type=float, default=None, metavar="FRAMES",
                   help="largest difference between a pixel's shadow time and the plane's prediction "
                   "(default: 3 robust standard deviations inside the plane, at least 0.25)")
    p.add_argument("--margin", type=int, default=2, metavar="PX", help="keep this far from anything else")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _png(path: Path, image: np.ndarray) -> None:
    import cv2

    from gnomon.util import atomic

    ok, data = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise OSError(f"could not encode {path}")
    atomic.write_bytes(path, data.tobytes())


def draw_regions(first: np.ndarray, masks: list[np.ndarray]) -> np.ndarray:
    """The first frame (BGR) with each plane's mask tinted and outlined in its colour."""
    import cv2

    if first.dtype == np.uint16:
        first = (first // 257).astype(np.uint8)
    img = first.copy() if first.ndim == 3 else cv2.cvtColor(first, cv2.COLOR_GRAY2BGR)
    for k, mask in enumerate(masks):
        colour = np.array(PLANE_COLOURS[k % len(PLANE_COLOURS)], dtype=np.float64)
        img[mask] = (0.55 * img[mask] + 0.45 * colour).astype(np.uint8)
        contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(img, contours, -1, tuple(int(c) for c in colour), 1)
    return img


def run(args: argparse.Namespace) -> int:
    from gnomon.capture.tracking import track_source, track_widening
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import (
        dip_width_policy,
        frame_source,
        plane_region_mask,
        resolve_reference_planes,
        tracker_settings,
        untied_planes,
    )
    from gnomon.errors import FieldLogError
    from gnomon.geometry.reference_lines import PlaneInCamera
    from gnomon.reconstruct.corners import tie_message
    from gnomon.reconstruct.edges import edge_time_maps
    from gnomon.runs.regions import hull_mask, propose_regions, tie_on_seeds
    from gnomon.util import atomic, validate
    from gnomon.util.validate import check_output_folder

    if args.out is not None:
        check_output_folder(args.out)
    if args.tolerance is not None:
        validate.number(args.tolerance, "--tolerance", positive=True)
    validate.number(args.margin, "--margin", minimum=0, maximum=10_000, integer=True)
    log = load_field_log(args.field_log)
    source = frame_source(log)
    log, planes_report = resolve_reference_planes(log, source)
    if log.pose is None:
        raise FieldLogError(f"{log.path}: no [camera.pose] and no plane with markers or a chessboard: "
                            "the planes cannot be placed")
    measured = {entry["plane"]: np.array(entry["pixels"]) for entry in planes_report}
    shape = (log.camera.height, log.camera.width)
    seeds, start = [], {}
    for plane in log.planes:
        if plane.has_regions:
            seeds.append(plane_region_mask(plane, shape))
            start[plane.name] = "its regions"
        elif len(log.planes) == 1 and plane.chessboard is not None:
            # one desk placed by a board lying on it (a lamp capture): the board's outline is where it lay,
            # not where the desk is bare (an object may stand there), so start as the paper does, from two
            # bands of the image's top and bottom rows
            seeds.append(paper_bands(shape))
            start[plane.name] = "two bands of the image's top and bottom rows"
            print(f"{plane.name}: no regions given: started from two bands of the image's top and bottom rows "
                  f"(rows {int(BAND_ROWS[0][0] * shape[0])}-{int(BAND_ROWS[0][1] * shape[0])} and "
                  f"{int(BAND_ROWS[1][0] * shape[0])}-{int(BAND_ROWS[1][1] * shape[0])}); if the object reaches "
                  "into them, give regions of bare desk instead")
        elif plane.name in measured and len(measured[plane.name]) >= 3:
            seeds.append(hull_mask(shape, measured[plane.name], shrink=SEED_GROWTH))
            start[plane.name] = "its marks' outline"
        else:
            raise FieldLogError(f"{log.path}: [[planes]] {plane.name}: nothing to start from; give it markers, "
                                "a chessboard or rough regions")
    settings = tracker_settings(log)
    tracked, _, notes = track_widening(track_source, source, settings, shape,
                                       dip_width=dip_width_policy(log), progress=not args.quiet,
                                       where=f"{log.path}: [camera]")
    for note in notes:
        print(f"warning: {note}")
    # The scan's own times: a compressed video's block times interpolated between their centres, a fast
    # sweep's staircase re-timed between its isochrones (gnomon.reconstruct.edges.edge_time_maps).
    maps = edge_time_maps(tracked, log.scan.edge)
    if settings.steps and len(maps) == 2:
        # An [edge]'s steps into and out of its shadow are one event each, both on its boundary at their time:
        # one map (a pixel with both: its step into the shadow).
        maps = [np.where(np.isfinite(maps[0]), maps[0], maps[1])]
    planes = [PlaneInCamera.from_world(p.point, p.normal, log.pose) for p in log.planes]
    names = [p.name for p in log.planes]
    untied = untied_planes(planes_report)
    if untied:  # planes whose marks fix only their orientation: their distance where they meet the first
        planes, ties = tie_on_seeds(maps, tracked.n_frames, planes, names, seeds, log.camera, untied)
        for (name, anchor), tie in zip(untied, ties.values(), strict=True):
            error, warning = tie_message(name, anchor, tie, (np.nan, np.nan))
            if error:
                raise FieldLogError(f"{log.path}: {error}")
            assert tie is not None
            print(f"{name}: {abs(tie.offset / planes[names.index(anchor)].offset):.4f} times the {anchor}'s "
                  "distance from "
                  f"the camera (± {100 * tie.sigma / abs(tie.offset):.3f} %), where their shadow lines meet "
                  f"in {tie.frames} frames" + (f"; warning: {warning}" if warning else ""))
    proposals = propose_regions(maps, tracked.n_frames, planes, names, seeds, log.camera,
                                tolerance=args.tolerance, margin_px=max(args.margin, 0))

    out = args.out if args.out is not None else args.field_log.parent / "regions"
    out.mkdir(parents=True, exist_ok=True)
    rel = Path(os.path.relpath(out, args.field_log.parent))
    snippet = ["# Written by `gnomon regions`: add each plane's `mask` to its [[planes]] table",
               "# (the scan uses it with any `regions` rectangles or polygons given).", ""]
    for region in proposals:
        if not region.mask.any():
            print(f"warning: plane {region.name!r}: no pixel is consistent with it; check its markers "
                  "and that the shadow crosses it")
        _png(out / f"{region.name}_mask.png", region.mask.astype(np.uint8) * 255)
        snippet += ["[[planes]]", f'name = "{region.name}"', f'mask = "{(rel / f"{region.name}_mask.png").as_posix()}"',
                    (f"# {int(region.mask.sum())} pixels, shadow-time tolerance {region.tolerance:.2f} frames, "
                     f"lines in {region.lines_found} frames"), ""]
        print(f"{region.name}: {int(region.mask.sum())} pixels ({100 * region.mask.mean():.1f} % of the image), "
              f"tolerance {region.tolerance:.2f} frames, lines in {region.lines_found} frames")
        if region.seed_left_out:
            area, (u0, v0, u1, v1) = region.seed_pieces[0]
            print(f"  cut out: {region.seed_left_out} pixels of what it started from ({start[region.name]}) do not "
                  f"follow the {region.name}'s shadow lines (more than {region.tolerance:.2f} frame off on an edge; "
                  f"{len(region.seed_pieces)} pieces, the largest {area} px in [{u0}, {v0}, {u1}, {v1}]): an "
                  "object, its shadow, a mark or another surface")
        if region.gaps:
            spans = ", ".join(f"{a}–{b}{_files(source, tracked.used, a, b)}" for a, b in region.gaps[:6]) + (
                " …" if len(region.gaps) > 6 else "")
            print(f"warning: plane {region.name!r}: no line in frames {spans} of its sweep (the shadow there fits "
                  "no line through its pixels): the stripes it crossed then are missing from the mask; check "
                  "there for an object or a wrong plane, or draw a rough region across them and run again")
    atomic.write_text(out / "regions.toml", "\n".join(snippet))
    first = tracked.first_color if tracked.first_color is not None else tracked.first_grey
    _png(out / "regions.png", draw_regions(first, [r.mask for r in proposals]))
    print(f"wrote {out / 'regions.toml'}, {len(proposals)} masks and {out / 'regions.png'}")
    masks = {r.name: (rel / f"{r.name}_mask.png").as_posix() for r in proposals if r.mask.any()}
    text = args.field_log.read_text(encoding="utf-8")
    switched, text = switch_on_masks(text, masks)
    if switched:
        atomic.write_text(args.field_log, text)
        one = len(switched) == 1
        print(f"{args.field_log}: {' and '.join(switched)} now read{'s its mask' if one else ' their masks'} (the "
              f"template's `mask` line{'' if one else 's'} switched on)")
    rest = [n for n in masks if n not in switched and not _reads_mask(text, n, masks[n])]
    if rest:
        print(f"add each plane's `mask` from {out / 'regions.toml'} to {args.field_log} ({', '.join(rest)})")
    return 0


#: The paper's reference rows: where a desk-lamp capture's regions start when none are given (shares of the
#: image's height, top band and bottom band).
BAND_ROWS = ((0.05, 0.2), (0.8, 0.95))


def paper_bands(shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the two bands of :data:`BAND_ROWS` across the whole width."""
    mask = np.zeros(shape, dtype=bool)
    for top, bottom in BAND_ROWS:
        mask[int(top * shape[0]):int(bottom * shape[0])] = True
    return mask


_TABLE = re.compile(r"^\[\[planes\]\][^\n]*$", re.M)


def _plane_blocks(text: str) -> list[tuple[int, int, str]]:
    """(start, end, name) of each [[planes]] table of a field log's text (the name from its `name = ` line)."""
    starts = [m.start() for m in _TABLE.finditer(text)]
    blocks = []
    for i, a in enumerate(starts):
        b = starts[i + 1] if i + 1 < len(starts) else len(text)
        head = text.find("\n", a, b)
        head = b if head < 0 else head
        nxt = re.search(r"^\[(?!\[planes\.)[^\n]*$", text[head:b], re.M)  # a following table ends it
        b = head + nxt.start() if nxt else b
        name = re.search(r'^name\s*=\s*"([^"]*)"', text[a:b], re.M)
        blocks.append((a, b, name.group(1) if name else ""))
    return blocks


def _reads_mask(text: str, name: str, path: str) -> bool:
    return any(n == name and re.search(rf'^mask\s*=\s*"{re.escape(path)}"', text[a:b], re.M)
               for a, b, n in _plane_blocks(text))


def switch_on_masks(text: str, masks: dict[str, str]) -> tuple[list[str], str]:
    """Uncomment, in each named plane's table, the line ``# mask = "PATH"`` that `gnomon init` writes, where
    PATH is the mask just written for it; a table with any other `mask` (or none commented) is left as it is.
    Returns the planes switched on and the new text."""
    switched = []
    for a, b, name in reversed(_plane_blocks(text)):
        path = masks.get(name)
        if path is None or re.search(r"^mask\s*=", text[a:b], re.M):
            continue
        line = re.search(rf'^# mask = "{re.escape(path)}"[^\n]*$', text[a:b], re.M)
        if line is None:
            continue
        text = (text[:a + line.start()] + f'mask = "{path}"  # written by `gnomon regions`'
                + text[a + line.end():])
        switched.append(name)
    return sorted(switched, key=list(masks).index), text
