"""An independent textbook shadow scanner, to find where Gnomon loses pixels on a real capture (a script, not a test).

    PYTHONPATH=python python benchmarks/textbook_reference.py CAPTURE_DIR [--masks DIR | --rects JSON] [--out DIR]

``CAPTURE_DIR`` is a folder written by ``benchmarks/real_captures.py`` (its
``field_log.toml``, ``camera.toml`` and ``scan/``). The reference reuses only
what Gnomon was *given or measured from the markers* (the camera file and
each plane's pose from ``scan/report.json``) and the same reference regions
(``--masks``: a folder with ``<plane>_mask.png``, default the capture's
``regions/``; or ``--rects`` '{"desk": [u0, v0, u1, v1], ...}'). Everything
else is the textbook method (Bouguet & Perona 1998, as taught in CMU 15-463),
written here from its description, with no Gnomon code:

1. per pixel, ``Imax`` and ``Imin`` over the whole sequence, the shadow
   threshold half-way between them (in decoded sRGB irradiance), and the
   shadow time of each edge: the first fall through the threshold (entering)
   and the first rise after it (leaving), linearly interpolated between frames;
   pixels with ``Imax − Imin`` below ``--min-contrast`` DN have none;
2. per frame and plane, the shadow edge in the plane's region, straight
   from the frames: along every row of the region the sub-pixel column where
   ``I − Ishadow`` changes sign in the edge's sense (leading edge: lit ahead,
   dark behind), back-projected onto the plane, and a total-least-squares line
   with one 3σ rejection;
3. per frame the shadow plane through both planes' lines (the least-squares
   plane through points sampled along them; no light position);
4. per pixel the ray meets the plane interpolated between the two frames
   around its time; the two edges' points are averaged when both exist and
   agree within 2 % of the depth.

It writes ``depth.npy``, ``shadow_time.npy`` and a copy of ``report.json``
into ``--out`` (so ``benchmarks/score.py`` scores it like a scan), then
compares with Gnomon's scan stage by stage: of the pixels with a reference
shadow time, how many have none in Gnomon and why (no dip deeper than
``min_contrast``, two comparable dips, contrast under the noise gate), how many
have a time but no point (no shadow plane near their time, or dropped later),
and the planes' agreement frame by frame.
"""

from __future__ import annotations

import argparse
import glob
import json
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def srgb_to_linear(dn: np.ndarray) -> np.ndarray:
    x = dn.astype(np.float32) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def load_frames(pattern: str) -> np.ndarray:
    paths = sorted(glob.glob(pattern))
    if not paths:
        raise SystemExit(f"no frames match {pattern}")
    first = cv2.imread(paths[0], cv2.IMREAD_GRAYSCALE)
    stack = np.empty((len(paths), *first.shape), dtype=np.uint8)
    for i, p in enumerate(paths):
        stack[i] = cv2.imread(p, cv2.IMREAD_GRAYSCALE)
    return stack


