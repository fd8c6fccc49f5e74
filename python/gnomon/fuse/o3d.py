"""Open3D, the optional geometry library of the fusion (``pip install "gnomon[fuse]"``), imported on first use."""

from __future__ import annotations

from typing import Any

from gnomon.errors import GnomonError

__all__ = ["open3d", "INSTALL_HINT"]

INSTALL_HINT = 'gnomon fuse needs Open3D: pip install "gnomon[fuse]"'


def open3d() -> Any:
    """The ``open3d`` module, or a one-line :class:`GnomonError` saying how to install it."""
    try:
        import open3d as o3d
    except ImportError:
        raise GnomonError(INSTALL_HINT) from None
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d
