"""The rerun recording layer: write synthetic recordings, read them back with rerun's
own chunk API (rerun.chunk.RrdReader), and check their content; `rerun rrd verify`
must accept every recording written here. Offline: no viewer, no network."""

from __future__ import annotations

import subprocess
import sys
from datetime import UTC, datetime, timedelta

import cv2
import numpy as np
import pyarrow as pa
import pytest

from gnomon.recording.recorder import ENTITY, ScanRecording, display_to_pixels

# rerun's usage analytics are off when CI is set (re_analytics); TELEMETRY_ENABLED
# gates rerun's OpenTelemetry tracing (off by default). RERUN_TELEMETRY_ENABLED is
# not read by rerun 0.41 but costs nothing.
OFFLINE_ENV = {"CI": "1", "TELEMETRY_ENABLED": "false", "RERUN_TELEMETRY_ENABLED": "false"}


@pytest.fixture(autouse=True)
def _offline(monkeypatch):
    for k, v in OFFLINE_ENV.items():
        monkeypatch.setenv(k, v)
    # Never a viewer window in tests, whatever the machine has.
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


def rrd_verify(path) -> subprocess.CompletedProcess:
    """Run `rerun rrd verify` (the CLI shipped with rerun-sdk, via `python -m rerun`)."""
    import os

    env = {**os.environ, **OFFLINE_ENV}
    return subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "verify", str(path)],
        capture_output=True, text=True, env=env, timeout=120,
    )


# --------------------------------------------------------------------------- reading back


def load(path) -> dict[str, list[pa.RecordBatch]]:
    """entity path → its chunks as Arrow record batches (recording store only)."""
    from rerun.chunk import RrdReader

    out: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(path).stream():
        out.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return out


def rows(data, entity: str, component: str, timeline: str | None = "frame") -> list[tuple]:
    """[(time or None, python value of the cell)] for one component, sorted by time."""
    out = []
    for batch in data.get("/" + entity, []):
        names = batch.schema.names
        if component not in names:
            continue
        col = batch.column(component).to_pylist()
        times = [None] * len(col)
        if timeline and timeline in names:
            tcol = batch.column(timeline)
            times = tcol.cast(pa.int64()).to_pylist()
            if pa.types.is_timestamp(tcol.type):  # ns since the epoch, UTC
                times = [None if t is None else EPOCH + timedelta(microseconds=t / 1000) for t in times]
        out += [(t, v) for t, v in zip(times, col, strict=True) if v is not None]
    return sorted(out, key=lambda x: (x[0] is None, x[0] if x[0] is not None else 0))


def one(data, entity: str, component: str):
    r = rows(data, entity, component)
    assert r, f"{entity} has no {component}"
    return r[-1][1]


# --------------------------------------------------------------------------- the synthetic run

W, H = 64, 48
N_FRAMES = 30
STRIDE = 10
T0 = datetime(2024, 6, 21, 10, 0, 0, tzinfo=UTC)
EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
K = np.array([[80.0, 0.0, 31.5], [0.0, 80.0, 23.5], [0.0, 0.0, 1.0]])
R = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # looking down at z = 0
T = np.array([-30.0, 20.0, 400.0])
PLANE = np.array([[0, 0, 0], [100, 0, 0], [100, 80, 0], [0, 80, 0]], dtype=np.float64)
RNG = np.random.default_rng(7)
XYZ = (RNG.random((500, 3)) * [100, 80, 10]).astype(np.float32)
RGB = RNG.integers(0, 256, (500, 3), dtype=np.uint8)
SIGMA = (RNG.random(500) * 0.2).astype(np.float32)
UV = (RNG.random((500, 2)) * [W - 1, H - 1]).astype(np.float32)
MESH_V = RNG.random((40, 3)).astype(np.float32)
MESH_F = RNG.integers(0, 40, (60, 3)).astype(np.int32)
SHADOW_TIME = np.full((H, W), np.nan, np.float32)
SHADOW_TIME[5:40, 4:60] = np.linspace(0, 29, 56, dtype=np.float32)[None, :]
DEPTH = np.where(np.isfinite(SHADOW_TIME), 400.0, np.nan).astype(np.float32)
SIGMA_MAP = np.where(np.isfinite(SHADOW_TIME), 0.05, np.nan).astype(np.float32)
METRICS = {"coverage": 0.93, "depth_rms_mm": 0.12, "timings": {"total_s": 1.5, "kernel s": 0.25}, "note": "x"}
COVERAGE = np.where(np.isfinite(SHADOW_TIME), 1, 0).astype(np.uint8)
COVERAGE[:3] = 2
WARNINGS = ["low contrast in 7% of pixels", "frame 17: edge fit residual 2.1 px"]


