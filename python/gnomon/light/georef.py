"""Georeferencing a sun scan: the world frame in East-North-Up metres at the site.

A sun scan's world frame has z up and its x axis at the compass heading
``heading_deg`` (``[site] heading_deg`` or measured from a gnomon); its origin
is taken to be at the ``[site]`` latitude, longitude and altitude. Then

    X_enu = s · R_enu_from_world · X_world

with ``s`` the metres per world unit: a local East-North-Up frame (metres)
with its origin at the site, which GIS tools place on the WGS84 ellipsoid
from the site's coordinates (written into the files and report.json).
"""

from __future__ import annotations

import numpy as np

from gnomon.light.ephemeris import R_world_from_enu

__all__ = ["METRES_PER_UNIT", "world_to_enu_matrix", "points_to_enu", "georeference_report"]

#: Metres per world unit, for the units a field log may declare.
METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}


def world_to_enu_matrix(heading_deg: float, units: str) -> np.ndarray:
    """(4, 4) homogeneous transform from world coordinates (world units) to ENU metres."""
    if units not in METRES_PER_UNIT:
        raise ValueError(f"unknown units {units!r} (one of {sorted(METRES_PER_UNIT)})")
    m = np.eye(4)
    m[:3, :3] = METRES_PER_UNIT[units] * R_world_from_enu(heading_deg).T
    return m


def points_to_enu(points_world: np.ndarray, heading_deg: float, units: str) -> np.ndarray:
    """(N, 3) float64 East, North, Up metres of (N, 3) world points."""
    m = world_to_enu_matrix(heading_deg, units)
    return np.asarray(points_world, dtype=np.float64).reshape(-1, 3) @ m[:3, :3].T


def georeference_report(latitude_deg: float, longitude_deg: float, altitude_m: float, heading_deg: float,
                        units: str) -> dict:
    """The ``site`` entry of report.json: where the world origin is and how to get to ENU."""
    return {
        "latitude_deg": float(latitude_deg),
        "longitude_deg": float(longitude_deg),
        "altitude_m": float(altitude_m),
        "datum": "WGS84",
        "world_origin": "at the site",
        "world_to_enu": world_to_enu_matrix(heading_deg, units).tolist(),
        "world_to_enu_note": "X_enu (m, East North Up at the site) = M[:3, :3] @ X_world + M[:3, 3]",
    }
