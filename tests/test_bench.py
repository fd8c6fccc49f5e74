"""`gnomon bench`: the kernel against the numpy tracker on a small synthetic sweep,
and `--scan` input errors."""

from __future__ import annotations

import pytest

from gnomon import _kernel
from gnomon.cli import main
from gnomon.runs.bench import format_scan_table, format_table, run_bench, run_scan_bench


def test_small_bench_reports_the_simd_path_and_both_trackers():
    r = run_bench(frames=40, numpy_frames=8, width=96, height=24, max_width=8, memory_frames=())
    assert r.simd_path == _kernel.simd_path()
    assert r.kernel.frames == 40 and r.numpy.frames == 8
    assert r.kernel.seconds > 0 and r.numpy.seconds > 0
    text = format_table(r)
    assert f"SIMD path {r.simd_path}" in text and "speed-up" in text


@pytest.mark.slow
def test_scan_bench_names_a_missing_field_log(tmp_path, capsys):
    missing = tmp_path / "nope.toml"
    assert main(["bench", "--scan", str(missing)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.toml" in err[0]


def test_scan_bench_times_decoding_tracking_and_the_scan(tiny_capture, tmp_path):
    """`--scan`: decoding alone, one tracking pass alone (the scan's reader and tracker, nothing after)
    and the whole scan, over the same frames; the table names each (times are the benchmark's, not
    asserted)."""
    r = run_scan_bench(str(tiny_capture), str(tmp_path / "out"), no_rrd_dir=str(tmp_path / "no-rrd"))
    assert (r.width, r.height) == (48, 36)
    assert r.decode.frames == 24
    assert r.track is not None and r.track.frames == 24  # a lamp skips no frame
    assert r.track.seconds > 0 and r.scan_seconds > 0
    assert (tmp_path / "out" / "report.json").is_file()
    text = format_scan_table(r)
    assert "decode alone" in text and "decode+track" in text and "whole scan" in text
    assert f"{r.track.seconds / r.decode.seconds:.2f}x the decode-alone wall time" in text
    # the ratios to the floor and the recording's share are those of the measured times
    assert r.floor_ratio == (r.scan_seconds / r.track.seconds, r.scan_cpu_seconds / r.track.cpu_seconds)
    assert f"{r.floor_ratio[0]:.2f}x the floor's wall time" in text
    assert r.no_rrd_seconds is not None and r.no_rrd_seconds > 0 and r.no_rrd_cpu_seconds is not None
    assert r.recording_share is not None
    assert r.recording_share[0] == pytest.approx(1 - r.no_rrd_seconds / r.scan_seconds)
    assert (tmp_path / "no-rrd" / "report.json").is_file() and not (tmp_path / "no-rrd" / "scan.rrd").exists()
    assert "set-up (field log, camera, marks)" in text and "setup_s" in r.stages  # the set-up's own stage
    assert r.to_dict()["track"]["frames"] == 24
