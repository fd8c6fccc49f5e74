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

from gnomon.camera.models import undistort_points
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


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_rodrigues_matches_opencv(small):
    _, gt = small
    R_cv, _ = cv2.Rodrigues(gt["rvec"])
    np.testing.assert_allclose(R_cv, gt["R"], atol=1e-12)
    rng = np.random.default_rng(1)
    axes = rng.normal(size=(20, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0, np.pi, 16), [0.0, 1e-9, np.pi - 1e-6, np.pi]])
    for k, a in zip(axes, angles, strict=True):
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
    ref = undistort_points(pts, np.eye(3), np.array(dist), crit).reshape(-1, 2)  # OpenCV's solver
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


@pytest.mark.slow
def test_fov_is_kept_when_the_size_changes():
    a = DeskLampScene(DeskLampConfig(width=160, height=120, frames=24)).lens
    b = DeskLampScene(DeskLampConfig(width=320, height=240, frames=24)).lens
    assert a.fx / 160 == pytest.approx(b.fx / 320) and a.fy / 120 == pytest.approx(b.fy / 240)
    assert (a.cx + 0.5) / 160 == pytest.approx((b.cx + 0.5) / 320)
    assert (a.cy + 0.5) / 120 == pytest.approx((b.cy + 0.5) / 240)
    assert b.fx * 800 / 320 == pytest.approx(900, rel=0.02)


# ------------------------------------------------------------------ the field log and files


@pytest.mark.slow
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


@pytest.mark.slow
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
    e, lv = gt["enter_time"][sw], gt["leave_time"][sw]
    assert (e >= 1).all() and (lv <= N - 2).all() and (e < lv).all()
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


@pytest.mark.slow
def test_determinism_and_seed(tmp_path):
    a = simulate_desk_lamp(tmp_path / "a", TINY)
    b = simulate_desk_lamp(tmp_path / "b", TINY)
    c = simulate_desk_lamp(tmp_path / "c", DeskLampConfig(width=160, height=120, frames=24, seed=4))
    assert [p.name for p in a.frames] == [p.name for p in b.frames]
    assert all(p.suffix == ".jpg" for p in a.frames)
    assert all(pa.read_bytes() == pb.read_bytes() for pa, pb in zip(a.frames, b.frames, strict=True))
    ga, gb = np.load(a.ground_truth), np.load(b.ground_truth)
    for key in ga.files:
        np.testing.assert_array_equal(ga[key], gb[key])
    assert a.field_log.read_text() == b.field_log.read_text()
    assert any(pa.read_bytes() != pc.read_bytes() for pa, pc in zip(a.frames, c.frames, strict=True))


@pytest.mark.slow
def test_rerun_replaces_a_previous_capture(tmp_path):
    simulate_desk_lamp(tmp_path, DeskLampConfig(width=160, height=120, frames=30, jpeg_quality=0))
    r = simulate_desk_lamp(tmp_path, TINY)
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [p.name for p in r.frames]
    assert tomllib.loads(r.field_log.read_text())["capture"]["frames"] == "frames/*.jpg"


# ------------------------------------------------------------------ the shadow


def linearise(dn: np.ndarray, gamma: float) -> np.ndarray:
    return (dn / 255.0) ** gamma


@pytest.mark.slow
def test_frames_show_the_shadow_between_enter_and_leave(small, small_frames, small_scene):
    _, gt = small
    sc = small_scene
    lit, dark = sc.lit_image(), sc.shadowed_image()
    sw = gt["swept"]
    e, lv = gt["enter_time"], gt["leave_time"]
    for k in (30, 48, 70):
        lin = linearise(small_frames[k], SMALL.gamma)
        level = np.divide(lin - dark, lit - dark, out=np.zeros_like(lin), where=sw)  # 1 lit, 0 dark
        inside = sw & (e < k - 0.5) & (lv > k + 0.5)
        outside = sw & ((e > k + 3) | (lv < k - 3))
        assert inside.sum() > 50 and outside.sum() > 10000
        assert np.median(level[inside]) < 0.2
        assert np.median(level[outside]) == pytest.approx(1.0, abs=0.02)
        assert np.percentile(level[inside], 95) < 0.5 < np.percentile(level[outside], 1)
    # The first two and the last two frames are entirely lit.
    for k in (0, 1, SMALL.frames - 2, SMALL.frames - 1):
        assert sc.occlusion(k, restrict=False).max() == 0.0


