"""The sun model: NREL SPA via pvlib, ENU and world frames, time parsing, `gnomon sun`."""

from __future__ import annotations

import argparse
import datetime as dt

import numpy as np
import pytest

from gnomon.commands import sun as sun_command
from gnomon.errors import GnomonError
from gnomon.light.ephemeris import (
    R_world_from_enu,
    Site,
    direction_from_angles,
    enu_to_world,
    parse_time,
    sun_direction_enu,
    sun_position,
    world_to_enu,
)

# Reda & Andreas (2004), table A5.1 / NREL SPA's spa_tester: Golden, Colorado.
SPA_SITE = dict(latitude_deg=39.742476, longitude_deg=-105.1786, altitude_m=1830.14,
                pressure_pa=82000.0, temperature_c=11.0)
SPA_TIME = "2003-10-17T12:30:30-07:00"
SPA_ZENITH_DEG = 50.11162  # topocentric, refraction included
SPA_AZIMUTH_DEG = 194.34024  # clockwise from north


def test_nrel_spa_reference_case():
    pos = sun_position(SPA_TIME, Site(**SPA_SITE), delta_t_s=67.0)
    assert abs(pos.apparent_zenith_deg[0] - SPA_ZENITH_DEG) < 0.001
    assert abs(pos.azimuth_deg[0] - SPA_AZIMUTH_DEG) < 0.001
    assert abs(pos.apparent_elevation_deg[0] - (90.0 - SPA_ZENITH_DEG)) < 0.001
    # The published zenith is the refracted one: the geometric zenith is ~0.016° larger.
    assert pos.zenith_deg[0] - pos.apparent_zenith_deg[0] > 0.01


def test_naive_time_in_the_site_zone_equals_the_offset_time():
    site = Site(**SPA_SITE, timezone="America/Denver")  # MDT on 2003-10-17: UTC−6, not −7
    assert parse_time("2003-10-17T13:30:30", site.timezone) == parse_time(SPA_TIME)
    fixed = Site(**SPA_SITE, timezone="UTC-07:00")
    pos = sun_position("2003-10-17T12:30:30", fixed)
    assert abs(pos.apparent_zenith_deg[0] - SPA_ZENITH_DEG) < 0.001


def test_pressure_defaults_to_the_altitude():
    from pvlib.atmosphere import alt2pres

    implicit = sun_position(SPA_TIME, Site(39.742476, -105.1786, 1830.14))
    explicit = sun_position(SPA_TIME, Site(39.742476, -105.1786, 1830.14, pressure_pa=float(alt2pres(1830.14))))
    np.testing.assert_allclose(implicit.apparent_zenith_deg, explicit.apparent_zenith_deg, atol=1e-12)
    assert Site(0, 0, 1830.14).effective_pressure_pa == pytest.approx(float(alt2pres(1830.14)))


def test_sun_direction_is_a_unit_vector_matching_the_angles():
    site = Site(48.8566, 2.3522, 35.0, timezone="Europe/Paris")
    times = [f"2024-06-21T{h:02d}:00" for h in range(0, 24, 2)]
    pos = sun_position(times, site)
    d = sun_direction_enu(times, site)
    assert d.shape == (len(times), 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.degrees(np.arcsin(d[:, 2])), pos.apparent_elevation_deg, atol=1e-9)
    np.testing.assert_allclose(np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360.0, pos.azimuth_deg, atol=1e-9)


def test_elevation_sign_noon_and_midnight():
    site = Site(48.8566, 2.3522, timezone="Europe/Paris")
    noon, midnight = sun_position(["2024-06-21T13:50", "2024-06-22T01:50"], site).apparent_elevation_deg
    assert noon > 60 and midnight < -15
    # Southern hemisphere at local noon: the sun is to the north.
    sydney = sun_position("2024-12-21T13:00+11:00", Site(-33.8688, 151.2093))
    assert sydney.apparent_elevation_deg[0] > 70
    assert sydney.direction_enu[0, 1] > 0


