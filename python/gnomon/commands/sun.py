"""`gnomon sun --lat .. --lon .. --time ..`: where the sun is, seen from a site.

Prints the apparent (refracted) solar position by NREL SPA (pvlib) and the
unit vector towards the sun in East-North-Up — and in the world frame when
the heading of the world x axis is given (see :mod:`gnomon.light.ephemeris` for the
conventions).
"""

from __future__ import annotations

import argparse

import numpy as np

from gnomon.commands import COMMANDS
from gnomon.light.ephemeris import Site, SiteError, enu_to_world, parse_time, sun_position

#: The option of each :class:`gnomon.light.ephemeris.Site` field, for messages.
OPTIONS = {"latitude_deg": "--lat", "longitude_deg": "--lon", "altitude_m": "--alt", "pressure_pa": "--pressure",
           "temperature_c": "--temperature", "timezone": "--tz"}


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sun",
        help=COMMANDS["sun"],
        description="Print the sun's apparent azimuth (clockwise from north), elevation and zenith, and "
        "the unit vector towards the sun in East-North-Up (and in the world frame with --heading). "
        "Refraction uses --pressure and --temperature when given, else the pressure from --alt and 12 °C.",
    )
    p.add_argument("--lat", type=float, required=True, metavar="DEG", help="latitude, degrees north (±90)")
    p.add_argument("--lon", type=float, required=True, metavar="DEG", help="longitude, degrees east (±180)")
    p.add_argument(
        "--time",
        action="append",
        required=True,
        metavar="ISO",
        help="ISO 8601 time, e.g. 2003-10-17T12:30:30-07:00; without an offset it is local time in --tz. "
        "Repeat for several times",
    )
    p.add_argument("--alt", type=float, default=0.0, metavar="M", help="altitude above sea level, m (default 0)")
    p.add_argument("--pressure", type=float, metavar="PA", help="air pressure, Pa (e.g. 82000; default from --alt)")
    p.add_argument("--temperature", type=float, metavar="C", help="air temperature, °C (default 12)")
    p.add_argument("--tz", metavar="ZONE", help="time zone of naive times: IANA name (Europe/Paris) or offset "
                   "(UTC-07:00, or --tz=-07:00: a bare '-07:00' looks like an option to the parser)")
    p.add_argument(
        "--heading",
        type=float,
        metavar="DEG",
        help="compass heading of the world x axis, degrees clockwise from north (world z up): "
        "also print the sun vector in the world frame",
    )
    p.set_defaults(func=run)


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:+.6f}" for x in v) + "]"


def run(args: argparse.Namespace) -> int:
    from gnomon.util import validate

    validate.number(args.lat, "--lat")  # finite; the range is Site's to check
    validate.number(args.lon, "--lon")
    validate.number(args.alt, "--alt")
    for name in ("pressure", "temperature", "heading"):
        if getattr(args, name) is not None:
            validate.number(getattr(args, name), f"--{name}", positive=name == "pressure")
    try:
        site = Site(args.lat, args.lon, args.alt, args.pressure, args.temperature, args.tz)
    except SiteError as exc:
        raise exc.named(OPTIONS) from None
    times = [parse_time(t, site.timezone) for t in args.time]
    pos = sun_position(times, site)
    enu = pos.direction_enu
    ns = "N" if site.latitude_deg >= 0 else "S"
    ew = "E" if site.longitude_deg >= 0 else "W"
    print(
        f"site: {abs(site.latitude_deg):.6f}° {ns}, {abs(site.longitude_deg):.6f}° {ew}, {site.altitude_m:g} m; "
        f"refraction at {site.effective_pressure_pa:.0f} Pa, {site.effective_temperature_c:g} °C"
    )
    for i, (text, t) in enumerate(zip(args.time, pos.times, strict=True)):
        if i:
            print()
        local = f" ({t.tz_convert(site.tzinfo).isoformat()} local)" if site.tzinfo is not None else ""
        print(f"time:       {t.isoformat()}{local}  [input {text!r}]")
        print(f"azimuth:    {pos.azimuth_deg[i]:.5f}° (clockwise from north)")
        below = "  — below the horizon" if pos.apparent_elevation_deg[i] < 0 else ""
        print(f"elevation:  {pos.apparent_elevation_deg[i]:.5f}° (apparent){below}")
        print(f"zenith:     {pos.apparent_zenith_deg[i]:.5f}° (apparent)")
        print(f"sun ENU:    {_vec(enu[i])} (east, north, up; towards the sun)")
        if args.heading is not None:
            world = enu_to_world(enu[i], args.heading)
            print(f"sun world:  {_vec(world)} (world x at heading {args.heading:g}°, z up)")
    return 0
