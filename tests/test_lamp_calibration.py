"""The lamp from pencil shadows (docs/method.md §7), on synthetic photos.

The photos are made here, independently of gnomon's geometry: the shadow tip
is the desk point on the line from the lamp through the pencil's top, and
pixels come straight from cv2.projectPoints with the scene's rvec/tvec.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import copy_capture
from gnomon.camera.models import OpenCVCamera, Pose
from gnomon.config.pencil_log import load_pencil_log
from gnomon.errors import GnomonError
from gnomon.light import calibrate_lamp_from_pencil
from gnomon.runs.calibrate_lamp import calibrate_lamp_cli
from gnomon.util import toml_io

SIGMA_PX = 0.3


@dataclasses.dataclass
class Scene:
    camera: OpenCVCamera
    pose: Pose
    rvec: np.ndarray
    tvec: np.ndarray
    lamp: np.ndarray
    height: float
    bases: np.ndarray  # world, on the desk z = 0
    tips: np.ndarray  # shadow tips, world

    def project(self, points_world: np.ndarray) -> np.ndarray:
        pix, _ = cv2.projectPoints(points_world.reshape(-1, 1, 3), self.rvec, self.tvec,
                                   self.camera.K, self.camera.dist_coeffs)
        return pix.reshape(-1, 2)

    @property
    def distance(self) -> float:
        """Lamp to scene (the pencils' centroid), mm."""
        return float(np.linalg.norm(self.lamp - self.bases.mean(axis=0)))


def make_scene(lamp=(-250.0, 80.0, 480.0), height=150.0,
               bases=((-120.0, -100.0), (70.0, -80.0), (0.0, 110.0))) -> Scene:
    """A 1280x960 webcam with some distortion, 600 mm from a desk (z = 0, mm), looking
    down at 42°; a bare-bulb lamp up and to the left; a 150 mm pencil at 3 spots."""
    camera = OpenCVCamera(1280, 960, 1100.0, 1100.0, 639.5, 479.5, (-0.1, 0.02, 0.001, -0.0005, 0.0))
    centre = np.array([0.0, -450.0, 400.0])
    z = -centre / np.linalg.norm(centre)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])  # rows: camera axes in the world (x right, y down, z forward)
    tvec = -R @ centre
    lamp = np.asarray(lamp, dtype=np.float64)
    b = np.array([[u, v, 0.0] for u, v in bases])
    top = b + [0.0, 0.0, height]
    tips = lamp + (top - lamp) * (lamp[2] / (lamp[2] - top[:, 2]))[:, None]
    return Scene(camera, Pose(R, tvec), cv2.Rodrigues(R)[0].ravel(), tvec, lamp, height, b, tips)


