"""Accuracy of a scan against the simulator's ground truth.

Errors are measured on the ground truth's *swept* pixels (the simulator
documents that mask: directly lit, crossed by the shadow inside the sequence,
not mixed at an occlusion boundary). Coverage is the fraction of them that
received a depth.

Errors over swept pixels cannot see points written where nothing was
measured, so every output point is also judged: the **false-point rate** is
the share of output points

* on a pixel where the ground truth has no swept surface (no surface, or a
  surface the shadow never crossed while it was lit: the truth's
  ``swept_surface``, falling back to ``swept`` for older captures), or
* farther from the true depth than ``FALSE_SIGMAS`` times the point's own
  σZ *and* than ``GROSS_FRACTION`` of the camera distance.

Gross errors (farther than ``GROSS_FRACTION`` of the distance, whatever σ)
are counted over all output points too.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["FALSE_SIGMAS", "GROSS_FRACTION", "DepthAccuracy", "depth_accuracy", "false_points"]

FALSE_SIGMAS = 5.0
GROSS_FRACTION = 0.01  # of the camera distance


@dataclass(frozen=True)
class DepthAccuracy:
    """Depth errors (camera Z) in world units and as % of the camera distance.

    ``rms`` … ``coverage`` are over the swept pixels; ``output_points``,
    ``false_points``, ``false_point_rate``, ``gross_points`` and
    ``gross_rate`` over every output point (rates 0..1).
    """

    rms: float
    median_abs: float
    p95_abs: float
    mean: float  # signed: a bias shows here
    rms_pct: float
    median_pct: float
    p95_pct: float
    coverage: float  # of swept pixels, 0..1
    swept_pixels: int
    measured_pixels: int
    camera_distance: float
    units: str = "mm"
    output_points: int = 0
    false_points: int = 0
    false_point_rate: float = 0.0
    gross_points: int = 0
    gross_rate: float = 0.0
    rms_all_points: float = float("nan")  # over every output point with a true surface

    def as_dict(self) -> dict:
        return asdict(self)

    def table(self, title: str) -> str:
        u = self.units
        return "\n".join([
            f"{title}",
            f"  depth error RMS     {self.rms:8.3f} {u}   {self.rms_pct:6.3f} % of {self.camera_distance:.0f} {u}",
            f"  depth error median  {self.median_abs:8.3f} {u}   {self.median_pct:6.3f} %",
            f"  depth error p95     {self.p95_abs:8.3f} {u}   {self.p95_pct:6.3f} %",
            f"  mean (bias)         {self.mean:+8.3f} {u}",
            f"  coverage            {100 * self.coverage:7.2f} % of {self.swept_pixels} swept pixels",
            (f"  false points        {100 * self.false_point_rate:7.2f} % of {self.output_points} output points "
             f"({self.false_points}: nothing swept there, or > {FALSE_SIGMAS:g} σ and "
             f"> {100 * GROSS_FRACTION:g} % off)"),
            (f"  gross errors        {100 * self.gross_rate:7.2f} % of output points "
             f"(> {100 * GROSS_FRACTION:g} % of the distance off)"),
        ])


def false_points(depth: np.ndarray, sigma: np.ndarray | None, truth_depth: np.ndarray,
                 swept_surface: np.ndarray, camera_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Masks (H, W) of false points and of gross errors among the output points (finite ``depth``).

    ``sigma``: each point's σZ (world units); None or NaN counts as 0, so that
    only the distance test applies.
    """
    points = np.isfinite(depth)
    surface = swept_surface & np.isfinite(truth_depth)
    with np.errstate(invalid="ignore"):
        err = np.abs(depth - truth_depth)
        gross = points & np.isfinite(truth_depth) & (err > GROSS_FRACTION * camera_distance)
        sig = np.zeros_like(err) if sigma is None else np.nan_to_num(np.asarray(sigma, dtype=np.float64))
        far = gross & (err > FALSE_SIGMAS * sig)
    false = points & (~surface | far)
    gross = gross | (points & ~np.isfinite(truth_depth))  # a point in the sky is as wrong as it gets
    return false, gross


def depth_accuracy(depth: np.ndarray, truth_depth: np.ndarray, swept: np.ndarray,
                   camera_distance: float, units: str = "mm", *, sigma: np.ndarray | None = None,
                   swept_surface: np.ndarray | None = None) -> DepthAccuracy:
    """Compare a depth map with the true one over the swept pixels, and judge every output point.

    ``sigma``: the scan's σZ map (for the false-point test); ``swept_surface``:
    the truth's mask of surfaces the shadow crossed while lit (default ``swept``).
    """
    surface_mask = swept if swept_surface is None else swept_surface
    swept = swept & np.isfinite(truth_depth)
    measured = swept & np.isfinite(depth)
    err = (depth - truth_depth)[measured].astype(np.float64)
    n_swept = int(swept.sum())
    false, gross = false_points(depth, sigma, truth_depth, surface_mask, camera_distance)
    n_out = int(np.isfinite(depth).sum())
    with_truth = np.isfinite(depth) & np.isfinite(truth_depth)
    all_err = (depth - truth_depth)[with_truth].astype(np.float64)
    if err.size:
        a = np.abs(err)
        rms, med, p95, mean = (float(np.sqrt(np.mean(err**2))), float(np.median(a)), float(np.percentile(a, 95)),
                               float(err.mean()))
        coverage, n_measured = float(measured.sum() / max(n_swept, 1)), int(measured.sum())
    else:
        rms = med = p95 = mean = float("nan")
        coverage, n_measured = 0.0, 0
    pct = 100.0 / camera_distance
    return DepthAccuracy(
        rms, med, p95, mean, rms * pct, med * pct, p95 * pct, coverage, n_swept, n_measured, camera_distance, units,
        output_points=n_out, false_points=int(false.sum()), false_point_rate=float(false.sum() / max(n_out, 1)),
        gross_points=int(gross.sum()), gross_rate=float(gross.sum() / max(n_out, 1)),
        rms_all_points=float(np.sqrt(np.mean(all_err**2))) if all_err.size else float("nan"),
    )
