"""The edges fused into one depth map: inverse-variance fusion, neighbour support, crop.

:func:`fuse_edges` fuses the edges' depths (the kernel: :func:`gnomon.reconstruct.fusion.fuse_depths`
then :func:`gnomon.geometry.triangulation.supported_by_neighbours`), flags points whose σ the depth-jump
test cannot vouch for, and gives the shadow time in capture frames; :func:`crop_fused` applies
``[output]``'s crop and ``max_sigma``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel
from gnomon.capture.tracking import (
    TrackedSequence,
    contrast_floor,
)
from gnomon.config.setup import ScanSetup
from gnomon.errors import Remark
from gnomon.geometry.crop import crop_mask
from gnomon.geometry.surface import points_from_depth
from gnomon.geometry.uncertainty import (
    MIN_FRAMES_PER_TRANSITION,
    undersampled,
)
from gnomon.geometry.validity import direct_light
from gnomon.light.base import LightModel
from gnomon.outputs.images import NO_DIRECT_LIGHT
from gnomon.reconstruct.edges import EdgeResult, Levels
from gnomon.reconstruct.fusion import beyond_trust


@dataclass
class FusedMaps:
    depth: np.ndarray
    sigma: np.ndarray
    keep: np.ndarray
    conflict: np.ndarray
    shadow_time: np.ndarray
    undersampled: np.ndarray
    unsupported: np.ndarray  # (H, W) a fused depth no neighbour shares (dropped)
    untrusted: np.ndarray  # (H, W) a kept point whose σ the depth-jump test cannot vouch for (counted, kept)
    # the median number of frames the shadow edge took to cross an under-sampled point (NaN: none is)
    transition_frames: float = float("nan")
    # (H, W) points refused because the light's own shadow did not make their dip (screen_direct_light)
    no_direct_light: np.ndarray | None = None
    direct_light_refused: dict[str, int] | None = None  # those points by reason


def fuse_edges(edges: list[EdgeResult], tracked: TrackedSequence, max_depth_jump: float,
          levels: Levels | None = None) -> FusedMaps:
    """Fuse the edges, drop unsupported points, flag those whose σ is beyond the depth-jump test
    (:func:`gnomon.reconstruct.fusion.beyond_trust`), shadow time in capture frames, under-sampled points."""
    # fuse_depths then supported_by_neighbours, per pixel in the kernel (rows in parallel)
    depth, sigma, code = _kernel.fuse_supported(np.stack([e.depth for e in edges]).astype(np.float32, copy=False),
                                                np.stack([e.sigma for e in edges]).astype(np.float32, copy=False),
                                                float(max_depth_jump))
    keep, conflict, unsupported = code == 1, code == 2, code == 3
    untrusted = keep & beyond_trust(depth, sigma, max_depth_jump)
    shadow_time = mean_ignoring_nan([e.times for e in edges])
    used = tracked.used
    if len(used) and not np.array_equal(used, np.arange(len(used))):
        # frames were skipped (clouds, night): report times as the capture's frame indices
        finite = np.isfinite(shadow_time)
        shadow_time[finite] = np.interp(shadow_time[finite], np.arange(len(used)), used)
    levels = levels or Levels(tracked)
    imax, imin = levels.imax, levels.imin
    under = np.zeros(keep.shape, dtype=bool)
    lengths = []
    for e in edges:
        fast = undersampled(e.slope, imax, imin) & keep
        under |= fast
        with np.errstate(invalid="ignore", divide="ignore"):
            lengths.append(((imax - imin) / e.slope)[fast])  # frames from fully lit to fully shadowed
    crossing = np.concatenate(lengths) if lengths else np.zeros(0)
    transition = float(np.median(crossing)) if crossing.size else float("nan")
    return FusedMaps(depth, sigma, keep, conflict, shadow_time, under, unsupported, untrusted, transition)


def screen_direct_light(fused: FusedMaps, edges: list[EdgeResult], tracked: TrackedSequence,
                        levels: Levels) -> list[str]:
    """Refuse, in place, the fused points whose dip the light's own shadow did not make
    (:func:`gnomon.geometry.validity.direct_light`: bounced light only, the edge of the light, lit mostly by
    bounced light with edges that disagree); for a light whose occluder hides it whole (a lamp). Returns
    the note that counts them (``fused.direct_light_refused`` by reason)."""
    relative, _ = levels.relative_depth
    # a dip is there where it stands out of the image noise, even under the field log's min_contrast: a
    # dim face the lamp lights at a grazing angle is reached by its light
    with np.errstate(invalid="ignore"):
        dip = tracked.times.contrast >= contrast_floor(None, tracked.noise_dn)
    screen = direct_light(fused.keep, dip, relative, [e.depth for e in edges], [e.sigma for e in edges])
    refused = screen.refused
    fused.keep &= ~refused
    fused.depth[refused] = np.nan
    fused.sigma[refused] = np.nan
    fused.undersampled &= fused.keep
    fused.untrusted &= fused.keep
    fused.no_direct_light = refused
    counts = {"bounce_only": int(screen.bounce_only.sum()), "edge_of_light": int(screen.edge_of_light.sum()),
              "mostly_bounce_edges_disagree": int(screen.edges_disagree.sum())}
    fused.direct_light_refused = counts
    if not refused.any():
        return []
    return [Remark(f"{int(refused.sum())} points refused: the light's own shadow did not make their dip "
                   f"(light bounced off another surface: {counts['bounce_only']}; at the edge of the light, beside "
                   f"a pixel it does not reach: {counts['edge_of_light']}; lit mostly by bounced light, the two "
                   f"edges disagree: {counts['mostly_bounce_edges_disagree']}); coverage.npy class "
                   f"{NO_DIRECT_LIGHT}")]


def fusion_warnings(fused: FusedMaps, light: LightModel) -> list[str]:
    """The warning for a capture most of whose points the shadow edge crossed in under
    ``MIN_FRAMES_PER_TRANSITION`` frames, with what the light lets the user change (``light``)."""
    warnings = []
    under, keep = fused.undersampled, fused.keep
    if under.mean() > 0.2 * max(keep.mean(), 1e-9):
        factor = MIN_FRAMES_PER_TRANSITION / fused.transition_frames if fused.transition_frames > 0 else 2.0
        warnings.append(
            f"{int(under.sum())} points ({100 * under.sum() / max(keep.sum(), 1):.0f} %) are under-sampled: the "
            f"shadow edge crossed them in {fused.transition_frames:.1f} frames (median), fewer than "
            f"{MIN_FRAMES_PER_TRANSITION:g}; their times are interpolated across the edge and their σ includes "
            f"that error; to sample the edge, {light.undersampling_advice(max(factor, 1.0))}"
        )
    return warnings


def mean_ignoring_nan(maps: list[np.ndarray]) -> np.ndarray:
    """(H, W) float32: each pixel's sum of the maps with NaN as 0 (``np.nansum`` over their stack, in the
    maps' dtype, in order) over its count of finite values, divided in float64; NaN where none is finite.
    The same values as ``np.nansum(stack, 0) / np.maximum(n, 1)`` without the stack and its NaN-less copy."""
    total = np.zeros(maps[0].shape, np.result_type(*maps))  # from +0, as np.sum starts (+0 + -0.0 is +0)
    count = np.zeros(maps[0].shape, np.uint16)
    for m in maps:
        total += np.where(np.isnan(m), 0, m)
        count += np.isfinite(m)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.divide(total, np.maximum(count, 1), dtype=np.float64).astype(np.float32)
    mean[count == 0] = np.nan
    return mean


def crop_fused(fused: FusedMaps, setup: ScanSetup, ray_map: np.ndarray) -> np.ndarray:
    """Apply ``[output]``'s crop and ``max_sigma`` to the fused maps in place; returns the (H, W) pixels they
    removed."""
    cropped = np.zeros(fused.keep.shape, dtype=bool)
    if setup.crop is None:
        return cropped
    points = points_from_depth(ray_map, fused.depth)[fused.keep].astype(np.float64)
    inside = crop_mask(setup.pose.camera_to_world(points), setup.crop, setup.pose.camera_centre_world,
                       fused.sigma[fused.keep])
    cropped[fused.keep] = ~inside
    fused.keep &= ~cropped
    fused.depth[cropped] = np.nan
    fused.sigma[cropped] = np.nan
    fused.undersampled &= fused.keep
    return cropped
