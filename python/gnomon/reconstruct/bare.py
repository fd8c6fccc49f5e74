"""The scan's reference regions held to their planes: what does not follow a plane is left out, and said.

A region (``[[planes]] regions`` or ``mask``) is where the field log says a plane is seen bare. A
hand-drawn rectangle, or a region started from the marks' outline, may hold part of an object, its cast
shadow or another surface: there the shadow's isochrones are not the plane's lines, and a frame whose
line is fitted to them gives a wrong shadow plane, a band of wrong depth across the whole image.

:func:`hold_regions` measures each plane's lines on its region with the scan's own fit, predicts every
region pixel's shadow time from them (:func:`gnomon.geometry.plane_times.predicted_times`), on the
entering and the leaving edge, and leaves out the pieces whose measured times are off
(:func:`gnomon.geometry.plane_times.off_plane_pieces`, grown by ``MARGIN_PX``), measuring again without
them, up to ``ROUNDS`` times. Each plane that loses pixels gets a warning with the numbers.
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from gnomon.config.setup import ScanSetup
from gnomon.geometry.plane_times import off_plane_pieces, plane_points, times_at_points
from gnomon.geometry.reference_lines import LineMemo, ReferencePlane, measure_reference_lines

__all__ = ["MIN_PIECE_PX", "OffPlane", "hold_regions", "off_plane"]

#: A pixel follows its plane when its time is within this many robust σ of the region's residuals ...
TOLERANCE_SIGMAS = 3.0
#: ... and never less than this (frames): the re-timed times of a bare plane scatter by 0.05-0.4 frame.
MIN_TOLERANCE = 0.5
#: Smaller pieces of off pixels are noise (a dark texture spot, the marks' black squares' low contrast).
MIN_PIECE_PX = 50
#: The pieces left out are grown by this much (px): their borders' blur and penumbra.
MARGIN_PX = 2
#: Measure-and-leave-out rounds at most.
ROUNDS = 3


@dataclasses.dataclass(frozen=True)
class OffPlane:
    """One plane's region after :func:`off_plane`: ``mask`` what is left, ``left_out`` (px) what was
    taken out of the ``given`` (px) pixels, ``pieces`` [(area px, (u0, v0, u1, v1))] the largest first,
    ``tolerance`` (frames) and ``residual_frames`` the median |measured − predicted| time of what is left."""

    mask: np.ndarray
    given: int
    left_out: int
    pieces: list[tuple[int, tuple[int, int, int, int]]]
    tolerance: float
    residual_frames: float


def off_plane(reference: ReferencePlane, maps: list[np.ndarray], n_frames: int, camera,
              ray_map: np.ndarray, memo: LineMemo | None = None) -> OffPlane:
    """One plane's region without the pieces that do not follow the plane's own lines (see the module).

    Every round works on the given region's pixels and their box alone (grown by the closing's and the
    margin's reach, so the pieces are the whole image's): their points on the plane are computed once,
    each later round takes those of the pixels left. ``memo``: where the lines are measured (and kept: the
    last round's, on the final mask, are those the scan's edges measure again on the same times)."""
    mask = reference.mask.copy()
    given = int(mask.sum())
    pieces: list[tuple[int, tuple[int, int, int, int]]] = []
    tolerance, typical = MIN_TOLERANCE, float("nan")
    if given == 0:
        return OffPlane(mask, given, 0, pieces, tolerance, typical)
    grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * MARGIN_PX + 1, 2 * MARGIN_PX + 1))
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    reach = MARGIN_PX + 1  # the closing (3 × 3) reads 2 px around a pixel, the margin's disc MARGIN_PX
    v0, u0 = max(int(rows[0]) - reach, 0), max(int(cols[0]) - reach, 0)
    v1, u1 = min(int(rows[-1]) + 1 + reach, mask.shape[0]), min(int(cols[-1]) + 1 + reach, mask.shape[1])
    box = mask[v0:v1, u0:u1]  # a view: the rounds leave pixels out of ``mask`` through it
    at = np.flatnonzero(mask)  # the given pixels (flat indices, row-major), gathered with np.take
    v_all, u_all = np.divmod(at, mask.shape[1])
    in_box = (v_all - v0) * (u1 - u0) + (u_all - u0)
    ok_all, xy_all = plane_points(reference.plane, ray_map.reshape(-1, 3)[at])  # their points, for every edge
    hits = np.zeros(at.size, dtype=bool)
    hits[ok_all] = True
    xy_of = np.full((at.size, 2), np.nan)
    xy_of[ok_all] = xy_all
    left = np.ones(at.size, dtype=bool)  # the given pixels still in the region
    for _ in range(ROUNDS):
        here = at[left]
        ok = np.flatnonzero(hits[left])
        xy = xy_of[left][ok]
        worst = np.full(here.size, -np.inf)
        for times in maps:
            held = dataclasses.replace(reference, mask=mask)
            lines = (measure_reference_lines(times, n_frames, held, camera) if memo is None
                     else memo.measure(times, n_frames, held, camera))
            predicted = np.full(here.size, np.nan)
            if np.count_nonzero(lines.found) >= 2:
                predicted[ok] = times_at_points(lines, xy)
            with np.errstate(invalid="ignore"):
                worst = np.fmax(worst, np.abs(np.take(times.reshape(-1), here) - predicted))
        worst[~np.isfinite(worst)] = np.nan
        residual = np.full(box.shape, np.nan)
        residual.reshape(-1)[in_box[left]] = worst
        judged = worst[np.isfinite(worst)]
        if judged.size == 0:
            break
        typical = float(np.median(judged))
        tolerance = max(MIN_TOLERANCE, TOLERANCE_SIGMAS * 1.4826 * typical)
        off, found = off_plane_pieces(residual, box, tolerance, MIN_PIECE_PX)
        if not found:
            break
        pieces += [(area, (a + u0, b + v0, c + u0, d + v0)) for area, (a, b, c, d) in found]
        box &= ~cv2.dilate(off.astype(np.uint8), grow).astype(bool)
        left &= np.take(mask.reshape(-1), at)
        if not left.any():
            break
    pieces.sort(reverse=True)
    return OffPlane(mask, given, given - int(mask.sum()), pieces, tolerance, typical)


def hold_regions(setup: ScanSetup, maps: list[np.ndarray], n_frames: int, ray_map: np.ndarray,
                 warnings: list[str], memo: LineMemo | None = None) -> ScanSetup:
    """``setup`` with each plane's region held to the plane (:func:`off_plane`) on the edges' time ``maps``
    (:func:`gnomon.reconstruct.edges.edge_time_maps`), a warning per plane that lost pixels: how many,
    where the largest piece lies, and what to do. ``memo``: :func:`off_plane`'s."""
    # the planes are independent: one thread each (numpy, OpenCV and the kernel release the GIL)
    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="gnomon-regions") as pool:
        helds = list(pool.map(lambda ref: off_plane(ref, maps, n_frames, setup.camera, ray_map, memo),
                              setup.planes))
    planes = []
    for reference, held in zip(setup.planes, helds, strict=True):
        if held.left_out and held.pieces:
            area, (u0, v0, u1, v1) = held.pieces[0]
            warnings.append(
                f"{setup.inputs.field_log}: [[planes]] {reference.name}: {held.left_out} of its {held.given} region "
                f"pixels ({100 * held.left_out / held.given:.1f} %) do not follow its shadow lines (shadow times "
                f"more than {held.tolerance:.2f} frame off the plane's on the entering or leaving edge, in "
                f"{len(held.pieces)} pieces, the largest {area} px in [{u0}, {v0}, {u1}, {v1}]): an object, its "
                "shadow, a mark or another surface; left out of the plane's lines. `gnomon regions` proposes regions "
                "without them")
            reference = dataclasses.replace(reference, mask=held.mask)
        planes.append(reference)
    return dataclasses.replace(setup, planes=tuple(planes))
