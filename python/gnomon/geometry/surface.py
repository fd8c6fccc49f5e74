"""The scan's surface on the pixel grid: world points, colours, normals and the cut grid mesh.

A surface is built from a depth map (camera Z per pixel, NaN where none), its σ, the pixels kept and
a colour image, for one camera's ray map and pose: :func:`surface_points` gives the points (world
frame, row-major over the kept pixels) and their normals, :func:`mesh_surface` the mesh on the pixel
grid (:mod:`gnomon.geometry.meshing`), :func:`build_surface` both. The scan and `gnomon merge` write
what these return.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnomon import _kernel
from gnomon.camera.models import Pose
from gnomon.geometry.meshing import (
    MIN_PIECE_VERTICES,
    GridMesh,
    clean_faces,
    grid_faces,
    grid_normals,
)


def ray_plane_angles(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray,
                     where: np.ndarray) -> np.ndarray:
    """Angle (degrees) between each pixel's ray and the shadow plane it was triangulated on, at ``where``.

    ``times``: (H, W) in rows of ``planes`` (N, 4) (the plane interpolated at the pixel's time, as the
    kernel does); ``ray_map``: (H, W, 3) camera-frame rays. Returns the angles of the pixels of ``where``
    (row-major), NaN where a plane is missing. The kernel computes them (``_kernel.ray_plane_angles``, the
    same f64 arithmetic); :func:`_ray_plane_angles_numpy` is the definition in numpy."""
    if len(planes) == 0:
        return _ray_plane_angles_numpy(ray_map, times, planes, where)
    return _kernel.ray_plane_angles(np.ascontiguousarray(ray_map, dtype=np.float64),
                                    np.ascontiguousarray(times, dtype=np.float64),
                                    np.ascontiguousarray(planes, dtype=np.float64),
                                    np.ascontiguousarray(where, dtype=np.uint8))


def _ray_plane_angles_numpy(ray_map: np.ndarray, times: np.ndarray, planes: np.ndarray,
                            where: np.ndarray) -> np.ndarray:
    """:func:`ray_plane_angles` in numpy (the kernel's ``ray_plane_angles`` gives the same)."""
    t = times[where].astype(np.float64)
    i = np.clip(np.floor(t).astype(np.int64), 0, len(planes) - 1)
    j = np.minimum(i + 1, len(planes) - 1)
    f = (t - i)[:, None]
    n = (1.0 - f) * planes[i, :3] + f * planes[j, :3]
    r = ray_map[where].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        sine = np.abs(np.sum(n * r, axis=1)) / (np.linalg.norm(n, axis=1) * np.linalg.norm(r, axis=1))
    return np.degrees(np.arcsin(np.clip(sine, 0.0, 1.0)))


@dataclass
class Surface:
    """A reconstructed surface on the pixel grid: what `scan` and `merge` write."""

    depth: np.ndarray  # (H, W) camera Z, NaN = none
    sigma: np.ndarray  # (H, W) σZ, NaN = none
    valid: np.ndarray  # (H, W)
    points_world: np.ndarray  # (N, 3) float32, row-major over valid pixels
    colors: np.ndarray  # (N, 3) uint8
    uv: np.ndarray  # (N, 2) float32 pixel of each point
    mesh: GridMesh
    vertex_rgb: np.ndarray  # (V, 3) uint8
    normals: np.ndarray  # (N, 3) float32 unit normals (world frame, towards the camera)
    rgb: np.ndarray  # (H, W, 3) uint8 colour image (the mesh's texture)


@dataclass
class SurfacePoints:
    """A surface's points on the pixel grid before its mesh (:func:`surface_points`): :class:`Surface`'s
    fields but the mesh's, and the grids the mesh is built from."""

    depth: np.ndarray  # (H, W) camera Z, NaN = none
    sigma: np.ndarray  # (H, W) σZ, NaN = none
    valid: np.ndarray  # (H, W)
    points_world: np.ndarray  # (N, 3) float32, row-major over valid pixels
    colors: np.ndarray  # (N, 3) uint8
    uv: np.ndarray  # (N, 2) float32 pixel of each point
    normals: np.ndarray  # (N, 3) float32 unit normals (world frame, towards the camera)
    rgb: np.ndarray  # (H, W, 3) uint8 colour image
    world_grid: np.ndarray  # (H, W, 3) float32 world points, NaN off the surface
    normal_grid: np.ndarray  # (H, W, 3) float32 unit normals, NaN off the surface


def surface_maps(depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The depth and σ maps (float32) of the valid pixels, NaN elsewhere: what :func:`surface_points` and
    :func:`mesh_faces` take (either again gives the same maps)."""
    return (np.where(valid, depth, np.nan).astype(np.float32, copy=False),
            np.where(valid, sigma, np.nan).astype(np.float32, copy=False))


def surface_points(ray_map: np.ndarray, pose: Pose, depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray,
                   rgb: np.ndarray, max_relative_jump: float) -> SurfacePoints:
    """Points (world frame), colours and normals of the valid pixels (the mesh: :func:`mesh_surface`);
    a neighbour beyond ``max_relative_jump`` of a pixel's depth takes no part in its normal."""
    depth, sigma = surface_maps(depth, sigma, valid)
    # points_from_depth, then pose.camera_to_world, per pixel in the kernel (rows in parallel)
    world_grid = _kernel.world_points(np.ascontiguousarray(ray_map, dtype=np.float64), depth,
                                      np.ascontiguousarray(valid, dtype=np.uint8), pose.R, pose.t)
    normals = grid_normals(world_grid, depth, valid, pose.camera_centre_world, max_relative_jump)
    index = np.flatnonzero(valid)  # the valid pixels, row-major: one gather (np.take) per array
    v, u = np.divmod(index, valid.shape[1])
    uv = np.empty((index.size, 2), dtype=np.float32)  # the pixels' columns and rows, cast as astype casts them
    uv[:, 0], uv[:, 1] = u, v
    return SurfacePoints(depth, sigma, valid, np.take(world_grid.reshape(-1, 3), index, axis=0),
                         np.take(rgb.reshape(-1, 3), index, axis=0), uv, np.take(normals.reshape(-1, 3), index, axis=0),
                         rgb, world_grid, normals)


@dataclass
class MeshFaces:
    """A surface's cleaned grid mesh before its vertices are gathered (:func:`mesh_faces`)."""

    faces: np.ndarray  # (F, 3) int32 into the mesh's vertices
    source: np.ndarray  # (V,) int64: the point (valid pixel, row-major rank) each mesh vertex is


def mesh_faces(depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray, max_relative_jump: float) -> MeshFaces:
    """The cut grid mesh's faces over the valid pixels, small pieces removed and non-manifold vertices split
    (:func:`gnomon.geometry.meshing.grid_faces` then ``clean_faces``): it needs only the maps
    (:func:`surface_maps`'), not the points, so it can be built while they are."""
    depth, sigma = surface_maps(depth, sigma, valid)
    faces = grid_faces(depth, valid, max_relative_jump, sigma=sigma)
    clean, source = clean_faces(int(np.count_nonzero(valid)), faces, np.flatnonzero(valid), MIN_PIECE_VERTICES,
                                valid.shape[1])
    return MeshFaces(clean, source)


def mesh_surface(points: SurfacePoints, max_relative_jump: float, faces: MeshFaces | None = None) -> Surface:
    """The cut grid mesh of a surface's points (:func:`gnomon.geometry.meshing.grid_mesh`, small pieces removed);
    ``faces``: :func:`mesh_faces` of the same maps, if already built."""
    # grid_mesh's vertices and normals are the points' own (the valid pixels, row-major): not gathered again
    if faces is None:
        faces = mesh_faces(points.depth, points.sigma, points.valid, max_relative_jump)
    source = faces.source
    mesh = GridMesh(np.take(points.points_world, source, axis=0), faces.faces,
                    np.take(np.flatnonzero(points.valid), source), np.take(points.normals, source, axis=0))
    return Surface(points.depth, points.sigma, points.valid, points.points_world, points.colors, points.uv, mesh,
                   np.take(points.rgb.reshape(-1, 3), mesh.pixel_index, axis=0), points.normals, points.rgb)


def build_surface(ray_map: np.ndarray, pose: Pose, depth: np.ndarray, sigma: np.ndarray, valid: np.ndarray,
                  rgb: np.ndarray, max_relative_jump: float) -> Surface:
    """Points (world frame), colours and the cut grid mesh of the valid pixels."""
    return mesh_surface(surface_points(ray_map, pose, depth, sigma, valid, rgb, max_relative_jump), max_relative_jump)


def points_from_depth(ray_map: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Camera-frame points (H, W, 3) on each pixel's ray at camera Z = depth."""
    return (ray_map * (depth / ray_map[..., 2])[..., None]).astype(np.float32)
