"""Reference planes from ArUco markers or a ChArUco board: found by their IDs, no pixel hints.

OpenCV's ArUco module (``cv2.aruco``) finds the markers of a predefined
dictionary in an image and decodes their IDs, so a field log only says which
marker sits where on its plane. Two kinds of target:

* **ArUco markers** (:func:`plane_pose_from_aruco`): each marker ``size``
  wide (its black border included), its centre at ``plane_xy`` on the plane,
  printed with its bitmap's columns along the plane's +x and its rows along
  −y (upright when the plane is seen from the side its normal points to,
  y up). Its four corners, in OpenCV's order (top-left, top-right,
  bottom-right, bottom-left of the bitmap), are then at
  ``(a ∓ size/2, b ± size/2)`` (:func:`aruco_corner_points`). Corners are
  refined to sub-pixel by OpenCV (``CORNER_REFINE_SUBPIX``).
* **A ChArUco board** (:func:`plane_pose_from_charuco`): a chessboard of
  ``squares = (cols, rows)`` squares with ArUco markers in its white squares;
  its inner chessboard corners (X-junctions: more accurate than marker
  corners, and identified by the markers around them, so a board partly
  covered by an object still works) are the points. Board coordinates
  (OpenCV's: origin at the board's top-left corner, x right, y down) map to
  the plane as ``(a, b) = origin + (x, −y)``.

Both return a :class:`gnomon.camera.plane_pose.PlanePose` fitted by
:func:`gnomon.camera.plane_pose.fit_plane_pose` (any camera model), with the points'
names (``"id 7 corner 2"``, ``"charuco corner 12"``) for the residuals.

Frames: pixels with centres at integer coordinates (OpenCV's convention);
lengths in the plane's units.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from gnomon.camera.plane_pose import PlanePose, fit_plane_pose
from gnomon.capture.frames import grey_8bit_scale
from gnomon.errors import GnomonError

__all__ = [
    "ArucoDetection",
    "aruco_corner_points",
    "detect_aruco",
    "dictionary",
    "plane_pose_from_aruco",
    "plane_pose_from_charuco",
]


def dictionary(name: str, where: str = "aruco") -> cv2.aruco.Dictionary:
    """An OpenCV predefined ArUco dictionary by name, e.g. ``"DICT_4X4_50"``; unknown → GnomonError."""
    key = str(name).upper()
    if not key.startswith("DICT_") or not hasattr(cv2.aruco, key):
        raise GnomonError(f"{where}: unknown ArUco dictionary {name!r} (e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250)")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, key))


def _grey_u8(image: np.ndarray) -> np.ndarray:
    """The image as 8-bit grey for OpenCV's ArUco detector (:func:`gnomon.capture.frames.grey_8bit_scale`, rounded)."""
    img = np.asarray(image)
    if img.ndim == 2 and img.dtype == np.uint8:
        return img
    return np.clip(np.rint(grey_8bit_scale(img)), 0, 255).astype(np.uint8)


_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)


def _parameters() -> cv2.aruco.DetectorParameters:
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    p.cornerRefinementWinSize = 4
    p.cornerRefinementMaxIterations = 100
    p.cornerRefinementMinAccuracy = 0.001
    return p


