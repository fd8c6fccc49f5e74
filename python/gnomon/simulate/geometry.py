"""Independent geometry for the simulator: rotations, the lens, ray casting.

Nothing here imports the pipeline (``gnomon.camera.models`` and friends): the
simulator is the ground truth the pipeline is checked against, so it has its
own projection, its own distortion inversion and its own ray/primitive
intersections, all in plain numpy. Only the *conventions* are shared with the
pipeline, because they are part of the file formats:

* camera frame x right, y down, z forward (OpenCV); ``X_cam = R·X_world + t``;
* pixel centres at integer coordinates, (0, 0) the centre of the top-left pixel;
* the lens is OpenCV's 5-coefficient model (k1, k2, p1, p2, k3) acting on
  normalised coordinates ``(x, y) = (X/Z, Y/Z)``::

      r² = x² + y²,  radial = 1 + k1·r² + k2·r⁴ + k3·r⁶
      x_d = x·radial + 2·p1·x·y + p2·(r² + 2·x²)
      y_d = y·radial + p1·(r² + 2·y²) + 2·p2·x·y
      u = fx·x_d + cx,  v = fy·y_d + cy
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

EPS_T = 1e-6  # smallest accepted ray parameter (mm for unit rays)


# --------------------------------------------------------------------------- rotations

def rotation_from_rodrigues(rvec) -> np.ndarray:
    """Rotation matrix from a Rodrigues vector (axis · angle, radians)."""
    r = np.asarray(rvec, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(r))
    if theta < 1e-300:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * (kx @ kx)


def rodrigues_from_rotation(R) -> np.ndarray:
    """Rodrigues vector (axis · angle) of a rotation matrix; accurate near 0 and π."""
    R = np.asarray(R, dtype=np.float64)
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    sin_t = np.linalg.norm(skew) / 2.0
    cos_t = (np.trace(R) - 1.0) / 2.0
    theta = float(np.arctan2(sin_t, cos_t))
    if theta < 1e-8:
        return skew / 2.0
    if cos_t > -0.5:
        return skew / (2.0 * sin_t) * theta
    # Towards π the skew part vanishes: the axis comes from the symmetric part,
    # (R + Rᵀ)/2 = cos θ·I + (1 − cos θ)·k kᵀ, its sign from the skew part.
    B = ((R + R.T) / 2.0 - cos_t * np.eye(3)) / (1.0 - cos_t)
    i = int(np.argmax(np.diag(B)))
    k = B[:, i] / np.sqrt(B[i, i])
    k /= np.linalg.norm(k)
    if np.dot(k, skew) < 0:
        k = -k
    return k * theta


def look_at(eye, target, up=(0.0, 0.0, 1.0), roll_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """World→camera (R, t) for a camera at ``eye`` looking at ``target``.

    Camera z is the viewing direction, x points to the right of the image
    (horizontal in the world), y down; ``roll_deg`` turns the camera about its
    z axis.
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    a = np.radians(roll_deg)
    xr = np.cos(a) * x + np.sin(a) * y
    yr = -np.sin(a) * x + np.cos(a) * y
    R = np.stack([xr, yr, z])
    return R, -R @ eye


# --------------------------------------------------------------------------- the lens

