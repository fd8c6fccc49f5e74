"""Gnomon: shadow-sweep 3D scanning with a desk lamp or the sun.

A fixed camera films a scene while a stick's shadow sweeps across it. From
when each pixel falls into shadow, where the shadow lies on known reference
planes at each instant, and a known light, Gnomon recovers dense 3D
(Bouguet & Perona, "3D photography on your desk", ICCV 1998).
"""

# The version's one home is Cargo.toml ([workspace.package] version): the
# compiled kernel carries it, and maturin writes it into the package metadata.
from gnomon._kernel import __version__
