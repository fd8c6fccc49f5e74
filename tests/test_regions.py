"""`gnomon regions`, `gnomon preview` and `gnomon init` on a synthetic two-plane capture.

The capture (desk and wall with printed markers, a sphere and a box on the
desk) has exact ground truth: which object every pixel sees, and which
pixels the shadow sweeps.
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from gnomon.cli import main
from gnomon.config.fieldlog import load_field_log
from gnomon.errors import GnomonError
from gnomon.util import toml_io

DESK, WALL = 0, 4  # the simulator's object ids


def _without_regions(capture: Path, name: str) -> Path:
    log = tomllib.loads((capture / "field_log.toml").read_text())
    for plane in log["planes"]:
        plane.pop("regions")
    path = capture / name
    toml_io.dump(log, path)
    return path


@pytest.fixture(scope="module")
def proposed(two_plane_small: Path):
    """`gnomon regions` on the capture's field log with its regions removed: only the markers to start from."""
    log = _without_regions(two_plane_small, "no_regions.toml")
    out = two_plane_small / "proposed"
    assert main(["regions", str(log), "--out", str(out), "--quiet"]) == 0
    return log, out, dict(np.load(two_plane_small / "ground_truth.npz"))


@pytest.mark.slow
def test_proposed_regions_are_bare_plane(proposed) -> None:
    _, out, truth = proposed
    for name, oid in (("desk", DESK), ("wall", WALL)):
        mask = cv2.imread(str(out / f"{name}_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
        bare_swept = truth["swept"] & (truth["object_id"] == oid)
        on_plane = (truth["object_id"][mask] == oid).mean()
        covered = (mask & bare_swept).sum() / bare_swept.sum()
        print(name, mask.sum(), on_plane, covered)
        # nothing but the plane (a pixel is 1 of ~60 000 on each plane)
        assert on_plane >= 0.999
        # most of the plane the shadow sweeps (less the markers, the objects' cast shadows and a 2 px margin)
        assert covered >= 0.6
    snippet = tomllib.loads((out / "regions.toml").read_text())
    assert [p["name"] for p in snippet["planes"]] == ["desk", "wall"]
    drawing = cv2.imread(str(out / "regions.png"))
    assert drawing.shape[:2] == truth["object_id"].shape


@pytest.mark.slow
def test_a_scan_with_the_proposed_regions(proposed, tmp_path: Path) -> None:
    """As accurate as with the simulator's own regions (bands it knows are bare), and covering as much."""
    from gnomon.runs.accuracy import depth_accuracy
    from gnomon.runs.scan import ScanOptions, run_scan

    log_path, _, truth = proposed
    log = tomllib.loads(log_path.read_text())
    for plane in log["planes"]:
        plane["mask"] = f"proposed/{plane['name']}_mask.png"
    path = log_path.with_name("with_masks.toml")
    toml_io.dump(log, path)
    scores = {}
    for name, field_log in (("simulator's regions", log_path.with_name("field_log.toml")), ("proposed", path)):
        result = run_scan(field_log, tmp_path / name, ScanOptions(progress=False, rrd=False))
        scores[name] = depth_accuracy(result.depth, truth["depth"], truth["swept"], float(truth["camera_distance_mm"]))
        print(scores[name].table(f"two_plane small, {name}"))
    ours, theirs = scores["proposed"], scores["simulator's regions"]
    # The proposal holds more of each plane (near the corner too, where the lines
    # are shorter), so the RMS may move by a few %, not more.
    assert ours.rms <= 1.15 * theirs.rms
    assert ours.coverage >= theirs.coverage - 0.01


@pytest.mark.slow
def test_preview_draws_the_corner_where_it_is(two_plane_small: Path, tmp_path: Path) -> None:
    """The yellow line where the measured planes meet lies on the true corner's image."""
    from gnomon.runs.setup_preview import COLOURS  # noqa: F401  (the preview's palette)
    from gnomon.simulate.two_plane_scene import WALL_Y

    truth = dict(np.load(two_plane_small / "ground_truth.npz"))
    png = tmp_path / "preview.png"
    assert main(["preview", str(two_plane_small / "field_log.toml"), "--out", str(png)]) == 0
    img = cv2.imread(str(png))
    assert img.shape[:2] == truth["object_id"].shape
    yellow = (img[..., 0] < 60) & (img[..., 1] > 200) & (img[..., 2] > 200)
    v, u = np.nonzero(yellow)
    assert len(u) > 100
    # the true corner (y = WALL_Y, z = 0) through the true camera
    xs = np.linspace(-2000, 2000, 4001)
    corner = np.stack([xs, np.full_like(xs, WALL_Y), np.zeros_like(xs)], axis=1)
    R = cv2.Rodrigues(truth["rvec"])[0]
    cam = corner @ R.T + truth["tvec"]
    pix = cv2.projectPoints(cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), truth["K"], truth["dist"])[0]
    pix = pix.reshape(-1, 2)
    d = np.min(np.hypot(u[:, None] - pix[None, :, 0], v[:, None] - pix[None, :, 1]), axis=1)
    print(np.percentile(d, [50, 95]))
    assert np.percentile(d, 95) < 1.5  # px: the line is drawn 1 px wide, antialiased


@pytest.mark.slow
def test_init_writes_a_template_that_loads_once_filled(two_plane_small: Path, tmp_path: Path) -> None:
    frames = sorted((two_plane_small / "frames").glob("*"))
    work = tmp_path / "capture"
    shutil.copytree(two_plane_small / "frames", work / "frames")
    camera = tomllib.loads((two_plane_small / "field_log.toml").read_text())["camera"]
    pose = camera.pop("pose")
    toml_io.dump(camera, work / "camera.toml")
    out = work / "field_log.toml"
    assert main(["init", *map(str, sorted((work / "frames").glob("*"))), "--camera", str(work / "camera.toml")]) == 0
    text = out.read_text()
    assert text.count("\n#") > 10  # commented
    data = tomllib.loads(text)
    assert data["capture"]["frames"].startswith("frames/*") and data["camera"] == {"file": "camera.toml"}
    # the printed checkers found in the first frame, each within 0.2 px of its true centre
    original = tomllib.loads((two_plane_small / "field_log.toml").read_text())
    true_pixels = np.load(two_plane_small / "ground_truth.npz")["marker_pixels"]
    for plane, truth in zip(data["planes"], true_pixels, strict=True):
        found = np.array([m["pixel_hint"] for m in plane["markers"]])
        assert len(found) == len(truth) == 4
        assert np.max(np.min(np.linalg.norm(found[:, None] - truth[None], axis=2), axis=0)) < 0.2
    # fill in what a user would: measured markers (then units mm) and regions (here the simulator's)
    data["capture"]["units"] = "mm"
    for plane, filled in zip(data["planes"], original["planes"], strict=True):
        plane["markers"] = filled["markers"]
        plane["regions"] = filled["regions"]
        plane.update(point=filled["point"], normal=filled["normal"], x_axis=filled["x_axis"])
    data["camera"]["pose"] = pose
    # the commented [output] keys, uncommented, are valid
    block = text[text.index("# [output]"):].split("\n\n")[0]
    output = tomllib.loads("\n".join(line[2:] for line in block.splitlines()))["output"]
    assert set(output) == {"crop_above", "crop_min_height", "max_sigma"}
    data["output"] = output
    toml_io.dump(data, out)
    log = load_field_log(out)
    assert len(log.capture.image_files) == len(frames) and [p.name for p in log.planes] == ["desk", "wall"]
    assert log.output.crop_above == "desk" and log.output.max_sigma == 1.5
    # an existing log is kept
    assert main(["init", *map(str, sorted((work / "frames").glob("*")))]) == 2


@pytest.mark.slow
def test_a_plane_without_regions_cannot_be_scanned(two_plane_small: Path, tmp_path: Path) -> None:
    from gnomon.runs.scan import ScanOptions, run_scan

    path = _without_regions(two_plane_small, "bare.toml")
    with pytest.raises(GnomonError, match="gnomon regions"):
        run_scan(path, tmp_path / "scan", ScanOptions(progress=False, rrd=False))


def test_shadow_plane_ransac_ignores_an_object_inside_a_region() -> None:
    """One frame's crossings on a desk (z = 0) and a wall (y = 0): the shadow plane's lines on both, plus
    an object's isochrone back-projected onto the desk (half of the desk's crossings, on a curve that a
    line fit of the desk alone would follow). The joint fit keeps the lines' crossings and none of the curve."""
    from gnomon.runs.regions import ransac_shadow_plane

    rng = np.random.default_rng(3)
    n = np.array([0.9, 0.2, 0.3])
    n /= np.linalg.norm(n)
    d = 40.0  # shadow plane n·X = d (mm)
    y_desk = np.linspace(5.0, 300.0, 120)
    # desk (z = 0): n0 x + n1 y = d  → x = (d − n1 y) / n0
    desk = np.stack([(d - n[1] * y_desk) / n[0], y_desk, np.zeros_like(y_desk)], axis=1)
    z_wall = np.linspace(5.0, 250.0, 100)
    wall = np.stack([(d - n[2] * z_wall) / n[0], np.zeros_like(z_wall), z_wall], axis=1)
    line = np.concatenate([desk, wall])
    line[:, 0] += rng.normal(0.0, 0.2, len(line))  # crossing noise (mm), within the 1 mm tolerance
    s = np.linspace(0, 1, 120)  # the object's curve on the desk, 60–120 mm off the desk line
    curve = np.stack([desk[:, 0] + 60 + 60 * np.sin(3 * s), 80 + 150 * s, np.zeros_like(s)], axis=1)
    points = np.concatenate([line, curve])
    label = np.concatenate([np.zeros(120), np.ones(100), np.zeros(120)]).astype(int)
    inl = ransac_shadow_plane(points, label, np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]), np.array([1.0, 1.0]))
    assert inl[:220].mean() > 0.99
    assert not inl[220:].any()


