"""Is a two-edge pixel's disagreement a widened dip? Measures it on a scanned capture.

    PYTHONPATH=python python benchmarks/edge_widening.py FIELD_LOG [--frog]

A dip widened by δ tracker frames on both sides (entered at t_e − δ, left at
t_l + δ: indirect light from surfaces shadowed first dims a point slowly
before its sharp edge and brightens it slowly after) moves the two edges'
depths apart along the ray: ``Z_e ≈ Z − δ·a`` and ``Z_l ≈ Z + δ·b``, where
``a``, ``b`` (world units per frame) are how fast the depth at which each
edge's shadow plane meets the ray changes at the pixel's time. Solved per
pixel: ``δ = (Z_l − Z_e)/(a + b)``, ``Z = (b·Z_e + a·Z_l)/(a + b)``.

The bound a widening can reach while the tracker's mid-level crossing still
sits on the sharp (direct-light) edge: with a fraction g < ½ of the dip
already gone to the slow indirect dimming when the sharp edge arrives, the
mid-level crossing of an edge ramp R frames long moves out by
``R·½g/(1 − g)``; the slope the tracker measures there is ``(1 − g)·C/R``
(C = Imax − Imin, linear), so ``δ ≤ ½g·C/slope < C/(4·slope)``. A larger δ
means the mid level fell in the slow indirect ramp, where the crossing's
time says nothing about the edge.

Prints, per region (with ``--frog``, the benchmark's hand-drawn frog, its
cast shadow, the box faces and the bare desk and wall of
``benchmarks/real_captures.py``), the distribution of δ over all two-edge
pixels and over those the fusion refuses as "edges disagree"; the share of
the refused ones a widening within the bound explains; and how far the
refused pixels' edge depths and their δ-corrected depth lie from the depth of
their kept neighbours (the median over 7 × 7). Run real_captures.py first for
the frog's field log (``OUT/frog/field_log.toml``).
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gnomon.capture.tracking import decoding_lut, linear
from gnomon.geometry.triangulation import triangulate
from gnomon.reconstruct.edges import EdgeResult
from gnomon.reconstruct.fusion import CONFLICT_SIGMAS
from score import frog_arguments, scan_field_log


def depth_rate(ray_map: np.ndarray, edge: EdgeResult) -> np.ndarray:
    """(H, W) dZ/dt of ``edge`` (world units per tracker frame; its planes one row per frame): the depth where
    its shadow plane meets each ray ½ frame after the pixel's time less ½ frame before."""
    t = edge.times.astype(np.float32)
    later = triangulate(ray_map, t + np.float32(0.5), edge.planes).depth
    earlier = triangulate(ray_map, t - np.float32(0.5), edge.planes).depth
    return np.where(np.isfinite(edge.depth), later - earlier, np.nan)


