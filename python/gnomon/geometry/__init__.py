"""Geometry on plain arrays, shared by the light models and the reconstruction: the shadow lines on
the reference planes (:mod:`~gnomon.geometry.reference_lines`), rays against shadow planes
(:mod:`~gnomon.geometry.triangulation`), σ by propagation (:mod:`~gnomon.geometry.uncertainty`), the
checks a point must pass (:mod:`~gnomon.geometry.validity`), the output crop (:mod:`~gnomon.geometry.crop`),
the surface's points and normals (:mod:`~gnomon.geometry.surface`) and its mesh on the pixel grid
(:mod:`~gnomon.geometry.meshing`). Camera frame and world units unless a name says otherwise.
"""

from gnomon.geometry.crop import Crop, crop_mask
from gnomon.geometry.meshing import GridMesh, grid_mesh, remove_small_components
from gnomon.geometry.reference_lines import PlaneInCamera, ReferenceLines, ReferencePlane, measure_reference_lines
from gnomon.geometry.surface import (
    Surface,
    SurfacePoints,
    build_surface,
    mesh_surface,
    points_from_depth,
    surface_points,
)
from gnomon.geometry.triangulation import supported_by_neighbours, triangulate, triangulate_depth
from gnomon.geometry.uncertainty import depth_sigma, line_time_sigma

__all__ = [
    "Crop", "GridMesh", "PlaneInCamera", "ReferenceLines", "ReferencePlane", "Surface", "SurfacePoints",
    "build_surface", "crop_mask", "depth_sigma", "grid_mesh", "line_time_sigma", "measure_reference_lines",
    "mesh_surface", "points_from_depth", "remove_small_components", "supported_by_neighbours", "surface_points",
    "triangulate", "triangulate_depth",
]
