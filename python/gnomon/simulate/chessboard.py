"""Synthetic chessboard views with known intrinsics, distortion and poses.

The ground truth for the calibration suite. By design the simulator shares
no geometry with the code it checks: the camera models here (OpenCV's
5-coefficient model and Tsai's κ1 model) are our own implementations of the
published formulas — forward projection, and the inverse (distorted pixel →
ray) by our own Newton iteration — and the renderer casts one ray per
sub-sample onto the board plane. Only file formats are shared.

Frames: camera as OpenCV's (x right, y down, z forward), pixel centres at
integer coordinates; a pose maps board (world) to camera, ``X_cam = R·X + t``.
The board's inner corners are at ``(i·square, j·square, 0)``, i < cols,
j < rows, in OpenCV's order (i fastest) — what cv2.findChessboardCornersSB
reports for ``patternSize = (cols, rows)``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

# --------------------------------------------------------------------------- truth cameras


@dataclass(frozen=True)
class TruthPinhole:
    """OpenCV's pinhole + (k1, k2, p1, p2, k3) model; our own implementation.

    ``fx, fy, cx, cy`` in pixels. Distortion acts on normalised coordinates
    (x/z, y/z), undistorted → distorted.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def _distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k1, k2, p1, p2, k3 = self.dist
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return xd, yd

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) → pixels (N, 2)."""
        p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        xd, yd = self._distort(p[:, 0] / p[:, 2], p[:, 1] / p[:, 2])
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=1)

    def normalised(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) → undistorted (x/z, y/z) by Newton's method on the 2×2 system."""
        pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        xd = (pix[:, 0] - self.cx) / self.fx
        yd = (pix[:, 1] - self.cy) / self.fy
        k1, k2, p1, p2, k3 = self.dist
        x, y = xd.copy(), yd.copy()
        for _ in range(50):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r²
            fx_, fy_ = self._distort(x, y)
            ex, ey = fx_ - xd, fy_ - yd
            j11 = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
            j12 = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
            j21 = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
            j22 = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
            det = j11 * j22 - j12 * j21
            sx = (j22 * ex - j12 * ey) / det
            sy = (j11 * ey - j21 * ex) / det
            x -= sx
            y -= sy
            if np.max(np.abs(sx)) < 1e-14 and np.max(np.abs(sy)) < 1e-14:
                break
        return np.stack([x, y], axis=1)


@dataclass(frozen=True)
class TruthTsai:
    """Tsai's model; our own implementation (see gnomon.camera.models.TsaiCamera for the formulas).

    ``f_mm`` (mm), ``kappa1`` (1/mm², ``Xu = Xd·(1 + κ1·r²)``), ``cx, cy``
    (pixels), ``dx_mm, dy_mm`` (pixel pitch, mm), ``sx``.
    """

    width: int
    height: int
    f_mm: float
    kappa1: float
    cx: float
    cy: float
    dx_mm: float
    dy_mm: float
    sx: float = 1.0

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        xu = self.f_mm * p[:, 0] / p[:, 2]
        yu = self.f_mm * p[:, 1] / p[:, 2]
        ru = np.hypot(xu, yu)
        # Cubic κ1·rd³ + rd − ru = 0: Cardano's real root for κ1 > 0, then
        # Newton to polish (κ1 < 0: Newton alone from rd = ru).
        k = self.kappa1
        if k > 0:
            q = ru / (2.0 * k)
            p3 = (1.0 / (3.0 * k)) ** 3
            s = np.sqrt(q * q + p3)
            rd = np.cbrt(q + s) + np.cbrt(q - s)
        else:
            rd = ru.copy()
        for _ in range(30):
            rd = rd - (k * rd**3 + rd - ru) / (3.0 * k * rd**2 + 1.0)
        scale = np.divide(rd, ru, out=np.ones_like(ru), where=ru > 0)
        xd, yd = xu * scale, yu * scale
        return np.stack([self.sx * xd / self.dx_mm + self.cx, yd / self.dy_mm + self.cy], axis=1)

    def normalised(self, pixels: np.ndarray) -> np.ndarray:
        pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        xd = (pix[:, 0] - self.cx) * self.dx_mm / self.sx
        yd = (pix[:, 1] - self.cy) * self.dy_mm
        g = 1.0 + self.kappa1 * (xd * xd + yd * yd)
        return np.stack([xd * g / self.f_mm, yd * g / self.f_mm], axis=1)