def distort(x: np.ndarray, y: np.ndarray, dist) -> tuple[np.ndarray, np.ndarray]:
    """Apply the 5-coefficient distortion to normalised coordinates."""
    k1, k2, p1, p2, k3 = (float(c) for c in dist)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def undistort(xd: np.ndarray, yd: np.ndarray, dist, *, max_iter: int = 50,
              tol: float = 1e-15) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`distort` by Newton's method with the analytic Jacobian.

    Converges to machine precision in a handful of iterations for any lens
    whose distortion is monotone over the image; raises if it does not.
    """
    k1, k2, p1, p2, k3 = (float(c) for c in dist)
    xd = np.asarray(xd, dtype=np.float64)
    yd = np.asarray(yd, dtype=np.float64)
    x = xd.copy()
    y = yd.copy()
    for _ in range(max_iter):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r²
        fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
        fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
        a = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        b = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        c = b  # the Jacobian is symmetric for this model
        d = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        det = a * d - b * c
        dx = (d * fx - b * fy) / det
        dy = (a * fy - c * fx) / det
        x = x - dx
        y = y - dy
        if np.all(np.abs(dx) + np.abs(dy) <= tol * (1.0 + np.abs(x) + np.abs(y))):
            break
    xr, yr = distort(x, y, dist)
    err = np.max(np.abs(xr - xd) + np.abs(yr - yd), initial=0.0)
    if not err < 1e-12:
        raise RuntimeError(f"distortion inversion did not converge (residual {err:.3g})")
    return x, y


class PinholeLens:
    """Intrinsics K plus the 5 distortion coefficients; the simulator's own camera."""

    def __init__(self, fx: float, fy: float, cx: float, cy: float, dist) -> None:
        self.fx, self.fy, self.cx, self.cy = float(fx), float(fy), float(cx), float(cy)
        self.dist = np.asarray(dist, dtype=np.float64).reshape(5)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project_cam(self, X: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) → pixels (..., 2)."""
        X = np.asarray(X, dtype=np.float64)
        x = X[..., 0] / X[..., 2]
        y = X[..., 1] / X[..., 2]
        xd, yd = distort(x, y, self.dist)
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)

    def rays_cam(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Pixels → camera-frame unit rays (..., 3), inverting the distortion."""
        xd = (np.asarray(u, dtype=np.float64) - self.cx) / self.fx
        yd = (np.asarray(v, dtype=np.float64) - self.cy) / self.fy
        x, y = undistort(xd, yd, self.dist)
        d = np.stack([x, y, np.ones_like(x)], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)


@dataclass(frozen=True)
class SceneCamera:
    """A scene's camera: its lens and its pose ``X_cam = R·X_world + t``."""

    lens: PinholeLens
    R: np.ndarray
    t: np.ndarray

    @classmethod
    def scaled(cls, width: int, height: int, *, ref_size: tuple[int, int], ref_focal_px: tuple[float, float],
               ref_centre_px: tuple[float, float], dist: Sequence[float], eye: np.ndarray, target: np.ndarray,
               roll_deg: float) -> SceneCamera:
        """A reference camera rescaled to ``width`` × ``height`` pixels (the same field of view), placed at
        ``eye`` looking at ``target``.

        ``ref_focal_px`` (fx, fy) and ``ref_centre_px`` (cx, cy) are in pixels of an image of
        ``ref_size`` (width, height), pixel-centre convention.
        """
        sx, sy = width / ref_size[0], height / ref_size[1]
        lens = PinholeLens(ref_focal_px[0] * sx, ref_focal_px[1] * sy, (ref_centre_px[0] + 0.5) * sx - 0.5,
                           (ref_centre_px[1] + 0.5) * sy - 0.5, dist)
        R, t = look_at(eye, target, roll_deg=roll_deg)
        return cls(lens, R, t)

    @property
    def rvec(self) -> np.ndarray:
        return rodrigues_from_rotation(self.R)

    @property
    def centre(self) -> np.ndarray:
        """The camera centre in the world frame."""
        return -self.R.T @ self.t

    def summary(self) -> dict:
        """The camera's entries of a scene's ground truth (world units of the scene)."""
        return {"camera_centre_world": self.centre.tolist(), "K": self.lens.K.tolist(),
                "dist": self.lens.dist.tolist(), "rvec": self.rvec.tolist(), "tvec": self.t.tolist()}


# --------------------------------------------------------------------------- primitives
# Every intersect(o, d) takes origins o (..., 3) (or one origin, broadcast) and
# directions d (..., 3) and returns the smallest ray parameter t > EPS_T at which
# the ray o + t·d enters the solid (inf when it misses). ``normal(X)`` gives the
# outward unit normal at surface points X.

class Surface(Protocol):
    """A ray-castable primitive (the classes below)."""

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray: ...

    def normal(self, X: np.ndarray) -> np.ndarray: ...


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class Plane:
    """The plane n·X = offset, hit from either side."""

    def __init__(self, normal, offset: float = 0.0) -> None:
        self.n = _unit(np.asarray(normal, dtype=np.float64))
        self.offset = float(offset)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        denom = _dot(d, self.n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.offset - _dot(o, self.n)) / denom
        return np.where(np.isfinite(t) & (t > EPS_T), t, np.inf)

    def normal(self, X: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.n, X.shape).copy()


