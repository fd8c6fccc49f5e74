"""Timing that uses the whole edge: an edge-profile fit against the mid-level crossing (a script, not a test).

    PYTHONPATH=python python benchmarks/edge_profile.py CAPTURE_DIR

CAPTURE_DIR is a simulated capture with its ``ground_truth.npz`` (``gnomon simulate room``, or any lamp
scene). The script scans it in memory (the shipped pipeline) and, on the same frames, times each swept pixel's
entering and leaving edge three ways:

* **mid-level**: the tracker's crossing of the half-way level (linear light, the two samples around it);
* **scan**: the scan's edge times (the tracker's, re-timed between the isochrones where the sweep is fast,
  :mod:`gnomon.reconstruct.retiming`);
* **profile fit**: every sample of the transition, from 3 frames before the mid-level crossing to 4 after,
  normalised to the dip's levels ``s = (Imax − I)/(Imax − Imin)`` (linear light), fitted by least squares with
  the edge's profile ``s(t) = Φ((t − t0)/w)`` (a Gaussian edge: the lamp's disc seen past the stick's edge
  convolved with the pixel's footprint is close to it), first ``t0`` and ``w`` per pixel (Gauss–Newton), then
  ``t0`` alone with ``w`` the median of the fitted widths over 15 × 15 px around the pixel (a penumbra's width
  in frames changes slowly over a surface; two or three samples do not fix it per pixel).

Each is compared with the truth's crossing time of the penumbra's centre (``enter_time`` / ``leave_time``) and,
to see what it does to the depth alone, turned into a depth through the *true* shadow planes (interpolated
linearly between frames, as the triangulation does): RMS and median of the time error (frames) and of the
depth error (% of the camera distance) over the swept pixels both methods time.

``--full``: then the whole scan again with the profile fit's times (local levels, ``w`` smoothed) in place of
the tracker's crossings on every pixel with a dip (the planes, the re-timing, the fusion and the screen as
shipped), scored as ``benchmarks/room_light.py`` scores a scan: the depth through the measured planes.
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import median_filter
from scipy.special import erf

import gnomon.runs.scan as scan_run
from gnomon.capture.tracking import decoding_lut
from gnomon.runs.scan import prepare_scan, scan

BEFORE, AFTER = 3, 4  # frames of the window around the mid-level crossing


def profile(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + erf(x / np.sqrt(2.0)))


def fit_edges(frames: np.ndarray, t_mid: np.ndarray, hi: np.ndarray, lo: np.ndarray, falling: bool,
              width: np.ndarray | None = None, iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel (1-D arrays of M pixels; ``frames`` (N, M) linear): the profile's t0 and w (frames) by least
    squares over the window around ``t_mid``; ``width`` fixed (M,) or None to fit it too."""
    N, M = frames.shape
    k0 = np.clip(np.floor(t_mid).astype(np.int64) - BEFORE + 1, 0, N - (BEFORE + AFTER))
    ks = k0[None, :] + np.arange(BEFORE + AFTER)[:, None]           # (K, M)
    samples = np.take_along_axis(frames, ks, axis=0)
    s = (hi - samples) / np.maximum(hi - lo, 1e-9)
    if not falling:
        s = 1.0 - s  # a rising edge: fit the lit fraction's return as the same profile
    t = ks.astype(np.float64)
    t0 = t_mid.astype(np.float64).copy()
    w = np.full(M, 0.6) if width is None else width.astype(np.float64)
    for _ in range(iterations):
        x = (t - t0) / w
        r = profile(x) - s
        g = np.exp(-0.5 * x * x) / np.sqrt(2 * np.pi)                # dΦ/dx
        j_t0 = -g / w
        if width is None:
            j_w = -g * x / w
            a, b, c = (j_t0 * j_t0).sum(0), (j_t0 * j_w).sum(0), (j_w * j_w).sum(0)
            e, f = (j_t0 * r).sum(0), (j_w * r).sum(0)
            det = a * c - b * b + 1e-12
            d_t0 = -(c * e - b * f) / det
            d_w = -(a * f - b * e) / det
            t0 += np.clip(d_t0, -1.0, 1.0)
            w = np.clip(w + np.clip(d_w, -0.5, 0.5), 0.15, 4.0)
        else:
            t0 += np.clip(-(j_t0 * r).sum(0) / ((j_t0 * j_t0).sum(0) + 1e-12), -1.0, 1.0)
    return t0, w


