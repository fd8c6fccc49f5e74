"""gnomon fuse: several scans of one object registered and fused, against known transforms and the simulator's truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from gnomon.cli import main
from gnomon.errors import GnomonError

o3d = pytest.importorskip("open3d")

from gnomon.fuse.registration import Cloud, coarse_alignment, features, icp, rotation_angle_deg, se3_exp  # noqa: E402
from gnomon.fuse.surface import FusedMesh, VoxelFusion, holes  # noqa: E402


def hills(n: int = 100, step: float = 1.0, seed: int = 0, sigma: float = 0.02):
    """An asymmetric smooth surface (mm) sampled every ``step`` mm, its unit normals, and noise of σ along z."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(n) * step - n * step / 2, np.arange(n) * step - n * step / 2)
    x, y = x.ravel(), y.ravel()
    g1 = 20 * np.exp(-((x - 10) ** 2 + (y + 5) ** 2) / 400)
    g2 = 10 * np.exp(-((x + 25) ** 2 + (y - 15) ** 2) / 150)
    z = g1 + g2 + 0.1 * x
    dzdx = g1 * (-2 * (x - 10) / 400) + g2 * (-2 * (x + 25) / 150) + 0.1
    dzdy = g1 * (-2 * (y + 5) / 400) + g2 * (-2 * (y - 15) / 150)
    N = np.column_stack([-dzdx, -dzdy, np.ones_like(x)])
    N /= np.linalg.norm(N, axis=1)[:, None]
    P = np.column_stack([x, y, z + sigma * rng.standard_normal(len(x))])
    return P, N


def test_registration_recovers_a_known_transform_without_hints():
    """A surface and a moved, partly overlapping copy (σ = 0.02 mm): coarse (FPFH + RANSAC) then σ-weighted
    ICP find the motion. With 10 000 points of σ 0.02 mm on a 100 mm patch, the noise allows ~1e-4 mm and
    ~1e-4°; the tolerances (0.01 mm, 0.005°) are what a correct solver meets with a wide margin and a
    wrong local minimum does not."""
    P, N = hills(seed=1)
    Q, M = hills(seed=2)
    keep = Q[:, 0] > -30  # the second view sees 80 % of the patch
    T = se3_exp(np.array([0.05, -0.08, 0.6, 12.0, -7.0, 3.0]))  # 35° about a tilted axis
    Qm = Q[keep] @ T[:3, :3].T + T[:3, 3]
    Mm = M[keep] @ T[:3, :3].T
    sig = np.full(len(P), 0.02)
    src = Cloud.of(Qm, Mm, np.full(len(Qm), 0.02))
    dst = Cloud.of(P, N, sig)
    coarse = coarse_alignment(features(Qm, Mm, 2.0), features(P, N, 2.0), 2.0)
    r = icp(src, dst, coarse, max_distance=6.0, min_distance=2.0, sigma_floor=0.1)
    E = r.transform @ T  # should be the identity: source → target undoes T
    assert rotation_angle_deg(E) < 0.005
    assert np.linalg.norm(E[:3, 3]) < 0.01
    assert r.overlap > 0.9
    assert r.rms == pytest.approx(np.sqrt(2) * 0.02, rel=0.15)  # the two points' σ along the normal, no more


def test_voxel_fusion_weights_by_sigma():
    """Two views of the same points: the fused point is the inverse-variance mean, σ = (Σ 1/σ²)^-1/2."""
    P = np.array([[0.2, 0.2, 0.2], [5.3, 0.1, 0.4]])
    N = np.array([[0.0, 0.0, 1.0]] * 2)
    grid = VoxelFusion(1.0)
    grid.add(0, P, N, np.array([0.1, 0.1]), None)
    grid.add(1, P + [0.0, 0.0, 0.3], N, np.array([0.2, 0.2]), None)
    f = grid.result()
    assert len(f.points) == 2 and list(f.views) == [2, 2]
    w1, w2 = 1 / 0.1**2, 1 / 0.2**2
    np.testing.assert_allclose(f.points[:, 2], P[:, 2] + 0.3 * w2 / (w1 + w2))
    np.testing.assert_allclose(f.sigma, (w1 + w2) ** -0.5)


def _box_mesh(open_top: bool) -> FusedMesh:
    """A 10 mm cube standing on z = 0, its bottom face left out (and its top too with ``open_top``)."""
    m = o3d.geometry.TriangleMesh.create_box(10.0, 10.0, 10.0)
    V, F = np.asarray(m.vertices), np.asarray(m.triangles)
    cz = V[F].mean(axis=1)[:, 2]
    F = F[(cz > 1e-9) & ((cz < 10 - 1e-9) | (not open_top))]
    return FusedMesh(V, F.astype(np.int32), V * 0, np.zeros((len(V), 3), np.uint8), np.zeros(len(V)))


