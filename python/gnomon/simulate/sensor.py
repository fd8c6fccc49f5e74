"""The simulated camera's optics and sensor, shared by every scene.

Linear radiance → optical blur (Gaussian, on the linear image rendered with a
margin, then cropped: border pixels are blurred with the real scene beyond the
border) → gamma encoding → Gaussian sensor noise in DN → quantisation to u8.
Also the ground-truth files every scene writes beside its capture.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon.util import atomic

AMBIENT = 0.1  # ambient irradiance of the desk scenes (radiance = albedo · AMBIENT)


def blur_and_crop(L_full: np.ndarray, sigma_px: float, crop) -> np.ndarray:
    """Blur the padded linear image by ``sigma_px`` (0 = none) and crop it to the frame."""
    L: np.ndarray = np.asarray(L_full, dtype=np.float32)
    if sigma_px > 0:
        L = cv2.GaussianBlur(L, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REFLECT)
    return np.ascontiguousarray(L[crop])


def encode_dn(L_blurred: np.ndarray, gamma: float, noise_dn: float, rng: np.random.Generator) -> np.ndarray:
    """Gamma-encode, add sensor noise, quantise: linear (blurred) radiance in [0, 1] → u8."""
    dn = 255.0 * np.power(np.clip(L_blurred, 0.0, 1.0, dtype=np.float32), np.float32(1.0 / gamma))
    if noise_dn > 0:
        dn += np.float32(noise_dn) * rng.standard_normal(dn.shape, dtype=np.float32)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


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