def observe(scene: Scene, rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    b, t = scene.project(scene.bases), scene.project(scene.tips)
    assert np.all((b >= 0) & (b <= [1279, 959])) and np.all((t >= 0) & (t <= [1279, 959]))
    if rng is not None:
        b = b + rng.normal(0.0, SIGMA_PX, b.shape)
        t = t + rng.normal(0.0, SIGMA_PX, t.shape)
    return b, t


def calibrate(scene: Scene, b: np.ndarray, t: np.ndarray, **kw):
    return calibrate_lamp_from_pencil(scene.camera, scene.pose, [0, 0, 0], [0, 0, 1], b, t, scene.height,
                                      kw.pop("sigma_px", SIGMA_PX), **kw)


def test_exact_photos_give_the_lamp_exactly():
    scene = make_scene()
    cal = calibrate(scene, *observe(scene))
    assert np.linalg.norm(cal.position_world - scene.lamp) < 1e-6
    assert np.all(cal.residuals < 1e-6)
    np.testing.assert_allclose(cal.bases_world, scene.bases, atol=1e-6)
    np.testing.assert_allclose(cal.shadow_tips_world, scene.tips, atol=1e-6)
    np.testing.assert_allclose(cal.tops_world[:, 2], scene.height, atol=1e-6)
    assert cal.warnings == []
    assert cal.covariance.shape == (3, 3) and np.all(np.linalg.eigvalsh(cal.covariance) > 0)
    assert cal.dof == 3


def test_normal_sign_does_not_matter():
    scene = make_scene()
    b, t = observe(scene)
    up = calibrate(scene, b, t)
    down = calibrate_lamp_from_pencil(scene.camera, scene.pose, [5.0, -3.0, 0.0], [0, 0, -2.0], b, t,
                                      scene.height, SIGMA_PX)
    np.testing.assert_allclose(down.position_world, up.position_world, atol=1e-9)


def test_noisy_photos_locate_the_lamp_within_one_percent():
    scene = make_scene()
    cal = calibrate(scene, *observe(scene, np.random.default_rng(20240417)))
    error = np.linalg.norm(cal.position_world - scene.lamp)
    assert error < 0.01 * scene.distance, (error, scene.distance)
    # ... and within what its own covariance says (χ², 3 dof, 99.9 %: 16.3).
    e = cal.position_world - scene.lamp
    assert e @ np.linalg.solve(cal.covariance, e) < 16.3
    assert np.all(cal.residuals < 3.0)  # mm; lines miss each other by ~σ_px × footprint


def test_reported_covariance_matches_monte_carlo():
    scene = make_scene()
    b0, t0 = observe(scene)
    reference = calibrate(scene, b0, t0)
    rng = np.random.default_rng(7)
    errors, d2, chi2 = [], [], []
    for _ in range(100):
        cal = calibrate(scene, *observe(scene, rng))
        e = cal.position_world - scene.lamp
        errors.append(e)
        d2.append(e @ np.linalg.solve(cal.covariance, e))
        chi2.append(cal.chi2)
    errors = np.array(errors)
    ratio = errors.std(axis=0, ddof=1) / reference.sigma_world
    assert np.all((ratio > 1 / 1.3) & (ratio < 1.3)), ratio
    assert 2.3 <= np.mean(d2) <= 3.8, np.mean(d2)  # Mahalanobis² has mean 3 for 3 dof
    assert 2.3 <= np.mean(chi2) <= 3.8, np.mean(chi2)  # residual χ², 2N − 3 = 3 dof
    assert np.all(np.linalg.norm(errors, axis=1) < 0.02 * scene.distance)


def test_height_uncertainty_acts_along_the_normal_only():
    scene = make_scene()
    b, t = observe(scene)
    plain = calibrate(scene, b, t)
    with_h = calibrate(scene, b, t, sigma_height=1.0)
    # A wrong height scales the lamp's height and keeps its foot (similar triangles).
    extra = with_h.covariance - plain.covariance
    np.testing.assert_allclose(extra[:2, :], 0.0, atol=1e-6)
    assert extra[2, 2] == pytest.approx((scene.lamp[2] / scene.height) ** 2, rel=1e-3)
    wrong = calibrate_lamp_from_pencil(scene.camera, scene.pose, [0, 0, 0], [0, 0, 1], b, t, 0.8 * scene.height)
    np.testing.assert_allclose(wrong.position_world, scene.lamp * [1, 1, 0.8], atol=1e-6)
    zero = calibrate(scene, b, t, sigma_px=0.0)
    assert np.all(zero.covariance == 0) and np.isnan(zero.chi2)


def test_nearly_parallel_lines_warn():
    # Two pencil spots 8 mm apart: their lines to the lamp are ~1° apart.
    scene = make_scene(bases=((-40.0, -60.0), (-34.0, -55.0)))
    cal = calibrate(scene, *observe(scene))
    assert cal.line_spread_deg < 5.0
    assert any("close to parallel" in w for w in cal.warnings)
    assert any("uncertain" in w for w in cal.warnings)


def test_a_misplaced_click_fails_the_consistency_check():
    scene = make_scene(bases=((-120.0, -100.0), (70.0, -80.0), (0.0, 110.0), (-150.0, 60.0)))
    b, t = observe(scene, np.random.default_rng(3))
    assert calibrate(scene, b, t).warnings == []
    t[1] += [4.0, -3.0]  # 5 px off
    cal = calibrate(scene, b, t)
    assert cal.dof == 5 and cal.chi2 > 50
    assert any("χ²" in w for w in cal.warnings)


def test_swapped_base_and_tip_warns():
    scene = make_scene()
    b, t = observe(scene)
    b[0], t[0] = t[0].copy(), b[0].copy()
    cal = calibrate(scene, b, t)
    assert any("photo(s) 1" in w for w in cal.warnings)


def _one_line_error(excinfo) -> str:
    message = str(excinfo.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize("height", [0.0, -10.0, float("nan")])
def test_height_must_be_positive(height):
    scene = make_scene()
    b, t = observe(scene)
    with pytest.raises(GnomonError) as excinfo:
        calibrate_lamp_from_pencil(scene.camera, scene.pose, [0, 0, 0], [0, 0, 1], b, t, height)
    assert "height must be > 0" in _one_line_error(excinfo)


def test_one_photo_is_not_enough():
    scene = make_scene()
    b, t = observe(scene)
    with pytest.raises(GnomonError) as excinfo:
        calibrate(scene, b[:1], t[:1])
    assert "at least 2 pencil photos, got 1" in _one_line_error(excinfo)


def test_mismatched_shapes():
    scene = make_scene()
    b, t = observe(scene)
    with pytest.raises(GnomonError) as excinfo:
        calibrate(scene, b, t[:2])
    assert "(N, 2)" in _one_line_error(excinfo)


def test_ray_missing_the_plane():
    scene = make_scene()
    scene = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, dist=(0.0,) * 5))
    b, t = observe(scene)
    t[1] = [640.0, -1500.0]  # 54° above the optical axis: above the horizon
    with pytest.raises(GnomonError) as excinfo:
        calibrate(scene, b, t)
    message = _one_line_error(excinfo)
    assert "photo 2" in message and "shadow tip" in message and "does not see the plane" in message


