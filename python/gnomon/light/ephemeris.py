"""The sun as a calibrated light: its direction from the site and the time.

Solar position comes from pvlib's implementation of NREL's Solar Position
Algorithm (SPA, Reda & Andreas 2004; ``method='nrel_numpy'``), whose stated
uncertainty is ±0.0003° over years −2000..6000. Gnomon uses the *apparent*
(refracted) topocentric position: refraction depends on the air pressure and
temperature, taken from the :class:`Site` when given; otherwise pressure
follows from the altitude (``pvlib.atmosphere.alt2pres``) and the temperature
is pvlib's default, 12 °C. ΔT (TT − UT1) is pvlib's default, 67 s: it only
moves the ephemeris (the sun travels ~1°/day along the ecliptic, so a few
seconds of ΔT error are ~1e-5°); the Earth's rotation uses the UTC time given.

Frames and angles
-----------------
* **Azimuth** in degrees, clockwise from true north (east = 90°); **elevation**
  above the horizon and **zenith** = 90° − elevation, degrees.
* **ENU**: local East-North-Up, a right-handed frame at the site. The sun
  direction is the unit vector *towards* the sun:
  ``(cos e·sin A, cos e·cos A, sin e)`` for azimuth A and elevation e.
* **World frame for sun scans**: world z is up and the world x
  axis points at compass heading ``heading_deg`` (clockwise from north), so
  world y = z × x is 90° anticlockwise of x, seen from above. Heading 90°
  (x east) makes the world frame ENU itself; heading 0° gives x north,
  y west. ``v_world = R_world_from_enu(heading_deg) @ v_enu``.

Times
-----
:func:`parse_time` reads ISO 8601 text. Times with a UTC offset (or ``Z``)
are taken as they are; naive times are local times in the site's time zone,
and an error when the site has none (a silent UTC guess can be hours wrong).
Times are returned and used in UTC.
"""

from __future__ import annotations

import datetime as dt
import math
import re
import zoneinfo
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
import pandas as pd

from gnomon.errors import GnomonError

TimeLike: TypeAlias = str | dt.datetime | pd.Timestamp | np.datetime64
TzLike: TypeAlias = str | dt.tzinfo | None

# Plausible ranges: a value outside is almost certainly a unit mistake
# (pressure in mbar or kPa instead of Pa, altitude in feet...).
_PRESSURE_RANGE_PA = (10_000.0, 120_000.0)
_TEMPERATURE_RANGE_C = (-90.0, 70.0)
_ALTITUDE_RANGE_M = (-1_000.0, 10_000.0)

_OFFSET_RE = re.compile(r"^(?:UTC|GMT)?\s*([+-])(\d{1,2})(?::?(\d{2}))?$", re.IGNORECASE)


def parse_timezone(tz: TzLike) -> dt.tzinfo | None:
    """A time zone from an IANA name (``"Europe/Paris"``), ``"UTC"``, a fixed
    offset (``"+02:00"``, ``"UTC-07:00"``, ``"-0700"``) or a tzinfo object."""
    if tz is None or isinstance(tz, dt.tzinfo):
        return tz
    if not isinstance(tz, str) or not tz.strip():
        raise GnomonError(f"time zone {tz!r} is not a zone name or a UTC offset")
    text = tz.strip()
    if text.upper() in ("UTC", "Z", "GMT"):
        return dt.UTC
    m = _OFFSET_RE.match(text)
    if m:
        sign, hours, minutes = m.group(1), int(m.group(2)), int(m.group(3) or 0)
        if hours > 14 or minutes >= 60:
            raise GnomonError(f"time zone offset {tz!r} is out of range (±14:00)")
        delta = dt.timedelta(hours=hours, minutes=minutes)
        return dt.timezone(-delta if sign == "-" else delta)
    try:
        return zoneinfo.ZoneInfo(text)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        raise GnomonError(
            f"unknown time zone {tz!r} (give an IANA name such as 'Europe/Paris' or an offset such as '+02:00')"
        ) from None


