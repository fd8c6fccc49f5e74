"""The simulated camera's optics and sensor, shared by every scene.

Linear radiance → optical blur (Gaussian, on the linear image rendered with a
margin, then cropped: border pixels are blurred with the real scene beyond the
border) → gamma encoding → Gaussian sensor noise in DN → quantisation to u8.
Also the ground-truth files every scene writes beside its capture, and the
camera's motion on its tripod (:func:`camera_motion`): a frame whose camera
moved by ``m`` (pixels) samples the same blurred image at ``x − m``
(:func:`blur_and_crop` with ``shift``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon.errors import GnomonError
from gnomon.util import atomic

AMBIENT = 0.1  # ambient irradiance of the desk scenes (radiance = albedo · AMBIENT)


def blur_and_crop(L_full: np.ndarray, sigma_px: float, crop, shift: np.ndarray | None = None) -> np.ndarray:
    """Blur the padded linear image by ``sigma_px`` (0 = none) and crop it to the frame.

    ``shift`` (mx, my), pixels: the image moved by that much on the sensor (the camera drifted): the
    frame's pixel ``x`` sees the blurred image at ``x − shift``. The blurred image is one continuous
    function, ``I(x) = Σ_p G(x − p) R(p) / Σ_p G(x − p)`` over the padded grid's radiance samples
    ``R(p)`` (``G`` the Gaussian of ``sigma_px``): at ``shift = 0`` exactly the unshifted frame (the
    same call), otherwise the same ``I`` sampled at the moved points (separable kernels of the
    Gaussian at the shift's fraction, the crop moved by its whole pixels). The padding must hold
    the moved crop and the kernel (``sigma_px > 0``)."""
    L: np.ndarray = np.asarray(L_full, dtype=np.float32)
    if shift is not None and (shift[0] != 0.0 or shift[1] != 0.0):
        if not sigma_px > 0:
            raise ValueError("a shifted frame needs the optical blur (sigma_px > 0): it is the interpolant")
        return _shifted_blur(L, float(sigma_px), crop, float(shift[0]), float(shift[1]))
    if sigma_px > 0:
        L = cv2.GaussianBlur(L, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REFLECT)
    return np.ascontiguousarray(L[crop])


def shift_margin(sigma_px: float, motion: np.ndarray) -> int:
    """Pixels of padding :func:`blur_and_crop` needs beyond the frame for ``motion`` (N, 2) px."""
    return int(math.ceil(float(np.abs(motion).max(initial=0.0)))) + int(math.ceil(4.0 * sigma_px)) + 2


def _shifted_blur(L: np.ndarray, sigma: float, crop, mx: float, my: float) -> np.ndarray:
    rows, cols = crop
    r = int(math.ceil(4.0 * sigma)) + 1
    taps = np.arange(-r, r + 1, dtype=np.float64)

    def kernel(fraction: float) -> np.ndarray:
        k = np.exp(-0.5 * ((taps - fraction) / sigma) ** 2)
        return (k / k.sum()).astype(np.float32)

    # out(u) = I(u − m) = Σ_i G(i − f) R(u + n + i), with −m = n + f, n whole, 0 ≤ f < 1.
    nx, fx = divmod(-mx, 1.0)
    ny, fy = divmod(-my, 1.0)
    v0, u0 = rows.start + int(ny), cols.start + int(nx)
    h, w = rows.stop - rows.start, cols.stop - cols.start
    if v0 - r < 0 or u0 - r < 0 or v0 + h + r > L.shape[0] or u0 + w + r > L.shape[1]:
        raise ValueError(f"shift ({mx:.3f}, {my:.3f}) px: the padded grid does not hold the moved frame")
    window = L[v0 - r:v0 + h + r, u0 - r:u0 + w + r]
    out = cv2.sepFilter2D(window, cv2.CV_32F, kernel(fx), kernel(fy), borderType=cv2.BORDER_REFLECT)
    return np.ascontiguousarray(out[r:r + h, r:r + w])


def camera_motion(frames: int, drift_px: float, bump_px: float, bump_frame: int | None) -> np.ndarray:
    """The image's motion on the sensor per frame, (N, 2) pixels (x right, y down), frame 0 still.

    A slow drift (a tripod settling, warming up): ``drift_px`` by the last frame, x growing linearly
    and y quadratically in time, ``(0.8, −0.6)·drift_px`` at the end; and a sudden shift (the
    tripod knocked) of ``bump_px`` along ``(0.6, 0.8)`` from frame ``bump_frame`` on (None: 60 %
    of the way). A frame that moved by ``m`` shows a scene point of pixel ``p`` of frame 0 at
    ``p + m``."""
    s = np.arange(frames, dtype=np.float64) / max(frames - 1, 1)
    motion = np.stack([0.8 * drift_px * s, -0.6 * drift_px * s * s], axis=-1)
    if bump_px:
        motion[bump_index(frames, bump_frame):] += bump_px * np.array([0.6, 0.8])
    return motion


def bump_index(frames: int, bump_frame: int | None) -> int:
    """The first frame after :func:`camera_motion`'s sudden shift."""
    return int(round(0.6 * (frames - 1))) if bump_frame is None else int(bump_frame)


def check_motion_options(drift_px: float, bump_px: float, bump_frame: int | None, frames: int, blur: float,
                         bad: Callable[[str], Exception]) -> None:
    """The camera-motion options (:func:`camera_motion`); ``bad`` makes the error to raise."""
    if not (math.isfinite(drift_px) and 0 <= drift_px <= 20):
        raise bad(f"--drift {drift_px}: must be 0 to 20 px")
    if not (math.isfinite(bump_px) and 0 <= bump_px <= 20):
        raise bad(f"--bump {bump_px}: must be 0 to 20 px")
    if bump_frame is not None and not 1 <= bump_frame < frames:
        raise bad(f"bump_frame {bump_frame}: must be 1 to {frames - 1}")
    if (drift_px or bump_px) and not blur >= 0.3:
        raise bad(f"--blur {blur}: a moving camera needs the optical blur (>= 0.3 px): it interpolates the frames")


def encode_dn(L_blurred: np.ndarray, gamma: float, noise_dn: float, rng: np.random.Generator) -> np.ndarray:
    """Gamma-encode, add sensor noise, quantise: linear (blurred) radiance in [0, 1] → u8."""
    dn = 255.0 * np.power(np.clip(L_blurred, 0.0, 1.0, dtype=np.float32), np.float32(1.0 / gamma))
    if noise_dn > 0:
        dn += np.float32(noise_dn) * rng.standard_normal(dn.shape, dtype=np.float32)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def start_captures(out_dir: Any, config: Any, index: str) -> Path:
    """The folder of several captures (views, stations) and its index file's name, ``index``: the
    configuration checked, the folder made, a previous index removed (the index is written last, so a
    folder with one holds every capture)."""
    config.validate()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise GnomonError(f"{out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    (out / index).unlink(missing_ok=True)
    return out


def write_ground_truth(out: Path, arrays: dict[str, Any], summary: dict) -> tuple[Path, Path]:
    """Write ``out/ground_truth.npz`` (the arrays) and ``out/ground_truth.json`` (the summary), atomically."""
    gt_path = out / "ground_truth.npz"
    with atomic.atomic_path(gt_path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    json_path = out / "ground_truth.json"
    atomic.write_text(json_path, json.dumps(summary, indent=2) + "\n")
    return gt_path, json_path


def check_sensor_options(noise: float, jpeg_quality: int, blur: float, bad: Callable[[str], Exception]) -> None:
    """The sensor options every scene has (noise DN, JPEG quality, blur px); ``bad`` makes the error to raise."""
    if not (math.isfinite(noise) and noise >= 0):
        raise bad(f"--noise {noise}: must be >= 0")
    if not 0 <= jpeg_quality <= 100:
        raise bad(f"--jpeg-quality {jpeg_quality}: must be 0 (PNG) to 100")
    if not (math.isfinite(blur) and 0 <= blur <= 20):
        raise bad(f"--blur {blur}: must be 0 to 20 px")


def encode_image(img: np.ndarray, config: Any) -> bytes:
    """A u8 image as JPEG (``config.jpeg_quality``) or PNG (quality 0) bytes."""
    ext = config.extension
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1] if ext == "png" else [cv2.IMWRITE_JPEG_QUALITY, config.jpeg_quality]
    ok, buf = cv2.imencode(f".{ext}", img, params)
    if not ok:  # pragma: no cover
        raise RuntimeError("cv2.imencode failed")
    return buf.tobytes()


def encode_shot_noise(L_blurred: np.ndarray, gamma: float, full_well: float, read_noise_e: float, noise_dn: float,
                      rng: np.random.Generator) -> np.ndarray:
    """A sensor's noise, then gamma and quantisation: linear (blurred) radiance in [0, 1] → u8.

    The linear signal is ``L · full_well`` electrons; shot noise (a Gaussian of the Poisson variance, the
    signal itself) and read noise (``read_noise_e`` electrons) are added before the gamma encoding
    ``DN = 255 · L^(1/gamma)``, which stretches them in the dark; then ``noise_dn`` (a Gaussian in DN, as
    :func:`encode_dn`) and rounding. ``full_well = 0``: no shot or read noise."""
    L = np.clip(L_blurred, 0.0, 1.0, dtype=np.float32)
    if full_well > 0:
        e = L * np.float32(full_well)
        sigma_e = np.sqrt(e + np.float32(read_noise_e) ** 2)
        L = np.clip((e + sigma_e * rng.standard_normal(L.shape, dtype=np.float32)) / np.float32(full_well), 0.0, 1.0)
    return encode_dn(L, gamma, noise_dn, rng)