def kept_neighbour_depth(depth: np.ndarray, half: int = 3) -> np.ndarray:
    """(H, W) the median of the finite depths in the (2·half + 1)² window around each pixel."""
    h, w = depth.shape
    pad = np.pad(depth, half, constant_values=np.nan)
    stack = np.stack([pad[half + dv:half + dv + h, half + du:half + du + w]
                      for dv in range(-half, half + 1) for du in range(-half, half + 1)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(stack, axis=0)


def frog_regions(shape: tuple[int, int]) -> dict[str, np.ndarray]:
    from real_captures import FROG_OTHER_FACES, FROG_OUTLINE, FROG_SHADOW
    from score import _polygon_mask
    h, w = shape
    frog = _polygon_mask(shape, [FROG_OUTLINE])
    faces = _polygon_mask(shape, list(FROG_OTHER_FACES.values()))
    shadow = _polygon_mask(shape, [FROG_SHADOW])
    v, u = np.mgrid[0:h, 0:w]
    rest = ~frog & ~faces & ~shadow
    return {"frog": frog, "frog's cast shadow": shadow, "box faces": faces, "desk (v > 510)": rest & (v > 510),
            "wall (v < 340)": rest & (v < 340) & (u > 200) & (u < 900)}


def main(argv: list[str] | None = None) -> int:
    args = frog_arguments(__doc__, argv)
    log, setup, result = scan_field_log(args.field_log)
    edges = {e.name: e for e in result.edges}
    if set(edges) != {"enter", "leave"}:
        print(f"{args.field_log}: the scan has edges {sorted(edges)}, not enter and leave")
        return 2
    enter, leave = edges["enter"], edges["leave"]
    ray_map = setup.camera.ray_map()
    a, b = depth_rate(ray_map, enter), depth_rate(ray_map, leave)
    ze, zl, se, sl = enter.depth, leave.depth, enter.sigma, leave.sigma
    lut = decoding_lut(log.capture.gamma, np.uint8)
    contrast = linear(result.times.imax, lut) - linear(result.times.imin, lut)
    jump = setup.max_depth_jump
    with np.errstate(invalid="ignore", divide="ignore"):
        both = np.isfinite(ze) & np.isfinite(zl) & np.isfinite(a) & np.isfinite(b) & (a + b > 0)
        delta = (zl - ze) / (a + b)
        sigma_delta = np.hypot(se, sl) / (a + b)
        corrected = (b * ze + a * zl) / (a + b)
        mean = (ze / se**2 + zl / sl**2) / (1 / se**2 + 1 / sl**2)
        conflict = both & (np.abs(zl - ze) > np.maximum(CONFLICT_SIGMAS * np.hypot(se, sl), jump * np.abs(mean)))
        bound = 0.25 * contrast / np.fmax(enter.slope, leave.slope)
        explained = (delta >= -3 * sigma_delta) & (delta <= bound + 3 * sigma_delta)
    reference = kept_neighbour_depth(np.where(both & ~conflict, mean, np.nan).astype(np.float32))
    regions = frog_regions(ze.shape) if args.frog else {"all": np.ones(ze.shape, dtype=bool)}
    print(f"{args.field_log}: depth jump {jump:g}·Z; δ in tracker frames, depths in world units")
    for name, region in regions.items():
        m, c = region & both, region & conflict
        if not m.any():
            continue
        p = np.percentile(delta[m], [10, 50, 90])
        print(f"{name}: {int(m.sum())} two-edge pixels, δ p10/50/90 {p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}, "
              f"a/b median {np.median(a[m]):.2f}/{np.median(b[m]):.2f} per frame")
        if not c.any():
            continue
        p = np.percentile(delta[c], [10, 50, 90])
        ratio = np.percentile(delta[c] / bound[c], [10, 50, 90])
        print(f"  edges disagree: {int(c.sum())} ({100 * c.sum() / max(region.sum(), 1):.1f} % of the region), "
              f"δ p10/50/90 {p[0]:+.2f} {p[1]:+.2f} {p[2]:+.2f}, δ over its bound C/(4·slope) p10/50/90 "
              f"{ratio[0]:.2f} {ratio[1]:.2f} {ratio[2]:.2f}; a widening within the bound explains "
              f"{100 * explained[c].mean():.1f} %")
        r = c & np.isfinite(reference)
        if r.any():
            off_e, off_l, off_c = ze[r] - reference[r], zl[r] - reference[r], corrected[r] - reference[r]
            within = np.abs(off_c) <= np.maximum(3 * np.hypot(se[r], sl[r]) / 2, 0.0)
            print(f"    against their kept neighbours' depth: enter p10/50/90 "
                  f"{' '.join(f'{x:+.1f}' for x in np.percentile(off_e, [10, 50, 90]))}, leave "
                  f"{' '.join(f'{x:+.1f}' for x in np.percentile(off_l, [10, 50, 90]))}, δ-corrected "
                  f"{' '.join(f'{x:+.1f}' for x in np.percentile(off_c, [10, 50, 90]))} "
                  f"({100 * within.mean():.1f} % within 3 σ of the mean); dip length "
                  f"{np.median((leave.times - enter.times)[r]):.1f} frames (kept pixels of the region: "
                  f"{np.nanmedian((leave.times - enter.times)[region & both & ~conflict]):.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
