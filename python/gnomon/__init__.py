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

Errors in the input raise :class:`GnomonError`.
"""

import importlib as _importlib

# The version's one home is Cargo.toml ([workspace.package] version): the
# compiled kernel carries it, and maturin writes it into the package metadata.
from gnomon._kernel import __version__
from gnomon.api import Scan, ScanMesh, load_scan, scan
from gnomon.errors import GnomonError

__all__ = ["__version__", "GnomonError", "Scan", "ScanMesh", "load_scan", "scan", "simulate"]


def __getattr__(name: str):
    # gnomon.simulate: the simulator package, also callable as gnomon.api.simulate (imported on first use)
    if name == "simulate":
        return _importlib.import_module("gnomon.simulate")
    raise AttributeError(f"module 'gnomon' has no attribute {name!r}")