@pytest.mark.slow
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


@pytest.mark.slow
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


# ------------------------------------------------------------------ desk_lamp_right: the mirrored lamp

RIGHT = DeskLampConfig(width=320, height=240, frames=96, jpeg_quality=0, seed=0, lamp_side="right",
                       pencil_photos=0)


@pytest.fixture(scope="module")
def right_scene():
    return DeskLampScene(RIGHT)


def test_right_lamp_is_the_mirror_image(small_scene, right_scene):
    left, right = small_scene, right_scene
    # Same camera, same pixel grid, same surfaces and texture.
    np.testing.assert_array_equal(left.lens.K, right.lens.K)
    np.testing.assert_array_equal(left.R, right.R)
    np.testing.assert_array_equal(left.t, right.t)
    np.testing.assert_array_equal(left.depth, right.depth)
    np.testing.assert_array_equal(left.object_id, right.object_id)
    np.testing.assert_array_equal(left.albedo, right.albedo)
    # The lamp: mirrored across the vertical plane through the camera and the scene centre.
    SL, SR, C = left.S, right.S, left.C
    centre = np.zeros(3)
    m = np.cross([0.0, 0.0, 1.0], C - centre)
    m /= np.linalg.norm(m)
    np.testing.assert_allclose(SR, SL - 2 * (SL @ m) * m, atol=1e-9)
    assert SR[2] == pytest.approx(SL[2])
    assert np.linalg.norm(SR - C) == pytest.approx(np.linalg.norm(SL - C))
    assert np.linalg.norm(SR) == pytest.approx(np.linalg.norm(SL))
    # Left of the camera vs right of it (camera x).
    assert (left.R @ (SL - C))[0] < -200 and (right.R @ (SR - C))[0] > 200


@pytest.mark.slow
def test_right_scan_fills_other_cast_shadows(small, right_scene):
    _, gt = small
    right = right_scene.ground_truth_arrays()
    assert set(gt) - {k for k in gt if k.startswith("pencil_")} == set(right)
    sl, sr = gt["swept"], right["swept"]
    assert sr.mean() > 0.85
    # The cast shadows differ: each scan sweeps pixels the other cannot.
    only_right, only_left = (sr & ~sl).sum(), (sl & ~sr).sum()
    assert only_right > 0.01 * sl.size and only_left > 0.01 * sl.size
    assert (sl | sr).mean() > max(sl.mean(), sr.mean())
    # The stick sweeps the same way: on the desk, shadow times grow with the column.
    for g in (gt, right):
        desk = g["swept"] & (g["object_id"] == 0)
        v, u = np.nonzero(desk)
        assert np.corrcoef(u, g["enter_time"][desk])[0, 1] > 0.95
    np.testing.assert_allclose(right["shadow_planes_enter"][:, :3] @ right["lamp"] - right["shadow_planes_enter"][:, 3],
                               0, atol=1e-9)


@pytest.mark.slow
def test_right_capture_files(tmp_path, small):
    r = simulate_desk_lamp(tmp_path, RIGHT)
    log = tomllib.loads(r.field_log.read_text())
    gt = np.load(r.ground_truth)
    assert "desk_lamp_right" in r.field_log.read_text().splitlines()[0]
    assert log["light"] == {"kind": "lamp", "position": list(gt["lamp"])}
    assert gt["lamp"][0] > 300
    _, left = small
    assert set(gt.files) == set(left)
    info = json.loads(r.ground_truth_json.read_text())
    assert info["scene"] == "desk_lamp_right" and info["lamp_side"] == "right"
    assert r.pencil_log is None and not (tmp_path / "pencil_log.toml").exists()
    assert gt["pencil_bases_world"].shape == (0, 3)
    for (u0, v0, u1, v1) in log["planes"][0]["regions"]:
        assert (gt["object_id"][v0:v1, u0:u1] == 0).all() and gt["swept"][v0:v1, u0:u1].all()


@pytest.mark.slow
def test_right_capture_has_its_own_noise(tmp_path, small, small_scene, right_scene):
    """Another recording, another noise draw: the two captures' noise is uncorrelated."""
    left_result, _ = small
    right_result = simulate_desk_lamp(tmp_path, RIGHT)
    residuals = []
    for result, sc in ((left_result, small_scene), (right_result, right_scene)):
        dn = cv2.imread(str(result.frames[0]), cv2.IMREAD_UNCHANGED).astype(np.float64)
        clean = 255.0 * np.clip(sc.lit_image(), 0, 1) ** (1 / SMALL.gamma)
        residuals.append((dn - clean).ravel())
    assert 1.2 < residuals[0].std() < 2.0 and 1.2 < residuals[1].std() < 2.0
    assert abs(np.corrcoef(residuals[0], residuals[1])[0, 1]) < 0.05


