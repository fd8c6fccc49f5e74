"""Several scans of one object made into one model: registration, pose graph, σ-weighted fusion.

The views are finished scan folders (:mod:`~gnomon.fuse.views`: their points, σ and set-up planes);
pairs are aligned without hints and refined by σ-weighted ICP (:mod:`~gnomon.fuse.registration`),
sun scans placed first by their georeference (:mod:`~gnomon.fuse.georeference`); a pose graph
over all pairs closes the loop (:mod:`~gnomon.fuse.posegraph`); the points are fused on one voxel
grid and surfaced (:mod:`~gnomon.fuse.surface`); :mod:`~gnomon.fuse.model` runs those stages.
Open3D (``pip install "gnomon[fuse]"``) is imported on first use (:mod:`~gnomon.fuse.o3d`).
"""

from typing import TYPE_CHECKING

from gnomon._lazy import attach

if TYPE_CHECKING:
    from gnomon.fuse.model import FuseSettings as FuseSettings
    from gnomon.fuse.model import Registration as Registration
    from gnomon.fuse.model import fuse_surface as fuse_surface
    from gnomon.fuse.model import register_views as register_views
    from gnomon.fuse.views import View as View
    from gnomon.fuse.views import read_view as read_view

#: Each name this package gives and the module it lives in (imported on first use).
_WHERE = {
    "FuseSettings": "gnomon.fuse.model",
    "Registration": "gnomon.fuse.model",
    "fuse_surface": "gnomon.fuse.model",
    "register_views": "gnomon.fuse.model",
    "View": "gnomon.fuse.views",
    "read_view": "gnomon.fuse.views",
}

__getattr__, __dir__, __all__ = attach(__name__, _WHERE)
