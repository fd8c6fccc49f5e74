"""Trustworthy points (issue 10): the pieces that need no simulated scan.

* the image noise σI is measured without quantisation (8-bit frames);
* a truncated frame is an error naming it (the decoder only warns);
* the false-point rate counts points where nothing was swept, or far off.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import write_tiny_capture
from gnomon.capture.noise import _median_of_integers, image_noise_dn
from gnomon.cli import main
from gnomon.runs.accuracy import FALSE_SIGMAS, GROSS_FRACTION, depth_accuracy


def noisy_pair(sigma_dn: float, seed: int, gain: float = 1.0, moved_rows: int = 0):
    """Two u8 frames of one textured scene with independent Gaussian noise σ (DN), quantised."""
    rng = np.random.default_rng(seed)
    scene = rng.uniform(30.0, 220.0, (300, 400))
    a = np.clip(np.rint(scene + sigma_dn * rng.standard_normal(scene.shape)), 0, 255).astype(np.uint8)
    b = np.clip(np.rint(gain * scene + sigma_dn * rng.standard_normal(scene.shape)), 0, 255).astype(np.uint8)
    if moved_rows:
        b[100:100 + moved_rows] = 15  # a shadow arrived there
    return a, b


@pytest.mark.parametrize("sigma_dn", [0.6, 1.0, 1.25, 1.5, 2.0])
def test_noise_is_not_quantised(sigma_dn: float) -> None:
    # The truth a frame's threshold crossing sees: sensor noise plus rounding (1/12 DN²).
    expected = np.sqrt(sigma_dn**2 + 1.0 / 12.0)
    a, b = noisy_pair(sigma_dn, seed=int(10 * sigma_dn), gain=1.02, moved_rows=30)
    got = image_noise_dn(a, b)
    # 120 000 differences: the estimate's own spread is ≈ 0.2 %; the moved rows and
    # the 2 % gain change must not bias it by more than a few per cent.
    assert got == pytest.approx(expected, rel=0.03)


def test_noise_tells_close_levels_apart() -> None:
    # The old MAD estimate gave 1.048 DN for every one of these.
    values = [image_noise_dn(*noisy_pair(s, seed=3)) for s in (0.9, 1.2, 1.5)]
    assert values[0] < values[1] < values[2]
    assert values[2] - values[0] > 0.5


def test_noise_ignores_saturated_pixels() -> None:
    a, b = noisy_pair(1.5, seed=5)
    a[:150] = 255
    b[:150] = 255  # half the image clipped: no noise visible there
    assert image_noise_dn(a, b) == pytest.approx(np.sqrt(1.5**2 + 1 / 12), rel=0.03)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("seed", range(6))
def test_integer_frames_give_exactly_the_float_definition(dtype, seed: int) -> None:
    """uint8/uint16 frames take a faster path (samples selected on the integers, medians from histograms):
    it must give the float32 definition's value to the last bit (the frames here have no clipped sample,
    which only the integer types can tell)."""
    rng = np.random.default_rng(seed)
    top = np.iinfo(dtype).max
    scale = 1.0 if dtype == np.uint8 else 180.0
    scene = rng.uniform(20.0, 230.0, (int(rng.integers(40, 200)), int(rng.integers(40, 200)))) * scale
    sigma = rng.uniform(0.5, 3.0) * scale
    a = np.clip(np.rint(scene + sigma * rng.standard_normal(scene.shape)), 1, top - 1).astype(dtype)
    b = np.clip(np.rint(rng.uniform(0.97, 1.03) * scene + sigma * rng.standard_normal(scene.shape)), 1,
                top - 1).astype(dtype)
    b[: seed * 5] = 3  # a shadow arrived in some rows
    assert image_noise_dn(a, b) == image_noise_dn(a.astype(np.float32), b.astype(np.float32))


def test_the_histogram_median_is_numpys() -> None:
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 10, 11, 1000, 1001):
        for spread in (1, 5, 300, 70000):
            values = rng.integers(-spread, spread + 1, n).astype(np.int32)
            assert _median_of_integers(values) == float(np.median(values))


def _jpeg_capture(folder: Path) -> Path:
    log = write_tiny_capture(folder, extra={"capture": {"frames": "frames/*.jpg"}})
    for png in sorted((folder / "frames").glob("*.png")):
        image = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(png.with_suffix(".jpg")), image, [cv2.IMWRITE_JPEG_QUALITY, 95])
        png.unlink()
    return log


@pytest.mark.slow
def test_truncated_jpeg_is_an_error_naming_the_frame(tmp_path: Path, capsys) -> None:
    log = _jpeg_capture(tmp_path / "capture")
    out = tmp_path / "scan"
    assert main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"]) == 0
    capsys.readouterr()
    victim = tmp_path / "capture" / "frames" / "frame_0009.jpg"
    raw = victim.read_bytes()
    victim.write_bytes(raw[: int(0.8 * len(raw))])
    # cv2.imread still decodes it (libjpeg only warns "premature end"): the check must come from us.
    assert cv2.imread(str(victim), cv2.IMREAD_UNCHANGED) is not None
    out2 = tmp_path / "scan2"
    code = main(["scan", str(log), "--out", str(out2), "--quiet", "--no-rrd"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "frame_0009.jpg" in err[0] and "truncated" in err[0], err
    assert not out2.exists()


@pytest.mark.slow
def test_truncated_png_is_an_error_naming_the_frame(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "capture")
    victim = tmp_path / "capture" / "frames" / "frame_0003.png"
    raw = victim.read_bytes()
    victim.write_bytes(raw[:-12])  # the IEND chunk is gone
    code = main(["scan", str(log), "--out", str(tmp_path / "scan"), "--quiet", "--no-rrd"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "frame_0003.png" in err[0], err


def test_false_point_rate_counts_what_was_not_swept() -> None:
    dist = 1000.0
    truth = np.full((10, 10), 1000.0)
    truth[0, :] = np.nan  # no surface (sky)
    swept = np.zeros((10, 10), dtype=bool)
    swept[2:, :] = True  # rows 0-1 never swept
    depth = truth + 0.5
    depth[0, :3] = 50.0  # 3 points in the sky
    depth[1, :] = 1000.2  # 10 points on a surface the shadow never crossed, right or not
    depth[5, 0] = 1000.0 + 2 * GROSS_FRACTION * dist  # > 1 % and > 5σ: false
    depth[5, 1] = 1000.0 + 2 * GROSS_FRACTION * dist  # > 1 % but σ is large: not false, still gross
    depth[6, 0] = np.nan  # not measured
    sigma = np.full((10, 10), 1.0)
    sigma[5, 1] = 2 * GROSS_FRACTION * dist / FALSE_SIGMAS * 1.5
    acc = depth_accuracy(depth, truth, swept, dist, sigma=sigma)
    assert acc.output_points == 3 + 10 + 80 - 1
    assert acc.false_points == 3 + 10 + 1
    assert acc.false_point_rate == pytest.approx(14 / 92)
    assert acc.gross_points == 3 + 2
    assert acc.coverage == pytest.approx(79 / 80)
    # errors over swept pixels are unchanged by the false points elsewhere
    assert acc.median_abs == pytest.approx(0.5)


def _scan(log: Path, out: Path, capsys) -> tuple[int, str]:
    code = main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"])
    return code, capsys.readouterr().err.strip()


def _refill_frames(folder: Path, make) -> None:
    for i, png in enumerate(sorted((folder / "frames").glob("*.png"))):
        image = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(png), make(i, image))


def _reference_rows_lit(image: np.ndarray) -> np.ndarray:
    """A copy of a tiny capture's frame with its reference regions (8 rows at top and bottom) lit."""
    image = image.copy()
    image[:8] = 200
    image[-8:] = 200
    return image


