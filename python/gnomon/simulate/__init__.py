"""Synthetic captures with exact ground truth (``gnomon simulate``).

The simulator is the ground truth the pipeline is measured against, so it
shares *no* geometry with it: it has its own projection and distortion
inversion, ray casting and lighting (:mod:`gnomon.simulate.geometry`,
:mod:`gnomon.simulate.shadow`), and shares only the file formats (field log,
frames, ``.npz``). Scenes:

* ``desk_lamp`` — :func:`simulate_desk_lamp` (:mod:`gnomon.simulate.desk_lamp`),
  with pencil photos for lamp calibration (:mod:`gnomon.simulate.pencil`);
* ``desk_lamp_right`` — the same scene with the lamp mirrored to the other
  side of the camera (``DeskLampConfig(lamp_side="right")``), for dual-scan
  fusion on the same pixel grid;
* ``desk_turns`` — :func:`simulate_turns` (:mod:`gnomon.simulate.turntable`): one object
  turned on the desk by known angles, a ``desk_lamp`` capture per view, for ``gnomon fuse``;
* ``two_plane`` — :func:`simulate_two_plane` (:mod:`gnomon.simulate.two_plane_scene`):
  desk + wall, printed markers, a lamp the field log does not give;
* ``room`` — :func:`simulate_room` (:mod:`gnomon.simulate.room`): the two_plane
  scene lit as a room is (one bounce of interreflection, :mod:`gnomon.simulate.radiosity`;
  a lamp of real size for every shadow; shot and read noise), with the pixels the
  lamp never lights and those only bounced light changes in its truth;
* ``facade_sun`` — :func:`simulate_facade_sun` (:mod:`gnomon.simulate.facade_sun`):
  a pole's shadow swept by the sun (pvlib) over ground and a building facade; with ``roof_edge=True``
  (:func:`gnomon.simulate.roof_edge.simulate_roof_edge`) no pole, and the roof line across the street
  casting a shadow that climbs the facade, each point stepping into it once; with ``bounce=True``
  the sun and sky light bounced between street, facade and balconies
  (:mod:`gnomon.simulate.outdoor_bounce`), frame by frame;
* ``facade_day`` — the same facade over a whole day, night at both ends
  (``FacadeSunConfig.day()``): six cloud dips, a lamp post whose shadow is
  another moving darkening, the evening's fading sun.
"""

import sys as _sys
import types as _types

from gnomon.simulate.desk_lamp import (
    DeskLampConfig,
    DeskLampScene,
    SimulationResult,
    SweepConfig,
    simulate_desk_lamp,
)
from gnomon.simulate.facade_sun import FacadeSunConfig, FacadeSunResult, FacadeSunScene, simulate_facade_sun
from gnomon.simulate.room import RoomConfig, RoomScene, simulate_room
from gnomon.simulate.turntable import TurnsConfig, TurnsResult, simulate_turns
from gnomon.simulate.two_plane_scene import TwoPlaneConfig, TwoPlaneScene, simulate_two_plane

SCENES = ("desk_lamp", "desk_lamp_right", "desk_turns", "two_plane", "room", "facade_sun", "facade_day")

__all__ = [
    "SCENES",
    "FacadeSunConfig",
    "FacadeSunResult",
    "FacadeSunScene",
    "simulate_facade_sun",
    "DeskLampConfig",
    "RoomConfig",
    "RoomScene",
    "DeskLampScene",
    "SimulationResult",
    "SweepConfig",
    "TurnsConfig",
    "TurnsResult",
    "TwoPlaneConfig",
    "TwoPlaneScene",
    "simulate_desk_lamp",
    "simulate_room",
    "simulate_turns",
    "simulate_two_plane",
]


class _CallableModule(_types.ModuleType):
    """``gnomon.simulate`` is this package and also the function :func:`gnomon.simulate.scenes.simulate`:
    ``gnomon.simulate("desk_lamp", "capture", frames=120)`` renders a scene and returns its field log."""

    def __call__(self, scene: str, out, *, progress: bool = False, **options):
        from gnomon.simulate.scenes import simulate

        return simulate(scene, out, progress=progress, **options)


_sys.modules[__name__].__class__ = _CallableModule
