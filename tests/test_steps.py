"""The step tracker (gnomon.capture.steps): a shadow that comes once and stays, against series written out here.

Each pixel's series is built from a known transition: lit level L, shadow level S, the disc's occluded
fraction ramping linearly over ``p`` frames centred on ``t0`` (the mid-level is crossed at ``t0`` exactly,
and linear interpolation between two samples of a linear ramp is exact), decoded with gamma 2.2.
"""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.capture.steps import STEP_SPREADS, StepTracker
from gnomon.capture.tracking import ShadowTimes, decoding_lut

LUT = decoding_lut(2.2, np.uint8)
N, W = 120, 32


def series(t0: float, ramp: float, lit: float = 0.7, dark: float = 0.15, entering: bool = True) -> np.ndarray:
    """Linear irradiance per frame: lit, then a linear ramp of ``ramp`` frames centred on ``t0``, then dark."""
    i = np.arange(N, dtype=np.float64)
    f = np.clip((i - t0) / ramp + 0.5, 0.0, 1.0)  # occluded share
    if not entering:
        f = 1.0 - f
    return lit - (lit - dark) * f


def track(columns: list[np.ndarray], noise_dn: float = 0.0, seed: int = 0) -> ShadowTimes:
    """Feed the columns (linear, one pixel each) as 8-bit frames (gamma 2.2, + Gaussian noise in DN)."""
    rng = np.random.default_rng(seed)
    lin = np.stack(columns, axis=1)  # (N, P)
    dn = 255.0 * lin ** (1 / 2.2) + noise_dn * rng.standard_normal(lin.shape)
    frames = np.clip(np.rint(dn), 0, 255).astype(np.uint8)
    tracker = StepTracker((1, lin.shape[1]), LUT, W, 4, 0.6)
    for row in frames:
        tracker.update(row[None, :])
    return ShadowTimes(**tracker.finish(10.0))


def test_step_time_is_the_mid_level_crossing() -> None:
    t0s = [20.3, 47.75, 60.5, 99.1]
    times = track([series(t, 6.0) for t in t0s] + [series(t, 6.0, entering=False) for t in t0s])
    # 8-bit quantisation of a ramp of (lit − dark)/6 per frame: well under 0.1 frame
    np.testing.assert_allclose(times.enter[0, :4], t0s, atol=0.1)
    np.testing.assert_allclose(times.leave[0, 4:], t0s, atol=0.1)
    assert np.isnan(times.leave[0, :4]).all() and np.isnan(times.enter[0, 4:]).all()
    assert times.valid.all()


def test_noise_gives_the_time_within_its_sigma() -> None:
    t0 = 55.4
    cols = [series(t0, 8.0)] * 400
    times = track(cols, noise_dn=1.5, seed=3)
    err = times.enter[0] - t0
    # σ_t = σ_I / slope at the crossing: 1.5 DN carried to linear at the mid-level, over (lit − dark)/8 per frame
    mid = 0.5 * (0.7 + 0.15)
    sigma_lin = 1.5 / 255 * 2.2 * mid ** (1.2 / 2.2)
    sigma_t = np.sqrt(2) * sigma_lin / ((0.7 - 0.15) / 8)  # two samples interpolated
    assert abs(np.mean(err)) < 4 * sigma_t / np.sqrt(len(cols))
    assert np.std(err) < 1.5 * sigma_t


@pytest.mark.parametrize("width", [3, 16, 24])
def test_a_passing_shadow_is_no_step(width: int) -> None:
    """A dip shorter than W (a pole's, a cloud's) scatters its side: its 'step' is less than STEP_SPREADS times it."""
    i = np.arange(N)
    dip = np.where((i >= 50) & (i < 50 + width), 0.15, 0.7)
    times = track([dip])
    assert not times.valid[0, 0]
    assert np.isnan(times.enter[0, 0]) and np.isnan(times.leave[0, 0])
    assert STEP_SPREADS > np.sqrt(2 * (24 / W) / (1 - 24 / W))  # the module's bound for the widest of them


