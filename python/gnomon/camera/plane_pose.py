"""Reference planes: printed markers, a chessboard, or an explicit pose.

A *marker* is a printed 2×2 checker pattern: its centre is an X-junction (a
saddle point of the intensity), which a field log gives as an approximate
pixel (the *hint*) plus its known coordinates on the plane.
:func:`find_marker` finds the saddle near the hint (Hessian response), refines
it to sub-pixel (by point symmetry, see :func:`_symmetric_centre`) and checks that it really is a 2×2
checker corner (the intensity around it alternates dark/bright/dark/bright and
is point-symmetric), else a :class:`GnomonError` names the marker and hint.

:func:`plane_pose_from_markers`, :func:`plane_pose_from_chessboard` and
:func:`plane_pose_from_pose` all return a :class:`PlanePose`: the pose of the
plane's frame (or of the world frame, when the points are given in 3D world
coordinates) in the camera frame, the plane as ``n·X = d`` in the camera
frame, and the residuals. The pose comes from ``cv2.solvePnPGeneric`` (IPPE
for planar points, SQPnP otherwise) on undistorted normalised coordinates —
so any camera model with ``rays`` works — then Levenberg–Marquardt on the
pixel reprojection error through the camera model's ``project``.

Frames: camera as OpenCV's; ``Pose`` maps the points' frame to the camera,
``X_cam = R·X + t``. Lengths in the units of the given coordinates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from gnomon.camera.models import Pose
from gnomon.capture.frames import grey_8bit_scale
from gnomon.errors import GnomonError
from gnomon.util.fitting import levenberg_marquardt

# --------------------------------------------------------------------------- marker detection


@dataclass(frozen=True)
class MarkerDetection:
    """One marker found near its hint.

    ``pixel`` the refined centre (u, v); ``contrast`` the bright − dark
    difference around it (8-bit DN); ``x_score`` the share of the circular
    intensity profile in its 2nd harmonic relative to an ideal 2×2 checker
    (1 = perfect, ≈0 for an edge or flat area); ``asymmetry`` the odd
    harmonics relative to the 2nd (≈0 at a true centre).
    """

    name: str
    hint: tuple[float, float]
    pixel: tuple[float, float]
    contrast: float
    x_score: float
    asymmetry: float
    sigma_px: float = float("nan")  # the centre's 1 σ per axis from the image noise (symmetric_centre_sigma)
    kind: str = "checker"  # "checker" (a printed 2×2 checker: x_score, asymmetry as above) or "cross" (a
    # hand-drawn cross, :func:`search_crosses`: x_score its ink's isotropy, asymmetry 1 − its point symmetry)


@dataclass(frozen=True)
class MarkKind:
    """How a kind of mark is named to the user and written into a field log: ``plural`` / ``singular`` in
    messages, ``key`` the marker table's pixel key (a checker's ``pixel_hint`` is refined again by the scan;
    a cross is found once and for all and given as ``pixel``), with ``digits`` decimals."""

    plural: str
    singular: str
    key: str
    digits: int


MARK_KINDS = {"checker": MarkKind("printed 2x2 checkers", "2x2 checker", "pixel_hint", 1),
              "cross": MarkKind("hand-drawn crosses", "cross", "pixel", 2)}
""":attr:`MarkerDetection.kind` → its :class:`MarkKind`."""


def _circle_profile(img: np.ndarray, centre: tuple[float, float], radius: float, n: int = 64) -> np.ndarray:
    th = np.arange(n) * (2 * np.pi / n)
    mx = (centre[0] + radius * np.cos(th)).astype(np.float32).reshape(1, -1)
    my = (centre[1] + radius * np.sin(th)).astype(np.float32).reshape(1, -1)
    return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel().astype(np.float64)


def _x_check(img: np.ndarray, centre: tuple[float, float], radius: float) -> tuple[float, float, float]:
    """(contrast, x_score, asymmetry) of the circular profiles at 0.6 and 1.0 × radius."""
    scores = []
    for r in (0.6 * radius, radius):
        p = _circle_profile(img, centre, r)
        n = len(p)
        spec = np.abs(np.fft.rfft(p - p.mean())) * 2.0 / n
        contrast = float(np.percentile(p, 95) - np.percentile(p, 5))
        # An ideal X-junction of contrast C is a 4-sector square wave: its 2nd
        # harmonic has amplitude 2C/π; odd harmonics vanish (point symmetry:
        # the two edges through the centre stay straight lines under perspective).
        x_score = float(spec[2] / (2.0 * contrast / np.pi)) if contrast > 0 else 0.0
        asym = float(np.hypot(spec[1], spec[3]) / max(spec[2], 1e-12))
        scores.append((contrast, x_score, asym))
    return min(s[0] for s in scores), min(s[1] for s in scores), max(s[2] for s in scores)


def _sample(img: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = pts.astype(np.float32)
    out = cv2.remap(img, p[:, 0].reshape(1, -1), p[:, 1].reshape(1, -1), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.ravel().astype(np.float64)


def _symmetry_system(img: np.ndarray, radius: int):
    """The blurred image, its gradients and the half-disc of offsets of :func:`_symmetric_centre`."""
    b = cv2.GaussianBlur(img, (0, 0), 0.7)
    gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    yy, xx = np.mgrid[-radius : radius + 1, -radius : radius + 1]
    half = (xx * xx + yy * yy <= radius * radius) & ((yy > 0) | ((yy == 0) & (xx > 0)))
    d = np.stack([xx[half], yy[half]], axis=1).astype(np.float64)
    return b, gx, gy, d


def _symmetry_residuals(system, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The asymmetry I(p + d) − I(p − d) over the half-disc, and its Jacobian in p (M, 2)."""
    b, gx, gy, d = system
    pa, pb = p + d, p - d
    r = _sample(b, pa) - _sample(b, pb)
    J = np.stack([_sample(gx, pa) - _sample(gx, pb), _sample(gy, pa) - _sample(gy, pb)], axis=1)
    return r, J


def symmetric_centre_sigma(img: np.ndarray, centre: tuple[float, float], radius: int) -> float:
    """The 1-σ (px, per axis) of a point-symmetric pattern's centre found by :func:`_symmetric_centre`, from
    the image noise its asymmetry residuals show: σ_r² (JᵀJ)⁻¹ at the centre (``img`` as given to it)."""
    r, J = _symmetry_residuals(_symmetry_system(img, radius), np.array(centre, dtype=np.float64))
    dof = len(r) - 2
    a = J.T @ J
    if dof <= 0 or np.linalg.cond(a) > 1e12:
        return float("nan")
    cov = np.linalg.inv(a) * float(r @ r) / dof
    return float(np.sqrt(max(np.trace(cov), 0.0) / 2.0))


