"""The light-model interface every light shares.

A light model answers the few questions the scan asks about the light, all in
plain values resolved from the field log beforehand (camera frame, world
units, frames of the tracker):

* which capture frames the tracker must not see (:meth:`LightModel.skipped_frames`),
  and the capture time of a frame (:meth:`LightModel.frame_time`);
* what the tracking pass means for it (:meth:`LightModel.after_tracking`), and
  which of a pixel's two candidate dips is its own shadow's (:meth:`LightModel.choose_dips`);
* which shadow edges to reconstruct (:meth:`LightModel.edges`) and, for each,
  the shadow planes Π(t) in the camera frame (:meth:`LightModel.shadow_planes`);
* its entries in ``report.json`` (:meth:`LightModel.report`) and its part of
  the recording (:meth:`LightModel.record_setup`, :meth:`LightModel.shadow_plane_polygon`,
  :meth:`LightModel.record`).

Lights whose planes come from the shadow lines measured on the reference
planes implement only :meth:`LightModel.planes_from_lines`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, ClassVar, Protocol

import numpy as np

from gnomon.camera.models import CameraModel
from gnomon.capture.tracking import ShadowTimes, TrackedSequence
from gnomon.errors import Remark
from gnomon.geometry.reference_lines import LineMemo, ReferenceLines, ReferencePlane, measure_reference_lines
from gnomon.geometry.uncertainty import line_time_sigma

__all__ = ["TIMESTAMP_MODES", "EdgePlanes", "EdgeTimes", "LightModel", "PlaneCompletion", "Recorder",
           "ReferenceGeometry", "Screening", "skipped_frames_warning"]

#: How each frame's time is known (``[capture] timestamps`` in the field log, read by
#: :mod:`gnomon.light.timestamps`): here, where the field log's parser finds them without loading pandas.
TIMESTAMP_MODES = ("filename", "exif", "start+fps")


class Recorder(Protocol):
    """The part of :class:`gnomon.recording.recorder.ScanRecording` a light model uses."""

    def log_lamp(self, position_world: np.ndarray, sigma: float | None = None) -> None: ...

    def log_sun(self, index: int, direction_world: np.ndarray, anchor_world: np.ndarray, length: float,
                capture_time: Any = None) -> None: ...


@dataclass(frozen=True)
class EdgeTimes:
    """One shadow edge's per-pixel times, as the tracker measured them.

    ``times`` (H, W) float32 tracker frames (NaN = none); ``slope`` (H, W) the
    irradiance change per frame at the crossing (linear units, for the
    under-sampling test); ``sigma_t`` (H, W) the 1σ of each time (frames).
    """

    name: str  # "enter" | "leave" | "centre"
    times: np.ndarray
    slope: np.ndarray
    sigma_t: np.ndarray


@dataclass(frozen=True)
class EdgePlanes:
    """The shadow planes of one edge, ready to triangulate.

    ``planes`` (N, 4) rows ``[nx, ny, nz, d]`` (camera frame, world units; NaN
    row = none); row k is the plane at tracker time ``k / time_scale``.
    ``sigma_t_line`` (N,) the 1σ (in rows) each plane's own measurement adds to
    the pixel times. ``lines``: the reference lines they came from (may be empty).
    ``completion``: the rows completed from one line and the located light, with
    their lines and the completion's measured 1σ angle (None: every row measured).
    """

    planes: np.ndarray
    degenerate: int
    lines: list[ReferenceLines]
    sigma_t_line: np.ndarray
    time_scale: int = 1
    measured: bool = True  # one plane per tracker frame, measured from the reference lines (else computed)
    completion: PlaneCompletion | None = None


@dataclass
class PlaneCompletion:
    """Rows of :class:`EdgePlanes` completed from one line and the located light (camera frame).

    ``line_point``, ``line_direction`` (N, 3): each completed row's line (unit direction; NaN rows:
    measured); ``sigma_rad``: the completion's 1σ angle, from its measured median error on the
    two-plane rows (:func:`gnomon.light.shadow_planes.completion_light`) as a Gaussian's (median/0.6745).
    """

    line_point: np.ndarray
    line_direction: np.ndarray
    sigma_rad: float


@dataclass
class Screening:
    """Which triangulated points a light model accepts as its own shadow: ``keep`` (H, W) bool
    (None = all), the points refused by reason, and notes for the warnings."""

    keep: np.ndarray | None = None
    rejected: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class ReferenceGeometry:
    """What measuring the shadow lines on the reference planes needs."""

    camera: CameraModel
    planes: tuple[ReferencePlane, ...]
    n_frames: int  # frames fed to the tracker
    memo: LineMemo | None = None  # lines already measured on the same times (the scan's regions')

    def lines(self, times: np.ndarray) -> list[ReferenceLines]:
        """The shadow line on every reference plane, at every tracker frame."""
        if self.memo is not None:
            return [self.memo.measure(times, self.n_frames, p, self.camera) for p in self.planes]
        return [measure_reference_lines(times, self.n_frames, p, self.camera) for p in self.planes]


def best_line_sigma(lines: list[ReferenceLines]) -> np.ndarray:
    """Per frame, the time σ of the best-measured line (several planes constrain one shadow plane)."""
    per_plane = np.stack([line_time_sigma(ln) for ln in lines])
    with np.errstate(invalid="ignore"):
        sigma = np.nanmin(np.where(np.isfinite(per_plane), per_plane, np.inf), axis=0)
    sigma[~np.isfinite(sigma)] = np.nan
    return sigma


def skipped_frames_warning(frames: list[int], why: str) -> str:
    more = " …" if len(frames) > 8 else ""
    return Remark(f"{len(frames)} frames skipped as {why} (frames {frames[:8]}{more})", frames)


class LightModel:
    """The light of one scan (see the module docstring). Subclasses set ``kind``."""

    kind: ClassVar[str] = ""
    # True when :meth:`choose_dips` needs the tracker's second candidate dips (``tracked.second``).
    chooses_dips: ClassVar[bool] = False
    # True when the planes come from the shadow lines on the reference planes (:meth:`planes_from_lines`,
    # whatever :meth:`shadow_planes` adds to them): the live view (:mod:`gnomon.runs.live`) then measures the
    # lines and planes as the frames come; False for a light whose planes need the whole capture.
    planes_from_reference_lines: ClassVar[bool] = True
    # True when the occluder hides the whole light from a pixel it shadows (a stick before a lamp: an umbra),
    # so that a dip much shallower than the pixel's lit level is not the light's own shadow on it
    # (gnomon.reconstruct.fused.screen_direct_light); False for the sun, whose pole may cast no umbra.
    occluder_hides_light: ClassVar[bool] = False
    # True when the light's shadow passes each pixel once and does not come back (a straight edge under the sun):
    # the tracker reports each pixel's lasting steps into and out of the shadow instead of its dip
    # (gnomon.capture.steps; TrackerSettings.steps).
    tracks_steps: ClassVar[bool] = False

    def skipped_frames(self, n_frames: int) -> np.ndarray:
        """(n_frames,) bool: capture frames the tracker must not see."""
        return np.zeros(n_frames, dtype=bool)

    def frame_time(self, index: int) -> datetime | np.datetime64 | None:
        """The capture time of capture frame ``index`` (UTC), when the light needs clock time."""
        return None

    def undersampling_advice(self, factor: float) -> str:
        """What to change so that the shadow edge takes ``factor`` times as many frames to cross a point."""
        return f"sweep the shadow {factor:.1f}× more slowly, or film {factor:.1f}× as many frames per second"

    def georeference(self, units: str) -> dict[str, Any] | None:
        """Where the world frame is on Earth (report.json's ``site``), when the light knows it."""
        return None

    def after_tracking(self, used: np.ndarray, skipped_dips: list[int]) -> list[str]:
        """Told which capture frames the tracker saw (in order); returns warnings."""
        if skipped_dips:
            return [skipped_frames_warning(skipped_dips, "sudden illumination dips")]
        return []

    def choose_dips(self, tracked: TrackedSequence, ray_map: np.ndarray, planes: tuple[ReferencePlane, ...],
                    max_jump: float, min_contrast_dn: float) -> list[str]:
        """Choose, per pixel, between the tracker's two candidate dips (``tracked.second``) the one
        this light's shadow made, rewriting ``tracked.times`` in place; returns warnings.
        ``ray_map`` (H, W, 3) unit camera rays; ``planes`` the reference planes; ``max_jump`` the
        relative depth step separating surfaces; ``min_contrast_dn`` the contrast floor (DN).
        By default the tracker's own verdict stands (its deepest dip, unless ambiguous)."""
        return []

    def edges(self, enter: EdgeTimes, leave: EdgeTimes, wanted: str) -> list[EdgeTimes]:
        """The edges to reconstruct; ``wanted``: "enter", "leave" or "both"."""
        return [e for e in (enter, leave) if wanted in (e.name, "both")]

    def shadow_planes(self, edge: EdgeTimes, geometry: ReferenceGeometry) -> EdgePlanes:
        """Π(t) for one edge: from the shadow lines measured on the reference planes."""
        lines = geometry.lines(edge.times)
        planes, degenerate = self.planes_from_lines(lines)
        return EdgePlanes(planes, degenerate, lines, best_line_sigma(lines))

    def planes_from_lines(self, lines: list[ReferenceLines]) -> tuple[np.ndarray, int]:
        """(N, 4) camera-frame planes, one per tracker frame, and the frames dropped as degenerate."""
        raise NotImplementedError

    def screen(self, edge: EdgeTimes, points_cam: np.ndarray, times: ShadowTimes, n_frames: int,
               relative_depth: np.ndarray | None = None,
               relative_depth_sigma: np.ndarray | None = None,
               levelled: np.ndarray | None = None) -> Screening:
        """The triangulated points (H, W, 3, camera frame) this light's shadow can explain; all by default.
        ``relative_depth`` (H, W): each dip's ``(Imax − Imin)/Imax`` in linear irradiance, and its 1σ
        from the image noise; ``levelled``: the tracker frames of illumination dips it saw levelled
        pixel by pixel (:attr:`gnomon.capture.tracking.TrackedSequence.levelled_frames`)."""
        return Screening()

    def report(self, planes_cam: list[np.ndarray], warnings: list[str]) -> dict[str, Any]:
        """Top-level ``report.json`` entries; ``planes_cam``: every reconstructed edge's planes.
        Appends to ``warnings`` what the report shows that the user should know."""
        return {"light": {"kind": self.kind, "position": None}}

    def record_setup(self, recorder: Recorder) -> None:
        """Log the light itself before the frames."""

    def shadow_plane_polygon(self, ends_world: list[np.ndarray]) -> np.ndarray | None:
        """A polygon (K, 3, world) showing one frame's shadow plane, from each line's two end points."""
        if len(ends_world) >= 2:
            return np.array([ends_world[0][0], ends_world[0][1], ends_world[1][1], ends_world[1][0]])
        return None

    def record(self, recorder: Recorder, points_world: np.ndarray, stride: int) -> None:
        """Log the light over time, after the surface is known."""
