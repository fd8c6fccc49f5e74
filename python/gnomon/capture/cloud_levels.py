"""Levelling the frames of a cloud dip pixel by pixel, so the tracker can see a shadow pass under it.

Outdoors a pixel's irradiance is the direct sun's term plus the sky's,
``x_p = D·dir_p + S·sky_p``: a shadowed pixel sees only the sky, a lit one
both. A cloud dims the direct term (``D`` falls) and brightens the sky's
(``S`` rises), by amounts that both follow the cloud's optical depth: so a
pixel's departure from its clear level is, to first order, its own multiple
``β_p`` of the frame's departure for the average lit pixel,

    a_p(k) − 1 = β_p · (λ_k − 1),

where ``a_p(k) = x_p(k) / ℓ_p`` is the pixel's level in cloud frame ``k``
against its clear level ``ℓ_p`` (from the clear frames around the dip) and
``λ_k`` the frame's global gain against the clear light (the
:class:`gnomon.capture.tracking.IlluminationNormalizer`'s gain over the gain the
clear frames around the dip give). ``β_p`` is 1 for the average lit pixel,
larger where less of the light is sky (the pixel dims more), near 0 or below
for a pixel already in a shadow (the sky alone: it brightens). One global
gain per frame levels only ``β = 1``; per pixel, a cloud frame is levelled by
``1 + β_p (λ_k − 1)``.

``β_p`` is the least-squares fit over the dip's frames. A shadow passing
during the cloud (the pole's: one or two frames) lowers ``a_p`` in those
frames and so raises the fit; the shadow's line is thin, while ``β`` is a
property of the surface (its share of sky light, not its albedo), shared by
its neighbours: a pixel's ``β`` is capped at the median of its neighbourhood
plus a fixed margin (``BETA_MARGIN``).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["HeldFrame", "cloud_levels"]

# A pixel whose clear level changes by more than this (log) between the frames around the dip
# (a shadow at one end) takes the brighter of the two instead of their interpolation.
CLEAR_CHANGE = 0.1
# Linear irradiance (of the full scale, in the clear light) below which a pixel's β is not fitted.
LEVEL_FLOOR = 0.01
# Neighbourhood (px) whose median β caps a pixel's own fit.
MEDIAN_SIZE = 9
# What a pixel's β may exceed its neighbourhood's median by (β units).
BETA_MARGIN = 0.1
# β is quantised for the median in steps of BETA_STEP over [BETA_MIN, BETA_MIN + 255·BETA_STEP].
BETA_MIN = -2.0
BETA_STEP = 0.02
# Per-pixel levels are clamped to this range (a level is a factor on the frame's clear gain).
LEVEL_RANGE = (0.05, 20.0)


@dataclass(frozen=True)
class HeldFrame:
    """A frame of a cloud dip waiting to be levelled: its DN and its measured global gain."""

    grey: np.ndarray
    gain: float


def cloud_levels(lut: np.ndarray, before: np.ndarray, gain_before: float, after: np.ndarray,
                 gain_after: float, held: list[HeldFrame]) -> list[tuple[float, np.ndarray]]:
    """Per held frame, its clear gain and per-pixel levels ``(gain, levels (H, W) float32)`` for
    :meth:`gnomon._kernel.TemporalTracker.update`.

    ``before``/``after``: the clear (accepted) frames around the dip (DN), with their gains;
    ``held``: the dip's frames in order. The clear gain of held frame ``k`` is interpolated (in
    log) between ``gain_before`` and ``gain_after``; its levels are ``1 + β_p (λ_k − 1)``, see the
    module docstring.
    """
    n = len(held)
    if n == 0:
        return []
    positions = np.arange(1, n + 1) / (n + 1)
    log_b, log_a = np.log(gain_before), np.log(gain_after)
    clear_gain = np.exp(log_b + positions * (log_a - log_b))
    lam = np.array([h.gain for h in held]) / clear_gain - 1.0   # λ_k − 1 (< 0 in a dip)
    xb = lut[before] / np.float32(gain_before)
    xa = lut[after] / np.float32(gain_after)
    with np.errstate(divide="ignore", invalid="ignore"):
        change = np.abs(np.log(xa / xb))
    steady = change <= CLEAR_CHANGE
    fit = np.minimum(xa, xb) > LEVEL_FLOOR
    num = np.zeros(before.shape, np.float64)
    for k, h in enumerate(held):
        clear = np.where(steady, xb + np.float32(positions[k]) * (xa - xb), np.maximum(xa, xb))
        with np.errstate(divide="ignore", invalid="ignore"):
            a = lut[h.grey] / np.float32(clear_gain[k]) / clear
        num += np.where(fit, (a - 1.0) * lam[k], 0.0)
    den = float(np.sum(lam * lam))
    if den < 1e-6:
        beta = np.ones(before.shape, np.float32)
    else:
        beta = np.where(fit, num / den, 1.0).astype(np.float32)
        beta = _cap_by_neighbours(beta, fit)
    out = []
    for k in range(n):
        levels = np.clip(1.0 + beta * np.float32(lam[k]), *LEVEL_RANGE).astype(np.float32)
        out.append((float(clear_gain[k]), levels))
    return out


def _cap_by_neighbours(beta: np.ndarray, fit: np.ndarray) -> np.ndarray:
    """``β`` capped at its neighbourhood's median (a shadow during the dip only raises a fit)."""
    code = np.clip(np.rint((beta - BETA_MIN) / BETA_STEP), 0, 255).astype(np.uint8)
    median = cv2.medianBlur(code, MEDIAN_SIZE).astype(np.float32) * BETA_STEP + BETA_MIN
    return np.where(fit, np.minimum(beta, median + BETA_MARGIN), beta).astype(np.float32)
