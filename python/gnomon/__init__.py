"""Gnomon: shadow-sweep 3D scanning with a desk lamp or the sun.

A fixed camera films a scene while a stick's shadow sweeps across it. From
when each pixel falls into shadow, where the shadow lies on known reference
planes at each instant, and a known light, Gnomon recovers dense 3D
(Bouguet & Perona, "3D photography on your desk", ICCV 1998).
"""

__version__ = "0.1.0"