@pytest.mark.slow
def test_random_noise_frames_are_an_error(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "capture", width=96, height=72)
    rng = np.random.default_rng(1)
    _refill_frames(tmp_path / "capture", lambda i, im: rng.integers(0, 256, im.shape, dtype=np.uint8))
    code, err = _scan(log, tmp_path / "scan", capsys)
    assert code == 2 and "noise" in err and "frames" in err, err
    assert not (tmp_path / "scan").exists()


@pytest.mark.slow
def test_identical_frames_are_an_error(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "capture")
    first = cv2.imread(str(sorted((tmp_path / "capture" / "frames").glob("*.png"))[0]), cv2.IMREAD_UNCHANGED)
    _refill_frames(tmp_path / "capture", lambda i, im: first)
    code, err = _scan(log, tmp_path / "scan", capsys)
    assert code == 2 and "identical" in err, err
    assert not (tmp_path / "scan").exists()


@pytest.mark.slow
def test_reference_regions_never_crossed_is_an_error(tmp_path: Path, capsys) -> None:
    # The band sweeps the middle rows only: the reference regions (6 rows at the
    # top and bottom) stay lit in every frame.
    log = write_tiny_capture(tmp_path / "capture")

    _refill_frames(tmp_path / "capture", lambda i, im: _reference_rows_lit(im))
    code, err = _scan(log, tmp_path / "scan", capsys)
    assert code == 2 and "shadow line was found on the reference regions in 0" in err, err


