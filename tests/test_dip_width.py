"""Slow sweeps: shadows that stay on a pixel longer than the tracker's dip width.

A pixel's dip is found within the tracker's width ``W`` (``TrackerSettings.max_width``); a shadow that
stays longer is cut in two events and the pixel is left out as ambiguous. A slow sweep with a wide stick
does that (a public phone capture stays 33–53 frames on its pixels against 32), so a scan measures how
long its pixels stayed in shadow (:func:`gnomon.capture.tracking.dwell`) and tracks again wider when many reach
the width (``[scan] max_dip_frames = "auto"``, the default), or warns when the field log fixed it.

The frames: a dark band with linear soft edges sweeping at constant speed, so every pixel's true enter
and leave times are known in closed form.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from conftest import write_tiny_capture
from gnomon.capture.tracking import LONG_DWELL, Dwell, dwell, track
from gnomon.cli import main
from gnomon.util import toml_io

# The band: dark core ±HALF px, linear 6 px edges, lit 200 DN, dark 40 DN (the tiny capture's levels),
# moving SPEED px per frame; its mid-level (the threshold, gamma 1) is HALF + 3 px from its centre.
HALF, EDGE, SPEED, WIDTH, FRAMES = 12.0, 6.0, 0.5, 40, 170
DWELL = 2 * (HALF + EDGE / 2) / SPEED  # 60 frames in shadow at every pixel


def band_frames(noise_dn: float = 1.0) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The frames (8 rows × WIDTH uint8, Gaussian noise ``noise_dn``, seeded) and each column's true enter
    and leave times (frames)."""
    rng = np.random.default_rng(3)
    u = np.arange(WIDTH, dtype=np.float64)
    start = -(HALF + EDGE + 2)
    frames = []
    for i in range(FRAMES):
        lit = np.clip((np.abs(u - (start + SPEED * i)) - HALF) / EDGE, 0.0, 1.0)
        image = np.tile(40 + 160 * lit, (8, 1)) + rng.normal(0.0, noise_dn, (8, WIDTH))
        frames.append(np.clip(np.round(image), 0, 255).astype(np.uint8))
    enter = (u - (HALF + EDGE / 2) - start) / SPEED
    leave = (u + (HALF + EDGE / 2) - start) / SPEED
    return frames, enter, leave


def test_dips_longer_than_the_width_are_cut_and_found_again_wider() -> None:
    frames, enter, leave = band_frames()
    enter, leave = np.broadcast_to(enter, (8, WIDTH)), np.broadcast_to(leave, (8, WIDTH))
    narrow = track(frames, min_contrast=20, gamma=1.0, max_width=32)
    d = dwell(narrow, 32)
    # Every pixel stays 60 frames in shadow: the 32-frame pass is at its limit ...
    assert d.at_limit and d.long_share > 0.9
    assert d.wider() == 96  # max(2 × 32, 1.5 × 60 = 90) up to a multiple of 16
    # ... and its times are those of a dip cut short: its lit level read on the edge, off by frames.
    cut = narrow.valid & (np.abs(narrow.enter - enter) > 0.5)
    assert cut.mean() > 0.1 and np.nanmax(np.abs(narrow.enter - enter)) > 1.5

    wide = track(frames, min_contrast=20, gamma=1.0, max_width=d.wider())
    dw = dwell(wide, 96)
    assert not dw.at_limit and dw.wider() is None
    assert wide.valid.all()
    # σ_t ≈ σ_I / slope = 1 DN / (160 DN / 12 frames) = 0.075 frame; 640 crossings stay within 4σ + rounding.
    assert np.max(np.abs(wide.enter - enter)) < 0.35 and np.max(np.abs(wide.leave - leave)) < 0.35
    assert dw.p99 == pytest.approx(DWELL, abs=0.35)


def test_the_widening_rule() -> None:
    assert Dwell(32, 1000, 40.0, 0.5).wider() == 64  # doubled at least
    assert Dwell(32, 1000, 51.0, 0.97).wider() == 80  # 1.5 × the 99th percentile, a multiple of 16
    assert Dwell(64, 1000, 120.0, 0.5).wider() == 128  # never beyond the kernel's widest
    assert Dwell(128, 1000, 120.0, 0.5).wider() is None
    assert Dwell(32, 1000, 20.0, 0.01).wider() is None  # 1 % near the limit: left as it is
    assert not Dwell(32, 0, float("nan"), 0.0).at_limit
    assert LONG_DWELL * 32 == 24


def _slow_sweep(folder: Path, **scan) -> Path:
    # 48 × 36 px, the band 24 px dark + 2 × 6 px edges moving 0.5 px/frame: 60 frames in shadow.
    log = write_tiny_capture(folder, n_frames=int((48 + 2 * 19) / 0.5) + 1, band_half_width=HALF, noise_dn=1.0)
    data = tomllib.loads(log.read_text())
    data["scan"].update(scan)
    toml_io.dump(data, log)
    return log


def _scan(log: Path, out: Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """The scan's report, and its depth and predicted depth σ over the columns the band crossed whole."""
    assert main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"]) == 0
    inner = (slice(None), slice(2, -2))
    return (json.loads((out / "report.json").read_text()), np.load(out / "depth.npy")[inner],
            np.load(out / "sigma.npy")[inner])


def test_a_slow_sweep_is_tracked_again_wider(tmp_path: Path) -> None:
    report, depth, sigma = _scan(_slow_sweep(tmp_path / "auto"), tmp_path / "auto_scan")
    assert report["settings"]["max_dip_frames"] == 96 and report["settings"]["max_dip_frames_from"] == "auto"
    assert any("tracked again with dips of up to 96 frames" in w for w in report["warnings"])
    assert np.isfinite(depth).all()
    # The desk is 500 mm under the camera, which looks straight down: every point within 5 of its own σ
    # (1 DN of noise; 1584 points, none expected beyond 5σ).
    assert np.all(np.abs(depth - 500.0) <= 5 * sigma)


def test_a_width_the_field_log_fixes_is_kept_and_its_limit_named(tmp_path: Path) -> None:
    report, depth, _ = _scan(_slow_sweep(tmp_path / "fixed", max_dip_frames=32), tmp_path / "fixed_scan")
    assert report["settings"]["max_dip_frames"] == 32 and report["settings"]["max_dip_frames_from"] == "field log"
    assert any("longer shadows are cut in two" in w and "set [scan] max_dip_frames = 96" in w
               for w in report["warnings"])
    # Cut dips: a fifth of the pixels lost (ambiguous, or their edges' depths disagree).
    assert np.isfinite(depth).mean() < 0.9


def test_who_sets_the_width(tmp_path: Path) -> None:
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import dip_width_policy

    assert dip_width_policy(load_field_log(write_tiny_capture(tmp_path / "a"))) == "auto"
    fixed = write_tiny_capture(tmp_path / "b", extra={"scan": {"max_dip_frames": 48}})
    assert dip_width_policy(load_field_log(fixed)) == "field log"
    assert load_field_log(fixed).scan.max_dip_frames == 48
    # under a changing light the width tells the shadow from a cloud: not widened, not checked
    sunlike = write_tiny_capture(tmp_path / "c", extra={"scan": {"normalize_illumination": True}})
    assert dip_width_policy(load_field_log(sunlike)) == "sun"
