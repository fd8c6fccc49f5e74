"""Frame registration (gnomon.capture.registration) on frames rendered exactly at known motions.

The frames are an analytic texture (a sum of sinusoids, 8–40 px wavelengths) evaluated at each pixel's
point of the scene, so a frame moved by ``m`` (or turned) is exact, independent of the code under test;
a dark band (a shadow) sweeps over it and the light changes. The bar is the registration's tolerance,
``MOTION_TOLERANCE_PX`` (0.05 px): the motion per frame within it of the truth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnomon.capture.frames import Frame, FrameSource
from gnomon.capture.registration import (
    MOTION_TOLERANCE_PX,
    FrameRegistrar,
    border_band,
    shift_image,
)
from gnomon.capture.tracking import TrackerSettings, track_source
from gnomon.errors import FieldLogError, FrameError

H, W = 240, 320
_rng = np.random.default_rng(5)
WAVES = [(_rng.uniform(0, 2 * np.pi), 2 * np.pi / _rng.uniform(8, 40), _rng.uniform(0, 2 * np.pi),
          _rng.uniform(0.3, 1.0)) for _ in range(12)]


def texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    v = np.zeros_like(x)
    for angle, k, phase, amplitude in WAVES:
        v += amplitude * np.sin(k * (x * math.cos(angle) + y * math.sin(angle)) + phase)
    return 120.0 + 12.0 * v


def render(motion=(0.0, 0.0), *, turn_px: float = 0.0, gain: float = 1.0, band: float | None = None,
           noise: float = 1.5, seed: int = 0, shape=(H, W)) -> np.ndarray:
    """The frame (uint8) of a camera moved by ``motion`` (a scene point of pixel p is at p + motion) and
    turned about the image centre by ``turn_px`` at the corners; ``band``: a shadow (35 % of the light
    over 8 px, with 5 px penumbrae) centred on scene column ``band``."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    theta = turn_px / math.hypot(cx, cy)
    c, s = math.cos(theta), math.sin(theta)
    xs = c * (x - cx) + s * (y - cy) + cx - motion[0]
    ys = -s * (x - cx) + c * (y - cy) + cy - motion[1]
    v = texture(xs, ys) * gain
    if band is not None:
        v = v * (0.35 + 0.65 * np.clip((np.abs(xs - band) - 4.0) / 5.0, 0.0, 1.0))
    v += np.random.default_rng(seed).normal(0.0, noise, v.shape)
    return np.clip(np.rint(v), 0, 255).astype(np.uint8)


def register_all(frames: list[np.ndarray]):
    reg = FrameRegistrar(frames[0].shape, len(frames))
    out = [reg.register(Frame(i, f, None, f"frame_{i:02d}.png")) for i, f in enumerate(frames)]
    return reg.result("synthetic"), out


def test_the_motion_is_measured_through_a_shadow_and_a_change_of_light():
    """A slow drift, then a 1 px knock, while a shadow sweeps and the light changes by ±15 %."""
    n = 16
    motion = np.array([(0.06 * k, -0.01 * k - 0.002 * k * k) for k in range(n)])
    motion[10:] += (0.6, 0.8)
    frames = [render(motion[k], gain=1.0 + 0.15 * math.sin(k), band=-10.0 + 22.0 * k, seed=k) for k in range(n)]
    result, out = register_all(frames)
    error = np.hypot(*(result.motion_px - motion).T)
    assert result.reference_frame == 0 and not result.unregistered
    assert error.max() <= MOTION_TOLERANCE_PX, error
    assert (result.sigma_px[1:] < MOTION_TOLERANCE_PX).all()
    moved = np.hypot(*result.motion_px.T) >= MOTION_TOLERANCE_PX
    np.testing.assert_array_equal(result.compensated, moved)
    assert out[0].grey is frames[0] and all(out[k].grey is not frames[k] for k in np.flatnonzero(moved))
    # the frames on the reference grid: the knocked frame 12 moved back onto frame 0 (away from the band)
    back, still = out[12].grey.astype(float), render((0.0, 0.0), gain=1.0 + 0.15 * math.sin(12), noise=0.0)
    inner = (slice(8, 120), slice(8, 140))                              # the band is at x ≈ 254 by then
    assert np.sqrt(np.mean((back[inner] - still[inner]) ** 2)) < 2.0      # noise 1.5 DN, Keys' cubic
    assert result.report()["frames_compensated"] == int(moved.sum())
    assert any("the camera moved: up to" in w for w in result.warnings())


def test_a_still_camera_passes_its_frames_as_read():
    frames = [render(gain=1.0 + 0.1 * k, band=20.0 * k, seed=k) for k in range(6)]
    result, out = register_all(frames)
    assert all(o.grey is f for o, f in zip(out, frames, strict=True))
    assert not result.compensated.any() and not result.border.any()
    assert np.hypot(*result.motion_px.T).max() < MOTION_TOLERANCE_PX
    assert not result.warnings()


def test_a_large_jump_is_found_and_a_larger_one_refused():
    result, _ = register_all([render(seed=1), render((6.3, -3.1), seed=2)])
    assert np.hypot(*(result.motion_px[1] - (6.3, -3.1))) <= MOTION_TOLERANCE_PX
    with pytest.raises(FrameError, match=r"frame 1 \(frame_01.png\): the camera moved by 20.5 px since frame 0"):
        register_all([render(seed=1), render((20.3, -3.1), seed=2)])


