"""Each edge's own threshold: a dip that dims slowly before its sharp enter edge and
brightens slowly after its leave edge (indirect light from surfaces the shadow reaches
first) is timed at its sharp edges, where the dip's overall mid-level is crossed early
on enter and late on leave."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon import _kernel
from gnomon.tracking import EDGE_OUTSIDE_MIN, NumpyTracker, ShadowTimes

FLOOR = 30.0  # DN: the light left in the shadow
DIRECT = 150.0  # DN: the lamp's direct light, cut by the sharp edge
INDIRECT = 50.0  # DN: light scattered from nearby surfaces while they are lit
REMAINING = 10.0  # DN: the scattered light left once those surfaces are in shadow
RAMP = 2.0  # frames: the sharp edge's (linear) ramp, centred on the true time
DIMMING = 10.0  # frames over which the scattered light dims (brightens) ...
LEAD = 4.0  # ... ending this many frames before the enter edge (starting after the leave)
NOISE = 1.0  # DN, Gaussian, before rounding to uint8
N_FRAMES = 60
SHAPE = (40, 50)


def lopsided_dips(rng):
    """(frames, pixels) DN and the true enter/leave times (frames): the direct light's
    half-way points. Sub-frame phases are uniform so that sampling averages out."""
    n = SHAPE[0] * SHAPE[1]
    enter = rng.uniform(18.0, 19.0, n)
    leave = enter + rng.uniform(13.0, 15.0, n)
    t = np.arange(N_FRAMES, dtype=np.float64)[:, None]
    direct = DIRECT * np.maximum(np.clip((enter - t) / RAMP + 0.5, 0, 1), np.clip((t - leave) / RAMP + 0.5, 0, 1))
    dim_in = np.clip((enter - LEAD - t) / DIMMING, 0, 1)  # 1 while the surroundings are lit
    dim_out = np.clip((t - leave - LEAD) / DIMMING, 0, 1)
    scattered = REMAINING + (INDIRECT - REMAINING) * np.maximum(dim_in, dim_out)
    values = FLOOR + scattered + direct + rng.normal(0, NOISE, direct.shape)
    return np.clip(np.round(values), 0, 255).astype(np.uint8), enter, leave


def mid_level_times(values: np.ndarray, threshold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rule without edge thresholds: the fall through the dip's mid-level last before
    its darkest frame and the rise first after it (no LUT: linear = DN)."""
    v = values.astype(np.float64)
    thr = threshold.astype(np.float64)[None, :]
    k_min = np.argmin(v, axis=0)
    frames = np.arange(len(v) - 1)[:, None]
    falls = (v[:-1] >= thr) & (thr > v[1:]) & (frames < k_min)
    rises = (v[:-1] < thr) & (thr <= v[1:]) & (frames >= k_min)
    cols = np.arange(v.shape[1])
    k_e = len(frames) - 1 - np.argmax(falls[::-1], axis=0)
    k_l = np.argmax(rises, axis=0)
    enter = k_e + (v[k_e, cols] - thr[0]) / (v[k_e, cols] - v[k_e + 1, cols])
    leave = k_l + (v[k_l, cols] - thr[0]) / (v[k_l, cols] - v[k_l + 1, cols])
    return enter, leave


@pytest.mark.parametrize("make", [_kernel.TemporalTracker, NumpyTracker])
def test_edges_are_timed_at_their_sharp_step_despite_slow_dimming(make):
    rng = np.random.default_rng(11)
    values, enter_true, leave_true = lopsided_dips(rng)
    tracker = make(*SHAPE, "uint8", window=4, max_width=32)
    for f in values:
        tracker.update(np.ascontiguousarray(f.reshape(SHAPE)))
    times = ShadowTimes.from_kernel(tracker.finish(20.0)) if make is _kernel.TemporalTracker \
        else tracker.finish(20.0)
    assert times.valid.all()
    # the reported threshold stays the dip's mid-level
    np.testing.assert_allclose(times.threshold, (times.imax + times.imin) / 2, rtol=1e-6)

    slope = DIRECT / RAMP  # DN per frame on the sharp ramp
    n_dark = int(leave_true.min() - enter_true.max()) - 1  # samples fully in the dip
    # The dip's darkest sample lies below its level by up to sqrt(2 ln n) sigma, lowering
    # an edge's threshold by half that (enter later, leave earlier); the threshold's and
    # the crossing's own noise (sigma / slope per pixel, a few samples) averages over the
    # pixels: 4 standard errors of the mean. Rounding to DN adds 1/sqrt(12) DN of noise.
    sigma = np.hypot(NOISE, 1 / np.sqrt(12))
    floor_shift = 0.5 * sigma * np.sqrt(2 * np.log(n_dark)) / slope
    tol = floor_shift + 4 * 2 * sigma / slope / np.sqrt(values.shape[1])

    err_enter = times.enter.ravel() - enter_true
    err_leave = times.leave.ravel() - leave_true
    assert abs(np.mean(err_enter)) <= tol, (np.mean(err_enter), tol)
    assert abs(np.mean(err_leave)) <= tol, (np.mean(err_leave), tol)
    # per pixel: within the noise of one crossing (threshold + two samples), 5 sigma
    per_pixel = floor_shift + 5 * 2 * sigma / slope
    assert np.percentile(np.abs(err_enter), 99) <= per_pixel
    assert np.percentile(np.abs(err_leave), 99) <= per_pixel

    # The dip's mid-level is crossed early on enter and late on leave, by the scattered
    # light's excess at the edge over the dip, halved, over the edge's slope.
    old_enter, old_leave = mid_level_times(values, times.threshold.ravel())
    bias = (INDIRECT - REMAINING) / 2 / slope
    assert np.mean(old_enter - enter_true) < -0.5 * bias < -5 * tol
    assert np.mean(old_leave - leave_true) > 0.5 * bias > 5 * tol


def test_an_edge_too_slow_for_the_window_keeps_the_mid_level():
    """A ramp longer than the window reaches (m = 2: the outside sample would be
    max(EDGE_OUTSIDE_MIN, D) frames out, beyond the 4 kept samples): the mid-level crossing."""
    profile = [200] * 12 + [180, 160, 140, 120, 100, 80, 60] + [40] * 12 + [60, 80, 100, 120, 140, 160, 180] \
        + [200] * 12
    frames = [np.full((1, 2), v, np.uint8) for v in profile]
    for make in (_kernel.TemporalTracker, NumpyTracker):
        tracker = make(1, 2, "uint8", window=2, max_width=32)
        for f in frames:
            tracker.update(f)
        times = tracker.finish(20.0)
        # mid-level 120, reached at frame 15 (enter) and 34 (leave); D = 160 / 20 = 8 frames
        assert 160 / 20 > EDGE_OUTSIDE_MIN
        np.testing.assert_array_equal(np.asarray(times.enter), 15.0)
        np.testing.assert_array_equal(np.asarray(times.leave), 34.0)
