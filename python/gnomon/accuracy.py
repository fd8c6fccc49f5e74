"""Accuracy of a scan against the simulator's ground truth.

Errors are measured on the ground truth's *swept* pixels (the simulator
documents that mask: directly lit, crossed by the shadow inside the sequence,
not mixed at an occlusion boundary). Coverage is the fraction of them that
received a depth.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class DepthAccuracy:
    """Depth errors (camera Z) in world units and as % of the camera distance."""

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
        ])


def depth_accuracy(depth: np.ndarray, truth_depth: np.ndarray, swept: np.ndarray,
                   camera_distance: float, units: str = "mm") -> DepthAccuracy:
    """Compare a depth map with the true one over the swept pixels."""
    swept = swept & np.isfinite(truth_depth)
    measured = swept & np.isfinite(depth)
    err = (depth - truth_depth)[measured].astype(np.float64)
    n_swept = int(swept.sum())
    if err.size == 0:
        nan = float("nan")
        return DepthAccuracy(nan, nan, nan, nan, nan, nan, nan, 0.0, n_swept, 0, camera_distance, units)
    a = np.abs(err)
    rms = float(np.sqrt(np.mean(err**2)))
    med = float(np.median(a))
    p95 = float(np.percentile(a, 95))
    pct = 100.0 / camera_distance
    return DepthAccuracy(rms, med, p95, float(err.mean()), rms * pct, med * pct, p95 * pct,
                         measured.sum() / max(n_swept, 1), n_swept, int(measured.sum()), camera_distance, units)