def test_holes_are_named_by_where_they_lie():
    desk = [(np.array([0.0, 0.0, 1.0]), 0.0)]
    closed_but_bottom = holes(_box_mesh(False), desk, band=0.5)
    assert [(h.edges, h.where) for h in closed_but_bottom] == [(4, "on the set-up")]
    assert closed_but_bottom[0].perimeter == pytest.approx(40.0)
    both = holes(_box_mesh(True), desk, band=0.5)
    assert sorted(h.where for h in both) == ["on the set-up", "unseen"]
    top = next(h for h in both if h.where == "unseen")
    assert top.centre[2] == pytest.approx(10.0)


def _fake_scan(folder: Path, units: str, points: np.ndarray, normals: np.ndarray) -> Path:
    from gnomon.outputs.ply import write_points_ply

    folder.mkdir(parents=True)
    write_points_ply(folder / "points.ply", points.astype(np.float32), None,
                     np.full(len(points), 0.05, np.float32), None, (), normals.astype(np.float32))
    report = {"units": units, "camera": {"pose": {"rvec": [np.pi, 0.0, 0.0], "tvec": [0.0, 0.0, 500.0]}}}
    (folder / "report.json").write_text(json.dumps(report))
    return folder


def test_units_that_differ_are_refused_and_nothing_is_written(tmp_path, capsys):
    P, N = hills()
    a = _fake_scan(tmp_path / "a", "mm", P, N)
    b = _fake_scan(tmp_path / "b", "m", P / 1000, N)
    assert main(["fuse", str(a), str(b), "--out", str(tmp_path / "model")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "units 'm' differ" in err[0] and str(b) in err[0]
    assert not (tmp_path / "model").exists()


def test_without_open3d_the_command_says_how_to_install(tmp_path, capsys, monkeypatch):
    import sys

    P, N = hills()
    a = _fake_scan(tmp_path / "a", "mm", P, N)
    b = _fake_scan(tmp_path / "b", "mm", P, N)
    monkeypatch.setitem(sys.modules, "open3d", None)  # import open3d raises ImportError
    assert main(["fuse", str(a), str(b), "--out", str(tmp_path / "model")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'pip install "gnomon[fuse]"' in err[0]
    assert not (tmp_path / "model").exists()


def test_not_a_scan_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    P, N = hills()
    a = _fake_scan(tmp_path / "a", "mm", P, N)
    assert main(["fuse", str(a), str(tmp_path / "empty"), "--out", str(tmp_path / "model")]) == 2
    assert "missing points.ply" in capsys.readouterr().err
    with pytest.raises(GnomonError, match="at least two"):
        from gnomon.fuse.views import check_views, read_view

        check_views([read_view(a)])


# ----------------------------------------------------------------- simulated desk object, 4 views (slow)


@pytest.fixture(scope="module")
def turned_scans(tmp_path_factory):
    """``desk_turns`` with 4 views (800 × 600, the default capture) each scanned: (root, scan folders)."""
    from gnomon.runs.scan import ScanOptions, run_scan
    from gnomon.simulate.turntable import TurnsConfig, simulate_turns

    root = tmp_path_factory.mktemp("turns")
    sim = simulate_turns(root / "capture", TurnsConfig(views=4))
    scans = []
    for k, log in enumerate(sim.field_logs):
        run_scan(log, root / f"scan_{k}", ScanOptions(progress=False, rrd=False))
        scans.append(root / f"scan_{k}")
    return root, scans


@pytest.mark.slow
def test_four_desk_views_fuse_to_the_true_object(turned_scans):
    """The acceptance figures: poses within 0.1° and 0.05 % of the distance, the fused surface within
    0.1 % RMS of the true surface over ≥ 95 % of the surface the views saw; the only holes the desk
    under the object's and where no view saw."""
    from gnomon.fuse.registration import rotation_angle_deg as angle
    from gnomon.recording.review import summarize
    from gnomon.simulate.turntable import figure_distance, seen_surface

    root, scans = turned_scans
    out = root / "model"
    assert main(["fuse", *map(str, scans), "--out", str(out), "--mesh-formats", "all"]) == 0
    report = json.loads((out / "report.json").read_text())
    truth = json.loads((root / "capture" / "turns.json").read_text())
    d = report["distance"]
    assert 550 < d < 650  # the camera is 650 mm from the desk's centre, the object stands up to 90 mm tall
    for k, v in enumerate(truth["views"]):
        E = np.linalg.inv(np.asarray(v["pose_to_reference"])) @ np.asarray(report["views"][k]["pose"])
        with np.load(root / "capture" / v["folder"] / "ground_truth.npz") as gt:
            c = gt["points_world"][gt["swept"] & (gt["object_id"] > 0)].astype(np.float64).mean(axis=0)
        assert angle(E) < 0.1, k
        assert np.linalg.norm(E[:3, :3] @ c + E[:3, 3] - c) < 0.0005 * d, k
    from gnomon.outputs.ply import read_ply

    mesh = read_ply(out / "mesh.ply")
    V = np.asarray(mesh["xyz"], np.float64)
    F0 = np.linalg.inv(np.asarray(truth["views"][0]["figure_pose"]))
    err = figure_distance(V @ F0[:3, :3].T + F0[:3, 3])
    assert np.sqrt(np.mean(err**2)) < 0.001 * d
    assert mesh["sigma"].min() > 0 and np.median(mesh["sigma"]) < 0.001 * d
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(mesh["faces"].astype(np.uint32)))
    seen, _ = seen_surface(root / "capture")
    gap = scene.compute_distance(o3d.core.Tensor(seen.astype(np.float32))).numpy()
    assert np.mean(gap < 0.001 * d) >= 0.95
    holes_ = report["model"]["holes"]
    assert any(h["where"] == "on the set-up" for h in holes_)
    assert report["registration"]["loop_closure"]["rotation_deg"] < 0.5
    assert {"mesh.ply", "mesh.obj", "mesh.stl", "points.ply", "report.json", "fuse.rrd"} <= {
        p.name for p in out.iterdir()}
    names = set(summarize(out / "fuse.rrd").entities)
    for k in range(4):  # each view's pose, with its object points below it
        assert {f"/world/views/scan_{k}", f"/world/views/scan_{k}/points"} <= names
    assert {"/world/mesh", "/world/points", "/metrics/loop/rotation_deg", "/metrics/pairs/0-1/rms"} <= names


@pytest.mark.slow
def test_a_scan_of_another_object_is_refused(turned_scans, desk_lamp_full_scan, tmp_path, capsys):
    """The desk_lamp scene (a sphere, a box and a cylinder) among views of the figure: one line naming
    it, exit 2, nothing written."""
    root, scans = turned_scans
    other = desk_lamp_full_scan[0] / "scan"
    out = tmp_path / "model"
    assert main(["fuse", str(scans[0]), str(scans[1]), str(other), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(other) in err[0] and "does not overlap" in err[0]
    assert not out.exists()
    shutil.rmtree(tmp_path, ignore_errors=True)


# ----------------------------------------------------------------- simulated building, two stations (slow)


@pytest.fixture(scope="module")
def station_scans(tmp_path_factory):
    """The facade from two georeferenced stations (800 × 600, 200 frames; the second station's site 1.5 m
    off, 2 m stated), each scanned: (root, scan folders)."""
    from gnomon.runs.scan import ScanOptions, run_scan
    from gnomon.simulate.stations import StationsConfig, simulate_stations

    root = tmp_path_factory.mktemp("stations")
    sim = simulate_stations(root / "capture", StationsConfig())
    scans = []
    for k, log in enumerate(sim.field_logs):
        run_scan(log, root / f"scan_{k}", ScanOptions(progress=False, rrd=False))
        scans.append(root / f"scan_{k}")
    return root, scans


def _station_offsets(root: Path, scans: list[Path], pose: np.ndarray) -> np.ndarray:
    """How far station 1's points land from where they belong (m), placed by ``pose``."""
    from gnomon.fuse.views import read_view

    truth = json.loads((root / "capture" / "stations.json").read_text())
    T = np.asarray(truth["stations"][1]["pose_to_reference"])
    X = read_view(scans[1]).points
    return np.linalg.norm(X @ pose[:3, :3].T + pose[:3, 3] - (X @ T[:3, :3].T + T[:3, 3]), axis=1)


@pytest.mark.slow
def test_two_stations_placed_by_georeference_then_registered(station_scans):
    """Before registration the stations are where their georeference puts them: off by the simulated
    1.5 m error, within the 2 m the field logs state; after it within 0.05 % of the distance; one model,
    in East-North-Up metres at the first station's site."""
    from gnomon.fuse.georeference import station_priors
    from gnomon.fuse.views import read_view
    from gnomon.outputs.ply import read_ply

    root, scans = station_scans
    out = root / "model"
    assert main(["fuse", *map(str, scans), "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    d = report["distance"]
    prior = station_priors([read_view(s) for s in scans])[1]
    before = _station_offsets(root, scans, prior.pose)
    assert before.max() == pytest.approx(1.5, abs=0.01) and before.max() < prior.sigma_position
    after = _station_offsets(root, scans, np.asarray(report["views"][1]["pose"]))
    assert np.sqrt(np.mean(after**2)) < 0.0005 * d
    assert report["warnings"] == []  # moved 1.5 m, 3σ allows more
    assert report["units"] == "m" and "East-North-Up" in report["frame"]
    import laspy  # the survey's cloud in the site's projected CRS too, as a sun scan's

    las = laspy.read(out / "points.laz")
    assert "UTM zone 32N" in las.header.parse_crs().name and las.header.point_count == len(
        read_ply(out / "points.ply")["xyz"])
    # station 0's own points, taken to ENU by its own georeference, lie on the model
    v0 = read_view(scans[0])
    M = np.asarray(v0.site["world_to_enu"])
    enu = v0.points @ M[:3, :3].T + M[:3, 3]
    from scipy.spatial import cKDTree

    gap, _ = cKDTree(np.asarray(read_ply(out / "points.ply")["xyz"], np.float64)).query(enu[::50])
    assert np.median(gap) < 0.001 * d


@pytest.mark.slow
def test_a_station_moved_beyond_its_stated_sigma_is_named(station_scans, tmp_path):
    """Both stations state their sites to 5 cm (and headings to 0.1°), but the second is 1.5 m off: the
    registration moves it that far and the report says so, with the numbers."""
    from gnomon.fuse.run import fuse_scans

    root, scans = station_scans
    copies = []
    for scan in scans:
        copy = shutil.copytree(scan, tmp_path / scan.name)
        report = json.loads((copy / "report.json").read_text())
        report["site"]["position_sigma_m"] = 0.05
        (copy / "report.json").write_text(json.dumps(report))
        copies.append(copy)
    result = fuse_scans(copies, None)
    warnings = result.report["warnings"]
    assert len(warnings) == 1 and str(copies[1]) in warnings[0] and "beyond 3σ" in warnings[0]
    st = result.report["registration"]["stations"][1]
    assert st["moved"] == pytest.approx(1.5, abs=0.05) and st["allowed_3sigma"] < 0.5 < st["moved"]


def test_station_prior_from_two_sites():
    """Two stations' georeferences (the second's origin 10 m east, 5 m south and 1 m up of the first's, its
    heading 30° more; sites from the simulator's own geodesy): the prior pose takes the second's frame to
    the first's exactly (to 1 mm over 11 m: the Earth's curvature is below 0.1 mm there)."""
    from gnomon.fuse.georeference import station_priors
    from gnomon.fuse.views import View
    from gnomon.light.georef import georeference_report
    from gnomon.simulate.stations import offset_site

    lat, lon, alt, heading = 47.3769, 8.5417, 408.0, 295.0
    lat2, lon2, alt2 = offset_site(lat, lon, alt, 10.0, -5.0, 1.0)
    views = []
    for la, lo, al, h in ((lat, lon, alt, heading), (lat2, lon2, alt2, heading + 30.0)):
        site = {**georeference_report(la, lo, al, h, "m"), "position_sigma_m": 0.5}
        views.append(View(Path("s"), "m", np.zeros((1, 3)), np.zeros((1, 3)), np.ones(1), None, np.zeros(3), site,
                          {"sun": {"heading_sigma_deg": 0.2}}))
    prior = station_priors(views)[1]
    a = np.radians(heading)
    world_from_enu = np.array([[np.sin(a), np.cos(a), 0.0], [-np.cos(a), np.sin(a), 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(prior.pose[:3, 3], world_from_enu @ [10.0, -5.0, 1.0], atol=1e-3)
    # 30°, less the meridians' convergence over 10 m east: 10 m / (R cos φ) · sin φ = 9.7e-5° at 47.4° N
    convergence = np.degrees(10.0 / (6.39e6 * np.cos(np.radians(lat))) * np.sin(np.radians(lat)))
    assert rotation_angle_deg(prior.pose) == pytest.approx(30.0 - convergence, abs=1e-5)
    # the second station's x axis, in the first's frame, is the first's turned by 30° clockwise seen from above
    np.testing.assert_allclose(prior.pose[:3, 0], [np.cos(np.radians(-30)), np.sin(np.radians(-30)), 0.0], atol=1e-5)
    assert (prior.sigma_position, prior.sigma_heading_deg, prior.stated) == (0.5, 0.2, True)
