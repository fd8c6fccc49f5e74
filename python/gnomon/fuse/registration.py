"""Registering two views of one object: a coarse alignment that needs no hint, refined by ICP with σ weights.

Coarse: FPFH features on the object's points (the set-up left out) matched by RANSAC (Open3D), on
a voxel grid of ``voxel`` world units. Fine: point-to-plane ICP written here because its weights
are the scans' own — each correspondence weighs ``1 / (σ_src² + σ_dst² + σ_floor²)`` (the points'
depth σ from the scans, ``σ_floor`` the sampling's share: a plane through sampled points is not the
surface between them), times Tukey's biweight of the residual in those σ, so that points where the
views do not see the same surface (an edge seen from one side only) do not pull. Its normal
matrix at convergence is the pair's information matrix for the pose graph.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from gnomon.fuse.o3d import open3d

__all__ = ["Cloud", "PairRegistration", "agreement", "coarse_alignment", "features", "icp", "rotation_angle_deg",
           "se3_exp"]

TUKEY_C = 4.685


@dataclass
class Cloud:
    """An object's points for registration (one view, its own world frame): points, unit normals,
    depth σ (world units), and a KD-tree of the points."""

    points: np.ndarray
    normals: np.ndarray
    sigma: np.ndarray
    tree: cKDTree

    @classmethod
    def of(cls, points: np.ndarray, normals: np.ndarray, sigma: np.ndarray) -> Cloud:
        return cls(points, normals, sigma, cKDTree(points))


@dataclass
class PairRegistration:
    """ICP's result for one pair: ``transform`` (4, 4) source → target frame; ``information`` (6, 6)
    for (ω, t) in the target frame, in units of the pair's own typical variance; ``overlap`` the share of
    the source's points with a partner; ``rms`` the partners' point-to-plane RMS (world units),
    ``rms_sigma`` the same in the points' own σ (≈ 1 when they see the same surface); ``pairs``
    the number of partners; ``iterations``."""

    transform: np.ndarray
    information: np.ndarray
    overlap: float
    rms: float
    rms_sigma: float
    pairs: int
    iterations: int


def se3_exp(x: np.ndarray) -> np.ndarray:
    """(4, 4) of a twist x = (ω, t): rotation by Rodrigues' formula, then the translation."""
    w, t = x[:3], x[3:]
    theta = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if theta < 1e-12:
        R = np.eye(3) + K
    else:
        R = np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * (K @ K)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def rotation_angle_deg(R: np.ndarray) -> float:
    """The angle of a rotation matrix, degrees."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))))


def features(points: np.ndarray, normals: np.ndarray, voxel: float) -> tuple[Any, Any]:
    """A view's points on a ``voxel`` grid and their FPFH features (radius 5 voxels), for :func:`coarse_alignment`."""
    o3d = open3d()
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.normals = o3d.utility.Vector3dVector(normals)
    down = pcd.voxel_down_sample(voxel)
    fpfh = o3d.pipelines.registration.compute_fpfh_feature(
        down, o3d.geometry.KDTreeSearchParamHybrid(radius=5.0 * voxel, max_nn=100))
    return down, fpfh


def coarse_alignment(src: tuple[Any, Any], dst: tuple[Any, Any], voxel: float, *, iterations: int = 5000,
                     seed: int = 0) -> np.ndarray:
    """A source → target transform (4, 4) from two views' :func:`features` matched by RANSAC, without
    any hint (inlier distance 1.5 voxels)."""
    o3d = open3d()
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(seed)
    dist = 1.5 * voxel
    result = reg.registration_ransac_based_on_feature_matching(
        src[0], dst[0], src[1], dst[1], True, dist, reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)],
        reg.RANSACConvergenceCriteria(iterations, 0.999))
    return np.asarray(result.transformation)


def agreement(src: Cloud, dst: Cloud, T: np.ndarray, radius: float, sigma_floor: float) -> float:
    """The share of ``src``'s points that, moved by T (source → target), lie on ``dst``'s surface: a
    partner within ``radius`` and a point-to-plane residual within 3σ of the two points' σ."""
    p = src.points @ T[:3, :3].T + T[:3, 3]
    d, j = dst.tree.query(p, distance_upper_bound=radius)
    ok = np.isfinite(d)
    jj = j[ok]
    r = np.einsum("ij,ij->i", p[ok] - dst.points[jj], dst.normals[jj])
    var = src.sigma[ok] ** 2 + dst.sigma[jj] ** 2 + sigma_floor**2
    return float(np.count_nonzero(r * r < 9.0 * var)) / max(len(src.points), 1)


def icp(src: Cloud, dst: Cloud, T0: np.ndarray, *, max_distance: float, min_distance: float, sigma_floor: float,
        iterations: int = 40, tolerance: float = 1e-6) -> PairRegistration:
    """σ-weighted point-to-plane ICP of ``src`` onto ``dst`` from ``T0`` (source → target).

    The partner search radius halves from ``max_distance`` to ``min_distance`` (world units), each
    time the pose has settled at the radius (or after 8 steps); the weights are described in the
    module's docstring.
    """
    T = np.asarray(T0, dtype=np.float64).copy()
    radius = max_distance
    settle = 0
    H = np.zeros((6, 6))
    it = 0
    ok = np.zeros(len(src.points), bool)
    r = w = np.zeros(0)
    var = np.zeros(0)
    for step_index in range(1, iterations + 1):
        it = step_index
        p = src.points @ T[:3, :3].T + T[:3, 3]
        d, j = dst.tree.query(p, distance_upper_bound=radius)
        ok = np.isfinite(d)
        if ok.sum() < 6:
            break
        jj = j[ok]
        pk, q, n = p[ok], dst.points[jj], dst.normals[jj]
        r = np.einsum("ij,ij->i", pk - q, n)
        var = src.sigma[ok] ** 2 + dst.sigma[jj] ** 2 + sigma_floor**2
        u = r / (TUKEY_C * np.sqrt(var))
        w = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0) / var
        J = np.hstack([np.cross(pk, n), n])
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ r
        try:
            x = -np.linalg.solve(H + 1e-12 * np.trace(H) * np.eye(6), g)
        except np.linalg.LinAlgError:
            break
        T = se3_exp(x) @ T
        step = float(np.linalg.norm(x[:3]) + np.linalg.norm(x[3:]) / max(radius, 1e-12))
        # Settle at each radius before narrowing it: a narrow search too early keeps a wrong partner set.
        if radius > min_distance and (step < 1e-3 or settle >= 8):
            radius, settle = max(min_distance, radius * 0.5), 0
        elif radius <= min_distance and step < tolerance:
            break
        settle += 1
    used = w > 0
    rms = float(np.sqrt(np.mean(r[used] ** 2))) if used.any() else float("inf")
    rms_sigma = float(np.sqrt(np.mean((r[used] ** 2) / var[used]))) if used.any() else float("inf")
    typical = float(np.median(var[used])) if used.any() else 1.0
    return PairRegistration(T, H * typical, float(used.sum()) / max(len(src.points), 1), rms, rms_sigma,
                            int(used.sum()), it)