def test_predicted_times_ignore_lines_off_the_sweep() -> None:
    """A plane swept by lines x = 10·t mm (frames 5–45), plus the wrong lines a real first pass finds: in
    frame 1 a line beyond the sweep's end (an off-plane surface's isochrone back-projected onto the
    plane: on the stand capture's wall it reversed the sweep's sense and left every pixel unpredicted), in
    frame 2 one far behind its start and in frame 30 one behind its neighbours. Every pixel the true
    lines pass gets its time (to 1e-9 frame), and the wrong lines are the ones left out."""
    from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines
    from gnomon.runs.regions import monotone_sweep, predicted_times

    n_frames = 50
    # Plane z = 1000 mm in the camera frame; plane coordinates (x, y) = camera (x, y) via e1, e2.
    plane = PlaneInCamera(np.array([0.0, 0.0, 1.0]), 1000.0, np.array([0.0, 0.0, 1000.0]),
                          np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    point = np.full((n_frames, 3), np.nan)
    direction = np.full((n_frames, 3), np.nan)
    for t in range(5, 46):
        point[t], direction[t] = [10.0 * t - 250.0, 0.0, 1000.0], [0.0, 1.0, 0.0]
    point[1], direction[1] = [900.0, 0.0, 1000.0], [0.0, 1.0, 0.0]  # beyond the sweep's end
    point[2], direction[2] = [-900.0, 0.0, 1000.0], [0.0, 1.0, 0.0]  # far behind its start
    point[30], direction[30] = [10.0 * 20 - 250.0, 0.0, 1000.0], [0.0, 1.0, 0.0]  # back at frame 20's place
    lines = ReferenceLines("p", plane, point, direction, np.zeros(n_frames), np.zeros(n_frames, dtype=int),
                           [np.zeros((0, 2))] * n_frames, np.zeros(n_frames, dtype=bool),
                           [np.zeros((0, 3))] * n_frames)
    x = np.linspace(-195.0, 195.0, 40)
    rays = np.stack([x / 1000.0, np.zeros_like(x), np.ones_like(x)], axis=1)
    pred = predicted_times(lines, rays.reshape(1, -1, 3))[0]
    truth = (x + 250.0) / 10.0
    assert np.all(np.isfinite(pred))
    np.testing.assert_allclose(pred, truth, atol=1e-9)  # across 29–31 too: the sweep is linear
    found = np.flatnonzero(np.isfinite(point[:, 0]))
    centres = point[found][:, :2]
    normals = np.stack([-direction[found][:, 1], direction[found][:, 0]], axis=1)
    kept = found[monotone_sweep(found, centres, normals)]
    assert 1 not in kept and 2 not in kept and 30 not in kept and len(kept) == 40


def test_the_kernel_times_the_points_as_numpy_does_bit_for_bit() -> None:
    """times_at_points: the kernel's bisection (``_kernel.line_times``) equals the numpy definition element for
    element, on lines of turning directions and uneven frames and on points inside, before and beyond them."""
    from gnomon.geometry.plane_times import times_at_points
    from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines

    rng = np.random.default_rng(11)
    n_frames = 120
    plane = PlaneInCamera(np.array([0.0, 0.0, 1.0]), 800.0, np.array([0.0, 0.0, 800.0]),
                          np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    point = np.full((n_frames, 3), np.nan)
    direction = np.full((n_frames, 3), np.nan)
    frames = np.sort(rng.choice(np.arange(3, 117), 77, replace=False))
    for k, t in enumerate(frames):  # a sweep along x whose lines turn by up to 20°
        a = np.radians(90.0 + 20.0 * np.sin(k / 9.0))
        point[t], direction[t] = [6.0 * k - 230.0 + rng.normal(0, 0.3), 0.0, 800.0], [np.cos(a), np.sin(a), 0.0]
    lines = ReferenceLines("p", plane, point, direction, np.zeros(n_frames), np.zeros(n_frames, dtype=int),
                           [np.zeros((0, 2))] * n_frames, np.zeros(n_frames, dtype=bool),
                           [np.zeros((0, 3))] * n_frames)
    xy = rng.uniform([-300.0, -150.0], [300.0, 150.0], (20_000, 2))
    got = times_at_points(lines, xy)
    want = times_at_points(lines, xy, kernel=False)
    assert np.isfinite(want).mean() > 0.5 and np.isnan(want).any()  # both kinds of points are there
    assert got.tobytes() == want.tobytes()


def _fast_sweep_with_a_fold(fold_deg: float) -> dict:
    """A wall z = 1000 mm (camera frame) whose last 30 rows are folded towards the camera by ``fold_deg``
    about a horizontal hinge (like the frog capture's wall board, folded at its edge), swept by the shadow
    edge of a lamp at (−600, 0, 0) mm: on the wall the edge is the line x = c − 0.1·y across the rows,
    so each frame's line runs over the bare wall and then the fold; c moves 10 mm per frame (8 px per
    frame at f = 800 px: a fast sweep). The tracker's times are modelled exactly: each pixel's irradiance
    in frame k is its lit share under a penumbra 1 px wide on the wall, its time the threshold crossing
    interpolated between the two frames around it, so most pixels get k + 0.5 (a staircase, ±0.5 frame).
    Returns the times of both edges (the trailing edge 60 mm behind), the wall, the camera, the fold's
    pixels and how far each pixel's surface is in front of the wall (mm)."""
    from gnomon.camera.models import OpenCVCamera
    from gnomon.geometry.reference_lines import PlaneInCamera

    w, h, f = 200, 120, 800.0
    camera = OpenCVCamera(w, h, f, f, w / 2, h / 2)
    hinge_v = h - 30
    y_hinge = (hinge_v - h / 2) / f * 1000.0
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    x_ray, y_ray = (uu - w / 2) / f, (vv - h / 2) / f
    tan = np.tan(np.radians(fold_deg))
    # The fold: z = 1000 − (y − y_hinge)·tan for y ≥ y_hinge; the ray's point s·(x_ray, y_ray, 1) on it.
    s = np.where(vv >= hinge_v, (1000.0 + y_hinge * tan) / (1.0 + y_ray * tan), 1000.0)
    px, py, pz = x_ray * s, y_ray * s, s
    lamp_x, slant = -600.0, 0.1
    # The shadow plane through the lamp and the wall's line x = c − slant·y passes the point when
    # c = lamp_x + 1000·(px − lamp_x + slant·py)/pz (for a point on the wall: c = px + slant·py).
    c_point = lamp_x + 1000.0 * (px - lamp_x + slant * py) / pz
    speed, start, n_frames = 10.0, -200.0, 60
    footprint = 1000.0 / f  # mm per pixel on the wall

    def tracker_times(behind_mm: float) -> np.ndarray:
        edge = (start + speed * np.arange(n_frames) - behind_mm)[:, None, None]
        lit = np.clip(0.5 - (edge - c_point[None]) / footprint, 0.0, 1.0)  # 1 ahead of the edge, 0 behind
        fall = (lit[:-1] >= 0.5) & (lit[1:] < 0.5)
        k = np.argmax(fall, axis=0)
        a = np.take_along_axis(lit, k[None], 0)[0]
        b = np.take_along_axis(lit, k[None] + 1, 0)[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(fall.any(axis=0), k + (a - 0.5) / (a - b), np.nan)

    wall = PlaneInCamera(np.array([0.0, 0.0, 1.0]), 1000.0, np.array([0.0, 0.0, 1000.0]),
                         np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    seed = np.zeros((h, w), dtype=bool)
    seed[20:100, 40:160] = True
    return {"maps": [tracker_times(0.0), tracker_times(60.0)], "n_frames": n_frames, "plane": wall,
            "camera": camera, "seed": seed, "fold": vv >= hinge_v, "depth_off": 1000.0 - pz}


def test_regions_on_retimed_times_leave_out_a_fold() -> None:
    """A fold 20° off the wall over its last 30 rows (up to 13 mm in front) bends the isochrones by up to
    0.75 frame, which the staircase of a fast sweep (±0.5 frame per pixel) hides: on the tracker's own
    times the proposed wall takes nearly all of the fold. On the times re-timed between the isochrones (as
    the scan, and so `gnomon regions`, uses them: gnomon.reconstruct.edges.edge_time_maps) the residuals on the bare
    wall are a few hundredths of a frame, the tolerance is its 0.25-frame floor, and the region stops
    where the fold leaves the wall by more than that: a time off by 0.25 frame is 2.5 mm along the wall,
    which a point δ in front of it makes as δ·600/1000 (the lamp 600 mm aside, the wall 1000 mm away),
    so what it keeps of the fold is within 4.2 mm of the wall (but at the image's sides, where a frame's
    line is mostly on the fold). The bare wall is kept whole but for the columns the sweep's first and
    last lines do not bracket."""
    from gnomon.reconstruct.retiming import retime_between_isochrones
    from gnomon.runs.regions import propose_regions

    scene = _fast_sweep_with_a_fold(20.0)
    fold, bare = scene["fold"], ~scene["fold"]

    def propose(maps: list[np.ndarray]):
        return propose_regions(maps, scene["n_frames"], [scene["plane"]], ["wall"], [scene["seed"]],
                               scene["camera"], margin_px=0, min_area_px=50)[0]

    raw = propose(scene["maps"])
    assert raw.mask[fold].mean() > 0.9  # the staircase hides the fold
    region = propose([retime_between_isochrones(m, scene["n_frames"]).times for m in scene["maps"]])
    assert region.tolerance == pytest.approx(0.25)
    inner = bare.copy()
    inner[:, :12] = inner[:, -12:] = False
    assert region.mask[inner].mean() > 0.98
    kept_fold = region.mask & fold
    assert kept_fold.sum() < 0.4 * fold.sum()
    # Away from the image's first and last 20 columns, where the sweep's first and last lines are mostly on
    # the fold (their part on the bare wall is out of the image) and so follow it.
    kept_fold[:, :20] = kept_fold[:, -20:] = False
    assert scene["depth_off"][kept_fold].max() < 4.2 * 1.1  # 10 % for the line fit and the hinge's pixel


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_one_plane_seeded_over_a_flat_topped_object_leaves_its_top_out() -> None:
    """A single plane (the paper's desk and lamp) seeded over an object with a flat top and its cast
    shadow: the top's isochrones are straight too, but off the desk's lines; the proposal keeps the desk
    beside it and leaves the top out."""
    from gnomon.camera.models import OpenCVCamera, Pose
    from gnomon.geometry.reference_lines import PlaneInCamera
    from gnomon.runs.regions import propose_regions

    cam = OpenCVCamera(200, 150, 180.0, 180.0, 99.5, 74.5, (0.0,) * 5)
    pose = Pose.from_rvec_tvec(np.array([np.pi, 0.0, 0.0]), np.array([0.0, 0.0, 300.0]))  # looking down
    lamp = np.array([-400.0, 0.0, 450.0])
    x0, speed, n_frames = -200.0, 4.0, 100  # the desk line x = x0 + speed·t
    # a disc 60 mm above the desk under the camera: its isochrones run over 82 rows and 110 mm, the desk
    # beside it and its cast shadow over fewer rows, and the desk's whole lines over 250 mm
    top, radius = 60.0, 55.0
    rays = pose.R.T @ cam.ray_map().reshape(-1, 3).T  # world directions
    centre = pose.camera_centre_world
    s_top = (top - centre[2]) / rays[2]
    on_top = centre[:, None] + rays * s_top
    hits_top = np.hypot(on_top[0], on_top[1]) < radius
    s_desk = -centre[2] / rays[2]
    p = np.where(hits_top, on_top, centre[:, None] + rays * s_desk)
    # the desk the disc's top hides from the lamp sees no shadow pass
    via_top = p + (lamp[:, None] - p) * (top / lamp[2])
    cast = ~hits_top & (np.hypot(via_top[0], via_top[1]) < radius)
    # the plane through the lamp and the desk line at x = X contains p when X = (px − Lx·z/Lz) / (1 − z/Lz)
    x_line = (p[0] - lamp[0] * p[2] / lamp[2]) / (1.0 - p[2] / lamp[2])
    times = ((x_line - x0) / speed).reshape(150, 200).astype(np.float32)
    times[(times < 0) | (times > n_frames - 1) | cast.reshape(150, 200)] = np.nan
    on_disc = hits_top.reshape(150, 200)
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0.0, 0.0, 1.0]), pose)
    seed = np.ones((150, 200), dtype=bool)
    region = propose_regions([times, times], n_frames, [plane], ["desk"], [seed], cam)[0].mask
    assert not (region & on_disc).any()
    # the desk above and below the disc, in the columns the disc's top shadows the lines of
    desk = ~on_disc & np.isfinite(times)
    columns = np.zeros_like(desk)
    columns[:, on_disc.any(axis=0)] = True
    # all but the 2 px margins the proposal keeps around the disc, its cast shadow and its stripes (84 %)
    assert (region & desk & columns).sum() > 0.8 * (desk & columns).sum()


def test_short_lines_off_the_sweep_are_moved_to_where_their_long_neighbours_put_them() -> None:
    """:func:`gnomon.runs.regions.follow_the_sweep`: frames whose (short) line sits on an object's top, tens of
    mm off the line the long lines before and after predict, are refitted to their crossings near the
    prediction; a frame with none there loses its line; the others are left as they are."""
    from gnomon.camera.models import OpenCVCamera, Pose
    from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines
    from gnomon.runs.regions import follow_the_sweep

    cam = OpenCVCamera(200, 150, 180.0, 180.0, 99.5, 74.5, (0.0,) * 5)
    pose = Pose.from_rvec_tvec(np.array([np.pi, 0.0, 0.0]), np.array([0.0, 0.0, 400.0]))  # looking down
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0.0, 0.0, 1.0]), pose)
    x0, speed, n = -150.0, 10.0, 31  # the desk's line x = x0 + speed·t (world mm)
    rays = pose.R.T @ cam.ray_map().reshape(-1, 3).T
    c = pose.camera_centre_world
    desk_x = (c[:, None] + rays * (-c[2] / rays[2]))[0].reshape(150, 200)
    times = ((desk_x - x0) / speed).astype(np.float32)
    times[np.abs(times - 20.0) < 0.5] = np.nan  # frame 20: no crossings anywhere
    world_y = np.array([0.0, 1.0, 0.0])
    point = np.array([pose.world_to_camera(np.array([x0 + speed * t, 0.0, 0.0])) for t in range(n)])
    direction = np.tile(pose.R @ world_y, (n, 1))
    extrapolated = np.zeros(n, dtype=bool)
    extrapolated[12:21] = True
    point[12:21] = [pose.world_to_camera(np.array([x0 + speed * t + 25.0, 0.0, 0.0])) for t in range(12, 21)]
    lines = ReferenceLines("desk", plane, point.copy(), direction, np.full(n, 0.1), np.full(n, 50),
                           [np.zeros((0, 2))] * n, extrapolated, [np.zeros((0, 3))] * n)
    follow_the_sweep(lines, times, n, np.ones((150, 200), dtype=bool), cam, tolerance=0.5)
    x = np.array([pose.camera_to_world(p)[0] for p in lines.point])
    np.testing.assert_allclose(x[12:20], x0 + speed * np.arange(12, 20), atol=0.5)  # back on the desk's line
    assert np.isnan(x[20])  # nothing near the prediction: no line
    np.testing.assert_allclose(x[:12], x0 + speed * np.arange(12), atol=1e-9)  # the long lines untouched
    np.testing.assert_allclose(x[21:], x0 + speed * np.arange(21, n), atol=1e-9)


