"""Gnomon: shadow-sweep 3D scanning with a desk lamp or the sun.

A fixed camera films a scene while a stick's shadow sweeps across it. From
when each pixel falls into shadow, where the shadow lies on known reference
planes at each instant, and a known light, Gnomon recovers dense 3D
(Bouguet & Perona, "3D photography on your desk", ICCV 1998).

The Python API (:mod:`gnomon.api`)::

    import gnomon
    log = gnomon.simulate("desk_lamp", "capture", width=400, height=300, frames=120)
    s = gnomon.scan(log)                  # a Scan: depth, sigma, points, normals, mesh, report …
    s = gnomon.scan(log, out="scan")      # … and the files of `gnomon scan` in scan/
    s = gnomon.load_scan("scan")          # read a scan folder back
    m = gnomon.fuse(["scan_a", "scan_b", "scan_c"], out="model")  # several places, one model

Errors in the input raise :class:`GnomonError`.
"""

import importlib as _importlib
from typing import TYPE_CHECKING

# The version's one home is Cargo.toml ([workspace.package] version): the
# compiled kernel carries it, and maturin writes it into the package metadata.
from gnomon._kernel import __version__
from gnomon.errors import GnomonError

if TYPE_CHECKING:
    from gnomon.api import Scan, ScanMesh, load_scan, scan

__all__ = ["__version__", "GnomonError", "Scan", "ScanMesh", "fuse", "load_scan", "scan", "simulate"]

# The API is imported on first use: `python -m gnomon` imports this package before its
# __main__ can catch a Ctrl-C, so the package itself loads nothing heavy (numpy, OpenCV).
_API = ("Scan", "ScanMesh", "load_scan", "scan")


def __getattr__(name: str):
    if name in _API:
        return getattr(_importlib.import_module("gnomon.api"), name)
    # gnomon.simulate: the simulator package, also callable as gnomon.api.simulate
    if name == "simulate":
        return _importlib.import_module("gnomon.simulate")
    # gnomon.fuse: the fusion package, also callable (several scans into one model)
    if name == "fuse":
        return _importlib.import_module("gnomon.fuse")
    raise AttributeError(f"module 'gnomon' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
