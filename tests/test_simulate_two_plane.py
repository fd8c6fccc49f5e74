"""The synthetic two-plane capture (desk + wall, unknown lamp): its ground truth is
self-consistent and agrees with independent code (OpenCV's projection and corner
refinement), its regions are bare and swept, every shadow plane contains the lamp
and cuts both planes, and the field log gives everything but the lamp."""

from __future__ import annotations

import glob
import json
import tomllib

import cv2
import numpy as np
import pytest

from gnomon.simulate import TwoPlaneConfig, TwoPlaneScene, simulate_two_plane
from gnomon.simulate.two_plane_scene import MARKER_PAPER, WALL_Y

SMALL = TwoPlaneConfig(width=320, height=240, frames=96, jpeg_quality=0, seed=0)
DESK, SPHERE, BOX, WALL = 0, 1, 2, 4


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("two_plane")
    result = simulate_two_plane(out, SMALL)
    gt = dict(np.load(result.ground_truth))
    log = tomllib.loads(result.field_log.read_text())
    return result, gt, log


@pytest.fixture(scope="module")
def scene():
    return TwoPlaneScene(SMALL)


@pytest.fixture(scope="module")
def frames(capture):
    result, _, _ = capture
    return np.stack([cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in result.frames]).astype(np.float64)


def plane_frame(plane: dict):
    p, n, x = (np.asarray(plane[k], dtype=np.float64) for k in ("point", "normal", "x_axis"))
    return p, n, x, np.cross(n, x)


# ------------------------------------------------------------------ geometry


@pytest.mark.slow
def test_depth_points_and_surfaces(capture):
    _, gt, _ = capture
    P = gt["points_world"].astype(np.float64)
    depth = gt["depth"]
    assert np.isfinite(depth).all()  # desk and wall fill the view
    Xc = P @ gt["R"].T + gt["t"]
    np.testing.assert_allclose(Xc[..., 2], depth, atol=1e-3)
    C = -gt["R"].T @ gt["t"]
    assert abs(np.linalg.norm(C - [0.0, 70.0, 60.0]) - float(gt["camera_distance_mm"])) < 1e-9
    assert 600 < float(gt["camera_distance_mm"]) < 700
    oid = gt["object_id"]
    assert set(np.unique(oid)) == {DESK, SPHERE, BOX, WALL}
    assert np.abs(P[oid == DESK][:, 2]).max() < 1e-3 and (P[oid == DESK][:, 1] <= WALL_Y + 1e-3).all()
    assert np.abs(P[oid == WALL][:, 1] - WALL_Y).max() < 1e-3 and (P[oid == WALL][:, 2] >= -1e-3).all()
    assert float(gt["wall_y"]) == WALL_Y
    # Both planes are seen well: each covers a good part of the image.
    assert 0.3 < (oid == DESK).mean() < 0.6 and 0.3 < (oid == WALL).mean() < 0.6
    # The wall is above the desk in the image.
    rows = np.broadcast_to(np.arange(oid.shape[0])[:, None], oid.shape)
    assert np.median(rows[oid == WALL]) < np.median(rows[oid == DESK])


@pytest.mark.slow
def test_cv2_projectpoints_lands_on_pixel_centres(capture):
    _, gt, _ = capture
    h, w = gt["depth"].shape
    P = gt["points_world"].astype(np.float64).reshape(-1, 1, 3)
    img, _ = cv2.projectPoints(P, gt["rvec"], gt["tvec"], gt["K"], gt["dist"])
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    err = np.hypot(img[:, 0, 0] - u.ravel(), img[:, 0, 1] - v.ravel())
    assert err.max() < 0.01
    R_cv, _ = cv2.Rodrigues(gt["rvec"])
    np.testing.assert_allclose(R_cv, gt["R"], atol=1e-12)


# ------------------------------------------------------------------ the field log


