"""Stations of a georeferenced survey placed by their georeference, before any registration.

A sun scan's ``report.json`` ``site`` says where its world frame is on Earth: the origin's
latitude, longitude and altitude (WGS 84) and ``world_to_enu`` (the heading and the units). Each
station's world frame goes to East-North-Up metres at its own site, to Earth-centred coordinates,
and back down into the reference station's ENU and world frame: the prior pose ICP starts from.

The georeference's stated uncertainty: ``site.position_sigma_m`` (``[site] position_sigma_m``:
how well the site's position is known, e.g. 3 m for a phone's GNSS, 0.02 m for a surveyed
mark) and the heading's σ (``sun.heading_sigma_deg``: from the gnomon measurement, or
``[site] heading_sigma_deg``). A scan that states neither is taken at :data:`DEFAULT_POSITION_SIGMA_M`
and :data:`DEFAULT_HEADING_SIGMA_DEG`, and the report says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon.errors import GnomonError
from gnomon.fuse.views import View
from gnomon.light.georef import METRES_PER_UNIT
from gnomon.outputs.crs import enu_to_ecef

__all__ = ["StationPrior", "station_priors", "DEFAULT_POSITION_SIGMA_M", "DEFAULT_HEADING_SIGMA_DEG"]

#: A site position typed from a phone or a map, m (1σ), when the scan states none.
DEFAULT_POSITION_SIGMA_M = 3.0
#: A heading typed from a compass or a map, degrees (1σ), when the scan states none.
DEFAULT_HEADING_SIGMA_DEG = 1.0


@dataclass
class StationPrior:
    """A station's pose from its georeference: ``pose`` (4, 4) its world frame → the reference station's
    world frame (world units); σ of its position (world units) and heading (degrees); ``stated``
    whether the scan gave both (``assumed`` says which defaults stand in)."""

    pose: np.ndarray
    sigma_position: float
    sigma_heading_deg: float
    stated: bool
    assumed: tuple[str, ...] = ()  # what was not stated and is taken at its default, in words


def _world_to_ecef(site: dict, where: str) -> tuple[np.ndarray, np.ndarray]:
    """(R, t): ECEF metres = R @ X_world + t, for a scan's site."""
    try:
        M = np.asarray(site["world_to_enu"], dtype=np.float64)
        origin = enu_to_ecef(np.zeros((1, 3)), site)[0]
        axes = enu_to_ecef(np.eye(3), site) - origin  # rows: East, North, Up in ECEF
    except (KeyError, TypeError, ValueError) as exc:
        raise GnomonError(f"{where}: site: not a georeference ({exc})") from None
    R = axes.T @ M[:3, :3]
    return R, axes.T @ M[:3, 3] + origin


def station_priors(views: list[View]) -> list[StationPrior]:
    """Every station's prior pose in the reference (first) station's world frame, with its σ."""
    out = []
    ref = views[0]
    assert ref.site is not None
    R0, t0 = _world_to_ecef(ref.site, str(ref.folder / "report.json"))
    for v in views:
        assert v.site is not None
        R, t = _world_to_ecef(v.site, str(v.folder / "report.json"))
        T = np.eye(4)
        T[:3, :3] = np.linalg.solve(R0, R)
        T[:3, 3] = np.linalg.solve(R0, t - t0)
        scale = METRES_PER_UNIT.get(v.units, 1.0)
        pos = v.site.get("position_sigma_m")
        head = (v.report.get("sun") or {}).get("heading_sigma_deg") or v.site.get("heading_sigma_deg")
        assumed = tuple(([] if pos is not None else [f"position σ {DEFAULT_POSITION_SIGMA_M:g} m"])
                        + ([] if head is not None else [f"heading σ {DEFAULT_HEADING_SIGMA_DEG:g}°"]))
        out.append(StationPrior(T, float(pos if pos is not None else DEFAULT_POSITION_SIGMA_M) / scale,
                                float(head if head is not None else DEFAULT_HEADING_SIGMA_DEG), not assumed,
                                assumed))
    return out
