"""`gnomon calibrate lamp`: the lamp from a pencil log, written to lamp.toml beside it.

Shadow tips left out of the log are found first (against the empty desk, or the photos' median:
:mod:`gnomon.light.pencil_detection`); the lamp is then located
(:func:`gnomon.light.pencil.calibrate_lamp_from_pencil`).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from gnomon.config.pencil_log import MEDIAN_PHOTOS, PencilLog, load_pencil_log
from gnomon.errors import GnomonError
from gnomon.light.pencil import calibrate_lamp_from_pencil
from gnomon.util import toml_io


def _median_photo(folder: Path, log: PencilLog) -> np.ndarray:
    """The per-pixel median of the pencil photos (as encoded: the median commutes with the decoding).
    Each photo's pencil and shadow cover pixels the others leave bare, so with 3 or more photos spread
    around the scene it is the desk without the pencil."""
    from gnomon.camera.calibration import read_grey

    photos: list[np.ndarray] = []
    for name in log.images:
        assert name is not None
        photo = read_grey(folder / name)
        if photos and photo.shape != photos[0].shape:
            raise GnomonError(f"{log.path}: [pencil] photo {name} is {photo.shape[1]}x{photo.shape[0]}, "
                              f"{log.images[0]} {photos[0].shape[1]}x{photos[0].shape[0]}")
        photos.append(photo)
    return np.median(np.stack(photos), axis=0).round().astype(photos[0].dtype)


def detect_missing_tips(log: PencilLog) -> tuple[PencilLog, list[str]]:
    """Find the shadow tips the log leaves out (and refine those photos' bases) against ``empty``.

    Returns the completed log and one line per detected photo. See
    :mod:`gnomon.light.pencil_detection`.
    """
    from dataclasses import replace

    from gnomon.camera.calibration import read_grey
    from gnomon.capture.tracking import decoding_lut
    from gnomon.geometry.reference_lines import PlaneInCamera
    from gnomon.light.pencil_detection import detect_pencil, find_pencil_base

    missing = np.flatnonzero(~np.isfinite(log.tips_px[:, 0]))
    if len(missing) == 0:
        return log, []
    folder = log.path.resolve().parent
    if log.empty is not None:
        empty_raw, empty_name = read_grey(log.empty), log.empty.name
    else:  # the desk as most photos see it: the pencil stands elsewhere in each (checked when the log was read)
        assert len(log.images) >= MEDIAN_PHOTOS and all(name is not None for name in log.images)
        empty_raw, empty_name = _median_photo(folder, log), f"the median of the {len(log.images)} photos"
    lut = decoding_lut(log.gamma, empty_raw.dtype)
    empty = lut[empty_raw]
    plane = PlaneInCamera.from_world(log.plane_point, log.plane_normal, log.pose)
    # the pencil stands on the camera's side of the plane (a board's normal may point into the desk)
    up = np.asarray(log.plane_normal, dtype=np.float64)
    if (log.pose.camera_centre_world - log.plane_point) @ up < 0:
        up = -up
    def tops_of(feet_px: np.ndarray) -> np.ndarray:
        """(N, 2) pixels of the pencil's top standing on the plane at each foot pixel (NaN off the plane)."""
        feet = plane.intersect(log.camera.rays(feet_px))
        tops = log.pose.camera_to_world(feet) + log.height * up
        return np.asarray(log.camera.project(log.pose.world_to_camera(tops)), dtype=np.float64).reshape(-1, 2)

    bases, tips, lines = log.bases_px.copy(), log.tips_px.copy(), []
    for i in missing:
        name = log.images[i]
        assert name is not None  # a tip to find needs its photo (checked when the log was read)
        photo_raw = read_grey(folder / name)
        if photo_raw.shape != empty_raw.shape:
            raise GnomonError(f"{log.path}: [pencil] photo {name} is {photo_raw.shape[1]}x{photo_raw.shape[0]}, "
                              f"the empty desk {empty_raw.shape[1]}x{empty_raw.shape[0]}")
        photo, source = lut[photo_raw], f"{log.path}: {name}"
        if np.all(np.isfinite(bases[i])):
            how, top_px = "", tops_of(bases[i][None])[0]
        else:
            standing = find_pencil_base(photo, empty, tops_of, source=source)
            bases[i], top_px = standing.base_px, standing.top_px
            how = f", the pencil found with it (fit {standing.fit:.2f})"
        if not np.all(np.isfinite(top_px)):
            raise GnomonError(f"{log.path}: [pencil] photo {name}: the base pixel does not see the plane")
        found = detect_pencil(photo, empty, bases[i], top_px, source=source)
        bases[i], tips[i] = found.base_px, found.tip_px
        lines.append(f"photo {i + 1} ({name}): base {found.base_px.round(2).tolist()}, "
                     f"tip {found.tip_px.round(2).tolist()} (found against {empty_name}{how})")
    return replace(log, bases_px=bases, tips_px=tips), lines


def predicted_tips_px(log: PencilLog, cal) -> np.ndarray:
    """(N, 2) pixels where the solved lamp puts each photo's shadow tip: the ray from the lamp through
    the pencil's top, met with the plane, seen by the camera."""
    lamp = np.asarray(cal.position_world, dtype=np.float64)
    n = np.asarray(cal.plane_normal_world, dtype=np.float64)
    tops = np.asarray(cal.tops_world, dtype=np.float64)
    d = tops - lamp
    s = ((log.plane_point - lamp) @ n) / (d @ n)
    on_plane = lamp + s[:, None] * d
    return np.asarray(log.camera.project(log.pose.world_to_camera(on_plane)), dtype=np.float64).reshape(-1, 2)


def draw_tips(log: PencilLog, predicted: np.ndarray, path: Path) -> None:
    """``lamp_tips.png``: each pencil photo cropped around its pencil and shadow, its base (green), its
    shadow's tip as clicked or found (red) and where the solved lamp puts it (yellow cross), labelled with
    the photo's file name and the tip's miss in pixels. Photos the log does not name, or that cannot be
    read beside it, are left out (and named)."""
    import cv2

    from gnomon.camera.calibration import read_grey
    from gnomon.capture.frames import grey_8bit_scale
    from gnomon.util import atomic

    tiles, unread = [], []
    for name, base, tip, pred in zip(log.images, log.bases_px, log.tips_px, predicted, strict=True):
        if name is None:
            continue
        try:
            img = np.clip(grey_8bit_scale(read_grey(log.path.parent / name)), 0, 255).astype(np.uint8)
        except GnomonError:  # the photo is only named (its pixels clicked elsewhere): nothing to draw on
            unread.append(Path(name).name)
            continue
        pts = np.array([base, tip, pred])
        span = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])), 40.0)
        c = pts.mean(axis=0)
        half = 0.75 * span
        x0, y0 = int(max(c[0] - half, 0)), int(max(c[1] - half, 0))
        x1, y1 = int(min(c[0] + half, img.shape[1])), int(min(c[1] + half, img.shape[0]))
        crop = cv2.cvtColor(img[y0:y1, x0:x1], cv2.COLOR_GRAY2BGR)
        k = 300.0 / max(crop.shape[:2])
        crop = cv2.resize(crop, None, fx=k, fy=k, interpolation=cv2.INTER_AREA if k < 1 else cv2.INTER_LINEAR)

        b, t, q = (tuple(int(round(x)) for x in (p - (x0, y0)) * k) for p in (base, tip, pred))
        cv2.circle(crop, b, 6, (0, 200, 0), 2, cv2.LINE_AA)
        cv2.circle(crop, t, 6, (0, 0, 255), 2, cv2.LINE_AA)
        cv2.drawMarker(crop, q, (0, 230, 255), cv2.MARKER_CROSS, 14, 2, cv2.LINE_AA)
        tile = np.full((330, 300, 3), 255, np.uint8)
        tile[:crop.shape[0], :crop.shape[1]] = crop
        miss = float(np.hypot(*(tip - pred)))
        cv2.putText(tile, f"{Path(name).name}  tip off {miss:.1f} px", (4, 322), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(tile)
    if unread:
        print(f"note: {path.name} leaves out {', '.join(unread)} (not readable beside the log)")
    if not tiles:
        return
    per_row = min(len(tiles), 4)
    rows = [np.hstack(tiles[i:i + per_row] + [np.full_like(tiles[0], 255)] * (per_row - len(tiles[i:i + per_row])))
            for i in range(0, len(tiles), per_row)]
    ok, buf = cv2.imencode(".png", np.vstack(rows))
    if ok:
        atomic.write_bytes(path, buf.tobytes())


def _decimals(sigma: float) -> int:
    """Decimals showing a value to about a tenth of its 1σ."""
    if not (sigma > 0 and math.isfinite(sigma)):
        return 3
    return int(min(6, max(0, 1 - math.floor(math.log10(sigma)))))


def _degenerate_lamp(cal, distance: float) -> str | None:
    """Why a lamp estimate must not be written without --force (its σ is a large part of its distance,
    or the photos' lines are nearly parallel), or None."""
    sig = np.asarray(cal.sigma_world, dtype=float)
    if not (np.all(np.isfinite(cal.position_world)) and np.all(np.isfinite(sig))):
        return "not finite"
    if sig.max() > 0.25 * distance:
        return f"σ {sig.max():.3g} against a distance of {distance:.3g} to the pencils"
    if math.isfinite(cal.line_spread_deg) and cal.line_spread_deg < 2.0:
        return f"the photos' lines spread over {cal.line_spread_deg:.2g}° only"
    return None


def calibrate_lamp_cli(args: argparse.Namespace) -> int:
    """``gnomon calibrate lamp FIELD_LOG``: reads ``args.field_log`` (a Path), prints the
    lamp ± 1σ, residuals and warnings, writes ``lamp.toml`` beside the field log (atomic)."""
    from dataclasses import replace

    from gnomon.light.pencil_detection import FOUND_FOOT_SIGMA_PX

    given = load_pencil_log(args.field_log)
    log, detected = detect_missing_tips(given)
    for line in detected:
        print(line)
    if not np.isfinite(given.bases_px).all() and log.sigma_px < FOUND_FOOT_SIGMA_PX:
        print(f"note: σ = {FOUND_FOOT_SIGMA_PX:g} px instead of sigma_px = {log.sigma_px:g}: the pencils' feet "
              f"were found, to about {FOUND_FOOT_SIGMA_PX:g} px (give them as `base` to use yours)")
        log = replace(log, sigma_px=FOUND_FOOT_SIGMA_PX)
    try:
        cal = calibrate_lamp_from_pencil(
            log.camera, log.pose, log.plane_point, log.plane_normal, log.bases_px, log.tips_px,
            log.height, log.sigma_px, sigma_height=log.sigma_height,
        )
    except GnomonError as exc:
        raise GnomonError(f"{log.path}: [pencil] {exc}") from None

    u = log.units
    sig = cal.sigma_world
    dec = _decimals(float(sig.min()))
    print(
        f"lamp from {cal.n_photos} pencil photos (plane {log.plane_name!r}, height {log.height:g} {u}, "
        f"σ = {log.sigma_px:g} px)"
    )
    print(
        f"position (world, {u}): "
        + "   ".join(f"{a} = {x:.{dec}f} ± {s:.2g}" for a, x, s in zip("xyz", cal.position_world, sig, strict=True))
    )
    distance = float(np.linalg.norm(cal.position_world - cal.bases_world.mean(axis=0)))
    height_above = float(np.dot(cal.position_world - log.plane_point, cal.plane_normal_world))
    print(f"  {height_above:.{dec}f} {u} above the plane, {distance:.{dec}f} {u} from the pencils")
    print(f"residuals (distance from the lamp to each photo's line, {u}):")
    for i, r in enumerate(cal.residuals):
        name = f"  ({log.images[i]})" if log.images[i] else ""
        print(f"  photo {i + 1}: {r:.{dec + 1}f}{name}")
    if math.isfinite(cal.chi2):
        print(f"consistency: χ² = {cal.chi2:.3g} for {cal.dof} dof; line spread {cal.line_spread_deg:.1f}°")
    predicted = predicted_tips_px(log, cal)
    print("shadow tips against the lamp's (pixels, base green, tip red, the lamp's yellow in "
          f"{log.path.with_name('lamp_tips.png').name}):")
    for i, (tip, pred) in enumerate(zip(log.tips_px, predicted, strict=True)):
        name = log.images[i] or f"photo {i + 1}"
        print(f"  {Path(name).name}: {float(np.hypot(*(tip - pred))):.2f} px")
    for w in cal.warnings:
        print(f"warning: {w}")

    out = log.path.parent / "lamp.toml"
    problem = _degenerate_lamp(cal, distance)
    if problem is not None and not getattr(args, "force", False):
        raise GnomonError(f"{out}: not written: the lamp estimate is degenerate ({problem}); take photos with "
                          "the pencil in places spread around the scene, or write it anyway with --force")
    data = {
        "light": {"kind": "lamp", "position": cal.position_world},
        "lamp_calibration": {
            "field_log": log.path.name,
            "units": u,
            "frame": "world",
            "sigma": sig,
            "covariance": cal.covariance,
            "photos": cal.n_photos,
            "height": cal.height,
            "sigma_px": cal.sigma_px,
            "sigma_height": cal.sigma_height,
            "residuals": cal.residuals,
            "chi2": cal.chi2,
            "dof": cal.dof,
            "line_spread_deg": cal.line_spread_deg,
            "warnings": list(cal.warnings),
        },
    }
    header = (
        f"Lamp position from {cal.n_photos} pencil photos: gnomon calibrate lamp {log.path.name}\n"
        f"World frame, {u}; covariance in {u}². Paste [light] into a scan's field log."
    )
    toml_io.dump(data, out, header)
    draw_tips(log, predicted, out.with_name("lamp_tips.png"))
    print(f"wrote {out}")
    return 0
