"""Frame timestamps: file-name patterns, EXIF, start + fps; their errors; interpolation."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from gnomon.errors import GnomonError
from gnomon.light.timestamps import frame_times, interpolate_times


def utc(*texts: str) -> pd.DatetimeIndex:
    return pd.DatetimeIndex([pd.Timestamp(t) for t in texts]).tz_convert("UTC")


def touch(folder, *names):
    paths = []
    for n in names:
        p = folder / n
        p.write_bytes(b"")
        paths.append(p)
    return paths


def write_image(path, *, original=None, offset=None, subsec=None, fmt="JPEG"):
    exif = Image.Exif()
    ifd = exif.get_ifd(0x8769)
    if original is not None:
        ifd[0x9003] = original
    if offset is not None:
        ifd[0x9011] = offset
    if subsec is not None:
        ifd[0x9291] = subsec
    buf = io.BytesIO()
    Image.fromarray(np.full((8, 8), 128, np.uint8)).save(buf, format=fmt, exif=exif.tobytes())
    path.write_bytes(buf.getvalue())
    return path


# ------------------------------------------------------------------ file names


def test_filename_with_a_literal_z_is_utc(tmp_path):
    files = touch(tmp_path, "20261112T104000Z.jpg", "20261112T104100Z.jpg")
    t = frame_times(files, "filename", pattern="%Y%m%dT%H%M%SZ", site_tz="Europe/Zurich")
    assert str(t.tz) == "UTC"
    assert t.equals(utc("2026-11-12T10:40:00Z", "2026-11-12T10:41:00Z"))
    # No site zone needed when the pattern says UTC.
    assert frame_times(files, "filename", pattern="%Y%m%dT%H%M%SZ").equals(t)


def test_filename_with_an_offset(tmp_path):
    files = touch(tmp_path, "IMG_2026-06-21_12-15-00+0200.jpg", "IMG_2026-06-21_10-16-00Z.jpg")
    t = frame_times(files, "filename", pattern="IMG_%Y-%m-%d_%H-%M-%S%z")
    assert t.equals(utc("2026-06-21T10:15:00Z", "2026-06-21T10:16:00Z"))


def test_filename_local_time_uses_the_site_zone(tmp_path):
    # Zurich is UTC+1 in November and UTC+2 in June.
    files = touch(tmp_path, "2026-06-21 12-15-00.500.png")
    t = frame_times(files, "filename", pattern="%Y-%m-%d %H-%M-%S.%f", site_tz="Europe/Zurich")
    assert t[0] == pd.Timestamp("2026-06-21T10:15:00.5Z")
    files = touch(tmp_path, "20261112_1140.png")
    t = frame_times(files, "filename", pattern="%Y%m%d_%H%M", site_tz="+01:00")
    assert t[0] == pd.Timestamp("2026-11-12T10:40:00Z")


def test_filename_local_time_without_a_zone_is_an_error(tmp_path):
    files = touch(tmp_path, "20261112_1140.png")
    with pytest.raises(GnomonError, match=r"20261112_1140\.png.*no UTC offset.*timezone"):
        frame_times(files, "filename", pattern="%Y%m%d_%H%M")


def test_filename_that_does_not_match_names_the_file(tmp_path):
    files = touch(tmp_path, "20261112T104000Z.jpg", "frame_0001.jpg")
    with pytest.raises(GnomonError, match=r"frame_0001\.jpg.*does not match.*%Y%m%dT%H%M%SZ"):
        frame_times(files, "filename", pattern="%Y%m%dT%H%M%SZ")


def test_filename_pattern_problems(tmp_path):
    files = touch(tmp_path, "20261112T104000Z.jpg")
    with pytest.raises(GnomonError, match="need a time pattern"):
        frame_times(files, "filename")
    with pytest.raises(GnomonError, match="%Z"):
        frame_times(files, "filename", pattern="%Y%m%dT%H%M%S%Z")
    with pytest.raises(GnomonError, match="lone '%'"):
        frame_times(files, "filename", pattern="%Y%m%dT%H%M%SZ%")


def test_local_time_skipped_or_repeated_by_a_clock_change(tmp_path):
    files = touch(tmp_path, "2026-10-25_02-30.png")  # happens twice in Zurich
    with pytest.raises(GnomonError, match="ambiguous"):
        frame_times(files, "filename", pattern="%Y-%m-%d_%H-%M", site_tz="Europe/Zurich")
    files = touch(tmp_path, "2026-03-29_02-30.png")  # never happens
    with pytest.raises(GnomonError, match="does not exist"):
        frame_times(files, "filename", pattern="%Y-%m-%d_%H-%M", site_tz="Europe/Zurich")


def test_timestamps_out_of_order_name_both_frames(tmp_path):
    files = touch(tmp_path, "20261112T104100Z.jpg", "20261112T104000Z.jpg")
    with pytest.raises(GnomonError, match=r"out of order: .*20261112T104000Z\.jpg \(.*\) is before "
                                          r".*20261112T104100Z\.jpg"):
        frame_times(files, "filename", pattern="%Y%m%dT%H%M%SZ")
    # Equal times (here: the same instant written in two zones).
    files = touch(tmp_path, "20261112T114000+0100.jpg", "20261112T104000+0000.jpg")
    with pytest.raises(GnomonError, match=r"20261112T104000\+0000\.jpg has the same time .* as "
                                          r".*20261112T114000\+0100\.jpg"):
        frame_times(files, "filename", pattern="%Y%m%dT%H%M%S%z")


# ------------------------------------------------------------------ EXIF


def test_exif_with_offset_and_subseconds(tmp_path):
    a = write_image(tmp_path / "a.jpg", original="2026:11:12 11:40:00", offset="+01:00")
    b = write_image(tmp_path / "b.jpg", original="2026:11:12 11:41:00", offset="+01:00", subsec="250")
    t = frame_times([a, b], "exif")
    assert t.equals(utc("2026-11-12T10:40:00Z", "2026-11-12T10:41:00.25Z"))


def test_exif_without_offset_uses_the_site_zone(tmp_path):
    a = write_image(tmp_path / "a.jpg", original="2026:06:21 12:15:00")
    assert frame_times([a], "exif", site_tz="Europe/Zurich")[0] == pd.Timestamp("2026-06-21T10:15:00Z")
    with pytest.raises(GnomonError, match=r"a\.jpg.*no UTC offset"):
        frame_times([a], "exif")
    # A blank offset ("   :  ", the camera did not know) counts as none.
    b = write_image(tmp_path / "b.jpg", original="2026:06:21 12:15:00", offset="   :  ")
    assert frame_times([b], "exif", site_tz="Europe/Zurich")[0] == pd.Timestamp("2026-06-21T10:15:00Z")


def test_exif_in_png(tmp_path):
    a = write_image(tmp_path / "a.png", original="2026:11:12 11:40:00", offset="+01:00", fmt="PNG")
    assert frame_times([a], "exif")[0] == pd.Timestamp("2026-11-12T10:40:00Z")


def test_exif_problems_name_the_file(tmp_path):
    missing = write_image(tmp_path / "no_tag.jpg")
    with pytest.raises(GnomonError, match=r"no_tag\.jpg: no EXIF DateTimeOriginal"):
        frame_times([missing], "exif", site_tz="UTC")
    bad = write_image(tmp_path / "bad.jpg", original="12/11/2026 11:40", offset="+01:00")
    with pytest.raises(GnomonError, match=r"bad\.jpg: EXIF DateTimeOriginal '12/11/2026 11:40'"):
        frame_times([bad], "exif")
    bad_off = write_image(tmp_path / "bad_off.jpg", original="2026:11:12 11:40:00", offset="CET")
    with pytest.raises(GnomonError, match=r"bad_off\.jpg: EXIF OffsetTimeOriginal 'CET'"):
        frame_times([bad_off], "exif")
    bad_sub = write_image(tmp_path / "bad_sub.jpg", original="2026:11:12 11:40:00", offset="+01:00", subsec="x")
    with pytest.raises(GnomonError, match=r"bad_sub\.jpg: EXIF SubSecTimeOriginal"):
        frame_times([bad_sub], "exif")
    junk = tmp_path / "junk.jpg"
    junk.write_bytes(b"not an image")
    with pytest.raises(GnomonError, match=r"junk\.jpg: cannot read its EXIF"):
        frame_times([junk], "exif")
    with pytest.raises(GnomonError, match=r"gone\.jpg: file not found"):
        frame_times([tmp_path / "gone.jpg"], "exif")


def test_exif_out_of_order(tmp_path):
    a = write_image(tmp_path / "a.jpg", original="2026:11:12 11:41:00", offset="+01:00")
    b = write_image(tmp_path / "b.jpg", original="2026:11:12 11:40:00", offset="+01:00")
    with pytest.raises(GnomonError, match=r"out of order: .*b\.jpg .* is before .*a\.jpg"):
        frame_times([a, b], "exif")


# ------------------------------------------------------------------ start + fps


def test_start_and_fps():
    t = frame_times(4, "start+fps", start="2026-11-12T11:40:00+01:00", fps=29.97)
    assert t[0] == pd.Timestamp("2026-11-12T10:40:00Z") and len(t) == 4
    steps = np.diff(t.asi8)
    assert np.abs(steps - 1e9 / 29.97).max() <= 1
    t = frame_times(["a.mp4"] * 3, "start+fps", start="2026-06-21T12:15:00", fps=2, site_tz="Europe/Zurich")
    assert t.equals(utc("2026-06-21T10:15:00Z", "2026-06-21T10:15:00.5Z", "2026-06-21T10:15:01Z"))


def test_start_and_fps_problems():
    with pytest.raises(GnomonError, match="need a start time"):
        frame_times(3, "start+fps", fps=30)
    with pytest.raises(GnomonError, match="need fps"):
        frame_times(3, "start+fps", start="2026-06-21T12:15:00Z")
    for bad in (0, -1, float("nan"), float("inf")):
        with pytest.raises(GnomonError, match="must be a positive number"):
            frame_times(3, "start+fps", start="2026-06-21T12:15:00Z", fps=bad)
    with pytest.raises(GnomonError, match="no UTC offset"):
        frame_times(3, "start+fps", start="2026-06-21T12:15:00", fps=30)
    with pytest.raises(GnomonError, match="not an ISO 8601"):
        frame_times(3, "start+fps", start="noon", fps=30)
    with pytest.raises(GnomonError, match="need the frame files"):
        frame_times(3, "exif")


def test_unknown_mode():
    with pytest.raises(GnomonError, match="timestamps 'gps'.*'filename', 'exif', 'start\\+fps'"):
        frame_times([], "gps")


# ------------------------------------------------------------------ interpolation


def test_interpolate_times():
    t = utc("2026-11-12T10:40:00Z", "2026-11-12T10:41:00Z", "2026-11-12T10:43:00Z")
    f = np.array([[0.0, 0.5, 1.0], [1.25, 2.0, np.nan], [-0.01, 2.01, 1.999999]])
    out = interpolate_times(t, f)
    assert out.dtype == np.dtype("datetime64[ns]") and out.shape == f.shape
    expect = np.array([["2026-11-12T10:40:00", "2026-11-12T10:40:30", "2026-11-12T10:41:00"],
                       ["2026-11-12T10:41:30", "2026-11-12T10:43:00", "NaT"]], dtype="datetime64[ns]")
    np.testing.assert_array_equal(out[:2], expect)
    assert np.isnat(out[2, 0]) and np.isnat(out[2, 1])
    assert out[2, 2] == np.datetime64("2026-11-12T10:42:59.999880", "ns")
    # Any zone and naive datetime64 (taken as UTC) give the same.
    np.testing.assert_array_equal(interpolate_times(t.tz_convert("Europe/Zurich"), f), out)
    np.testing.assert_array_equal(interpolate_times(t.tz_localize(None).to_numpy(), f), out)
    # A single frame: only index 0 has a time.
    one = interpolate_times(t[:1], [0.0, 0.5])
    assert one[0] == np.datetime64("2026-11-12T10:40:00", "ns") and np.isnat(one[1])
    assert interpolate_times(t, 1.5).shape == ()
