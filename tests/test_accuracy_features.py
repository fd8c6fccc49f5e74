"""Bouguet & Perona's noise analysis put to work (issue 6), on the synthetic desk.

* both shadow edges of a wide stick, fused, beat either edge alone;
* the predicted per-pixel σZ matches the observed error, bin by bin;
* two scans (lamp left and right) merged cover more and are no worse.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gnomon.runs.accuracy import depth_accuracy
from gnomon.runs.merge import merge_scans
from gnomon.runs.scan import ScanOptions, run_scan
from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

OPTS = ScanOptions(progress=False, rrd=False)


def scan(root: Path, cfg: DeskLampConfig):
    simulate_desk_lamp(root / "capture", cfg)
    result = run_scan(root / "capture" / "field_log.toml", root / "scan", OPTS)
    return result, dict(np.load(root / "capture" / "ground_truth.npz"))


@pytest.fixture(scope="module")
def left_right(tmp_path_factory):
    root = tmp_path_factory.mktemp("lr")
    # A lower lamp (elevation ≈ 30°) casts object shadows long enough that
    # each scan misses a good part of the scene: what the other fills.
    left = scan(root / "left", DeskLampConfig(seed=11, lamp_height=280.0, pencil_photos=0))
    right = scan(root / "right", DeskLampConfig(seed=12, lamp_side="right", lamp_height=280.0, pencil_photos=0))
    return root, left, right


@pytest.mark.slow
def test_both_edges_of_a_wide_stick_beat_one(tmp_path: Path) -> None:
    result, truth = scan(tmp_path, DeskLampConfig(seed=7, stick_radius=6.0))  # a 12 mm stick
    dist = float(truth["camera_distance_mm"])
    swept = truth["swept"]
    enter, leave = result.edges
    common = swept & np.isfinite(enter.depth) & np.isfinite(leave.depth) & np.isfinite(result.depth)
    rms = {name: depth_accuracy(np.where(common, d, np.nan), truth["depth"], common, dist).rms
           for name, d in (("enter", enter.depth), ("leave", leave.depth), ("fused", result.depth))}
    print(rms, result.report["edges"]["disagreement"])
    assert rms["fused"] <= 0.8 * min(rms["enter"], rms["leave"])
    # the report says how far the two edges disagree, in mm and in σ
    dis = result.report["edges"]["disagreement"]
    assert dis["pixels"] > 0.5 * swept.sum() and 0 < dis["median_abs"] < 0.002 * dist


def sigma_calibration(result, truth) -> list[tuple[float, float, int]]:
    """(predicted σ, observed RMS error, count) per quantile bin of predicted σ, on swept pixels."""
    m = truth["swept"] & np.isfinite(result.depth) & np.isfinite(result.sigma)
    err = (result.depth - truth["depth"])[m]
    sig = result.sigma[m]
    edges = np.quantile(sig, np.linspace(0, 1, 6))
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (sig >= lo) & (sig <= hi)
        rows.append((float(np.sqrt(np.mean(sig[sel] ** 2))), float(np.sqrt(np.mean(err[sel] ** 2))), int(sel.sum())))
    return rows


@pytest.mark.slow
def test_sigma_predicts_the_error_desk(desk_lamp_full_scan) -> None:
    _, result, truth = desk_lamp_full_scan
    rows = sigma_calibration(result, truth)
    print(rows)
    for predicted, observed, n in rows:
        assert n > 1000
        assert predicted / 1.5 <= observed <= predicted * 1.5


@pytest.mark.slow
def test_merge_left_right(left_right) -> None:
    root, (left, truth), (right, truth_r) = left_right
    np.testing.assert_array_equal(truth["depth"], truth_r["depth"])  # one camera, one scene
    surface, report = merge_scans(root / "left" / "scan", root / "right" / "scan", root / "merged",
                                  options=OPTS)
    visible = np.isfinite(truth["depth"])
    dist = float(truth["camera_distance_mm"])
    cov = {k: float((np.isfinite(d) & visible).sum() / visible.sum())
           for k, d in (("left", left.depth), ("right", right.depth), ("merged", surface.depth))}
    # RMS over the pixels that either lamp sweeps (the union of the swept masks)
    swept = truth["swept"] | truth_r["swept"]
    acc = {k: depth_accuracy(d, truth["depth"], swept, dist)
           for k, d in (("left", left.depth), ("right", right.depth), ("merged", surface.depth))}
    print(cov, {k: (a.rms, a.coverage) for k, a in acc.items()})
    better = max(cov["left"], cov["right"])
    assert cov["merged"] >= better + 0.10
    best_rms = min(acc["left"].rms, acc["right"].rms)
    assert acc["merged"].rms <= best_rms
    assert (root / "merged" / "points.ply").is_file() and report["coverage"]["both"] > 0