def temporal_times(frames: np.ndarray, min_contrast: float) -> dict[str, np.ndarray]:
    """Per pixel: Imax, Imin (DN), the threshold (linear), entering and leaving times (frames, NaN = none)."""
    n, h, w = frames.shape
    lut = srgb_to_linear(np.arange(256))
    imax = frames.max(axis=0)
    imin = frames.min(axis=0)
    thr = 0.5 * (lut[imax] + lut[imin])
    enter = np.full((h, w), np.nan, np.float32)
    leave = np.full((h, w), np.nan, np.float32)
    for r0 in range(0, h, 64):  # rows in chunks: (n, 64, w) float32
        v = lut[frames[:, r0:r0 + 64]]
        t = thr[r0:r0 + 64][None]
        below = v < t
        fall = ~below[:-1] & below[1:]  # frame k lit, k+1 dark
        has_fall = fall.any(axis=0)
        k = np.argmax(fall, axis=0)
        a = np.take_along_axis(v, k[None], 0)[0]
        b = np.take_along_axis(v, k[None] + 1, 0)[0]
        tt = t[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            te = k + (a - tt) / (a - b)
        rise = below[:-1] & ~below[1:]
        idx = np.arange(n - 1)[:, None, None]
        rise &= idx > k[None]
        has_rise = rise.any(axis=0)
        j = np.argmax(rise, axis=0)
        a2 = np.take_along_axis(v, j[None], 0)[0]
        b2 = np.take_along_axis(v, j[None] + 1, 0)[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            tl = j + (tt - a2) / (b2 - a2)
        enter[r0:r0 + 64] = np.where(has_fall, te, np.nan)
        leave[r0:r0 + 64] = np.where(has_fall & has_rise, tl, np.nan)
    ok = (imax.astype(np.float32) - imin) >= min_contrast
    enter[~ok] = np.nan
    leave[~ok] = np.nan
    return {"imax": imax, "imin": imin, "thr": thr, "enter": enter, "leave": leave, "contrast_ok": ok}


class Camera:
    def __init__(self, path: Path):
        import tomllib

        c = tomllib.loads(path.read_text())
        self.K = np.array([[c["fx"], 0, c["cx"]], [0, c["fy"], c["cy"]], [0, 0, 1.0]])
        self.dist = np.asarray(c.get("dist", [0.0] * 5), dtype=np.float64)
        self.w, self.h = int(c["width"]), int(c["height"])

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Unit rays (N, 3), camera frame, of pixels (N, 2)."""
        k1, k2, p1, p2, k3 = (list(self.dist) + [0.0] * 5)[:5]
        xd = (uv[:, 0] - self.K[0, 2]) / self.K[0, 0]
        yd = (uv[:, 1] - self.K[1, 2]) / self.K[1, 1]
        x, y = xd.copy(), yd.copy()
        for _ in range(60):  # fixed point of the Brown–Conrady model (converges over the image)
            r2 = x * x + y * y
            radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
            x = (xd - (2 * p1 * x * y + p2 * (r2 + 2 * x * x))) / radial
            y = (yd - (p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)) / radial
        r = np.stack([x, y, np.ones_like(x)], axis=1)
        return r / np.linalg.norm(r, axis=1, keepdims=True)


def plane_hits(rays: np.ndarray, n: np.ndarray, d: float) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        s = d / (rays @ n)
    s[~(s > 0)] = np.nan
    return rays * s[:, None]


def frame_edges(frames: np.ndarray, thr: np.ndarray, contrast_ok: np.ndarray, mask: np.ndarray, t: int,
                sense: int, leading: bool) -> np.ndarray:
    """Sub-pixel (u, v) of frame t's shadow edge on each row of ``mask`` (the textbook's spatial edge).

    ``sense`` +1 when the shadow moves towards +u. The leading (entering) edge
    has lit pixels ahead of it and dark ones behind; the trailing edge the reverse.
    """
    lut = srgb_to_linear(np.arange(256))
    rows = np.flatnonzero(mask.any(axis=1))
    out = []
    for v in rows:
        cols = np.flatnonzero(mask[v] & contrast_ok[v])
        if cols.size < 3:
            continue
        seg_break = np.flatnonzero(np.diff(cols) != 1)
        d = lut[frames[t, v, cols]] - thr[v, cols]
        a, b = d[:-1], d[1:]
        contiguous = np.ones(len(a), bool)
        contiguous[seg_break] = False
        # along +u: leading edge when moving +u is dark (a<0) → lit (b≥0); trailing is lit → dark.
        up = (a < 0) & (b >= 0)
        down = (a >= 0) & (b < 0)
        want = (up if leading else down) if sense > 0 else (down if leading else up)
        k = np.flatnonzero(want & contiguous)
        if k.size != 1:  # none, or ambiguous on this row (the textbook keeps rows with one clean edge)
            continue
        k = k[0]
        u = cols[k] + a[k] / (a[k] - b[k])
        out.append((u, v))
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def fit_line_3d(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """TLS 3-D line with one 3σ rejection: (centre, unit direction, inliers)."""
    if len(p) < 10:
        return None
    keep = np.ones(len(p), bool)
    for _ in range(2):
        c = p[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(p[keep] - c, full_matrices=False)
        r = np.linalg.norm(np.cross(p - c, vt[0]), axis=1)
        s = np.sqrt(np.mean(r[keep] ** 2))
        keep = r <= 3 * max(s, 1e-9)
    if keep.sum() < 10:
        return None
    c = p[keep].mean(axis=0)
    _, _, vt = np.linalg.svd(p[keep] - c, full_matrices=False)
    return c, vt[0], keep


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("capture", type=Path)
    ap.add_argument("--masks", type=Path, default=None)
    ap.add_argument("--rects", default=None)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--min-contrast", type=float, default=20.0)
    ap.add_argument("--object-mask", type=Path, default=None, help="a mask image of the object (its pixels are "
                    "another group in the comparison)")
    args = ap.parse_args(argv)
    import tomllib

    cap = args.capture
    log = tomllib.loads((cap / "field_log.toml").read_text())
    camera_file = cap / log["camera"]["file"]
    cam = Camera(camera_file)
    report = json.loads((cap / "scan" / "report.json").read_text())
    planes = {}
    for p in report["reference_planes"]:
        R = cv2.Rodrigues(np.array(p["rvec"]))[0]
        t = np.array(p["tvec"])
        planes[p["plane"]] = (R[:, 2], float(R[:, 2] @ t), R, t)
    names = list(planes)
    h, w = cam.h, cam.w
    masks = {}
    if args.rects:
        for k, (u0, v0, u1, v1) in json.loads(args.rects).items():
            m = np.zeros((h, w), bool)
            m[v0:v1, u0:u1] = True
            masks[k] = m
    else:
        folder = args.masks or cap / "regions"
        for k in names:
            masks[k] = cv2.imread(str(folder / f"{k}_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
    frames = load_frames(str(cap / log["capture"]["frames"]))
    n = len(frames)
    print(f"{n} frames {w}x{h}; planes {names}; regions {[int(m.sum()) for m in masks.values()]} px")
    T = temporal_times(frames, args.min_contrast)
    uu, vv = np.meshgrid(np.arange(w), np.arange(h))
    rays = cam.rays(np.stack([uu.ravel(), vv.ravel()], 1).astype(np.float64)).reshape(h, w, 3)
    depth_edges = {}
    planes_edges = {}
    for edge in ("enter", "leave"):
        times = T[edge]
        # sweep sense from the time map on the first plane's region
        g = np.nanmedian(np.diff(np.where(masks[names[0]], times, np.nan), axis=1))
        sense = 1 if g > 0 else -1
        shadow = np.full((n, 4), np.nan)
        gaps = []
        for t in range(n):
            lines = []
            for k in names:
                pix = frame_edges(frames, T["thr"], T["contrast_ok"], masks[k], t, sense, edge == "enter")
                if len(pix) < 10:
                    continue
                nk, dk = planes[k][:2]
                P = plane_hits(cam.rays(pix), nk, dk)
                P = P[np.isfinite(P[:, 0])]
                fit = fit_line_3d(P)
                if fit is not None:
                    lines.append(fit)
            if len(lines) < 2:
                continue
            samples = []
            for c, d, _keep in lines:
                ext = 100.0
                samples += [c - ext * d, c, c + ext * d]
            S = np.array(samples)
            c0 = S.mean(axis=0)
            _, _, vt = np.linalg.svd(S - c0)
            nrm = vt[2]
            (c1, d1, _), (c2, d2, _) = lines[0], lines[1]
            cr = np.cross(d1, d2)
            gaps.append((t, abs((c2 - c1) @ cr) / max(np.linalg.norm(cr), 1e-12)))
            earlier = shadow[:t][np.isfinite(shadow[:t, 0])]
            if len(earlier) and nrm @ earlier[-1, :3] < 0:  # one sense for all, so rows interpolate
                nrm = -nrm
            shadow[t] = [*nrm, nrm @ c0]
        planes_edges[edge] = shadow
        # triangulate: plane interpolated between floor and ceil of the time
        ts = times.ravel()
        ok = np.isfinite(ts) & (ts >= 0) & (ts <= n - 1)
        k0 = np.clip(np.floor(np.nan_to_num(ts)).astype(int), 0, n - 2)
        f = (np.nan_to_num(ts) - k0)[:, None]
        pl = (1 - f) * shadow[k0] + f * shadow[k0 + 1]
        r = rays.reshape(-1, 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            s = pl[:, 3] / np.einsum("ij,ij->i", pl[:, :3], r)
        z = np.where(ok & (s > 0), s * r[:, 2], np.nan).reshape(h, w)
        depth_edges[edge] = z
        g = np.array(gaps)
        print(f"{edge}: planes in {int(np.isfinite(shadow[:, 0]).sum())} frames; line gap between the planes' "
              f"lines median {np.median(g[:, 1]):.2f} mm (frames {int(g[0, 0])}–{int(g[-1, 0])})")
    ze, zl = depth_edges["enter"], depth_edges["leave"]
    both = np.isfinite(ze) & np.isfinite(zl)
    with np.errstate(invalid="ignore"):
        agree = both & (np.abs(ze - zl) <= 0.02 * ze)
    depth = np.where(agree, 0.5 * (ze + zl), np.where(both, np.nan, np.fmin(ze, zl)))
    d = (ze - zl)[both]
    print(f"enter − leave depth over {both.sum()} pixels: mean {np.mean(d):.2f} mm, "
          f"median |.| {np.median(np.abs(d)):.2f} mm")
    shadow_time = np.where(np.isfinite(T["enter"]) & np.isfinite(T["leave"]), 0.5 * (T["enter"] + T["leave"]),
                           T["enter"])
    out = args.out or cap / "textbook"
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "depth.npy", depth.astype(np.float32))
    np.save(out / "shadow_time.npy", shadow_time.astype(np.float32))
    np.save(out / "enter.npy", T["enter"])
    np.save(out / "depth_enter.npy", ze.astype(np.float32))
    np.save(out / "depth_leave.npy", zl.astype(np.float32))
    np.save(out / "leave.npy", T["leave"])
    np.save(out / "planes_enter.npy", planes_edges["enter"])
    np.save(out / "planes_leave.npy", planes_edges["leave"])
    shutil.copy(cap / "scan" / "report.json", out / "report.json")
    print(f"wrote {out}")
    groups = dict(masks)
    if args.object_mask is not None:
        groups["object"] = cv2.imread(str(args.object_mask), cv2.IMREAD_GRAYSCALE) > 0
    gnomon_losses(cap, shadow_time, groups)
    return 0



def gnomon_losses(cap: Path, ref_times: np.ndarray, groups: dict[str, np.ndarray]) -> None:
    """Run Gnomon's scan in memory on the capture's field log and count, per group of pixels, where the
    pixels with a reference shadow time are lost, stage by stage (first failing stage wins)."""
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import frame_source, resolve_scan
    from gnomon.geometry.validity import contrast_above_noise
    from gnomon.runs.scan import scan

    log = load_field_log(cap / "field_log.toml")
    source = frame_source(log)
    setup = resolve_scan(log, source)
    captured = {}

    def track(*a, **k):
        from gnomon.capture.tracking import track_source

        captured["tracked"] = tr = track_source(*a, **k)
        captured["times"] = {f: getattr(tr.times, f).copy() for f in ("contrast", "ambiguous", "valid", "enter",
                                                                      "leave")}
        return tr

    result = scan(setup, source, track=track)
    tr, raw = captured["tracked"], captured["times"]
    # the field log's min_contrast, or (none given) 8 σ of the image noise, as the scan resolves it
    mc = setup.tracker.min_contrast if setup.tracker.min_contrast is not None else 8.0 * tr.noise_dn
    edges = {e.name: e for e in result.edges}
    stages = [
        ("no dip ≥ min_contrast", raw["contrast"] < mc),
        ("two comparable dips (ambiguous)", raw["ambiguous"] & (raw["contrast"] >= mc)),
        ("dip under the noise gate", raw["valid"] & ~contrast_above_noise(raw["contrast"], tr.noise_dn)),
        ("no crossing on either edge", ~np.isfinite(raw["enter"]) & ~np.isfinite(raw["leave"])),
    ]
    no_depth = np.ones(ref_times.shape, bool)
    for e in edges.values():
        no_depth &= ~np.isfinite(e.depth)
    stages.append(("time but no depth on either edge (no shadow plane near it, or the light refused it)", no_depth))
    fused_any = np.zeros(ref_times.shape, bool)
    for e in edges.values():
        fused_any |= np.isfinite(e.depth)
    with np.errstate(invalid="ignore"):
        conflict = np.isfinite(edges["enter"].depth) & np.isfinite(edges["leave"].depth) & ~result.valid
    stages.append(("both edges' depths, dropped at fusion or for lack of neighbours", conflict))
    stages.append(("one edge's depth, dropped for lack of neighbours", fused_any & ~result.valid))
    has_ref = np.isfinite(ref_times)
    for name, grp in groups.items():
        base = grp & has_ref
        left = base.copy()
        print(f"{name}: {int(base.sum())} pixels with a reference shadow time; Gnomon points on "
              f"{int((base & result.valid).sum())} ({100 * (base & result.valid).sum() / max(base.sum(), 1):.1f} %)")
        for label, lost in stages:
            n = int((left & lost).sum())
            left &= ~lost
            if n:
                print(f"    lost {n:7d} ({100 * n / max(base.sum(), 1):5.1f} %): {label}")
    planes = {k: np.isfinite(e.planes[:, 0]) for k, e in edges.items()}
    print("frames with a Gnomon shadow plane: " + ", ".join(f"{k} {int(v.sum())}" for k, v in planes.items()))


if __name__ == "__main__":
    raise SystemExit(main())
