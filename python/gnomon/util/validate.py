"""Validation at the edge: numbers that make sense, paths that are what they claim.

Every check raises a :class:`~gnomon.errors.GnomonError` (a
:class:`~gnomon.errors.FieldLogError` for field-log keys) whose message names
the file and key, or the command-line option, and the value: the CLI prints it
as one line and exits with code 2. Inner steps can then take plain values
without re-checking them.

What is checked beyond "a finite number of the right sign":

- a camera whose lens model is invertible over the whole image (every border
  pixel's ray projects back onto that pixel) and whose field of view is
  plausible (between 0.05° and 175°);
- a lamp that is not at the camera's centre (shadow planes through the camera
  centre are seen edge-on) nor absurdly far;
- a pole that is not within 20° of horizontal (the world's z axis is up in
  sun scans);
- frame times: a frame rate between one frame a day and 10,000 per second; a
  time zone that exists;
- reference planes with distinct names; chessboards of at least 3x3 inner
  corners; a tracker window the kernel supports.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.errors import GnomonError, OutputError

__all__ = [
    "MAX_WINDOW",
    "check_camera",
    "check_output_file",
    "check_output_folder",
    "input_file",
    "input_folder",
    "number",
    "read_text",
]

MAX_WINDOW = 64
"""The kernel tracker's largest window half-width (``rust/core/src/tracker.rs``: ``MAX_WINDOW``)."""

MAX_DIP_FRAMES = 128
"""The kernel tracker's widest dip, frames (``rust/core/src/tracker.rs``: ``TrackerConfig::MAX_WIDTH``)."""

MIN_FOV_DEG, MAX_FOV_DEG = 0.05, 175.0
MIN_FPS, MAX_FPS = 1.0 / 86400.0, 10_000.0
MIN_POLE_ELEVATION_DEG = 20.0
MIN_CHESSBOARD = 3


# ------------------------------------------------------------------------ numbers


