"""Tsai's camera model and two-stage calibration (gnomon.camera.models.TsaiCamera, gnomon.camera.tsai).

Ground truth comes from the simulator's own Tsai model
(gnomon.simulate.chessboard.TruthTsai), not from the code under test.
Scene: a 1280×960 camera, 3.75 µm pixels, f = 6 mm (1600 px), κ1 = 3e-3 /mm²
(≈2.7 % radial distortion, ≈25 px, in the image corners); a 16×12 grid of
20 mm squares ≈450 mm away, filling most of the frame; 0.2 px Gaussian noise
per axis. The issue's acceptance bars (f 0.5 %, κ1 10 %, R 0.1°, T 0.5 %) are
3–5× the errors measured on this scene over 10 seeds (f ≤ 0.15 %, κ1 ≤ 3 %,
R ≤ 0.03°, T ≤ 0.15 %).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gnomon.camera import calibration, tsai
from gnomon.camera.models import Pose, TsaiCamera
from gnomon.errors import GnomonError
from gnomon.simulate.chessboard import TruthTsai, board_points, random_poses, synthetic_corners

W, H = 1280, 960
PITCH = 0.00375
NOISE = 0.2


def truth_camera(kappa1=3e-3, sx=1.0, cx=None, cy=None) -> TruthTsai:
    return TruthTsai(
        W, H, 6.0, kappa1, (W - 1) / 2 if cx is None else cx, (H - 1) / 2 if cy is None else cy, PITCH, PITCH, sx
    )


def grid(nx=16, ny=12, sq=20.0, z=None) -> np.ndarray:
    g = board_points(nx, ny, sq)
    if z is not None:  # a second, parallel layer: a non-coplanar target
        g2 = g.copy()
        g2[:, 2] = z
        g = np.concatenate([g, g2])
    return g


def pose_for(world: np.ndarray, euler_deg, centre_cam) -> tuple[np.ndarray, np.ndarray]:
    R = Rotation.from_euler("xyz", euler_deg, degrees=True).as_matrix()
    c = world.mean(axis=0)
    return R, np.asarray(centre_cam, dtype=np.float64) - R @ c


def observe(cam, world, R, t, noise=NOISE, seed=0):
    pix = cam.project(world @ R.T + t)
    return pix + np.random.default_rng(seed).normal(0.0, noise, pix.shape)


def errors(res: tsai.TsaiResult, cam: TruthTsai, R, t):
    dR = np.degrees(Rotation.from_matrix(res.pose.R @ R.T).magnitude())
    return {
        "f": abs(res.camera.f_mm / cam.f_mm - 1),
        "kappa1": abs(res.camera.kappa1 / cam.kappa1 - 1),
        "R_deg": dR,
        "T": np.linalg.norm(res.pose.t - t) / np.linalg.norm(t),
    }


def report(label, res, e):
    """Measured figures, shown with `pytest -s -k acceptance`."""
    print(
        f"\n[tsai {label}] f {100 * e['f']:.3f} %  kappa1 {100 * e['kappa1']:.2f} %  R {e['R_deg']:.4f}°  "
        f"T {100 * e['T']:.3f} %  sx {res.camera.sx:.5f}  RMS {res.rms_px:.3f} px "
        f"(noise σ√2 = {NOISE * np.sqrt(2):.3f})"
    )


def assert_acceptance(e):
    assert e["f"] < 0.005, e
    assert e["kappa1"] < 0.10, e
    assert e["R_deg"] < 0.1, e
    assert e["T"] < 0.005, e


# Poses spanning both signs of Tx and Ty and both tilt directions (Tsai's sign
# test and the r3/r6 sign choice are exercised).
POSES = [
    ((40, 15, 10), (0, 0, 450)),
    ((-35, 20, -25), (20, -30, 460)),
    ((30, -25, 170), (-25, 35, 440)),
    ((-45, -10, 95), (15, 25, 470)),
]


# --------------------------------------------------------------------------- the model


@pytest.mark.parametrize("kappa1", [0.0, 3e-3, -3e-3])
@pytest.mark.parametrize("sx", [1.0, 1.013])
def test_tsai_camera_round_trip_is_exact(kappa1, sx):
    cam = TsaiCamera(W, H, 6.0, kappa1, 641.3, 478.2, PITCH, PITCH * 1.01, sx)
    pix = np.random.default_rng(1).uniform([0, 0], [W - 1, H - 1], (20000, 2))
    rays = cam.rays(pix)
    assert np.allclose(np.linalg.norm(rays, axis=1), 1.0)
    assert np.max(np.abs(cam.project(rays * 3.7) - pix)) < 1e-9
    # and the other way: points → pixels → rays along the points
    pts = rays * np.random.default_rng(2).uniform(100, 1000, (len(rays), 1))
    back = cam.rays(cam.project(pts))
    assert np.max(np.linalg.norm(back - pts / np.linalg.norm(pts, axis=1, keepdims=True), axis=1)) < 1e-12


def test_tsai_camera_matches_the_simulators_independent_model():
    truth = truth_camera(kappa1=3e-3, sx=1.02, cx=650.0, cy=470.0)
    cam = TsaiCamera(W, H, truth.f_mm, truth.kappa1, truth.cx, truth.cy, PITCH, PITCH, truth.sx)
    pts = np.random.default_rng(3).uniform([-200, -150, 400], [200, 150, 600], (5000, 3))
    assert np.max(np.abs(cam.project(pts) - truth.project(pts))) < 1e-9
    pix = np.random.default_rng(4).uniform([0, 0], [W - 1, H - 1], (5000, 2))
    n = truth.normalised(pix)
    r = cam.rays(pix)
    assert np.max(np.abs(r[:, :2] / r[:, 2:] - n)) < 1e-12


def test_tsai_camera_negative_kappa_folds_to_nan_and_z_behind_is_nan():
    cam = TsaiCamera(W, H, 6.0, -0.05, 639.5, 479.5, PITCH, PITCH)
    fold_rd = 1 / np.sqrt(3 * 0.05)  # mm: the distorted radius where the map turns back
    far = np.array([[639.5 + 1.2 * fold_rd / PITCH, 479.5]])
    assert np.all(np.isnan(cam.rays(far)))
    assert np.all(np.isnan(cam.project(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -5.0]]))))


# --------------------------------------------------------------------------- two stages


@pytest.mark.parametrize("euler,centre", POSES)
def test_coplanar_exact_without_noise(euler, centre):
    cam = truth_camera()
    world = grid()
    R, t = pose_for(world, euler, centre)
    pix = observe(cam, world, R, t, noise=0.0)
    res = tsai.calibrate_coplanar(world[:, :2], pix, W, H, PITCH, PITCH)
    assert res.method == "coplanar"
    assert abs(res.camera.f_mm / cam.f_mm - 1) < 1e-9
    assert abs(res.camera.kappa1 / cam.kappa1 - 1) < 1e-7
    assert np.allclose(res.pose.R, R, atol=1e-9)
    assert np.allclose(res.pose.t, t, rtol=0, atol=1e-7)
    assert res.rms_px < 1e-6


@pytest.mark.parametrize("euler,centre", POSES)
def test_noncoplanar_exact_without_noise(euler, centre):
    cam = truth_camera(sx=1.02)
    world = grid(z=-60.0)
    R, t = pose_for(world, euler, centre)
    pix = observe(cam, world, R, t, noise=0.0)
    res = tsai.calibrate_noncoplanar(world, pix, W, H, PITCH, PITCH)
    assert res.method == "noncoplanar"
    assert abs(res.camera.sx / 1.02 - 1) < 1e-9
    assert abs(res.camera.f_mm / cam.f_mm - 1) < 1e-9
    assert np.allclose(res.pose.R, R, atol=1e-9)
    assert np.allclose(res.pose.t, t, rtol=0, atol=1e-7)


def test_linear_step_is_exact_without_distortion():
    cam = truth_camera(kappa1=0.0)
    world = grid()
    R, t = pose_for(world, *POSES[1])
    res = tsai.calibrate_coplanar(world, observe(cam, world, R, t, noise=0.0), W, H, PITCH, PITCH)
    assert res.linear["f_mm"] == pytest.approx(6.0, rel=1e-9)
    assert res.linear["tz"] == pytest.approx(t[2], rel=1e-9)
    assert abs(res.camera.kappa1) < 1e-12


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("euler,centre", POSES[:2])
def test_coplanar_acceptance_with_noise(seed, euler, centre):
    cam = truth_camera()
    world = grid()
    R, t = pose_for(world, euler, centre)
    res = tsai.calibrate_coplanar(world, observe(cam, world, R, t, seed=seed), W, H, PITCH, PITCH)
    report("coplanar", res, errors(res, cam, R, t))
    assert_acceptance(errors(res, cam, R, t))
    # honest residuals: the RMS 2-D error matches the injected noise (σ·√2)
    assert res.rms_px == pytest.approx(NOISE * np.sqrt(2), rel=0.15)
    assert res.warnings == ()
    # the reported σ of f is the right size: the error is within 4σ
    assert abs(res.camera.f_mm - cam.f_mm) < 4 * res.std["f_mm"] + 1e-12


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("euler,centre", POSES[2:])
def test_noncoplanar_acceptance_with_noise(seed, euler, centre):
    cam = truth_camera(sx=1.02)
    world = grid(z=-60.0)
    R, t = pose_for(world, euler, centre)
    res = tsai.calibrate_noncoplanar(world, observe(cam, world, R, t, seed=seed), W, H, PITCH, PITCH)
    report("non-coplanar", res, errors(res, cam, R, t))
    assert_acceptance(errors(res, cam, R, t))
    assert abs(res.camera.sx / 1.02 - 1) < 0.002
    assert res.rms_px == pytest.approx(NOISE * np.sqrt(2), rel=0.15)


def test_calibrate_dispatches_and_handles_a_plane_in_any_position():
    cam = truth_camera()
    world2d = grid()
    R, t = pose_for(world2d, *POSES[0])
    pix = observe(cam, world2d, R, t, noise=0.0)
    # The same target described in a world frame where it is tilted and shifted.
    Q = Rotation.from_euler("zyx", [30, 20, -15], degrees=True).as_matrix()
    o = np.array([100.0, -50.0, 30.0])
    world3d = world2d @ Q.T + o  # X_w = Q·X_p + o  ⇒  X_cam = R·Qᵀ·(X_w − o) + t
    res = tsai.calibrate(world3d, pix, W, H, PITCH, PITCH)
    assert res.method == "coplanar"
    assert np.allclose(res.pose.R, R @ Q.T, atol=1e-8)
    assert np.allclose(res.pose.t, t - R @ Q.T @ o, atol=1e-6)
    res = tsai.calibrate(grid(z=-60.0), observe(cam, grid(z=-60.0), R, t, noise=0), W, H, PITCH, PITCH)
    assert res.method == "noncoplanar"


def test_full_optimisation_finds_an_off_centre_principal_point():
    # A non-coplanar target pins (Cx, Cy); the two stages assume the image centre.
    cam = truth_camera(sx=1.01, cx=(W - 1) / 2 + 9.0, cy=(H - 1) / 2 - 6.0)
    world = grid(z=-80.0)
    R, t = pose_for(world, *POSES[3])
    pix = observe(cam, world, R, t, seed=5)
    two = tsai.calibrate(world, pix, W, H, PITCH, PITCH)
    full = tsai.refine_full(two, world, pix)
    assert full.method == "noncoplanar+full"
    assert full.rms_px < two.rms_px
    assert full.rms_px == pytest.approx(NOISE * np.sqrt(2), rel=0.15)
    assert abs(full.camera.cx - cam.cx) < 4 * full.std["cx"] and full.std["cx"] < 1.0
    assert abs(full.camera.cy - cam.cy) < 4 * full.std["cy"] and full.std["cy"] < 1.0
    assert_acceptance(errors(full, cam, R, t))


# --------------------------------------------------------------------------- degenerate set-ups


def test_too_few_points_is_a_clear_error():
    world = grid()[:4]
    with pytest.raises(GnomonError, match=r"coplanar calibration needs at least 5 points, got 4"):
        tsai.calibrate_coplanar(world, np.random.default_rng(0).uniform(0, 500, (4, 2)), W, H, PITCH, PITCH)
    w3 = grid(z=-60.0)[[0, 1, 20, 192, 193, 212]]
    with pytest.raises(GnomonError, match=r"non-coplanar calibration needs at least 7 points, got 6"):
        tsai.calibrate_noncoplanar(w3, np.zeros((6, 2)), W, H, PITCH, PITCH)


def test_collinear_points_are_a_clear_error():
    world = np.stack([np.arange(10.0) * 20, np.arange(10.0) * 10, np.zeros(10)], axis=1)
    pix = np.stack([300 + np.arange(10.0) * 30, 200 + np.arange(10.0) * 14], axis=1)
    with pytest.raises(GnomonError, match="collinear"):
        tsai.calibrate(world, pix, W, H, PITCH, PITCH, where="view 3")


def test_coplanar_points_given_to_the_noncoplanar_variant():
    world = grid()
    with pytest.raises(GnomonError, match="coplanar: use the coplanar variant"):
        tsai.calibrate_noncoplanar(world, np.zeros((len(world), 2)), W, H, PITCH, PITCH)


@pytest.mark.parametrize("noncoplanar", [False, True])
def test_ty_near_zero_warns_and_is_solved(noncoplanar):
    # World origin at the target's centre, which sits on the camera's x–z plane:
    # Ty = 0 exactly. Tsai's stage 1 (divided by Ty) then fails; we warn and
    # move the origin to a target point for the solve.
    cam = truth_camera(sx=1.02 if noncoplanar else 1.0)
    world = grid(z=-60.0 if noncoplanar else None)
    world = world - world.mean(axis=0)
    R = Rotation.from_euler("xyz", (40, 15, 10), degrees=True).as_matrix()
    t = np.array([0.0, 0.0, 450.0])
    pix = observe(cam, world, R, t, seed=3)
    res = tsai.calibrate(world, pix, W, H, PITCH, PITCH, where="img.png")
    assert any("Ty ≈ 0" in w and w.startswith("img.png") for w in res.warnings)
    assert_acceptance(errors(res, cam, R, t))
    # Without the remedy the paper's algorithm breaks down here (documents why we need it).
    old = tsai.TY_DEGENERATE_RATIO
    try:
        tsai.TY_DEGENERATE_RATIO = 0.0
        try:
            bad = tsai.calibrate(world, pix, W, H, PITCH, PITCH)
            e = errors(bad, cam, R, t)
            assert e["R_deg"] > 0.1 or e["f"] > 0.005
        except GnomonError:
            pass
    finally:
        tsai.TY_DEGENERATE_RATIO = old


def test_target_nearly_parallel_to_the_image_plane_warns():
    cam = truth_camera()
    world = grid()
    R, t = pose_for(world, (4, 3, 20), (30, 20, 600))
    res = tsai.calibrate_coplanar(world, observe(cam, world, R, t), W, H, PITCH, PITCH, where="flat.png")
    assert any("parallel to the image plane" in w for w in res.warnings)


# --------------------------------------------------------------------------- several views; Tsai vs Zhang


@pytest.mark.slow
def test_views_and_tsai_vs_zhang_on_the_same_views_acceptance():
    """12 chessboard views of a Tsai-model camera: both methods find the same focal length.

    Zhang's model (k1, k2, p1, p2, k3 forward) only approximates Tsai's
    inverse κ1 law, but at ≈1.7 % distortion the difference is far below the
    noise: both reach the noise floor and agree on f within 0.2 %.
    """
    truth = TruthTsai(W, H, 4.0, 4e-3, (W - 1) / 2, (H - 1) / 2, PITCH, PITCH, 1.0)
    poses = random_poses(truth, 14, 10, 15.0, 12, seed=1, fill=(0.5, 0.85), tilt_deg=(20, 50), margin_px=5)
    objs, pixs = synthetic_corners(truth, 14, 10, 15.0, poses, noise_px=NOISE, seed=1)
    z = calibration.calibrate_zhang(objs, pixs, (W, H))
    r = tsai.calibrate_views(list(zip(objs, pixs, strict=True)), W, H, PITCH, PITCH)
    rf = tsai.calibrate_views(list(zip(objs, pixs, strict=True)), W, H, PITCH, PITCH, full=True)
    f_zhang = z.camera.fy * PITCH
    print(
        f"\n[tsai vs zhang, 12 views] f: zhang {100 * (f_zhang / 4 - 1):+.3f} %, "
        f"tsai {100 * (r.camera.f_mm / 4 - 1):+.3f} %, "
        f"tsai full {100 * (rf.camera.f_mm / 4 - 1):+.3f} %; kappa1 tsai {100 * (r.camera.kappa1 / 4e-3 - 1):+.2f} %; "
        f"RMS zhang {z.rms_px:.3f} tsai {r.rms_px:.3f} full {rf.rms_px:.3f} px; "
        f"full centre error ({rf.camera.cx - truth.cx:+.2f}, {rf.camera.cy - truth.cy:+.2f}) px"
    )
    assert f_zhang == pytest.approx(4.0, rel=0.002)
    assert r.camera.f_mm == pytest.approx(4.0, rel=0.002)
    assert r.camera.f_mm == pytest.approx(f_zhang, rel=0.002)
    assert r.camera.kappa1 == pytest.approx(4e-3, rel=0.05)
    floor = NOISE * np.sqrt(2)
    for rms in (z.rms_px, r.rms_px, rf.rms_px):
        assert rms == pytest.approx(floor, rel=0.1)
    # each view alone is a coplanar Tsai calibration: all of them within the acceptance bar
    assert len(r.per_view) == 12
    for v in r.per_view:
        assert abs(v.camera.f_mm / 4.0 - 1) < 0.005
    # full: the image centre from several views, within 1 px (truth: the image centre)
    assert abs(rf.camera.cx - truth.cx) < 1.0 and abs(rf.camera.cy - truth.cy) < 1.0
    assert abs(rf.camera.sx - 1.0) < 1e-3
    assert r.poses[0].R.shape == (3, 3) and len(r.per_view_rms_px) == 12


def test_views_with_a_single_view_is_the_two_stage_result():
    cam = truth_camera()
    world = grid()
    R, t = pose_for(world, *POSES[0])
    pix = observe(cam, world, R, t)
    one = tsai.calibrate_views([(world, pix)], W, H, PITCH, PITCH)
    direct = tsai.calibrate_coplanar(world, pix, W, H, PITCH, PITCH)
    assert one.camera == direct.camera
    assert isinstance(one.poses[0], Pose)


def test_views_skip_a_degenerate_view_with_a_warning():
    cam = truth_camera()
    world = grid()
    views, names = [], []
    for k, (euler, centre) in enumerate(POSES):
        R, t = pose_for(world, euler, centre)
        views.append((world, observe(cam, world, R, t, seed=k)))
        names.append(f"v{k}.png")
    line = np.stack([np.arange(10.0) * 20, np.zeros(10), np.zeros(10)], axis=1)
    views.insert(1, (line, np.stack([300 + np.arange(10.0) * 30, np.full(10, 200.0)], axis=1)))
    names.insert(1, "line.png")
    r = tsai.calibrate_views(views, W, H, PITCH, PITCH, names=names)
    assert r.names == ("v0.png", "v1.png", "v2.png", "v3.png")
    assert any(w.startswith("line.png:") and "collinear" in w and w.endswith("view skipped") for w in r.warnings)
    assert abs(r.camera.f_mm / cam.f_mm - 1) < 0.005