# ------------------------------------------------------------------ the field log and the CLI hook


def write_pencil_log(folder, scene: Scene, b: np.ndarray, t: np.ndarray, pencil_extra=None, extra=None):
    cam = scene.camera
    log = {
        "camera": {
            "model": "opencv", "width": cam.width, "height": cam.height,
            "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "dist": list(cam.dist),
            "pose": {"rvec": scene.rvec.tolist(), "tvec": scene.tvec.tolist()},
        },
        "planes": [{"name": "desk", "point": [0, 0, 0], "normal": [0, 0, 1], "regions": [[0, 0, 100, 100]]}],
        "pencil": {
            "height": scene.height,
            "sigma_px": SIGMA_PX,
            "photos": [{"base": bi.tolist(), "tip": ti.tolist(), "image": f"pencil{i + 1}.jpg"}
                       for i, (bi, ti) in enumerate(zip(b, t, strict=True))],
            **(pencil_extra or {}),
        },
        **(extra or {}),
    }
    path = folder / "pencil.toml"
    toml_io.dump(log, path)
    return path


def test_cli_writes_lamp_toml(tmp_path, capsys):
    scene = make_scene()
    b, t = observe(scene, np.random.default_rng(11))
    path = write_pencil_log(tmp_path, scene, b, t, extra={"light": {"kind": "lamp", "position": [0, 0, 1]}})
    assert calibrate_lamp_cli(argparse.Namespace(field_log=path)) == 0
    out = capsys.readouterr().out
    assert "position (world, mm)" in out and "±" in out and "photo 3" in out
    written = toml_io.load(tmp_path / "lamp.toml")
    assert written["light"]["kind"] == "lamp"
    position = np.array(written["light"]["position"])
    assert np.linalg.norm(position - scene.lamp) < 0.01 * scene.distance
    cov = np.array(written["lamp_calibration"]["covariance"])
    assert cov.shape == (3, 3) and np.allclose(cov, cov.T)
    assert written["lamp_calibration"]["units"] == "mm"
    assert len(written["lamp_calibration"]["residuals"]) == 3


def test_field_log_parsing(tmp_path):
    scene = make_scene()
    b, t = observe(scene)
    path = write_pencil_log(tmp_path, scene, b, t, pencil_extra={"units": "m", "sigma_height": 0.5})
    log = load_pencil_log(path)
    assert log.units == "m" and log.sigma_height == 0.5 and log.plane_name == "desk"
    assert log.images == ("pencil1.jpg", "pencil2.jpg", "pencil3.jpg")
    np.testing.assert_allclose(log.bases_px, b)


@pytest.mark.parametrize(
    "pencil_extra, extra, expected",
    [
        ({"height": -5.0}, None, "[pencil] height: must be > 0, got -5.0"),
        ({"height": 0}, None, "[pencil] height: must be > 0"),
        ({"hieght": 80.0}, None, "[pencil] unknown key 'hieght'"),
        ({"plane": "wall"}, None, "[pencil] plane: no [[planes]] entry is named 'wall'"),
        ({"sigma_px": -1.0}, None, "[pencil] sigma_px: must be ≥ 0"),
        (None, {"lamp": {"x": 1}}, "[field log] unknown key 'lamp'"),
    ],
)
def test_field_log_errors(tmp_path, pencil_extra, extra, expected):
    scene = make_scene()
    b, t = observe(scene)
    path = write_pencil_log(tmp_path, scene, b, t, pencil_extra=pencil_extra, extra=extra)
    with pytest.raises(GnomonError) as excinfo:
        calibrate_lamp_cli(argparse.Namespace(field_log=path))
    message = _one_line_error(excinfo)
    assert expected in message and str(path) in message
    assert not (tmp_path / "lamp.toml").exists()


