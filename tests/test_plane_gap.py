"""The scan drops points whose shadow time is far from every measured plane: the fast screen
(pipeline._far_from_planes) against the distance to the nearest plane frame measured directly; and the
lit colours' capture frames (pipeline._capture_frames) against np.interp."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.reconstruct.edges import MAX_PLANE_GAP
from gnomon.reconstruct.edges import far_from_planes as _far_from_planes


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


@pytest.mark.parametrize("skipped", [False, True])
def test_capture_frames_are_the_interpolated_indices(skipped: bool) -> None:
    """pipeline._capture_frames (the lit colours' frame times) is np.interp over the kept frames' capture
    indices bit for bit: with no frame skipped through its identity shortcut, else the interpolation;
    NaN and ±inf give NaN, times beyond the kept frames clamp."""
    from gnomon.capture.colours import capture_frames as _capture_frames

    rng = np.random.default_rng(1)
    n = 50
    used = np.arange(n) if not skipped else np.sort(rng.choice(80, n, replace=False))
    times = rng.uniform(-2.0, n + 1.0, (30, 40)).astype(np.float32)
    times[0, :4] = (np.nan, np.inf, -np.inf, float(n - 1))
    times[1, :] = np.arange(40)  # whole kept frames
    steps = np.arange(n, dtype=np.float64)
    ref = np.where(np.isfinite(times), np.interp(np.nan_to_num(times), steps, used.astype(np.float64)), np.nan)
    out = _capture_frames(times, used)
    assert out.dtype == np.float64
    assert np.array_equal(out.view(np.uint64), ref.view(np.uint64))


def _edge(name: str, have: np.ndarray, times: np.ndarray, depth: np.ndarray):
    from gnomon.reconstruct.edges import EdgeResult

    planes = np.where(have[:, None], np.array([[0.0, 0.0, 1.0, 500.0]]), np.nan)
    return EdgeResult(name, times, [], planes, depth.copy(), depth.copy(), 0, np.ones_like(times))


def test_plane_coverage_taken_on_the_edges_threads_says_what_the_check_says() -> None:
    """The scan takes each edge's plane coverage on its thread (plane_coverage) and says it afterwards in edge
    order (check_plane_coverage with the coverage given): the same warnings, the same points dropped, as the
    check taking them itself; numbers against a direct count (frames of the sweep's 2nd–98th percentile of
    times with a plane; points more than MAX_PLANE_GAP frames from any)."""
    from gnomon.errors import FrameError
    from gnomon.reconstruct.edges import check_plane_coverage, plane_coverage

    rng = np.random.default_rng(3)
    n = 80
    have = np.ones(n, dtype=bool)
    have[30:70] = False  # 40 frames without a plane: half the sweep, a long gap
    times = rng.uniform(0.0, n - 1.0, (30, 40)).astype(np.float32)
    depth = rng.uniform(100.0, 900.0, times.shape).astype(np.float32)
    edges = [_edge("enter", have, times, depth), _edge("leave", np.ones(n, dtype=bool), times, depth)]
    given = [plane_coverage(e) for e in [_edge("enter", have, times, depth), _edge("leave", np.ones(n, bool), times,
                                                                                     depth)]]
    said_given: list[str] = []
    said: list[str] = []
    check_plane_coverage(edges, "log.toml", said)
    again = [_edge("enter", have, times, depth), _edge("leave", np.ones(n, dtype=bool), times, depth)]
    for e, c in zip(again, given, strict=True):  # as the threads leave them: the far points already dropped
        assert c is not None
        e.depth[:] = edges[[x.name for x in edges].index(e.name)].depth
    check_plane_coverage(again, "log.toml", said_given, given)
    assert said == said_given and len(said) == 2
    lo, hi = np.percentile(times[np.isfinite(times)], [2, 98])
    span = np.arange(int(np.floor(lo)), min(int(np.ceil(hi)) + 1, n))
    far = _direct(times, depth, have)
    assert given[0] is not None and given[1] is not None
    assert (given[0].measured, given[0].frames, given[0].dropped) == (int(have[span].sum()), span.size, int(far.sum()))
    assert given[1].dropped == 0 and given[1].share == 1.0
    assert f"{int(far.sum())} points dropped" in said[0] and "rarely crossed" in said[1]
    assert np.array_equal(np.isnan(edges[0].depth), far) and not np.isnan(edges[1].depth).any()
    have[:60] = False  # a fifth of the sweep or less: an error, the same either way
    with pytest.raises(FrameError, match="too few to scan"):
        check_plane_coverage([_edge("enter", have, times, depth)], "log.toml", [])
    with pytest.raises(FrameError, match="too few to scan"):
        check_plane_coverage([_edge("enter", have, times, depth)], "log.toml", [],
                             [plane_coverage(_edge("enter", have, times, depth))])