def _symmetric_centre(img: np.ndarray, start: tuple[float, float], radius: int, iters: int = 30,
                      system=None) -> tuple[float, float]:
    """Sub-pixel centre of a point-symmetric pattern: minimise Σ (I(p + d) − I(p − d))² over a disk.

    A 2×2 checker stays point-symmetric about its centre under perspective
    (its two edges through the centre stay straight lines), so this holds
    where gradient-based refiners (cornerSubPix) are biased by the skewed,
    blurred junction — on our synthetic frames ≈0.02 px instead of ≈0.1 px.
    Gauss–Newton on the lightly blurred image with bilinear sampling. ``system``: the image's
    :func:`_symmetry_system` at ``radius``, when many centres are sought in one image.
    """
    system = _symmetry_system(img, radius) if system is None else system
    p = np.array(start, dtype=np.float64)
    for _ in range(iters):
        r, J = _symmetry_residuals(system, p)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        if not np.all(np.isfinite(step)) or np.hypot(*step) > radius:
            return float("nan"), float("nan")
        p += step
        if np.hypot(*step) < 1e-5:
            break
    return float(p[0]), float(p[1])


def _saddle_response(img: np.ndarray, radius_px: int) -> np.ndarray:
    """−det(H) of the image blurred to the radius's scale (σ = radius/3, at least 1 px): c² at an
    X-junction of contrast c (any orientation), 0 on a straight edge, negative on a blob."""
    b = cv2.GaussianBlur(img, (0, 0), max(1.0, radius_px / 3.0))
    ixx = cv2.Sobel(b, cv2.CV_32F, 2, 0, ksize=3)
    iyy = cv2.Sobel(b, cv2.CV_32F, 0, 2, ksize=3)
    ixy = cv2.Sobel(b, cv2.CV_32F, 1, 1, ksize=3)
    return ixy * ixy - ixx * iyy


def find_marker(
    image: np.ndarray,
    hint: Sequence[float] | np.ndarray,
    *,
    name: str = "marker",
    search_px: float = 30.0,
    radius_px: int = 6,
    min_contrast: float = 20.0,
    source: str = "image",
) -> MarkerDetection:
    """Find one 2×2 checker marker's centre near ``hint`` (pixels), to sub-pixel.

    ``search_px``: how far from the hint the centre may be (pixels).
    ``radius_px``: radius (pixels) of the symmetric refinement and of the
    check; each of the marker's four squares should span at least about half
    this in the image, and the printed marker (with its white margin) at
    least this. ``min_contrast``: minimum bright − dark difference (8-bit DN).
    ``source`` names the image in errors. Raises GnomonError when no marker
    is there.
    """
    img = grey_8bit_scale(image)
    h, w = img.shape
    u0, v0 = float(hint[0]), float(hint[1])
    where = f"{source}: marker '{name}'"
    if not (np.isfinite(u0) and np.isfinite(v0)) or not (0 <= u0 <= w - 1 and 0 <= v0 <= h - 1):
        raise GnomonError(f"{where}: hint ({u0:.1f}, {v0:.1f}) lies outside the {w}x{h} image")
    pad = int(np.ceil(search_px + 2 * radius_px + 4))
    x0, x1 = max(int(u0) - pad, 0), min(int(u0) + pad + 1, w)
    y0, y1 = max(int(v0) - pad, 0), min(int(v0) + pad + 1, h)
    resp = _saddle_response(img[y0:y1, x0:x1], radius_px)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - u0) ** 2 + (yy - v0) ** 2 <= search_px**2
    inside &= (xx >= radius_px) & (xx <= w - 1 - radius_px) & (yy >= radius_px) & (yy <= h - 1 - radius_px)
    resp = np.where(inside, resp, -np.inf)
    if not np.isfinite(resp).any():
        raise GnomonError(f"{where}: not found within {search_px:g} px of its hint ({u0:.1f}, {v0:.1f}): "
                          "too close to the image border")
    k = int(np.argmax(resp))
    u, v = _symmetric_centre(img, (float(xx.flat[k]), float(yy.flat[k])), radius_px)
    if not (np.isfinite(u) and np.isfinite(v)) or np.hypot(u - xx.flat[k], v - yy.flat[k]) > radius_px:
        u, v = float(xx.flat[k]), float(yy.flat[k])  # refinement slid away: keep the saddle (the check below judges it)
    contrast, x_score, asym = _x_check(img, (u, v), float(radius_px))
    ok = (
        contrast >= min_contrast
        and x_score >= 0.5
        and asym <= 0.35
        and np.hypot(u - u0, v - v0) <= search_px
    )
    if not ok:
        raise GnomonError(
            f"{where}: not found within {search_px:g} px of its hint ({u0:.1f}, {v0:.1f}) "
            f"(best candidate ({u:.1f}, {v:.1f}): contrast {contrast:.0f} DN, 2x2-checker score {x_score:.2f}, "
            f"asymmetry {asym:.2f}; need ≥ {min_contrast:g} DN, ≥ 0.5, ≤ 0.35); if the mark is there but not a "
            "clean 2x2 checker (squares that overlap or gap, seen at a grazing angle), give its centre as "
            "pixel = [u, v] instead of pixel_hint"
        )
    return MarkerDetection(name=name, hint=(u0, v0), pixel=(u, v), contrast=contrast, x_score=x_score, asymmetry=asym,
                           sigma_px=symmetric_centre_sigma(img, (u, v), radius_px))


def find_markers(
    image: np.ndarray,
    hints: np.ndarray,
    *,
    names: Sequence[str] | None = None,
    search_px: float = 30.0,
    radius_px: int = 6,
    min_contrast: float = 20.0,
    source: str = "image",
) -> list[MarkerDetection]:
    """:func:`find_marker` for each hint (N, 2); two markers on one corner is an error."""
    hints = np.asarray(hints, dtype=np.float64).reshape(-1, 2)
    names = list(names) if names is not None else [f"m{i}" for i in range(len(hints))]
    dets = [
        find_marker(image, h, name=n, search_px=search_px, radius_px=radius_px, min_contrast=min_contrast,
                    source=source)
        for h, n in zip(hints, names, strict=True)
    ]
    for i in range(len(dets)):
        for j in range(i + 1, len(dets)):
            if np.hypot(dets[i].pixel[0] - dets[j].pixel[0], dets[i].pixel[1] - dets[j].pixel[1]) < 1.0:
                raise GnomonError(
                    f"{source}: markers '{dets[i].name}' and '{dets[j].name}' were found on the same corner "
                    f"({dets[i].pixel[0]:.1f}, {dets[i].pixel[1]:.1f}); check their hints or reduce search_px"
                )
    return dets


#: The image radii (px) at which :func:`search_markers` looks for 2×2 checkers: a checker whose squares
#: span about 3–40 px in the image is found at one of them.
SEARCH_RADII_PX = (4, 6, 9, 13, 19)