def test_field_log_with_one_photo(tmp_path):
    scene = make_scene()
    b, t = observe(scene)
    path = write_pencil_log(tmp_path, scene, b[:1], t[:1])
    with pytest.raises(GnomonError) as excinfo:
        calibrate_lamp_cli(argparse.Namespace(field_log=path))
    assert "[pencil] photos: the lamp needs at least 2 pencil photos, got 1" in _one_line_error(excinfo)


def test_field_log_pixel_outside_the_image(tmp_path):
    scene = make_scene()
    b, t = observe(scene)
    t[2] = [1500.0, 300.0]
    path = write_pencil_log(tmp_path, scene, b, t)
    with pytest.raises(GnomonError) as excinfo:
        calibrate_lamp_cli(argparse.Namespace(field_log=path))
    assert "[pencil.photos.2] tip: pixel [1500.0, 300.0] is outside the 1280x960 image" in _one_line_error(excinfo)


def test_field_log_missing_pencil_table(tmp_path):
    scene = make_scene()
    b, t = observe(scene)
    path = write_pencil_log(tmp_path, scene, b, t)
    data = toml_io.load(path)
    del data["pencil"]
    toml_io.dump(data, path)
    with pytest.raises(GnomonError) as excinfo:
        calibrate_lamp_cli(argparse.Namespace(field_log=path))
    assert "missing required table [pencil]" in _one_line_error(excinfo)


@pytest.mark.slow
def test_tips_found_against_the_empty_desk(desk_lamp_full, tmp_path) -> None:
    """[pencil] empty = ...: photos give only a base hint; the shadow tips are found automatically."""
    import tomllib

    from gnomon.cli import main
    from gnomon.util import toml_io

    cap = copy_capture(desk_lamp_full, tmp_path / "capture")  # the lamp file is written beside the log
    log = tomllib.loads((cap / "pencil_log.toml").read_text())
    rng = np.random.default_rng(9)
    for photo in log["pencil"]["photos"]:
        photo.pop("tip")
        photo["base"] = (np.array(photo["base"]) + rng.normal(0, 1.0, 2)).round(1).tolist()  # a clicked hint
    log["pencil"].update(empty="frames/frame_0000.jpg", gamma=2.2, sigma_px=1.0)
    toml_io.dump(log, cap / "auto.toml")
    assert main(["calibrate", "lamp", str(cap / "auto.toml")]) == 0
    lamp = np.array(tomllib.loads((cap / "lamp.toml").read_text())["light"]["position"])
    truth = np.load(cap / "ground_truth.npz")
    distance = np.linalg.norm(truth["lamp"] - truth["pencil_bases_world"].mean(axis=0))
    assert np.linalg.norm(lamp - truth["lamp"]) <= 0.01 * distance


@pytest.fixture(scope="module")
def dark_pencil(tmp_path_factory):
    """The desk-lamp scene with a dark marker pen (albedo 0.06) under a lamp 1.2 m high: in each photo
    the pen's own image is dark and longer than its shadow, as in real photos taken from above."""
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    root = tmp_path_factory.mktemp("dark_pencil")
    simulate_desk_lamp(root / "capture", DeskLampConfig(seed=3, frames=8, pencil_albedo=0.06, lamp_height=1200.0))
    return root / "capture"