def test_a_turned_camera_is_measured_and_refused_beyond_half_a_pixel():
    """What a translation leaves of a turn by 0.3 px at the corners is 0.3 px; a 1 px turn is refused."""
    result, _ = register_all([render(seed=1), render((0.4, 0.2), turn_px=0.3, seed=2)])
    assert result.non_translation_px[1] == pytest.approx(0.3, abs=MOTION_TOLERANCE_PX)
    assert any("not a translation alone (up to 0.3" in w for w in result.warnings())
    with pytest.raises(FrameError, match="turned or zoomed"):
        register_all([render(seed=1), render((0.4, 0.2), turn_px=1.0, seed=2)])


def test_shift_image_moves_back_by_whole_pixels_exactly():
    frame = render(noise=0.0)
    np.testing.assert_array_equal(shift_image(frame, (2.0, -1.0))[2:-2, 2:-3], frame[1:-3, 4:-1])
    assert shift_image(frame, (0.0, 0.0)) is not frame and np.array_equal(shift_image(frame, (0.0, 0.0)), frame)


def test_the_border_band_is_what_the_moved_frames_do_not_see():
    band = border_band((10, 12), np.array([[0.3, -1.2], [2.4, 0.0]]))
    # x from 0 to +2.4: 1 column on the left, 3 + 2 on the right; y from −1.2 to 0: 2 + 1 rows on top, 2 below
    assert band[:, :1].all() and band[:, -5:].all() and band[:3].all() and band[-2:].all()
    assert not band[3:-2, 1:-5].any()


def write_frames(folder, frames) -> FrameSource:
    import cv2

    folder.mkdir()
    paths = []
    for i, f in enumerate(frames):
        paths.append(folder / f"frame_{i:03d}.png")
        cv2.imwrite(str(paths[-1]), f)
    return FrameSource(tuple(paths))


def test_tracking_a_drifting_capture_gives_the_still_capture_s_shadow_times(tmp_path):
    """A shadow band sweeping a textured scene, 32 frames: tracked with registration, the drifting
    camera's shadow times are the still camera's (within the times' own noise between the two
    renderings); without it, they are off where the texture moved under the pixels."""
    n, shape = 32, (120, 160)
    motion = np.array([(0.06 * k, 0.0012 * k * k) for k in range(n)])
    motion[20:] += (0.6, 0.8)
    band = [-15.0 + 6.0 * k for k in range(n)]  # 6 px a frame
    still = write_frames(tmp_path / "still", [render(band=band[k], seed=k, shape=shape) for k in range(n)])
    moved = write_frames(tmp_path / "moved", [render(motion[k], band=band[k], seed=k, shape=shape) for k in range(n)])
    settings = TrackerSettings(gamma=1.0, min_contrast=20.0, register=True)
    reference = track_source(still, settings, shape)
    registered = track_source(moved, settings, shape)
    plain = track_source(moved, TrackerSettings(gamma=1.0, min_contrast=20.0), shape)
    assert reference.registration is not None and not reference.registration.compensated.any()
    reg = registered.registration
    assert reg is not None and np.hypot(*(reg.motion_px - motion).T).max() <= MOTION_TOLERANCE_PX
    assert reg.border.any() and not np.isfinite(registered.times.enter[reg.border]).any()
    both = reference.times.valid & registered.times.valid & plain.times.valid
    assert both.sum() > 0.7 * both.size
    off_registered = np.abs(registered.times.enter - reference.times.enter)[both]
    off_plain = np.abs(plain.times.enter - reference.times.enter)[both]
    # The band moves 6 px a frame: 0.05 px of motion error is 0.01 frame. Two still renderings with other
    # noise differ by 0.02 frame (median) and 0.11 (99th percentile); the motion moved the times by up to
    # 2.9 px / 6 px a frame ≈ 0.5 frame.
    assert np.median(off_registered) < 0.03 and np.percentile(off_registered, 99) < 0.15
    assert np.percentile(off_plain, 99) > 0.4


def test_the_field_log_key(tmp_path):
    from conftest import write_tiny_capture
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import tracker_settings

    lamp = load_field_log(write_tiny_capture(tmp_path / "a"))
    assert lamp.capture.register == "auto" and not tracker_settings(lamp).register  # a lamp's sweep: off
    on = load_field_log(write_tiny_capture(tmp_path / "b", extra={"capture": {"register": "on"}}))
    assert tracker_settings(on).register
    with pytest.raises(FieldLogError, match=r"\[capture\] register: expected one of 'auto', 'on', 'off'"):
        load_field_log(write_tiny_capture(tmp_path / "c", extra={"capture": {"register": "yes"}}))


def test_the_reference_is_the_first_frame_lit_like_the_capture_and_dim_frames_keep_the_last_motion(tmp_path):
    """Dawn (a fifth of the day's light) before the day: the reference is the first day frame; a dusk frame
    after a knock is not measured and keeps the last measured motion."""
    from gnomon.capture.registration import reference_frame

    gains = [0.2, 0.2, 1.0, 1.0, 1.0, 1.0, 0.25]
    motion = [(0.0, 0.0)] * 4 + [(0.7, 0.5)] * 3
    source = write_frames(tmp_path / "day", [render(motion[k], gain=g, seed=k) for k, g in enumerate(gains)])
    reference = reference_frame(source)
    assert reference is not None and reference.index == 2
    registrar = FrameRegistrar((H, W), len(gains))
    registrar.set_reference(reference)
    for frame in source:
        registrar.register(frame)
    result = registrar.result(source.name)
    assert result.reference_frame == 2 and result.dim == [0, 1, 6]
    assert np.hypot(*(result.motion_px[5] - (0.7, 0.5))) <= MOTION_TOLERANCE_PX
    assert result.compensated[6] and not np.isfinite(result.motion_px[6]).any()   # moved as frame 5
    assert not result.compensated[:2].any()                                        # before any: as read
