"""The streaming shadow tracker: accuracy on synthetic edges, kernel vs numpy,
decoding LUTs, and input errors."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon import _kernel
from gnomon.errors import FrameError
from gnomon.tracking import NumpyTracker, ShadowTimes, decoding_lut, track

LIT, SHADOW = 200.0, 40.0


def logistic(z):
    return 0.5 * (1 + np.tanh(0.5 * z))


def edge_profiles(n_pixels: int, n_frames: int, rng, *, scale: float = 1.0):
    """Per-pixel shadow occupancy (1 = in shadow), (n_frames, n_pixels), with a
    logistic enter edge at a random fractional time and a leave edge later.

    The plateaus are long enough (≥ 7 scales each side) for the profile to
    reach its lit and shadow levels, so the mid-level is crossed exactly at
    ``enter`` and ``leave``."""
    enter = rng.uniform(8, 14, n_pixels)
    leave = enter + rng.uniform(14, 20, n_pixels)
    t = np.arange(n_frames, dtype=np.float64)[:, None]
    inside = logistic((t - enter) / scale) * logistic((leave - t) / scale)
    return inside, enter, leave


def to_frames(values: np.ndarray, shape, dtype) -> list[np.ndarray]:
    top = np.iinfo(dtype).max
    q = np.clip(np.round(values), 0, top).astype(dtype)
    return [f.reshape(shape) for f in q]


def run_kernel(frames, *, min_contrast=20.0, lut=None, window=4, block=16):
    h, w = frames[0].shape
    tracker = _kernel.TemporalTracker(h, w, frames[0].dtype.name, window=window, block=block)
    for f in frames:
        tracker.update(f)
    return ShadowTimes.from_kernel(tracker.finish(min_contrast, lut))


def rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


def test_sub_frame_accuracy_on_noisy_edges():
    rng = np.random.default_rng(0)
    shape = (100, 200)
    inside, enter, leave = edge_profiles(shape[0] * shape[1], 48, rng)
    values = LIT - (LIT - SHADOW) * inside + rng.normal(0, 1.0, inside.shape)
    times = run_kernel(to_frames(values, shape, np.uint8))
    assert times.valid.all()
    err_enter = times.enter.ravel() - enter
    err_leave = times.leave.ravel() - leave
    assert np.isfinite(err_enter).all() and np.isfinite(err_leave).all()
    assert np.mean(np.abs(err_enter)) <= 0.05 and np.mean(np.abs(err_leave)) <= 0.05
    assert rms(err_enter) <= 0.05, rms(err_enter)
    assert rms(err_leave) <= 0.05, rms(err_leave)
    # Steepest steps of a unit-scale logistic of 160 DN: about 40 DN per frame.
    assert 30 < np.median(times.enter_slope) < 45
    assert 30 < np.median(times.leave_slope) < 45
    assert np.allclose(times.threshold, 120, atol=3)


def test_ramp_has_the_exact_crossings():
    # Frames 0-9: 200; 180 140 100 60; 10 × 40; 70 110 150 190; 10 × 200.
    profile = [200] * 10 + [180, 140, 100, 60] + [40] * 10 + [70, 110, 150, 190] + [200] * 10
    frames = [np.full((2, 3), v, np.uint8) for v in profile]
    for block in (1, 7, 16):
        times = run_kernel(frames, block=block)
        assert np.all(times.enter == 11.5) and np.all(times.leave == 25.25)
        assert np.all(times.threshold == 120) and np.all(times.contrast == 160)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_kernel_and_numpy_tracker_agree(dtype):
    rng = np.random.default_rng(1)
    top = np.iinfo(dtype).max
    shape = (23, 37)
    inside, _, _ = edge_profiles(shape[0] * shape[1], 41, rng, scale=0.7)
    values = top * (0.8 - 0.6 * inside) + rng.normal(0, top / 150, inside.shape)
    frames = to_frames(values, shape, dtype)
    for lut in (None, decoding_lut(2.2, dtype), decoding_lut("srgb", dtype)):
        for window, block in ((4, 16), (2, 1), (6, 5)):
            h, w = shape
            kernel = _kernel.TemporalTracker(h, w, np.dtype(dtype).name, window=window, block=block)
            reference = NumpyTracker(h, w, np.dtype(dtype).name, window=window)
            for f in frames:
                kernel.update(f)
                reference.update(f)
            assert kernel.frames_seen == reference.frames_seen == len(frames)
            got = kernel.finish(top / 10, lut)
            want = reference.finish(top / 10, lut)
            assert set(got) == set(want)
            for key in got:
                assert got[key].shape == shape and got[key].dtype == want[key].dtype, key
                if key == "valid":
                    assert np.array_equal(got[key], want[key])
                else:
                    np.testing.assert_allclose(got[key], want[key], rtol=0, atol=1e-5, err_msg=key)
                    assert np.array_equal(np.isnan(got[key]), np.isnan(want[key])), key


def test_finish_is_a_preview():
    rng = np.random.default_rng(2)
    shape = (8, 9)
    inside, _, _ = edge_profiles(72, 40, rng)
    frames = to_frames(LIT - (LIT - SHADOW) * inside + rng.normal(0, 1, inside.shape), shape, np.uint8)
    streaming = _kernel.TemporalTracker(*shape, block=7)
    for i, f in enumerate(frames):
        streaming.update(f)
        if i in (3, 17, 30):
            preview = streaming.finish(20.0)
            expect = run_kernel(frames[: i + 1])
            np.testing.assert_array_equal(preview["enter"], expect.enter)
            np.testing.assert_array_equal(preview["leave"], expect.leave)
    final = ShadowTimes.from_kernel(streaming.finish(20.0))
    np.testing.assert_array_equal(final.enter, run_kernel(frames).enter)


def test_gamma_lut_puts_the_crossing_at_mid_irradiance():
    gamma, lit, shadow = 2.2, 0.8, 0.05  # linear irradiance levels
    rng = np.random.default_rng(3)
    shape = (50, 80)
    inside, enter, leave = edge_profiles(shape[0] * shape[1], 48, rng)
    irradiance = lit - (lit - shadow) * inside
    dn = 255 * irradiance ** (1 / gamma) + rng.normal(0, 0.5, inside.shape)
    frames = to_frames(dn, shape, np.uint8)
    lut = decoding_lut(gamma, np.uint8)

    # Decoded: the threshold is the mid-irradiance, crossed at enter / leave.
    decoded = run_kernel(frames, lut=lut)
    assert rms(decoded.enter.ravel() - enter) <= 0.05
    assert rms(decoded.leave.ravel() - leave) <= 0.05
    np.testing.assert_allclose(
        decoded.threshold, (lut[decoded.imax.astype(int)] + lut[decoded.imin.astype(int)]) / 2, rtol=1e-6
    )

    # Thresholding the encoded values instead: the DN mid-level is a lower
    # irradiance E*, reached at occupancy f = (lit − E*) / (lit − shadow) of the
    # logistic, i.e. logit(f) frames after `enter` and before `leave`.
    dn_mid = 255 * (lit ** (1 / gamma) + shadow ** (1 / gamma)) / 2
    f = (lit - (dn_mid / 255) ** gamma) / (lit - shadow)
    offset = np.log(f / (1 - f))
    assert offset > 0.6
    encoded = run_kernel(frames)
    assert abs(np.mean(encoded.enter.ravel() - enter) - offset) < 0.05
    assert abs(np.mean(encoded.leave.ravel() - leave) + offset) < 0.05


def test_low_contrast_pixels_are_invalid():
    frames = [np.full((2, 2), v, np.uint8) for v in (100, 100, 90, 80, 80, 95, 100)]
    times = run_kernel(frames, min_contrast=21)
    assert not times.valid.any()
    assert np.isnan(times.enter).all() and np.isnan(times.leave).all()
    assert np.isnan(times.enter_slope).all()
    np.testing.assert_array_equal(times.contrast, 20)
    times = run_kernel(frames, min_contrast=20)
    assert times.valid.all() and np.isfinite(times.enter).all()


def test_decoding_lut():
    lin = decoding_lut(1.0, np.uint8)
    assert lin.dtype == np.float32 and lin.shape == (256,)
    np.testing.assert_allclose(lin, np.arange(256) / 255, rtol=1e-6)
    g = decoding_lut(2.2, "uint16")
    assert g.shape == (65536,) and g[0] == 0 and g[-1] == 1
    np.testing.assert_allclose(g[32768], (32768 / 65535) ** 2.2, rtol=1e-6)
    s = decoding_lut("srgb", np.uint8)
    assert s[0] == 0 and s[-1] == pytest.approx(1.0)
    assert s[10] == pytest.approx(10 / 255 / 12.92, rel=1e-6)  # linear toe
    assert s[128] == pytest.approx(((128 / 255 + 0.055) / 1.055) ** 2.4, rel=1e-6)
    assert np.all(np.diff(s) > 0)
    for bad in (0, -1.0, float("nan"), "rec709"):
        with pytest.raises(ValueError):
            decoding_lut(bad, np.uint8)
    with pytest.raises(ValueError):
        decoding_lut(2.2, np.float32)


def test_track_feeds_the_kernel_and_reports_progress():
    rng = np.random.default_rng(4)
    shape = (6, 7)
    inside, _, _ = edge_profiles(42, 40, rng)
    frames = to_frames(LIT - (LIT - SHADOW) * inside, shape, np.uint8)
    seen = []
    times = track(iter(frames), min_contrast=20, gamma=2.2, progress=seen.append)
    assert seen == list(range(len(frames)))
    expect = run_kernel(frames, lut=decoding_lut(2.2, np.uint8))
    np.testing.assert_array_equal(times.enter, expect.enter)
    assert times.shape == shape and times.valid.dtype == bool
    with pytest.raises(FrameError, match="frame 3"):
        track(frames[:3] + [frames[3][:, :5]], min_contrast=20, gamma=1.0)
    with pytest.raises(FrameError):
        track([], min_contrast=20, gamma=1.0)
    with pytest.raises(FrameError):
        track([np.zeros((4, 4), np.float32)], min_contrast=20, gamma=1.0)


@pytest.mark.parametrize("make", [_kernel.TemporalTracker, NumpyTracker])
def test_wrong_frames_raise_value_error(make):
    tracker = make(4, 5, "uint8")
    with pytest.raises(ValueError, match="uint8.*uint16"):
        tracker.update(np.zeros((4, 5), np.uint16))
    with pytest.raises(ValueError, match=r"\(4, 5\).*\(5, 4\)"):
        tracker.update(np.zeros((5, 4), np.uint8))
    with pytest.raises(ValueError):
        tracker.update(np.zeros((4, 5, 1), np.uint8))
    assert tracker.frames_seen == 0
    with pytest.raises(ValueError):
        tracker.finish(10.0)  # no frames yet
    tracker.update(np.zeros((4, 5), np.uint8))
    with pytest.raises(ValueError, match="256"):
        tracker.finish(10.0, np.zeros(255, np.float32))
    with pytest.raises(ValueError, match="float32"):
        tracker.finish(10.0, np.zeros(256, np.float64))
    with pytest.raises(ValueError):
        tracker.finish(10.0, np.linspace(1, 0, 256, dtype=np.float32))  # decreasing


def test_kernel_tracker_arguments():
    with pytest.raises(ValueError, match="uint8"):
        _kernel.TemporalTracker(4, 5, "float32")
    with pytest.raises(ValueError, match="window"):
        _kernel.TemporalTracker(4, 5, window=0)
    with pytest.raises(ValueError, match="block"):
        _kernel.TemporalTracker(4, 5, block=0)
    with pytest.raises(ValueError):
        _kernel.TemporalTracker(0, 5)
    t = _kernel.TemporalTracker(4, 5, "uint16", window=3, block=8)
    assert (t.shape, t.dtype, t.window, t.block, t.frames_seen) == ((4, 5), "uint16", 3, 8, 0)
    with pytest.raises(ValueError, match="uint16"):
        t.update(np.zeros((4, 5), np.uint8))
    # Non-contiguous frames are accepted (copied).
    t.update(np.zeros((5, 4), np.uint16).T)
    assert t.frames_seen == 1
    with pytest.raises(ValueError, match="65536"):
        t.finish(1.0, decoding_lut(2.2, np.uint8))
    assert t.finish(1.0, decoding_lut(2.2, np.uint16))["valid"].dtype == bool


_PATH_SCRIPT = """
import sys, numpy as np
from gnomon import _kernel
frames = np.load(sys.argv[1])
t = _kernel.TemporalTracker(*frames.shape[1:], "uint8", window=3, block=5)
for f in frames:
    t.update(f)