@pytest.mark.slow
def test_reference_regions_rarely_crossed_is_an_error(tmp_path: Path, capsys) -> None:
    # The shadow reaches the reference rows in only 3 of its 24 frames: the planes
    # cover too little of the sweep for the depths between them to mean anything.
    log = write_tiny_capture(tmp_path / "capture")

    def regions_lit_mostly(i, im):
        return im if i in (10, 11, 12) else _reference_rows_lit(im)

    _refill_frames(tmp_path / "capture", regions_lit_mostly)
    code, err = _scan(log, tmp_path / "scan", capsys)
    assert code == 2 and "too few to scan" in err and "shadow planes were measured in" in err, err


def _planes_through(lamp: np.ndarray, normals: np.ndarray) -> np.ndarray:
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return np.concatenate([normals, (normals @ lamp)[:, None]], axis=1)


def test_lamp_from_planes_all_round() -> None:
    from gnomon.geometry.validity import light_point_or_line

    lamp = np.array([-200.0, 50.0, 400.0])
    rng = np.random.default_rng(2)
    # a stick swept by hand: its planes turn about several directions
    normals = rng.normal(size=(40, 3))
    est = light_point_or_line(_planes_through(lamp, normals))
    assert not est.degenerate and est.conditioning > 0.2
    np.testing.assert_allclose(est.point, lamp, atol=1e-6)


def test_lamp_from_planes_sharing_one_direction_is_a_line() -> None:
    from gnomon.geometry.validity import light_point_or_line

    lamp = np.array([-200.0, 50.0, 400.0])
    stick = np.array([0.0, 0.6, 0.8])  # a stick translated parallel to itself
    rng = np.random.default_rng(3)
    normals = np.cross(stick, rng.normal(size=(40, 3)))  # every plane contains the stick's direction
    planes = _planes_through(lamp, normals)
    planes[:, 3] += rng.normal(scale=0.05, size=len(planes))  # 0.05 mm of plane noise
    est = light_point_or_line(planes)
    assert est.degenerate and est.conditioning < 1e-3
    assert abs(abs(est.direction @ stick) - 1.0) < 1e-6
    # the lamp lies on the reported line (to the noise), wherever along it the point was put
    off = (lamp - est.point) - ((lamp - est.point) @ est.direction) * est.direction
    assert np.linalg.norm(off) < 0.5


def _jitter_regions(folder: Path, shift_px: float, seed: int) -> None:
    """Shift the band by a random amount on every row of the reference regions (6 rows at the top and
    the bottom): their crossings scatter across the line as on a region that is not flat or not bare."""
    rng = np.random.default_rng(seed)
    rows = list(range(6)) + list(range(30, 36))
    shifts = {r: int(v) for r, v in zip(rows, np.rint(rng.uniform(-shift_px, shift_px, len(rows))), strict=True)}

    def shifted(i, im):
        im = im.copy()
        for r, s in shifts.items():
            im[r] = np.roll(im[r], s)
        return im

    _refill_frames(folder, shifted)


@pytest.mark.slow
def test_reference_line_residuals_far_above_sigma_warn(tmp_path: Path) -> None:
    from gnomon.geometry.validity import LINE_RESIDUAL_WARN_RATIO
    from gnomon.runs.scan import ScanOptions, run_scan

    clean = run_scan(write_tiny_capture(tmp_path / "clean"), tmp_path / "s0", ScanOptions(progress=False, rrd=False))
    assert not any("residual" in w for w in clean.warnings), clean.warnings
    log = write_tiny_capture(tmp_path / "capture")
    # ±1 px on a band moving 3.1 px per frame: ≈ 0.2 frames of scatter, far above the times' noise
    _jitter_regions(tmp_path / "capture", 1.0, seed=2)
    result = run_scan(log, tmp_path / "scan", ScanOptions(progress=False, rrd=False))
    warned = [w for w in result.warnings if "residual" in w]
    assert warned and "'desk'" in warned[0] and "times what" in warned[0], result.warnings
    ratio = float(warned[0].split(" times what")[0].split(", ")[-1])
    assert ratio > LINE_RESIDUAL_WARN_RATIO


