"""The light: where each frame's shadow plane comes from. One class per kind of light, one small
interface (:class:`LightModel`), and what the models need.

* :class:`LampLight`: a point lamp at a known position;
* :class:`TwoPlaneLight`: any point light, the planes from two reference planes;
* :class:`SunWithLines`: the sun, the planes through the reference lines;
* :class:`SunWithPole`: the sun and a vertical pole of known axis;
* :class:`SunWithEdge`: the sun and a straight edge of the scene (a roof line), its shadow a step per pixel.

Beside the models: the shadow planes from reference lines (:mod:`~gnomon.light.shadow_planes`), the
sun's ephemeris (:mod:`~gnomon.light.ephemeris`, pvlib), the frames' times
(:mod:`~gnomon.light.timestamps`), the georeference of a sun scan (:mod:`~gnomon.light.georef`), the
choice between a pixel's two dips (:mod:`~gnomon.light.dip_choice`), and the lamp located from a
standing pencil's shadows (:mod:`~gnomon.light.pencil`, :mod:`~gnomon.light.pencil_detection`).
A field log's ``[light]`` becomes a model through the registry of light kinds,
:data:`gnomon.config.lights.LIGHTS`, once, at the edge; the scan then only talks to the interface.

The sun's names (:class:`SunClock`, :class:`SunWithLines`, :class:`SunWithPole`, ...) are
loaded on first use: they need pandas and pvlib, which a lamp or two-plane scan never loads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gnomon._lazy import attach
from gnomon.light.base import TIMESTAMP_MODES, EdgePlanes, EdgeTimes, LightModel, ReferenceGeometry, Screening
from gnomon.light.lamp import LampLight
from gnomon.light.pencil import LampCalibration, calibrate_lamp_from_pencil
from gnomon.light.two_plane import TwoPlaneLight

if TYPE_CHECKING:
    from gnomon.light.edge import SunWithEdge as SunWithEdge
    from gnomon.light.sun import HeadingEstimate as HeadingEstimate
    from gnomon.light.sun import SunClock as SunClock
    from gnomon.light.sun import SunWithLines as SunWithLines
    from gnomon.light.sun import SunWithPole as SunWithPole
    from gnomon.light.sun import heading_from_gnomon as heading_from_gnomon

__all__ = [
    "EdgePlanes", "EdgeTimes", "HeadingEstimate", "LampCalibration", "LampLight", "LightModel", "ReferenceGeometry",
    "Screening", "SunClock", "SunWithEdge", "SunWithLines", "SunWithPole", "TIMESTAMP_MODES", "TwoPlaneLight",
    "calibrate_lamp_from_pencil", "heading_from_gnomon",
]

#: Names of :mod:`gnomon.light.sun` this package gives, imported on first use (pandas, pvlib).
_SUN_NAMES = ("HeadingEstimate", "SunClock", "SunWithLines", "SunWithPole", "heading_from_gnomon")


__getattr__, __dir__, _ = attach(__name__, {**dict.fromkeys(_SUN_NAMES, "gnomon.light.sun"),
                                            "SunWithEdge": "gnomon.light.edge"})
