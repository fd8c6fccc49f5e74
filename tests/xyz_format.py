"""An example mesh format written for tests/test_mesh_formats.py: the mesh's vertices as ``x y z`` lines.

It shows what adding a format to Gnomon takes: this module (its writer) and one line in the
registry, :data:`gnomon.outputs.formats.FORMATS`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gnomon.geometry.surface import Surface
from gnomon.outputs.formats import OutputContext
from gnomon.util import atomic


def write_scan_xyz(folder: Path, surface: Surface, ctx: OutputContext) -> None:
    """mesh.xyz: one ``x y z`` line per mesh vertex (world frame, ``ctx.units``), after a comment naming them."""
    rows = "\n".join(" ".join(f"{c:.6f}" for c in v) for v in np.asarray(surface.mesh.vertices, dtype=np.float64))
    atomic.write_text(folder / "mesh.xyz", f"# gnomon mesh vertices, units {ctx.units}\n{rows}\n")