@pytest.mark.slow
def test_meaningless_reference_lines_are_an_error(tmp_path: Path, capsys) -> None:
    # A slow sweep (0.76 px per frame) and ±2 px: the lines are long and straight enough to be
    # fitted, but scattered across by more than the shadow moves in a frame
    log = write_tiny_capture(tmp_path / "capture", n_frames=96)
    _jitter_regions(tmp_path / "capture", 2.0, seed=3)
    code, err = _scan(log, tmp_path / "scan", capsys)
    assert code == 2 and "meaningless" in err and "'desk'" in err and "\n" not in err, err
    assert not (tmp_path / "scan").exists()


def test_share_of_the_sun_a_pole_hides() -> None:
    from gnomon.geometry.validity import SUN_ANGULAR_RADIUS_RAD as rho
    from gnomon.geometry.validity import occluded_fraction

    r = 0.05  # m
    umbra = r / rho  # ≈ 10.7 m: the pole as wide as the disc
    np.testing.assert_allclose(occluded_fraction(r, np.array([1.0, 0.5 * umbra, umbra])), 1.0)
    # far away a band of width 2r across a disc of radius ρs: area 2r·2ρs / (π ρ² s²)
    s = 200.0 * umbra
    assert occluded_fraction(r, np.array([s]))[0] == pytest.approx(4 * r / (np.pi * rho * s), rel=1e-3)
    # in between it falls monotonically
    f = occluded_fraction(r, np.linspace(umbra, 10 * umbra, 50))
    assert np.all(np.diff(f) < 0) and 0 < f[-1] < 1


@pytest.mark.slow
def test_contrast_floor_from_the_noise_unless_given(tmp_path: Path) -> None:
    import tomllib

    from gnomon.capture.tracking import MIN_CONTRAST_SIGMAS
    from gnomon.runs.scan import ScanOptions, run_scan
    from gnomon.util import toml_io

    log = write_tiny_capture(tmp_path / "capture")
    rng = np.random.default_rng(4)
    # σ = 2 DN of noise on every frame; the band's dip is 160 DN
    _refill_frames(tmp_path / "capture",
                   lambda i, im: np.clip(im + rng.normal(0, 2.0, im.shape), 0, 255).astype(np.uint8))
    given = run_scan(log, tmp_path / "s20", ScanOptions(progress=False, rrd=False)).report["settings"]
    assert given["min_contrast_dn"] == 20 and given["min_contrast_from"] == "field log"
    data = tomllib.loads(log.read_text())
    del data["scan"]["min_contrast"]
    toml_io.dump(data, log)
    result = run_scan(log, tmp_path / "snoise", ScanOptions(progress=False, rrd=False))
    s, noise = result.report["settings"], result.report["noise"]["image_noise_dn"]
    assert s["min_contrast_from"] == "image noise"
    assert noise == pytest.approx(np.sqrt(4 + 1 / 12), rel=0.15)
    assert s["min_contrast_dn"] == pytest.approx(MIN_CONTRAST_SIGMAS * noise)
    assert result.report["coverage"]["points"] > 0.5 * 48 * 36


def _noise_cases():
    """Frame pairs of every kind the noise estimate meets: u8 and u16, float, gain drifts, shadows,
    clipped and saturated samples, large flat regions (many equal differences), tiny images."""
    rng = np.random.default_rng(11)
    for seed in range(6):
        yield noisy_pair(rng.uniform(0.4, 3.0), seed=seed, gain=rng.uniform(0.95, 1.05), moved_rows=seed * 12)
    for _ in range(4):
        top = 65535
        scene = rng.uniform(500.0, 60000.0, (int(rng.integers(20, 90)), int(rng.integers(20, 90))))
        sigma = rng.uniform(50.0, 400.0)
        a = np.clip(np.rint(scene + sigma * rng.standard_normal(scene.shape)), 0, top).astype(np.uint16)
        b = np.clip(np.rint(1.01 * scene + sigma * rng.standard_normal(scene.shape)), 0, top).astype(np.uint16)
        yield a, b
    a, b = noisy_pair(1.5, seed=21)
    a[:100], b[:100] = 255, 0  # saturated in one frame, black in the other
    yield a, b
    flat = np.full((200, 300), 128, np.uint8)
    yield flat, flat + (rng.random(flat.shape) < 0.01).astype(np.uint8)  # nearly every difference 0
    yield noisy_pair(1.0, seed=5)[0].astype(np.float32) * 1.37, noisy_pair(1.0, seed=5)[1].astype(np.float64)
    yield np.full((4, 5), 9, np.uint8), np.full((4, 5), 9, np.uint8)  # fewer than 16 samples
    a, b = noisy_pair(2.0, seed=8)
    yield a, (b.astype(np.uint16) * 3)  # two integer types: the float path, inside the first one's range
    yield a[::2, 1::3], b[::2, 1::3]  # strided views
    big = rng.uniform(2.0, 250.0, (300, 700))
    yield (np.rint(big + rng.normal(0, 1.2, big.shape)).clip(0, 255).astype(np.uint8),
           np.rint(big + 40 + rng.normal(0, 1.2, big.shape)).clip(0, 255).astype(np.uint8))  # a large offset


