"""The synthetic facade/sun time-lapse: its ground truth is self-consistent and
agrees with independent code (OpenCV's projection, pvlib's sun, gnomon.light.ephemeris's
world frame, the timestamp readers), and its frames show the pole's shadow
where the ground truth says."""

from __future__ import annotations

import dataclasses
import glob
import json
import math
import tomllib

import cv2
import numpy as np
import pandas as pd
import pytest
from PIL import Image

from gnomon.camera.models import undistort_points
from gnomon.errors import GnomonError
from gnomon.light.timestamps import frame_times
from gnomon.simulate import sensor
from gnomon.simulate.facade_sun import (
    GROUND,
    POLE,
    WALL,
    FacadeSunConfig,
    FacadeSunScene,
    simulate_facade_sun,
)

SMALL = FacadeSunConfig(width=320, height=240, frames=48, seed=1)          # JPEG
TINY = FacadeSunConfig(width=160, height=120, frames=12, jpeg_quality=0, clouds=2)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("facade_small")
    result = simulate_facade_sun(out, SMALL)
    gt = dict(np.load(result.ground_truth))
    log = tomllib.loads(result.field_log.read_text())
    return result, gt, log


@pytest.fixture(scope="module")
def small_scene():
    return FacadeSunScene(SMALL)


@pytest.fixture(scope="module")
def small_frames(small):
    result, _, _ = small
    return np.stack([cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in result.frames]).astype(np.float64)


def pixel_grid(w: int, h: int):
    return np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))


def nlerp_sun(sun: np.ndarray, tau: np.ndarray) -> np.ndarray:
    k = np.minimum(np.floor(tau).astype(int), len(sun) - 2)
    f = (tau - k)[:, None]
    d = sun[k] * (1 - f) + sun[k + 1] * f
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# ------------------------------------------------------------------ geometry


