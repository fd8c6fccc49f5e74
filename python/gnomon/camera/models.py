"""Camera models and poses.

Conventions: the camera frame is OpenCV's (x right, y down, z
forward); pixel centres sit at integer coordinates, so pixel (u, v) = (0, 0)
is the centre of the top-left pixel.

Every model offers the same two vectorised operations:

* ``project(points_cam)``: (N, 3) camera-frame points → (N, 2) pixels;
* ``rays(pixels)``: (N, 2) pixels → (N, 3) unit camera-frame rays;

and ``ray_map()`` gives one unit ray per pixel centre, shape (H, W, 3), which is
all the per-pixel pipeline ever asks of a model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, TypeAlias

import cv2
import numpy as np

from gnomon import _kernel

# undistortPoints is iterative; the default (5 iterations) leaves errors of
# ~0.1 px at the corners of a strongly distorted lens. Metrology wants better.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


def undistort_points(pixels: np.ndarray, K: np.ndarray, dist: np.ndarray, criteria: tuple) -> np.ndarray:
    """OpenCV's iterative undistortion of distorted pixels (N, 1, 2) to normalised coordinates (N, 1, 2),
    stopped by ``criteria``: ``cv2.undistortPoints(..., criteria=)`` on OpenCV 5, which took over
    OpenCV 4's ``cv2.undistortPointsIter`` (the same solver; 4.x's ``undistortPoints`` takes no criteria)."""
    iterate: Any = getattr(cv2, "undistortPointsIter", None)  # OpenCV 4.x; typed loosely: each version's
    undistort: Any = cv2.undistortPoints  # stubs know only its own API
    if iterate is not None:  # identity R and P: normalised coordinates, as None gives
        return np.asarray(iterate(pixels, K, dist, np.eye(3), np.eye(3), criteria))
    return np.asarray(undistort(pixels, K, dist, criteria=criteria))


# OpenCVCamera.ray_map: Newton's method in the kernel (_kernel.ray_map), pixel by pixel. A pixel
# is solved when its ray reprojects within RAY_MAP_TOL_PX of it: rounding alone leaves ~1e-13 px
# (a coordinate of ~1000 px has an ulp of 1.1e-13), undistortPoints above stops at 1e-12 px, and
# 1e-10 px is reached one step earlier and far below any use. From the pinhole start an ordinary
# lens (|k1| ~ 0.1) needs 2-3 steps; a strongly distorted one converges slowly near the fold of
# its distortion (det J -> 0), and the pixels not solved in RAY_MAP_MAX_STEPS go to
# undistortPoints (``normalized``).
RAY_MAP_TOL_PX = 1e-10
RAY_MAP_MAX_STEPS = 8


class CameraModel(Protocol):
    """What the scan needs of a camera model (:class:`OpenCVCamera` and :class:`TsaiCamera` are ones)."""

    @property
    def width(self) -> int: ...

    @property
    def height(self) -> int: ...

    @property
    def K(self) -> np.ndarray:
        """The pinhole intrinsic matrix (pixels)."""
        ...

    def project(self, points_cam: np.ndarray) -> np.ndarray: ...

    def rays(self, pixels: np.ndarray) -> np.ndarray: ...

    def ray_map(self) -> np.ndarray: ...


def pixel_grid(width: int, height: int) -> np.ndarray:
    """All pixel centres as an (H*W, 2) float64 array, row-major (u fastest)."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class OpenCVCamera:
    """OpenCV's pinhole model with 5 distortion coefficients (k1, k2, p1, p2, k3).

    ``fx, fy, cx, cy`` in pixels; ``width, height`` the image size in pixels.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=np.float64)

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) → distorted pixels (N, 2)."""
        pts = np.ascontiguousarray(np.asarray(points_cam, dtype=np.float64).reshape(-1, 1, 3))
        zero = np.zeros(3)
        pix, _ = cv2.projectPoints(pts, zero, zero, self.K, self.dist_coeffs)
        return pix.reshape(-1, 2)

    def normalized(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) → undistorted normalised coordinates (x/z, y/z)."""
        pix = np.ascontiguousarray(np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2))
        return undistort_points(pix, self.K, self.dist_coeffs, _UNDISTORT_CRITERIA).reshape(-1, 2)

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) → unit rays in the camera frame (N, 3)."""
        xy = self.normalized(pixels)
        return _unit(np.concatenate([xy, np.ones((len(xy), 1))], axis=1))

    def ray_map(self) -> np.ndarray:
        """Unit camera-frame ray of every pixel centre, (H, W, 3) float64.

        Each ray reprojects (:meth:`project`) within ``RAY_MAP_TOL_PX`` of its pixel wherever the
        lens has an inverse there: solved by the kernel's Newton iteration (rows in parallel, GIL
        released), the pixels it leaves (see ``RAY_MAP_MAX_STEPS``) by :meth:`rays`.
        """
        return ray_map_newton(self, RAY_MAP_MAX_STEPS)


