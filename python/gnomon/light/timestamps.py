"""Frame timestamps: from file names, from EXIF, or from a start time and a frame rate.

A sun scan needs the UTC time of every frame (the sun's direction follows
from it, :mod:`gnomon.light.ephemeris`). Three sources, the field log's
``[capture] timestamps``:

``"filename"``
    The file name's stem (the name without its extension) is read with a
    ``strftime`` pattern, ``[capture] time_pattern``, which must match the
    whole stem, e.g. ``"%Y%m%dT%H%M%SZ"`` for ``20261008T094500Z.jpg`` or
    ``"IMG_%Y-%m-%d_%H-%M-%S"``. ``%f`` reads fractions of a second. A pattern
    with ``%z`` reads the UTC offset from the name (``+0200``, ``+02:00`` or
    ``Z``); a pattern with a literal ``Z`` (outside a ``%`` directive) means
    UTC; any other pattern gives *local* times in the site's time zone (and
    is an error when the site has none). ``%Z`` (zone names) is not accepted:
    names are ambiguous, use ``%z``.
``"exif"``
    EXIF ``DateTimeOriginal`` (local time, ``YYYY:MM:DD HH:MM:SS``), with
    ``SubSecTimeOriginal`` for fractions of a second and ``OffsetTimeOriginal``
    (``+02:00``) for the UTC offset, read with Pillow. Without an offset tag
    the time is local in the site's time zone. A file without
    ``DateTimeOriginal`` is an error that names it.
``"start+fps"``
    For videos (or image sequences shot at a fixed rate): frame i is at
    ``start + i / fps``. ``start`` is ISO 8601; without a UTC offset it is
    local in the site's time zone.

Local times that a daylight-saving change skips or repeats are errors (give
an offset). The times must increase strictly from frame to frame; a frame
that is not after the one before it is an error naming both.

Every problem is a :class:`~gnomon.errors.GnomonError` with a one-line
message naming the file.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TypeAlias

import numpy as np
import pandas as pd

from gnomon.errors import GnomonError
from gnomon.light.base import TIMESTAMP_MODES as MODES
from gnomon.light.ephemeris import localize, parse_time

_EXIF_IFD = 0x8769
_DATETIME_ORIGINAL = 0x9003
_OFFSET_TIME_ORIGINAL = 0x9011
_SUBSEC_TIME_ORIGINAL = 0x9291
_EXIF_FORMAT = "%Y:%m:%d %H:%M:%S"
_EXIF_OFFSET = re.compile(r"^([+-])(\d{2}):?(\d{2})$")
_EXIF_BLANK_OFFSET = re.compile(r"^\s*:\s*$")

FileLike: TypeAlias = str | os.PathLike


def frame_times(files: Sequence[FileLike] | int, mode: str, *, pattern: str | None = None,
                start: str | dt.datetime | pd.Timestamp | None = None, fps: float | None = None,
                site_tz=None) -> pd.DatetimeIndex:
    """The UTC time of each frame, as a tz-aware ``pd.DatetimeIndex``.

    ``files``: the frame files in frame order (for ``"start+fps"`` an integer
    frame count is accepted too). ``mode``: ``"filename"`` (needs
    ``pattern``), ``"exif"`` or ``"start+fps"`` (needs ``start`` and ``fps``).
    ``site_tz``: the site's time zone (IANA name, offset or tzinfo) for
    timestamps that carry no UTC offset. See the module docstring.
    """
    if mode not in MODES:
        raise GnomonError(f"timestamps {mode!r}: expected one of {', '.join(repr(m) for m in MODES)}")
    if mode == "start+fps":
        return _start_fps(files, start, fps, site_tz)
    if isinstance(files, (int, np.integer)):
        raise GnomonError(f"timestamps {mode!r} need the frame files, not a frame count")
    paths = [Path(f) for f in files]
    if mode == "filename":
        if not isinstance(pattern, str) or not pattern:
            raise GnomonError("timestamps 'filename' need a time pattern (e.g. time_pattern = \"%Y%m%dT%H%M%SZ\")")
        kind = _pattern_kind(pattern)
        ns = [_from_name(p, pattern, kind, site_tz) for p in paths]
    else:
        ns = [_from_exif(p, site_tz) for p in paths]
    _check_order(ns, [str(p) for p in paths])
    return pd.DatetimeIndex(np.array(ns, dtype="datetime64[ns]")).tz_localize("UTC").as_unit("ns")


def interpolate_times(frame_times, fractional_frames) -> np.ndarray:
    """Times at fractional frame indices, linear between neighbouring frames.

    ``frame_times``: the frames' times (a tz-aware ``DatetimeIndex`` in any
    zone, or naive ``datetime64`` values taken as UTC). ``fractional_frames``:
    any shape of frame indices (0 = the first frame). Returns ``datetime64[ns]``
    of the same shape, in UTC (numpy datetimes are naive); NaN and indices
    outside ``[0, N - 1]`` give NaT.
    """
    idx = pd.DatetimeIndex(frame_times)
    if idx.tz is not None:
        idx = idx.tz_convert("UTC").tz_localize(None)
    ns = idx.as_unit("ns").asi8.astype(np.int64)
    if len(ns) == 0 or idx.hasnans:
        raise GnomonError("interpolate_times: need at least one frame time and no missing ones")
    f = np.asarray(fractional_frames, dtype=np.float64)
    n = len(ns)
    valid = np.isfinite(f) & (f >= 0.0) & (f <= n - 1)
    fv = np.where(valid, f, 0.0)
    k = np.clip(np.floor(fv).astype(np.int64), 0, max(n - 2, 0))
    k1 = np.minimum(k + 1, n - 1)
    frac = fv - k
    step = (ns[k1] - ns[k]).astype(np.float64)
    out = ns[k] + np.rint(step * frac).astype(np.int64)
    out = np.where(valid, out, np.iinfo(np.int64).min)  # int64 min is NaT
    return out.astype("datetime64[ns]")


# --------------------------------------------------------------------------- helpers

def _aware_ns(aware: dt.datetime) -> int:
    return int(pd.Timestamp(aware).tz_convert("UTC").value)


def _pattern_kind(pattern: str) -> str:
    """'offset' (%z), 'utc' (a literal Z) or 'local'."""
    kind = "local"
    i = 0
    while i < len(pattern):
        c = pattern[i]
        if c == "%":
            if i + 1 >= len(pattern):
                raise GnomonError(f"time pattern {pattern!r} ends with a lone '%'")
            directive = pattern[i + 1]
            if directive == "Z":
                raise GnomonError(f"time pattern {pattern!r}: %Z (zone names) is ambiguous; use %z "
                                  "(+0200, +02:00 or Z) or a literal Z for UTC")
            if directive == "z":
                return "offset"
            i += 2
            continue
        if c == "Z":
            kind = "utc"
        i += 1
    return kind


def _from_name(path: Path, pattern: str, kind: str, site_tz) -> int:
    stem = path.stem
    try:
        parsed = dt.datetime.strptime(stem, pattern)
    except ValueError:
        raise GnomonError(f"{path}: file name {stem!r} does not match the time pattern {pattern!r}") from None
    if parsed.tzinfo is not None:
        return _aware_ns(parsed)
    if kind == "utc":
        return _aware_ns(parsed.replace(tzinfo=dt.UTC))
    return int(localize(parsed, site_tz, str(path)).value)


def _exif_text(value) -> str | None:
    if value is None:
        return None
    if isinstance(value, bytes):
        value = value.decode("ascii", errors="replace")
    text = str(value).replace("\x00", "").strip()
    return text or None


def _from_exif(path: Path, site_tz) -> int:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            exif = im.getexif()
            ifd = exif.get_ifd(_EXIF_IFD)
    except FileNotFoundError:
        raise GnomonError(f"{path}: file not found") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise GnomonError(f"{path}: cannot read its EXIF data ({exc})") from None
    original = _exif_text(ifd.get(_DATETIME_ORIGINAL))
    if original is None:
        raise GnomonError(f"{path}: no EXIF DateTimeOriginal (use timestamps = \"filename\" or \"start+fps\")")
    try:
        parsed = dt.datetime.strptime(original, _EXIF_FORMAT)
    except ValueError:
        raise GnomonError(f"{path}: EXIF DateTimeOriginal {original!r} is not 'YYYY:MM:DD HH:MM:SS'") from None
    subsec = _exif_text(ifd.get(_SUBSEC_TIME_ORIGINAL))
    if subsec is not None:
        if not subsec.isdigit():
            raise GnomonError(f"{path}: EXIF SubSecTimeOriginal {subsec!r} is not a string of digits")
        parsed = parsed.replace(microsecond=int(round(float("0." + subsec) * 1e6)) % 1_000_000)
    offset = _exif_text(ifd.get(_OFFSET_TIME_ORIGINAL))
    if offset is not None and _EXIF_BLANK_OFFSET.match(offset):
        offset = None  # "   :  ": the camera did not know
    if offset is None:
        return int(localize(parsed, site_tz, str(path)).value)
    m = _EXIF_OFFSET.match(offset)
    if not m or int(m.group(2)) > 14 or int(m.group(3)) >= 60:
        raise GnomonError(f"{path}: EXIF OffsetTimeOriginal {offset!r} is not a UTC offset such as +02:00")
    delta = dt.timedelta(hours=int(m.group(2)), minutes=int(m.group(3)))
    zone = dt.timezone(-delta if m.group(1) == "-" else delta)
    return _aware_ns(parsed.replace(tzinfo=zone))


def _start_fps(files, start, fps, site_tz) -> pd.DatetimeIndex:
    if isinstance(files, (int, np.integer)) and not isinstance(files, bool):
        count = int(files)
    else:
        count = len(files)
    if count < 0:
        raise GnomonError(f"timestamps 'start+fps': frame count {count} is negative")
    if start is None:
        raise GnomonError("timestamps 'start+fps' need a start time (ISO 8601, e.g. 2026-10-08T11:40:00+02:00)")
    if fps is None or isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise GnomonError(f"timestamps 'start+fps' need fps as a number (got {fps!r})")
    rate = float(fps)
    if not (math.isfinite(rate) and rate > 0):
        raise GnomonError(f"timestamps 'start+fps': fps {fps!r} must be a positive number")
    t0 = parse_time(start, site_tz)
    offsets = np.rint(np.arange(count, dtype=np.float64) * (1e9 / rate)).astype(np.int64)
    return pd.DatetimeIndex((t0.value + offsets).astype("datetime64[ns]")).tz_localize("UTC").as_unit("ns")


def _check_order(ns: list[int], names: list[str]) -> None:
    for i in range(1, len(ns)):
        if ns[i] <= ns[i - 1]:
            a = pd.Timestamp(ns[i - 1], tz="UTC").isoformat()
            b = pd.Timestamp(ns[i], tz="UTC").isoformat()
            if ns[i] == ns[i - 1]:
                raise GnomonError(f"timestamps out of order: {names[i]} has the same time ({b}) as {names[i - 1]}")
            raise GnomonError(f"timestamps out of order: {names[i]} ({b}) is before {names[i - 1]} ({a})")
