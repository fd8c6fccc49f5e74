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
  another moving darkening, the evening's fading sun;
* ``chessboard`` — views of a 9 × 6 board with known intrinsics, distortion and poses
  (:mod:`gnomon.simulate.chessboard`), for ``gnomon calibrate camera``.

The scenes' names (:data:`SCENES`) and :func:`gnomon.simulate.scenes.simulate` load no scene: each
scene's module is imported when it is rendered or one of its names is asked for.
"""

import sys as _sys
import types as _types
from typing import TYPE_CHECKING

from gnomon._lazy import attach
from gnomon.simulate.scenes import SCENES

if TYPE_CHECKING:
    from gnomon.simulate.desk_lamp import DeskLampConfig as DeskLampConfig
    from gnomon.simulate.desk_lamp import DeskLampScene as DeskLampScene
    from gnomon.simulate.desk_lamp import SimulationResult as SimulationResult
    from gnomon.simulate.desk_lamp import SweepConfig as SweepConfig
    from gnomon.simulate.desk_lamp import simulate_desk_lamp as simulate_desk_lamp
    from gnomon.simulate.facade_sun import FacadeSunConfig as FacadeSunConfig
    from gnomon.simulate.facade_sun import FacadeSunResult as FacadeSunResult
    from gnomon.simulate.facade_sun import FacadeSunScene as FacadeSunScene
    from gnomon.simulate.facade_sun import simulate_facade_sun as simulate_facade_sun
    from gnomon.simulate.room import RoomConfig as RoomConfig
    from gnomon.simulate.room import RoomScene as RoomScene
    from gnomon.simulate.room import simulate_room as simulate_room
    from gnomon.simulate.turntable import TurnsConfig as TurnsConfig
    from gnomon.simulate.turntable import TurnsResult as TurnsResult
    from gnomon.simulate.turntable import simulate_turns as simulate_turns
    from gnomon.simulate.two_plane_scene import TwoPlaneConfig as TwoPlaneConfig
    from gnomon.simulate.two_plane_scene import TwoPlaneScene as TwoPlaneScene
    from gnomon.simulate.two_plane_scene import simulate_two_plane as simulate_two_plane

# Each scene's names are imported from its module on first use: importing the package (as `gnomon scan`
# does through gnomon.api, for SCENES) loads no scene, and so not pandas (the facade's and pvlib's, ~0.45 s).
__getattr__, __dir__, _names = attach(__name__, {
    **dict.fromkeys(("DeskLampConfig", "DeskLampScene", "SimulationResult", "SweepConfig", "simulate_desk_lamp"),
                    "gnomon.simulate.desk_lamp"),
    **dict.fromkeys(("FacadeSunConfig", "FacadeSunResult", "FacadeSunScene", "simulate_facade_sun"),
                    "gnomon.simulate.facade_sun"),
    **dict.fromkeys(("RoomConfig", "RoomScene", "simulate_room"), "gnomon.simulate.room"),
    **dict.fromkeys(("TurnsConfig", "TurnsResult", "simulate_turns"), "gnomon.simulate.turntable"),
    **dict.fromkeys(("TwoPlaneConfig", "TwoPlaneScene", "simulate_two_plane"), "gnomon.simulate.two_plane_scene"),
})
__all__ = ["SCENES", *_names]


class _CallableModule(_types.ModuleType):
    """``gnomon.simulate`` is this package and also the function :func:`gnomon.simulate.scenes.simulate`:
    ``gnomon.simulate("desk_lamp", "capture", frames=120)`` renders a scene and returns its field log."""

    def __call__(self, scene: str, out, *, progress: bool = False, **options):
        from gnomon.simulate.scenes import simulate

        return simulate(scene, out, progress=progress, **options)


_sys.modules[__name__].__class__ = _CallableModule