def search_markers(
    image: np.ndarray,
    *,
    radii_px: Sequence[int] = SEARCH_RADII_PX,
    min_contrast: float = 40.0,
    min_x_score: float = 0.75,
    max_asymmetry: float = 0.1,
    max_candidates: int = 400,
) -> list[MarkerDetection]:
    """Every printed 2×2 checker in ``image``, found without hints: the saddle response (as in
    :func:`find_marker`) at each radius of ``radii_px``, its strongest local maxima refined to sub-pixel
    and kept when they pass the checker test at that radius with the stricter thresholds given here
    (a hint-free search must not take the corner of a box or a texture for a mark). One detection per
    checker (the radius with the best 2×2-checker score), named ``m0, m1, ...`` from the top of the image
    down. ``hint`` is the saddle where the search started (pixels).

    The thresholds: on three real first frames (the CMU frog's second sweep and two phone videos with
    home-made checkers) the marks score 0.80-0.99 and are symmetric to 0.08; the junctions of printed
    text and of an object's shading score 0.71-0.82 with an asymmetry of 0.09-0.17."""
    img = grey_8bit_scale(image)
    found: list[tuple[float, int, MarkerDetection]] = []
    for radius in radii_px:
        sigma = max(1.0, radius / 3.0)
        resp = _saddle_response(img, radius)
        # an X-junction of contrast C gives a response of the order of (C/σ²)²/16: half of that at the
        # least contrast accepted keeps every candidate worth the test
        floor = 0.5 * (min_contrast / (4.0 * sigma * sigma)) ** 2
        peak = (resp >= cv2.dilate(resp, np.ones((2 * radius + 1, 2 * radius + 1), np.uint8))) & (resp > floor)
        m = 3 * radius + 2  # room for the check at 1.5 × radius
        peak[:m], peak[-m:], peak[:, :m], peak[:, -m:] = False, False, False, False
        vs, us = np.nonzero(peak)
        order = np.argsort(-resp[vs, us])[:max_candidates]
        system = _symmetry_system(img, radius)
        for v0, u0 in zip(vs[order], us[order], strict=True):
            start = (float(u0), float(v0))
            # a loose test at the saddle first: most candidates (edges' ends, texture) stop here
            if _x_check(img, start, float(radius))[1] < 0.5 * min_x_score:
                continue
            u, v = _symmetric_centre(img, start, radius, system=system)
            if not (np.isfinite(u) and np.isfinite(v)) or np.hypot(u - u0, v - v0) > radius:
                continue
            # a printed checker's squares reach beyond the radius it was found at; a texture's X does not
            checks = [_x_check(img, (u, v), float(r)) for r in (radius, 1.5 * radius)]
            contrast, x_score, asym = (min(c[0] for c in checks), min(c[1] for c in checks),
                                       max(c[2] for c in checks))
            if contrast < min_contrast or x_score < min_x_score or asym > max_asymmetry:
                continue
            det = MarkerDetection(name="", hint=start, pixel=(u, v), contrast=contrast, x_score=x_score,
                                  asymmetry=asym, sigma_px=symmetric_centre_sigma(img, (u, v), radius))
            found.append((x_score, radius, det))
    kept: list[tuple[int, MarkerDetection]] = []
    for _, radius, det in sorted(found, key=lambda f: -f[0]):
        if all(np.hypot(det.pixel[0] - k.pixel[0], det.pixel[1] - k.pixel[1]) > max(radius, r) for r, k in kept):
            kept.append((radius, det))
    dets = sorted((d for _, d in kept), key=lambda d: (d.pixel[1], d.pixel[0]))
    return [replace(d, name=f"m{i}") for i, d in enumerate(dets)]


#: Seven marks are split 4 and 3 only where the gap between the planes is this many times the other one.
SEVEN_MARKS_GAP_RATIO = 3.0


@dataclass(frozen=True)
class MarkGroups:
    """Marks found without hints, assigned to the set-up's two planes by where they lie in the image: the
    lower plane (a desk, the ground) below the upper one (a wall, a facade), each with at least 4
    (:attr:`complete`), or 4 and 3 when one of 8 is missing and a clear gap parts them. Both are empty when
    the marks cannot be assigned (fewer, or no clear split); ``why`` then says what was found and ``found``
    holds every mark, for the user to assign."""

    lower: tuple[MarkerDetection, ...]
    upper: tuple[MarkerDetection, ...]
    why: str = ""
    found: tuple[MarkerDetection, ...] = ()

    @property
    def complete(self) -> bool:
        return len(self.lower) >= 4 and len(self.upper) >= 4


def split_marks(dets: Sequence[MarkerDetection]) -> MarkGroups:
    """Split marks into the plane below and the plane above: at the widest gap between their image rows
    that leaves ≥ 4 marks on each side, when every mark of the upper group lies above the line through the
    lower group's two highest marks (their outlines do not interleave). With fewer than 8 marks nothing is
    assigned: the gaps inside one plane's rectangle (its top and bottom rows) may be wider than the gap
    between the planes, and with a mark missing no split can be told from another."""
    dets = sorted(dets, key=lambda d: d.pixel[1])
    n = len(dets)
    kind = MARK_KINDS[dets[0].kind if dets else "checker"]
    marks, mark = kind.plural, f"clean {kind.singular}"
    v = np.array([d.pixel[1] for d in dets])
    gaps = np.diff(v)
    if n == 7 and max(gaps[2], gaps[3]) >= SEVEN_MARKS_GAP_RATIO * min(gaps[2], gaps[3]):
        # one mark missing: 4 above and 3 below, or 3 and 4, where one gap clearly parts them
        upper, lower = (dets[:4], dets[4:]) if gaps[3] > gaps[2] else (dets[:3], dets[3:])
        short = "lower" if len(lower) == 3 else "upper"
        return MarkGroups(tuple(lower), tuple(upper), f"7 {marks} found in the first frame: the "
                          f"{short} plane has 3 (its fourth mark is not a {mark}, or hidden)", tuple(dets))
    if n < 8:
        return MarkGroups((), (), f"{n} {marks} found in the first frame; two planes need 4 each", tuple(dets))
    cut = max(range(3, n - 4), key=lambda i: gaps[i])
    upper, lower = dets[: cut + 1], dets[cut + 1:]
    top2 = sorted(lower, key=lambda d: d.pixel[1])[:2]
    (u1, v1), (u2, v2) = top2[0].pixel, top2[1].pixel

    def line_v(u: float) -> float:
        return v1 if abs(u2 - u1) < 1e-9 else v1 + (v2 - v1) * (u - u1) / (u2 - u1)

    if not all(d.pixel[1] < line_v(d.pixel[0]) for d in upper):
        return MarkGroups((), (), f"{n} {marks} found in the first frame, but no row splits them "
                          "into two planes of 4 or more (the planes' marks interleave in the image)", tuple(dets))
    return MarkGroups(tuple(lower), tuple(upper))