# ------------------------------------------------------------------ a wide stick


@pytest.fixture(scope="module")
def wide_scene():
    return DeskLampScene(DeskLampConfig(width=320, height=240, frames=96, stick_radius=6.0, pencil_photos=0))


def test_wide_stick_planes_are_tangent_on_both_sides(wide_scene):
    sc = wide_scene
    gt = sc.ground_truth_arrays()
    assert float(gt["stick_radius"]) == 6.0
    S = gt["lamp"]
    QA, QB = gt["stick_axis"][:, 0], gt["stick_axis"][:, 1]
    D = (QB - QA) / np.linalg.norm(QB - QA, axis=1, keepdims=True)
    foot = QA + np.einsum("ij,ij->i", S - QA, D)[:, None] * D   # the axis point nearest the lamp
    en, le = gt["shadow_planes_enter"], gt["shadow_planes_leave"]
    g_en = np.einsum("ij,ij->i", en[:, :3], foot) - en[:, 3]
    g_le = np.einsum("ij,ij->i", le[:, :3], foot) - le[:, 3]
    # Each plane is tangent to the stick (its axis 6 mm away), the stick between them:
    # at the stick the two planes are 12 mm apart, the stick's width.
    np.testing.assert_allclose(g_en, -6.0, atol=1e-9)
    np.testing.assert_allclose(g_le, 6.0, atol=1e-9)
    # Both contain the axis direction and the lamp; they open at 2·asin(r/h) from the lamp.
    np.testing.assert_allclose(en[:, :3] @ S - en[:, 3], 0, atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,ij->i", en[:, :3], D), 0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", le[:, :3], D), 0, atol=1e-12)
    h = np.linalg.norm(foot - S, axis=1)
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", en[:, :3], le[:, :3]), -1, 1))
    np.testing.assert_allclose(angle, 2 * np.arcsin(6.0 / h), atol=1e-9)
    assert gt["swept"].mean() > 0.85


def test_wide_stick_times_are_exact(wide_scene, small_scene):
    """Both edges of the wide shadow are where the ground truth puts them: half of the
    lamp hidden at enter_time and at leave_time, and a longer shadow than the thin stick's."""
    sc = wide_scene
    sw = sc.swept
    rng = np.random.default_rng(5)
    ys, xs = np.nonzero(sw)
    for i in rng.choice(len(ys), 40, replace=False):
        y, x = ys[i], xs[i]
        e, lv = sc.enter_time[y, x], sc.leave_time[y, x]
        assert sc.occlusion(e)[y, x] == pytest.approx(0.5, abs=1e-6)
        assert sc.occlusion(lv)[y, x] == pytest.approx(0.5, abs=1e-6)
        assert sc.occlusion((e + lv) / 2)[y, x] == pytest.approx(1.0, abs=1e-6)   # the umbra between
    both = sw & small_scene.swept
    wide_len = (sc.leave_time - sc.enter_time)[both]
    thin_len = (small_scene.leave_time - small_scene.enter_time)[both]
    assert np.median(wide_len) > 2.0 * np.median(thin_len)


# ------------------------------------------------------------------ pencil photos


@pytest.fixture(scope="module")
def pencil_capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("pencil")
    cfg = DeskLampConfig(width=320, height=240, frames=24, jpeg_quality=0, seed=0, pencil_photos=4)
    return simulate_desk_lamp(out, cfg), cfg


