"""End to end on the synthetic desk scene, against the simulator's ground truth.

The bar (issue 2): depth RMS ≤ 0.1 % of the camera distance over
the swept pixels and coverage ≥ 95 % of them, with realistic nuisance (noise
σ ≈ 1.5 DN, blur, gamma, lens distortion, JPEG quality 90). The scene is the
default one (800×600, 240 frames, ~20 s to render and scan), with another seed.
At half the size the same per-pixel time noise maps to twice the depth error
(each pixel sees twice the desk), so a smaller scene would test a harder case
than the one the bar is set for.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from gnomon.runs.accuracy import depth_accuracy


@pytest.fixture(scope="module")
def desk_scan(desk_lamp_full_scan):
    """The full desk_lamp capture (seed 3) and its scan, shared with the other tests (conftest)."""
    return desk_lamp_full_scan


@pytest.mark.slow
def test_accuracy_and_coverage(desk_scan) -> None:
    root, result, truth = desk_scan
    dist = float(truth["camera_distance_mm"])
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], dist)
    print(acc.table("desk_lamp 800x600x240"))
    assert acc.swept_pixels > 0.5 * truth["depth"].size
    assert acc.rms_pct <= 0.1
    assert acc.coverage >= 0.95
    # no systematic bias beyond a tenth of the budget
    assert abs(acc.mean) <= 0.1 * 0.001 * dist + 3 * acc.rms / np.sqrt(acc.measured_pixels)


@pytest.mark.slow
def test_outputs_agree_with_each_other(desk_scan) -> None:
    root, result, truth = desk_scan
    out = root / "scan"
    depth = np.load(out / "depth.npy")
    np.testing.assert_array_equal(np.isfinite(depth), result.valid)
    report = json.loads((out / "report.json").read_text())
    assert report["units"] == "mm"
    assert report["coverage"]["points"] == int(result.valid.sum())
    assert len(report["inputs"]["frames_sha256"]) == 64
    # world points land on the true surface points of their pixels
    dist = float(truth["camera_distance_mm"])
    v, u = np.nonzero(result.valid)
    err = np.linalg.norm(result.points_world - truth["points_world"][v, u], axis=1)
    swept = truth["swept"][v, u]
    assert np.sqrt(np.mean(err[swept] ** 2)) <= 0.001 * dist
    # and among all points a user gets (mixed pixels at occlusions included),
    # gross errors (> 1 % of the distance) are rare
    assert np.mean(err > 0.01 * dist) <= 0.001


@pytest.mark.slow
def test_shadow_planes_match_the_true_ones(desk_scan) -> None:
    """The measured planes (camera frame) against the simulator's world planes."""
    root, result, truth = desk_scan
    R, t = truth["R"], truth["t"]
    true_world = truth["shadow_planes_enter"]
    n_cam = true_world[:, :3] @ R.T
    d_cam = true_world[:, 3] + n_cam @ t
    ok = np.isfinite(result.planes[:, 0])
    assert ok.sum() >= 0.7 * len(ok)
    dots = np.sum(result.planes[ok, :3] * n_cam[ok], axis=1)
    angle_deg = np.degrees(np.arccos(np.clip(np.abs(dots), -1, 1)))
    assert np.median(angle_deg) < 0.05
    # and their offsets from the camera agree to a fraction of a millimetre
    offset_error = np.abs(np.sign(dots) * result.planes[ok, 3] - d_cam[ok])
    assert np.median(offset_error) < 0.0005 * float(truth["camera_distance_mm"])


@pytest.mark.slow
def test_edges_disagree_as_their_sigma_says(desk_scan) -> None:
    # The two edges are independent measurements of one depth: where both were
    # fused, their difference over its predicted σ must have an RMS near 1
    # (σ from the unquantised image noise; 0.8–1.3 leaves room for the model's
    # approximations, while a quantised σI gave 2.4–6).
    _, result, _ = desk_scan
    dis = result.report["edges"]["disagreement"]
    print(dis, result.report["noise"])
    assert dis["pixels"] > 100_000
    assert 0.8 <= dis["rms_in_sigmas"] <= 1.3
    # conflicts are outliers, counted apart, and rare
    assert dis["not_fused"] <= 0.001 * dis["pixels"]