class Sphere:
    def __init__(self, centre, radius: float) -> None:
        self.c = np.asarray(centre, dtype=np.float64)
        self.r = float(radius)

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        oc = o - self.c
        a = _dot(d, d)
        b = _dot(oc, d)
        c = _dot(oc, oc) - self.r * self.r
        disc = b * b - a * c
        ok = disc >= 0.0
        sq = np.sqrt(np.where(ok, disc, 0.0))
        t1 = (-b - sq) / a
        t2 = (-b + sq) / a
        t = np.where(t1 > EPS_T, t1, np.where(t2 > EPS_T, t2, np.inf))
        return np.where(ok, t, np.inf)

    def normal(self, X: np.ndarray) -> np.ndarray:
        return _unit(X - self.c)


class Box:
    """A box of full ``size`` (sx, sy, sz), centred at ``centre``, turned by ``yaw_deg`` about z."""

    def __init__(self, centre, size, yaw_deg: float) -> None:
        self.c = np.asarray(centre, dtype=np.float64)
        self.half = np.asarray(size, dtype=np.float64) / 2.0
        a = np.radians(yaw_deg)
        # Columns: the box axes in world coordinates.
        self.axes = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])

    def _local(self, X: np.ndarray) -> np.ndarray:
        return (X - self.c) @ self.axes

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        ol = self._local(o)
        dl = d @ self.axes
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / dl
            t1 = (-self.half - ol) * inv
            t2 = (self.half - ol) * inv
        # A ray parallel to a slab: inside it (t = ±inf) or outside (nan → miss).
        lo = np.fmin(t1, t2)
        hi = np.fmax(t1, t2)
        parallel = dl == 0.0
        inside = np.abs(ol) <= self.half
        lo = np.where(parallel, np.where(inside, -np.inf, np.inf), lo)
        hi = np.where(parallel, np.where(inside, np.inf, -np.inf), hi)
        t_near = lo.max(axis=-1)
        t_far = hi.min(axis=-1)
        hit = t_near <= t_far
        t = np.where(t_near > EPS_T, t_near, np.where(t_far > EPS_T, t_far, np.inf))
        return np.where(hit, t, np.inf)

    def normal(self, X: np.ndarray) -> np.ndarray:
        q = self._local(X) / self.half
        k = np.argmax(np.abs(q), axis=-1)
        nl = np.zeros_like(q)
        np.put_along_axis(nl, k[..., None], np.sign(np.take_along_axis(q, k[..., None], axis=-1)), axis=-1)
        return nl @ self.axes.T


class Cylinder:
    """A solid finite cylinder: axis through ``centre`` along ``axis``, capped."""

    def __init__(self, centre, axis, radius: float, length: float) -> None:
        self.c = np.asarray(centre, dtype=np.float64)
        self.a = _unit(np.asarray(axis, dtype=np.float64))
        self.r = float(radius)
        self.h = float(length) / 2.0

    def intersect(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        oc = o - self.c
        oa = _dot(oc, self.a)
        da = _dot(d, self.a)
        op = oc - oa[..., None] * self.a
        dp = d - da[..., None] * self.a
        A = _dot(dp, dp)
        B = _dot(op, dp)
        C = _dot(op, op) - self.r * self.r
        disc = B * B - A * C
        ok = (disc >= 0.0) & (A > 0.0)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            best = np.full(np.broadcast(oa, da).shape, np.inf)
            for sgn in (-1.0, 1.0):
                ts = (-B + sgn * sq) / A
                z = oa + ts * da
                good = ok & (ts > EPS_T) & (np.abs(z) <= self.h)
                best = np.where(good & (ts < best), ts, best)
            for cap in (-self.h, self.h):
                tc = (cap - oa) / da
                p = op + tc[..., None] * dp
                good = np.isfinite(tc) & (tc > EPS_T) & (_dot(p, p) <= self.r * self.r)
                best = np.where(good & (tc < best), tc, best)
        return best

    def normal(self, X: np.ndarray) -> np.ndarray:
        q = X - self.c
        z = _dot(q, self.a)
        radial = q - z[..., None] * self.a
        rr = np.linalg.norm(radial, axis=-1)
        on_cap = (np.abs(np.abs(z) - self.h) < 1e-6 * max(self.h, 1.0)) & (rr < self.r * (1 - 1e-9))
        side = radial / np.where(rr > 0, rr, 1.0)[..., None]
        cap = np.sign(z)[..., None] * self.a
        return np.where(on_cap[..., None], cap, side)