@pytest.mark.slow
def test_pencil_log_and_truth(pencil_capture):
    r, cfg = pencil_capture
    assert r.pencil_log == r.out_dir / "pencil_log.toml"
    log = tomllib.loads(r.pencil_log.read_text())
    gt = np.load(r.ground_truth)
    assert set(log) == {"camera", "planes", "pencil"}
    pen = log["pencil"]
    assert pen["height"] == 150.0 and pen["units"] == "mm" and pen["plane"] == "desk" and pen["sigma_px"] > 0
    photos = pen["photos"]
    assert len(photos) == 4 == len(r.pencil_photos)
    S = gt["lamp"]
    B, T, Ts = gt["pencil_bases_world"], gt["pencil_tops_world"], gt["pencil_tips_world"]
    np.testing.assert_allclose(B[:, 2], 0) and np.testing.assert_allclose(Ts[:, 2], 0, atol=1e-9)
    np.testing.assert_allclose(T - B, np.tile([0.0, 0.0, 150.0], (4, 1)))
    # The tip is on the line from the lamp through the pencil's top.
    d1, d2 = T - S, Ts - S
    np.testing.assert_allclose(np.cross(d1, d2) / np.linalg.norm(d1, axis=1)[:, None]
                               / np.linalg.norm(d2, axis=1)[:, None], 0, atol=1e-12)
    # Pixels: cv2's projection of the truth, rounded to 0.1 px; inside the image.
    for key, pts in (("base", B), ("tip", Ts)):
        proj, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), gt["rvec"], gt["tvec"], gt["K"], gt["dist"])
        logged = np.array([p[key] for p in photos])
        assert np.abs(logged - proj.reshape(-1, 2)).max() <= 0.05 + 1e-9
        assert (logged >= 0).all() and (logged[:, 0] <= 319).all() and (logged[:, 1] <= 239).all()
    for p in photos:
        assert (r.out_dir / p["image"]).is_file() and p["image"].startswith("pencil/pencil_")
    # Well spread: no two bases closer than 100 mm.
    dists = np.linalg.norm(B[:, None, :2] - B[None, :, :2], axis=-1)
    assert dists[~np.eye(4, dtype=bool)].min() > 100
    info = json.loads(r.ground_truth_json.read_text())
    assert info["pencil"]["photos"] == 4


@pytest.mark.slow
def test_pencil_photos_show_pencil_and_shadow(pencil_capture):
    r, cfg = pencil_capture
    gt = np.load(r.ground_truth)
    sc = DeskLampScene(cfg)
    lit, dark = sc.lit_image(), sc.shadowed_image()
    for k, path in enumerate(r.pencil_photos):
        img = linearise(cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float64), cfg.gamma)
        level = np.divide(img - dark, lit - dark, out=np.zeros_like(img), where=lit > dark + 1e-3)
        b, t = gt["pencil_base_pixels"][k], gt["pencil_tip_pixels"][k]
        # Half-way along the shadow, the desk is dark (the umbra, up to blur and noise).
        mid = np.rint((b + t) / 2).astype(int)
        assert level[mid[1], mid[0]] < 0.3
        # Beyond the tip (8 px further along, away from the pencil) the desk is lit.
        beyond = np.rint(t + 8.0 * (t - b) / np.linalg.norm(t - b)).astype(int)
        if 0 <= beyond[0] < cfg.width and 0 <= beyond[1] < cfg.height:
            assert level[beyond[1], beyond[0]] > 0.85
        # Away from pencil and shadow, the photo is the stick-free lit image.
        far = np.abs(img - lit) < 0.03
        assert far.mean() > 0.9


@pytest.mark.slow
def test_pencil_photos_calibrate_the_lamp(pencil_capture):
    """gnomon.light (the pipeline) recovers the simulator's lamp from the pencil log."""
    from gnomon.config.pencil_log import load_pencil_log
    from gnomon.light import calibrate_lamp_from_pencil

    r, _ = pencil_capture
    gt = np.load(r.ground_truth)
    log = load_pencil_log(r.pencil_log)
    assert [str(x) for x in log.images] == [f"pencil/pencil_{k}.png" for k in range(4)]
    cal = calibrate_lamp_from_pencil(log.camera, log.pose, log.plane_point, log.plane_normal,
                                     log.bases_px, log.tips_px, log.height, log.sigma_px)
    S = gt["lamp"]
    distance = np.linalg.norm(S - gt["pencil_bases_world"].mean(axis=0))
    assert np.linalg.norm(cal.position_world - S) < 0.01 * distance
    assert not cal.warnings


