"""Webcam auto-exposure indoors: `[scan] normalize_illumination` undoes it.

The desk capture is re-encoded with a slow ±25 % exposure drift (applied to
linear irradiance, as a camera's gain is). Each pixel's threshold assumes the
lit and shadowed levels stay put, so without normalisation the shadow times
shift with the drift; with it, the scan is as good as without any drift.
"""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest

from conftest import copy_capture
from gnomon.runs.accuracy import depth_accuracy
from gnomon.runs.scan import ScanOptions, run_scan
from gnomon.util import toml_io


@pytest.mark.slow
def test_normalisation_undoes_exposure_drift(desk_lamp_full, tmp_path) -> None:
    tmp_path = copy_capture(desk_lamp_full, tmp_path / "capture")  # its frames are re-encoded
    frames = sorted((tmp_path / "frames").glob("*.jpg"))
    for i, f in enumerate(frames):
        gain = 1.0 + 0.25 * np.sin(2 * np.pi * 1.5 * i / len(frames))
        linear = (cv2.imread(str(f), cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255) ** 2.2 * gain
        dn = np.rint(255 * np.clip(linear, 0, 1) ** (1 / 2.2)).astype(np.uint8)
        cv2.imwrite(str(f), dn, [cv2.IMWRITE_JPEG_QUALITY, 95])
    truth = np.load(tmp_path / "ground_truth.npz")
    acc = {}
    for normalise in (False, True):
        log = tomllib.loads((tmp_path / "field_log.toml").read_text())
        log["scan"]["normalize_illumination"] = normalise
        toml_io.dump(log, tmp_path / f"log_{normalise}.toml")
        result = run_scan(tmp_path / f"log_{normalise}.toml", tmp_path / f"scan_{normalise}",
                          ScanOptions(progress=False, rrd=False))
        acc[normalise] = depth_accuracy(result.depth, truth["depth"], truth["swept"], 650.0)
    print({k: (a.rms, a.coverage) for k, a in acc.items()})
    assert acc[True].rms_pct <= 0.1 and acc[True].coverage >= 0.95
    # Each pixel's threshold is set from its own shadow dip's lit level (one dip
    # per pixel), so a drift slower than the shadow's passage costs the
    # unnormalised scan little (measured: RMS 0.20 vs 0.18 mm); normalising must
    # still do at least as well.
    assert acc[True].rms <= acc[False].rms


def _day_frames(clouds: dict[int, float], n: int = 120, seed: int = 0):
    """8-bit sRGB-ish frames of a day: direct sun rising from dawn and falling into dusk (×30 over the
    day), a constant ambient, a sky (a quarter of the image) that brightens under a cloud, a shadow
    band sweeping the image, noise. ``clouds``: frame → the direct sun's factor (0–1)."""
    rng = np.random.default_rng(seed)
    h, w = 60, 80
    albedo = rng.uniform(0.2, 0.9, (h, w))
    ambient = 0.03
    for k in range(n):
        phase = np.sin(np.pi * (k + 2) / (n + 3))
        direct = 0.5 * phase**3 * clouds.get(k, 1.0)
        light = albedo * (ambient + direct)
        band = (np.arange(w) // 3) == (k % (w // 3))
        light[:, band] = albedo[:, band] * ambient  # the moving shadow
        light[: h // 4] = 0.4 + 0.3 * (1.0 - clouds.get(k, 1.0))  # sky: brighter under a cloud
        dn = 255 * np.clip(light, 0, 1) ** (1 / 2.2) + rng.normal(0, 1.5, light.shape)
        yield np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def test_normaliser_skips_clouds_not_dawn_or_dusk() -> None:
    from gnomon.capture.tracking import IlluminationNormalizer, decoding_lut

    # clouds: one at mid-morning, one at noon, one just before dusk (the light falls fast
    # meanwhile: after it the level is far below the one before)
    clouds = {30: 0.9, 31: 0.5, 32: 0.3, 33: 0.6, 34: 0.95,
              60: 0.7, 61: 0.4, 62: 0.7,
              100: 0.8, 101: 0.4, 102: 0.3, 103: 0.5, 104: 0.85}
    norm = IlluminationNormalizer(decoding_lut(2.2, np.uint8))
    for frame in _day_frames(clouds):
        norm.gain(frame)
    deep = {k for k, c in clouds.items() if c <= 0.7}
    # every frame the cloud darkened by 30 % or more is skipped, and no clear frame (dawn's and
    # dusk's fast changes, the frames after the last cloud) is
    assert deep <= set(norm.skipped) <= set(clouds), (sorted(norm.skipped), sorted(deep))
    # the gains follow the day: several-fold up to noon and down again by dusk (at dawn only the
    # sky is above GAIN_FLOOR, so the first steps are the sky's)
    gains = norm.accepted_gains
    assert max(gains) / gains[0] > 3 and max(gains) / gains[-1] > 3


def test_normaliser_takes_a_lasting_darkening_as_a_new_level() -> None:
    from gnomon.capture.tracking import IlluminationNormalizer, decoding_lut

    rng = np.random.default_rng(1)
    scene = rng.uniform(0.1, 0.8, (40, 50))
    norm = IlluminationNormalizer(decoding_lut(1.0, np.uint8), max_run=8)
    for k in range(40):
        level = 1.0 if k < 10 else 0.6  # the exposure stepped down for good at frame 10
        frame = np.clip(np.rint(255 * scene * level + rng.normal(0, 1.0, scene.shape)), 0, 255)
        norm.gain(frame.astype(np.uint8))
    # the step is refused for max_run frames at most, then the new level is accepted
    assert norm.skipped == list(range(10, 18))
    assert norm.accepted_gains[-1] == pytest.approx(0.6, rel=0.02)


def _cloudy_sweep(clouds: dict[int, float], seed: int = 3):
    """Frames (uint8, gamma 2.2) of a shadow band sweeping one column per frame over two surfaces
    with different shares of sky light (left 15 %, right 40 %) and a strip already in a shadow
    (sky only), under a cloud that dims the direct sun by ``1 − clouds[k]`` and brightens the sky by
    30 % of that; and the band's true time per column."""
    rng = np.random.default_rng(seed)
    h, w, n = 48, 96, 96
    albedo = rng.uniform(0.5, 0.8, (h, w))
    sky_share = np.where(np.arange(w) < w // 2, 0.15, 0.40)[None, :].repeat(h, 0)
    direct0 = 0.7 * (1 - sky_share)
    sky0 = 0.7 * sky_share
    shaded = np.zeros((h, w), bool)
    shaded[:8] = True  # under an overhang: sky light only
    frames = []
    for k in range(n):
        dip = 1.0 - clouds.get(k, 1.0)
        lit = np.where(shaded, 0.0, 1.0 - dip)
        band = np.abs(np.arange(w) - (k - 0.3)) < 1.5  # the moving shadow, 3 columns wide
        lit[:, band] = 0.0
        light = albedo * (sky0 * (1 + 0.3 * dip) + direct0 * lit)
        dn = 255 * np.clip(light, 0, 1) ** (1 / 2.2) + rng.normal(0, 1.5, light.shape)
        frames.append(np.clip(np.rint(dn), 0, 255).astype(np.uint8))
    return frames, shaded


def test_cloud_frames_are_levelled_pixel_by_pixel() -> None:
    """A shadow passing under a cloud is found at its time on both surfaces (one global gain per
    frame could level only one of them), and the strip already in a shadow, which brightens under
    the cloud, shows no dip."""
    from gnomon.capture.tracking import ShadowTracker, TrackerSettings

    clouds = {40: 0.8, 41: 0.55, 42: 0.35, 43: 0.3, 44: 0.4, 45: 0.6, 46: 0.85}
    frames, shaded = _cloudy_sweep(clouds)
    tracker = ShadowTracker(TrackerSettings(gamma=2.2, min_contrast=None, normalize_illumination=True),
                            frames[0].shape, np.dtype(np.uint8))
    for k, f in enumerate(frames):
        tracker.update(f, k)
    tracker.flush()
    assert tracker.refused == []  # the cloud's frames were levelled and fed, none skipped
    assert tracker.fed == list(range(len(frames)))
    times = tracker.finish(1.5)
    centre = (times.enter + times.leave) / 2
    cols = np.arange(frames[0].shape[1])
    truth = np.broadcast_to(cols + 0.0, centre.shape)
    lit = ~shaded
    # columns the band crossed under the cloud (frames 41-45: 20-70 % of the direct sun gone)
    under = lit & np.isin(cols, range(41, 46))[None, :]
    # Under the cloud the levels bring the lit samples back to their clear level, not the shadowed
    # ones (sky only, brighter under the cloud): the dip is shallower there and its mid-level
    # crossings shift, on the surface with more sky light by up to 0.85 frame at the cloud's
    # deepest (70 % of the direct sun gone); measured median 0.29 frame.
    error = np.abs(centre - truth)[under]
    assert (times.valid[under] & (error <= 1.0)).mean() > 0.98, error
    assert np.median(error) < 0.4, np.median(error)
    # and the clear columns as before, to a tenth of a frame
    clear = lit & ~np.isin(cols, range(38, 49))[None, :] & (cols >= 2)[None, :] & (cols <= 93)[None, :]
    assert (times.valid & (np.abs(centre - truth) <= 0.1))[clear].mean() > 0.98
    # the strip under the overhang (sky only) brightens under the cloud: nothing like a dip there
    assert not (times.valid & shaded).any()


def test_levelled_cloud_frames_in_a_tile_and_at_the_end() -> None:
    """A tile's levels come from the whole frame (its times equal the same pixels' in an untiled
    pass), and the frames of a dip the capture ends in are skipped and counted."""
    from gnomon.capture.tracking import ShadowTracker, TrackerSettings

    clouds = {40: 0.8, 41: 0.55, 42: 0.35, 43: 0.3, 44: 0.4, 45: 0.6, 46: 0.85, 93: 0.5, 94: 0.4, 95: 0.4}
    frames, _ = _cloudy_sweep(clouds)
    settings = TrackerSettings(gamma=2.2, min_contrast=None, normalize_illumination=True)
    crop = (slice(5, 30), slice(30, 70))
    whole = ShadowTracker(settings, frames[0].shape, np.dtype(np.uint8))
    tile = ShadowTracker(settings, frames[0].shape, np.dtype(np.uint8), crop)
    for k, f in enumerate(frames):
        whole.update(f, k)
        tile.update(f, k)
    for t in (whole, tile):
        t.flush()
        # the first cloud's deep frames levelled (its shallow flanks may pass with their gain), the
        # last cloud's, which the capture ends in, refused
        assert set(range(41, 45)) <= set(t.levelled) <= set(range(40, 47)), t.levelled
        assert t.refused == [93, 94, 95], t.refused
        assert t.fed == [k for k in range(len(frames)) if k not in (93, 94, 95)]
    a, b = whole.finish(1.5), tile.finish(1.5)
    np.testing.assert_array_equal(a.enter[crop], b.enter)
    np.testing.assert_array_equal(a.leave[crop], b.leave)