def find_cross(
    image: np.ndarray,
    rough: Sequence[float] | np.ndarray,
    *,
    name: str = "cross",
    search_px: float = 60.0,
    radius_px: int = 10,
    stroke_px: int = 11,
    follow: int = 3,
    source: str = "image",
) -> tuple[float, float]:
    """The centre (u, v) of a hand-drawn cross (dark pen strokes on bright paper) near ``rough`` (pixels).

    The strokes are isolated by a black-hat filter (dark details narrower than
    ``stroke_px``); the cross is where they overlap most, the maximum of the
    blurred ink within ``search_px`` of the rough pixel, refined to the
    centroid of the ink within ``radius_px`` of it (mean shift) and then to
    the point about which the ink is point-symmetric (a pen line passing
    beside the cross, e.g. the stick's trace, pulls a centroid by about a
    pixel, not the symmetric centre: 0.05 px on the synthetic test). A maximum on the search
    window's border means the cross lies beyond it (a rough click far off):
    the ink is followed from there through small windows (``2·radius_px``
    around each border maximum, its local maximum rather than the darkest
    thing near it), up to ``follow`` times. Raises GnomonError when
    there is no ink.
    """
    img = grey_8bit_scale(image)
    h, w = img.shape
    u0, v0 = float(rough[0]), float(rough[1])
    where = f"{source}: cross '{name}'"
    if not (np.isfinite(u0) and np.isfinite(v0)) or not (0 <= u0 <= w - 1 and 0 <= v0 <= h - 1):
        raise GnomonError(f"{where}: rough pixel ({u0:.1f}, {v0:.1f}) lies outside the {w}x{h} image")
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (stroke_px, stroke_px))
    s = int(np.ceil(search_px))
    cu, cv_ = int(np.rint(u0)), int(np.rint(v0))
    for _ in range(follow + 1):
        a0, a1 = max(cu - s, 0), min(cu + s + 1, w)
        b0, b1 = max(cv_ - s, 0), min(cv_ + s + 1, h)
        ink = cv2.morphologyEx(img[b0:b1, a0:a1], cv2.MORPH_BLACKHAT, kernel)
        resp = cv2.GaussianBlur(ink, (0, 0), radius_px / 2.5)
        vv, uu = np.unravel_index(int(np.argmax(resp)), resp.shape)
        if float(resp[vv, uu]) <= 0.0:
            raise GnomonError(f"{where}: no pen stroke within {search_px:g} px of ({u0:.1f}, {v0:.1f})")
        on_border = ((uu < radius_px and a0 > 0) or (uu >= resp.shape[1] - radius_px and a1 < w)
                     or (vv < radius_px and b0 > 0) or (vv >= resp.shape[0] - radius_px and b1 < h))
        if not on_border:
            break
        # Follow the ink outwards: a small window around the border maximum (its own local maximum,
        # not whatever is darkest within the whole search radius of it).
        cu, cv_ = a0 + int(uu), b0 + int(vv)
        s = 2 * radius_px
    # Mean shift: the centroid of the ink within a disc of radius_px, recentred until it stays (a cross's
    # strokes are point-symmetric about its centre; the blurred maximum leans towards other ink near it).
    yy, xx = np.mgrid[0:ink.shape[0], 0:ink.shape[1]].astype(np.float64)
    ink64 = ink.astype(np.float64)
    pu, pv = float(uu), float(vv)
    for _ in range(20):
        disc = (xx - pu) ** 2 + (yy - pv) ** 2 <= radius_px**2
        inside = ink64[disc]
        weight = np.clip(inside - 0.3 * inside.max(), 0, None)
        if weight.sum() <= 0:
            break
        nu, nv = float((weight * xx[disc]).sum() / weight.sum()), float((weight * yy[disc]).sum() / weight.sum())
        moved = np.hypot(nu - pu, nv - pv)
        pu, pv = nu, nv
        if moved < 1e-3:
            break
    # Then the point of the ink's point symmetry (a pen line passing beside the centre pulls a centroid).
    su, sv = _symmetric_centre(ink, (pu, pv), radius_px)
    if np.isfinite(su) and np.isfinite(sv) and np.hypot(su - pu, sv - pv) <= radius_px / 2:
        pu, pv = su, sv
    return a0 + pu, b0 + pv


CROSS_SIZE_PX = (8, 80)
"""The extent (pixels) of a hand-drawn cross that :func:`search_crosses` looks for."""