def _sample(img: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = pts.astype(np.float32).reshape(-1, 2)
    out = cv2.remap(img, p[:, 0].reshape(1, -1), p[:, 1].reshape(1, -1), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.ravel().astype(np.float64)


def _refine_by_edges(lin: np.ndarray, corners: np.ndarray, n_cells: int) -> np.ndarray | None:
    """A marker's outer corners as intersections of its four border edges, each fitted to sub-pixel edge points.

    Along each side (its middle 70 %), the profile across the edge in linear
    intensity is searched from the paper inwards for the point where it falls
    halfway between its two ends (paper and border): unbiased for any
    symmetric blur,
    unlike a corner detector's window, which the marker's inner cells disturb.
    A line is fitted to each side's points (total least squares); adjacent
    lines meet at the corners. None when a side has too few clean crossings.
    """
    c = np.asarray(corners, dtype=np.float64)
    centre = c.mean(axis=0)
    sides = []
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        length = float(np.linalg.norm(b - a))
        d = (b - a) / length
        n = np.array([-d[1], d[0]])
        if n @ ((a + b) / 2 - centre) < 0:
            n = -n  # outward
        # Across this side the black border is one cell deep, the white paper 1.5 cells wide.
        cell = float(0.5 * (np.linalg.norm(c[(k + 2) % 4] - b) + np.linalg.norm(a - c[(k + 3) % 4])) / n_cells)
        h_in, h_out = float(min(3.0, 0.8 * cell)), float(min(3.0, 1.2 * cell))
        if h_in < 1.0:
            return None  # too small to resolve the border: keep OpenCV's corners
        ts = np.linspace(0.15, 0.85, max(int(0.7 * length), 4))
        ss = np.arange(h_out, -h_in - 1e-9, -0.25)  # from the paper inwards
        base = a[None, :] + ts[:, None] * (b - a)[None, :]
        grid = base[:, None, :] + ss[None, :, None] * n[None, None, :]
        prof = _sample(lin, grid.reshape(-1, 2)).reshape(len(ts), len(ss))
        sides.append((base, n, ss, prof))
    lines = []
    for base, n, ss, prof in sides:
        outer, inner = prof[:, :2].mean(axis=1), prof[:, -2:].mean(axis=1)
        contrast = outer - inner
        pts = []
        for i in range(len(base)):
            if not contrast[i] > 0.5 * np.median(contrast) > 0:
                continue
            level = 0.5 * (outer[i] + inner[i])
            below = np.flatnonzero(prof[i] <= level)
            if len(below) == 0 or below[0] == 0:
                continue
            j = int(below[0])
            p0, p1 = prof[i, j - 1], prof[i, j]
            s_star = ss[j - 1] + (p0 - level) / (p0 - p1) * (ss[j] - ss[j - 1])
            pts.append(base[i] + s_star * n)
        if len(pts) < 4:
            return None
        line_pts = np.array(pts)
        m = line_pts.mean(axis=0)
        _, _, vt = np.linalg.svd(line_pts - m)
        lines.append((m, vt[0]))
    out = np.empty((4, 2))
    for k in range(4):
        (m1, d1), (m2, d2) = lines[(k - 1) % 4], lines[k]
        A = np.stack([d1, -d2], axis=1)
        if abs(np.linalg.det(A)) < 1e-6:
            return None
        s1, _ = np.linalg.solve(A, m2 - m1)
        out[k] = m1 + s1 * d1
    return out


@dataclass(frozen=True)
class ArucoDetection:
    """Markers found in one image: ``corners[id]`` (4, 2) pixels in OpenCV's order; ``duplicates`` IDs seen twice."""

    corners: dict[int, np.ndarray]
    duplicates: tuple[int, ...] = ()


def detect_aruco(image: np.ndarray, dict_name: str, *, where: str = "image",
                 linear: np.ndarray | None = None) -> ArucoDetection:
    """Find every marker of the dictionary ``dict_name`` in ``image`` (grey or BGR), with sub-pixel corners.

    ``linear``: the same image in linear intensity (any float scale), where
    the corners are refined as intersections of the marker's border edges
    (:func:`_refine_by_edges`). A marker's corners are corners of a dark
    square on white paper; in gamma-encoded values its blurred edges move
    towards the dark side, so OpenCV's corners, refined on encoded values, sit
    ≈0.5 px inside the square. On our rendered two-plane frames (gamma 2.2,
    blur σ 0.7 px, 1.5 DN noise) the corners' RMS error is 0.67 px with
    OpenCV's sub-pixel refinement, 0.22 px with cornerSubPix on linear values
    and 0.07 px with the edge fit. Without ``linear``, OpenCV's corners are kept.
    """
    d = dictionary(dict_name, where)
    det = cv2.aruco.ArucoDetector(d, _parameters())
    corners, ids, _ = det.detectMarkers(_grey_u8(image))
    found: dict[int, np.ndarray] = {}
    dup: list[int] = []
    if ids is not None:
        lin = None if linear is None else np.asarray(linear, dtype=np.float32)
        for c, i in zip(corners, np.asarray(ids).ravel(), strict=True):
            k = int(i)
            if k in found:
                dup.append(k)
            pts = np.asarray(c, dtype=np.float64).reshape(4, 2)
            if lin is not None:
                ref = _refine_by_edges(lin, pts, int(d.markerSize) + 2)
                side = float(np.min(np.linalg.norm(pts - np.roll(pts, 1, axis=0), axis=1)))
                if ref is not None and np.all(np.linalg.norm(ref - pts, axis=1) < max(1.5, 0.1 * side)):
                    pts = ref  # (a refinement that slid away is dropped)
            found[k] = pts
    return ArucoDetection(corners=found, duplicates=tuple(sorted(set(dup))))


def aruco_corner_points(centre: Sequence[float], size: float) -> np.ndarray:
    """(4, 2) plane coordinates of a marker's corners, OpenCV's order (TL, TR, BR, BL of the bitmap)."""
    a, b = float(centre[0]), float(centre[1])
    h = float(size) / 2.0
    return np.array([[a - h, b + h], [a + h, b + h], [a + h, b - h], [a - h, b - h]])


def plane_pose_from_aruco(
    image: np.ndarray,
    camera,
    markers: Mapping[int, Sequence[float]],
    dict_name: str,
    size: float,
    *,
    linear: np.ndarray | None = None,
    to_world: Callable[[np.ndarray], np.ndarray] | None = None,
    source: str = "image",
    min_markers: int = 2,
) -> PlanePose:
    """A reference plane from the ArUco markers printed on it.

    ``markers``: ``{id: (a, b)}`` the centres on the plane (world units);
    ``dict_name``: the dictionary (e.g. ``"DICT_4X4_50"``); ``size``: each
    marker's side, black border included (world units). Markers of other IDs
    in the image are ignored (they may belong to another plane). At least
    ``min_markers`` of the declared markers must be found; those missing are
    named in a warning. An ID seen twice is an error (two prints of one marker).
    ``linear``: the image in linear intensity, for the corners' refinement
    (see :func:`detect_aruco`; give it whenever the input's gamma is known).
    ``to_world``: maps (N, 2) plane coordinates to (N, 3) world coordinates;
    then the pose is the world frame's (as for markers given in world
    coordinates), else the plane frame's.
    """
    if not size > 0:
        raise GnomonError(f"{source}: ArUco marker size must be positive, got {size!r}")
    found = detect_aruco(image, dict_name, where=source, linear=linear)
    dup = [i for i in found.duplicates if i in markers]
    if dup:
        raise GnomonError(f"{source}: ArUco marker id {dup[0]} appears twice in the image; "
                          "each printed marker needs its own id")
    ids = [i for i in markers if i in found.corners]
    missing = [i for i in markers if i not in found.corners]
    if len(ids) < min_markers:
        seen = sorted(found.corners)
        raise GnomonError(
            f"{source}: found {len(ids)} of the plane's {len(markers)} ArUco markers ({dict_name}; missing ids "
            f"{', '.join(map(str, missing))}; ids seen in the image: {', '.join(map(str, seen)) or 'none'}); "
            f"need at least {min_markers}"
        )
    obj = np.concatenate([aruco_corner_points(markers[i], size) for i in ids])
    if to_world is not None:
        obj = to_world(obj)
    pix = np.concatenate([found.corners[i] for i in ids])
    names = [f"id {i} corner {k}" for i in ids for k in range(4)]
    res = fit_plane_pose(camera, obj, pix, names=names, method="aruco", source=source)
    if missing:
        w = (f"{source}: ArUco markers not found: ids {', '.join(map(str, missing))} "
             f"(the plane's pose uses the {len(ids)} others)")
        res = replace(res, warnings=res.warnings + (w,))
    return res


def plane_pose_from_charuco(
    image: np.ndarray,
    camera,
    dict_name: str,
    squares: tuple[int, int],
    square: float,
    marker: float,
    *,
    origin: Sequence[float] = (0.0, 0.0),
    to_world: Callable[[np.ndarray], np.ndarray] | None = None,
    source: str = "image",
    min_corners: int = 6,
) -> PlanePose:
    """A reference plane from a ChArUco board lying on it.

    ``squares``: (cols, rows) squares of the board; ``square``, ``marker``:
    the sides of a square and of a marker (world units); ``origin``: where the
    board's top-left corner lies on the plane. The board's inner corners that
    OpenCV interpolates from the markers it sees are the points: a board
    partly covered by an object still gives a plane while ``min_corners``
    corners remain. ``to_world`` as for :func:`plane_pose_from_aruco`. A corner whose residual is
    over 4× the median (and 1 px) — pulled off by an occluding edge — is left out once, with a warning.
    """
    cols, rows = (int(x) for x in squares)
    if cols < 2 or rows < 2:
        raise GnomonError(f"{source}: a ChArUco board needs at least 2x2 squares, got {cols}x{rows}")
    if not (square > 0 and 0 < marker < square):
        raise GnomonError(f"{source}: ChArUco sizes: need square > marker > 0, "
                          f"got square {square!r}, marker {marker!r}")
    d = dictionary(dict_name, source)
    n_markers = (cols * rows) // 2
    if n_markers > d.bytesList.shape[0]:
        raise GnomonError(f"{source}: a {cols}x{rows} ChArUco board needs {n_markers} markers; {dict_name} has "
                          f"{d.bytesList.shape[0]}")
    board = cv2.aruco.CharucoBoard((cols, rows), float(square), float(marker), d)
    cd = cv2.aruco.CharucoDetector(board)
    ch_corners, ch_ids, _, _ = cd.detectBoard(_grey_u8(image))
    n = 0 if ch_ids is None else len(ch_ids)
    if n < min_corners:
        raise GnomonError(
            f"{source}: ChArUco board {cols}x{rows} ({dict_name}) not found: {n} of its {(cols - 1) * (rows - 1)} "
            f"inner corners seen, need at least {min_corners}"
        )
    ids = np.asarray(ch_ids).ravel().astype(int)
    pix = np.asarray(ch_corners, dtype=np.float64).reshape(-1, 2)
    bxy = np.asarray(board.getChessboardCorners(), dtype=np.float64)[ids, :2]
    obj = np.asarray(origin, dtype=np.float64) + bxy * np.array([1.0, -1.0])
    if to_world is not None:
        obj = to_world(obj)
    names = [f"charuco corner {i}" for i in ids]
    res = fit_plane_pose(camera, obj, pix, names=names, method="charuco", source=source)
    # A corner at the edge of an object standing on the board can be pulled off
    # by it: drop corners whose residual is far above the others', once.
    err = np.linalg.norm(res.residuals_px, axis=1)
    bad = err > max(1.0, 4.0 * float(np.median(err)))
    if bad.any() and (~bad).sum() >= min_corners:
        keep = ~bad
        dropped = ", ".join(f"{n} ({e:.1f} px)" for n, e, b in zip(names, err, bad, strict=True) if b)
        res = fit_plane_pose(camera, obj[keep], pix[keep], names=[n for n, k in zip(names, keep, strict=True) if k],
                             method="charuco", source=source)
        res = replace(res, warnings=res.warnings + (f"{source}: ChArUco corners off the board's fit, left out: "
                                                    f"{dropped}",))
    return res
