"""Camera models and poses.

Conventions (DESIGN.md): the camera frame is OpenCV's (x right, y down, z
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
from typing import Protocol

import cv2
import numpy as np

# undistortPoints is iterative; the default (5 iterations) leaves errors of
# ~0.1 px at the corners of a strongly distorted lens. Metrology wants better.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


class CameraModel(Protocol):
    width: int
    height: int

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
        out = cv2.undistortPoints(pix, self.K, self.dist_coeffs, criteria=_UNDISTORT_CRITERIA)
        return out.reshape(-1, 2)

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) → unit rays in the camera frame (N, 3)."""
        xy = self.normalized(pixels)
        return _unit(np.concatenate([xy, np.ones((len(xy), 1))], axis=1))

    def ray_map(self) -> np.ndarray:
        """Unit camera-frame ray of every pixel centre, (H, W, 3) float64."""
        return self.rays(pixel_grid(self.width, self.height)).reshape(self.height, self.width, 3)


@dataclass(frozen=True)
class Pose:
    """A rigid transform from the world frame to the camera frame.

    ``X_cam = R @ X_world + t``; ``t`` in world units (mm or m, as declared).
    """

    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_rvec_tvec(cls, rvec: np.ndarray, tvec: np.ndarray) -> "Pose":
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