def test_a_cloud_before_the_step_moves_it_by_its_share_of_the_side() -> None:
    """A cloud inside the step's lit side lowers that side's mean, so the mid-level and the crossing: four frames
    at 0.6 of the lit level among W = 32 lower the mean by 4/32 · 0.4 · 0.7 = 0.035 and the threshold by half
    that, which the ramp of (0.7 − 0.15)/6 per frame crosses 0.19 frame later. Not more, and nothing else."""
    col = series(80.2, 6.0)
    col[60:64] *= 0.6  # a cloud dims the light for four frames, 16 frames before the shadow comes
    times = track([col])
    shift = 0.5 * 4 / W * 0.4 * 0.7 / ((0.7 - 0.15) / 6)
    assert times.valid[0, 0] and np.isnan(times.leave[0, 0])
    assert abs(times.enter[0, 0] - (80.2 + shift)) < 0.1


def test_a_long_shadow_gives_both_steps() -> None:
    """In shadow longer than W frames: an entering and a leaving step, each at its own time."""
    col = np.maximum(series(30.4, 5.0), series(85.6, 5.0, entering=False))
    times = track([col])
    assert abs(times.enter[0, 0] - 30.4) < 0.1 and abs(times.leave[0, 0] - 85.6) < 0.1


def test_steps_at_the_ends_need_min_side_frames() -> None:
    times = track([series(3.0, 2.0), series(N - 3.0, 2.0)])
    assert not times.valid.any()


def test_pile_ups_are_a_cloud_s_onset_and_hole() -> None:
    """Steps moved to a cloud's onset pile up in one frame and leave the cloud's frames empty; a row of windows
    makes a pile-up with no hole after it."""
    from gnomon.light.edge import pile_ups

    rng = np.random.default_rng(0)
    t = rng.uniform(0, 120, 60000)  # a steady sweep: 500 steps a frame
    t[(t >= 80) & (t < 86)] = 80.5 + 0.3 * rng.random(int(((t >= 80) & (t < 86)).sum()))  # a cloud at 80–85
    t = np.concatenate([t, 40.2 + 0.5 * rng.random(800)])  # windows' sills: many steps at frame 40, no hole
    spans = pile_ups(t.reshape(1, -1), 120)
    assert spans == [(79, 86)]


def test_common_line_of_a_plane_family() -> None:
    """Planes turning about a known line (a roof edge seen from the camera), their offsets perturbed: the line back."""
    from gnomon.light.edge import common_line

    rng = np.random.default_rng(1)
    p0, e = np.array([3.0, -8.0, 40.0]), np.array([0.8, 0.1, -0.2])
    e /= np.linalg.norm(e)
    u = np.cross(e, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(e, u)
    angle = np.radians(np.linspace(20.0, 31.0, 150))  # the planes turn by 11° about the line
    n = np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v
    planes = np.concatenate([n, (n @ p0 + 0.002 * rng.standard_normal(150))[:, None]], axis=1)
    planes[::15, 3] += 0.5  # ten frames' lines from another shadow
    planes[5] = np.nan
    fit = common_line(planes)
    assert fit is not None and 149 - 13 <= fit.planes <= 149 - 10 and fit.offered == 149
    assert abs(abs(fit.direction @ e) - 1.0) < 1e-6
    off = (fit.point - p0) - ((fit.point - p0) @ e) * e  # the distance between the two lines
    # 2 mm of noise per plane over planes 11° apart at 40 m: the line's place to about 2 mm / sin(11°) / √150
    assert np.linalg.norm(off) < 0.01
    assert abs(fit.turn_deg - 11.0) <= 0.075 and fit.rms < 0.004  # within a plane's step, should an end one be cut
    parallel = planes.copy()
    parallel[:, :3] = n[0]
    assert common_line(parallel[:8]) is None  # too few planes