TruthCamera = TruthPinhole | TruthTsai


def default_truth_camera(width: int = 1280, height: int = 960) -> TruthPinhole:
    """A webcam-like camera: ≈62° horizontal field, barrel distortion, off-centre principal point."""
    s = width / 1280.0
    return TruthPinhole(
        width=width,
        height=height,
        fx=1050.0 * s,
        fy=1048.0 * s,
        cx=(width - 1) / 2.0 + 7.5 * s,
        cy=(height - 1) / 2.0 - 5.25 * s,
        dist=(-0.12, 0.08, 4e-4, -3e-4, -0.02),
    )


# --------------------------------------------------------------------------- board and poses


def board_points(cols: int, rows: int, square: float) -> np.ndarray:
    """Inner-corner coordinates (N, 3) on the board plane, OpenCV's order."""
    i, j = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    return np.stack([i.ravel() * square, j.ravel() * square, np.zeros(i.size)], axis=1)


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(axis, dtype=np.float64) * angle)[0]


def _board_outline(camera: TruthCamera, cols: int, rows: int,
                   square: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The board's paper outline (one square beyond the inner corners; (4, 3), board frame), its centre
    (board frame) and the camera's focal length in pixels."""
    outline = np.array(
        [[-square, -square, 0], [cols * square, -square, 0], [cols * square, rows * square, 0],
         [-square, rows * square, 0]],
        dtype=np.float64,
    )
    centre = np.array([(cols - 1) * square / 2, (rows - 1) * square / 2, 0.0])
    f = camera.fx if isinstance(camera, TruthPinhole) else camera.f_mm / camera.dy_mm
    return outline, centre, f


def _in_view(camera: TruthCamera, corners_cam: np.ndarray, margin_px: float) -> bool:
    """Whether points (camera frame) are in front of the camera and at least ``margin_px`` inside the image."""
    if np.any(corners_cam[:, 2] <= 0):
        return False
    pix = camera.project(corners_cam)
    return bool(np.all(pix[:, 0] > margin_px) and np.all(pix[:, 0] < camera.width - 1 - margin_px)
                and np.all(pix[:, 1] > margin_px) and np.all(pix[:, 1] < camera.height - 1 - margin_px))


def _random_ray(rng: np.random.Generator, camera: TruthCamera, f: float, spread: float) -> np.ndarray:
    """The pinhole ray (x, y, 1) through a random pixel within ``spread`` × the image size of its centre."""
    u = rng.uniform(0.5 - spread, 0.5 + spread) * camera.width
    v = rng.uniform(0.5 - spread, 0.5 + spread) * camera.height
    return np.array([(u - camera.cx) / f, (v - camera.cy) / f, 1.0])


def random_poses(
    camera: TruthCamera,
    cols: int,
    rows: int,
    square: float,
    n: int = 12,
    *,
    seed: int = 0,
    tilt_deg: tuple[float, float] = (15.0, 45.0),
    fill: tuple[float, float] = (0.35, 0.7),
    margin_px: float = 20.0,
    spread: float = 0.2,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` board poses (R, t) with the whole board (plus one square of margin) in view.

    Each board is tilted by an angle in ``tilt_deg`` about a random in-plane
    axis, turned by up to ±20° in-plane, and placed so that its width spans a
    fraction ``fill`` of the image, its centre aimed at a point at most
    ``spread`` × the image size from the image centre.
    """
    rng = np.random.default_rng(seed)
    outline, centre, f = _board_outline(camera, cols, rows, square)
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n:
        tries += 1
        if tries > 10000:
            raise RuntimeError("could not place the boards in view; use a smaller board or fill")
        tilt = math.radians(rng.uniform(*tilt_deg))
        phi = rng.uniform(0, 2 * math.pi)
        axis = np.array([math.cos(phi), math.sin(phi), 0.0])
        spin = math.radians(rng.uniform(-20, 20))
        R = _rot(axis, tilt) @ _rot(np.array([0, 0, 1.0]), spin)
        width_frac = rng.uniform(*fill)
        depth = f * (cols + 1) * square / (width_frac * camera.width)
        ray = _random_ray(rng, camera, f, spread)
        t = ray * depth - R @ centre
        if _in_view(camera, outline @ R.T + t, margin_px):
            poses.append((R, t))
    return poses


def coplanar_poses(
    camera: TruthCamera,
    cols: int,
    rows: int,
    square: float,
    n: int = 12,
    *,
    seed: int = 0,
    tilt_deg: float = 50.0,
    fill: float = 0.35,
    margin_px: float = 20.0,
    spread: float = 0.3,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` board poses (R, t) that all lie in one plane: the board moved about and turned on a desk that
    the camera sees tilted by ``tilt_deg`` from face-on (the paper's calibration set-up).

    The desk is at the depth where a board in the image's centre spans ``fill`` of the image's width; each
    board is turned about the desk's normal by a random angle and centred on the desk where a random ray
    within ``spread`` × the image size of its centre meets it, with the whole board (plus one square)
    in view. Every pose has the desk's normal as its z axis: the views are exactly coplanar.
    """
    rng = np.random.default_rng(seed)
    outline, centre, f = _board_outline(camera, cols, rows, square)
    desk = _rot(np.array([1.0, 0.0, 0.0]), math.radians(tilt_deg))  # board frame → camera, turned about x
    normal = desk[:, 2]
    depth = f * (cols + 1) * square / (fill * camera.width)
    point = np.array([0.0, 0.0, depth])  # the desk passes through it
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n:
        tries += 1
        if tries > 10000:
            raise RuntimeError("could not place the boards in view; use a smaller board or fill")
        R = desk @ _rot(np.array([0, 0, 1.0]), rng.uniform(0, 2 * math.pi))
        ray = _random_ray(rng, camera, f, spread)
        lam = float(normal @ point) / float(normal @ ray)
        if not lam > 0:
            continue
        t = ray * lam - R @ centre
        if _in_view(camera, outline @ R.T + t, margin_px):
            poses.append((R, t))
    return poses


def synthetic_corners(
    camera: TruthCamera,
    cols: int,
    rows: int,
    square: float,
    poses: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    noise_px: float = 0.0,
    seed: int = 0,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Object points and pixels (Gaussian noise ``noise_px`` per axis) for each pose."""
    rng = np.random.default_rng(seed)
    obj = board_points(cols, rows, square)
    objs, pixs = [], []
    for R, t in poses:
        pix = camera.project(obj @ R.T + t)
        pixs.append(pix + rng.normal(0.0, noise_px, pix.shape))
        objs.append(obj.copy())
    return objs, pixs


# --------------------------------------------------------------------------- rendering


class SampleRays:
    """Undistorted rays (x/z, y/z) of n×n sub-samples per pixel, computed once per camera."""

    def __init__(self, camera: TruthCamera, supersample: int = 3):
        self.camera = camera
        self.n = int(supersample)
        offs = (np.arange(self.n) + 0.5) / self.n - 0.5
        u = (np.arange(camera.width)[None, :, None, None] + offs[None, None, None, :]).astype(np.float64)
        v = (np.arange(camera.height)[:, None, None, None] + offs[None, None, :, None]).astype(np.float64)
        shape = (camera.height, camera.width, self.n, self.n)
        pix = np.stack([np.broadcast_to(u, shape).ravel(), np.broadcast_to(v, shape).ravel()], axis=1)
        # In chunks: the Newton iteration's temporaries then stay in cache (≈10× faster).
        self.xy = np.concatenate([camera.normalised(pix[i : i + 262144]) for i in range(0, len(pix), 262144)])

    def average(self, values: np.ndarray) -> np.ndarray:
        """Per-sample values → per-pixel means, (H, W)."""
        c = self.camera
        return values.reshape(c.height, c.width, self.n * self.n).mean(axis=2)


def _plane_coords(xy: np.ndarray, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intersect rays (x, y, 1) with the plane z = 0 of the frame (R, t); plane coordinates and depth."""
    n = R[:, 2]
    d = float(n @ t)
    denom = xy[:, 0] * n[0] + xy[:, 1] * n[1] + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = d / denom
    px = lam * xy[:, 0] - t[0]
    py = lam * xy[:, 1] - t[1]
    pz = lam - t[2]
    a = R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz
    b = R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz
    return a, b, lam


def finish_image(radiance: np.ndarray, *, blur_px: float = 0.5, noise_dn: float = 1.0, seed: int = 0) -> np.ndarray:
    """Optics and sensor: Gaussian PSF, Gaussian read noise (DN), 8-bit quantisation."""
    img: np.ndarray = radiance.astype(np.float32)
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    if noise_dn > 0:
        img = img + np.random.default_rng(seed).normal(0.0, noise_dn, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def render_view(
    rays: SampleRays,
    cols: int,
    rows: int,
    square: float,
    R: np.ndarray,
    t: np.ndarray,
    *,
    black: float = 25.0,
    white: float = 225.0,
    background: float = 110.0,
    margin_squares: float = 1.0,
    blur_px: float = 0.5,
    noise_dn: float = 1.0,
    seed: int = 0,
) -> np.ndarray:
    """Render one view of the board, grey uint8 (H, W).

    The board has (cols+1)×(rows+1) squares around the inner corners, the
    square at the origin corner black, on white paper ``margin_squares``
    wide, against a flat ``background``.
    """
    a, b, lam = _plane_coords(rays.xy, R, t)
    i = np.floor(a / square)
    j = np.floor(b / square)
    on_board = (i >= -1) & (i <= cols - 1) & (j >= -1) & (j <= rows - 1)
    m = margin_squares * square
    on_paper = (a >= -square - m) & (a <= cols * square + m) & (b >= -square - m) & (b <= rows * square + m)
    val = np.full(a.shape, background)
    val[on_paper] = white
    dark = on_board & (((i + j) % 2) == 1)
    val[dark] = black
    val[~(lam > 0)] = background
    return finish_image(rays.average(val), blur_px=blur_px, noise_dn=noise_dn, seed=seed)


def write_chessboard_views(
    out_dir: str | os.PathLike,
    *,
    camera: TruthCamera | None = None,
    cols: int = 9,
    rows: int = 6,
    square: float = 25.0,
    n_views: int = 12,
    seed: int = 0,
    supersample: int = 3,
    noise_dn: float = 1.0,
    coplanar: bool = False,
) -> dict:
    """Render ``n_views`` PNG views and a ``truth.toml`` into ``out_dir``; ``coplanar``: the board lies on
    one desk in every view (:func:`coplanar_poses`), else it is held up turned and tilted (:func:`random_poses`).

    ``truth.toml`` holds the camera (model, intrinsics, distortion), the board
    and each view's pose (rvec radians, tvec in the board's units). Returns
    the same content as a dict. Files are written atomically.
    """
    from gnomon.util import atomic, toml_io  # file formats only

    camera = camera or default_truth_camera()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    poses = (coplanar_poses if coplanar else random_poses)(camera, cols, rows, square, n_views, seed=seed)
    rays = SampleRays(camera, supersample)
    views = []
    for k, (R, t) in enumerate(poses):
        img = render_view(rays, cols, rows, square, R, t, noise_dn=noise_dn, seed=seed * 1000 + k)
        name = f"view_{k:02d}.png"
        ok, buf = cv2.imencode(".png", img)
        atomic.write_bytes(out / name, buf.tobytes())
        views.append({"image": name, "rvec": cv2.Rodrigues(R)[0].ravel().tolist(), "tvec": list(map(float, t))})
    truth = {"board": {"cols": cols, "rows": rows, "square": square}, "camera": truth_camera_table(camera),
             "views": views}
    toml_io.dump(truth, out / "truth.toml", header="Ground truth of `gnomon simulate chessboard` (board units for "
                                                   "lengths).")
    return truth


def truth_camera_table(camera: TruthCamera) -> dict:
    """The truth camera as the keys of a Gnomon camera file (model = "opencv" or "tsai")."""
    if isinstance(camera, TruthPinhole):
        return {
            "model": "opencv",
            "width": camera.width,
            "height": camera.height,
            "fx": camera.fx,
            "fy": camera.fy,
            "cx": camera.cx,
            "cy": camera.cy,
            "dist": list(camera.dist),
        }
    return {
        "model": "tsai",
        "width": camera.width,
        "height": camera.height,
        "f_mm": camera.f_mm,
        "kappa1": camera.kappa1,
        "cx": camera.cx,
        "cy": camera.cy,
        "sx": camera.sx,
        "dx_mm": camera.dx_mm,
        "dy_mm": camera.dy_mm,
    }