def test_direction_from_angles_cardinal_points():
    np.testing.assert_allclose(direction_from_angles([0, 90, 180, 270], [0, 0, 0, 0]),
                               [[0, 1, 0], [1, 0, 0], [0, -1, 0], [-1, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(direction_from_angles(123.0, 90.0), [[0, 0, 1]], atol=1e-15)


def test_enu_world_rotation():
    np.testing.assert_allclose(R_world_from_enu(90.0), np.eye(3), atol=1e-15)  # x east: world = ENU
    north, east, up = np.eye(3)[1], np.eye(3)[0], np.eye(3)[2]
    np.testing.assert_allclose(enu_to_world(north, 0.0), [1, 0, 0], atol=1e-15)  # x north ...
    np.testing.assert_allclose(enu_to_world(east, 0.0), [0, -1, 0], atol=1e-15)  # ... so y west
    np.testing.assert_allclose(enu_to_world(up, 37.0), [0, 0, 1], atol=1e-15)
    for heading in (-20.0, 30.0, 200.0):
        R = R_world_from_enu(heading)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
        assert np.linalg.det(R) == pytest.approx(1.0)
        x_axis_enu = direction_from_angles(heading, 0.0)[0]
        np.testing.assert_allclose(enu_to_world(x_axis_enu, heading), [1, 0, 0], atol=1e-15)
        v = np.random.default_rng(1).normal(size=(5, 3))
        np.testing.assert_allclose(world_to_enu(enu_to_world(v, heading), heading), v, atol=1e-14)


def test_parse_time_forms():
    utc = parse_time("2003-10-17T19:30:30Z")
    assert str(utc.tz) == "UTC"
    assert parse_time(SPA_TIME) == utc
    assert parse_time("20031017T193030Z") == utc
    assert parse_time("2003-10-17 21:30:30.000", "Europe/Paris") == utc
    assert parse_time(dt.datetime(2003, 10, 17, 19, 30, 30, tzinfo=dt.UTC)) == utc


@pytest.mark.parametrize(
    "call, expected",
    [
        (lambda: Site(95.0, 0.0), "Site latitude_deg: 95.0 is outside ±90°"),
        (lambda: Site(-90.5, 0.0), "Site latitude_deg: -90.5 is outside ±90°"),
        (lambda: Site(0.0, 181.0), "Site longitude_deg: 181.0 is outside ±180°"),
        (lambda: Site(float("nan"), 0.0), "Site latitude_deg: nan is not a finite number"),
        (lambda: Site(0.0, 0.0, pressure_pa=820.0), "(give it in pascals: 820 mbar = 82000 Pa)"),
        (lambda: Site(0.0, 0.0, temperature_c=300.0), "Site temperature_c: 300 °C is outside"),
        (lambda: Site(0.0, 0.0, timezone="Mars/Olympus"), "Site timezone: unknown time zone 'Mars/Olympus'"),
        (lambda: parse_time("2003-10-17T12:30:30"),
         "time '2003-10-17T12:30:30': no UTC offset, and the site has no timezone"),
        (lambda: sun_position("2003-10-17T12:30:30", Site(0.0, 0.0)),
         "time '2003-10-17T12:30:30': no UTC offset, and the site has no timezone"),
        (lambda: parse_time("17/10/2003 12:30"), "is not an ISO 8601 timestamp"),
        (lambda: parse_time("now"), "is not an ISO 8601 timestamp"),
        (lambda: parse_time("2024-03-31T02:30", "Europe/Paris"), "does not exist"),
        (lambda: parse_time("2024-10-27T02:30", "Europe/Paris"), "is ambiguous"),
        (lambda: R_world_from_enu(float("inf")), "heading inf is not a finite number"),
    ],
)
def test_bad_input_is_one_clear_line(call, expected):
    with pytest.raises(GnomonError) as excinfo:
        call()
    assert expected in str(excinfo.value)
    assert "\n" not in str(excinfo.value)


# ------------------------------------------------------------------ `gnomon sun`


def run_sun(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="gnomon")
    sun_command.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["sun", *argv])
    return args.func(args)


def test_sun_command_prints_the_spa_case(capsys):
    rc = run_sun(["--lat", "39.742476", "--lon", "-105.1786", "--alt", "1830.14", "--pressure", "82000",
                  "--temperature", "11", "--time", "2003-10-17T12:30:30", "--tz=-07:00", "--heading", "30"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "azimuth:    194.3402" in out
    assert "elevation:  39.8883" in out
    assert "zenith:     50.1116" in out
    enu_line = next(line for line in out.splitlines() if line.startswith("sun ENU:"))
    world_line = next(line for line in out.splitlines() if line.startswith("sun world:"))
    enu = np.array([float(x) for x in enu_line.split("[")[1].split("]")[0].split(",")])
    world = np.array([float(x) for x in world_line.split("[")[1].split("]")[0].split(",")])
    np.testing.assert_allclose(world, enu_to_world(enu, 30.0), atol=2e-6)


def test_sun_command_several_times_without_heading(capsys):
    assert run_sun(["--lat", "48.85", "--lon", "2.35", "--tz", "Europe/Paris",
                    "--time", "2024-06-21T13:00", "--time", "2024-06-21T23:30"]) == 0
    out = capsys.readouterr().out
    assert out.count("azimuth:") == 2 and "below the horizon" in out and "sun world" not in out


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--lat", "95", "--lon", "0", "--time", "2003-10-17T12:30:30Z"], "--lat: 95.0 is outside ±90°"),
        (["--lat", "45", "--lon", "0", "--time", "2003-10-17T12:30:30"], "and the site has no timezone"),
        (["--lat", "45", "--lon", "0", "--time", "noon"], "is not an ISO 8601 timestamp"),
        (["--lat", "45", "--lon", "0", "--time", "2003-10-17T12:30:30Z", "--pressure", "1013"], "mbar"),
        (["--lat", "45", "--lon", "0", "--time", "2003-10-17T12:30:30Z", "--heading", "nan"], "heading nan"),
    ],
)
def test_sun_command_bad_input(argv, expected, capsys):
    with pytest.raises(GnomonError) as excinfo:
        run_sun(argv)
    assert expected in str(excinfo.value) and "\n" not in str(excinfo.value)
