"""What a scan leaves in its folder, and how it gets there: the registry of mesh formats
(:mod:`~gnomon.outputs.formats`: a format is one module and one line), PLY, OBJ and STL
(:mod:`~gnomon.outputs.ply`, :mod:`~gnomon.outputs.obj`, :mod:`~gnomon.outputs.stl`), the scan folder's
files (:mod:`~gnomon.outputs.scan_files`) written on worker threads (:mod:`~gnomon.outputs.writers`),
preview.png (:mod:`~gnomon.outputs.images`), and the folder published all at once
(:mod:`~gnomon.outputs.publish`).
"""

from gnomon.outputs.formats import FORMATS, MeshFormat, mesh_formats
from gnomon.outputs.images import COVERAGE_CLASSES, write_preview
from gnomon.outputs.obj import write_obj
from gnomon.outputs.ply import read_ply, write_mesh_ply, write_points_ply
from gnomon.outputs.publish import recover, staged_outputs
from gnomon.outputs.scan_files import write_surface
from gnomon.outputs.stl import write_stl

__all__ = [
    "COVERAGE_CLASSES", "FORMATS", "MeshFormat", "mesh_formats", "read_ply", "recover", "staged_outputs",
    "write_mesh_ply", "write_obj", "write_points_ply", "write_preview", "write_stl", "write_surface",
]