def test_frames_without_a_line_between_long_ones_get_the_one_near_the_sweep() -> None:
    """:func:`gnomon.runs.regions.follow_the_sweep` with ``fill_gaps``: frames that lost their line (an object
    beside a short stretch of the plane's shadow took the fit) get the line their crossings near the
    prediction of the long lines around them make, not the object's crossings beside it; a frame with no
    crossings stays without one, and so does a gap longer than MAX_FOLLOW_GAP; without ``fill_gaps`` nothing
    changes."""
    from gnomon.camera.models import OpenCVCamera, Pose
    from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines
    from gnomon.runs.regions import MAX_FOLLOW_GAP, follow_the_sweep

    cam = OpenCVCamera(200, 150, 180.0, 180.0, 99.5, 74.5, (0.0,) * 5)
    pose = Pose.from_rvec_tvec(np.array([np.pi, 0.0, 0.0]), np.array([0.0, 0.0, 400.0]))  # looking down
    plane = PlaneInCamera.from_world(np.zeros(3), np.array([0.0, 0.0, 1.0]), pose)
    x0, speed, n, k = -150.0, 5.0, 61, 0.25  # the desk's line x + k·y = x0 + speed·t (world mm)
    rays = pose.R.T @ cam.ray_map().reshape(-1, 3).T
    c = pose.camera_centre_world
    on_desk = c[:, None] + rays * (-c[2] / rays[2])
    desk_x, desk_y = on_desk[0].reshape(150, 200), on_desk[1].reshape(150, 200)
    times = ((desk_x + k * desk_y - x0) / speed).astype(np.float32)
    times[np.abs(times - 40.0) < 0.5] = np.nan  # frame 40: no crossings anywhere
    # an object over most of the shadow's length in frames 24-36: its pixels (y > -20 mm) cross 30 mm later
    obj = (desk_y > -20.0) & (np.abs(times - 30.0) < 6.0)
    times[obj] += np.float32(30.0 / speed)
    assert obj.sum() > 2 * (np.abs(times - 30.0) < 6.0).sum() / 3
    along = np.array([-k, 1.0, 0.0]) / np.hypot(k, 1.0)
    point = np.array([pose.world_to_camera(np.array([x0 + speed * t, 0.0, 0.0])) for t in range(n)])
    direction = np.tile(pose.R @ along, (n, 1))
    lost = np.zeros(n, dtype=bool)
    lost[list(range(26, 35)) + [40]] = True

    def lines_with(missing: np.ndarray) -> ReferenceLines:
        pts = point.copy()
        pts[missing] = np.nan
        return ReferenceLines("desk", plane, pts, direction.copy(), np.full(n, 0.1), np.full(n, 50),
                              [np.zeros((0, 2))] * n, np.zeros(n, dtype=bool), [np.zeros((0, 3))] * n)

    def world_x(lines: ReferenceLines) -> np.ndarray:  # x + k·y of each line's point: x0 + speed·t on the desk's
        return np.array([pose.camera_to_world(p)[:2] @ [1.0, k] if np.isfinite(p[0]) else np.nan
                         for p in lines.point])

    mask = np.ones((150, 200), dtype=bool)
    same = follow_the_sweep(lines_with(lost), times, n, mask, cam, tolerance=0.5)
    assert np.array_equal(same.found, ~lost)
    filled = follow_the_sweep(lines_with(lost), times, n, mask, cam, tolerance=0.5, fill_gaps=True)
    x = world_x(filled)
    np.testing.assert_allclose(x[26:35], x0 + speed * np.arange(26, 35), atol=0.5)  # the desk's, not the object's
    assert np.isnan(x[40]) and filled.extrapolated[26:35].all()
    np.testing.assert_allclose(x[~lost], x0 + speed * np.arange(n)[~lost], atol=1e-9)  # the others untouched
    np.testing.assert_allclose(filled.direction[26:35], direction[26:35], atol=1e-9)
    wide = np.ones(n, dtype=bool)
    wide[[0, MAX_FOLLOW_GAP + 1]] = False  # long lines MAX_FOLLOW_GAP + 1 frames apart: too far to follow
    assert follow_the_sweep(lines_with(wide), times, n, mask, cam, tolerance=0.5, fill_gaps=True).found.sum() == 2
    wide[MAX_FOLLOW_GAP + 1], wide[MAX_FOLLOW_GAP] = True, False  # MAX_FOLLOW_GAP apart: filled
    within = follow_the_sweep(lines_with(wide), times, n, mask, cam, tolerance=0.5, fill_gaps=True)
    assert within.found[:MAX_FOLLOW_GAP + 1].all()