def _residuals(y: np.ndarray, ks: np.ndarray, t0: np.ndarray, w: np.ndarray, falling: bool) -> np.ndarray:
    """(G, m) least-squares residual of the samples y (K, m) at frames ks (K, m) for each candidate t0 (G, m),
    the edge's two levels free (linear least squares: variable projection)."""
    x = (ks[None] - t0[:, None, :]) / w[None, None]
    phi = profile(x)
    if not falling:
        phi = 1.0 - phi
    u, v = 1.0 - phi, phi                                              # I = hi·u + lo·v
    suu, suv, svv = (u * u).sum(1), (u * v).sum(1), (v * v).sum(1)
    suy, svy = (u * y[None]).sum(1), (v * y[None]).sum(1)
    det = suu * svv - suv * suv + 1e-18
    hi = (svv * suy - suv * svy) / det
    lo = (suu * svy - suv * suy) / det
    return ((hi[:, None] * u + lo[:, None] * v - y[None]) ** 2).sum(1)


def fit_free_levels(frames: np.ndarray, t_mid: np.ndarray, width: np.ndarray, falling: bool,
                    chunk: int = 20000) -> np.ndarray:
    """t0 per pixel with the edge's two levels free (local, not the whole sequence's extremes): the t0 of least
    residual (:func:`_residuals`) within ±1 frame of ``t_mid``, searched at 0.1 then 0.01 frame;
    ``width`` (M,) the profile's w."""
    N, M = frames.shape
    out = np.empty(M)
    for a in range(0, M, chunk):
        sl = slice(a, min(a + chunk, M))
        tm, w = t_mid[sl], width[sl]
        k0 = np.clip(np.floor(tm).astype(np.int64) - BEFORE + 1, 0, N - (BEFORE + AFTER))
        ks = k0[None, :] + np.arange(BEFORE + AFTER)[:, None]
        y = np.take_along_axis(frames[:, sl], ks, axis=0)
        best = tm.copy()
        for step, half in ((0.1, 1.0), (0.01, 0.1)):
            cand = best[None] + np.arange(-half, half + step / 2, step)[:, None]
            best = np.take_along_axis(cand, np.argmin(_residuals(y, ks, cand, w, falling), axis=0)[None], 0)[0]
        out[sl] = best
    return out


def depth_through(planes: np.ndarray, times: np.ndarray, C: np.ndarray, rays: np.ndarray, R: np.ndarray,
                  t: np.ndarray) -> np.ndarray:
    """Camera Z where each pixel's ray (world, unit) meets the true plane at its time (planes interpolated)."""
    k = np.clip(np.floor(times).astype(np.int64), 0, len(planes) - 2)
    f = (times - k)[:, None]
    pl = planes[k] * (1 - f) + planes[k + 1] * f
    n, d = pl[:, :3], pl[:, 3]
    lam = (d - n @ C) / np.einsum("ij,ij->i", n, rays)
    X = C + lam[:, None] * rays
    return (X @ R.T + t)[:, 2]