@dataclass(frozen=True)
class Site:
    """Where the capture happens.

    ``latitude_deg`` north positive (±90); ``longitude_deg`` east positive
    (±180); ``altitude_m`` above sea level (m); ``pressure_pa`` mean air
    pressure (Pa, e.g. 82000; default from the altitude); ``temperature_c``
    air temperature (°C; default 12 °C); ``timezone`` the zone of naive local
    timestamps: an IANA name, ``"UTC"``, a fixed offset ``"+02:00"`` or a
    tzinfo. Invalid values raise :class:`GnomonError`.
    """

    latitude_deg: float
    longitude_deg: float
    altitude_m: float = 0.0
    pressure_pa: float | None = None
    temperature_c: float | None = None
    timezone: TzLike = None

    def __post_init__(self) -> None:
        lat = _site_number("latitude_deg", self.latitude_deg)
        lon = _site_number("longitude_deg", self.longitude_deg)
        alt = _site_number("altitude_m", self.altitude_m)
        if abs(lat) > 90.0:
            raise SiteError("latitude_deg", f"{lat} is outside ±90°")
        if abs(lon) > 180.0:
            raise SiteError("longitude_deg", f"{lon} is outside ±180°")
        if not _ALTITUDE_RANGE_M[0] <= alt <= _ALTITUDE_RANGE_M[1]:
            raise SiteError("altitude_m", f"{alt} m is outside {_ALTITUDE_RANGE_M[0]:g}..{_ALTITUDE_RANGE_M[1]:g} m")
        object.__setattr__(self, "latitude_deg", lat)
        object.__setattr__(self, "longitude_deg", lon)
        object.__setattr__(self, "altitude_m", alt)
        if self.pressure_pa is not None:
            p = _site_number("pressure_pa", self.pressure_pa)
            if not _PRESSURE_RANGE_PA[0] <= p <= _PRESSURE_RANGE_PA[1]:
                hint = f" (give it in pascals: {p:g} mbar = {p * 100:g} Pa)" if 100 <= p <= 1200 else ""
                raise SiteError(
                    "pressure_pa", f"{p:g} Pa is outside {_PRESSURE_RANGE_PA[0]:g}..{_PRESSURE_RANGE_PA[1]:g} Pa{hint}"
                )
            object.__setattr__(self, "pressure_pa", p)
        if self.temperature_c is not None:
            t = _site_number("temperature_c", self.temperature_c)
            if not _TEMPERATURE_RANGE_C[0] <= t <= _TEMPERATURE_RANGE_C[1]:
                raise SiteError(
                    "temperature_c",
                    f"{t:g} °C is outside {_TEMPERATURE_RANGE_C[0]:g}..{_TEMPERATURE_RANGE_C[1]:g} °C",
                )
            object.__setattr__(self, "temperature_c", t)
        try:
            parse_timezone(self.timezone)  # validate now, not at the first naive timestamp
        except GnomonError as exc:
            raise SiteError("timezone", str(exc)) from None

    @property
    def tzinfo(self) -> dt.tzinfo | None:
        return parse_timezone(self.timezone)

    @property
    def effective_pressure_pa(self) -> float:
        """The pressure used for refraction: given, or pvlib's from the altitude."""
        if self.pressure_pa is not None:
            return self.pressure_pa
        from pvlib.atmosphere import alt2pres

        return float(alt2pres(self.altitude_m))

    @property
    def effective_temperature_c(self) -> float:
        """The temperature used for refraction: given, or pvlib's default 12 °C."""
        return 12.0 if self.temperature_c is None else self.temperature_c


class SiteError(GnomonError):
    """An invalid :class:`Site` value. ``field`` is the :class:`Site` field it concerns
    (``latitude_deg``, …) and ``detail`` the problem, so that a caller can name its own
    option or key for it (:meth:`SiteError.named`)."""

    def __init__(self, field: str, detail: str) -> None:
        super().__init__(f"Site {field}: {detail}")
        self.field = field
        self.detail = detail

    def named(self, names: Mapping[str, str], prefix: str = "") -> GnomonError:
        """The same error naming the caller's option or key for the field, e.g.
        ``err.named({"latitude_deg": "--lat"})`` → ``--lat: 95.0 is outside ±90°``."""
        return GnomonError(f"{prefix}{names.get(self.field, self.field)}: {self.detail}")


