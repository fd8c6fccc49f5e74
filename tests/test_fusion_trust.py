"""Points whose σ the scan's depth-jump test cannot vouch for are flagged (gnomon.reconstruct.fusion.beyond_trust)."""

from __future__ import annotations

import numpy as np
from scipy.special import erfc

from gnomon.reconstruct.fusion import TRUST_SIGMAS, beyond_trust, trust_limit


def _pairs_torn_apart(depth: np.ndarray, jump: float) -> float:
    """The share of horizontal neighbour pairs farther apart than the depth jump (``jump·Z``)."""
    a, b = depth[:, :-1], depth[:, 1:]
    return float(np.mean(np.abs(a - b) > jump * 0.5 * (a + b)))


def test_the_limit_keeps_a_surface_together_and_the_flagged_points_fall_apart() -> None:
    """A flat surface 1000 mm away, max_depth_jump 2 %: half its points measured with σ at 0.9 of the limit,
    half with three times it. None of the first is flagged and their neighbours essentially never differ by a jump
    (5.6 σ of a pair's difference: 2e-8 of the pairs); the second are all flagged, and as many of their
    neighbour pairs as the Gaussian predicts (erfc(5 / 3 / √2) ≈ 9.6 %) would be torn apart by the scan's
    own jump test."""
    jump, z0 = 0.02, 1000.0
    limit = float(trust_limit(np.array(z0), jump))
    assert limit == np.float64(jump * z0 / (TRUST_SIGMAS * np.sqrt(2.0)))  # 2.83 mm
    rng = np.random.default_rng(11)
    h, w = 400, 500
    sigma = np.full((h, w), 0.9 * limit)  # the limit scales with the measured Z: a margin of 35 σ
    sigma[:, w // 2:] = 3.0 * limit
    depth = z0 + sigma * rng.standard_normal((h, w))
    flagged = beyond_trust(depth.astype(np.float32), sigma.astype(np.float32), jump)
    assert not flagged[:, : w // 2].any() and flagged[:, w // 2:].all()
    within_torn = _pairs_torn_apart(depth[:, : w // 2], jump)
    beyond_torn = _pairs_torn_apart(depth[:, w // 2:], jump)
    expected = float(erfc(TRUST_SIGMAS / 3.0 / np.sqrt(2.0)))
    n = h * (w // 2 - 1)
    assert within_torn == 0.0  # expected 2e-8 · 1e5 pairs
    assert abs(beyond_torn - expected) <= 4 * np.sqrt(expected * (1 - expected) / n)


def test_points_without_a_finite_sigma_or_depth_are_not_judged() -> None:
    depth = np.array([[1000.0, np.nan, 1000.0, -1000.0]], dtype=np.float32)
    sigma = np.array([[np.nan, 100.0, 1.0, 100.0]], dtype=np.float32)
    # a depth behind the camera is judged by |Z| as well
    assert beyond_trust(depth, sigma, 0.02).tolist() == [[False, False, False, True]]


def test_mean_ignoring_nan_is_the_nansum_over_the_finite_count() -> None:
    from gnomon.reconstruct.fused import mean_ignoring_nan

    rng = np.random.default_rng(4)
    for dtype, k in ((np.float32, 2), (np.float32, 1), (np.float32, 3), (np.float64, 2)):
        maps = [(rng.random((30, 40)) * 300).astype(dtype) for _ in range(k)]
        for m in maps:
            m[rng.random(m.shape) < 0.3] = np.nan
        maps[0][0, :4] = [np.inf, -0.0, 1e-45, np.nan]
        maps[-1][0, :4] = [5.0, -0.0, 1e-45, np.nan]
        # the definition: the stack's nansum (NaN as 0, ±inf kept) over the finite values' count, in float64
        stack = np.stack(maps)
        n = np.isfinite(stack).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            expected = np.where(n > 0, np.nansum(stack, axis=0) / np.maximum(n, 1), np.nan).astype(np.float32)
        got = mean_ignoring_nan(maps)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, expected)
        assert np.array_equal(np.signbit(got), np.signbit(expected))
        assert np.isnan(got).sum() == (n == 0).sum() > 0