def search_crosses(
    image: np.ndarray,
    *,
    stroke_px: int = 11,
    min_ink: float = 12.0,
    min_isotropy: float = 0.1,
    min_symmetry: float = 0.75,
    min_relative_ink: float = 0.6,
) -> list[MarkerDetection]:
    """Every hand-drawn cross (dark pen strokes on bright paper) in ``image``, found without hints.

    The strokes are the black-hat filter's ink (dark details narrower than ``stroke_px``) at least
    ``min_ink`` DN (8-bit) and 12 % of the paper darker than the paper, on paper (the closed image at
    least 60 % of its 99th percentile: the brightest thing in view). Each piece of ink
    :data:`CROSS_SIZE_PX` across, sparse in its box (at most 60 % of it: not a blot) and about as wide
    one way as the other (its second moments' smaller eigenvalue at least ``min_isotropy`` of the larger:
    a stroke, a box's edge or the stick's trace is a line) is refined with :func:`find_cross` and kept
    when its ink is point-symmetric about that centre (correlation with itself turned by 180° at least
    ``min_symmetry``); of those, the ones whose ink is at least ``min_relative_ink`` of the darkest's (one
    pen drew them all) are the crosses. Named ``m0, m1, ...`` from the top of the image down, ``kind``
    "cross".

    The thresholds: on two real phone videos' first frames (1080p, crosses 15-20 px across, JPEG) the
    crosses' ink reaches 76-102 DN, their isotropy 0.15-0.69 and asymmetry 0.05-0.20, and the next
    strongest symmetric pieces (wood grain, an object's dark details, a shadow's corner) at most 53 DN:
    7 of one capture's 8 crosses found and nothing else, and the other's 3 visible crosses and nothing
    else."""
    img = grey_8bit_scale(image)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (stroke_px, stroke_px))
    ink = cv2.morphologyEx(img, cv2.MORPH_BLACKHAT, kernel).astype(np.float32)
    paper = cv2.morphologyEx(img, cv2.MORPH_CLOSE, kernel).astype(np.float32)
    on_paper = paper >= 0.6 * float(np.percentile(paper, 99))
    mask = ((ink >= min_ink) & (ink >= 0.12 * paper) & on_paper).astype(np.uint8)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask)
    h, w = img.shape
    found: list[MarkerDetection] = []
    for i in range(1, n):
        x, y, bw, bh, area = (int(v) for v in stats[i])
        size = max(bw, bh)
        if not (CROSS_SIZE_PX[0] <= size <= CROSS_SIZE_PX[1]) or area > 0.6 * bw * bh or area < 12:
            continue
        ys, xs = np.nonzero(labels[y:y + bh, x:x + bw] == i)
        weights = ink[y + ys, x + xs]
        cov = np.cov(np.stack([xs, ys]), aweights=weights)
        eig = np.linalg.eigvalsh(cov)
        isotropy = float(eig[0] / eig[1]) if eig[1] > 0 else 0.0
        if isotropy < min_isotropy:
            continue
        radius = max(3, size // 2)
        try:
            u, v = find_cross(img, centroids[i], search_px=float(size), radius_px=radius, stroke_px=stroke_px,
                              follow=0)
        except GnomonError:
            continue
        if np.hypot(u - centroids[i][0], v - centroids[i][1]) > size / 2:
            continue
        # point symmetry of the ink about the refined centre
        r = radius + 2
        grid = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float32)
        mx, my = (u + grid[1]).astype(np.float32), (v + grid[0]).astype(np.float32)
        patch = cv2.remap(ink, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        turned = patch[::-1, ::-1]
        a, b = patch.ravel() - patch.mean(), turned.ravel() - turned.mean()
        symmetry = float(a @ b / max(float(np.sqrt((a @ a) * (b @ b))), 1e-9))
        if symmetry < min_symmetry or not (0 <= u <= w - 1 and 0 <= v <= h - 1):
            continue
        found.append(MarkerDetection("", (float(centroids[i][0]), float(centroids[i][1])), (float(u), float(v)),
                                     float(patch.max()), isotropy, 1.0 - symmetry, kind="cross"))
    if found:
        darkest = max(d.contrast for d in found)
        found = [d for d in found if d.contrast >= min_relative_ink * darkest]
    found.sort(key=lambda d: (d.pixel[1], d.pixel[0]))
    return [replace(d, name=f"m{k}") for k, d in enumerate(found)]


# --------------------------------------------------------------------------- pose fitting


@dataclass(frozen=True)
class PlanePose:
    """A reference plane measured in one image.

    ``pose`` maps the points' frame to the camera (the plane's own frame for
    2-D plane coordinates, the world frame for 3-D ones). In the camera frame
    the plane is ``normal_cam·X = offset_cam`` with ``normal_cam`` a unit
    vector pointing away from the camera, so ``offset_cam`` > 0 is the
    distance from the optical centre to the plane (units of the
    coordinates). ``point_world``/``normal_world``: the plane in the points'
    frame. ``residuals_px``: observed − reprojected pixels (N, 2);
    ``std_normal_deg``/``std_offset``: 1-σ uncertainties from the LM
    covariance (NaN with no redundancy, e.g. with exactly 3 points).
    Marks nobody measured (:func:`fit_rectangle_pose`) also give ``marks_xy``
    (N, 2) each mark's estimated place in the plane's frame, ``rectangle``
    the sides of the rectangle they form (along x, along y) and ``corners``
    the indices of the marks at its corners; ``std_offset`` is then 0 unless
    a known length set the distance (the distance is the unit by convention).
    """

    pose: Pose
    normal_cam: np.ndarray
    offset_cam: float
    point_world: np.ndarray
    normal_world: np.ndarray
    pixels: np.ndarray
    residuals_px: np.ndarray
    rms_px: float
    max_px: float
    std_normal_deg: float
    std_offset: float
    method: str
    names: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    marks_xy: np.ndarray | None = None
    rectangle: tuple[float, float] | None = None
    corners: tuple[int, ...] = ()
    located_px: np.ndarray | None = None  # (N,) each mark's localisation σ (px per axis), when known

    def scaled(self, k: float) -> PlanePose:
        """The same plane with every length multiplied by ``k`` > 0 (another distance along the same rays)."""
        return replace(self, pose=Pose(R=self.pose.R, t=self.pose.t * k), offset_cam=self.offset_cam * k,
                       point_world=self.point_world * k, std_offset=self.std_offset * k,
                       marks_xy=None if self.marks_xy is None else self.marks_xy * k,
                       rectangle=None if self.rectangle is None else (self.rectangle[0] * k, self.rectangle[1] * k))

    def to_report(self) -> dict[str, Any]:
        """JSON-ready summary (for report.json): residuals and the plane."""
        return {
            "method": self.method,
            "n_points": int(len(self.pixels)),
            "rms_px": float(self.rms_px),
            "max_px": float(self.max_px),
            "residuals_px": {n: [float(r[0]), float(r[1])] for n, r in zip(self.names, self.residuals_px, strict=True)},
            "normal_cam": [float(x) for x in self.normal_cam],
            "offset_cam": float(self.offset_cam),
            "std_normal_deg": float(self.std_normal_deg),
            "std_offset": float(self.std_offset),
            "std_offset_relative": float(self.std_offset / self.offset_cam) if self.offset_cam > 0 else float("nan"),
            "rvec": [float(x) for x in self.pose.rvec],
            "tvec": [float(x) for x in self.pose.t],
            "warnings": list(self.warnings),
            **({} if self.marks_xy is None else {
                "marks_xy": {n: [float(a), float(b)] for n, (a, b) in zip(self.names, self.marks_xy, strict=True)},
                "rectangle": [float(x) for x in self.rectangle or ()],
                "corners": [self.names[i] for i in self.corners]}),
            **({} if self.located_px is None else {"located_px": [float(x) for x in self.located_px]}),
        }


def _plane_frame(points: np.ndarray, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coplanar 3-D points → (local 2-D coordinates, origin c, basis B) with X = B·[a, b, 0] + c."""
    c = points.mean(axis=0)
    _, s, Vt = np.linalg.svd(points - c)
    if s[1] <= 1e-6 * s[0]:
        raise GnomonError(f"{where}: the points are collinear; a plane needs at least 4 points not on one line")
    extent = float(np.max(np.linalg.norm(points - c, axis=1)))
    off = float(np.max(np.abs((points - c) @ Vt[2])))
    if off > 1e-3 * extent:
        raise GnomonError(f"{where}: the points are not coplanar (one lies {off:.4g} off their best plane)")
    B = Vt.T.copy()
    if np.linalg.det(B) < 0:
        B[:, 2] *= -1
    local = (points - c) @ B
    return local[:, :2], c, B


def _pixel_residuals(camera, rvec, tvec, obj, pixels):
    R = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3))[0]
    return pixels - camera.project(obj @ R.T + tvec)


def _fit_pose_planar(camera, local2d: np.ndarray, pixels: np.ndarray, where: str):
    """Planar points (plane coordinates, z = 0) → (rvec, tvec, lm result)."""
    obj = np.concatenate([local2d, np.zeros((len(local2d), 1))], axis=1)
    rays = camera.rays(pixels)
    if not np.all(np.isfinite(rays)):
        raise GnomonError(f"{where}: some pixels have no ray in the camera model (outside its valid field)")
    norm = rays[:, :2] / rays[:, 2:3]
    n_sol, rvecs, tvecs, _ = cv2.solvePnPGeneric(
        np.ascontiguousarray(obj, dtype=np.float64).reshape(-1, 1, 3),
        np.ascontiguousarray(norm, dtype=np.float64).reshape(-1, 1, 2),
        np.eye(3),
        None,
        flags=cv2.SOLVEPNP_IPPE,
    )
    if n_sol == 0:
        raise GnomonError(f"{where}: no pose fits the points (check their order and coordinates)")
    # IPPE returns both planar solutions: keep the one that reprojects best in pixels.
    best = None
    for rv, tv in zip(rvecs, tvecs, strict=True):
        res = _pixel_residuals(camera, rv, np.asarray(tv).ravel(), obj, pixels)
        err = float(np.sum(np.nan_to_num(res, nan=1e6) ** 2))
        if best is None or err < best[0]:
            best = (err, np.asarray(rv, dtype=np.float64).ravel(), np.asarray(tv, dtype=np.float64).ravel())
    assert best is not None  # n_sol > 0 solutions were compared
    return _refine(camera, obj, pixels, best[1], best[2])


def _refine(camera, obj, pixels, rvec, tvec):
    """The pose (rvec, tvec) minimising the pixel residuals, from a closed-form start; the fit (its
    residuals and their Jacobian at the solution, for the pose's covariance)."""
    def many(ps):  # the residuals of each pose row, the rows' points projected in one call
        moved = [obj @ cv2.Rodrigues(np.asarray(p[:3], dtype=np.float64).reshape(3))[0].T + p[3:] for p in ps]
        r = (pixels - camera.project(np.concatenate(moved)).reshape(len(ps), len(obj), 2)).reshape(len(ps), -1)
        # np.nan_to_num's call costs more than the projection: only when a residual is not finite
        return r if np.isfinite(r).all() else np.nan_to_num(r, nan=1e6)

    sol = levenberg_marquardt(lambda p: many(p[None])[0], np.concatenate([rvec, tvec]), many=many)
    return sol.x[:3], sol.x[3:], sol


def _plane_from_params(p: np.ndarray) -> tuple[np.ndarray, float]:
    """(rvec, tvec) of a plane frame → (unit normal away from the camera, distance)."""
    R = cv2.Rodrigues(p[:3].reshape(3))[0]
    n = R[:, 2]
    d = float(n @ p[3:])
    return (n, d) if d >= 0 else (-n, -d)


def fit_plane_pose(
    camera,
    points: np.ndarray,
    pixels: np.ndarray,
    *,
    names: Sequence[str] | None = None,
    method: str = "points",
    source: str = "image",
) -> PlanePose:
    """Pose of a plane from ≥ 4 of its points and their pixels.

    ``camera``: any model with ``project``/``rays`` (OpenCVCamera,
    TsaiCamera). ``points``: (N, 2) coordinates on the plane, or (N, 3)
    coplanar world coordinates; ``pixels``: (N, 2) observed (distorted).
    """
    pts = np.asarray(points, dtype=np.float64)
    pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    names = tuple(names) if names is not None else tuple(f"p{i}" for i in range(len(pts)))
    where = f"{source}: plane ({method})"
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise GnomonError(f"{where}: coordinates must be (N, 2) plane or (N, 3) world coordinates, "
                          f"got shape {pts.shape}")
    if len(pts) != len(pix):
        raise GnomonError(f"{where}: {len(pts)} points but {len(pix)} pixels")
    if len(pts) < 4:
        raise GnomonError(f"{where}: a plane's pose needs at least 4 points (markers), got {len(pts)}")
    if pts.shape[1] == 2:
        c, B = np.zeros(3), np.eye(3)
        _s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        if _s[1] <= 1e-6 * _s[0]:
            raise GnomonError(f"{where}: the points are collinear; a plane needs at least 4 points not on one line")
        local = pts
    else:
        local, c, B = _plane_frame(pts, where)
    rvec_l, tvec_l, sol = _fit_pose_planar(camera, local, pix, where)
    # Local plane frame → camera; then the points' frame → camera: X_cam = R_l·Bᵀ·(X − c) + t_l.
    R_l = cv2.Rodrigues(rvec_l)[0]
    R = R_l @ B.T
    t = tvec_l - R @ c
    pose = Pose(R=R, t=t)
    n_cam, d_cam = _plane_from_params(np.concatenate([rvec_l, tvec_l]))
    obj_l = np.concatenate([local, np.zeros((len(local), 1))], axis=1)
    res = _pixel_residuals(camera, rvec_l, tvec_l, obj_l, pix)
    lengths = np.linalg.norm(res, axis=1)
    # Covariance of (rvec, tvec) from the LM Jacobian, propagated to the plane.
    m, k = sol.jac.shape
    std_n = std_d = float("nan")
    if m > k:
        s2 = float(np.sum(sol.fun**2)) / (m - k)
        cov = np.linalg.pinv(sol.jac.T @ sol.jac) * s2
        p0 = np.concatenate([rvec_l, tvec_l])
        J = np.zeros((4, 6))
        for i in range(6):
            h = 1e-7 * max(1.0, abs(p0[i]))
            dp = np.zeros(6)
            dp[i] = h
            n1, d1 = _plane_from_params(p0 + dp)
            n0, d0 = _plane_from_params(p0 - dp)
            J[:3, i] = (n1 - n0) / (2 * h)
            J[3, i] = (d1 - d0) / (2 * h)
        C = J @ cov @ J.T
        std_n = float(np.degrees(np.sqrt(max(np.trace(C[:3, :3]), 0.0))))
        std_d = float(np.sqrt(max(C[3, 3], 0.0)))
    warns = []
    if len(pts) == 4:
        warns.append(f"{where}: only 4 points: the residuals barely test the fit (2 degrees of freedom); "
                     "more markers give an honest check")
    normal_world = B[:, 2] if (R @ B[:, 2]) @ n_cam > 0 else -B[:, 2]
    return PlanePose(
        pose=pose,
        normal_cam=n_cam,
        offset_cam=d_cam,
        point_world=c.copy(),
        normal_world=normal_world,
        pixels=pix,
        residuals_px=res,
        rms_px=float(np.sqrt(np.mean(lengths**2))),
        max_px=float(lengths.max()),
        std_normal_deg=std_n,
        std_offset=std_d,
        method=method,
        names=names,
        warnings=tuple(warns),
    )


# --------------------------------------------------------------------------- the three ways


def plane_pose_from_markers(
    image: np.ndarray,
    camera,
    plane_points: np.ndarray,
    hints: np.ndarray,
    *,
    names: Sequence[str] | None = None,
    search_px: float = 30.0,
    radius_px: int = 6,
    min_contrast: float = 20.0,
    source: str = "image",
    exact: np.ndarray | None = None,
) -> PlanePose:
    """A reference plane from ≥ 4 printed 2×2 markers.

    ``image``: the frame (grey or BGR array); ``camera``: the calibrated model;
    ``plane_points``: (N, 2) marker centres on the plane, or (N, 3) coplanar
    world coordinates; ``hints``: (N, 2) approximate pixels (from the field
    log); ``names``: marker names for messages. Each marker is found within
    ``search_px`` of its hint (see :func:`find_marker`), then the pose is
    fitted (:func:`fit_plane_pose`). ``exact``: (N,) bool, hints that are
    already exact pixels (a clicked cross) and are used as given.
    """
    pts = np.asarray(plane_points, dtype=np.float64)
    hints = np.asarray(hints, dtype=np.float64).reshape(-1, 2)
    names = list(names) if names is not None else [f"m{i}" for i in range(len(hints))]
    if len(pts) != len(hints) or len(names) != len(hints):
        raise GnomonError(f"{source}: {len(pts)} marker coordinates, {len(hints)} hints and {len(names)} names")
    if len(hints) < 4:
        raise GnomonError(f"{source}: a plane from markers needs at least 4 markers, got {len(hints)}")
    exact = np.zeros(len(hints), dtype=bool) if exact is None else np.asarray(exact, dtype=bool)
    pix = hints.copy()
    refine = np.flatnonzero(~exact)
    if refine.size:
        dets = find_markers(image, hints[refine], names=[names[i] for i in refine], search_px=search_px,
                            radius_px=radius_px, min_contrast=min_contrast, source=source)
        pix[refine] = np.array([d.pixel for d in dets])
    return fit_plane_pose(camera, pts, pix, names=names, method="markers", source=source)


def plane_pose_from_chessboard(
    image: np.ndarray,
    camera,
    board: tuple[int, int],
    square: float,
    *,
    source: str = "image",
) -> PlanePose:
    """A reference plane from a chessboard lying on it.

    ``board``: inner corners (cols, rows); ``square`` in world units. The
    plane's frame is the board's: origin at the first inner corner OpenCV
    reports, x along its row of corners, z = 0 on the board and **z towards
    the camera** (up from a desk the board lies on), y = z × x. OpenCV's own
    board frame (y along the columns, in the order it reports the rows)
    mostly has its z away from the camera, into the desk: it is then turned
    a half-turn about x (y and z reversed). A board with cols and rows
    of the same parity looks the same turned by 180°, so its origin may land
    on either end: the result then carries a warning.
    """
    from gnomon.camera.calibration import board_points, detect_chessboard

    corners = detect_chessboard(image, board)
    if corners is None:
        raise GnomonError(f"{source}: no {board[0]}x{board[1]} chessboard found (inner corners)")
    obj = board_points(board[0], board[1], square)[:, :2]
    names = [f"corner {i}" for i in range(len(obj))]
    res = fit_plane_pose(camera, obj, corners, names=names, method="chessboard", source=source)
    if res.pose.R[:, 2] @ res.pose.t > 0:  # z away from the camera: the half-turn about x
        res = fit_plane_pose(camera, obj * [1.0, -1.0], corners, names=names, method="chessboard", source=source)
    if (board[0] - board[1]) % 2 == 0:
        w = (f"{source}: a {board[0]}x{board[1]} board is symmetric under a half-turn: "
             "its origin corner is ambiguous (use e.g. 9x6)")
        res = replace(res, warnings=res.warnings + (w,))
    return res


def plane_pose_from_pose(rvec: Sequence[float], tvec: Sequence[float]) -> PlanePose:
    """A reference plane given explicitly: the pose of its frame (z = 0 on the plane) in the camera frame.

    ``rvec`` Rodrigues vector (radians), ``tvec`` in world units. No
    residuals (NaN): nothing was measured.
    """
    pose = Pose.from_rvec_tvec(np.asarray(rvec, dtype=np.float64), np.asarray(tvec, dtype=np.float64))
    n, d = _plane_from_params(np.concatenate([pose.rvec, pose.t]))
    return PlanePose(
        pose=pose,
        normal_cam=n,
        offset_cam=d,
        point_world=np.zeros(3),
        normal_world=np.array([0.0, 0.0, 1.0]) if pose.R[:, 2] @ n > 0 else np.array([0.0, 0.0, -1.0]),
        pixels=np.zeros((0, 2)),
        residuals_px=np.zeros((0, 2)),
        rms_px=float("nan"),
        max_px=float("nan"),
        std_normal_deg=float("nan"),
        std_offset=float("nan"),
        method="pose",
    )


def plane_in_camera(point_world: np.ndarray, normal_world: np.ndarray,
                    world_to_camera: Pose) -> tuple[np.ndarray, float]:
    """A plane given in world coordinates → (unit normal, offset) in the camera frame, offset ≥ 0.

    For a second plane (e.g. a wall) known in the world frame that another
    plane (the desk) fixed.
    """
    n = world_to_camera.R @ (np.asarray(normal_world, dtype=np.float64) / np.linalg.norm(normal_world))
    d = float(n @ world_to_camera.world_to_camera(np.asarray(point_world, dtype=np.float64)))
    return (n, d) if d >= 0 else (-n, -d)


# --------------------------------------------------------------------------- marks nobody measured


#: Each triangle of three of a rectangle's corners covers half of it, a little more or less in perspective:
#: less than this share of the quadrilateral means three marks on one line.
MIN_CORNER_SHARE = 0.05


def _rectangle_corners(norm: np.ndarray, where: str) -> np.ndarray:
    """Indices (4,) of the marks at a rectangle's corners, in order around it: of the marks' convex hull
    (in undistorted normalised coordinates), the four vertices spanning the largest quadrilateral."""
    from itertools import combinations

    hull = [int(i) for i in cv2.convexHull(norm.astype(np.float32).reshape(-1, 1, 2), returnPoints=False).ravel()]
    if len(hull) < 4:
        raise GnomonError(f"{where}: the marks' outline has {len(hull)} corners; marks taken as a rectangle need "
                          "4 at its corners (more may lie inside or on its sides)")

    def area(p: np.ndarray) -> float:  # of a polygon, its vertices in order
        return 0.5 * abs(float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))))

    best = max(combinations(hull, 4), key=lambda quad: area(norm[list(quad)]))  # hull order: convex
    quad = norm[list(best)]
    if min(area(quad[[i, (i + 1) % 4, (i + 2) % 4]]) for i in range(4)) < MIN_CORNER_SHARE * area(quad):
        raise GnomonError(f"{where}: three of the four outermost marks lie on one line; marks taken as a "
                          "rectangle need one at each of its 4 corners")
    return np.array(best)


