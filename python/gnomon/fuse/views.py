"""The views of a fusion: finished scan folders read back, and their set-up planes told from the object.

A view is one ``gnomon scan`` output folder: ``points.ply`` (world points, normals, each point's
depth σ, colours) and ``report.json`` (units, camera, the site of a georeferenced scan). The
set-up — the desk, a wall, the ground and a facade's background plane — fills most of a scan;
for a desk object it is not the object and must not take part in the registration (the object
moved on it; the desk did not). The planes that hold a large share of a view's points are found
by RANSAC and their points left out (``setup_fraction``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.camera.calibration import camera_from_table
from gnomon.camera.models import CameraModel, Pose
from gnomon.errors import GnomonError
from gnomon.fuse.o3d import open3d
from gnomon.outputs import ply
from gnomon.outputs.publish import recover

__all__ = ["View", "SetupPlane", "read_view", "check_views", "free_space_share", "split_setup"]


@dataclass
class SetupPlane:
    """A plane of the set-up found in a view: ``normal`` (3,) unit, pointing to the camera's side,
    ``offset`` (world units, ``normal·X = offset``), the share of the view's points on it."""

    normal: np.ndarray
    offset: float
    share: float


@dataclass
class View:
    """One scan, read back. Arrays per point (N,), world frame of the scan, its units.

    ``object_mask`` the points that are not the set-up (after :func:`split_setup`);
    ``distance`` the camera's median distance to the object's points (world units): the scale the
    fusion's tolerances and the report's relative figures use.
    """

    folder: Path
    units: str
    points: np.ndarray        # (N, 3) float64
    normals: np.ndarray       # (N, 3) float64, unit, towards the camera
    sigma: np.ndarray         # (N,) float64, depth σ, world units
    rgb: np.ndarray | None    # (N, 3) uint8
    camera_centre: np.ndarray  # (3,) world
    site: dict[str, Any] | None
    report: dict[str, Any]
    camera: CameraModel | None = None  # the scan's camera and pose, and its depth map (camera Z, NaN: none)
    pose: Pose | None = None
    depth: np.ndarray | None = None
    object_mask: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    planes: list[SetupPlane] = field(default_factory=list)
    distance: float = float("nan")

    @property
    def name(self) -> str:
        return self.folder.name

    setup_points: int = 0     # points left out as the set-up (after :func:`split_setup`)

    def object_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m = self.object_mask
        return self.points[m], self.normals[m], self.sigma[m]

    @property
    def prepared(self) -> bool:
        """Whether the object is told from the set-up (:func:`split_setup`, or all of a survey)."""
        return len(self.object_mask) == len(self.points)

    def keep_object(self) -> None:
        """Drop the set-up's points (most of a desk scan): what a fusion holds per view is its object."""
        m = self.object_mask
        self.setup_points += int(np.count_nonzero(~m))
        self.points, self.normals, self.sigma = self.points[m], self.normals[m], self.sigma[m]
        if self.rgb is not None:
            self.rgb = self.rgb[m]
        self.object_mask = np.ones(len(self.points), dtype=bool)


def read_view(folder: str | os.PathLike) -> View:
    """Read a scan folder; a folder that is not one is a one-line :class:`GnomonError` naming it."""
    f = Path(folder)
    if not f.is_dir():
        raise GnomonError(f"{f}: not a scan output folder")
    recover(f)
    for name in ("points.ply", "report.json"):
        if not (f / name).is_file():
            raise GnomonError(f"{f}: missing {name} (is it the output folder of `gnomon scan`?)")
    try:
        report = json.loads((f / "report.json").read_text())
        units = str(report["units"])
        pose = report["camera"]["pose"]
        rvec = np.asarray(pose["rvec"], dtype=np.float64)
        tvec = np.asarray(pose["tvec"], dtype=np.float64)
    except (ValueError, KeyError, TypeError) as exc:
        raise GnomonError(f"{f / 'report.json'}: not a gnomon scan report ({exc})") from None
    data = ply.read_ply(f / "points.ply")
    if data.get("xyz") is None or data.get("sigma") is None or data.get("normals") is None:
        raise GnomonError(f"{f / 'points.ply'}: needs x y z, normals and sigma per point (a gnomon scan's points)")
    P = np.asarray(data["xyz"], dtype=np.float64)
    N = np.asarray(data["normals"], dtype=np.float64)
    S = np.asarray(data["sigma"], dtype=np.float64)
    good = np.isfinite(P).all(axis=1) & np.isfinite(N).all(axis=1) & np.isfinite(S) & (S > 0)
    rgb = data.get("rgb")
    pose = Pose.from_rvec_tvec(rvec, tvec)
    camera, depth = None, None
    if (f / "depth.npy").is_file():
        table = {k: v for k, v in report["camera"].items() if k != "pose"}
        camera = camera_from_table(table, f"{f / 'report.json'}: camera")
        try:
            depth = np.load(f / "depth.npy", allow_pickle=False)
        except (ValueError, EOFError, OSError) as exc:
            raise GnomonError(f"{f / 'depth.npy'}: not a readable .npy map ({exc})") from None
        if depth.shape != (camera.height, camera.width):
            raise GnomonError(f"{f / 'depth.npy'}: shape {depth.shape} does not match the "
                              f"{camera.width}x{camera.height} camera")
    return View(f, units, P[good], N[good], S[good], None if rgb is None else np.asarray(rgb)[good],
                pose.camera_centre_world, report.get("site"), report, camera, pose, depth)