@pytest.mark.slow
def test_depth_agrees_with_points_world(small):
    _, gt, _ = small
    P = gt["points_world"].astype(np.float64)
    hit = np.isfinite(gt["depth"])
    assert np.array_equal(hit, np.isfinite(P).all(axis=-1))
    assert np.array_equal(hit, gt["object_id"] >= 0)
    assert 0.005 < (~hit).mean() < 0.2  # some sky above the roof line
    Xc = P[hit] @ gt["R"].T + gt["t"]
    np.testing.assert_allclose(Xc[:, 2], gt["depth"][hit], rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(gt["R"] @ gt["R"].T, np.eye(3), atol=1e-12)
    C = -gt["R"].T @ gt["t"]
    assert 1.0 <= C[2] <= 2.0                       # a tripod
    assert 25.0 <= float(gt["camera_distance"]) <= 40.0
    assert str(gt["units"]) == "m"
    # Every object is seen; ground points lie on z = 0, wall points on y = 0.
    ids = gt["object_id"]
    assert set(np.unique(ids)) == {-1, 0, 1, 2, 3, 4, 5, 6}
    assert np.abs(P[ids == GROUND][:, 2]).max() < 1e-6
    assert np.abs(P[ids == WALL][:, 1]).max() < 1e-6
    r = np.hypot(P[ids == POLE][:, 0] - gt["pole_base"][0], P[ids == POLE][:, 1] - gt["pole_base"][1])
    np.testing.assert_allclose(r, float(gt["pole_radius"]), atol=1e-6)
    # Normals are unit and face the camera.
    n = gt["normals_world"][hit].astype(np.float64)
    assert np.abs(np.linalg.norm(n, axis=1) - 1).max() < 1e-5
    assert (np.einsum("ij,ij->i", n, P[hit] - C) < 1e-6).all()


@pytest.mark.slow
@pytest.mark.parametrize("distortion", [True, False])
def test_cv2_projectpoints_lands_on_pixel_centres(small, distortion):
    if distortion:
        _, gt, _ = small
        assert gt["dist"].any()
    else:
        gt = FacadeSunScene(FacadeSunConfig(width=160, height=120, frames=12, distortion=False)).ground_truth_arrays()
        assert not gt["dist"].any()
    h, w = gt["depth"].shape
    hit = np.isfinite(gt["depth"])
    P = gt["points_world"].astype(np.float64)[hit].reshape(-1, 1, 3)
    img, _ = cv2.projectPoints(P, gt["rvec"], gt["tvec"], gt["K"], gt["dist"])
    u, v = pixel_grid(w, h)
    # float32 storage of points ~30 m away: 2e-6 m → < 1e-4 px
    err = np.hypot(img[:, 0, 0] - u[hit], img[:, 0, 1] - v[hit])
    assert err.max() < 0.01
    assert np.allclose(cv2.Rodrigues(gt["rvec"])[0], gt["R"], atol=1e-12)


@pytest.mark.slow
def test_fov_is_kept_when_the_size_changes():
    a = FacadeSunScene(FacadeSunConfig(width=160, height=120, frames=12)).lens
    b = FacadeSunScene(FacadeSunConfig(width=320, height=240, frames=12)).lens
    assert a.fx / 160 == pytest.approx(b.fx / 320) and a.fy / 120 == pytest.approx(b.fy / 240)
    assert b.fx * 800 / 320 == pytest.approx(900)


# ------------------------------------------------------------------ the sun and the world frame


@pytest.mark.slow
def test_sun_direction_matches_pvlib(small):
    from pvlib.atmosphere import alt2pres
    from pvlib.solarposition import get_solarposition

    from gnomon.light.ephemeris import R_world_from_enu, Site, sun_direction_enu

    _, gt, log = small
    site = log["site"]
    times = pd.DatetimeIndex(gt["frame_times_utc_ns"].astype("datetime64[ns]")).tz_localize("UTC")
    assert list(times.strftime("%Y-%m-%dT%H:%M:%SZ")) == list(gt["frame_times_utc"])
    sp = get_solarposition(times, site["latitude"], site["longitude"], altitude=site["altitude"],
                           pressure=alt2pres(site["altitude"]), method="nrel_numpy", temperature=12.0,
                           delta_t=67.0)
    a = np.radians(sp["azimuth"].to_numpy())
    e = np.radians(sp["apparent_elevation"].to_numpy())
    d = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=1)
    np.testing.assert_allclose(gt["sun_enu"], d, atol=1e-12)
    np.testing.assert_allclose(gt["sun_azimuth_deg"], sp["azimuth"].to_numpy(), atol=1e-9)
    # ... and with the pipeline's own sun for the field log's site.
    s = Site(site["latitude"], site["longitude"], site["altitude"], timezone=site["timezone"])
    np.testing.assert_allclose(sun_direction_enu(times, s), gt["sun_enu"], atol=1e-12)
    # The world frame: x at compass heading h, z up (the pipeline's convention).
    h = float(gt["heading_deg"])
    assert h == site["heading_deg"]
    np.testing.assert_allclose(gt["R_world_from_enu"], R_world_from_enu(h), atol=1e-15)
    np.testing.assert_allclose(gt["sun_world"], gt["sun_enu"] @ R_world_from_enu(h).T, atol=1e-12)
    # The facade (normal +y in world) faces the sun all along and the sun is up.
    assert (gt["sun_world"][:, 1] > 0.2).all() and (gt["sun_elevation_deg"] > 5).all()
    # The sun sweeps tens of degrees of azimuth, one frame a minute.
    assert np.ptp(gt["sun_azimuth_deg"]) > 40 and np.all(np.diff(gt["sun_azimuth_deg"]) > 0)


def test_world_frame_heading():
    from gnomon.light.ephemeris import R_world_from_enu as pipeline_R
    from gnomon.simulate.facade_sun import HEADING_DEG, R_world_from_enu

    for h in (0.0, 30.0, 90.0, HEADING_DEG):
        np.testing.assert_allclose(R_world_from_enu(h), pipeline_R(h), atol=1e-15)
    # World x at compass 295°, the facade's outward normal (+y) at 205° (SSW).
    R = R_world_from_enu(HEADING_DEG)
    for axis, heading in ((0, 295.0), (1, 205.0)):
        v = R.T @ np.eye(3)[axis]
        assert math.degrees(math.atan2(v[0], v[1])) % 360 == pytest.approx(heading)


# ------------------------------------------------------------------ the shadow's ground truth


