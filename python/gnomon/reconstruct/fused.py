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
)
from gnomon.config.setup import ScanSetup
from gnomon.geometry.crop import crop_mask
from gnomon.geometry.surface import points_from_depth
from gnomon.geometry.uncertainty import (
    MIN_FRAMES_PER_TRANSITION,
    undersampled,
)
from gnomon.light.base import LightModel
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
    stack = np.stack(maps)
    n = np.isfinite(stack).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.nansum(stack, axis=0) / np.maximum(n, 1), np.nan).astype(np.float32)


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
