"""Synthetic captures with exact ground truth (``gnomon simulate``).

The simulator is the ground truth the pipeline is measured against, so it
shares *no* geometry with it: it has its own projection and distortion
inversion, ray casting and lighting (:mod:`gnomon.simulate.geometry`,
:mod:`gnomon.simulate.shadow`), and shares only the file formats (field log,
frames, ``.npz``). Scenes:

* ``desk_lamp`` — :func:`simulate_desk_lamp` (:mod:`gnomon.simulate.desk_lamp`).
"""

from gnomon.simulate.desk_lamp import (
    DeskLampConfig,
    DeskLampScene,
    SimulationResult,
    simulate_desk_lamp,
)

SCENES = ("desk_lamp",)

__all__ = ["SCENES", "DeskLampConfig", "DeskLampScene", "SimulationResult", "simulate_desk_lamp"]