r = t.finish(10.0)
np.savez(sys.argv[2], path=_kernel.simd_path(), **{k: np.asarray(v) for k, v in r.items()})
"""


def test_every_simd_path_gives_identical_results(tmp_path):
    """Each instruction set this CPU supports, forced with GNOMON_SIMD in a fresh
    process (the path is chosen once per process), tracks a noisy sweep to the
    same bits as the default path in this process."""
    import os
    import subprocess
    import sys

    paths = _kernel.simd_paths()
    assert _kernel.simd_path() in paths and paths[-1] == "portable"
    rng = np.random.default_rng(5)
    shape = (7, 75)  # a width that is no multiple of any vector's lanes: tails too
    inside, _, _ = edge_profiles(shape[0] * shape[1], 45, rng, scale=0.8)
    frames = np.stack(to_frames(200 - 160 * inside + rng.normal(0, 2, inside.shape), shape, np.uint8))
    np.save(tmp_path / "frames.npy", frames)
    here = run_kernel(list(frames), min_contrast=10.0, window=3, block=5)
    for path in paths:
        out = tmp_path / f"{path}.npz"
        env = {**os.environ, "GNOMON_SIMD": path, "PYTHONPATH": os.pathsep.join(sys.path)}
        subprocess.run([sys.executable, "-c", _PATH_SCRIPT, str(tmp_path / "frames.npy"), str(out)],
                       check=True, env=env)
        got = np.load(out)
        assert str(got["path"]) == path
        for key in ("imax", "imin", "threshold", "enter", "leave", "enter_slope", "leave_slope", "valid"):
            np.testing.assert_array_equal(got[key], getattr(here, key), err_msg=f"{path}: {key}")


def test_version_names_the_simd_path():
    from gnomon.cli import version_text

    text = version_text()
    assert text.startswith("gnomon ") and text.endswith(f"SIMD {_kernel.simd_path()})")
