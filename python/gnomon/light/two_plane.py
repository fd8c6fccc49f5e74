"""Two reference planes (desk and wall): no light position needed.

Each frame's shadow plane is the plane through the shadow's crossings on both
reference planes (:func:`gnomon.light.shadow_planes.two_plane_shadow_planes`). All
shadow planes of a point light pass through it, so the report also gives the
light's position as the point closest to them all (or the line it lies on when
the planes share one direction).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gnomon.camera.models import Pose
from gnomon.geometry.reference_lines import ReferenceLines
from gnomon.geometry.validity import MIN_LAMP_CONDITIONING, light_point_or_line
from gnomon.light.base import EdgePlanes, EdgeTimes, LightModel, PlaneCompletion, ReferenceGeometry, best_line_sigma
from gnomon.light.shadow_planes import complete_from_light, completing_lines, completion_light, two_plane_shadow_planes

__all__ = ["TwoPlaneLight"]

# Two-plane frames needed before the light they locate completes the frames with one line.
MIN_PLANES_FOR_LIGHT = 10
# The median of |x| over a Gaussian's σ: a median error to a 1σ.
MEDIAN_TO_SIGMA = 0.6745


class TwoPlaneLight(LightModel):
    """``pose``: world → camera (to report the estimated light position in the world frame)."""

    occluder_hides_light = True

    kind = "two-plane"

    def __init__(self, pose: Pose):
        self.pose = pose

    def planes_from_lines(self, lines: list[ReferenceLines]) -> tuple[np.ndarray, int]:
        planes, degenerate, _ = self._planes_and_completion(lines, with_sigma=False)
        return planes, degenerate

    def shadow_planes(self, edge: EdgeTimes, geometry: ReferenceGeometry) -> EdgePlanes:
        lines = geometry.lines(edge.times)
        planes, degenerate, completion = self._planes_and_completion(lines, with_sigma=True)
        return EdgePlanes(planes, degenerate, lines, best_line_sigma(lines), completion=completion)

    @staticmethod
    def _planes_and_completion(lines: list[ReferenceLines],
                               with_sigma: bool) -> tuple[np.ndarray, int, PlaneCompletion | None]:
        """The planes, the frames dropped as degenerate and (``with_sigma``) the completed rows' lines and
        measured error; the live watch wants the planes only."""
        measured, degenerate = two_plane_shadow_planes(lines)
        if np.isfinite(measured[:, 0]).sum() < MIN_PLANES_FOR_LIGHT:
            return measured, degenerate, None
        # Frames whose shadow crossed one plane only: their plane from the light the others located
        # (a point, or the line the planes nearly share: whichever completes the two-plane frames better).
        light = completion_light(measured, lines, measure=with_sigma)
        planes, added = complete_from_light(measured, lines, light.point, light.direction)
        error_deg = light.errors_deg.get(light.model, float("inf"))
        if not with_sigma or not added or not np.isfinite(error_deg):
            return planes, degenerate, None
        point, direction = completing_lines(measured, planes, lines)
        return planes, degenerate, PlaneCompletion(point, direction, float(np.radians(error_deg)) / MEDIAN_TO_SIGMA)

    def report(self, planes_cam: list[np.ndarray], warnings: list[str]) -> dict[str, Any]:
        light: dict[str, Any] = {"kind": self.kind, "position": None}
        planes = np.concatenate(planes_cam)
        if np.isfinite(planes[:, 0]).sum() < 3:
            return {"light": light}
        est = light_point_or_line(planes)
        light["estimated_position_conditioning"] = est.conditioning
        if est.degenerate:
            # The planes share one direction (a stick moved parallel to itself): they fix the
            # lamp only along a line through the least-squares point, along that direction.
            light["estimated_position"] = None
            light["estimated_line"] = {
                "point": self.pose.camera_to_world(est.point).tolist(),
                "direction": (self.pose.R.T @ est.direction).tolist(),
                "reason": (f"the shadow planes all contain nearly one direction (singular-value ratio "
                           f"{est.conditioning:.4f} < {MIN_LAMP_CONDITIONING}): the lamp lies on a line, "
                           "not at a point"),
            }
            # No warning: a two-plane scan needs no lamp position (each plane comes from its own two
            # lines), so there is nothing for the user to do; report.json says why there is a line.
        else:
            light["estimated_position"] = self.pose.camera_to_world(est.point).tolist()
            light["estimated_position_plane_rms"] = est.plane_rms
        return {"light": light}
