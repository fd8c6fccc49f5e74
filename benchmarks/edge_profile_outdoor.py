"""Timing from the light's disc: a disc-past-an-edge profile fit against the mid-level crossing (a script).

    PYTHONPATH=python python benchmarks/edge_profile_outdoor.py CAPTURE_DIR [--full]

CAPTURE_DIR: a simulated capture with its ``ground_truth.npz`` — ``gnomon simulate facade_sun`` (the sun's disc,
0.533°, behind a 5 cm pole 16 m from the facade) or ``gnomon simulate desk_lamp`` (the lamp's 3 mm disc behind the
stick). ``benchmarks/edge_profile.py`` fitted a Gaussian edge to each edge alone indoors (the room) and lost; here
the profile is what the geometry says. Seen from a surface point the light is a uniform disc of angular radius ρ
and the occluder a band of angular half-width α (a cylinder of radius r at distance h: sin α = r/h) whose centre
passes the disc's centre at time ``tc``; the disc's hidden fraction is the band's share of it,

    f(t) = D(x + b) − D(x − b),   x = (t − tc)/w,  b = a/w,   D(u) = ½ + (u·√(1 − u²) + asin u)/π,

``D`` the share of a unit disc below a chord at ``u`` (the circular segment), ``w`` the time the band takes to move
by ρ and ``a`` by α (frames). When α > ρ (an umbra) each edge is the circular-segment profile alone; when α < ρ
(beyond h = r/ρ = 10.7 m from the pole: the whole facade) the two edges overlap and the dip never reaches the
shadow's level. The truth's enter and leave times (the pole's tangent planes through the disc's centre) are
``tc − a`` and ``tc + a`` (a pixel whose fit moves either by more than ``GUARD`` = 0.5 frame from its mid-level
crossing keeps its crossings: a failed fit). Each timed pixel's dip, from 3 frames before its mid-level enter
crossing to 4 after its leave crossing, decoded to linear light and divided by the scan's own per-frame gain
(the illumination normaliser's), is fitted by least squares with ``I(t) = hi·(1 − f) + lo·f`` (``hi``, ``lo``
linear, solved exactly; ``tc`` and ``a`` by Gauss–Newton from the mid-level crossings):

* facade: ``w`` from the sun's path (the disc's centre leaves a vertical plane through the pole at
  ``cos e · dφ/dt``, φ the sun's azimuth in the world, e its elevation: the ephemeris the scan has);
* desk: ``w`` is not known (the stick is moved by hand): per pixel the one of ``W_CANDIDATES`` whose fit leaves
  the least residual, then the median over 15 × 15 px, and the fit again with it fixed (as ``edge_profile.py``
  did with its Gaussian's width).

Compared with the truth on the swept pixels both methods time: the time error (frames) and the depth through the
*true* shadow planes (% of the camera distance), per edge. ``--full``: the whole scan again with the profile's
times in place of the tracker's crossings (every pixel with a dip; the rest of the pipeline as shipped), scored as
``benchmarks/building_shadows.py`` scores a scan.
"""

from __future__ import annotations

import argparse
import glob
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import median_filter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import gnomon.capture.tracking as tracking  # noqa: E402
import gnomon.runs.scan as scan_run  # noqa: E402
from edge_profile import depth_through  # noqa: E402
from gnomon.runs.accuracy import depth_accuracy  # noqa: E402
from gnomon.runs.scan import ScanOptions, prepare_scan, run_scan, scan  # noqa: E402

BEFORE, AFTER = 3, 4
MAX_SPAN = 14         # frames between the mid-level crossings beyond which a pixel is not fitted
GUARD = 0.5           # frames: a fitted edge farther than this from its mid-level crossing is a failed fit
W_CANDIDATES = (0.3, 0.45, 0.6, 0.8, 1.0, 1.3, 1.7)   # frames: the disc's radius tried where it is not known


def disc_below(u: np.ndarray) -> np.ndarray:
    """Share of a unit disc below the chord at u (the circular segment's area fraction)."""
    u = np.clip(u, -1.0, 1.0)
    return 0.5 + (u * np.sqrt(1.0 - u * u) + np.arcsin(u)) / np.pi