def _rectangle_points(p: np.ndarray) -> np.ndarray:
    """The corners (4, 3) of the rectangle of parameters ``p`` = (rvec, tvec, log height), width 1, in its
    own frame (z = 0), in the order (0, 0), (1, 0), (1, h), (0, h)."""
    h = float(np.exp(p[6]))
    return np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, h, 0.0], [0.0, h, 0.0]])


def _rectangle_start(norm: np.ndarray, where: str) -> np.ndarray:
    """Closed-form parameters (rvec, tvec, log h) of the rectangle whose corners (width 1) are seen at the
    normalised image points ``norm`` (4, 2): the homography from the unit square, its first two columns the
    rectangle's sides (orthogonalised), its third the corner's position."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=np.float32)
    H = cv2.getPerspectiveTransform(square, norm.astype(np.float32)).astype(np.float64)
    if not np.all(np.isfinite(H)):
        raise GnomonError(f"{where}: three of the marks lie on one line; a rectangle needs 4 corners")
    if H[2, 2] < 0:  # the corner in front of the camera
        H = -H
    a, b = np.linalg.norm(H[:, 0]), np.linalg.norm(H[:, 1])
    r1 = H[:, 0] / a
    r2 = H[:, 1] - (H[:, 1] @ r1) * r1
    r2 /= np.linalg.norm(r2)
    R = np.stack([r1, r2, np.cross(r1, r2)], axis=1)
    return np.concatenate([cv2.Rodrigues(R)[0].ravel(), H[:, 2] / a, [np.log(b / a)]])


@dataclass(frozen=True)
class MarkScale:
    """A known length between two marks of one plane: their indices and the length (world units)."""

    first: int
    second: int
    length: float


def fit_rectangle_pose(
    camera,
    pixels: np.ndarray,
    sigma_px: np.ndarray,
    *,
    names: Sequence[str] | None = None,
    scale: MarkScale | None = None,
    source: str = "image",
) -> PlanePose:
    """A plane from ≥ 4 marks at the corners of a rectangle of unknown size and proportions.

    ``pixels`` (N, 2) the marks as found (distorted); ``sigma_px`` (N,) how far (px, per axis, 1 σ) each
    may lie from where the rectangle puts it: its localisation and its placement off a true rectangle
    together. The four marks spanning the largest quadrilateral of their outline are the rectangle's
    corners; the others are free points of the plane (they fix nothing; their place on it is reported).
    For a calibrated camera the corners fix the plane's orientation (two vanishing points) and, beyond
    it, one right angle: 1 degree of freedom checks the rectangle (a focal length can mimic it on one
    plane). The fit is Levenberg–Marquardt on the pixel residuals (over σ) of 7 parameters: the pose of
    the rectangle of width 1 and its height, from the homography's closed form.

    The plane's frame: origin at the rectangle's centre, z towards the camera (up from a desk, out of a
    wall), x along the side nearer the image's rows (to the right), y = z × x. Its units: ``scale``'s
    length between two marks, or else the plane's distance from the camera's centre (it is 1).
    ``std_normal_deg`` from the covariance at ``sigma_px`` (scaled up by χ²/dof when the marks fit worse
    than that); ``std_offset`` the distance's σ when ``scale`` sets it, else 0 (the distance is the unit
    by convention; a plane tied to another later gets its tie's σ). ``marks_xy`` (N, 2) every mark's
    place in the plane's frame (free marks: where their ray meets the plane); ``rectangle`` its sides
    (along x, along y).
    """
    pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    sig = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (len(pix),)).copy()
    names = tuple(names) if names is not None else tuple(f"p{i}" for i in range(len(pix)))
    where = f"{source}: plane (marks as a rectangle)"
    if len(pix) < 4:
        raise GnomonError(f"{where}: a rectangle needs 4 marks at its corners, got {len(pix)}")
    rays = camera.rays(pix)
    if not np.all(np.isfinite(rays)):
        raise GnomonError(f"{where}: some pixels have no ray in the camera model (outside its valid field)")
    norm = rays[:, :2] / rays[:, 2:3]
    corners = _rectangle_corners(norm, where)
    p0 = _rectangle_start(norm[corners], where)

    def project(p: np.ndarray) -> np.ndarray:
        R = cv2.Rodrigues(p[:3].reshape(3))[0]
        return np.asarray(camera.project(_rectangle_points(p) @ R.T + p[3:6]))

    def fun(p: np.ndarray) -> np.ndarray:
        return np.nan_to_num(((pix[corners] - project(p)) / sig[corners, None]).ravel(), nan=1e6)

    sol = levenberg_marquardt(fun, p0)
    p = sol.x
    R_r = cv2.Rodrigues(p[:3].reshape(3))[0]
    corners_cam = _rectangle_points(p) @ R_r.T + p[3:6]
    n_away = R_r[:, 2] if R_r[:, 2] @ p[3:6] > 0 else -R_r[:, 2]
    # every mark on the plane: the corners as fitted, the others where their rays meet it
    offset = float(n_away @ p[3:6])
    with np.errstate(divide="ignore", invalid="ignore"):
        marks_cam = rays * (offset / (rays @ n_away))[:, None]
    marks_cam[corners] = corners_cam
    # the plane's frame: centre, x along the side nearer the image rows, z towards the camera
    z = -n_away
    sides = [R_r[:, 0], R_r[:, 1]]
    x = max(sides, key=lambda s: abs(float(s[0])))
    x = x if x[0] >= 0 else -x
    y = np.cross(z, x)
    frame = np.stack([x, y, z], axis=1)
    centre = corners_cam.mean(axis=0)
    units = offset  # the plane at distance 1 ...
    if scale is not None:  # ... or the marks' known spacing
        units = float(np.linalg.norm(marks_cam[scale.first] - marks_cam[scale.second])) / scale.length
    xy = ((marks_cam - centre) @ frame)[:, :2] / units
    residuals = pix - camera.project(marks_cam)
    lengths = np.linalg.norm(residuals, axis=1)
    dof = 2 * len(corners) - 7
    chi2 = float(np.sum(sol.fun**2))
    inflate = max(1.0, chi2 / dof) if dof > 0 else 1.0
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * inflate

    def plane_of(q: np.ndarray) -> np.ndarray:
        Rq = cv2.Rodrigues(q[:3].reshape(3))[0]
        nq = Rq[:, 2] if Rq[:, 2] @ n_away > 0 else -Rq[:, 2]
        dq = float(nq @ q[3:6])
        if scale is None:
            return np.concatenate([nq, [1.0]])
        cq = _rectangle_points(q) @ Rq.T + q[3:6]
        with np.errstate(divide="ignore", invalid="ignore"):
            mq = rays * (dq / (rays @ nq))[:, None]
        mq[corners] = cq
        return np.concatenate([nq, [dq * scale.length / float(np.linalg.norm(mq[scale.first] - mq[scale.second]))]])

    J = np.zeros((4, 7))
    for i in range(7):
        h = 1e-7 * max(1.0, abs(p[i]))
        dp = np.zeros(7)
        dp[i] = h
        J[:, i] = (plane_of(p + dp) - plane_of(p - dp)) / (2 * h)
    C = J @ cov @ J.T
    std_n = float(np.degrees(np.sqrt(max(np.trace(C[:3, :3]), 0.0))))
    std_d = float(np.sqrt(max(C[3, 3], 0.0))) if scale is not None else 0.0
    rect = (float(np.linalg.norm(corners_cam[1] - corners_cam[0])) / units,
            float(np.linalg.norm(corners_cam[3] - corners_cam[0])) / units)
    if abs(float(x @ R_r[:, 0])) < 0.5:
        rect = rect[::-1]
    pose = Pose(R=frame, t=centre / units)
    return PlanePose(
        pose=pose,
        normal_cam=n_away,
        offset_cam=offset / units,
        point_world=np.zeros(3),
        normal_world=np.array([0.0, 0.0, -1.0]),
        pixels=pix,
        residuals_px=residuals,
        rms_px=float(np.sqrt(np.mean(lengths[corners] ** 2))),
        max_px=float(lengths.max()),
        std_normal_deg=std_n,
        std_offset=std_d,
        method="rectangle",
        names=names,
        marks_xy=xy,
        rectangle=rect,
        corners=tuple(int(c) for c in corners),
    )
