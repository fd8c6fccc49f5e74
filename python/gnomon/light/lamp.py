"""A point lamp at a known position (measured with ``gnomon calibrate lamp``).

Each frame's shadow plane passes through the lamp centre S and the shadow
line(s) on the reference planes (:func:`gnomon.light.shadow_planes.lamp_shadow_planes`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gnomon.camera.models import Pose
from gnomon.geometry.reference_lines import ReferenceLines
from gnomon.light.base import LightModel, Recorder
from gnomon.light.shadow_planes import lamp_shadow_planes

__all__ = ["LampLight"]


class LampLight(LightModel):
    """``position_world`` (3,): the lamp centre (world units); ``pose``: world → camera."""

    occluder_hides_light = True

    kind = "lamp"

    def __init__(self, position_world: np.ndarray, pose: Pose):
        self.position_world = np.asarray(position_world, dtype=np.float64)
        self.position_cam = pose.world_to_camera(self.position_world)

    def planes_from_lines(self, lines: list[ReferenceLines]) -> tuple[np.ndarray, int]:
        return lamp_shadow_planes(lines, self.position_cam)

    def report(self, planes_cam: list[np.ndarray], warnings: list[str]) -> dict[str, Any]:
        return {"light": {"kind": self.kind, "position": self.position_world.tolist()}}

    def record_setup(self, recorder: Recorder) -> None:
        recorder.log_lamp(self.position_world)

    def shadow_plane_polygon(self, ends_world: list[np.ndarray]) -> np.ndarray | None:
        """The first line's ends and, 60 % of the way to the lamp, the same ends again."""
        if not ends_world:
            return None
        a, b = ends_world[0]
        s = self.position_world
        return np.array([a, b, b + 0.6 * (s - b), a + 0.6 * (s - a)])