@pytest.mark.slow
def test_field_log(capture):
    result, gt, log = capture
    text = result.field_log.read_text()
    assert text.startswith("#") and "two_plane" in text.splitlines()[0]
    assert set(log) == {"capture", "camera", "planes", "light", "scan"}
    assert log["light"] == {"kind": "two-plane"}
    # The lamp is nowhere in the log.
    for x in gt["lamp"]:
        assert repr(float(x)) not in text
    cap = log["capture"]
    assert cap["frames"] == "frames/*.png" and cap["frame_count"] == SMALL.frames and cap["gamma"] == 2.2
    assert len(glob.glob(str(result.out_dir / cap["frames"]))) == SMALL.frames
    cam = log["camera"]
    K = gt["K"]
    assert (cam["fx"], cam["fy"], cam["cx"], cam["cy"]) == (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    np.testing.assert_array_equal(cam["dist"], gt["dist"])
    np.testing.assert_array_equal(cam["pose"]["rvec"], gt["rvec"])
    np.testing.assert_array_equal(cam["pose"]["tvec"], gt["tvec"])
    assert log["scan"]["min_contrast"] == 20
    assert [p["name"] for p in log["planes"]] == ["desk", "wall"]
    for i, plane in enumerate(log["planes"]):
        assert set(plane) == {"name", "point", "normal", "x_axis", "regions", "markers"}
        p, n, x, y = plane_frame(plane)
        assert np.linalg.norm(n) == pytest.approx(1) and np.linalg.norm(x) == pytest.approx(1)
        assert n @ x == pytest.approx(0)
        np.testing.assert_array_equal(p, gt["plane_points"][i])
        np.testing.assert_array_equal(n, gt["plane_normals"][i])
        np.testing.assert_array_equal(x, gt["plane_x_axes"][i])
        # The normal faces the camera.
        C = -gt["R"].T @ gt["t"]
        assert n @ (C - p) > 0
    desk, wall = log["planes"]
    np.testing.assert_array_equal(plane_frame(desk)[3], [0, 1, 0])
    np.testing.assert_array_equal(plane_frame(wall)[3], [0, 0, 1])
    info = json.loads(result.ground_truth_json.read_text())
    assert info["scene"] == "two_plane" and info["lamp"] == list(gt["lamp"]) and not info["lamp_in_field_log"]
    assert not [p for p in result.out_dir.rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_regions_are_bare_swept_and_clear_of_markers(capture):
    _, gt, log = capture
    h, w = gt["depth"].shape
    P = gt["points_world"].astype(np.float64)
    for plane, oid in zip(log["planes"], (DESK, WALL), strict=True):
        regions = plane["regions"]
        assert len(regions) >= 2
        p, n, x, y = plane_frame(plane)
        ab = np.stack([(P - p) @ x, (P - p) @ y], axis=-1)
        on_paper = np.zeros((h, w), dtype=bool)
        for m in plane["markers"]:
            on_paper |= (np.abs(ab - m["plane_xy"]) < MARKER_PAPER / 2 + 1.0).all(axis=-1)
        on_paper &= gt["object_id"] == oid
        for u0, v0, u1, v1 in regions:
            assert all(isinstance(c, int) for c in (u0, v0, u1, v1))
            assert 0 <= u0 < u1 <= w and 0 <= v0 < v1 <= h
            assert v1 - v0 >= 0.04 * h and u1 - u0 >= 0.3 * w
            sl = (slice(v0, v1), slice(u0, u1))
            assert (gt["object_id"][sl] == oid).all()
            assert gt["swept"][sl].all()
            assert not on_paper[sl].any()
        # Regions spread over the plane's height in the image (a good line fit).
        tops = sorted(r[1] for r in regions)
        assert tops[-1] - tops[0] > 0.15 * h
    # Desk regions below wall regions.
    assert min(r[1] for r in log["planes"][0]["regions"]) > max(r[1] for r in log["planes"][1]["regions"])


# ------------------------------------------------------------------ markers


@pytest.mark.slow
def test_markers(capture, frames):
    _, gt, log = capture
    ids = []
    for i, plane in enumerate(log["planes"]):
        p, n, x, y = plane_frame(plane)
        assert len(plane["markers"]) == 4
        for k, m in enumerate(plane["markers"]):
            ids.append(m["id"])
            assert m["id"] == gt["marker_ids"][i, k]
            np.testing.assert_array_equal(m["plane_xy"], gt["marker_plane_xy"][i, k])
            np.testing.assert_array_equal(m["pixel_hint"], gt["marker_hints"][i, k])
            X = p + m["plane_xy"][0] * x + m["plane_xy"][1] * y
            np.testing.assert_allclose(X, gt["marker_world"][i, k], atol=1e-12)
            assert abs((X - p) @ n) < 1e-12
    assert sorted(ids) == list(range(8))
    # The true pixels are OpenCV's projections of the centres, 3–8 px from the hints.
    W = gt["marker_world"].reshape(-1, 1, 3)
    proj, _ = cv2.projectPoints(W, gt["rvec"], gt["tvec"], gt["K"], gt["dist"])
    np.testing.assert_allclose(proj.reshape(2, 4, 2), gt["marker_pixels"], atol=1e-9)
    dist = np.linalg.norm(gt["marker_hints"] - gt["marker_pixels"], axis=-1)
    assert (dist >= 3.0 - 0.08).all() and (dist <= 8.0 + 0.08).all()
    h, w = gt["depth"].shape
    assert (gt["marker_pixels"] > 3).all() and (gt["marker_pixels"][..., 0] < w - 4).all()
    assert (gt["marker_pixels"][..., 1] < h - 4).all()
    # The rendered X-junctions are where the truth says: OpenCV's corner refinement on the
    # first (shadow-free) frame, started at the nearest whole pixel (at this small size a
    # checker square is ~8 px, about the hint's offset), lands within 0.25 px.
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    img = frames[0].astype(np.float32)
    start = np.rint(gt["marker_pixels"]).reshape(-1, 1, 2).astype(np.float32)
    found = cv2.cornerSubPix(img, start, (3, 3), (-1, -1), crit)
    err = np.linalg.norm(found.reshape(2, 4, 2) - gt["marker_pixels"], axis=-1)
    assert err.max() < 0.25


# ------------------------------------------------------------------ the shadow planes


@pytest.mark.slow
def test_shadow_planes_contain_the_lamp_and_cut_both_planes(capture):
    _, gt, log = capture
    N = SMALL.frames
    S = gt["lamp"]
    en, le = gt["shadow_planes_enter"], gt["shadow_planes_leave"]
    assert en.shape == le.shape == (N, 4)
    for planes in (en, le):
        np.testing.assert_allclose(np.linalg.norm(planes[:, :3], axis=1), 1, atol=1e-12)
        np.testing.assert_allclose(planes[:, :3] @ S - planes[:, 3], 0, atol=1e-9)
    # The lamp lights both planes from the camera's side.
    for plane in log["planes"]:
        p, n, _, _ = plane_frame(plane)
        assert (S - p) @ n > 100
    sw = gt["swept"]
    cuts = gt["cuts_both"]
    assert cuts.dtype == bool and cuts.sum() > 0.5 * N
    k_first, k_last = np.nonzero(cuts)[0][[0, -1]]
    assert cuts[k_first:k_last + 1].all()                  # one contiguous stretch
    assert not cuts[:2].any() and not cuts[-2:].any()       # the shadow is out of view there
    # Every swept pixel's crossings lie between frames whose planes cut both planes.
    for times in (gt["enter_time"][sw], gt["leave_time"][sw]):
        assert (np.floor(times) >= k_first).all() and (np.ceil(times) <= k_last).all()
    # Independently: in each such frame the entering plane's line shows on the desk and on
    # the wall: there are swept pixels of both within a frame of it, and they lie on it.
    P = gt["points_world"].astype(np.float64)
    oid = gt["object_id"]
    e = gt["enter_time"]
    for k in range(k_first + 2, k_last - 1, 3):
        near = sw & (np.abs(e - k) < 1.0)
        for plane_id in (DESK, WALL):
            sel = near & (oid == plane_id)
            assert sel.sum() >= 3, (k, plane_id)
            g = P[sel] @ en[k, :3] - en[k, 3]
            assert np.abs(g).max() < 15.0   # mm: within a frame's motion of the plane
    # At integer frames the planes bracket each pixel's times (the sign convention).
    for key, tkey in (("shadow_planes_enter", "enter_time"), ("shadow_planes_leave", "leave_time")):
        planes = gt[key]
        t = gt[tkey][sw].astype(np.float64)
        k0 = np.floor(t).astype(int)
        Q = P[sw]
        g0 = np.einsum("ij,ij->i", planes[k0, :3], Q) - planes[k0, 3]
        g1 = np.einsum("ij,ij->i", planes[np.minimum(k0 + 1, N - 1), :3], Q) - planes[np.minimum(k0 + 1, N - 1), 3]
        assert (g0 > -1e-3).all() and (g1 < 1e-3).all()


@pytest.mark.slow
def test_times_and_coverage(capture):
    _, gt, _ = capture
    N = SMALL.frames
    sw = gt["swept"]
    assert sw.mean() > 0.75  # the stick is rocked ±8° (the lamp must be observable), which sweeps a little less
    e, lv = gt["enter_time"][sw], gt["leave_time"][sw]
    assert (e >= 1).all() and (lv <= N - 2).all() and (e < lv).all()
    # Most of each plane is swept (the rest: marker edges, the corner, object silhouettes and
    # cast shadows, the image's far corners the shadow plane reaches only off the other plane).
    for plane_id, share in ((DESK, 0.75), (WALL, 0.85)):
        assert (sw & (gt["object_id"] == plane_id)).sum() > share * (gt["object_id"] == plane_id).sum()
    # The stick sweeps left to right on both planes.
    for plane_id in (DESK, WALL):
        sel = sw & (gt["object_id"] == plane_id)
        v, u = np.nonzero(sel)
        assert np.corrcoef(u, gt["enter_time"][sel])[0, 1] > 0.9


@pytest.mark.slow
def test_penumbra_centre_on_both_planes(capture, scene):
    """At enter_time / leave_time half of the lamp is hidden, on desk, wall and objects."""
    _, gt, _ = capture
    sc = scene
    np.testing.assert_array_equal(sc.swept, gt["swept"])
    rng = np.random.default_rng(1)
    for plane_id in (DESK, WALL, SPHERE, BOX):
        ys, xs = np.nonzero(gt["swept"] & (gt["object_id"] == plane_id))
        for i in rng.choice(len(ys), 12, replace=False):
            y, x = ys[i], xs[i]
            for t in (sc.enter_time[y, x], sc.leave_time[y, x]):
                assert sc.occlusion(t)[y, x] == pytest.approx(0.5, abs=1e-6)


@pytest.mark.slow
def test_frames_show_the_shadow_on_both_planes(capture, frames, scene):
    _, gt, _ = capture
    sc = scene
    lit, dark = sc.lit_image(), sc.shadowed_image()
    sw = gt["swept"]
    e, lv = gt["enter_time"], gt["leave_time"]
    for k in (35, 55):
        lin = (frames[k] / 255.0) ** SMALL.gamma
        level = np.divide(lin - dark, lit - dark, out=np.zeros_like(lin), where=sw)
        for plane_id in (DESK, WALL):
            on = sw & (gt["object_id"] == plane_id)
            inside = on & (e < k - 0.5) & (lv > k + 0.5)
            outside = on & ((e > k + 3) | (lv < k - 3))
            assert inside.sum() > 20 and outside.sum() > 5000
            assert np.median(level[inside]) < 0.25
            assert np.median(level[outside]) == pytest.approx(1.0, abs=0.03)


@pytest.mark.slow
def test_determinism(tmp_path):
    cfg = TwoPlaneConfig(width=160, height=120, frames=20, seed=2)
    a = simulate_two_plane(tmp_path / "a", cfg)
    b = simulate_two_plane(tmp_path / "b", cfg)
    assert all(pa.read_bytes() == pb.read_bytes() for pa, pb in zip(a.frames, b.frames, strict=True))
    assert a.field_log.read_text() == b.field_log.read_text()
    ga, gb = np.load(a.ground_truth), np.load(b.ground_truth)
    for key in ga.files:
        np.testing.assert_array_equal(ga[key], gb[key])
