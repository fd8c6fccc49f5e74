"""The synthetic desk-lamp capture: its ground truth is self-consistent and
agrees with independent implementations (OpenCV's projection), its frames
show the shadow where the ground truth says, and its penumbra centres are
where the shadow planes are."""

from __future__ import annotations

import argparse
import glob
import json
import tomllib

import cv2
import numpy as np
import pytest

from gnomon.errors import GnomonError
from gnomon.simulate import DeskLampConfig, DeskLampScene, simulate_desk_lamp
from gnomon.simulate import geometry as geo

SMALL = DeskLampConfig(width=320, height=240, frames=96, jpeg_quality=0, seed=0)
TINY = DeskLampConfig(width=160, height=120, frames=24, seed=3)  # JPEG


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim_small")
    result = simulate_desk_lamp(out, SMALL)
    gt = dict(np.load(result.ground_truth))
    return result, gt


@pytest.fixture(scope="module")
def small_scene():
    return DeskLampScene(SMALL)


@pytest.fixture(scope="module")
def small_frames(small):
    result, _ = small
    return np.stack([cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in result.frames]).astype(np.float64)


def pixel_grid(w: int, h: int):
    return np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))


# ------------------------------------------------------------------ geometry


def test_depth_agrees_with_points_world(small):
    _, gt = small
    P = gt["points_world"].astype(np.float64)
    hit = np.isfinite(gt["depth"])
    assert hit.all()  # the desk fills the view
    assert np.array_equal(hit, np.isfinite(P).all(axis=-1))
    Xc = P @ gt["R"].T + gt["t"]
    np.testing.assert_allclose(Xc[..., 2], gt["depth"], atol=1e-3)
    np.testing.assert_allclose(gt["R"] @ gt["R"].T, np.eye(3), atol=1e-12)
    C = -gt["R"].T @ gt["t"]
    assert abs(np.linalg.norm(C) - float(gt["camera_distance_mm"])) < 1e-9
    assert 600 < float(gt["camera_distance_mm"]) < 700


@pytest.mark.parametrize("distortion", [True, False])
def test_cv2_projectpoints_lands_on_pixel_centres(small, distortion):
    """OpenCV's projection of the ground-truth points gives back the pixel centres:
    checks the simulator's own distortion inversion against an independent code."""
    if distortion:
        _, gt = small
    else:
        sc = DeskLampScene(DeskLampConfig(width=160, height=120, frames=24, distortion=False))
        gt = sc.ground_truth_arrays()
        assert not gt["dist"].any()
    h, w = gt["depth"].shape
    P = gt["points_world"].astype(np.float64).reshape(-1, 1, 3)
    img, _ = cv2.projectPoints(P, gt["rvec"], gt["tvec"], gt["K"], gt["dist"])
    u, v = pixel_grid(w, h)
    err = np.hypot(img[:, 0, 0] - u.ravel(), img[:, 0, 1] - v.ravel())
    assert err.max() < 0.01


def test_rodrigues_matches_opencv(small):
    _, gt = small
    R_cv, _ = cv2.Rodrigues(gt["rvec"])
    np.testing.assert_allclose(R_cv, gt["R"], atol=1e-12)
    rng = np.random.default_rng(1)
    axes = rng.normal(size=(20, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0, np.pi, 16), [0.0, 1e-9, np.pi - 1e-6, np.pi]])
    for k, a in zip(axes, angles):
        r = k * a
        R = geo.rotation_from_rodrigues(r)
        np.testing.assert_allclose(R, cv2.Rodrigues(r)[0], atol=1e-12)
        np.testing.assert_allclose(geo.rotation_from_rodrigues(geo.rodrigues_from_rotation(R)), R, atol=1e-9)