def edge(i: int) -> np.ndarray:
    return np.array([[2.0 * i, 0.0], [2.0 * i + 1.0, H - 1.0]])


def shadow_quad(i: int) -> np.ndarray:
    x = 3.0 * i
    return np.array([[x, 0, 0], [x, 80, 0], [x + 5, 80, 50], [x + 5, 0, 50]])


def frame(i: int) -> np.ndarray:
    img = np.full((H, W), 200, np.uint8)
    img[:, : 2 * i + 1] = 30  # the shadow sweeps left to right
    return img


def write_scan(path, **kwargs) -> ScanRecording:
    with ScanRecording(path, recording_name="synthetic desk", frame_stride=STRIDE, **kwargs) as rec:
        rec.log_camera(K, W, H, R, T, "mm")
        rec.log_reference_plane("ground", PLANE)
        rec.log_reference_plane("back wall", PLANE[:, [0, 2, 1]])
        rec.log_lamp([50.0, -40.0, 300.0])
        for i in range(N_FRAMES):
            t = T0 + timedelta(seconds=i)
            rec.log_frame(i, frame(i), capture_time=t)
            rec.log_edges(i, [edge(i)], capture_time=t)
            rec.log_shadow_plane(i, shadow_quad(i), capture_time=t)
        rec.log_warning(WARNINGS[0])
        rec.log_warning(WARNINGS[1], index=17)
        rec.log_points(XYZ, RGB, SIGMA, uv=UV)
        rec.log_mesh(MESH_V, MESH_F, RGB[:40])
        rec.log_maps(SHADOW_TIME, DEPTH, SIGMA_MAP)
        rec.log_camera_depth(DEPTH)
        rec.log_coverage(COVERAGE)
        rec.log_metrics(METRICS)
    return rec


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    path = d / "scan.rrd"
    rec = write_scan(path)
    return path, rec, load(path)


# --------------------------------------------------------------------------- tests


def test_file_is_complete_and_verified(scan):
    path, rec, _ = scan
    assert path.is_file() and path.stat().st_size > 0
    assert sorted(p.name for p in path.parent.iterdir()) == ["scan.rrd"]  # no temp file left
    res = rrd_verify(path)
    assert res.returncode == 0, res.stderr


def test_entities(scan):
    _, _, data = scan
    expected = {
        "/world/camera", "/world/camera/image", "/world/camera/image/edges", "/world/shadow_plane",
        "/world/planes/ground", "/world/planes/back_wall", "/world/light", "/world/points", "/world/mesh",
        "/maps/shadow_time", "/maps/depth", "/maps/sigma", "/log", "/world", "/world/camera/depth",
        "/maps/coverage", "/metrics/coverage", "/metrics/depth_rms_mm", "/metrics/timings/total_s", "/summary",
        "/metrics/timings/kernel_s",
    }
    assert set(data) - {"/__properties"} == expected


def test_recording_properties_and_blueprint(scan):
    from rerun.chunk import RrdReader

    path, _, data = scan
    reader = RrdReader(path)
    (store,) = reader.recordings()
    assert store.application_id == "gnomon"
    assert len(reader.blueprints()) == 1
    assert one(data, "__properties", "RecordingInfo:name") == ["synthetic desk"]
    views = [
        c.to_record_batch().column("ViewBlueprint:space_origin").to_pylist()[0][0]
        for c in RrdReader(path).stream(store=reader.blueprints()[0])
        if "ViewBlueprint:space_origin" in c.to_record_batch().schema.names
    ]
    assert sorted(v.strip("/") for v in views) == sorted(
        ["world", "world/camera/image", "maps/shadow_time", "live/shadow_time", "maps/depth", "maps/sigma",
         "maps/coverage", "log", "summary", "metrics"]
    )