def _site_number(field: str, value: object) -> float:
    try:
        return _finite("value", value)
    except GnomonError:
        number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
        kind = "a finite number" if number else "a number"
        raise SiteError(field, f"{value!r} is not {kind}") from None


def _finite(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GnomonError(f"{name} {value!r} is not a number")
    v = float(value)
    if not math.isfinite(v):
        raise GnomonError(f"{name} {value!r} is not a finite number")
    return v


def parse_time(text: TimeLike, site_tz: TzLike = None) -> pd.Timestamp:
    """An ISO 8601 timestamp → a tz-aware ``pd.Timestamp`` in UTC.

    ``"2003-10-17T12:30:30-07:00"``, ``"2003-10-17 19:30:30Z"`` are taken as
    they are. A naive ``"2003-10-17T12:30:30"`` is a local time in
    ``site_tz`` (zone name, offset or tzinfo); without ``site_tz`` it is a
    :class:`GnomonError`. Local times that do not exist or are ambiguous (a
    daylight-saving change) are errors too. datetime / Timestamp objects are
    accepted with the same rules.
    """
    if isinstance(text, str):
        s = text.strip()
        try:
            # Python ≥ 3.11 reads ISO 8601 (basic or extended, 'Z', fractions);
            # stricter than pd.Timestamp, which also takes words like 'now'.
            parsed = dt.datetime.fromisoformat(s)
        except ValueError:
            raise GnomonError(
                f"time {text!r} is not an ISO 8601 timestamp (e.g. 2003-10-17T12:30:30-07:00)"
            ) from None
        ts = pd.Timestamp(parsed)
    elif isinstance(text, (dt.datetime, pd.Timestamp, np.datetime64)):
        ts = pd.Timestamp(text)
    else:
        raise GnomonError(f"time {text!r} is not an ISO 8601 string or a datetime")
    if ts.tzinfo is None:
        return localize(ts, site_tz, f"time '{text}'")
    return ts.tz_convert("UTC")


def localize(naive: dt.datetime | pd.Timestamp, tz: TzLike, where: str) -> pd.Timestamp:
    """A naive local time in the zone ``tz`` → a tz-aware ``pd.Timestamp`` in UTC.

    ``tz`` as for :func:`parse_timezone`. Raises :class:`GnomonError` starting
    with ``where`` (e.g. the file the time came from) when there is no zone,
    or when the local time does not exist or is ambiguous (a daylight-saving
    change) in it.
    """
    zone = parse_timezone(tz)
    if zone is None:
        raise GnomonError(f"{where}: no UTC offset, and the site has no timezone "
                          "(give the site's time zone, or times with a UTC offset such as -07:00)")
    ts = pd.Timestamp(naive)
    try:
        ts = ts.tz_localize(zone, ambiguous="raise", nonexistent="raise")
    except ValueError:
        # pandas raises ValueError subclasses for both cases; tell them apart.
        gap = ts.tz_localize(zone, ambiguous=True, nonexistent="NaT") is pd.NaT
        what = "does not exist (skipped by a clock change)" if gap else "is ambiguous (repeated by a clock change)"
        raise GnomonError(f"{where}: local time {ts.isoformat()} {what} in {tz}: "
                          "give an explicit UTC offset") from None
    return ts.tz_convert("UTC")


def _times_index(times: TimeLike | Iterable[TimeLike] | pd.DatetimeIndex, site: Site) -> pd.DatetimeIndex:
    if isinstance(times, pd.DatetimeIndex):
        if times.tz is None:
            return pd.DatetimeIndex([parse_time(t, site.timezone) for t in times])
        return times.tz_convert("UTC")
    if isinstance(times, (str, dt.datetime, pd.Timestamp, np.datetime64)):
        times = [times]
    return pd.DatetimeIndex([parse_time(t, site.timezone) for t in times])


@dataclass(frozen=True)
class SunPosition:
    """Topocentric solar position at each time, degrees.

    ``apparent_zenith_deg`` / ``apparent_elevation_deg`` include atmospheric
    refraction (what the shadow sees); ``zenith_deg`` is the geometric
    (unrefracted) zenith; ``azimuth_deg`` is clockwise from true north.
    ``times`` are UTC.
    """

    times: pd.DatetimeIndex
    apparent_zenith_deg: np.ndarray
    apparent_elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    zenith_deg: np.ndarray

    @property
    def direction_enu(self) -> np.ndarray:
        """(N, 3) unit vectors towards the sun in East-North-Up."""
        return direction_from_angles(self.azimuth_deg, self.apparent_elevation_deg)


def direction_from_angles(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """Azimuth (clockwise from north) and elevation, degrees → (N, 3) unit ENU vectors."""
    a = np.radians(np.atleast_1d(np.asarray(azimuth_deg, dtype=np.float64)))
    e = np.radians(np.atleast_1d(np.asarray(elevation_deg, dtype=np.float64)))
    ce = np.cos(e)
    return np.stack([ce * np.sin(a), ce * np.cos(a), np.sin(e)], axis=-1)


def sun_position(
    times: TimeLike | Iterable[TimeLike] | pd.DatetimeIndex, site: Site, *, delta_t_s: float = 67.0
) -> SunPosition:
    """Solar position by NREL SPA (pvlib ``nrel_numpy``) at each time.

    ``times``: one time or a sequence of them (ISO strings, datetimes,
    Timestamps) or a DatetimeIndex; naive ones are read in the site's time
    zone (see :func:`parse_time`). ``delta_t_s``: TT − UT1 in seconds.
    """
    from pvlib.solarposition import get_solarposition

    index = _times_index(times, site)
    kwargs = {}
    if site.temperature_c is not None:
        kwargs["temperature"] = site.temperature_c
    df = get_solarposition(
        index,
        site.latitude_deg,
        site.longitude_deg,
        altitude=site.altitude_m,
        pressure=site.pressure_pa,  # None → pvlib.atmosphere.alt2pres(altitude)
        method="nrel_numpy",
        delta_t=delta_t_s,
        **kwargs,
    )
    return SunPosition(
        times=index,
        apparent_zenith_deg=df["apparent_zenith"].to_numpy(dtype=np.float64),
        apparent_elevation_deg=df["apparent_elevation"].to_numpy(dtype=np.float64),
        azimuth_deg=df["azimuth"].to_numpy(dtype=np.float64),
        zenith_deg=df["zenith"].to_numpy(dtype=np.float64),
    )


def sun_direction_enu(times: TimeLike | Iterable[TimeLike] | pd.DatetimeIndex, site: Site) -> np.ndarray:
    """(N, 3) unit vectors towards the sun in East-North-Up (apparent position)."""
    return sun_position(times, site).direction_enu


def R_world_from_enu(heading_deg: float) -> np.ndarray:
    """The rotation taking ENU vectors to the world frame: ``v_world = R @ v_enu``.

    The world frame has z up and its x axis at compass heading ``heading_deg``
    (clockwise from north); y = z × x. Its rows are the world axes written in
    ENU: x = (sin h, cos h, 0), y = (−cos h, sin h, 0), z = (0, 0, 1).
    """
    h = math.radians(_finite("heading", heading_deg))
    s, c = math.sin(h), math.cos(h)
    return np.array([[s, c, 0.0], [-c, s, 0.0], [0.0, 0.0, 1.0]])


def enu_to_world(vectors_enu: np.ndarray, heading_deg: float) -> np.ndarray:
    """ENU vectors (N, 3) or (3,) → world frame (same shape); see :func:`R_world_from_enu`."""
    return np.asarray(vectors_enu, dtype=np.float64) @ R_world_from_enu(heading_deg).T


def world_to_enu(vectors_world: np.ndarray, heading_deg: float) -> np.ndarray:
    """World-frame vectors (N, 3) or (3,) → ENU (same shape); the inverse of :func:`enu_to_world`."""
    return np.asarray(vectors_world, dtype=np.float64) @ R_world_from_enu(heading_deg)