def _wall_with_a_box(front_mm: float) -> dict:
    """A wall z = 1000 mm (camera frame) swept by a lamp's shadow edge as in ``_fast_sweep_with_a_fold`` (times
    exact, both edges), with a box's face ``front_mm`` in front of it over rows 40–70, columns 80–120 (0: no
    box): its shadow times are those of its own points, off the wall's by about 600·front/1000/10 frames."""
    from gnomon.camera.models import OpenCVCamera
    from gnomon.geometry.reference_lines import PlaneInCamera

    w, h, f = 200, 120, 800.0
    camera = OpenCVCamera(w, h, f, f, w / 2, h / 2)
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    box = (vv >= 40) & (vv < 70) & (uu >= 80) & (uu < 120)
    pz = np.where(box, 1000.0 - front_mm, 1000.0)
    px, py = (uu - w / 2) / f * pz, (vv - h / 2) / f * pz
    lamp_x, slant, speed, start, n_frames = -600.0, 0.1, 10.0, -200.0, 60
    c_point = lamp_x + 1000.0 * (px - lamp_x + slant * py) / pz
    maps = [(c_point - start - behind) / speed for behind in (0.0, 60.0)]
    maps = [np.where((m > 0) & (m < n_frames - 1), m, np.nan) for m in maps]
    wall = PlaneInCamera(np.array([0.0, 0.0, 1.0]), 1000.0, np.array([0.0, 0.0, 1000.0]),
                         np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    region = np.zeros((h, w), dtype=bool)
    region[20:100, 30:170] = True
    return {"maps": maps, "n_frames": n_frames, "plane": wall, "camera": camera, "region": region, "box": box}


def test_a_scan_leaves_an_object_in_its_region_out_of_the_planes_lines() -> None:
    """A hand-drawn region over a wall and a box's face 40 mm in front of it (about 2.4 frames off the wall's
    times): the pixels that do not follow the wall's own lines are exactly the box's, grown by the 2 px
    margin; the bare wall is kept; the same region without the box loses nothing."""
    from gnomon.geometry.reference_lines import ReferencePlane
    from gnomon.reconstruct.bare import MARGIN_PX, off_plane

    scene = _wall_with_a_box(40.0)
    camera, region, box = scene["camera"], scene["region"], scene["box"]
    held = off_plane(ReferencePlane("wall", scene["plane"], region), scene["maps"], scene["n_frames"], camera,
                     camera.ray_map())
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * MARGIN_PX + 1, 2 * MARGIN_PX + 1))
    grown = cv2.dilate(box.astype(np.uint8), disc).astype(bool)
    assert np.array_equal(held.mask, region & ~grown)
    assert held.left_out == int((region & grown).sum()) and held.pieces[0] == (int(box.sum()), (80, 40, 120, 70))
    bare = _wall_with_a_box(0.0)
    clean = off_plane(ReferencePlane("wall", bare["plane"], region), bare["maps"], bare["n_frames"], camera,
                      camera.ray_map())
    assert clean.left_out == 0 and clean.mask[region].all()


