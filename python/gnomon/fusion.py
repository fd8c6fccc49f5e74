"""Fusing per-pixel depth estimates: the two shadow edges of one scan, or two scans.

Bouguet & Perona (§5) fuse two scans of the same scene (lamp left and right)
as ``Z = wA·ZA + wB·ZB`` with either

* Gaussian weights, ``wA = σB²/(σA² + σB²)`` — the inverse-variance mean,
  which generalises to any number of estimates: ``Z = Σ Zi/σi² / Σ 1/σi²``,
  ``σ = 1/sqrt(Σ 1/σi²)``;
* the paper's sigmoid weights: with ``α = σB/σA``,
  ``ΔV = (α² − 1)/(α² + 1)``, ``wA = 1/(1 + exp(−β·ΔV))``, ``wB = 1 − wA``;
  β → ∞ picks the better estimate outright.

Estimates that differ by more than ``CONFLICT_SIGMAS`` combined σ *and* by
more than a depth jump (``max_relative_jump·Z``) cannot be the same surface
point (a mixed pixel at an occlusion, a glint): such pixels are dropped and
counted. σ models image noise only, so smaller disagreements (sampling and
model errors) are averaged, not discarded.
"""

from __future__ import annotations

import numpy as np

CONFLICT_SIGMAS = 6.0
METHODS = ("gaussian", "sigmoid")


def fusion_weights(sigmas: np.ndarray, method: str = "gaussian", beta: float = 10.0) -> np.ndarray:
    """Per-estimate weights (K, H, W) summing to 1 where any estimate exists (NaN σ = absent)."""
    ok = np.isfinite(sigmas) & (sigmas > 0)
    if method == "gaussian":
        w = np.where(ok, 1.0 / np.where(ok, sigmas, 1.0) ** 2, 0.0)
    elif method == "sigmoid":
        if len(sigmas) != 2:
            raise ValueError("the sigmoid weights fuse exactly two estimates")
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            alpha = sigmas[1] / sigmas[0]
            dv = (alpha**2 - 1) / (alpha**2 + 1)
            wa = 1.0 / (1.0 + np.exp(-beta * dv))
        both = ok[0] & ok[1]
        wa = np.where(both, wa, np.where(ok[0], 1.0, 0.0))
        wb = np.where(both, 1.0 - wa, np.where(ok[1], 1.0, 0.0))
        w = np.stack([wa, wb])
    else:
        raise ValueError(f"unknown fusion method {method!r} (expected one of {METHODS})")
    total = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, w / np.where(total > 0, total, 1.0), 0.0)


def fuse_depths(depths: list[np.ndarray], sigmas: list[np.ndarray], max_relative_jump: float,
                method: str = "gaussian", beta: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fuse per-pixel depth maps with their σ; returns (depth, σ, conflict), NaN = none."""
    z = np.stack(depths).astype(np.float64)
    s = np.stack(sigmas).astype(np.float64)
    ok = np.isfinite(z) & np.isfinite(s) & (s > 0)
    s = np.where(ok, s, np.nan)
    w = fusion_weights(s, method, beta)
    any_ok = ok.any(axis=0)
    fused = np.where(any_ok, np.sum(w * np.where(ok, z, 0.0), axis=0), np.nan)
    # σ of a weighted mean of independent estimates
    sigma = np.where(any_ok, np.sqrt(np.sum((w * np.where(ok, s, 0.0)) ** 2, axis=0)), np.nan)
    hi = np.max(np.where(ok, z, -np.inf), axis=0)
    lo = np.min(np.where(ok, z, np.inf), axis=0)
    combined = np.sqrt(np.sum(np.where(ok, s, 0.0) ** 2, axis=0))
    with np.errstate(invalid="ignore"):
        conflict = (ok.sum(axis=0) >= 2) & (hi - lo > np.maximum(CONFLICT_SIGMAS * combined,
                                                                 max_relative_jump * np.abs(fused)))
    fused[conflict] = np.nan
    sigma[conflict] = np.nan
    return fused.astype(np.float32), sigma.astype(np.float32), conflict