def ray_map_newton(cam: OpenCVCamera, max_steps: int) -> np.ndarray:
    """``cam``'s ray map (H, W, 3) with at most ``max_steps`` Newton steps per pixel in the kernel;
    the pixels not solved within ``RAY_MAP_TOL_PX`` get :meth:`OpenCVCamera.rays` (undistortPoints)."""
    rays, solved = _kernel.ray_map(cam.width, cam.height, (cam.fx, cam.fy, cam.cx, cam.cy),
                                   cam.dist, RAY_MAP_TOL_PX, max_steps)
    if not solved.all():
        v, u = np.nonzero(~solved)
        rays[v, u] = cam.rays(np.stack([u, v], axis=1).astype(np.float64))
    return rays


@dataclass(frozen=True)
class Pose:
    """A rigid transform from the world frame to the camera frame.

    ``X_cam = R @ X_world + t``; ``t`` in world units (mm or m, as declared).
    """

    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_rvec_tvec(cls, rvec: np.ndarray, tvec: np.ndarray) -> Pose:
        R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3))
        return cls(R=R, t=np.asarray(tvec, dtype=np.float64).reshape(3))

    @property
    def rvec(self) -> np.ndarray:
        return cv2.Rodrigues(self.R)[0].reshape(3)

    @property
    def camera_centre_world(self) -> np.ndarray:
        """The camera's optical centre in world coordinates."""
        return -self.R.T @ self.t

    def world_to_camera(self, points_world: np.ndarray) -> np.ndarray:
        return np.asarray(points_world, dtype=np.float64) @ self.R.T + self.t

    def camera_to_world(self, points_cam: np.ndarray) -> np.ndarray:
        return (np.asarray(points_cam, dtype=np.float64) - self.t) @ self.R


