"""``[output] crop``: keep only the object (by a box or by height above a reference plane), or only
the points whose predicted σ is small enough.

An object scan sees the desk too. A crop removes points (and the mesh over
them) before anything is written:

* ``box``: an axis-aligned box in world coordinates, ``[[xmin, ymin, zmin],
  [xmax, ymax, zmax]]`` (world units);
* ``above``: the name of a ``[[planes]]`` entry, with ``min_height`` (and an
  optional ``max_height``): the signed distance from that plane, positive on
  the side the camera looks from (world units), must lie in that range.

* ``max_sigma``: the largest predicted depth σ (world units) a point may
  have: a point as uncertain as that is dropped, whatever its place (a
  real capture's faces lit only indirectly, dark paper, grazing rays; the
  σ is each point's own, ``points.ply``'s ``sigma``).

Any of them may be given; a point must then pass all. The test is per point, on
the world coordinates the scan produced (so a point that is noisy by σ near
the threshold may fall either side: choose ``min_height`` a few σ above the
plane).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Crop", "crop_mask"]


@dataclass(frozen=True)
class Crop:
    """A resolved crop (world frame, world units); ``None`` fields are not applied."""

    box_min: np.ndarray | None = None  # (3,)
    box_max: np.ndarray | None = None  # (3,)
    plane_name: str | None = None
    plane_point: np.ndarray | None = None  # (3,)
    plane_normal: np.ndarray | None = None  # (3,) unit
    min_height: float = 0.0
    max_height: float | None = None
    max_sigma: float | None = None  # world units

    def to_report(self) -> dict:
        out: dict = {}
        if self.box_min is not None and self.box_max is not None:
            out["box"] = [self.box_min.tolist(), self.box_max.tolist()]
        if self.plane_name is not None:
            out["above"] = self.plane_name
            out["min_height"] = self.min_height
            out["max_height"] = self.max_height
        if self.max_sigma is not None:
            out["max_sigma"] = self.max_sigma
        return out


def crop_mask(points_world: np.ndarray, crop: Crop, camera_centre_world: np.ndarray,
              sigma: np.ndarray | None = None) -> np.ndarray:
    """(N,) bool: the points (N, 3) world coordinates that the crop keeps.

    NaN points are never kept. The plane's normal is turned towards the
    camera centre, so "above" is the side the camera sees. ``sigma`` (N,):
    each point's predicted depth σ (world units), needed by ``max_sigma``
    (a NaN σ is not within it).
    """
    p = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    keep = np.all(np.isfinite(p), axis=1)
    if crop.max_sigma is not None:
        if sigma is None or np.shape(sigma) != (len(p),):
            raise ValueError(f"max_sigma needs one sigma per point ({len(p)}), got "
                             f"{None if sigma is None else np.shape(sigma)}")
        with np.errstate(invalid="ignore"):
            keep &= np.asarray(sigma) <= crop.max_sigma
    if crop.box_min is not None and crop.box_max is not None:
        with np.errstate(invalid="ignore"):
            keep &= np.all((p >= crop.box_min) & (p <= crop.box_max), axis=1)
    if crop.plane_point is not None and crop.plane_normal is not None:
        n = np.asarray(crop.plane_normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        q = np.asarray(crop.plane_point, dtype=np.float64)
        if float(n @ (np.asarray(camera_centre_world, dtype=np.float64) - q)) < 0:
            n = -n
        with np.errstate(invalid="ignore"):
            h = (p - q) @ n
            keep &= h >= crop.min_height
            if crop.max_height is not None:
                keep &= h <= crop.max_height
    return keep
