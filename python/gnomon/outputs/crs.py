"""Coordinate reference systems of a scan's survey files (pyproj).

A georeferenced scan (a sun scan: report.json's ``site``) has its world frame tied to East-North-Up
metres at the site (:mod:`gnomon.light.georef`). Its survey files carry projected coordinates:
by default the site's UTM zone on WGS 84, any CRS pyproj knows on request (``[output] crs``). A
desk scan's files stay in the scan's own frame, declared as an engineering CRS whose unit is the
field log's (millimetre or metre), so that a reader knows the units.

ENU → projected: the ENU offsets are turned into Earth-centred (ECEF) coordinates here, from the
site's latitude, longitude and height on the WGS 84 ellipsoid (the closed-form rotation of a
local tangent frame), then pyproj takes ECEF to geodetic coordinates and on to the target CRS.

Heights: the site's altitude is given either above the WGS 84 ellipsoid
(``[site] altitude_datum = "ellipsoidal"``) or above the geoid ("orthometric", the altitude a map
gives; ``geoid`` names which: EGM2008 or EGM96). Converting one into the other needs the geoid's
grid, which PROJ does not ship; it is not needed: a scan spans at most a few hundred metres, over
which the geoid's height above the ellipsoid changes by millimetres, so the points' heights are
carried in the datum the site's altitude was given in, and the file's vertical CRS says which.
Using the orthometric altitude as the ellipsoidal one to place the local tangent frame moves the
points horizontally by at most (distance from the site) × (geoid height) / (Earth's radius):
0.8 mm at 100 m with a geoid 50 m above the ellipsoid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["ALTITUDE_DATUMS", "GEOIDS", "SurveyFrame", "local_crs", "survey_frame"]

#: How ``[site] altitude`` is measured.
ALTITUDE_DATUMS = ("orthometric", "ellipsoidal")
#: Geoids an orthometric altitude may be above, and the EPSG code of their height.
GEOIDS = {"EGM2008": 3855, "EGM96": 5773}

_WGS84_A = 6378137.0
_WGS84_F = 1.0 / 298.257223563
_WGS84_E2 = _WGS84_F * (2.0 - _WGS84_F)


@dataclass(frozen=True)
class SurveyFrame:
    """Where a georeferenced scan's points go: ``crs`` (a pyproj CRS, horizontal and vertical) and the
    function taking (N, 3) ENU metres at the site to (N, 3) float64 coordinates in it."""

    crs: Any  # pyproj.CRS
    description: str

    def from_enu(self, enu: np.ndarray, site: dict[str, Any]) -> np.ndarray:
        """(N, 3) float64 coordinates in :attr:`crs` of (N, 3) East-North-Up metres at ``site``."""
        from pyproj import Transformer

        ecef = enu_to_ecef(np.asarray(enu, dtype=np.float64).reshape(-1, 3), site)
        to_target = Transformer.from_crs("EPSG:4978", _horizontal_3d(self.crs), always_xy=True)
        x, y, z = to_target.transform(ecef[:, 0], ecef[:, 1], ecef[:, 2])
        # heights in the datum of the site's altitude (the ellipsoid's, or the geoid's: see the module)
        return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=1)


    def directions_from_enu(self, vectors: np.ndarray, site: dict[str, Any]) -> np.ndarray:
        """(N, 3) unit vectors along this CRS's axes of (N, 3) ENU directions (normals) near the site: the
        map's local Jacobian at the site (grid convergence and scale included), each vector renormalised."""
        steps = np.vstack([np.zeros(3), np.eye(3)])  # the site, and 1 m east, north and up of it
        at = self.from_enu(steps, site)
        jacobian = (at[1:] - at[0]).T  # column j: the image of ENU axis j
        out = np.asarray(vectors, dtype=np.float64).reshape(-1, 3) @ jacobian.T
        with np.errstate(invalid="ignore", divide="ignore"):
            return out / np.linalg.norm(out, axis=1, keepdims=True)


def _horizontal_3d(crs: Any) -> Any:
    """The 3D CRS (ellipsoidal heights) of a CRS's horizontal part, for pyproj's transformation."""
    horizontal = crs.sub_crs_list[0] if crs.is_compound else crs
    return horizontal.to_3d()


def enu_to_ecef(enu: np.ndarray, site: dict[str, Any]) -> np.ndarray:
    """(N, 3) ECEF metres of ENU offsets from the site (its latitude, longitude and altitude taken as
    the WGS 84 geodetic position of the ENU origin)."""
    lat, lon = np.radians(float(site["latitude_deg"])), np.radians(float(site["longitude_deg"]))
    h = float(site["altitude_m"])
    n = _WGS84_A / np.sqrt(1.0 - _WGS84_E2 * np.sin(lat) ** 2)
    origin = np.array([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                       (n * (1.0 - _WGS84_E2) + h) * np.sin(lat)])
    # columns: the local East, North and Up unit vectors in ECEF
    east = np.array([-np.sin(lon), np.cos(lon), 0.0])
    north = np.array([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    return origin + enu @ np.stack([east, north, up])


def survey_frame(site: dict[str, Any], crs: str | None = None) -> SurveyFrame:
    """The CRS of a georeferenced scan's survey files: ``crs`` (anything pyproj reads: "EPSG:2056",
    a WKT), else the site's UTM zone on WGS 84; with the site's vertical datum unless ``crs`` has one."""
    from pyproj import CRS
    from pyproj.aoi import AreaOfInterest
    from pyproj.database import query_utm_crs_info

    if crs is not None:
        horizontal = CRS.from_user_input(crs)
    else:
        lon, lat = float(site["longitude_deg"]), float(site["latitude_deg"])
        zone = query_utm_crs_info(datum_name="WGS 84", area_of_interest=AreaOfInterest(lon, lat, lon, lat))[0]
        horizontal = CRS.from_epsg(int(zone.code))
    if horizontal.is_compound or horizontal.is_vertical:
        return SurveyFrame(horizontal, horizontal.name)
    if site.get("altitude_datum", "ellipsoidal") == "orthometric":
        geoid = str(site.get("geoid", "EGM2008"))
        compound = CRS.from_json_dict({
            "type": "CompoundCRS", "name": f"{horizontal.name} + {geoid} height",
            "components": [horizontal.to_json_dict(), CRS.from_epsg(GEOIDS[geoid]).to_json_dict()]})
        return SurveyFrame(compound, compound.name)
    return SurveyFrame(horizontal.to_3d(), f"{horizontal.name}, heights above the WGS 84 ellipsoid")


def local_crs(units: str) -> Any:
    """An engineering CRS for a scan's own world frame (x, y, z in ``units``): no place on Earth, but
    the units a reader needs."""
    from pyproj import CRS

    name, factor = {"mm": ("millimetre", 0.001), "m": ("metre", 1.0)}[units]
    axes = ",".join(f'AXIS["{a}",{d},ORDER[{i}],LENGTHUNIT["{name}",{factor}]]'
                    for i, (a, d) in enumerate((("x", "east"), ("y", "north"), ("z", "up")), start=1))
    return CRS.from_wkt(f'ENGCRS["gnomon scan frame ({units})",EDATUM["the scan\'s world frame"],'
                        f'CS[Cartesian,3],{axes}]')
