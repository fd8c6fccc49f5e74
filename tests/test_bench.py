"""`gnomon bench`: the kernel against the numpy tracker on a small synthetic sweep,
and `--scan` input errors."""

from __future__ import annotations

import pytest

from gnomon import _kernel
from gnomon.bench import format_table, run_bench
from gnomon.cli import main


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