def number(value: Any, option: str, *, positive: bool = False, minimum: float | None = None,
           maximum: float | None = None, integer: bool = False) -> float:
    """A finite number within bounds, or a one-line error naming ``option``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GnomonError(f"{option} {value!r}: expected a number")
    v = float(value)
    if not math.isfinite(v):
        raise GnomonError(f"{option} {value}: must be a finite number")
    if integer and v != int(v):
        raise GnomonError(f"{option} {value}: must be a whole number")
    if positive and v <= 0:
        raise GnomonError(f"{option} {value}: must be > 0")
    if minimum is not None and v < minimum:
        raise GnomonError(f"{option} {value}: must be ≥ {minimum:g}")
    if maximum is not None and v > maximum:
        raise GnomonError(f"{option} {value}: must be ≤ {maximum:g}")
    return v


# -------------------------------------------------------------------------- paths


def input_file(path: str | os.PathLike, what: str = "file") -> Path:
    """An existing regular file (not a folder), or a one-line error."""
    p = Path(path)
    if not p.exists():
        raise GnomonError(f"{p}: {what} not found")
    if p.is_dir():
        raise GnomonError(f"{p}: {what} is a folder, expected a file")
    if not p.is_file():
        raise GnomonError(f"{p}: {what} is not a regular file")
    if not os.access(p, os.R_OK):
        raise GnomonError(f"{p}: {what} is not readable (permission denied)")
    return p


def input_folder(path: str | os.PathLike, what: str = "folder") -> Path:
    """An existing folder, or a one-line error."""
    p = Path(path)
    if not p.exists():
        raise GnomonError(f"{p}: {what} not found")
    if not p.is_dir():
        raise GnomonError(f"{p}: {what} is a file, expected a folder")
    return p


def read_text(path: str | os.PathLike, what: str = "file") -> str:
    """The UTF-8 text of an existing file, or a one-line error (missing, a folder, binary, not UTF-8)."""
    p = input_file(path, what)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise GnomonError(f"{p}: {what} cannot be read: {exc.strerror or exc}") from None
    if b"\x00" in data:
        raise GnomonError(f"{p}: {what} is a binary file, expected text (TOML)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise GnomonError(f"{p}: {what} is not UTF-8 text (byte {exc.start}: {data[exc.start:exc.start + 1]!r}); "
                          "save it as UTF-8") from None


# ------------------------------------------------------------------------ cameras


def _border_pixels(width: int, height: int, n: int = 24) -> np.ndarray:
    u = np.linspace(0.0, width - 1.0, n)
    v = np.linspace(0.0, height - 1.0, n)
    edges = [np.stack([u, np.zeros(n)], 1), np.stack([u, np.full(n, height - 1.0)], 1),
             np.stack([np.zeros(n), v], 1), np.stack([np.full(n, width - 1.0), v], 1)]
    return np.concatenate(edges)


def check_camera(camera, where: str) -> None:
    """Image size, focal lengths, principal point and lens distortion of a camera, or a one-line error.

    ``where`` names the file and table, e.g. ``"scan.toml: [camera]"``.
    """
    w, h = int(camera.width), int(camera.height)
    if not (2 <= w <= 100_000 and 2 <= h <= 100_000):
        raise GnomonError(f"{where}: image size {w}x{h} is not plausible (2 … 100000 pixels a side)")
    model = type(camera).__name__
    focal_keys: list[tuple[str, float, int]] = []
    if hasattr(camera, "fx"):
        focal_keys = [("fx", float(camera.fx), w), ("fy", float(camera.fy), h)]
    elif hasattr(camera, "f_mm") and hasattr(camera, "dx_mm"):
        focal_keys = [("f_mm", float(camera.f_mm) / float(camera.dx_mm), w)]
    for key, f_px, size in focal_keys:
        if not math.isfinite(f_px) or f_px <= 0:
            raise GnomonError(f"{where}: key '{key}' must be a positive finite number")
        fov = math.degrees(2.0 * math.atan(size / (2.0 * f_px)))
        if not MIN_FOV_DEG <= fov <= MAX_FOV_DEG:
            raise GnomonError(f"{where}: key '{key}' gives a field of view of {fov:.3g}° over {size} pixels "
                              f"(plausible: {MIN_FOV_DEG:g}° … {MAX_FOV_DEG:g}°); is it in pixels?")
    for key in ("cx", "cy"):
        if hasattr(camera, key):
            c = float(getattr(camera, key))
            size = w if key == "cx" else h
            if not math.isfinite(c) or not -size <= c <= 2 * size:
                raise GnomonError(f"{where}: key '{key}' = {c:g} is far outside the {w}x{h} image")
    dist_key = "dist" if model == "OpenCVCamera" else ("kappa1" if hasattr(camera, "kappa1") else "distortion")
    pix = _border_pixels(w, h)
    with np.errstate(all="ignore"):
        try:
            rays = camera.rays(pix)
            back = camera.project(rays)
        except Exception as exc:  # OpenCV rejecting absurd coefficients
            raise GnomonError(f"{where}: key '{dist_key}': the lens model cannot be inverted ({exc})") from None
    bad = ~np.all(np.isfinite(rays), axis=1) | (rays[:, 2] <= 1e-6)
    err = np.where(bad, np.inf, np.linalg.norm(np.asarray(back) - pix, axis=1))
    worst = int(np.argmax(err))
    if not err[worst] <= 0.5:
        u, v = pix[worst]
        raise GnomonError(f"{where}: key '{dist_key}': the distortion is not invertible over the image "
                          f"(pixel ({u:.0f}, {v:.0f}) does not map back onto itself); check the coefficients")
    # The field of view the rays span, corner to corner through the image, after distortion.
    span = math.degrees(math.acos(float(np.clip(np.min(rays @ rays.T), -1.0, 1.0))))
    if not MIN_FOV_DEG <= span <= 2 * MAX_FOV_DEG:
        raise GnomonError(f"{where}: key '{dist_key}': with this distortion the image spans {span:.3g}° "
                          f"(plausible: {MIN_FOV_DEG:g}° … {MAX_FOV_DEG:g}°); check the coefficients")
    angle = np.degrees(np.arccos(np.clip(rays[:, 2], -1.0, 1.0)))
    if angle.max() > MAX_FOV_DEG / 2:
        raise GnomonError(f"{where}: key '{dist_key}': the image corners would look {angle.max():.0f}° off the "
                          "optical axis; check the coefficients")


# ------------------------------------------------------------------------ outputs


def _first_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        if p.is_symlink():  # a dangling symlink
            raise OutputError(f"{path}: {p} is a broken symbolic link")
        p = p.parent
    return p


def check_output_folder(out: str | os.PathLike, option: str = "--out") -> Path:
    """The absolute output folder, or a one-line error: a file, under a file, not writable."""
    path = Path(os.path.abspath(os.fspath(out)))
    if path.exists() or path.is_symlink():
        path = path.resolve()
        if not path.is_dir():
            raise OutputError(f"{option} {out}: is a file, not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError(f"{option} {out}: the folder is not writable")
        return path
    return _creatable(path, out, option)


def check_output_file(path: str | os.PathLike, option: str) -> Path:
    """The absolute path of a file to write, or a one-line error (a folder, under a file, not writable)."""
    p = Path(os.path.abspath(os.fspath(path)))
    if p.is_dir():
        raise OutputError(f"{option} {path}: is a folder; give a file name")
    if p.exists():
        if not os.access(p.parent, os.W_OK | os.X_OK):
            raise OutputError(f"{option} {path}: its folder is not writable")
        return p
    return _creatable(p, path, option)


def _creatable(path: Path, given: str | os.PathLike, option: str) -> Path:
    """``path`` (not yet existing) if its nearest existing ancestor is a writable folder, else a one-line error."""
    base = _first_existing(path.parent)
    if not base.is_dir():
        raise OutputError(f"{option} {given}: {base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {given}: cannot create it in {base} (not writable)")
    return path