def test_frames_are_subsampled_jpegs_on_both_timelines(scan):
    _, rec, data = scan
    assert rec.frames_seen == N_FRAMES and rec.frames_stored == N_FRAMES // STRIDE
    blobs = rows(data, ENTITY["image"], "EncodedImage:blob")
    assert [t for t, _ in blobs] == [0, 10, 20]
    assert one(data, ENTITY["image"], "EncodedImage:media_type") == ["image/jpeg"]
    for i, blob in blobs:
        img = cv2.imdecode(np.frombuffer(bytes(blob[0]), np.uint8), cv2.IMREAD_UNCHANGED)
        assert img.shape == (H // 2, W // 2)  # image_scale 0.5
        expected = cv2.resize(frame(i), (W // 2, H // 2), interpolation=cv2.INTER_AREA)
        assert np.abs(img.astype(int) - expected).mean() < 3  # JPEG q80
    times = rows(data, ENTITY["image"], "EncodedImage:blob", timeline="capture_time")
    assert [t for t, _ in times] == [T0 + timedelta(seconds=i) for i in (0, 10, 20)]


def test_camera_pose_and_pinhole(scan):
    _, _, data = scan
    tr = np.array(one(data, ENTITY["camera"], "Transform3D:translation")[0])
    m = np.array(one(data, ENTITY["camera"], "Transform3D:mat3x3")[0]).reshape(3, 3, order="F")
    # camera → world: the camera centre, and R^T
    assert np.allclose(tr, -R.T @ T, atol=1e-4)
    assert np.allclose(m, R.T, atol=1e-6)
    kd = np.array(one(data, ENTITY["camera"], "Pinhole:image_from_camera")[0]).reshape(3, 3, order="F")
    assert np.allclose(kd, [[40, 0, 16], [0, 40, 12], [0, 0, 1]])  # K·0.5 with the half-pixel shift
    assert one(data, ENTITY["camera"], "Pinhole:resolution") == [[W // 2, H // 2]]
    assert np.allclose(one(data, ENTITY["camera"], "GnomonCamera:K"), K.ravel())
    assert one(data, ENTITY["camera"], "GnomonCamera:resolution") == [W, H]
    assert one(data, ENTITY["camera"], "GnomonCamera:units") == ["mm"]
    # Projecting a world point with the logged pinhole/transform lands where the calibration says.
    Xw = np.array([40.0, 30.0, 0.0])
    Xc = m.T @ (Xw - tr)
    xy = (kd @ Xc)[:2] / Xc[2]
    uv = (K @ (R @ Xw + T))[:2] / (R @ Xw + T)[2]
    assert np.allclose(display_to_pixels(xy, [0.5, 0.5]), uv)


def test_edges_per_frame(scan):
    _, _, data = scan
    strips = rows(data, ENTITY["edges"], "LineStrips2D:strips")
    assert [t for t, _ in strips] == list(range(N_FRAMES))
    for i, cell in strips:
        (strip,) = cell
        assert np.allclose(display_to_pixels(np.array(strip), [0.5, 0.5]), edge(i), atol=1e-4)


def test_shadow_planes_and_reference_planes(scan):
    _, _, data = scan
    quads = rows(data, ENTITY["shadow_plane"], "Mesh3D:vertex_positions")
    assert [t for t, _ in quads] == list(range(N_FRAMES))
    for i, cell in quads:
        assert np.allclose(cell, shadow_quad(i))
    assert one(data, ENTITY["shadow_plane"], "Mesh3D:triangle_indices") == [[0, 1, 2], [0, 2, 3]]
    assert len(rows(data, ENTITY["shadow_plane"], "LineStrips3D:strips")) == N_FRAMES
    assert np.allclose(one(data, "world/planes/ground", "Mesh3D:vertex_positions"), PLANE)
    assert np.allclose(one(data, "world/planes/back_wall", "Mesh3D:vertex_positions"), PLANE[:, [0, 2, 1]])


def test_lamp(scan):
    _, _, data = scan
    assert np.allclose(one(data, ENTITY["light"], "Points3D:positions"), [[50, -40, 300]])
    assert all(b.num_rows == 1 for b in data["/world/light"])  # static


def test_points_bit_for_bit(scan):
    _, _, data = scan
    (batch,) = data["/world/points"]
    pos = batch.column("Points3D:positions")
    values = pos.flatten().flatten().to_numpy(zero_copy_only=False)
    assert values.dtype == np.float32 and values.tobytes() == XYZ.tobytes()
    packed = np.array(one(data, ENTITY["points"], "Points3D:colors"), dtype=np.uint32)
    assert np.array_equal(packed >> 24, RGB[:, 0]) and np.array_equal((packed >> 16) & 255, RGB[:, 1])
    assert np.array_equal((packed >> 8) & 255, RGB[:, 2]) and np.all(packed & 255 == 255)
    sigma = batch.column("GnomonPoints:sigma").flatten().to_numpy(zero_copy_only=False)
    assert sigma.dtype == np.float32 and sigma.tobytes() == SIGMA.tobytes()
    uv = batch.column("GnomonPoints:uv").flatten().to_numpy(zero_copy_only=False)
    assert uv.tobytes() == UV.tobytes()
    assert one(data, ENTITY["points"], "GnomonPoints:units") == ["mm"]


def test_colours_packed_as_rerun_packs_them():
    """The recorder packs colours itself (rerun's own packing is slow on millions): the same uint32s."""
    from rerun._color_conversion import u8_array_to_rgba

    from gnomon.recording.recorder import _packed_rgba

    rgb = np.random.default_rng(3).integers(0, 256, (1000, 3), dtype=np.uint8)
    rgb[0], rgb[1] = (0, 0, 0), (255, 255, 255)
    assert np.array_equal(_packed_rgba(rgb), u8_array_to_rgba(rgb))
    assert _packed_rgba(rgb).dtype == np.uint32


def test_mesh(scan):
    _, _, data = scan
    assert np.allclose(one(data, ENTITY["mesh"], "Mesh3D:vertex_positions"), MESH_V)
    assert np.array_equal(one(data, ENTITY["mesh"], "Mesh3D:triangle_indices"), MESH_F)
    assert len(one(data, ENTITY["mesh"], "Mesh3D:vertex_colors")) == 40


@pytest.mark.parametrize(
    "key, expected, colormap",
    [("shadow_time", SHADOW_TIME, 5), ("depth", DEPTH, 6), ("sigma", SIGMA_MAP, 2)],
)
def test_maps_keep_values_and_nan(scan, key, expected, colormap):
    import rerun as rr

    _, _, data = scan
    fmt = one(data, ENTITY[key], "DepthImage:format")[0]
    assert (fmt["width"], fmt["height"]) == (W, H)
    buf = np.frombuffer(bytes(one(data, ENTITY[key], "DepthImage:buffer")[0]), np.float32).reshape(H, W)
    assert np.array_equal(buf, expected, equal_nan=True)
    lo, hi = one(data, ENTITY[key], "DepthImage:depth_range")[0]
    finite = expected[np.isfinite(expected)]
    assert lo == pytest.approx(finite.min()) and hi >= finite.max()
    cmap = one(data, ENTITY[key], "DepthImage:colormap")[0]
    names = {5: rr.components.Colormap.Turbo, 6: rr.components.Colormap.Viridis, 2: rr.components.Colormap.Inferno}
    assert cmap == names[colormap].value


def test_a_recording_not_full_has_no_mesh_and_its_maps_at_the_frames_size(tmp_path):
    """A scan's default recording (``full=False``): the points as they are, no mesh, each map at the stored
    frames' size (half here): the nearest pixel, i.e. every second row and column."""
    path = tmp_path / "lite.rrd"
    write_scan(path, full=False, image_scale=0.5)
    data = load(path)
    assert "/" + ENTITY["mesh"] not in data and "/" + ENTITY["points"] in data
    assert len(one(data, ENTITY["points"], "Points3D:positions")) == len(XYZ)
    for key, expected in (("shadow_time", SHADOW_TIME), ("depth", DEPTH), ("sigma", SIGMA_MAP)):
        fmt = one(data, ENTITY[key], "DepthImage:format")[0]
        assert (fmt["width"], fmt["height"]) == (W // 2, H // 2)
        buf = np.frombuffer(bytes(one(data, ENTITY[key], "DepthImage:buffer")[0]), np.float32).reshape(H // 2, W // 2)
        assert np.array_equal(buf, expected[::2, ::2], equal_nan=True)
    assert rrd_verify(path).returncode == 0


def test_warnings_and_metrics(scan):
    _, _, data = scan
    texts = rows(data, ENTITY["log"], "TextLog:text")
    assert sorted(v[0] for _, v in texts) == sorted(WARNINGS)
    # on the frame timeline (the default layout's Warnings view): a run's warning from frame 0
    assert (0, [WARNINGS[0]]) in texts and (17, [WARNINGS[1]]) in texts
    assert {v[0] for _, v in rows(data, ENTITY["log"], "TextLog:level")} == {"WARN"}
    assert one(data, "metrics/coverage", "Scalars:scalars") == [0.93]
    assert one(data, "metrics/timings/total_s", "Scalars:scalars") == [1.5]
    assert one(data, "metrics/timings/kernel_s", "Scalars:scalars") == [0.25]
    assert "/metrics/note" not in data  # non-numeric values are skipped


def test_sun_arrow_moves_with_time(tmp_path):
    path = tmp_path / "sun.rrd"
    dirs = []
    with ScanRecording(path, recording_name="sun", frame_stride=5) as rec:
        rec.log_camera(K, W, H, R, T, "m")
        for i in range(12):
            az = np.radians(100 + 5 * i)
            d = np.array([np.sin(az), np.cos(az), 0.8])
            dirs.append(d / np.linalg.norm(d))
            rec.log_sun(i, d, anchor_world=[1.0, 2.0, 0.0], length=10.0, capture_time=T0 + timedelta(minutes=10 * i))
    assert rrd_verify(path).returncode == 0
    data = load(path)
    arrows = rows(data, ENTITY["light"], "Arrows3D:vectors")
    origins = rows(data, ENTITY["light"], "Arrows3D:origins")
    stored = rows(data, ENTITY["light"], "GnomonSun:direction")
    assert [t for t, _ in arrows] == list(range(12))
    for (i, vec), (_, org), (_, d) in zip(arrows, origins, stored, strict=True):
        assert np.allclose(d, dirs[i])
        assert np.allclose(np.array(vec[0]), -10.0 * dirs[i], atol=1e-5)  # incoming light
        assert np.allclose(np.array(org[0]) + np.array(vec[0]), [1, 2, 0], atol=1e-5)  # tip at the anchor
    times = [t for t, _ in rows(data, ENTITY["light"], "Arrows3D:vectors", timeline="capture_time")]
    assert times == [T0 + timedelta(minutes=10 * i) for i in range(12)]


def test_frames_without_time_get_no_stale_capture_time(tmp_path):
    path = tmp_path / "t.rrd"
    with ScanRecording(path, recording_name="t", frame_stride=1) as rec:
        rec.log_frame(0, frame(0), capture_time=T0)
        rec.log_frame(1, frame(1))
    assert rrd_verify(path).returncode == 0
    data = load(path)
    frames = [t for t, _ in rows(data, ENTITY["image"], "EncodedImage:blob")]
    times = rows(data, ENTITY["image"], "EncodedImage:blob", timeline="capture_time")
    assert frames == [0, 1]
    assert [t for t, _ in times if t is not None] == [T0]


def test_later_logs_of_a_frame_reuse_its_capture_time(tmp_path):
    path = tmp_path / "reuse.rrd"
    with ScanRecording(path, recording_name="r", frame_stride=100) as rec:
        rec.log_frame(3, frame(3), capture_time=T0)  # not stored (stride 100), time remembered
        rec.log_edges(3, [edge(3)])
        rec.log_edges(4, [edge(4)])  # frame 4 has no known time
    assert rrd_verify(path).returncode == 0
    edges = rows(load(path), ENTITY["edges"], "LineStrips2D:strips", timeline="capture_time")
    assert sorted(t is None for t, _ in edges) == [False, True]
    assert [t for t, _ in edges if t is not None] == [T0]


def test_uint16_colour_and_naive_time(tmp_path):
    path = tmp_path / "u16.rrd"
    img16 = np.arange(W * H, dtype=np.uint16).reshape(H, W)  # a 12-bit sensor: max 3071
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 0] = 255  # pure red, RGB order
    with ScanRecording(path, recording_name="x", frame_stride=1, image_scale=1.0, jpeg_quality=95) as rec:
        rec.log_frame(0, img16, capture_time=datetime(2024, 1, 1, 12, 0, 0))  # naive → UTC
        rec.log_frame(1, rgb)
    assert rrd_verify(path).returncode == 0
    data = load(path)
    blobs = rows(data, ENTITY["image"], "EncodedImage:blob")
    g = cv2.imdecode(np.frombuffer(bytes(blobs[0][1][0]), np.uint8), cv2.IMREAD_UNCHANGED)
    assert g.shape == (H, W) and g.dtype == np.uint8
    assert np.abs(g.astype(int) - (img16 >> 4)).max() <= 3  # 12 significant bits: shift by 4
    c = cv2.imdecode(np.frombuffer(bytes(blobs[1][1][0]), np.uint8), cv2.IMREAD_COLOR)
    assert c[..., 2].mean() > 240 and c[..., 0].mean() < 15  # decoded BGR: red stays red
    (t,) = [t for t, _ in rows(data, ENTITY["image"], "EncodedImage:blob", timeline="capture_time") if t]
    assert t == datetime(2024, 1, 1, 12, 0, 0, tzinfo=UTC)


def test_disabled_recorder_writes_nothing(tmp_path):
    with ScanRecording(None, recording_name="off") as rec:
        assert not rec.enabled and rec.stream is None
        rec.log_camera(K, W, H, R, T, "mm")
        assert rec.log_frame(0, frame(0)) is False
        rec.log_edges(0, [edge(0)])
        rec.log_shadow_plane(0, shadow_quad(0))
        rec.log_reference_plane("p", PLANE)
        rec.log_lamp([0, 0, 1])
        rec.log_sun(0, [0, 0, 1], [0, 0, 0], 1.0)
        rec.log_points(XYZ, RGB, SIGMA)
        rec.log_mesh(MESH_V, MESH_F, None)
        rec.log_maps(SHADOW_TIME, DEPTH, SIGMA_MAP)
        rec.log_warning("w")
        rec.log_metrics(METRICS)
    rec.close()
    assert list(tmp_path.iterdir()) == []


def test_spawn_viewer_without_display_records_to_file_only(tmp_path):
    path = tmp_path / "v.rrd"
    with ScanRecording(path, recording_name="v", spawn_viewer=True) as rec:
        assert not rec.viewer_spawned and rec.enabled
        rec.log_lamp([0, 0, 1])
    assert rrd_verify(path).returncode == 0
    rec2 = ScanRecording(None, recording_name="v", spawn_viewer=True)
    assert not rec2.enabled and not rec2.viewer_spawned
    rec2.close()


def test_exception_in_context_leaves_no_rrd(tmp_path):
    path = tmp_path / "scan.rrd"
    with pytest.raises(RuntimeError, match="pipeline failed"):
        with ScanRecording(path, recording_name="boom") as rec:
            rec.log_frame(0, frame(0))
            rec.log_points(XYZ, RGB, SIGMA)
            raise RuntimeError("pipeline failed")
    assert list(tmp_path.iterdir()) == []


def test_exception_keeps_previous_recording(tmp_path):
    path = tmp_path / "scan.rrd"
    write_scan(path)
    assert rrd_verify(path).returncode == 0
    before = path.read_bytes()
    with pytest.raises(KeyboardInterrupt):
        with ScanRecording(path, recording_name="again") as rec:
            rec.log_points(XYZ[:10], RGB[:10], None)
            raise KeyboardInterrupt
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["scan.rrd"]


def test_rrd_appears_only_on_close(tmp_path):
    path = tmp_path / "late.rrd"
    rec = ScanRecording(path, recording_name="late")
    rec.log_points(XYZ, RGB, SIGMA)
    assert not path.exists()
    rec.close()
    assert path.exists()
    rec.close()  # idempotent
    rec.log_points(XYZ, RGB, SIGMA)  # no-op after close
    assert [p.name for p in tmp_path.iterdir()] == ["late.rrd"]
    assert rrd_verify(path).returncode == 0


def test_abandoned_recorder_removes_its_temp_file(tmp_path):
    rec = ScanRecording(tmp_path / "gone.rrd", recording_name="gone")
    rec.log_lamp([0, 0, 1])
    rec.abort()
    assert list(tmp_path.iterdir()) == []


def test_parameter_validation(tmp_path):
    for kwargs in ({"frame_stride": 0}, {"image_scale": 0.0}, {"image_scale": 1.5}, {"jpeg_quality": 0}):
        with pytest.raises(ValueError):
            ScanRecording(tmp_path / "x.rrd", recording_name="x", **kwargs)
    assert list(tmp_path.iterdir()) == []


def test_abandoned_recorder_is_cleaned_up_by_the_garbage_collector(tmp_path):
    import gc

    rec = ScanRecording(tmp_path / "gc.rrd", recording_name="gc")
    rec.log_lamp([0, 0, 1])
    del rec
    gc.collect()
    assert list(tmp_path.iterdir()) == []


def test_calibrate_run_poses_per_view_and_corners(tmp_path):
    path = tmp_path / "calibrate.rrd"
    corners = np.array([[10.0, 10.0], [20.0, 10.0], [10.0, 20.0]])
    with ScanRecording(path, recording_name="calibrate camera", frame_stride=1) as rec:
        for i in range(3):
            rec.log_camera(K, W, H, R, T + [i, 0, 0], "mm", index=i)
            rec.log_frame(i, frame(i))
            rec.log_image_points(i, corners + i)
        rec.log_metrics({"reprojection_rms_px": 0.21})
    assert rrd_verify(path).returncode == 0
    data = load(path)
    poses = rows(data, ENTITY["camera"], "GnomonCamera:t")
    assert [t for t, _ in poses] == [0, 1, 2] and np.allclose(poses[2][1], T + [2, 0, 0])
    pts = rows(data, "world/camera/image/corners", "Points2D:positions")
    assert [t for t, _ in pts] == [0, 1, 2]
    assert np.allclose(display_to_pixels(np.array(pts[1][1]), [0.5, 0.5]), corners + 1, atol=1e-4)


@pytest.mark.slow  # renders, records or tracks: seconds (the fast loop stays under a minute)
def test_command_line_options(tmp_path):
    import argparse

    from gnomon.errors import GnomonError
    from gnomon.recording.recorder import add_recording_arguments, recording_from_args

    parser = argparse.ArgumentParser()
    add_recording_arguments(parser)
    args = parser.parse_args([])
    with recording_from_args(args, tmp_path, recording_name="s") as rec:
        assert rec.path == tmp_path / "scan.rrd" and rec.frame_stride == 10
    assert rrd_verify(tmp_path / "scan.rrd").returncode == 0
    args = parser.parse_args(["--rrd", str(tmp_path / "other.rrd"), "--frame-stride", "3"])
    with recording_from_args(args, tmp_path, recording_name="s") as rec:
        assert rec.frame_stride == 3
    assert rrd_verify(tmp_path / "other.rrd").returncode == 0
    with recording_from_args(parser.parse_args(["--no-rrd"]), tmp_path / "x", recording_name="s") as rec:
        assert not rec.enabled
    with recording_from_args(parser.parse_args(["--no-rrd", "--view"]), tmp_path / "x", recording_name="s") as rec:
        assert not rec.enabled and not rec.viewer_spawned  # no display in tests
    assert not (tmp_path / "x").exists()
    with pytest.raises(SystemExit):  # argparse: not allowed together
        parser.parse_args(["--no-rrd", "--rrd", "a.rrd"])
    for argv in (["--frame-stride", "0"], ["--rrd", str(tmp_path)]):
        with pytest.raises(GnomonError):
            recording_from_args(parser.parse_args(argv), tmp_path, recording_name="s")


def test_world_is_z_up_and_depth_sits_under_the_camera(scan):
    import rerun as rr

    _, _, data = scan
    vc = one(data, "world", "ViewCoordinates:xyz")
    assert list(vc[0]) == list(rr.ViewCoordinates.RIGHT_HAND_Z_UP.as_arrow_array().to_pylist()[0])
    fmt = one(data, ENTITY["camera_depth"], "DepthImage:format")[0]
    # stored at the pinhole's (downscaled) resolution, in world units
    res = one(data, ENTITY["camera"], "Pinhole:resolution")[0]
    assert (fmt["width"], fmt["height"]) == tuple(int(round(x)) for x in res)
    assert one(data, ENTITY["camera_depth"], "DepthImage:meter") == [1.0]
    buf = np.frombuffer(bytes(one(data, ENTITY["camera_depth"], "DepthImage:buffer")[0]), np.float32)
    assert np.nanmax(buf) == 400.0 and np.isnan(buf).any()


def test_coverage_is_a_segmentation_image_with_named_classes(scan):
    from gnomon.outputs.images import COVERAGE_CLASSES

    _, _, data = scan
    fmt = one(data, ENTITY["coverage"], "SegmentationImage:format")[0]
    buf = np.frombuffer(bytes(one(data, ENTITY["coverage"], "SegmentationImage:buffer")[0]), np.uint8)
    assert np.array_equal(buf.reshape(fmt["height"], fmt["width"]), COVERAGE)
    ctx = one(data, ENTITY["coverage"], "AnnotationContext:context")[0]
    labels = {c["class_id"]: c["class_description"]["info"]["label"] for c in ctx}
    assert labels == {k: name for k, (name, _) in COVERAGE_CLASSES.items()}


def test_recording_worker_keeps_order_and_reports_a_failure_with_no_file(tmp_path) -> None:
    """The scan's recording thread (pipeline.RecordingWorker): calls run in order on one thread; a
    failing call is re-raised by finish in the caller's thread, later calls are skipped, and the
    unfinished file is removed (nothing half-written)."""
    import threading

    from gnomon.recording.recorder import ScanRecording
    from gnomon.recording.worker import RecordingWorker

    seen: list[tuple[int, str]] = []
    worker = RecordingWorker(lambda: ScanRecording(tmp_path / "ok.rrd", recording_name="ok"))
    for i in range(5):
        worker.submit(lambda rec, i=i: seen.append((i, threading.current_thread().name)))
    worker.submit(lambda rec: rec.log_frame(0, np.zeros((8, 8), np.uint8)))
    worker.submit(lambda rec: rec.log_frame(1, None))  # not stored (stride 10): its time only
    worker.finish()
    assert [i for i, _ in seen] == list(range(5)) and {n for _, n in seen} == {"gnomon-recording"}
    assert (tmp_path / "ok.rrd").stat().st_size > 0

    after: list[int] = []

    def fail(rec) -> None:
        raise OSError(28, "No space left on device", str(tmp_path / "bad.rrd"))

    worker = RecordingWorker(lambda: ScanRecording(tmp_path / "bad.rrd", recording_name="bad"))
    worker.submit(fail)
    worker.submit(lambda rec: after.append(1))
    with pytest.raises(OSError, match="No space left"):
        worker.finish()
    assert after == [] and not (tmp_path / "bad.rrd").exists()
    assert list(tmp_path.iterdir()) == [tmp_path / "ok.rrd"]  # no temporary file left behind