@pytest.mark.slow
def test_pencil_log_calibrates_either_lamp_closely(tmp_path):
    """The log's pixels (no rendering needed) pin both lamps to 0.1 % of their distance."""
    from gnomon.config.pencil_log import load_pencil_log
    from gnomon.light import calibrate_lamp_from_pencil
    from gnomon.simulate import pencil

    for side in ("left", "right"):
        sc = DeskLampScene(DeskLampConfig(width=400, height=300, frames=8, lamp_side=side))
        xy = pencil.pencil_positions(sc, 3)
        pens = [pencil.Pencil(p) for p in xy]
        ph = pencil.PencilPhotos(np.array([p.base for p in pens]), np.array([p.top for p in pens]),
                                 np.array([p.shadow_tip(sc.S) for p in pens]),
                                 sc.project(np.array([p.base for p in pens])),
                                 sc.project(np.array([p.shadow_tip(sc.S) for p in pens])), [],
                                 [f"pencil/pencil_{k}.jpg" for k in range(3)])
        path = tmp_path / f"{side}.toml"
        pencil.write_pencil_log(sc, ph, path)
        log = load_pencil_log(path)
        cal = calibrate_lamp_from_pencil(log.camera, log.pose, log.plane_point, log.plane_normal,
                                         log.bases_px, log.tips_px, log.height, log.sigma_px)
        assert np.linalg.norm(cal.position_world - sc.S) < 0.001 * np.linalg.norm(sc.S)


def test_pencil_cone_and_body():
    from gnomon.simulate.pencil import Pencil

    p = Pencil((10.0, -20.0))
    # Straight down from above, 0.5 mm off the axis: the cone where its radius is 0.5 mm.
    t = p.intersect(np.array([10.5, -20.0, 300.0]), np.array([0.0, 0.0, -1.0]))
    assert t == pytest.approx(150.0 + 0.5 * 18.0 / 3.5)
    # Horizontally at mid-height: the body.
    t = p.intersect(np.array([-90.0, -20.0, 60.0]), np.array([1.0, 0.0, 0.0]))
    assert t == pytest.approx(100.0 - 3.5)
    # Through the sharpened part, half-way up the cone: radius 1.75.
    z = 150.0 - 9.0
    t = p.intersect(np.array([-90.0, -20.0, z]), np.array([1.0, 0.0, 0.0]))
    assert t == pytest.approx(100.0 - 1.75)
    X = np.array([[10.0 - 1.75, -20.0, z]])
    n = p.normal(X)[0]
    assert n[0] < 0 and n[2] > 0 and np.linalg.norm(n) == pytest.approx(1.0)
    # Just above the apex: a miss.
    assert not np.isfinite(p.intersect(np.array([-90.0, -20.0, 150.5]), np.array([1.0, 0.0, 0.0])))


def test_bad_pencil_photo_count(tmp_path):
    parser = make_parser()
    args = parser.parse_args(["simulate", "desk_lamp", "--out", str(tmp_path / "x"), "--pencil-photos", "1"])
    with pytest.raises(GnomonError, match="pencil-photos"):
        args.func(args)


def test_command_line_right_and_two_plane(tmp_path, capsys):
    parser = make_parser()
    for scene in ("desk_lamp_right", "two_plane"):
        args = parser.parse_args(["simulate", scene, "--out", str(tmp_path / scene), "--width", "160",
                                  "--height", "120", "--frames", "16", "--pencil-photos", "2", "--quiet"])
        assert args.func(args) == 0
        info = json.loads((tmp_path / scene / "ground_truth.json").read_text())
        assert info["scene"] == scene
    out = capsys.readouterr().out
    assert "2 pencil photos" in out and out.count("wrote 16 frames") == 2
    assert len(list((tmp_path / "desk_lamp_right" / "pencil").glob("*.jpg"))) == 2
    assert not (tmp_path / "two_plane" / "pencil").exists()


@pytest.mark.slow
def test_a_drifting_camera_moves_the_frames_not_the_truth():
    """The desk scenes take the facade's camera motion (gnomon.simulate.sensor.camera_motion): the truth is
    frame 0's grid, frame 0 is the still camera's, a later frame samples the same blurred image moved."""
    import dataclasses

    from gnomon.simulate import sensor

    still = DeskLampScene(TINY)
    moving = DeskLampScene(dataclasses.replace(TINY, drift_px=2.0, bump_px=1.0))
    np.testing.assert_array_equal(moving.depth, still.depth)
    np.testing.assert_array_equal(moving.swept, still.swept)
    np.testing.assert_allclose(moving.ground_truth_arrays()["camera_motion_px"],
                               sensor.camera_motion(TINY.frames, 2.0, 1.0, None))
    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(moving.frame(0, np.random.default_rng(0)), still.frame(0, rng))
    k = TINY.frames - 1
    assert not np.array_equal(moving.linear_image(k, shift=moving.camera_motion[k]), still.linear_image(k))
