"""Synthetic frames of reference planes carrying printed 2×2 checker markers.

Ground truth for :mod:`gnomon.camera.plane_pose`. By design nothing here comes from
the code it checks: rays come from the simulator's own camera models
(:mod:`gnomon.simulate.chessboard`), are cast onto the planes by our own
intersection code, and the markers' true pixels are our own projections.

A marker is a square of white paper ``1.5 × size`` wide with a 2×2 checker
``size`` wide printed in its middle (the two squares where
``(a − a0)·(b − b0) > 0`` are black); its centre ``(a0, b0)`` is the
X-junction the detector looks for. Plane coordinates ``(a, b)`` map to the
world as ``origin + a·x_axis + b·y_axis``.

ArUco markers (:func:`aruco_bits`, :func:`aruco_class`) are drawn from
OpenCV's dictionary bitmaps (the published codes; a file format, not scanning
code): a marker ``size`` wide, its black border included, centred at
``(a0, b0)``, its bitmap's columns along +a and its rows along −b (it reads
upright when the plane is seen from the side its normal points to, with b
up). So its corners, in OpenCV's order (top-left, top-right, bottom-right,
bottom-left of the bitmap), are at ``(a0 ∓ size/2, b0 ± size/2)``:
:func:`aruco_corners`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from gnomon.simulate.chessboard import SampleRays, TruthCamera, default_truth_camera, finish_image
from gnomon.simulate.geometry import look_at


@functools.lru_cache(maxsize=256)
def aruco_bits(dictionary: str, marker_id: int) -> np.ndarray:
    """The ArUco marker's bitmap with its one-cell black border: (n+2, n+2) bool, True = black.

    ``dictionary``: an OpenCV predefined dictionary name, e.g. ``"DICT_4X4_50"``.
    """
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n = int(d.markerSize) + 2
    img = cv2.aruco.generateImageMarker(d, int(marker_id), n)
    return img < 128


def aruco_class(ab: np.ndarray, bits: np.ndarray, size: float, paper: float) -> np.ndarray:
    """Printed class at plane offsets ab (..., 2) from an ArUco marker's centre: 0 off the paper, 1 white, 2 black.

    ``size``: the marker's side (border included); ``paper``: the white square's side.
    """
    a, b = ab[..., 0], ab[..., 1]
    n = bits.shape[0]
    cell = size / n
    col = np.floor((a + size / 2) / cell).astype(np.int64)
    row = np.floor((size / 2 - b) / cell).astype(np.int64)
    inside = (col >= 0) & (col < n) & (row >= 0) & (row < n)
    black = np.zeros(a.shape, dtype=bool)
    black[inside] = bits[row[inside], col[inside]]
    on_paper = (np.abs(a) < paper / 2) & (np.abs(b) < paper / 2)
    return np.where(black, 2, np.where(on_paper, 1, 0)).astype(np.int8)


def aruco_corners(centre: Sequence[float], size: float) -> np.ndarray:
    """(4, 2) plane coordinates of an ArUco marker's corners in OpenCV's order (TL, TR, BR, BL of its bitmap)."""
    a0, b0 = float(centre[0]), float(centre[1])
    h = size / 2
    return np.array([[a0 - h, b0 + h], [a0 + h, b0 + h], [a0 + h, b0 - h], [a0 - h, b0 - h]])


@dataclass(frozen=True)
class CharucoPrint:
    """A ChArUco board printed on a plane, on white paper one square wider all round.

    ``squares`` (cols, rows), ``square`` and ``marker`` sides (world units),
    ``origin``: the board's top-left corner in plane coordinates; board
    coordinates (x right, y down, OpenCV's) map to the plane as
    ``(a, b) = origin + (x, −y)``. The layout (which squares hold which
    marker) is OpenCV's board definition; the bitmaps its dictionary's.
    """

    dictionary: str
    squares: tuple[int, int]
    square: float
    marker: float
    origin: tuple[float, float] = (0.0, 0.0)

    def _layout(self) -> tuple[np.ndarray, np.ndarray]:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard(tuple(self.squares), float(self.square), float(self.marker), d)
        return np.asarray(board.getIds()).ravel(), np.asarray(board.getObjPoints(), dtype=np.float64)[:, :, :2]

    def inner_corners(self) -> np.ndarray:
        """Plane coordinates (K, 2) of the inner chessboard corners, OpenCV's ChArUco corner order."""
        cols, rows = self.squares
        j, i = np.mgrid[1:rows, 1:cols]
        xy = np.stack([i.ravel(), j.ravel()], axis=1) * self.square
        return np.asarray(self.origin) + xy * np.array([1.0, -1.0])

    def printed_class(self, ab: np.ndarray) -> np.ndarray:
        """0 off the paper, 1 white, 2 black at plane coordinates ab (..., 2)."""
        cols, rows = self.squares
        sq = self.square
        xa = ab[..., 0] - self.origin[0]
        ya = self.origin[1] - ab[..., 1]
        on_paper = (xa > -sq) & (xa < (cols + 1) * sq) & (ya > -sq) & (ya < (rows + 1) * sq)
        out = np.zeros(xa.shape, dtype=np.int8)
        out[on_paper] = self._class_on_paper(xa[on_paper], ya[on_paper])
        return out

    def _class_on_paper(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        cols, rows = self.squares
        sq = self.square
        on_board = (x >= 0) & (x < cols * sq) & (y >= 0) & (y < rows * sq)
        i = np.floor(x / sq).astype(np.int64)
        j = np.floor(y / sq).astype(np.int64)
        ids, corners = self._layout()
        white_sq = np.zeros((rows, cols), dtype=bool)
        black = np.zeros(x.shape, dtype=bool)
        for mid, c in zip(ids, corners, strict=True):
            x0, y0 = c[0]
            white_sq[int(y0 // sq), int(x0 // sq)] = True
            bits = aruco_bits(self.dictionary, int(mid))
            n = bits.shape[0]
            cell = self.marker / n
            col = np.floor((x - x0) / cell).astype(np.int64)
            row = np.floor((y - y0) / cell).astype(np.int64)
            inside = (col >= 0) & (col < n) & (row >= 0) & (row < n)
            black[inside] |= bits[row[inside], col[inside]]
        ii, jj = np.clip(i, 0, cols - 1), np.clip(j, 0, rows - 1)
        black |= on_board & ~white_sq[jj, ii]
        return np.where(black, 2, 1).astype(np.int8)


@dataclass(frozen=True)
class PrintedMarker:
    name: str
    ab: tuple[float, float]  # centre, plane coordinates (world units)
    size: float = 30.0  # side of the 2×2 pattern, or of the ArUco marker with its border (world units)
    aruco_id: int | None = None  # None: a 2×2 checker; else this ArUco marker of the plane's dictionary


@dataclass(frozen=True)
class ScenePlane:
    """A finite rectangle ``a0 ≤ a ≤ a1, b0 ≤ b ≤ b1`` of a plane, with markers on it."""

    name: str
    origin: tuple[float, float, float]
    x_axis: tuple[float, float, float]
    y_axis: tuple[float, float, float]
    extent: tuple[float, float, float, float]
    albedo: float = 0.45
    markers: tuple[PrintedMarker, ...] = ()
    texture: float = 0.08  # relative amplitude of a smooth albedo pattern
    aruco_dictionary: str = "DICT_4X4_50"
    charuco: CharucoPrint | None = None

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(self.x_axis, self.y_axis)
        return n / np.linalg.norm(n)

    def to_world(self, ab: np.ndarray) -> np.ndarray:
        ab = np.asarray(ab, dtype=np.float64).reshape(-1, 2)
        return np.asarray(self.origin) + ab[:, :1] * np.asarray(self.x_axis) + ab[:, 1:2] * np.asarray(self.y_axis)


@dataclass(frozen=True)
class MarkerScene:
    camera: TruthCamera
    R: np.ndarray  # world → camera
    t: np.ndarray
    planes: tuple[ScenePlane, ...]
    background: float = 0.15

    def marker_pixels(self, plane: ScenePlane) -> np.ndarray:
        """True pixels (N, 2) of the plane's marker centres (our own projection)."""
        w = plane.to_world(np.array([m.ab for m in plane.markers]))
        return self.camera.project(w @ self.R.T + self.t)

    def plane_in_camera(self, plane: ScenePlane) -> tuple[np.ndarray, float]:
        """(unit normal pointing away from the camera, distance from the optical centre)."""
        n = self.R @ plane.normal
        d = float(n @ (self.R @ np.asarray(plane.origin) + self.t))
        return (n, d) if d >= 0 else (-n, -d)


def _albedo(plane: ScenePlane, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # A smooth, non-periodic texture (no saddles sharp enough to pass for a marker).
    tex = 1.0 + plane.texture * (np.sin(a / 37.0 + 0.3) * np.cos(b / 53.0) + 0.5 * np.sin((a + b) / 91.0))
    val = plane.albedo * tex
    for m in plane.markers:
        # Work on the samples that fall on this marker's paper only.
        idx = np.flatnonzero((np.abs(a - m.ab[0]) <= 0.75 * m.size) & (np.abs(b - m.ab[1]) <= 0.75 * m.size))
        da, db = a[idx] - m.ab[0], b[idx] - m.ab[1]
        if m.aruco_id is not None:
            cls = aruco_class(np.stack([da, db], axis=-1), aruco_bits(plane.aruco_dictionary, m.aruco_id), m.size,
                              1.5 * m.size)
            val[idx] = np.where(cls == 2, 0.06, 0.9)
            continue
        pattern = (np.abs(da) <= 0.5 * m.size) & (np.abs(db) <= 0.5 * m.size) & (da * db > 0)
        val[idx] = np.where(pattern, 0.06, 0.9)
    if plane.charuco is not None:
        cls = plane.charuco.printed_class(np.stack([a, b], axis=-1))
        val = np.where(cls == 2, 0.06, np.where(cls == 1, 0.9, val))
    return val


def render(scene: MarkerScene, rays: SampleRays, *, gain: float = 255.0, blur_px: float = 0.7, noise_dn: float = 1.0,
           seed: int = 0) -> np.ndarray:
    """Ray-cast the planes (nearest hit wins); grey uint8 (H, W)."""
    C = -scene.R.T @ scene.t
    chunk = 262144  # keeps the temporaries in cache
    val = np.concatenate([_shade(scene, rays.xy[i : i + chunk], C) for i in range(0, len(rays.xy), chunk)])
    return finish_image(rays.average(val * gain), blur_px=blur_px, noise_dn=noise_dn, seed=seed)


def _shade(scene: MarkerScene, xy: np.ndarray, C: np.ndarray) -> np.ndarray:
    d_w = np.concatenate([xy, np.ones((len(xy), 1))], axis=1) @ scene.R  # Rᵀ·d for each row
    best = np.full(len(xy), np.inf)
    val = np.full(len(xy), scene.background)
    for plane in scene.planes:
        n = plane.normal
        o = np.asarray(plane.origin, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = ((o - C) @ n) / (d_w @ n)
        oc = C - o
        a = oc @ np.asarray(plane.x_axis) + lam * (d_w @ np.asarray(plane.x_axis))
        b = oc @ np.asarray(plane.y_axis) + lam * (d_w @ np.asarray(plane.y_axis))
        a0, a1, b0, b1 = plane.extent
        hit = (lam > 0) & (lam < best) & (a >= a0) & (a <= a1) & (b >= b0) & (b <= b1)
        if np.any(hit):
            val[hit] = _albedo(plane, a[hit], b[hit])
            best[hit] = lam[hit]
    return val


def desk_and_wall_scene(camera: TruthCamera | None = None, *, marker_size: float = 30.0) -> MarkerScene:
    """A desk (z = 0, z up) meeting a wall (y = 250 mm), 4 markers on each, seen from above and in front. Units: mm."""
    camera = camera or default_truth_camera()
    R, t = look_at(eye=(40.0, -620.0, 520.0), target=(0.0, 60.0, 90.0))
    desk = ScenePlane(
        name="desk",
        origin=(0.0, 0.0, 0.0),
        x_axis=(1.0, 0.0, 0.0),
        y_axis=(0.0, 1.0, 0.0),
        extent=(-420.0, 420.0, -320.0, 250.0),
        albedo=0.45,
        markers=tuple(
            PrintedMarker(n, ab, marker_size)
            for n, ab in (("d1", (-230.0, -170.0)), ("d2", (230.0, -170.0)), ("d3", (230.0, 190.0)),
                          ("d4", (-230.0, 190.0)))
        ),
    )
    wall = ScenePlane(
        name="wall",
        origin=(0.0, 250.0, 0.0),
        x_axis=(1.0, 0.0, 0.0),
        y_axis=(0.0, 0.0, 1.0),
        extent=(-420.0, 420.0, 0.0, 500.0),
        albedo=0.6,
        markers=tuple(
            PrintedMarker(n, ab, marker_size)
            for n, ab in (("w1", (-230.0, 70.0)), ("w2", (230.0, 70.0)), ("w3", (230.0, 300.0)),
                          ("w4", (-230.0, 300.0)))
        ),
    )
    return MarkerScene(camera=camera, R=R, t=t, planes=(desk, wall))