@pytest.mark.slow
def test_times_and_planes(small):
    _, gt, _ = small
    N = SMALL.frames
    sw = gt["swept"]
    assert sw.mean() > 0.1
    e, c, lv = (gt[k][sw].astype(np.float64) for k in ("enter_time", "center_time", "leave_time"))
    assert (e >= 1).all() and (lv <= N - 2).all() and (e < c).all() and (c < lv).all()
    for key in ("shadow_planes_enter", "shadow_planes_center", "shadow_planes_leave"):
        planes = gt[key]
        assert planes.shape == (N, 4)
        np.testing.assert_allclose(np.linalg.norm(planes[:, :3], axis=1), 1, atol=1e-12)
        assert np.abs(planes[:, 2]).max() < 1e-12                    # vertical planes
        np.testing.assert_allclose(planes[:, :3] @ gt["sun_world"].T * np.eye(N), 0, atol=1e-12)
    r = float(gt["pole_radius"])
    base = gt["pole_base"]
    np.testing.assert_allclose(gt["shadow_planes_center"][:, :3] @ base, gt["shadow_planes_center"][:, 3], atol=1e-9)
    np.testing.assert_allclose(gt["shadow_planes_enter"][:, 3] - gt["shadow_planes_center"][:, 3], r, atol=1e-9)
    np.testing.assert_allclose(gt["shadow_planes_leave"][:, 3] - gt["shadow_planes_center"][:, 3], -r, atol=1e-9)
    # At integer frames the planes bracket each point's times (the shadow moves ahead of n).
    P = gt["points_world"][sw].astype(np.float64)
    for key, t in (("shadow_planes_enter", e), ("shadow_planes_center", c), ("shadow_planes_leave", lv)):
        planes = gt[key]
        k0 = np.floor(t).astype(int)
        g0 = np.einsum("ij,ij->i", planes[k0, :3], P) - planes[k0, 3]
        g1 = np.einsum("ij,ij->i", planes[k0 + 1, :3], P) - planes[k0 + 1, 3]
        assert (g0 > -1e-5).all() and (g1 < 1e-5).all()


@pytest.mark.slow
def test_center_plane_contains_the_pole_axis_and_the_sun(small):
    """At center_time the plane through the pole's axis containing the sun's
    direction (interpolated along the chord between frames) passes through the
    pixel's point, on the side away from the sun; at enter/leave_time the point
    is one pole radius ahead of / behind it."""
    _, gt, _ = small
    sw = gt["swept"]
    P = gt["points_world"][sw].astype(np.float64)
    base, top, r = gt["pole_base"], gt["pole_top"], float(gt["pole_radius"])
    axis = (top - base) / np.linalg.norm(top - base)
    np.testing.assert_allclose(axis, [0, 0, 1], atol=1e-15)
    for key, offset in (("center_time", 0.0), ("enter_time", r), ("leave_time", -r)):
        t = gt[key][sw].astype(np.float64)
        d = nlerp_sun(gt["sun_world"], t)
        n = np.cross(axis, d)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        dist = np.einsum("ij,ij->i", n, P - base)
        # float32 times: 1e-7 relative of ~40 frames → ~4e-6 frame → < 1e-6 m at 20 m
        assert np.abs(np.abs(dist) - abs(offset)).max() < 2e-5
        # The sun ray from the point runs towards the pole (the point is in its shadow)...
        assert (np.einsum("ij,ij->i", (P - base)[:, :2], d[:, :2]) < 0).all()
        # ... and passes the axis below the pole's top.
        s = -np.einsum("ij,ij->i", (P - base)[:, :2], d[:, :2]) / np.hypot(d[:, 0], d[:, 1]) ** 2
        assert (P[:, 2] + s * d[:, 2] < top[2]).all()
    # Points in front of the central plane are entered first: enter/leave are on opposite sides.
    tc = gt["center_time"][sw].astype(np.float64)
    assert np.ptp(tc) > 0.6 * SMALL.frames