def test_noise_estimate_is_the_numpy_definition_to_the_last_bit() -> None:
    from gnomon.capture.noise import _image_noise_dn_numpy

    for a, b in _noise_cases():
        for clip, iterations in ((4.0, 6), (2.5, 12), (6.0, 1)):
            got = image_noise_dn(a, b, clip_sigmas=clip, iterations=iterations)
            assert got == _image_noise_dn_numpy(a, b, clip_sigmas=clip, iterations=iterations), (a.shape, clip)


def test_a_clipped_fit_step_is_numpys_float32_arithmetic() -> None:
    """The kernel's step against the numpy expressions it stands for, on sizes around numpy's summation
    blocks (8, 128) and beyond, where the order of a float32 sum shows."""
    from gnomon import _kernel

    rng = np.random.default_rng(5)
    for n in (16, 17, 127, 128, 129, 1000, 4099, 100_003):
        diff = np.rint(rng.normal(0.3, 2.0, n)).astype(np.float32)
        level = (rng.uniform(-120.0, 120.0, n) + 0.25).astype(np.float32)
        offset, gain, limit = 0.5, 0.003, 5.5
        resid = diff - offset - gain * level
        keep = np.abs(resid) <= limit
        x, y = level[keep], diff[keep]
        x_mean, y_mean = x.mean(), y.mean()
        dx = x - x_mean
        var_x = float(np.mean(dx**2))
        new_gain = float(np.mean(dx * (y - y_mean)) / var_x)
        new_offset = float(y_mean - new_gain * x_mean)
        rms = float(np.sqrt(np.mean((y - new_offset - new_gain * x) ** 2)))
        assert _kernel.clipped_fit_step(diff, level, offset, gain, limit, 16) == (int(keep.sum()), new_offset,
                                                                                 new_gain, rms), n
    assert _kernel.clipped_fit_step(np.zeros(5, np.float32), np.zeros(5, np.float32), 0.0, 0.0, 1.0, 16) is None


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_the_noise_samples_are_the_numpy_ones(dtype) -> None:
    """The kernel's samples, centred levels and starting median and MAD against numpy's steps."""
    from gnomon import _kernel
    from gnomon.capture.noise import _median_of_integers

    rng = np.random.default_rng(2)
    top = np.iinfo(dtype).max
    for n in (16, 17, 999, 50_001):
        a = rng.integers(0, top + 1, n).astype(dtype)
        b = np.clip(a.astype(np.int64) + rng.integers(-9, 12, n), 0, top).astype(dtype)
        inside = (a > 0) & (b > 0) & (a < top) & (b < top)
        ai, bi = a[inside], b[inside]
        whole = ai.astype(np.int32) - bi.astype(np.int32)
        af, bf = ai.astype(np.float32), bi.astype(np.float32)
        level = 0.5 * (af + bf)
        med = _median_of_integers(whole)
        mad = _median_of_integers(np.abs(2 * whole - round(2 * med))) / 2
        got = _kernel.noise_samples(a, b, 16)
        if inside.sum() < 16:
            assert got is None
            continue
        diff, lev, got_med, got_mad = got
        assert np.array_equal(diff, af - bf) and diff.dtype == np.float32
        assert np.array_equal(lev, level - float(level.mean()))
        assert (got_med, got_mad) == (med, mad)
    assert _kernel.noise_samples(np.zeros(20, dtype), np.zeros(20, dtype), 16) is None
    with pytest.raises(ValueError):
        _kernel.noise_samples(np.zeros(20, np.int16), np.zeros(20, np.int16), 16)
