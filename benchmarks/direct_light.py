"""How many pixels does the lamp light directly? A ceiling on what a scan can measure (a script, not a test).

    PYTHONPATH=python python benchmarks/direct_light.py FIELD_LOG [--frog]

A pixel's shadow time says where the stick's shadow plane crossed *that
pixel's surface* only when the lamp lights it directly: the stick's shadow
then darkens it with an edge as sharp as the sweep is fast (here, under 2
frames). A surface the lamp does not reach (turned away from it, or in
another object's shadow) is lit only by light bounced off other surfaces; as
the stick's shadow sweeps those, it dims and brightens slowly (10 and more
frames) at times that belong to *them*. No level crossing, threshold or fusion
of such a dip gives the pixel's depth.

For every pixel with a dip the script decodes the frames to linear light
(the capture's own decoding table) and finds the largest one-frame fall in
the frames around the tracker's enter crossing and the largest one-frame rise
around its leave crossing (from ``SPAN`` frames before the crossing to the
middle of the dip, and from the middle to ``SPAN`` frames after: the bias of a
mid-level crossing on these dips reaches 5 frames). An edge is *direct* when
that step is at least a fraction ``f`` of the dip's linear contrast and its
largest one-frame step in DN of the frames is at least ``NOISE_SIGMAS`` times
the noise of a one-frame difference (measured on the frames' static pixels:
the robust spread of the DN differences far from every dip). Printed per
region, for f = 0 (the noise floor alone: the most generous reading), 1/8 and
1/4: the share of the region's pixels with a direct edge on both sides, on one
side only, on neither, and without a dip the tracker timed on both sides (no
shadow seen, two comparable dips); and the ceiling on coverage: every pixel
but those with a timed dip and no direct edge (a pixel without timed dip is
counted as measurable, so the ceiling is generous). Then each edge is timed
by its largest step instead (:func:`step_time`), triangulated with the scan's
planes and compared with the depth of the pixel's kept neighbours. With
``--frog``, the regions are ``real_captures.py``'s hand-drawn frog, its cast
shadow and the bare desk and wall; the frog's pixels are also split by the
scan's coverage class (kept or refused). Run real_captures.py first for
the frog's field log (``OUT/frog/field_log.toml``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gnomon.capture.frames import FrameSource
from gnomon.capture.tracking import decoding_lut
from gnomon.config.setup import ScanSetup, frame_source
from gnomon.outputs.images import COVERAGE_CLASSES
from gnomon.runs.scan import ScanResult
from score import frog_arguments, scan_field_log

#: Frames searched before the enter crossing and after the leave crossing.
SPAN = 8
#: A direct step is at least this many times the noise of a one-frame difference.
NOISE_SIGMAS = 3.0
FRACTIONS = (0.0, 0.125, 0.25)


def grey_frames(source: FrameSource) -> np.ndarray:
    """(N, H, W) float32 grey DN of every frame of ``source`` (the tracker's input)."""
    return np.stack([f.grey for f in source]).astype(np.float32)


def largest_steps(light: np.ndarray, enter: np.ndarray, leave: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(H, W) the largest one-frame fall from ``SPAN`` frames before ``enter`` to the dip's middle, and the largest
    one-frame rise from the middle to ``SPAN`` frames after ``leave`` (units of ``light``; NaN where a time is
    missing), and the frames ``k`` they start at (the step is ``light[k] → light[k + 1]``; 0 where none).

    ``light`` (N, H, W); ``enter``, ``leave`` (H, W) frame times (NaN = none).
    """
    n = light.shape[0]
    diff = np.diff(light, axis=0)  # diff[k] = light[k + 1] − light[k]
    have = np.isfinite(enter) & np.isfinite(leave)
    e = np.where(have, np.floor(enter), 0).astype(np.int64)
    lv = np.where(have, np.ceil(leave), 0).astype(np.int64)
    mid = (e + lv) // 2
    found = []
    for k0, k1, sign in ((e - SPAN, mid, -1.0), (mid, lv + SPAN, 1.0)):
        best = np.zeros(enter.shape, dtype=np.float32)
        at = np.zeros(enter.shape, dtype=np.int64)
        for offset in range(int((k1 - k0).max(initial=0)) + 1):
            k = k0 + offset
            inside = have & (k <= k1) & (k >= 0) & (k < n - 1)
            step = np.take_along_axis(diff, np.clip(k, 0, n - 2)[None], axis=0)[0] * np.float32(sign)
            larger = inside & (step > best)
            best = np.where(larger, step, best)
            at = np.where(larger, k, at)
        found.append((np.where(have, best, np.nan), at))
    (fall, k_fall), (rise, k_rise) = found
    return fall, rise, k_fall, k_rise


def step_time(light: np.ndarray, k: np.ndarray) -> np.ndarray:
    """(H, W) float32 time (frames) of the step ``light[k] → light[k + 1]``: where the samples ``k − 1 … k + 2``
    cross half-way between the levels one frame outside the step (``light[k − 1]`` and ``light[k + 2]``), the
    crossing nearest the step, linearly interpolated (NaN where none)."""
    n = light.shape[0]

    def at(j: np.ndarray) -> np.ndarray:
        return np.take_along_axis(light, np.clip(j, 0, n - 1)[None], axis=0)[0]

    level = (at(k - 1) + at(k + 2)) / 2
    time = np.full(k.shape, np.nan, dtype=np.float32)
    for j in (0, -1, 1):
        x0, x1 = at(k + j), at(k + j + 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            f = (x0 - level) / (x0 - x1)
        crossing = np.isnan(time) & (f >= 0) & (f <= 1) & (x0 != x1)
        time = np.where(crossing, (k + j + f).astype(np.float32), time)
    return time


def step_noise(light: np.ndarray, enter: np.ndarray, leave: np.ndarray) -> float:
    """The noise (1σ, units of ``light``) of a one-frame difference: 1.4826 × the median |difference| over the frames
    more than ``2·SPAN`` from a pixel's dip (every frame of a pixel without one)."""
    diff = np.abs(np.diff(light, axis=0))
    k = np.arange(diff.shape[0], dtype=np.float64)[:, None, None]
    with np.errstate(invalid="ignore"):
        near = (k >= np.floor(enter)[None] - 2 * SPAN) & (k <= np.ceil(leave)[None] + 2 * SPAN)
    return float(1.4826 * np.median(diff[~near]))


def frog_regions(shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """real_captures.py's frog (shrunk by 3 px, as scored), its cast shadow and the bare desk and wall."""
    from real_captures import FROG_OTHER_FACES, FROG_OUTLINE, FROG_SHADOW
    from score import _polygon_mask
    h, w = shape
    frog = _polygon_mask(shape, [FROG_OUTLINE], -3)
    near = _polygon_mask(shape, [FROG_OUTLINE, FROG_SHADOW, *FROG_OTHER_FACES.values()], 12)
    v, u = np.mgrid[0:h, 0:w]
    bare = ~near & (u > 200) & (u < 900)
    return {"frog": frog, "frog's cast shadow": _polygon_mask(shape, [FROG_SHADOW], -3),
            "bare desk (v > 510)": bare & (v > 510), "bare wall (v < 340)": bare & (v < 340)}


def main(argv: list[str] | None = None) -> int:
    args = frog_arguments(__doc__, argv)
    log, setup, result = scan_field_log(args.field_log)
    skipped = np.flatnonzero(setup.light.skipped_frames(frame_source(log).count))
    if len(skipped):
        print(f"{args.field_log}: the light skips frames {skipped[:5].tolist()}...; this script assumes none")
        return 2
    times = result.times
    lut = decoding_lut(log.capture.gamma, np.uint8).astype(np.float32)
    dn = grey_frames(frame_source(log))
    noise = step_noise(dn, times.enter, times.leave)
    fall_dn, rise_dn, _, _ = largest_steps(dn, times.enter, times.leave)
    light = lut[dn.astype(np.intp)]
    del dn
    fall, rise, k_fall, k_rise = largest_steps(light, times.enter, times.leave)
    contrast = lut[np.clip(np.rint(times.imax), 0, 255).astype(np.intp)] - \
        lut[np.clip(np.rint(times.imin), 0, 255).astype(np.intp)]
    dip = np.isfinite(times.enter) & np.isfinite(times.leave)
    print(f"{args.field_log}: {light.shape[0]} frames {light.shape[2]}x{light.shape[1]}; one-frame difference noise "
          f"{noise:.2f} DN (1 sigma); a direct step: >= {NOISE_SIGMAS:g} sigma in DN and >= f x the dip's linear "
          "contrast")
    regions = frog_regions(dip.shape) if args.frog else {"all": np.ones(dip.shape, dtype=bool)}
    for name, region in regions.items():
        n = int(region.sum())
        if n == 0:
            continue
        print(f"{name}: {n} pixels, {100 * (region & ~dip).sum() / n:.1f} % without a dip timed on both sides")
        for f in FRACTIONS:
            floor, above = np.float32(f) * contrast, np.float32(NOISE_SIGMAS * noise)
            sharp_in = dip & (fall >= floor) & (fall_dn >= above)
            sharp_out = dip & (rise >= floor) & (rise_dn >= above)
            both, one, neither = sharp_in & sharp_out, sharp_in ^ sharp_out, dip & ~sharp_in & ~sharp_out
            print(f"  f = {f:<5g} direct edge on both sides {100 * (region & both).sum() / n:5.1f} %, one side "
                  f"{100 * (region & one).sum() / n:5.1f} %, neither {100 * (region & neither).sum() / n:5.1f} %: "
                  f"at most {100 * (region & ~neither).sum() / n:5.1f} % of the region can be measured")
            if args.frog and name == "frog" and result.coverage is not None:
                for k, (cname, _) in COVERAGE_CLASSES.items():
                    c = region & (result.coverage == k)
                    if c.sum() >= 0.005 * n:
                        print(f"      its '{cname}' pixels ({100 * c.sum() / n:.1f} %): both "
                              f"{100 * (c & both).sum() / c.sum():.1f} %, one {100 * (c & one).sum() / c.sum():.1f} "
                              f"%, neither {100 * (c & neither).sum() / c.sum():.1f} %")
    step_timed(result, setup, light, k_fall, k_rise, regions, args.frog)
    return 0


def step_timed(result: ScanResult, setup: ScanSetup, light: np.ndarray, k_fall: np.ndarray, k_rise: np.ndarray,
               regions: dict[str, np.ndarray], frog: bool) -> None:
    """Print how far each edge's depth timed by its largest step (:func:`step_time`) lies from the depth of the
    pixel's kept neighbours (median over 7 × 7 px), per region: on the frog, for its kept pixels and those refused
    as "edges disagree" or "no neighbour at its depth"; and the share whose two step-timed depths agree (within
    3 of their edges' combined σ or 1 % of the depth)."""
    from edge_widening import kept_neighbour_depth
    from gnomon.geometry.triangulation import triangulate
    from gnomon.outputs.images import EDGES_DISAGREE, NO_NEIGHBOUR

    edges = {e.name: e for e in result.edges}
    if set(edges) != {"enter", "leave"}:
        return
    rays = setup.camera.ray_map()
    ze = triangulate(rays, step_time(light, k_fall), edges["enter"].planes).depth
    zl = triangulate(rays, step_time(light, k_rise), edges["leave"].planes).depth
    reference = kept_neighbour_depth(result.depth.astype(np.float32))
    mean = (ze + zl) / 2
    with np.errstate(invalid="ignore"):
        agree = np.abs(ze - zl) <= np.maximum(3 * np.hypot(edges["enter"].sigma, edges["leave"].sigma),
                                              0.01 * np.abs(mean))
    print("each edge timed by its largest one-frame step instead of the mid-level crossing, against the kept "
          "neighbours' depth (p10/50/90, world units):")
    kept = np.isfinite(result.depth)
    classes = {"kept": kept}
    if frog and result.coverage is not None:
        classes |= {"edges disagree": result.coverage == EDGES_DISAGREE,
                    "no neighbour at its depth": result.coverage == NO_NEIGHBOUR}
    for name, region in regions.items():
        for cname, c in classes.items():
            m = region & c & np.isfinite(reference) & np.isfinite(ze) & np.isfinite(zl)
            if m.sum() < 100 or (cname != "kept" and name != "frog"):
                continue
            a = agree[m]
            off = np.abs(mean[m][a] - reference[m][a])
            print(f"  {name}, {cname} ({int(m.sum())} px): enter "
                  f"{' '.join(f'{x:+.1f}' for x in np.percentile(ze[m] - reference[m], [10, 50, 90]))}, leave "
                  f"{' '.join(f'{x:+.1f}' for x in np.percentile(zl[m] - reference[m], [10, 50, 90]))}; the two "
                  f"agree on {100 * a.mean():.1f} %, and of those {100 * np.mean(off <= 5):.1f} % lie within 5 "
                  "of the neighbours' depth")


if __name__ == "__main__":
    sys.exit(main())
