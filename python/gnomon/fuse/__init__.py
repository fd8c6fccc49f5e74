"""Several scans of one object made into one model: registration, pose graph, σ-weighted fusion.

The views are finished scan folders (:mod:`~gnomon.fuse.views`: their points, σ and set-up planes);
pairs are aligned without hints and refined by σ-weighted ICP (:mod:`~gnomon.fuse.registration`),
sun scans placed first by their georeference (:mod:`~gnomon.fuse.georeference`); a pose graph
over all pairs closes the loop (:mod:`~gnomon.fuse.posegraph`); the points are fused on one voxel
grid and surfaced (:mod:`~gnomon.fuse.surface`); :mod:`~gnomon.fuse.model` runs those stages on
plain values and :mod:`~gnomon.fuse.run` reads the scan folders and writes the model (`gnomon fuse`).
``gnomon.fuse`` is this package and also :func:`gnomon.fuse.run.fuse_scans`::

    model = gnomon.fuse(["scan_0", "scan_1", "scan_2", "scan_3"], out="model")
    model.report["model"]["holes"], model.registration.poses

Open3D (``pip install "gnomon[fuse]"``) is imported on first use (:mod:`~gnomon.fuse.o3d`).
"""

import sys as _sys
import types as _types
from typing import TYPE_CHECKING

from gnomon._lazy import attach

if TYPE_CHECKING:
    from gnomon.fuse.model import FuseSettings as FuseSettings
    from gnomon.fuse.model import Registration as Registration
    from gnomon.fuse.model import fuse_surface as fuse_surface
    from gnomon.fuse.model import register_views as register_views
    from gnomon.fuse.run import fuse_scans as fuse_scans
    from gnomon.fuse.views import View as View
    from gnomon.fuse.views import read_view as read_view

#: Each name this package gives and the module it lives in (imported on first use).
_WHERE = {
    "FuseSettings": "gnomon.fuse.model",
    "Registration": "gnomon.fuse.model",
    "fuse_surface": "gnomon.fuse.model",
    "register_views": "gnomon.fuse.model",
    "fuse_scans": "gnomon.fuse.run",
    "View": "gnomon.fuse.views",
    "read_view": "gnomon.fuse.views",
}

__getattr__, __dir__, __all__ = attach(__name__, _WHERE)


class _CallableModule(_types.ModuleType):
    """``gnomon.fuse`` is this package and also :func:`gnomon.fuse.run.fuse_scans`:
    ``gnomon.fuse(scans, out=None, *, voxel=None, mesh_formats=("ply",), rrd=True, settings=None)``."""

    def __call__(self, scans, out=None, **options):
        from gnomon.fuse.run import fuse_scans

        return fuse_scans(scans, out, **options)


_sys.modules[__name__].__class__ = _CallableModule
