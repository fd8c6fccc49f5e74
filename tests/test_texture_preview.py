"""Colours from lit frames (not frame 0) and the preview picture."""

from __future__ import annotations

import cv2
import numpy as np

from gnomon.capture.texture import LitColour, sample_indices
from gnomon.outputs.images import COVERAGE_CLASSES, coverage_map, preview_image, write_preview


def test_colour_is_the_median_of_the_frames_a_pixel_is_lit_in() -> None:
    h, w, n = 20, 40, 50
    albedo = np.random.default_rng(1).integers(60, 250, (h, w, 3)).astype(np.uint8)
    # a shadow band sweeps left to right, one column per frame: column c is in shadow in frames c..c+4
    start = np.broadcast_to(np.arange(w, dtype=np.float64)[None, :], (h, w))
    end = start + 4
    picks = sample_indices(np.arange(n), 5)
    assert list(picks) == [0, 12, 24, 37, 49]
    lit = LitColour(picks)
    for k in range(n):
        img = albedo.copy()
        shadow = (np.arange(w) >= k - 4) & (np.arange(w) <= k)
        img[:, shadow] //= 5
        lit.add(k, img)
    rgb = lit.finish(start, end)
    np.testing.assert_array_equal(rgb, albedo)
    # a pixel shadowed in most kept frames: the plain median would be dark, the lit one is not
    lit2 = LitColour(np.array([10, 11, 12]))
    for k in (10, 11, 12):
        img = albedo.copy()
        img[:, 10:13] //= 5  # columns 10..12 dark in all three
        img[:, 20] //= 5 if k != 12 else 1  # column 20 dark in frames 10 and 11 only
        lit2.add(k, img)
    s0 = np.full((h, w), np.nan)
    s0[:, 20] = 9.0
    e0 = np.full((h, w), np.nan)
    e0[:, 20] = 11.0
    out = lit2.finish(s0, e0, margin=0.5)
    np.testing.assert_array_equal(out[:, 20], albedo[:, 20])  # only frame 12 is lit
    np.testing.assert_array_equal(out[:, 11], albedo[:, 11] // 5)  # never lit: all frames


def test_kernel_medians_equal_the_numpy_definition() -> None:
    """finish's kernel medians are the numpy definition's: random frames, lit or shadowed at random
    (some pixels in no kept frame), odd and even counts of lit samples."""
    rng = np.random.default_rng(5)
    h, w = 31, 47
    for kept in (2, 5, 6):
        picks = np.arange(kept) * 7
        colour = LitColour(picks)
        for k in picks:
            colour.add(int(k), rng.integers(0, 256, (h, w, 3)).astype(np.uint8))
        start = rng.uniform(-5, 7 * kept, (h, w))
        end = start + rng.uniform(0, 20, (h, w))
        start[rng.random((h, w)) < 0.1] = np.nan
        end[rng.random((h, w)) < 0.1] = np.nan
        start[0, :5] = -100.0  # shadowed in every kept frame
        end[0, :5] = 1000.0
        fast = colour.finish(start, end)
        slow = colour.finish(start, end, kernel=False)
        assert fast.dtype == np.uint8 and fast.shape == (h, w, 3)
        np.testing.assert_array_equal(fast, slow)


def test_grey_medians_once_per_pixel_equal_the_numpy_definition() -> None:
    """Grey frames (8 and 16 bit): the kernel's one median per pixel, repeated, is the definition's median of
    the three equal channels."""
    rng = np.random.default_rng(8)
    h, w = 29, 41
    for dtype, top in ((np.uint8, 256), (np.uint16, 65536)):
        for kept in (3, 4):
            picks = np.arange(kept) * 5
            colour = LitColour(picks)
            for k in picks:
                colour.add(int(k), rng.integers(0, top, (h, w)).astype(dtype))
            start = rng.uniform(-5, 5 * kept, (h, w))
            end = start + rng.uniform(0, 12, (h, w))
            start[rng.random((h, w)) < 0.1] = np.nan
            fast = colour.finish(start, end)
            slow = colour.finish(start, end, kernel=False)
            assert fast.dtype == np.uint8 and fast.shape == (h, w, 3)
            np.testing.assert_array_equal(fast, slow)
            assert len(np.unique(fast)) > 20  # the medians vary: not one value everywhere


def test_grey_and_16_bit_frames_and_no_shadow_times() -> None:
    lit = LitColour(np.array([0, 2]))
    lit.add(0, np.full((2, 3), 1000 << 4, np.uint16))
    lit.add(1, np.zeros((2, 3), np.uint16))  # not kept
    lit.add(2, np.full((2, 3), 3000 << 4, np.uint16))
    rgb = lit.finish(np.full((2, 3), np.nan), np.full((2, 3), np.nan))
    assert rgb.shape == (2, 3, 3)
    assert np.all(rgb == ((1000 << 4 >> 8) + (3000 << 4 >> 8) + 1) // 2)


def test_preview_has_four_captioned_panels(tmp_path) -> None:
    h, w = 60, 80
    rgb = np.full((h, w, 3), 128, np.uint8)
    depth = np.full((h, w), np.nan, np.float32)
    depth[10:50, 10:70] = np.linspace(600, 700, 60)[None, :]
    sigma = np.where(np.isfinite(depth), 0.2, np.nan).astype(np.float32)
    contrast = np.zeros((h, w), bool)
    contrast[5:55] = True
    cov = coverage_map(contrast, np.isfinite(depth))
    assert set(np.unique(cov)) == {0, 1, 2}
    img = preview_image(rgb, depth, sigma, cov, units="mm")
    assert img.shape[1] == 4 * w and img.shape[0] > h
    # the coverage panel shows the class colours
    assert tuple(img[30, 3 * w + 40]) == COVERAGE_CLASSES[1][1]
    assert tuple(img[2, 3 * w + 40]) == COVERAGE_CLASSES[0][1]
    # no depth → black in the depth panel; valid depth is coloured
    assert tuple(img[2, w + 2]) == (0, 0, 0) and img[30, w + 40].sum() > 0
    write_preview(tmp_path / "preview.png", rgb, depth, sigma, cov, units="mm")
    back = cv2.imread(str(tmp_path / "preview.png"))[:, :, ::-1]
    np.testing.assert_array_equal(back, img)


def test_scan_colours_of_a_colour_capture_come_from_its_lit_frames(tmp_path) -> None:
    """A colour capture: the reader hands the kept frames over in colour, so a pixel in the
    stick's shadow in frame 0 takes its colour from the frames it is lit in, not frame 0's."""
    import cv2

    from conftest import write_tiny_capture
    from gnomon.runs.scan import ScanOptions, run_scan

    log = write_tiny_capture(tmp_path / "capture")
    frames = sorted((tmp_path / "capture" / "frames").glob("*.png"))
    u = np.arange(48)
    for i, path in enumerate(frames):  # the band starts inside the view: columns 3–13 dark in frame 0
        centre = 8 + (48 + 4) * i / (len(frames) - 1)
        lit = np.clip((np.abs(u - centre) - 5.0) / 6.0, 0, 1)
        grey = np.tile(40 + 160 * lit, (36, 1))
        bgr = np.stack([0.5 * grey, 0.75 * grey, grey], axis=2)  # a reddish desk
        cv2.imwrite(str(path), np.round(bgr).astype(np.uint8))
    result = run_scan(log, tmp_path / "scan", ScanOptions(rrd=False, progress=False))
    rgb = result.surface.rgb.astype(float)
    dark_in_frame_0 = rgb[:, 6:11]
    # lit level 200 DN (red), 150 (green), 100 (blue): ±3 DN of JPEG-free rounding and the band's edge
    assert np.allclose(dark_in_frame_0[..., 0], 200, atol=3)
    assert np.allclose(dark_in_frame_0[..., 1], 150, atol=3)
    assert np.allclose(dark_in_frame_0[..., 2], 100, atol=3)


def test_coverage_map_says_why_a_pixel_has_no_point() -> None:
    """Each refused pixel gets its reason; a kept point is a point whatever else is set, and the
    reasons that need a shadow time (edges disagree, no neighbour) only where the shadow was seen."""
    from gnomon.outputs.images import AMBIGUOUS, EDGES_DISAGREE, NO_DEPTH, NO_NEIGHBOUR, NO_SHADOW, POINT

    h, w = 4, 6
    seen = np.zeros((h, w), bool)
    seen[:, :4] = True
    valid = np.zeros((h, w), bool)
    valid[0, :4] = True
    ambiguous = np.zeros((h, w), bool)
    ambiguous[:, 4] = True  # never seen as one dip
    ambiguous[0, 0] = True  # a point: the flag from another pass does not override it
    conflict = np.zeros((h, w), bool)
    conflict[1, :] = True
    unsupported = np.zeros((h, w), bool)
    unsupported[1:3, :] = True  # row 1 also disagrees: the edges' disagreement is the first reason
    cov = coverage_map(seen, valid, ambiguous=ambiguous, conflict=conflict, unsupported=unsupported)
    assert (cov[0, :4] == POINT).all()
    assert (cov[1, :4] == EDGES_DISAGREE).all() and (cov[2, :4] == NO_NEIGHBOUR).all()
    assert (cov[3, :4] == NO_DEPTH).all()
    assert (cov[:, 4] == AMBIGUOUS).all() and (cov[:, 5] == NO_SHADOW).all()
    assert set(COVERAGE_CLASSES) >= {AMBIGUOUS, EDGES_DISAGREE, NO_NEIGHBOUR}