@pytest.mark.slow
@pytest.mark.parametrize(("pencil", "normal"), [("pale", "up"), ("dark", "into the desk")])
def test_tips_found_against_the_photos_median(desk_lamp_full, dark_pencil, tmp_path, capsys, pencil,
                                              normal) -> None:
    """Without [pencil] empty, the median of the photos is the empty desk (each photo's pencil stands
    elsewhere). A dark pen whose image is longer than its shadow, on a desk whose normal points into it
    (as a chessboard's frame puts it): the pen's own image is still told from its shadow (it rises on the
    camera's side). Every tip within 2 px of the truth, the base hint (here exact) kept within 3 px, the
    lamp within 3 of its σ on each axis."""
    import tomllib

    from gnomon.cli import main
    from gnomon.util import toml_io

    cap = copy_capture(desk_lamp_full if pencil == "pale" else dark_pencil, tmp_path / "capture")
    log = tomllib.loads((cap / "pencil_log.toml").read_text())
    assert len(log["pencil"]["photos"]) == 3
    for photo in log["pencil"]["photos"]:
        photo.pop("tip")
    log["pencil"].update(gamma=2.2, sigma_px=1.0)
    if normal != "up":  # the same plane, its normal turned over
        log["planes"][0]["normal"] = [-x for x in log["planes"][0]["normal"]]
    toml_io.dump(log, cap / "auto.toml")
    capsys.readouterr()
    assert main(["calibrate", "lamp", str(cap / "auto.toml")]) == 0
    out = capsys.readouterr().out
    found = [line for line in out.splitlines() if "found against the median" in line]
    pixels = np.array([[float(x) for x in re.findall(r"-?\d+\.\d+", line)] for line in found])
    truth = np.load(cap / "ground_truth.npz")
    assert np.linalg.norm(pixels[:, 2:4] - truth["pencil_tip_pixels"], axis=1).max() <= 2.0
    assert np.linalg.norm(pixels[:, 0:2] - truth["pencil_base_pixels"], axis=1).max() <= 3.0
    lamp = tomllib.loads((cap / "lamp.toml").read_text())
    position, sigma = (np.array(lamp["light"]["position"]), np.array(lamp["lamp_calibration"]["sigma"]))
    assert np.all(np.abs(position - truth["lamp"]) <= 3.0 * sigma)
    # each photo's tip against where the solved lamp puts it, by the photo's file name, and drawn
    misses = {name: float(px) for name, px in re.findall(r"^  (\S+\.\w+): (\d+\.\d+) px$", out, re.M)}
    assert sorted(misses) == sorted(Path(p["image"]).name for p in log["pencil"]["photos"])
    assert max(misses.values()) <= 2.0 + 2.0  # a tip found within 2 px, the lamp's within 2 px of the truth's
    assert cv2.imread(str(cap / "lamp_tips.png")) is not None


@pytest.mark.slow
@pytest.mark.parametrize("pencil", ["pale", "dark"])
def test_feet_and_tips_found_from_the_photos_alone(desk_lamp_full, dark_pencil, tmp_path, capsys, pencil) -> None:
    """No pixel typed: each photo's image alone. The pencil is found from its own image and its shadow (two
    arms meeting at the foot, the pencil's arm predicted from the foot, the desk's pose and its length):
    every foot within the pencil's own radius in that photo (its projected width: 8.5-12 px here), every
    tip within 2 px, the lamp within 3 of its σ (found feet count 1.5 px each coordinate, said in a note)."""
    import tomllib

    from gnomon.cli import main
    from gnomon.config.pencil_log import load_pencil_log
    from gnomon.util import toml_io

    cap = copy_capture(desk_lamp_full if pencil == "pale" else dark_pencil, tmp_path / "capture")
    log = tomllib.loads((cap / "pencil_log.toml").read_text())
    for photo in log["pencil"]["photos"]:
        del photo["tip"], photo["base"]
    log["pencil"].update(gamma=2.2, sigma_px=0.5)
    toml_io.dump(log, cap / "auto.toml")
    capsys.readouterr()
    assert main(["calibrate", "lamp", str(cap / "auto.toml")]) == 0
    out = capsys.readouterr().out
    found = [line for line in out.splitlines() if "the pencil found with it" in line]
    assert len(found) == len(log["pencil"]["photos"])
    pixels = np.array([[float(x) for x in re.findall(r"-?\d+\.\d+", line.split(":", 1)[1])[:4]] for line in found])
    truth = np.load(cap / "ground_truth.npz")
    pencil_log = load_pencil_log(cap / "pencil_log.toml")
    depth = pencil_log.pose.world_to_camera(truth["pencil_bases_world"])[:, 2]
    radius_px = float(truth["pencil_radius"]) * pencil_log.camera.fx / depth
    assert np.all(np.linalg.norm(pixels[:, :2] - truth["pencil_base_pixels"], axis=1) <= radius_px)
    assert np.linalg.norm(pixels[:, 2:4] - truth["pencil_tip_pixels"], axis=1).max() <= 2.0
    assert "note: σ = 1.5 px instead of sigma_px = 0.5" in out
    lamp = tomllib.loads((cap / "lamp.toml").read_text())
    position, sigma = (np.array(lamp["light"]["position"]), np.array(lamp["lamp_calibration"]["sigma"]))
    assert np.all(np.abs(position - truth["lamp"]) <= 3.0 * sigma)