def free_space_share(view: View, points_world: np.ndarray, margin: float) -> float:
    """The share of points (this view's world frame) that lie more than ``margin`` in front of the surface
    this view saw along their pixel's ray: space the view saw through, where a correctly placed point of
    another view cannot be. 0 without a depth map."""
    if view.camera is None or view.pose is None or view.depth is None or not len(points_world):
        return 0.0
    Xc = view.pose.world_to_camera(points_world)
    front = Xc[:, 2] > 0
    uv = np.full((len(Xc), 2), -1.0)
    uv[front] = view.camera.project(Xc[front])
    u, v = np.rint(uv[:, 0]).astype(np.int64), np.rint(uv[:, 1]).astype(np.int64)
    inside = front & (u >= 0) & (v >= 0) & (u < view.camera.width) & (v < view.camera.height)
    seen = np.full(len(Xc), np.nan)
    seen[inside] = view.depth[v[inside], u[inside]]
    with np.errstate(invalid="ignore"):
        through = Xc[:, 2] < seen - margin
    return float(np.count_nonzero(through)) / len(Xc)


def check_views(views: list[View]) -> None:
    """Views that cannot be fused together: a one-line :class:`GnomonError` naming the odd one."""
    if len(views) < 2:
        raise GnomonError("fuse: needs at least two scans")
    first = views[0]
    seen: dict[Path, Path] = {}
    for v in views:
        key = v.folder.resolve()
        if key in seen:
            raise GnomonError(f"{v.folder}: given twice")
        seen[key] = v.folder
        if v.units != first.units:
            raise GnomonError(f"{v.folder}: units {v.units!r} differ from {first.folder}'s {first.units!r}; "
                              "rescan it with the same [capture] units")
        if (v.site is None) != (first.site is None):
            raise GnomonError(f"{v.folder}: {'a' if v.site else 'not a'} georeferenced scan, unlike "
                              f"{first.folder}; fuse desk scans with desk scans and sun scans with sun scans")


def split_setup(view: View, *, setup_fraction: float = 0.15, band_sigmas: float = 5.0,
                band_fraction: float = 0.002, max_planes: int = 3) -> None:
    """Find the set-up's planes in a view and keep the rest, the object (in place: the set-up's points are dropped).

    A plane holding at least ``setup_fraction`` of the view's points (RANSAC, inlier distance
    ``band_fraction`` of the camera's distance) is the set-up; its points — within
    ``band_sigmas`` σ or ``band_fraction`` of the distance of it, and behind it — are left out.
    """
    o3d = open3d()
    P = view.points
    scale = float(np.median(np.linalg.norm(P - view.camera_centre, axis=1))) if len(P) else 1.0
    band = band_fraction * scale
    keep = np.ones(len(P), dtype=bool)
    planes: list[SetupPlane] = []
    rng = np.random.default_rng(0)
    for _ in range(max_planes):
        idx = np.flatnonzero(keep)
        if len(idx) < 100:
            break
        sample = idx if len(idx) <= 20000 else np.sort(rng.choice(idx, 20000, replace=False))
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P[sample]))
        o3d.utility.random.seed(0)
        model, inl = pcd.segment_plane(distance_threshold=band, ransac_n=3, num_iterations=300)
        share = len(inl) / len(sample) * len(idx) / len(P)
        if share < setup_fraction:
            break
        n = np.asarray(model[:3], dtype=np.float64)
        norm = float(np.linalg.norm(n))
        n, d = n / norm, -float(model[3]) / norm
        if n @ view.camera_centre - d < 0:
            n, d = -n, -d
        # Refit on every point near it (least squares), then cut the band and what lies behind.
        near = idx[np.abs(P[idx] @ n - d) < band]
        c = P[near].mean(axis=0)
        w, vecs = np.linalg.eigh(np.cov((P[near] - c).T))
        n2 = vecs[:, 0] * (1.0 if vecs[:, 0] @ n > 0 else -1.0)
        n, d = n2, float(n2 @ c)
        h = P @ n - d
        on = h < np.maximum(band_sigmas * view.sigma, band)
        keep &= ~on
        planes.append(SetupPlane(n, d, float(share)))
    view.object_mask = keep
    view.planes = planes
    obj = P[keep]
    view.distance = float(np.median(np.linalg.norm(obj - view.camera_centre, axis=1))) if len(obj) else scale
    view.keep_object()