def test_undistort_inverts_distort():
    u, v = pixel_grid(81, 61)
    xd, yd = (u - 40) / 70.0, (v - 30) / 70.0  # normalised coordinates up to ±0.57
    dist = (-0.12, 0.05, 0.001, -0.0008, 0.0)
    x, y = geo.undistort(xd, yd, dist)
    xr, yr = geo.distort(x, y, dist)
    assert max(np.abs(xr - xd).max(), np.abs(yr - yd).max()) < 1e-13
    pts = np.stack([xd.ravel(), yd.ravel()], axis=1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(pts, np.eye(3), np.array(dist), None, None, None, crit).reshape(-1, 2)
    np.testing.assert_allclose(np.stack([x.ravel(), y.ravel()], axis=1), ref, atol=1e-7)


def test_surface_points_lie_on_their_objects(small_scene):
    sc = small_scene
    P, oid = sc.points, sc.object_id
    assert set(np.unique(oid)) == {0, 1, 2, 3}
    assert np.abs(P[oid == 0][:, 2]).max() < 1e-9
    sphere = sc.objects[1][0]
    assert np.abs(np.linalg.norm(P[oid == 1] - sphere.c, axis=1) - sphere.r).max() < 1e-9
    box = sc.objects[2][0]
    q = np.abs(box._local(P[oid == 2])) / box.half
    assert np.abs(q.max(axis=1) - 1).max() < 1e-9
    cyl = sc.objects[3][0]
    rel = P[oid == 3] - cyl.c
    z = rel @ cyl.a
    r = np.linalg.norm(rel - z[:, None] * cyl.a, axis=1)
    on_side = np.abs(r - cyl.r) < 1e-9
    on_cap = np.abs(np.abs(z) - cyl.h) < 1e-9
    assert (on_side | on_cap).all() and (np.abs(z) <= cyl.h + 1e-9).all()
    # Normals are unit and face the camera.
    n = sc.normals
    assert np.abs(np.linalg.norm(n, axis=-1) - 1).max() < 1e-9
    view = P - sc.C
    assert (np.einsum("...i,...i->...", n, view) < 1e-9).all()


def test_fov_is_kept_when_the_size_changes():
    a = DeskLampScene(DeskLampConfig(width=160, height=120, frames=24)).lens
    b = DeskLampScene(DeskLampConfig(width=320, height=240, frames=24)).lens
    assert a.fx / 160 == pytest.approx(b.fx / 320) and a.fy / 120 == pytest.approx(b.fy / 240)
    assert (a.cx + 0.5) / 160 == pytest.approx((b.cx + 0.5) / 320)
    assert (a.cy + 0.5) / 120 == pytest.approx((b.cy + 0.5) / 240)
    assert b.fx * 800 / 320 == pytest.approx(900, rel=0.02)


# ------------------------------------------------------------------ the field log and files


def test_field_log_parses_and_regions_are_bare_desk(small):
    result, gt = small
    text = result.field_log.read_text()
    assert text.startswith("#") and "ynthetic" in text.splitlines()[0] and "seed 0" in text.splitlines()[0]
    log = tomllib.loads(text)
    assert set(log) == {"capture", "camera", "planes", "light", "scan"}
    cap = log["capture"]
    assert cap["frames"] == "frames/*.png" and cap["units"] == "mm" and cap["gamma"] == 2.2
    assert cap["frame_count"] == SMALL.frames
    files = sorted(glob.glob(str(result.out_dir / cap["frames"])))
    assert len(files) == SMALL.frames
    cam = log["camera"]
    assert cam["model"] == "opencv" and (cam["width"], cam["height"]) == (320, 240)
    K = gt["K"]
    assert (cam["fx"], cam["fy"], cam["cx"], cam["cy"]) == (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    np.testing.assert_array_equal(cam["dist"], gt["dist"])
    np.testing.assert_array_equal(cam["pose"]["rvec"], gt["rvec"])
    np.testing.assert_array_equal(cam["pose"]["tvec"], gt["tvec"])
    assert log["light"] == {"kind": "lamp", "position": list(gt["lamp"])}
    assert log["scan"]["min_contrast"] == 20
    (plane,) = log["planes"]
    assert plane["name"] == "desk" and plane["point"] == [0, 0, 0] and plane["normal"] == [0, 0, 1]
    regions = plane["regions"]
    assert len(regions) >= 2
    h, w = gt["depth"].shape
    for u0, v0, u1, v1 in regions:
        assert 0 <= u0 < u1 <= w and 0 <= v0 < v1 <= h
        assert v1 - v0 >= 0.04 * h and u1 - u0 >= 0.9 * w
        assert (gt["object_id"][v0:v1, u0:u1] == 0).all()
        assert gt["swept"][v0:v1, u0:u1].all()
    tops = sorted(r[1] for r in regions)
    assert tops[0] < 0.2 * h and tops[-1] > 0.7 * h
    # The JSON carries the scalars; nothing temporary is left behind.
    info = json.loads(result.ground_truth_json.read_text())
    assert info["seed"] == 0 and info["config"]["width"] == 320
    assert info["camera_distance_mm"] == pytest.approx(float(gt["camera_distance_mm"]))
    assert info["lamp"] == list(gt["lamp"])
    assert not [p for p in result.out_dir.rglob("*") if p.name.endswith(".tmp")]


def test_ground_truth_arrays(small):
    _, gt = small
    h, w = 240, 320
    N = SMALL.frames
    assert gt["depth"].shape == (h, w) and gt["depth"].dtype == np.float32
    assert gt["points_world"].shape == (h, w, 3) and gt["points_world"].dtype == np.float32
    assert gt["object_id"].dtype == np.int8 and gt["swept"].dtype == bool
    assert gt["shadow_planes_enter"].shape == (N, 4) and gt["shadow_planes_leave"].shape == (N, 4)
    assert list(gt["image_size"]) == [w, h]
    sw = gt["swept"]
    assert sw.mean() > 0.85
    e, l = gt["enter_time"][sw], gt["leave_time"][sw]
    assert (e >= 1).all() and (l <= N - 2).all() and (e < l).all()
    # Every plane is unit, and at integer frames it brackets the pixel's times.
    for key, times in (("shadow_planes_enter", gt["enter_time"]), ("shadow_planes_leave", gt["leave_time"])):
        planes = gt[key]
        np.testing.assert_allclose(np.linalg.norm(planes[:, :3], axis=1), 1, atol=1e-12)
        P = gt["points_world"][sw].astype(np.float64)
        t = times[sw].astype(np.float64)
        k0 = np.floor(t).astype(int)
        g0 = np.einsum("ij,ij->i", planes[k0, :3], P) - planes[k0, 3]
        g1 = np.einsum("ij,ij->i", planes[k0 + 1, :3], P) - planes[k0 + 1, 3]
        assert (g0 > -1e-3).all() and (g1 < 1e-3).all()
        # The lamp lies on every shadow plane.
        np.testing.assert_allclose(planes[:, :3] @ gt["lamp"] - planes[:, 3], 0, atol=1e-9)


def test_determinism_and_seed(tmp_path):
    a = simulate_desk_lamp(tmp_path / "a", TINY)
    b = simulate_desk_lamp(tmp_path / "b", TINY)
    c = simulate_desk_lamp(tmp_path / "c", DeskLampConfig(width=160, height=120, frames=24, seed=4))
    assert [p.name for p in a.frames] == [p.name for p in b.frames]
    assert all(p.suffix == ".jpg" for p in a.frames)
    assert all(pa.read_bytes() == pb.read_bytes() for pa, pb in zip(a.frames, b.frames))
    ga, gb = np.load(a.ground_truth), np.load(b.ground_truth)
    for key in ga.files:
        np.testing.assert_array_equal(ga[key], gb[key])
    assert a.field_log.read_text() == b.field_log.read_text()
    assert any(pa.read_bytes() != pc.read_bytes() for pa, pc in zip(a.frames, c.frames))


def test_rerun_replaces_a_previous_capture(tmp_path):
    simulate_desk_lamp(tmp_path, DeskLampConfig(width=160, height=120, frames=30, jpeg_quality=0))
    r = simulate_desk_lamp(tmp_path, TINY)
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [p.name for p in r.frames]
    assert tomllib.loads(r.field_log.read_text())["capture"]["frames"] == "frames/*.jpg"


# ------------------------------------------------------------------ the shadow


def linearise(dn: np.ndarray, gamma: float) -> np.ndarray:
    return (dn / 255.0) ** gamma


def test_frames_show_the_shadow_between_enter_and_leave(small, small_frames, small_scene):
    _, gt = small
    sc = small_scene
    lit, dark = sc.lit_image(), sc.shadowed_image()
    sw = gt["swept"]
    e, l = gt["enter_time"], gt["leave_time"]
    for k in (30, 48, 70):
        lin = linearise(small_frames[k], SMALL.gamma)
        level = np.divide(lin - dark, lit - dark, out=np.zeros_like(lin), where=sw)  # 1 lit, 0 dark
        inside = sw & (e < k - 0.5) & (l > k + 0.5)
        outside = sw & ((e > k + 3) | (l < k - 3))
        assert inside.sum() > 50 and outside.sum() > 10000
        assert np.median(level[inside]) < 0.2
        assert np.median(level[outside]) == pytest.approx(1.0, abs=0.02)
        assert np.percentile(level[inside], 95) < 0.5 < np.percentile(level[outside], 1)
    # The first two and the last two frames are entirely lit.
    for k in (0, 1, SMALL.frames - 2, SMALL.frames - 1):
        assert sc.occlusion(k, restrict=False).max() == 0.0


def test_penumbra_centre_is_the_tangent_plane(small, small_scene):
    """At enter_time / leave_time exactly half of the lamp's disc is hidden
    (the model's own occlusion, before blur), on the desk and on the objects."""
    sc = small_scene
    _, gt = small
    rng = np.random.default_rng(0)
    ys, xs = np.nonzero(gt["swept"])
    for i in rng.choice(len(ys), 60, replace=False):
        y, x = ys[i], xs[i]
        for t in (sc.enter_time[y, x], sc.leave_time[y, x]):
            assert sc.occlusion(t)[y, x] == pytest.approx(0.5, abs=1e-6)
    # ... and the blurred linear image is half-way between lit and shadowed.
    lit, dark = sc.lit_image(), sc.shadowed_image()
    desk = np.nonzero(gt["swept"] & (gt["object_id"] == 0))
    for i in rng.choice(len(desk[0]), 30, replace=False):
        y, x = desk[0][i], desk[1][i]
        L = sc.linear_image(sc.enter_time[y, x])[y, x]
        assert (L - dark[y, x]) / (lit[y, x] - dark[y, x]) == pytest.approx(0.5, abs=0.01)


def test_penumbra_half_way_in_the_frames(small, small_frames, small_scene):
    """In the rendered frames (gamma, noise, quantisation), desk pixels whose
    enter (leave) time falls on a frame are half-way between lit and shadowed
    in linear intensity, to within what the noise allows."""
    _, gt = small
    sc = small_scene
    lit, dark = sc.lit_image().astype(np.float64), sc.shadowed_image().astype(np.float64)
    g = SMALL.gamma
    sigma_dn = np.hypot(SMALL.noise, 1 / np.sqrt(12))  # sensor noise + quantisation
    base = gt["swept"] & (gt["object_id"] == 0)
    for times in (gt["enter_time"].astype(np.float64), gt["leave_time"].astype(np.float64)):
        k = np.rint(times)
        sel = base & (np.abs(times - k) < 0.02)
        ys, xs = np.nonzero(sel)
        kk = k[sel].astype(int)
        dn = small_frames[kk, ys, xs]
        e = (linearise(dn, g) - dark[sel]) / (lit[sel] - dark[sel]) - 0.5
        # σ of e per pixel: the noise through the gamma decoding, over the contrast.
        sig = g * (dn / 255.0) ** (g - 1) * sigma_dn / 255.0 / (lit[sel] - dark[sel])
        n = len(e)
        assert n > 1000
        rms = np.sqrt(np.mean(sig**2))
        # Allowances: the blur moves the half-way point by < 0.005; the ±0.02
        # frame window times the penumbra's steepest slope (< 2 / frame) < 0.04.
        assert abs(e.mean()) < 4 * rms / np.sqrt(n) + 0.01
        assert e.std() < 1.25 * rms + 0.01            # the scatter is the noise's
        assert np.mean(np.abs(e) < 4 * sig + 0.04) > 0.995


# ------------------------------------------------------------------ the command and errors


def make_parser():
    from gnomon.commands import simulate as cmd

    parser = argparse.ArgumentParser(prog="gnomon")
    cmd.register(parser.add_subparsers(dest="command", required=True))
    return parser


def test_command_line(tmp_path, capsys):
    parser = make_parser()
    args = parser.parse_args(["simulate", "desk_lamp", "--out", str(tmp_path / "cap"), "--width", "160",
                              "--height", "120", "--frames", "20", "--jpeg-quality", "0",
                              "--no-distortion", "--seed", "7", "--blur", "0.5", "--lamp-radius", "2",
                              "--stick-radius", "3", "--noise", "1", "--gamma", "2.0"])
    assert args.func(args) == 0
    log = tomllib.loads((tmp_path / "cap" / "field_log.toml").read_text())
    assert log["capture"]["frames"] == "frames/*.png" and log["capture"]["gamma"] == 2.0
    assert log["camera"]["dist"] == [0.0] * 5
    assert len(list((tmp_path / "cap" / "frames").glob("*.png"))) == 20
    info = json.loads((tmp_path / "cap" / "ground_truth.json").read_text())
    assert info["seed"] == 7 and info["config"]["stick_radius"] == 3.0
    assert "wrote 20 frames" in capsys.readouterr().out


@pytest.mark.parametrize("flags", [["--frames", "3"], ["--width", "20"], ["--noise", "-1"],
                                   ["--jpeg-quality", "101"], ["--lamp-radius", "0"], ["--gamma", "0"]])
def test_bad_arguments_are_user_errors(tmp_path, flags):
    parser = make_parser()
    args = parser.parse_args(["simulate", "desk_lamp", "--out", str(tmp_path / "x"), *flags])
    with pytest.raises(GnomonError, match="simulate desk_lamp"):
        args.func(args)
    assert not (tmp_path / "x" / "field_log.toml").exists()


def test_no_bare_desk_band_is_an_error(small_scene):
    sc = small_scene
    saved = sc.swept
    try:
        sc.swept = saved.copy()
        sc.swept[:, sc.W // 2] = False  # a column never swept cuts every band
        with pytest.raises(GnomonError, match="no bare, swept desk band"):
            sc._desk_regions()
    finally:
        sc.swept = saved
