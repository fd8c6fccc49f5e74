"""The recording a scan leaves (issue 7): complete, valid, and usable as data."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from gnomon.cli import main
from gnomon.outputs import ply
from gnomon.recording.review import summarize


@pytest.fixture(scope="module")
def scanned(desk_scan):
    return desk_scan


@pytest.mark.slow
def test_rrd_verify_passes(scanned) -> None:
    proc = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(scanned / "scan" / "scan.rrd")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slow
def test_export_gives_points_ply_bit_for_bit(scanned, capsys) -> None:
    out = scanned / "exported.ply"
    assert main(["review", str(scanned / "scan" / "scan.rrd"), "--export", str(out)]) == 0
    capsys.readouterr()
    a, b = ply.read_ply(scanned / "scan" / "points.ply"), ply.read_ply(out)
    assert a["xyz"].dtype == np.float32 and len(a["xyz"]) > 50_000
    assert a["xyz"].tobytes() == b["xyz"].tobytes()
    np.testing.assert_array_equal(a["rgb"], b["rgb"])


@pytest.mark.slow
def test_summary_lists_the_layout(scanned, capsys) -> None:
    s = summarize(scanned / "scan" / "scan.rrd").to_dict()
    entities = set(s["entities"])
    for e in ("world/camera", "world/camera/image", "world/camera/image/edges", "world/points",
              "world/light", "world/shadow_plane", "maps/shadow_time", "maps/depth", "maps/sigma"):
        assert "/" + e in entities, (e, sorted(entities))
    assert "/world/mesh" not in entities  # by default mesh.ply has it (gnomon scan --rrd-full records it)
    assert any(e.startswith("/world/planes/") for e in entities)
    report = json.loads((scanned / "scan" / "report.json").read_text())
    assert s["point_count"] == report["coverage"]["points"]
    assert s["frames_stored"] == 12  # 120 frames, one in 10
    assert main(["review", str(scanned / "scan" / "scan.rrd")]) == 0
    assert "world/points" in capsys.readouterr().out


@pytest.mark.slow
def test_compare_with_itself_is_zero(scanned, capsys) -> None:
    rec = str(scanned / "scan" / "scan.rrd")
    assert main(["review", rec, "--compare", rec, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["compare"]["max"] == 0.0


@pytest.mark.slow
def test_calibration_and_merge_runs_leave_recordings(tmp_path, scanned, capsys) -> None:
    assert main(["simulate", "chessboard", "--out", str(tmp_path / "cb"), "--width", "640", "--height", "480"]) == 0
    assert main(["calibrate", "camera", str(tmp_path / "cb"), "--board", "9x6", "--square", "25",
                 "--out", str(tmp_path / "cam.toml")]) == 0
    capsys.readouterr()
    s = summarize(tmp_path / "cam.rrd").to_dict()
    assert s["frames_stored"] == 12 and "/world/camera/image/board" in s["entities"]
    # a merge of a scan with itself records its fused cloud
    scan = str(scanned / "scan")
    assert main(["merge", scan, scan, "--out", str(tmp_path / "merged")]) == 0
    merged = summarize(tmp_path / "merged" / "merge.rrd").to_dict()
    assert merged["point_count"] > 0.9 * summarize(scanned / "scan" / "scan.rrd").to_dict()["point_count"]
    for rec in (tmp_path / "cam.rrd", tmp_path / "merged" / "merge.rrd"):
        proc = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(rec)],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr


@pytest.mark.slow  # its fixture simulates and scans the desk scene
def test_scan_warnings_are_on_the_frame_timeline(scanned) -> None:
    """The default layout's Warnings view shows the TextLog on the `frame` timeline: every warning of
    the report is there, at frame 0 (the run's start), so it is listed at every frame."""
    from rerun.chunk import RrdReader

    report = json.loads((scanned / "scan" / "report.json").read_text())
    assert report["warnings"]  # this capture is under-sampled: the scan warns
    found = []
    for chunk in RrdReader(scanned / "scan" / "scan.rrd").stream():
        if chunk.entity_path != "/log":
            continue
        batch = chunk.to_record_batch()
        assert "frame" in batch.schema.names
        frames = batch.column("frame").to_pylist()
        texts = batch.column("TextLog:text").to_pylist()
        found += [(f, t[0]) for f, t in zip(frames, texts, strict=True) if t]
    assert sorted(t for _, t in found) == sorted(report["warnings"] + report["notes"])
    assert all(f == 0 for f, _ in found)


@pytest.mark.slow  # its fixture simulates and scans the desk scene
def test_scan_recording_has_coverage_and_depth_under_the_camera(scanned) -> None:
    from rerun.chunk import RrdReader

    from gnomon.outputs.images import COVERAGE_CLASSES

    seen = {}
    for chunk in RrdReader(scanned / "scan" / "scan.rrd").stream():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:
                seen.setdefault(chunk.entity_path, set()).add(name)
    assert "ViewCoordinates:xyz" in seen["/world"]
    assert "DepthImage:buffer" in seen["/world/camera/depth"]
    assert {"SegmentationImage:buffer", "AnnotationContext:context"} <= seen["/maps/coverage"]
    assert len(COVERAGE_CLASSES) == 9


@pytest.mark.slow
def test_the_recording_opens_in_its_own_layout(scanned, tmp_path) -> None:
    """The file carries the designed blueprint as the active one (a viewer opens it in that layout, not in
    its automatic grid): rerun's own reader lists the blueprint's activation command."""
    config = tmp_path / "config" / "rerun"
    config.mkdir(parents=True)
    (config / "analytics.json").write_text('{"analytics_enabled": false}')  # no first-run banner, no network
    env = {"HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "config"), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-m", "rerun", "rrd", "print", "-v", str(scanned / "scan" / "scan.rrd")],
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    commands = [line for line in proc.stdout.splitlines() if line.startswith("BlueprintActivationCommand")]
    assert len(commands) == 1 and "make_active: true" in commands[0] and "make_default: true" in commands[0]


@pytest.mark.slow
def test_warnings_sit_at_their_frames_and_the_metrics_are_a_table(tmp_path) -> None:
    """A sun scan's cloud dips are noted at the frames of the dips; the run's warnings at frame 0; the metrics
    as a table the Metrics view shows."""
    import shutil
    from pathlib import Path

    from rerun.chunk import RrdReader

    shutil.copytree(Path(__file__).resolve().parents[1] / "field_logs" / "facade_sun_small", tmp_path / "cap")
    out = tmp_path / "scan"
    assert main(["scan", str(tmp_path / "cap" / "field_log.toml"), "--out", str(out), "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    levelled = report["inputs"]["levelled_frames"]
    assert len(levelled) >= 3  # the capture's three cloud dips
    runs = [f for i, f in enumerate(levelled) if i == 0 or levelled[i - 1] != f - 1]
    found: dict[str, list[int]] = {}
    summary = []
    for chunk in RrdReader(out / "scan.rrd").stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/log":
            for f, t in zip(batch.column("frame").to_pylist(), batch.column("TextLog:text").to_pylist(), strict=True):
                if t:
                    found.setdefault(t[0], []).append(f)
        elif chunk.entity_path == "/summary":
            summary += [t[0] for t in batch.column("TextDocument:text").to_pylist() if t]
    # the cloud dips are a note (a fact, nothing to do), at their frames; each warning at frame 0
    clouds = [n for n in report["notes"] if "illumination dips" in n]
    assert len(clouds) == 1 and sorted(found[clouds[0]]) == runs[:8]
    assert not any("illumination dips" in w for w in report["warnings"])
    assert all(found[w] == [0] for w in report["warnings"])
    assert summary and f"| coverage/points | {report['coverage']['points']} |" in summary[-1]


@pytest.mark.slow
def test_rrd_full_records_the_mesh_and_full_size_maps(scanned, tmp_path) -> None:
    """--rrd-full: the mesh (mesh.ply's vertices and faces) and the maps at the frames' full size; the default
    recording's maps are at its stored frames' size (half)."""
    from rerun.chunk import RrdReader

    def maps_and_mesh(rrd):
        sizes, mesh = {}, None
        for chunk in RrdReader(rrd).stream():
            batch = chunk.to_record_batch()
            if chunk.entity_path == "/maps/depth" and "DepthImage:format" in batch.schema.names:
                fmt = batch.column("DepthImage:format").to_pylist()[-1][0]
                sizes["depth"] = (fmt["width"], fmt["height"])
            if chunk.entity_path == "/world/mesh" and "Mesh3D:triangle_indices" in batch.schema.names:
                mesh = len(batch.column("Mesh3D:triangle_indices").to_pylist()[-1])
        return sizes, mesh

    assert main(["scan", str(scanned / "capture" / "field_log.toml"), "--out", str(tmp_path / "full"), "--quiet",
                 "--rrd-full"]) == 0
    sizes, faces = maps_and_mesh(tmp_path / "full" / "scan.rrd")
    assert sizes["depth"] == (400, 300)
    assert faces == len(ply.read_ply(tmp_path / "full" / "mesh.ply")["faces"])
    default_sizes, default_mesh = maps_and_mesh(scanned / "scan" / "scan.rrd")
    assert default_sizes["depth"] == (200, 150) and default_mesh is None
