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

A fused point whose own σ is too large for the scan's depth-jump test to tell
which surface it lies on is flagged (:func:`beyond_trust`, counted in
report.json): two points of one surface, each with that σ and independent
errors, differ by ``√2·σ`` (1σ), and the neighbour support, the conflict test
and the mesh join points only when they lie within ``max_relative_jump·Z``;
beyond ``σ = max_relative_jump·Z / (TRUST_SIGMAS·√2)`` a surface's own points
would fall apart by chance more often than once in a million pairs. They are
counted, not refused: where the errors are shared by neighbours (rays grazing
the shadow planes, as in the phone captures of docs/method.md) the surface
holds together at a far larger σ, and such a scan would lose most of its points.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CONFLICT_SIGMAS", "METHODS", "TRUST_SIGMAS", "beyond_trust", "fuse_depths", "fusion_weights",
           "trust_limit"]

CONFLICT_SIGMAS = 6.0
METHODS = ("gaussian", "sigmoid")
# Two points of one surface must stay within the depth jump at this many σ of their difference.
TRUST_SIGMAS = 5.0


def trust_limit(depth: np.ndarray, max_relative_jump: float) -> np.ndarray:
    """The largest σZ (world units, like ``depth``) the scan trusts at each depth:
    ``max_relative_jump·|Z| / (TRUST_SIGMAS·√2)`` (see the module)."""
    return max_relative_jump * np.abs(np.asarray(depth, dtype=np.float64)) / (TRUST_SIGMAS * np.sqrt(2.0))


def beyond_trust(depth: np.ndarray, sigma: np.ndarray, max_relative_jump: float) -> np.ndarray:
    """(H, W) bool: points (finite depth) whose σZ exceeds :func:`trust_limit`. A point without a finite σ
    is not judged here (it is not refused)."""
    z = np.asarray(depth, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & np.isfinite(s) & (s > trust_limit(z, max_relative_jump))


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