def _naive_regions(capture: Path, folder: Path) -> tuple[Path, dict]:
    """A copy of the capture whose planes' regions are their marks' outlines (the convex hull of the true
    marker pixels), which on the desk hold the sphere, the box and their shadows."""
    shutil.copytree(capture, folder)
    truth = dict(np.load(folder / "ground_truth.npz"))
    log = tomllib.loads((folder / "field_log.toml").read_text())
    for p, plane in enumerate(log["planes"]):
        hull = cv2.convexHull(truth["marker_pixels"][p].astype(np.float32)).reshape(-1, 2)
        plane["regions"] = [{"polygon": hull.tolist()}]
    toml_io.dump(log, folder / "field_log.toml")
    return folder / "field_log.toml", truth


@pytest.mark.slow
def test_regions_started_over_objects_cut_them_out_and_say_so(two_plane_small: Path, tmp_path: Path,
                                                              capsys) -> None:
    """Regions drawn as the marks' outlines hold the sphere and the box on the desk (thousands of swept object
    pixels): `gnomon regions` grown from them keeps nothing but the planes (≤ 0.1 % of each mask off its
    plane, the scene's bar above) and says how much of what it started from it cut out, at least the swept
    object pixels in it; a scan with the outlines as they are warns with the numbers, its desk lines are
    measured without them, and no band of wrong depth appears: the points off by more than 1 % of the
    distance are as few as with the simulator's own bare regions (± 0.05 % of the points)."""
    from gnomon.runs.accuracy import depth_accuracy
    from gnomon.runs.scan import ScanOptions, run_scan

    log, truth = _naive_regions(two_plane_small, tmp_path / "naive")
    outline = load_field_log(log)
    from gnomon.config.setup import plane_region_mask

    desk_seed = plane_region_mask(outline.planes[0], truth["object_id"].shape)
    on_objects = desk_seed & np.isin(truth["object_id"], (1, 2)) & truth["swept"]
    assert on_objects.sum() > 1000  # the outline really holds the objects
    assert main(["regions", str(log), "--out", str(tmp_path / "proposed"), "--quiet"]) == 0
    said = capsys.readouterr().out
    for name, oid in (("desk", DESK), ("wall", WALL)):
        mask = cv2.imread(str(tmp_path / "proposed" / f"{name}_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
        assert (truth["object_id"][mask] == oid).mean() >= 0.999, name
    cut = int(said.split("desk: ")[1].split("cut out: ")[1].split(" pixels")[0])
    assert cut >= on_objects.sum(), said

    result = run_scan(log, tmp_path / "scan", ScanOptions(progress=False, rrd=False))
    warned = [w for w in result.warnings if "[[planes]] desk" in w and "do not follow its shadow lines" in w]
    assert warned, result.warnings
    left_out = int(warned[0].split("desk: ")[1].split(" of its")[0])
    assert left_out >= 0.9 * on_objects.sum()
    distance = float(truth["camera_distance_mm"])
    naive = depth_accuracy(result.depth, truth["depth"], truth["swept"], distance)
    bare = run_scan(two_plane_small / "field_log.toml", tmp_path / "bare", ScanOptions(progress=False, rrd=False))
    reference = depth_accuracy(bare.depth, truth["depth"], truth["swept"], distance)
    print(naive.table("marks' outlines as regions"), reference.table("the simulator's bare regions"), sep="\n")
    assert naive.gross_rate <= reference.gross_rate + 0.0005
    assert naive.rms_pct <= max(0.15, 1.5 * reference.rms_pct)


def test_frames_without_a_line_are_named_by_their_files() -> None:
    """`gnomon regions`' warning numbers frames from 0 (as field_logs/README.md does) and names their files
    too, through the tracker's `used` (a frame refused as a dip shifts the files); a video gets no names."""
    from pathlib import Path

    from gnomon.capture.frames import FrameSource
    from gnomon.commands.regions import _files

    files = tuple(Path(f"frames/{k + 1:06d}.jpg") for k in range(10))
    source = FrameSource(image_files=files)
    used = np.array([0, 1, 2, 4, 5, 6, 7, 8, 9])  # file 000004.jpg refused
    assert _files(source, used, 2, 4) == " (files 000003.jpg–000006.jpg)"
    assert _files(source, used, 3, 3) == " (file 000005.jpg)"
    assert _files(source, used, 7, 9) == ""  # past the tracked frames: nothing rather than a wrong name