@dataclass(frozen=True)
class TsaiCamera:
    """Tsai's camera model (IEEE J. Robotics & Automation, 1987).

    Camera frame as OpenCV's (x right, y down, z forward); pixel centres at
    integer coordinates.

    * Pinhole, sensor units (mm): ``Xu = f·x/z``, ``Yu = f·y/z``.
    * Radial distortion, Tsai's way round (undistorted *from* distorted):
      ``Xu = Xd·(1 + κ1·r²)``, ``Yu = Yd·(1 + κ1·r²)``, ``r² = Xd² + Yd²`` (mm²).
    * Sensor → frame buffer: ``u = sx·Xd/dx + Cx``, ``v = Yd/dy + Cy``.

    ``f_mm`` focal length (mm); ``kappa1`` (1/mm²); ``cx, cy`` the centre of
    radial distortion (pixels); ``sx`` the horizontal scale uncertainty
    (dimensionless, 1 for a digital camera); ``dx_mm`` and ``dy_mm`` the
    distance between the centres of adjacent frame-buffer pixels on the
    sensor, horizontally (Tsai's ``dx' = dx·Ncx/Nfx``) and vertically (mm).

    ``rays`` is closed-form. ``project`` inverts the distortion on the radius,
    ``κ1·rd³ + rd = ru``, by Newton's method to machine precision. For κ1 < 0
    that map folds over at ``rd² = 1/(3|κ1|)``: points whose undistorted
    radius lies beyond the fold project to NaN, and pixels beyond it have NaN
    rays (both far outside the image for any real lens).
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

    @property
    def fx(self) -> float:
        """Equivalent pinhole focal length along u (pixels): f·sx/dx."""
        return self.f_mm * self.sx / self.dx_mm

    @property
    def fy(self) -> float:
        """Equivalent pinhole focal length along v (pixels): f/dy."""
        return self.f_mm / self.dy_mm

    @property
    def K(self) -> np.ndarray:
        """The pinhole part as a 3×3 matrix (pixels), distortion ignored."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def sensor_from_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) → distorted sensor coordinates (Xd, Yd) in mm, (N, 2)."""
        pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        return np.stack(
            [(pix[:, 0] - self.cx) * self.dx_mm / self.sx, (pix[:, 1] - self.cy) * self.dy_mm], axis=1
        )

    def pixels_from_sensor(self, sensor_mm: np.ndarray) -> np.ndarray:
        """Distorted sensor coordinates (N, 2) in mm → pixels (N, 2)."""
        s = np.asarray(sensor_mm, dtype=np.float64).reshape(-1, 2)
        return np.stack([self.sx * s[:, 0] / self.dx_mm + self.cx, s[:, 1] / self.dy_mm + self.cy], axis=1)

    def undistort_sensor(self, sensor_mm: np.ndarray) -> np.ndarray:
        """Distorted (Xd, Yd) → undistorted (Xu, Yu), mm, (N, 2). Closed form.

        NaN beyond the fold of a negative κ1 (see the class docstring).
        """
        d = np.asarray(sensor_mm, dtype=np.float64).reshape(-1, 2)
        r2 = np.sum(d * d, axis=1, keepdims=True)
        out = d * (1.0 + self.kappa1 * r2)
        if self.kappa1 < 0.0:
            out[r2[:, 0] > 1.0 / (3.0 * -self.kappa1)] = np.nan
        return out

    def distort_sensor(self, sensor_mm: np.ndarray) -> np.ndarray:
        """Undistorted (Xu, Yu) → distorted (Xd, Yd), mm, (N, 2).

        Solves ``κ1·rd³ + rd − ru = 0`` on the radius by Newton's method. From
        ``rd = ru`` the iteration is monotone for either sign of κ1 (the cubic
        is convex for κ1 > 0 and we start right of the root, concave for
        κ1 < 0 and we start left of it), so it cannot jump to a wrong branch.
        """
        u = np.asarray(sensor_mm, dtype=np.float64).reshape(-1, 2)
        ru = np.hypot(u[:, 0], u[:, 1])
        k = self.kappa1
        if k == 0.0:
            return u.copy()
        rd = ru.copy()
        valid = np.isfinite(ru)
        if k < 0.0:
            valid &= ru <= 2.0 / (3.0 * np.sqrt(-3.0 * k))
        rd[~valid] = np.nan
        for _ in range(100):
            g = k * rd**3 + rd - ru
            step = g / (3.0 * k * rd**2 + 1.0)
            rd = rd - step
            if not np.any(np.abs(step[valid]) > 1e-15 * np.maximum(ru[valid], 1e-300)):
                break
        # Xd = Xu·rd/ru (same direction, radius rd); ru = 0 maps to 0.
        scale = np.where(ru > 0.0, rd / np.where(ru > 0.0, ru, 1.0), 1.0)
        return u * scale[:, None]

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) → distorted pixels (N, 2). NaN for z ≤ 0."""
        p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            und = self.f_mm * p[:, :2] / z[:, None]
        und[~(z > 0.0)] = np.nan
        return self.pixels_from_sensor(self.distort_sensor(und))

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) → unit rays in the camera frame (N, 3)."""
        und = self.undistort_sensor(self.sensor_from_pixels(pixels))
        v = np.concatenate([und, np.full((len(und), 1), self.f_mm)], axis=1)
        return _unit(v)

    def ray_map(self) -> np.ndarray:
        """Unit camera-frame ray of every pixel centre, (H, W, 3) float64."""
        return self.rays(pixel_grid(self.width, self.height)).reshape(self.height, self.width, 3)


# The camera models a camera file (or a field log's inline [camera]) describes.
CalibratedCamera: TypeAlias = OpenCVCamera | TsaiCamera
