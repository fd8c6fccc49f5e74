"""Synthetic frames of reference planes carrying printed 2×2 checker markers.

Ground truth for :mod:`gnomon.markers`. Per DESIGN.md nothing here comes from
the code it checks: rays come from the simulator's own camera models
(:mod:`gnomon.simulate.chessboard`), are cast onto the planes by our own
intersection code, and the markers' true pixels are our own projections.

A marker is a square of white paper ``1.5 × size`` wide with a 2×2 checker
``size`` wide printed in its middle (the two squares where
``(a − a0)·(b − b0) > 0`` are black); its centre ``(a0, b0)`` is the
X-junction the detector looks for. Plane coordinates ``(a, b)`` map to the
world as ``origin + a·x_axis + b·y_axis``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from gnomon.simulate.chessboard import SampleRays, TruthCamera, default_truth_camera, finish_image, truth_camera_table


@dataclass(frozen=True)
class PrintedMarker:
    name: str
    ab: tuple[float, float]  # centre, plane coordinates (world units)
    size: float = 30.0  # side of the 2×2 pattern (world units)


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


def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """World → camera (R, t) of a camera at ``eye`` looking at ``target`` (OpenCV axes: y down)."""
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ eye


def _albedo(plane: ScenePlane, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # A smooth, non-periodic texture (no saddles sharp enough to pass for a marker).
    tex = 1.0 + plane.texture * (np.sin(a / 37.0 + 0.3) * np.cos(b / 53.0) + 0.5 * np.sin((a + b) / 91.0))
    val = plane.albedo * tex
    for m in plane.markers:
        # Work on the samples that fall on this marker's paper only.
        idx = np.flatnonzero((np.abs(a - m.ab[0]) <= 0.75 * m.size) & (np.abs(b - m.ab[1]) <= 0.75 * m.size))
        da, db = a[idx] - m.ab[0], b[idx] - m.ab[1]
        pattern = (np.abs(da) <= 0.5 * m.size) & (np.abs(db) <= 0.5 * m.size) & (da * db > 0)
        val[idx] = np.where(pattern, 0.06, 0.9)
    return val


def render(scene: MarkerScene, rays: SampleRays, *, gain: float = 255.0, blur_px: float = 0.7, noise_dn: float = 1.0, seed: int = 0) -> np.ndarray:
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
            for n, ab in (("d1", (-230.0, -170.0)), ("d2", (230.0, -170.0)), ("d3", (230.0, 190.0)), ("d4", (-230.0, 190.0)))
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
            for n, ab in (("w1", (-230.0, 70.0)), ("w2", (230.0, 70.0)), ("w3", (230.0, 300.0)), ("w4", (-230.0, 300.0)))
        ),
    )
    return MarkerScene(camera=camera, R=R, t=t, planes=(desk, wall))


def write_marker_scene(
    out_dir: str | Path,
    *,
    scene: MarkerScene | None = None,
    hint_error_px: float = 6.0,
    supersample: int = 4,
    noise_dn: float = 1.0,
    seed: int = 0,
) -> dict:
    """Render ``frame.png`` and ``truth.toml`` for a marker scene into ``out_dir``.

    ``truth.toml``: the camera (camera-file keys), its pose (world → camera,
    rvec radians, tvec mm) and per plane its frame, normal and offset in the
    camera frame and its markers (plane and world coordinates, true pixels,
    and hints off by up to ``hint_error_px`` as a person would click them).
    Returns the same content as a dict.
    """
    from gnomon import atomic, toml_io  # file formats only

    scene = scene or desk_and_wall_scene()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rays = SampleRays(scene.camera, supersample)
    img = render(scene, rays, noise_dn=noise_dn, seed=seed)
    ok, buf = cv2.imencode(".png", img)
    atomic.write_bytes(out / "frame.png", buf.tobytes())
    rng = np.random.default_rng(seed)
    planes = []
    for plane in scene.planes:
        pix = scene.marker_pixels(plane)
        ang = rng.uniform(0, 2 * np.pi, len(pix))
        rad = rng.uniform(0, hint_error_px, len(pix))
        hints = pix + np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=1)
        n, d = scene.plane_in_camera(plane)
        planes.append(
            {
                "name": plane.name,
                "origin": list(plane.origin),
                "x_axis": list(plane.x_axis),
                "y_axis": list(plane.y_axis),
                "normal_world": plane.normal.tolist(),
                "normal_cam": n.tolist(),
                "offset_cam": d,
                "markers": [
                    {
                        "name": m.name,
                        "plane_xy": list(m.ab),
                        "world": plane.to_world(np.array(m.ab)).ravel().tolist(),
                        "pixel": p.tolist(),
                        "hint": [round(float(h[0]), 1), round(float(h[1]), 1)],
                        "size": m.size,
                    }
                    for m, p, h in zip(plane.markers, pix, hints)
                ],
            }
        )
    truth = {
        "image": "frame.png",
        "units": "mm",
        "camera": truth_camera_table(scene.camera),
        "pose": {"rvec": cv2.Rodrigues(scene.R)[0].ravel().tolist(), "tvec": scene.t.tolist()},
        "planes": planes,
    }
    toml_io.dump(truth, out / "truth.toml", header="Ground truth of a synthetic marker scene (mm; camera frame x right, y down, z forward).")
    return truth
