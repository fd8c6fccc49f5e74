"""Bad input: one line naming the problem, exit code 2, no outputs left behind."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import write_tiny_capture
from gnomon.cli import main
from gnomon.util import toml_io


def run_scan(log: Path, out: Path, capsys) -> tuple[int, str]:
    code = main(["scan", str(log), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip()
    return code, err


def assert_clean_failure(code: int, err: str, out: Path, *needles: str) -> None:
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("gnomon: error: ")
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert not out.exists()
    leftovers = [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]
    assert leftovers == []


def edit_log(path: Path, edit) -> None:
    data = tomllib.loads(path.read_text())
    edit(data)
    toml_io.dump(data, path)


@pytest.mark.slow
def test_tiny_capture_scans(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    out = tmp_path / "out"
    code = main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"])
    assert code == 0, capsys.readouterr().err
    for name in ("points.ply", "mesh.ply", "depth.npy", "shadow_time.npy", "report.json"):
        assert (out / name).is_file()
    depth = np.load(out / "depth.npy")
    # The tiny capture is a flat desk 500 mm below the camera.
    finite = depth[np.isfinite(depth)]
    assert finite.size > 0.5 * depth.size
    np.testing.assert_allclose(np.median(finite), 500.0, rtol=0.01)


@pytest.mark.slow
def test_missing_frames_folder(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    edit_log(log, lambda d: d["capture"].update(frames="nowhere/*.png"))
    out = tmp_path / "out"
    assert_clean_failure(*run_scan(log, out, capsys), out, "frames folder", "nowhere")


@pytest.mark.slow
def test_unreadable_image(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    (tmp_path / "cap" / "frames" / "frame_0005.png").write_bytes(b"not a png at all")
    out = tmp_path / "out"
    assert_clean_failure(*run_scan(log, out, capsys), out, "frame_0005.png", "cannot be decoded")


@pytest.mark.slow
def test_frames_of_different_sizes(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    cv2.imwrite(str(tmp_path / "cap" / "frames" / "frame_0007.png"), np.zeros((20, 30), np.uint8))
    out = tmp_path / "out"
    assert_clean_failure(*run_scan(log, out, capsys), out, "frame 7", "frame_0007.png", "30x20")


@pytest.mark.slow
def test_frames_not_matching_the_camera(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    edit_log(log, lambda d: d["camera"].update(width=64))
    out = tmp_path / "out"
    assert_clean_failure(*run_scan(log, out, capsys), out, "frame 0", "camera's 64x36")


@pytest.mark.slow
@pytest.mark.parametrize(
    "edit, needle",
    [
        (lambda d: d["light"].pop("position"), "[light] missing required key 'position'"),
        (lambda d: d["scan"].update(treshold=3), "[scan] unknown key 'treshold'"),
        (lambda d: d["light"].update(position=[0.0, 0.0, -50.0]), "below the plane 'desk'"),
    ],
)
def test_field_log_mistakes(tmp_path: Path, capsys, edit, needle: str) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    edit_log(log, edit)
    out = tmp_path / "out"
    assert_clean_failure(*run_scan(log, out, capsys), out, needle, str(log))


@pytest.mark.slow
def test_video_that_ends_early(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    frames = sorted((tmp_path / "cap" / "frames").glob("*.png"))
    video = tmp_path / "cap" / "sweep.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (48, 36), isColor=False)
    assert writer.isOpened()
    for f in frames[:8]:
        writer.write(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE))
    writer.release()
    edit_log(log, lambda d: d["capture"].update(frames="sweep.avi", frame_count=24))
    out = tmp_path / "out"
    assert_clean_failure(*run_scan(log, out, capsys), out, "sweep.avi", "ended after 8 frames, expected 24")


@pytest.mark.slow
def test_console_script_exit_code(tmp_path: Path) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    edit_log(log, lambda d: d["light"].update(kind="torch"))
    proc = subprocess.run([sys.executable, "-m", "gnomon", "scan", str(log), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "[light] kind" in proc.stderr
