"""The scan drops points whose shadow time is far from every measured plane: the fast screen
(pipeline._far_from_planes) against the distance to the nearest plane frame measured directly."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.pipeline import MAX_PLANE_GAP, _far_from_planes


def _direct(times: np.ndarray, depth: np.ndarray, have: np.ndarray) -> np.ndarray:
    frames = np.flatnonzero(have).astype(np.float64)
    t = times.astype(np.float64)[..., None]
    with np.errstate(invalid="ignore"):
        gap = np.min(np.abs(t - frames), axis=-1)
        return np.isfinite(depth) & ~(gap <= MAX_PLANE_GAP)


@pytest.mark.parametrize("seed", range(6))
def test_far_from_planes_matches_the_nearest_plane_distance(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 60
    have = rng.random(n) < [0.9, 0.5, 0.2, 0.05, 0.9, 0.3][seed]
    have[rng.integers(n)] = True
    if seed == 4:  # one long gap, and nothing after frame 40
        have[10:25] = False
        have[40:] = False
    times = rng.uniform(-3.0, n + 3.0, (40, 50)).astype(np.float32)
    times[rng.random(times.shape) < 0.05] = np.nan
    # times exactly on integers and on the bound's edges (a plane frame ± MAX_PLANE_GAP)
    f = np.flatnonzero(have)
    times[0, :len(f)] = f[:50] + MAX_PLANE_GAP
    times[1, :len(f)] = f[:50] - MAX_PLANE_GAP
    times[2, :] = rng.integers(-2, n + 2, 50)
    depth = rng.uniform(100.0, 900.0, times.shape).astype(np.float32)
    depth[rng.random(times.shape) < 0.1] = np.nan
    far = _far_from_planes(times, depth, have)
    assert np.array_equal(far, _direct(times, depth, have))
    if seed in (3, 4):
        assert far.any()  # the sparse planes leave far times to find