def band_share(t: np.ndarray, tc: np.ndarray, a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Share of the disc (radius w frames) the band (half-width a frames, centred at tc) hides at times t."""
    x = (t - tc) / w
    b = a / w
    return disc_below(x + b) - disc_below(x - b)


def _levels_residual(y, t, m, tc, a, w):
    """Residuals (K, M) of the best hi, lo for the band at (tc, a) (weights m: 1 in the pixel's window)."""
    f = band_share(t, tc, a, w)
    u, v = (1.0 - f) * m, f * m
    suu, suv, svv = (u * u).sum(0), (u * v).sum(0), (v * v).sum(0)
    suy, svy = (u * y).sum(0), (v * y).sum(0)
    det = suu * svv - suv * suv + 1e-18
    hi = (svv * suy - suv * svy) / det
    lo = (suu * svy - suv * suy) / det
    return (hi * (1.0 - f) + lo * f - y) * m


def fit_band(y, t, m, tc, a, w, *, fit_w: bool = False, iterations: int = 15):
    """Gauss–Newton (finite differences) on tc, a (and w): y, t, m (K, M); returns tc, a, w, rms residual."""
    tc, a, w = tc.astype(np.float64).copy(), a.astype(np.float64).copy(), w.astype(np.float64).copy()
    h = 1e-4
    for _ in range(iterations):
        r = _levels_residual(y, t, m, tc, a, w)
        cols = [(_levels_residual(y, t, m, tc + h, a, w) - r) / h, (_levels_residual(y, t, m, tc, a + h, w) - r) / h]
        if fit_w:
            cols.append((_levels_residual(y, t, m, tc, a, w + h) - r) / h)
        J = np.stack(cols, axis=-1)                                    # (K, M, p)
        JtJ = np.einsum("kmp,kmq->mpq", J, J) + 1e-9 * np.eye(len(cols))
        Jtr = np.einsum("kmp,km->mp", J, r)
        step = -np.linalg.solve(JtJ, Jtr[..., None])[..., 0]
        step = np.clip(step, -0.5, 0.5)
        tc += step[:, 0]
        a = np.clip(a + step[:, 1], 0.05, MAX_SPAN)
        if fit_w:
            w = np.clip(w + step[:, 2], 0.15, 6.0)
    r = _levels_residual(y, t, m, tc, a, w)
    return tc, a, w, np.sqrt((r * r).sum(0) / np.maximum(m.sum(0), 1))


@dataclass
class Dips:
    """The timed pixels' samples: rows vv, cols uu; y (K, M) linear and gain-divided, t (K, M) tracker frames,
    m (K, M) window weights; mid-level enter and leave (M,) tracker frames."""

    vv: np.ndarray
    uu: np.ndarray
    y: np.ndarray
    t: np.ndarray
    m: np.ndarray
    enter: np.ndarray
    leave: np.ndarray


def gather_dips(enter_map, leave_map, mask, paths, used, gains, lut) -> Dips:
    vv, uu = np.nonzero(mask & np.isfinite(enter_map) & np.isfinite(leave_map)
                        & (leave_map - enter_map < MAX_SPAN))
    e, lv = enter_map[vv, uu].astype(np.float64), leave_map[vv, uu].astype(np.float64)
    N = len(used)
    K = BEFORE + AFTER + MAX_SPAN + 1
    k0 = np.clip(np.floor(e).astype(np.int64) - BEFORE + 1, 0, max(N - K, 0))
    ks = np.minimum(k0[None, :] + np.arange(K)[:, None], N - 1)       # (K, M)
    frames = np.stack([lut[cv2.imread(paths[c], cv2.IMREAD_GRAYSCALE)][vv, uu] for c in used]).astype(np.float64)
    frames /= np.asarray(gains, dtype=np.float64)[:, None]
    y = np.take_along_axis(frames, ks, axis=0)
    m = (ks <= np.ceil(lv)[None] + AFTER - 1).astype(np.float64)
    m[1:][ks[1:] == ks[:-1]] = 0.0                                     # clamped duplicates at the end
    return Dips(vv, uu, y, ks.astype(np.float64), m, e, lv)


def sun_disc_frames(gt: dict, used: np.ndarray) -> np.ndarray:
    """(tracker frames,) the time the sun's centre takes to move by its angular radius across a vertical plane
    through the pole (tracker frames): ρ / (cos e · |dφ/dt|)."""
    d = gt["sun_world"].astype(np.float64)
    phi = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    e = np.arcsin(np.clip(d[:, 2], -1, 1))
    rate = np.abs(np.gradient(phi)) * np.cos(e)                        # rad per capture frame
    rho = float(gt["sun_angular_radius_rad"])
    per_capture = rho / rate
    step = np.gradient(used.astype(np.float64)) if len(used) > 1 else np.ones(1)
    return per_capture[used] / step


def profile_times(d: Dips, w_pixels: np.ndarray | None, shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fitted enter and leave (tracker frames) and the w used; w_pixels None: fitted per pixel then smoothed."""
    tc0, a0 = (d.enter + d.leave) / 2, np.maximum((d.leave - d.enter) / 2, 0.1)
    if w_pixels is None:
        # w per pixel: the candidate of least residual (a free Gauss–Newton step in w wanders off: on the small
        # desk it settled at 1.24 frames with 7 times the residual of w = 0.6), then the median over 15 × 15 px
        best_r = np.full(len(tc0), np.inf)
        w_best = np.full(len(tc0), W_CANDIDATES[0])
        for wc in W_CANDIDATES:
            _, _, _, rr = fit_band(d.y, d.t, d.m, tc0, a0, np.full(len(tc0), wc), iterations=8)
            better = rr < best_r
            best_r, w_best = np.where(better, rr, best_r), np.where(better, wc, w_best)
        wmap = np.full(shape, float(np.median(w_best)))
        wmap[d.vv, d.uu] = w_best
        w_pixels = median_filter(wmap, size=15)[d.vv, d.uu]
    tc, a, _, _ = fit_band(d.y, d.t, d.m, tc0, a0, w_pixels)
    enter, leave = tc - a, tc + a
    # a fit that moved an edge by more than GUARD frames from its crossing failed (a cloud, a clipped span):
    # that pixel keeps its mid-level crossings
    failed = ~((np.abs(enter - d.enter) <= GUARD) & (np.abs(leave - d.leave) <= GUARD))
    enter[failed], leave[failed] = d.enter[failed], d.leave[failed]
    return enter, leave, w_pixels


class Tap:
    """Wraps the scan's tracking pass: keeps the last pass's tracked sequence and the illumination normaliser's
    accepted gains (the scan's own, one per tracker frame), and applies ``modify(tracked, gains)`` if given."""

    def __init__(self, modify=None) -> None:
        self.modify = modify
        self.tracked = None
        self.gains: list[float] = []

    def __enter__(self):
        tap = self
        self.gain0, self.track0 = tracking.IlluminationNormalizer.gain, scan_run.track_widening
        gain0, track0 = self.gain0, self.track0

        def gain(norm, frame):
            g = gain0(norm, frame)
            if g is not None:
                tap.gains.append(g)
            return g

        def track(*a, **k):
            tap.gains.clear()
            tracked, tracker, notes = track0(*a, **k)
            n = len(tracked.used)
            gains = tap.gains[-n:] if len(tap.gains) >= n else [1.0] * n
            tap.tracked, tap.gains = tracked, list(gains)
            if tap.modify is not None:
                tap.modify(tracked, gains)
            return tracked, tracker, notes

        tracking.IlluminationNormalizer.gain = gain  # type: ignore[method-assign]
        scan_run.track_widening = track
        return self

    def __exit__(self, *exc):
        tracking.IlluminationNormalizer.gain = self.gain0  # type: ignore[method-assign]
        scan_run.track_widening = self.track0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--full", action="store_true", help="also the whole scan with the profile's times")
    ap.add_argument("--out", type=Path, default=None, help="where --full writes its two scans (default: a temp dir)")
    args = ap.parse_args(argv)
    gt = dict(np.load(args.capture / "ground_truth.npz"))
    outdoor = "sun_world" in gt
    setup, source = prepare_scan(args.capture / "field_log.toml")
    with Tap() as tap:
        result = scan(setup, source)
    assert tap.tracked is not None
    used, gains = np.asarray(tap.tracked.used), tap.gains
    lut = tracking.decoding_lut(setup.tracker.gamma, np.uint8)
    paths = sorted(glob.glob(str(args.capture / "frames" / "*")))
    times = result.times
    shape = times.enter.shape
    dips = gather_dips(times.enter, times.leave, gt["swept"] & times.valid, paths, used, gains, lut)
    w_pix = sun_disc_frames(gt, used)[np.clip(np.rint((dips.enter + dips.leave) / 2).astype(int), 0,
                                              len(used) - 1)] if outdoor else None
    p_enter, p_leave, w_used = profile_times(dips, w_pix, shape)
    dist = float(gt["camera_distance"]) if outdoor else float(gt["camera_distance_mm"])
    R, t = gt["R"], gt["t"]
    C = -R.T @ t
    vv, uu = dips.vv, dips.uu
    P = gt["points_world"][vv, uu].astype(np.float64)
    rays = (P - C) / np.linalg.norm(P - C, axis=1, keepdims=True)
    Z = gt["depth"][vv, uu].astype(np.float64)
    idx = np.arange(len(used), dtype=np.float64)

    def capture_time(tt):
        return np.interp(tt, idx, used.astype(np.float64))

    print(f"{args.capture}: {len(vv)} swept pixels timed, {len(used)} tracker frames; w (disc radius) median "
          f"{np.median(w_used):.2f} frames (p10/p90 {np.percentile(w_used, 10):.2f}/{np.percentile(w_used, 90):.2f}"
          f"{', from the sun' if outdoor else ', fitted and smoothed'})")
    scan_edges = {e.name: e.times for e in result.edges}
    for name, mid, fitted, truth_key, planes_key in (
            ("enter", dips.enter, p_enter, "enter_time", "shadow_planes_enter"),
            ("leave", dips.leave, p_leave, "leave_time", "shadow_planes_leave"),
            ("centre", (dips.enter + dips.leave) / 2, (p_enter + p_leave) / 2, "center_time",
             "shadow_planes_center")):
        if truth_key not in gt:
            continue
        truth = gt[truth_key][vv, uu].astype(np.float64)
        ok = np.isfinite(truth) & np.isfinite(fitted)
        rows = [("mid-level", mid), ("disc profile", fitted)]
        if name in scan_edges:  # the scan's own times for this edge (re-timed; a sun scan with a pole: the centre)
            scan_t = scan_edges[name][vv, uu].astype(np.float64)
            ok &= np.isfinite(scan_t)
            rows.insert(1, ("scan", scan_t))
        for label, tt in rows:
            tcap = capture_time(tt[ok])
            err = tcap - truth[ok]
            zerr = 100.0 * (depth_through(gt[planes_key], tcap, C, rays[ok], R, t) - Z[ok]) / dist
            print(f"  {name} {label:13s} time error RMS {np.sqrt(np.mean(err ** 2)):.3f} median|.| "
                  f"{np.median(np.abs(err)):.3f} mean {np.mean(err):+.3f} frames; depth RMS "
                  f"{np.sqrt(np.mean(zerr ** 2)):.4f} median|.| {np.median(np.abs(zerr)):.4f} % ({ok.sum()} px)")
    if args.full:
        out = args.out or Path(tempfile.mkdtemp(prefix="gnomon-edge-profile-"))
        full_comparison(args.capture, out, gt, paths, lut, outdoor, dist)
    return 0


def full_comparison(capture: Path, out_root: Path, gt: dict, paths: list[str], lut: np.ndarray, outdoor: bool,
                    dist: float) -> None:
    def with_profile_times(tracked, gains):
        used = np.asarray(tracked.used)
        tm = tracked.times
        d = gather_dips(tm.enter, tm.leave, tm.valid, paths, used, gains, lut)
        w_pix = sun_disc_frames(gt, used)[np.clip(np.rint((d.enter + d.leave) / 2).astype(int), 0,
                                                  len(used) - 1)] if outdoor else None
        e, lv, _ = profile_times(d, w_pix, tm.enter.shape)
        good = np.isfinite(e) & np.isfinite(lv) & (e >= 0) & (lv <= len(used) - 1) & (e < lv)
        tm.enter[d.vv[good], d.uu[good]] = e[good]
        tm.leave[d.vv[good], d.uu[good]] = lv[good]
        print(f"  (profile times on {int(good.sum())} of {len(d.vv)} timed pixels)")

    units = "m" if outdoor else "mm"
    for label, modify in (("mid-level crossing (shipped)", None), ("disc profile", with_profile_times)):
        with Tap(modify):
            out = out_root / f"scan_{'profile' if modify else 'shipped'}"
            res = run_scan(capture / "field_log.toml", out, ScanOptions(progress=False, rrd=False))
        acc = depth_accuracy(res.depth, gt["depth"], gt["swept"], dist, units, sigma=res.sigma,
                             swept_surface=gt.get("swept_surface"))
        print(acc.table(f"full scan, {label}"))


if __name__ == "__main__":
    raise SystemExit(main())