def test_a_found_foot_is_refused_where_no_pencil_stands() -> None:
    """A photo where nothing differs from the empty desk, or where what differs is no pencil and shadow: one
    line naming the photo and what to give instead."""
    from gnomon.light.pencil_detection import find_pencil_base

    rng = np.random.default_rng(2)
    empty = (0.5 + 0.01 * rng.standard_normal((120, 160))).astype(np.float32)

    def tops(feet):
        return feet + np.array([0.0, -40.0])

    with pytest.raises(GnomonError, match=r"p\.jpg: nothing differs from the empty desk.*give its base"):
        find_pencil_base(empty * 1.02, empty, tops, source="p.jpg")
    blob = empty.copy()
    blob[40:100, 30:130] *= 0.3  # a dark rectangle (a book put down), not a pencil and its shadow
    with pytest.raises(GnomonError, match=r"p\.jpg: (no standing pencil|what differs).*give its base"):
        find_pencil_base(blob, empty, tops, source="p.jpg")


def test_a_missing_tip_needs_the_empty_desk_or_three_photos(tmp_path, capsys) -> None:
    import tomllib
    from pathlib import Path

    from gnomon.cli import main
    from gnomon.util import toml_io

    src = Path(__file__).resolve().parents[1] / "field_logs" / "desk_lamp_small" / "pencil_log.toml"
    log = tomllib.loads(src.read_text())
    log["pencil"]["photos"] = log["pencil"]["photos"][:2]  # two photos: no median to stand for the desk
    log["pencil"]["photos"][0].pop("tip")
    toml_io.dump(log, tmp_path / "p.toml")
    assert main(["calibrate", "lamp", str(tmp_path / "p.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tip: missing" in err[0] and "at least 3 photos" in err[0]


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_without_a_pose_the_planes_own_markers_place_the_camera(two_plane_small, tmp_path) -> None:
    """The paper's set-up: no pose typed; the desk's printed markers in the capture's first frame place the
    camera (as a scan of the same field log does), and the pencils are located in that frame."""
    import json

    truth = json.loads((two_plane_small / "ground_truth.json").read_text())
    K, dist = np.array(truth["K"]), np.array(truth["dist"])
    rvec, tvec = np.array(truth["rvec"]), np.array(truth["tvec"])
    lamp, height = np.array(truth["lamp"]), 80.0
    # pencils standing on the desk (world z = 0, the desk markers' frame), their shadow tips from the lamp
    bases = np.array([[20.0, 20.0, 0.0], [120.0, 30.0, 0.0], [40.0, 110.0, 0.0], [150.0, 100.0, 0.0]])
    tips = bases + [0.0, 0.0, height]
    shadows = lamp + (tips - lamp) * (lamp[2] / (lamp[2] - height))[..., None]
    project = lambda p: cv2.projectPoints(p, rvec, tvec, K, dist)[0].reshape(-1, 2)  # noqa: E731
    b, s = project(bases), project(shadows)

    capture = copy_capture(two_plane_small, tmp_path / "capture")
    log = toml_io.load(capture / "field_log.toml")
    del log["camera"]["pose"]
    log["pencil"] = {"height": height, "sigma_px": 0.3,
                     "photos": [{"base": bi.tolist(), "tip": si.tolist()} for bi, si in zip(b, s, strict=True)]}
    path = capture / "pencil.toml"
    toml_io.dump(log, path)
    assert calibrate_lamp_cli(argparse.Namespace(field_log=path)) == 0
    written = toml_io.load(capture / "lamp.toml")
    found = np.array(written["light"]["position"])
    # exact clicks: what is left is the markers' pose (found to ~0.05 px in a noisy JPEG frame): 0.11 mm
    # of 570 mm here; 1 mm is a tenth of a pixel's footprint at the desk
    assert np.linalg.norm(found - lamp) < 1.0
    # without [capture] nothing can be measured: the message says what to give
    del log["capture"]
    toml_io.dump(log, path)
    with pytest.raises(GnomonError) as excinfo:
        calibrate_lamp_cli(argparse.Namespace(field_log=path))
    assert "or a [capture] and a plane with markers or a chessboard to measure it from" in _one_line_error(excinfo)
