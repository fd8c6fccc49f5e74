"""The simulated camera's optics and sensor, shared by every scene.

Linear radiance → optical blur (Gaussian, on the linear image rendered with a
margin, then cropped: border pixels are blurred with the real scene beyond the
border) → gamma encoding → Gaussian sensor noise in DN → quantisation to u8.
"""

from __future__ import annotations

import cv2
import numpy as np


def blur_and_crop(L_full: np.ndarray, sigma_px: float, crop) -> np.ndarray:
    """Blur the padded linear image by ``sigma_px`` (0 = none) and crop it to the frame."""
    L = np.asarray(L_full, dtype=np.float32)
    if sigma_px > 0:
        L = cv2.GaussianBlur(L, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REFLECT)
    return np.ascontiguousarray(L[crop])


def encode_dn(L_blurred: np.ndarray, gamma: float, noise_dn: float, rng: np.random.Generator) -> np.ndarray:
    """Gamma-encode, add sensor noise, quantise: linear (blurred) radiance in [0, 1] → u8."""
    dn = 255.0 * np.power(np.clip(L_blurred, 0.0, 1.0, dtype=np.float32), np.float32(1.0 / gamma))
    if noise_dn > 0:
        dn += np.float32(noise_dn) * rng.standard_normal(dn.shape, dtype=np.float32)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)