@pytest.mark.slow
def test_penumbra_and_occlusion(small, small_scene):
    sc = small_scene
    _, gt, _ = small
    sw = gt["swept"]
    assert np.array_equal(sc.swept, sw)
    ys, xs = np.nonzero(sw)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(ys), 300, replace=False)
    p = sc.pad
    # The occluded fraction at the central time is the recorded peak, and the shadow is
    # symmetric: its half-way points are symmetric about the centre time.
    peak = gt["pole_occlusion_peak"][sw]
    assert 0.5 < np.percentile(peak, 1) and np.percentile(peak, 99) <= 1.0
    for k in range(SMALL.frames):
        f = sc.pole_occlusion(k)[ys[pick] + p, xs[pick] + p]
        c = gt["center_time"][ys[pick], xs[pick]]
        e = gt["enter_time"][ys[pick], xs[pick]]
        l_ = gt["leave_time"][ys[pick], xs[pick]]
        far = (k < e - (c - e) * 4 - 1) | (k > l_ + (l_ - c) * 4 + 1)
        assert (f[far] == 0).all()
    # The full (unrestricted) computation agrees with the restricted one.
    for k in (5, 20, 40):
        np.testing.assert_allclose(sc.pole_occlusion(k), sc.pole_occlusion(k, restrict=False), atol=0)


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_building_shadows_are_soft_and_kept_out_of_swept(small_scene):
    sc = small_scene
    fractional = 0
    for k in (0, SMALL.frames // 2, SMALL.frames - 1):
        soft = sc.building_visibility(k)
        hard = sc.building_visibility(k, soft=False)
        fractional += ((soft > 0) & (soft < 1)).sum()
        # Soft and hard differ only in a thin band along the hard shadow's edges.
        differ = np.abs(soft - hard) > 0.5
        edge = cv2.dilate((hard < 0.5).astype(np.uint8), np.ones((5, 5), np.uint8)) \
            & ~cv2.erode((hard < 0.5).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        assert (~differ | edge.astype(bool)).all()
        # No swept pixel is ever in a building shadow.
        assert (soft[sc.crop][sc.swept] == 1.0).all()
        assert (hard[sc.crop] < 1).sum() > 50            # there are building shadows
    assert fractional > 20


@pytest.mark.slow
def test_regions_are_bare_and_swept(small):
    result, gt, log = small
    planes = {p["name"]: p for p in log["planes"]}
    assert set(planes) == {"ground", "facade"}
    h, w = gt["depth"].shape
    for name, oid in (("ground", GROUND), ("facade", WALL)):
        plane = planes[name]
        n = np.array(plane["normal"], float)
        assert plane["regions"]
        for u0, v0, u1, v1 in plane["regions"]:
            assert 0 <= u0 < u1 <= w and 0 <= v0 < v1 <= h
            sl = (slice(v0, v1), slice(u0, u1))
            assert (gt["object_id"][sl] == oid).all() and gt["swept"][sl].all()
            P = gt["points_world"][sl].reshape(-1, 3).astype(np.float64)
            assert np.abs((P - plane["point"]) @ n).max() < 1e-5
        assert result.regions[name] == plane["regions"]
    # Swept pixels on every kind of surface the shadow crosses.
    for oid in (0, 1, 2, 4):
        assert (gt["swept"] & (gt["object_id"] == oid)).sum() > 20, oid
    assert not (gt["swept"] & (gt["object_id"] == POLE)).any()
    assert not (gt["cloud_free_passage"] & ~gt["swept"]).any()


# ------------------------------------------------------------------ frames, names and EXIF


@pytest.mark.slow
def test_file_names_and_exif_give_the_frame_times(small):
    result, gt, log = small
    cap = log["capture"]
    assert cap["timestamps"] == "filename" and cap["time_pattern"] == "%Y%m%dT%H%M%SZ"
    files = sorted(glob.glob(str(result.out_dir / cap["frames"])))
    assert len(files) == SMALL.frames == cap["frame_count"]
    expect = gt["frame_times_utc_ns"]
    by_name = frame_times(files, "filename", pattern=cap["time_pattern"], site_tz=log["site"]["timezone"])
    np.testing.assert_array_equal(by_name.asi8, expect)
    by_exif = frame_times(files, "exif", site_tz=log["site"]["timezone"])
    np.testing.assert_array_equal(by_exif.asi8, expect)
    assert np.all(np.diff(expect) == SMALL.interval_s * 10**9)
    # EXIF holds local time (CET in November, UTC+1) and the offset.
    with Image.open(files[0]) as im:
        ifd = im.getexif().get_ifd(0x8769)
    t0 = pd.Timestamp(int(expect[0]), tz="UTC").tz_convert("Europe/Zurich")
    assert ifd[0x9003] == t0.strftime("%Y:%m:%d %H:%M:%S") and ifd[0x9011] == "+01:00"
    assert result.frame_times.equals(by_name)


@pytest.mark.slow
def test_field_log(small):
    result, gt, log = small
    text = result.field_log.read_text()
    assert text.startswith("#") and "facade_sun" in text.splitlines()[0]
    assert set(log) == {"capture", "camera", "planes", "site", "light", "pole", "gnomon", "scan"}
    assert log["capture"]["units"] == "m" and log["capture"]["gamma"] == 2.2
    assert log["capture"]["frames"] == "frames/*.jpg"
    cam = log["camera"]
    K = gt["K"]
    assert (cam["fx"], cam["fy"], cam["cx"], cam["cy"]) == (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    np.testing.assert_array_equal(cam["pose"]["rvec"], gt["rvec"])
    np.testing.assert_array_equal(cam["pose"]["tvec"], gt["tvec"])
    assert log["light"] == {"kind": "sun"}
    assert log["site"] == {"latitude": 47.3769, "longitude": 8.5417, "altitude": 408.0,
                           "timezone": "Europe/Zurich", "heading_deg": float(gt["heading_deg"])}
    assert log["pole"] == {"base": list(gt["pole_base"]), "top": list(gt["pole_top"]),
                           "radius": float(gt["pole_radius"])}
    assert log["scan"] == {"normalize_illumination": True}  # the contrast floor from the noise
    info = json.loads(result.ground_truth_json.read_text())
    assert info["scene"] == "facade_sun" and info["seed"] == SMALL.seed
    assert info["camera_distance"] == pytest.approx(float(gt["camera_distance"]))
    assert not [p for p in result.out_dir.rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_gnomon_observation_gives_the_heading(small):
    """The [gnomon] pixels back-projected onto the ground and the sun's azimuth
    at that frame's time give back the heading (independent code: OpenCV)."""
    result, gt, log = small
    g = log["gnomon"]
    frame = result.out_dir / g["frame"]
    assert frame.is_file()
    K, dist = gt["K"], gt["dist"]
    px, _ = cv2.projectPoints(np.stack([gt["pole_base"], gt["pole_top"]]), gt["rvec"], gt["tvec"], K, dist)
    np.testing.assert_allclose(px[:, 0], [g["base_px"], g["top_px"]], atol=1e-3)
    h, w = gt["depth"].shape
    assert 0 <= g["base_px"][0] < w and 0 <= g["base_px"][1] < h
    assert 0 <= g["shadow_px"][0] < w and 0 <= g["shadow_px"][1] < h
    # Back-project onto z = 0.
    R, t = gt["R"], gt["t"]
    C = -R.T @ t
    norm = undistort_points(np.array([g["base_px"], g["shadow_px"]], np.float64).reshape(-1, 1, 2), K, dist,
                            (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)).reshape(-1, 2)
    rays = np.column_stack([norm, np.ones(2)]) @ R
    G = C + (-C[2] / rays[:, 2])[:, None] * rays
    np.testing.assert_allclose(G[0], gt["pole_base"], atol=1e-3)
    phi = math.degrees(math.atan2(G[1, 1] - G[0, 1], G[1, 0] - G[0, 0]))
    k = [p.name for p in result.frames].index(frame.name)
    heading = (gt["sun_azimuth_deg"][k] + 180.0 + phi) % 360
    assert heading == pytest.approx(float(gt["heading_deg"]), abs=0.05)


def linearise(dn, gamma):
    return (np.asarray(dn, np.float64) / 255.0) ** gamma


@pytest.mark.slow
def test_frames_show_the_pole_shadow(small, small_frames, small_scene):
    """In the encoded frames, swept pixels whose centre time is on a frame are
    darker than the sun-lit, pole-free render by about the direct light the
    pole hides; pixels far from their passage match it."""
    _, gt, _ = small
    sc = small_scene
    sw = gt["swept"]
    c = gt["center_time"].astype(np.float64)
    inside_all, outside_all = [], []
    for k in (12, 24, 36):
        lin = linearise(small_frames[k], SMALL.gamma)
        free = sc.linear_image(k, pole=False)
        ratio = np.divide(lin, free, out=np.ones_like(lin), where=free > 0.02)
        inside = sw & (np.abs(c - k) < 0.15) & (gt["pole_occlusion_peak"] > 0.6)
        outside = sw & (np.abs(c - k) > 6)
        inside_all.append(ratio[inside])
        outside_all.append(ratio[outside])
    inside, outside = np.concatenate(inside_all), np.concatenate(outside_all)
    assert len(inside) > 30 and len(outside) > 5000
    assert np.median(inside) < 0.6
    assert np.median(outside) == pytest.approx(1.0, abs=0.02)
    assert np.percentile(inside, 95) < np.percentile(outside, 1)


@pytest.mark.slow
def test_illumination_drift_and_clouds(small, small_frames):
    _, gt, _ = small
    gain = gt["gain"]
    assert 0.78 <= gain.min() and gain.max() <= 1.22 and np.ptp(gain) > 0.25
    assert np.abs(np.diff(gain)).max() < 0.1                       # smooth
    cloud = gt["cloud"]
    runs = np.count_nonzero(np.diff(cloud.astype(int)) == 1) + int(cloud[0])
    assert runs == SMALL.clouds
    df = gt["direct_factor"]
    assert (df[~cloud] >= 0.99).all() and 0.2 <= df.min() <= 0.6
    # In the deepest cloud frame a sun-lit wall is darker than the frames around it,
    # once the exposure gain is divided out.
    k = int(np.argmin(df))
    wall = gt["sunlit"] & (gt["object_id"] == WALL) & ~np.isfinite(gt["center_time"])
    level = [linearise(small_frames[j][wall], SMALL.gamma).mean() / gain[j] for j in range(SMALL.frames)]
    assert level[k] < 0.75 * np.median(level)


@pytest.mark.slow
def test_determinism_png_and_rerun(tmp_path):
    a = simulate_facade_sun(tmp_path / "a", TINY)
    b = simulate_facade_sun(tmp_path / "a", TINY)    # again, into the same folder
    c = simulate_facade_sun(tmp_path / "c", FacadeSunConfig(width=160, height=120, frames=12, jpeg_quality=0,
                                                            clouds=2, seed=5))
    assert all(p.suffix == ".png" for p in b.frames)
    assert sorted(p.name for p in (tmp_path / "a" / "frames").iterdir()) == [p.name for p in b.frames]
    assert [p.name for p in a.frames] == [p.name for p in c.frames]  # names are the times
    assert any(pa.read_bytes() != pc.read_bytes() for pa, pc in zip(b.frames, c.frames, strict=True))
    gb, gc = np.load(b.ground_truth), np.load(c.ground_truth)
    np.testing.assert_array_equal(gb["depth"], gc["depth"])
    with Image.open(b.frames[0]) as im:                             # PNG frames carry EXIF too
        assert im.getexif().get_ifd(0x8769)[0x9011] == "+01:00"
    d = simulate_facade_sun(tmp_path / "d", TINY)
    assert all(pb.read_bytes() == pd_.read_bytes() for pb, pd_ in zip(b.frames, d.frames, strict=True))


@pytest.mark.slow
@pytest.mark.parametrize("kwargs, message", [
    (dict(frames=3), "need 8 to"),
    (dict(width=20), "--width/--height 20x120"),
    (dict(noise=-1.0), "noise"),
    (dict(pole_radius=0.0), "pole-radius"),
    (dict(start="noon"), "--start 'noon' is not an ISO 8601"),
    (dict(start="2026-11-12T19:00:00"), "--start .* below 3° or behind"),
    (dict(gain_drift=0.9), "gain_drift 0.9"),
    (dict(duration_s=60.0), "duration_s 60"),
    (dict(clouds=11), "clouds"),
    (dict(frames=20000, duration_s=3600), "--frames 20000 over duration_s 3600 s: .* at least 1 s apart"),
    (dict(drift_px=-1.0), "--drift -1.0"),
    (dict(bump_px=2.0, bump_frame=12), "bump_frame 12: must be 1 to 11"),
    (dict(drift_px=2.0, blur=0.0), "--blur 0.0: a moving camera needs the optical blur"),
])
def test_bad_configurations_are_user_errors(tmp_path, kwargs, message):
    with pytest.raises(GnomonError, match=message):
        simulate_facade_sun(tmp_path / "x", FacadeSunConfig(**{**dict(width=160, height=120, frames=12), **kwargs}))
    assert not (tmp_path / "x" / "field_log.toml").exists()


# ------------------------------------------------------------------ the camera's motion

def test_camera_motion_is_a_slow_drift_and_one_bump():
    """x grows linearly and y quadratically to (0.8, −0.6)·drift by the last frame; the bump adds
    (0.6, 0.8)·bump from 60 % of the way on; frame 0 is still."""
    n = 101
    m = sensor.camera_motion(n, 2.0, 1.0, None)
    s = np.arange(n) / (n - 1)
    bump = np.where(np.arange(n) >= 60, 1.0, 0.0)[:, None] * np.array([0.6, 0.8])
    np.testing.assert_allclose(m, np.stack([1.6 * s, -1.2 * s * s], axis=1) + bump, atol=1e-12)
    assert np.array_equal(m[0], [0.0, 0.0]) and math.isclose(np.hypot(*(m[-1] - bump[-1])), 2.0)
    assert not sensor.camera_motion(n, 0.0, 0.0, None).any()


@pytest.mark.parametrize("shift", [(1.0, 0.0), (0.0, -2.0), (0.37, -0.81), (-1.6, 0.25)])
def test_a_moved_frame_samples_the_same_blurred_image(shift):
    """blur_and_crop with a shift is I(x − shift) for I(x) = Σ G(x − p) R(p) / Σ G(x − p), evaluated here
    pixel by pixel; a whole-pixel shift is the still frame moved by whole pixels."""
    rng = np.random.default_rng(3)
    sigma, pad, h, w = 0.7, 8, 12, 16
    radiance = rng.uniform(0.1, 0.9, (h + 2 * pad, w + 2 * pad))
    crop = (slice(pad, pad + h), slice(pad, pad + w))
    moved = sensor.blur_and_crop(radiance, sigma, crop, np.array(shift))
    py, px = np.mgrid[0:h + 2 * pad, 0:w + 2 * pad]
    for v, u in ((0, 0), (5, 7), (h - 1, w - 1), (3, 12)):
        x, y = u + pad - shift[0], v + pad - shift[1]             # I at x − shift, padded coordinates
        g = np.exp(-((px - x) ** 2 + (py - y) ** 2) / (2 * sigma**2))
        assert moved[v, u] == pytest.approx(float((g * radiance).sum() / g.sum()), abs=2e-6)
    if float(shift[0]).is_integer() and float(shift[1]).is_integer():
        still = sensor.blur_and_crop(radiance, sigma, (slice(pad - int(shift[1]), pad - int(shift[1]) + h),
                                                       slice(pad - int(shift[0]), pad - int(shift[0]) + w)))
        np.testing.assert_allclose(moved, still, atol=2e-6)


@pytest.mark.slow
def test_a_drifting_camera_keeps_the_truth_and_moves_the_gnomon_pixels():
    """Drift changes the frames, not the ground truth (frame 0's grid); the motion per frame is in it;
    the gnomon's pixels are those of its frame, moved; the padding holds the moved frames."""
    still = FacadeSunScene(TINY)
    moving = FacadeSunScene(dataclasses.replace(TINY, drift_px=3.0, bump_px=1.0))
    np.testing.assert_array_equal(moving.depth, still.depth)
    np.testing.assert_array_equal(moving.swept, still.swept)
    m = moving.ground_truth_arrays()["camera_motion_px"]
    np.testing.assert_allclose(m, sensor.camera_motion(TINY.frames, 3.0, 1.0, None))
    k = still.gnomon_obs["k"]
    np.testing.assert_allclose(np.subtract(moving.gnomon_obs["base_px"], still.gnomon_obs["base_px"]), m[k])
    np.testing.assert_array_equal(moving.linear_image(0), still.linear_image(0))
    last = len(m) - 1
    assert not np.array_equal(moving.linear_image(last), still.linear_image(last))