def linear_levels(dn: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """Fractional DN levels → linear, interpolating the decoding table."""
    return np.interp(dn, np.arange(len(lut)), lut)


def profile_times(tracked, paths: list[str], lut: np.ndarray) -> None:
    """Replace, in place, every timed pixel's entering and leaving time by the profile fit's (local levels,
    ``w`` fitted per pixel then smoothed over 15 × 15 px)."""
    times = tracked.times
    for name, falling in (("enter", True), ("leave", False)):
        mid_map = getattr(times, name)
        vv, uu = np.nonzero(np.isfinite(mid_map))
        frames = np.stack([lut[cv2.imread(p, cv2.IMREAD_GRAYSCALE)][vv, uu] for p in paths]).astype(np.float64)
        mid = mid_map[vv, uu].astype(np.float64)
        hi, lo = linear_levels(times.imax[vv, uu], lut), linear_levels(times.imin[vv, uu], lut)
        _, w = fit_edges(frames, mid, hi, lo, falling)
        wmap = np.full(mid_map.shape, float(np.median(w)))
        wmap[vv, uu] = w
        w_smooth = median_filter(wmap, size=15)[vv, uu]
        mid_map[vv, uu] = np.clip(fit_free_levels(frames, mid, w_smooth, falling), 0, len(paths) - 1)


def full_comparison(capture: Path, paths: list[str], lut: np.ndarray) -> None:
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from gnomon import api
    from room_light import figures

    gt = dict(np.load(capture / "ground_truth.npz"))
    shipped = api.scan(capture / "field_log.toml")
    original = scan_run.track_widening

    def with_profile_times(*a, **k):
        tracked, tracker, notes = original(*a, **k)
        profile_times(tracked, paths, lut)
        return tracked, tracker, notes

    scan_run.track_widening = with_profile_times
    try:
        fitted = api.scan(capture / "field_log.toml")
    finally:
        scan_run.track_widening = original
    for label, sc in (("mid-level crossing (shipped)", shipped), ("profile fit", fitted)):
        f = figures(sc, gt)
        print(f"  full scan, {label:28s}: depth RMS {f['depth_rms_pct']:.4f} median {f['depth_median_pct']:.4f} % "
              f"of the distance, coverage {f['coverage_swept_pct']:.2f} %, false points {f['false_point_pct']:.2f} %, "
              f"error/σ RMS {f['sigma_rms_ratio']:.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--full", action="store_true", help="also the whole scan with the profile fit's times")
    args = ap.parse_args(argv)
    setup, source = prepare_scan(args.capture / "field_log.toml")
    result = scan(setup, source)
    gt = dict(np.load(args.capture / "ground_truth.npz"))
    lut = decoding_lut(setup.tracker.gamma, np.uint8)
    paths = sorted(glob.glob(str(args.capture / "frames" / "*")))
    times = result.times
    swept = gt["swept"] & times.valid
    vv, uu = np.nonzero(swept)
    frames = np.stack([lut[cv2.imread(p, cv2.IMREAD_GRAYSCALE)][vv, uu] for p in paths]).astype(np.float64)
    hi, lo = linear_levels(times.imax[vv, uu], lut), linear_levels(times.imin[vv, uu], lut)
    R, t = gt["R"], gt["t"]
    C = -R.T @ t
    P = gt["points_world"][vv, uu].astype(np.float64)
    rays = (P - C) / np.linalg.norm(P - C, axis=1, keepdims=True)
    Z = gt["depth"][vv, uu].astype(np.float64)
    dist = float(gt["camera_distance_mm"])
    print(f"{args.capture}: {len(vv)} swept pixels with a dip, {len(paths)} frames")
    for name, falling, mid_map, planes_key, truth_key, edge in (
            ("enter", True, times.enter, "shadow_planes_enter", "enter_time", 0),
            ("leave", False, times.leave, "shadow_planes_leave", "leave_time", 1)):
        mid = mid_map[vv, uu].astype(np.float64)
        truth = gt[truth_key][vv, uu].astype(np.float64)
        ok = np.isfinite(mid) & np.isfinite(truth)
        t0, w = fit_edges(frames[:, ok], mid[ok], hi[ok], lo[ok], falling)
        wmap = np.full(gt["swept"].shape, np.nan)
        wmap[vv[ok], uu[ok]] = w
        filled = np.where(np.isfinite(wmap), wmap, np.nanmedian(w))
        w_smooth = median_filter(filled, size=15)[vv[ok], uu[ok]]
        t_fit, _ = fit_edges(frames[:, ok], mid[ok], hi[ok], lo[ok], falling, width=w_smooth)
        t_free = fit_free_levels(frames[:, ok], mid[ok], w_smooth, falling)
        scan_t = result.edges[edge].times[vv, uu][ok].astype(np.float64)
        planes = gt[planes_key]
        print(f"  {name} edge: {ok.sum()} pixels, fitted width w median {np.median(w):.2f} frames "
              f"(p10/p90 {np.percentile(w, 10):.2f}/{np.percentile(w, 90):.2f})")
        for label, tt in (("mid-level", mid[ok]), ("scan (re-timed)", scan_t), ("profile, w per pixel", t0),
                          ("profile, w smoothed", t_fit), ("profile, local levels", t_free)):
            good = np.isfinite(tt)
            err = (tt - truth[ok])[good]
            zerr = 100.0 * (depth_through(planes, tt[good], C, rays[ok][good], R, t) - Z[ok][good]) / dist
            print(f"    {label:22s} time error RMS {np.sqrt(np.mean(err ** 2)):.3f} median|.| "
                  f"{np.median(np.abs(err)):.3f} mean {np.mean(err):+.3f} frames; depth RMS "
                  f"{np.sqrt(np.mean(zerr ** 2)):.4f} median|.| {np.median(np.abs(zerr)):.4f} % "
                  f"({good.sum()} px)")
    if args.full:
        full_comparison(args.capture, paths, lut)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
