"""A field log resolved, once, into the plain values a scan needs.

:func:`resolve_scan` reads the field log (and, for planes with markers or a
chessboard, one photo) and returns a :class:`ScanSetup`: the camera, its pose,
the reference planes in the camera frame, the tracker settings, the light
model and the reconstruction settings. Nothing after it reads the field log.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon.camera.aruco import plane_pose_from_aruco, plane_pose_from_charuco
from gnomon.camera.calibration import fit_camera_to_frames, read_grey
from gnomon.camera.models import CalibratedCamera, CameraModel, OpenCVCamera, Pose
from gnomon.camera.plane_pose import (
    MarkScale,
    PlanePose,
    find_markers,
    fit_plane_pose,
    fit_rectangle_pose,
    plane_pose_from_chessboard,
    plane_pose_from_markers,
)
from gnomon.capture.frames import FrameSource, to_grey
from gnomon.capture.tracking import DEFAULT_DIP_FRAMES, TrackerSettings, decoding_lut
from gnomon.config.fieldlog import check_geometry
from gnomon.config.lights import LIGHTS, light_model, registers
from gnomon.config.specs import FieldLog, PlaneSpec
from gnomon.errors import FieldLogError, GnomonError
from gnomon.geometry.crop import Crop
from gnomon.geometry.reference_lines import PlaneInCamera, ReferencePlane, region_mask
from gnomon.light import LightModel
from gnomon.util.chi2 import chi2_isf

__all__ = ["FocalFit", "ScanInputs", "ScanSetup", "alone_focal_factor", "best_focal_factor", "check_rectangle_marks",
           "crop_of", "dip_width_policy", "first_frame", "fit_focal",
           "focal_diagnosis", "frame_source", "marked_points", "plane_region_mask", "resolve_reference_planes",
           "provisional_distance", "resolve_scan", "site_datum", "tracker_settings", "untied_planes"]


@dataclass(frozen=True)
class ScanInputs:
    """Where a scan's inputs came from, for its report."""

    field_log: Path
    camera_file: Path | None = None
    calibration: dict[str, Any] = field(default_factory=dict)  # the camera file's calibration summary
    reference_planes: list[dict[str, Any]] = field(default_factory=list)  # planes measured from markers


@dataclass(frozen=True)
class ScanSetup:
    """Everything a scan needs, in plain values (camera frame, world units).

    ``edge``: which shadow edges to reconstruct ("enter", "leave", "both");
    ``max_depth_jump``: relative depth step that cuts the mesh and marks
    outliers; ``units``: the world units ("mm" or "m").
    """

    camera: CalibratedCamera
    pose: Pose
    planes: tuple[ReferencePlane, ...]
    tracker: TrackerSettings
    light: LightModel
    edge: str
    max_depth_jump: float
    units: str
    inputs: ScanInputs
    warnings: tuple[str, ...] = ()
    crop: Crop | None = None  # [output] crop (world frame)
    mesh_formats: tuple[str, ...] = ("ply",)  # [output] mesh_formats: the mesh's files (gnomon.outputs.formats)
    dip_width: str = "auto"  # how the dip width was set: see dip_width_policy
    cloud_formats: tuple[str, ...] = ()  # [output] cloud_formats: the survey files (LAZ by default when georeferenced)
    crs: str | None = None  # [output] crs: the survey files' CRS (None: the site's UTM zone)
    site_datum: dict[str, Any] | None = None  # [site]'s altitude datum, geoid and heading's north, for the report
    # (plane, anchor) names: planes whose marks fix only their orientation, at a provisional distance
    # until the shadow ties them to the anchor where they meet (gnomon.reconstruct.corners)
    untied: tuple[tuple[str, str], ...] = ()

    def georeference(self) -> dict[str, Any] | None:
        """report.json's ``site``: where the world frame is on Earth (a sun scan), else None."""
        site = self.light.georeference(self.units)
        if site is not None and self.site_datum is not None:
            site.update(self.site_datum)
        return site


def frame_source(log: FieldLog) -> FrameSource:
    """The field log's frames (image files or a video), corrupt ones refused or dropped as
    ``[capture] on_corrupt_frame`` says."""
    c = log.capture
    return FrameSource(c.image_files, c.video, c.frame_count, c.on_corrupt_frame)


def resolve_scan(log: FieldLog, source: FrameSource) -> ScanSetup:
    """Resolve the field log into a :class:`ScanSetup` (measuring marker planes on their photo)."""
    for plane in log.planes:
        if not plane.has_regions:
            raise FieldLogError(f"{log.path}: [[planes]] {plane.name}: no 'regions' or 'mask' (where the plane is "
                                f"bare and swept); `gnomon regions {log.path}` proposes them")
    log, planes_report = resolve_reference_planes(log, source)
    assert log.pose is not None  # resolve_reference_planes sets it
    pose = log.pose
    warnings: list[str] = [e["marker_warning"] for e in planes_report if "marker_warning" in e]
    light = light_model(log, pose, source.count, warnings)
    shape = (log.camera.height, log.camera.width)
    planes = tuple(ReferencePlane(p.name, PlaneInCamera.from_world(p.point, p.normal, pose),
                                  plane_region_mask(p, shape), p.regions) for p in log.planes)
    s = log.scan
    tracker = dataclasses.replace(tracker_settings(log), second_dips=light.chooses_dips, steps=light.tracks_steps)
    inputs = ScanInputs(log.path, log.camera_file, dict(log.calibration), planes_report)
    georeferenced = light.georeference(log.capture.units) is not None
    if log.output.crs is not None and not georeferenced:
        raise FieldLogError(f"{log.path}: [output] crs: this scan is not georeferenced (its world frame is the "
                            "scan's own); a CRS needs a sun scan's [site]")
    clouds = log.output.cloud_formats
    if clouds is None:
        clouds = ("laz",) if georeferenced else ()
    return ScanSetup(log.camera, pose, planes, tracker, light, s.edge, s.max_depth_jump, log.capture.units,
                     inputs, tuple(warnings), crop_of(log), log.output.mesh_formats, dip_width_policy(log),
                     clouds, log.output.crs, site_datum(log), untied_planes(planes_report))


def site_datum(log: FieldLog) -> dict[str, Any] | None:
    """How the field log's [site] altitude and heading are meant (report.json's ``site``)."""
    s = log.site
    if s is None:
        return None
    datum: dict[str, Any] = {"altitude_datum": s.altitude_datum, "heading_north": s.heading_north,
             "datum": "WGS84" if s.altitude_datum == "ellipsoidal" else f"WGS84, heights above {s.geoid}"}
    if s.altitude_datum == "orthometric":
        datum["geoid"] = s.geoid
    if s.declination_deg is not None:
        datum["declination_deg"] = s.declination_deg
    if s.position_sigma_m is not None:
        datum["position_sigma_m"] = s.position_sigma_m
    if s.heading_sigma_deg is not None:
        datum["heading_sigma_deg"] = s.heading_sigma_deg
    return datum


def untied_planes(planes_report: list[dict[str, Any]]) -> tuple[tuple[str, str], ...]:
    """(plane, anchor) of each plane :func:`resolve_reference_planes` left at a provisional distance: the
    first measured plane (the world frame) is every such plane's anchor."""
    return tuple((e["plane"], planes_report[0]["plane"]) for e in planes_report if e.get("distance") == "provisional")


def crop_of(log: FieldLog) -> Crop | None:
    """The field log's ``[output]`` crop in world coordinates, or None."""
    out = log.output
    if not out.crops:
        return None
    box = out.crop_box
    plane = next((p for p in log.planes if p.name == out.crop_above), None)
    return Crop(box_min=None if box is None else box[0], box_max=None if box is None else box[1],
                plane_name=None if plane is None else plane.name,
                plane_point=None if plane is None else np.asarray(plane.point, dtype=np.float64),
                plane_normal=None if plane is None else np.asarray(plane.normal, dtype=np.float64),
                min_height=out.crop_min_height, max_height=out.crop_max_height, max_sigma=out.max_sigma)


def dip_width_policy(log: FieldLog) -> str:
    """How a scan of ``log`` sets the tracker's dip width: ``"auto"`` (widened as the shadows need,
    :func:`gnomon.capture.tracking.track_widening`), ``"field log"`` (``[scan] max_dip_frames``, checked), or
    ``"sun"`` (kept and not checked: under a moving sun, with clouds and dusk, the width is what tells the
    shadow from a change of light; ``max_dip_frames`` sets it)."""
    if log.scan.max_dip_frames is not None:
        return "field log"
    kind = LIGHTS.get(log.light.kind)
    return "sun" if (kind is not None and kind.dip_width == "sun") or log.scan.normalize_illumination else "auto"


def tracker_settings(log: FieldLog) -> TrackerSettings:
    """How the field log's frames become shadow times."""
    s = log.scan
    # An [edge]'s shadow passes each pixel once and stays: steps, not dips (the scan's light, SunWithEdge,
    # says so too; `gnomon regions` tracks without building the light).
    return TrackerSettings(log.capture.gamma, s.min_contrast, s.window, s.normalize_illumination,
                           DEFAULT_DIP_FRAMES if s.max_dip_frames is None else s.max_dip_frames,
                           register=registers(log), steps=log.edge is not None)


def first_frame(source: FrameSource) -> np.ndarray:
    """The capture's first frame (colour when it has colour)."""
    frame = source.first()
    return frame.color if frame.color is not None else frame.grey


def _plane_pose_from_aruco(log: FieldLog, plane: PlaneSpec, image: np.ndarray, camera: CameraModel,
                           where: str) -> PlanePose:
    """A plane's pose from its ArUco markers or ChArUco board, in the world frame (no pixel hints)."""
    grey = to_grey(image)
    if plane.aruco is not None:
        linear = decoding_lut(log.capture.gamma, grey.dtype)[grey] if grey.dtype in (np.uint8, np.uint16) else None
        return plane_pose_from_aruco(
            grey, camera, dict(plane.aruco.markers), plane.aruco.dictionary, plane.aruco.size,
            linear=linear, to_world=plane.plane_to_world, source=where,
        )
    c = plane.charuco
    assert c is not None
    return plane_pose_from_charuco(grey, camera, c.dictionary, c.squares, c.square, c.marker, origin=c.origin,
                                   to_world=plane.plane_to_world, source=where)


def _measured(plane: PlaneSpec) -> bool:
    """The plane carries something to measure its pose from."""
    return bool(plane.markers or plane.chessboard or plane.aruco or plane.charuco)


def _measure_plane(log: FieldLog, plane: PlaneSpec, image: np.ndarray, name: str) -> PlanePose:
    """The pose of a plane's own 2-D frame in the camera, from its markers or board in ``image``."""
    where = f"{log.path}: [[planes]] {plane.name}: {name}"
    # A plane's own photo may be a still at another resolution of the same sensor.
    camera, _ = fit_camera_to_frames(log.camera, image.shape[1], image.shape[0], f"{log.path}: [camera]", name)
    if plane.aruco is not None or plane.charuco is not None:
        return _plane_pose_from_aruco(log, plane, image, camera, where)
    if plane.unmeasured_marks:
        return _measure_rectangle(plane, image, camera, where)
    if plane.markers:
        names = [f"{plane.name} marker {m.id}" for m in plane.markers]
        pixels = np.array([m.pixel_hint for m in plane.markers])
        if all(m.exact for m in plane.markers):
            return fit_plane_pose(camera, plane.marker_world(), pixels, names=names, method="pixels", source=where)
        exact = np.array([m.exact for m in plane.markers])
        return plane_pose_from_markers(image, camera, plane.marker_world(), pixels, names=names, source=where,
                                       exact=exact)
    assert plane.chessboard is not None and plane.square is not None
    return plane_pose_from_chessboard(image, camera, plane.chessboard, plane.square, source=where)


def _measure_rectangle(plane: PlaneSpec, image: np.ndarray, camera: CameraModel, where: str) -> PlanePose:
    """A plane from marks nobody measured, taken as a rectangle's corners (:func:`fit_rectangle_pose`), its
    pose from the world frame (the plane's ``point``, ``normal``, ``x_axis`` placing the fitted frame:
    origin at the rectangle's centre, z towards the camera) to the camera."""
    names = [f"{plane.name} marker {m.id}" for m in plane.markers]
    pixels = np.array([m.pixel_hint for m in plane.markers], dtype=np.float64)
    located = np.array([CLICKED_SIGMA_PX if m.exact else np.nan for m in plane.markers])
    found = [k for k, m in enumerate(plane.markers) if not m.exact]
    if found:
        dets = find_markers(image, pixels[found], names=[names[k] for k in found], source=where)
        pixels[found] = np.array([d.pixel for d in dets])
        located[found] = [float(np.hypot(d.sigma_px, FOUND_MARK_FLOOR_PX)) if np.isfinite(d.sigma_px)
                          else MARKER_SIGMA_PX for d in dets]
    ids = [m.id for m in plane.markers]
    scale = None
    if plane.mark_distance is not None:
        a, b, length = plane.mark_distance
        scale = MarkScale(ids.index(a), ids.index(b), length)
    pp = fit_rectangle_pose(camera, pixels, np.hypot(located, plane.off_rectangle_px), names=names, scale=scale,
                            source=where)
    assert plane.x_axis is not None  # the parser gives one
    B = np.stack([plane.x_axis, np.cross(plane.normal, plane.x_axis), plane.normal], axis=1)
    R = pp.pose.R @ B.T
    return dataclasses.replace(pp, pose=Pose(R=R, t=pp.pose.t - R @ plane.point), point_world=plane.point.copy(),
                               normal_world=-plane.normal, located_px=located)


def _measure_planes(log: FieldLog, source: FrameSource) -> list[tuple[PlaneSpec, PlanePose]]:
    """Every plane with markers or a chessboard, measured on its ``image`` or the capture's first frame."""
    first = None
    measured = []
    for plane in (p for p in log.planes if _measured(p)):
        if plane.image is not None:
            image, name = read_grey(plane.image), plane.image.name
        else:
            first = first_frame(source) if first is None else first
            image = first
            name = log.capture.image_files[0].name if log.capture.image_files else f"{log.capture.video} frame 0"
        measured.append((plane, _measure_plane(log, plane, image, name)))
    return measured


#: σ (px, per axis) of a marker centre or board corner found in the image, against where the plane
#: puts it: the localisation and the marker's hand-measured position on its plane. The fits leave
#: 0.01–0.03 px rms on the simulated two_plane capture, 0.2 px (desk) and 1.1 px (wall) on the real
#: frog capture (CMU 15-463).
MARKER_SIGMA_PX = 1.0
#: ... of a marker pixel given as it is (``pixel``: a clicked cross).
CLICKED_SIGMA_PX = 1.5
#: A found 2×2 checker's centre errs by more than its image noise says (blur, compression, the pixel
#: grid: 0.02–0.04 px against the simulator's truth where the noise says 0.005–0.01): added in quadrature.
FOUND_MARK_FLOOR_PX = 0.05
#: Chance that a correct plane's markers fail the consistency check (a χ² test of their residuals).
MARKER_CHECK_P = 1e-3
#: A plane whose orientation is off by more than this (from the declared plane, or as the 1-σ
#: uncertainty of its markers' fit when nothing is declared) is no reference: an error.
MAX_PLANE_TILT_DEG = 5.0


#: Focal lengths tried (as factors of the camera's) when a plane's markers do not fit it.
FOCAL_FACTORS = np.geomspace(0.5, 2.0, 57)


def focal_diagnosis(camera: Any, points: np.ndarray, pixels: np.ndarray, limit_rms_px: float,
                    others: dict[str, float] | Callable[[], dict[str, float]] | None = None) -> str:
    """Why a plane's points do not fit it, as far as the camera's focal length can tell (one clause).

    ``camera`` an :class:`~gnomon.camera.models.OpenCVCamera` (other models: no
    clause); ``points`` (N, 2) plane or (N, 3) coplanar world coordinates;
    ``pixels`` (N, 2). The pose is refitted with the focal lengths scaled by
    each of :data:`FOCAL_FACTORS` (principal point and distortion kept). A
    scale that brings the residuals within ``limit_rms_px`` and below a
    quarter of their present value means the camera
    does not fit this capture (a zoom, a refocus, another crop or frame size
    than the calibration's; with 4 points, whose residuals have 2 degrees of
    freedom, one misplaced mark can look the same, and the clause says so);
    no scale bringing them below half their present value means the points
    themselves are not where their plane coordinates put them (hand-placed
    marks, a surface that is not flat, a wrong id).

    With 4 points one plane alone cannot tell a focal length from one
    misplaced mark: ``others`` (the best factor of each other marked plane
    alone, :func:`best_focal_factor`) then decides. The camera is blamed only
    when another plane agrees on the factor (within :data:`FOCAL_AGREEMENT`);
    otherwise the clause says that the planes disagree and the marks are off.
    Without ``others`` (None) the clause only warns that 4 points cannot tell. ``others`` may be a call
    that returns them: it is called only when the clause would blame the focal length (each other plane's
    factor costs a search of its own).
    """
    if not isinstance(camera, OpenCVCamera) or len(pixels) < 4:
        return ""
    factor, best_rms, here = best_focal_factor(camera, lambda cam: fit_plane_pose(cam, points, pixels).rms_px)
    return _focal_clause(camera, factor, best_rms, here, limit_rms_px, len(pixels) > 4, others,
                         "the points are not where their plane coordinates put them (marks placed by hand, a "
                         "surface that is not flat, a wrong id)")


#: Two planes' best focal factors agree when they differ by less than this (relative): two steps of
#: :data:`FOCAL_FACTORS`.
FOCAL_AGREEMENT = 0.05


def best_focal_factor(camera: OpenCVCamera, rms_at: Any) -> tuple[float, float, float]:
    """(factor, rms px at it, rms px at the camera's focal length): of :data:`FOCAL_FACTORS`, the one
    whose scaled camera (``fx``, ``fy`` times it) ``rms_at(camera)`` fits best (NaN factor: none fits),
    searched on every 4th factor and then on every one within 3 of the best of those."""
    rms = np.full(len(FOCAL_FACTORS), np.inf)

    def at(i: int) -> float:
        if rms[i] == np.inf:
            k = FOCAL_FACTORS[i]
            try:
                rms[i] = rms_at(dataclasses.replace(camera, fx=camera.fx * k, fy=camera.fy * k))
            except (GnomonError, ValueError, np.linalg.LinAlgError):  # no pose at that focal length
                rms[i] = np.nan
        return float(np.nan_to_num(rms[i], nan=np.inf))

    # every 4th factor, then every one around the best of those (a fit's residual varies smoothly with it)
    coarse = min(range(0, len(FOCAL_FACTORS), 4), key=at)
    for i in range(max(coarse - 3, 0), min(coarse + 4, len(FOCAL_FACTORS))):
        at(i)
    best = int(np.argmin(np.nan_to_num(rms, nan=np.inf)))
    if not np.isfinite(rms[best]):
        return float("nan"), float("nan"), float("nan")
    return float(FOCAL_FACTORS[best]), float(rms[best]), float(rms_at(camera))


#: What a plane's marker warning says when its marks fit another focal length better (the scan's shadow check,
#: gnomon.reconstruct.corners.focal_blame_doubt, looks for it).
FOCAL_BLAME = "the camera's calibration does not fit these frames"


def _focal_clause(camera: OpenCVCamera, factor: float, best_rms: float, here: float, limit_rms_px: float,
                  alone_tells: bool, others: dict[str, float] | Callable[[], dict[str, float]] | None,
                  marks_off: str) -> str:
    """The clause of :func:`focal_diagnosis` (and of marks taken as a rectangle) from a plane's best factor.
    ``alone_tells``: the plane's own points can tell a focal length from a misplaced mark (more than the
    parameters they fix)."""
    if not np.isfinite(factor):
        return ""
    if best_rms <= limit_rms_px and best_rms < 0.25 * here and abs(factor - 1.0) > 0.02:
        others = others() if callable(others) else others  # asked for only here
        agree = {n: k for n, k in (others or {}).items() if abs(k / factor - 1.0) < FOCAL_AGREEMENT}
        fits = f"they fit to {best_rms:.1f} px rms with the focal length × {factor:.2f}"
        if alone_tells or agree or not others:
            caveat = ("" if alone_tells or agree else " (or a mark is off: 4 points cannot tell)")
            also = (" as do " + ", ".join(f"{n}'s (× {k:.2f})" for n, k in agree.items())) if agree else ""
            return (f"; {fits}{also} ({camera.fx * factor:.0f} px instead of {camera.fx:.0f}): {FOCAL_BLAME} "
                    f"(zoom, focus or crop changed since){caveat}")
        told = ", ".join(f"{n} × {k:.2f}" for n, k in others.items())
        return (f"; {fits}, but the other planes' marks do not agree on it ({told} alone): the marks are off, "
                "not the camera")
    if best_rms > 0.5 * here:
        return f"; no focal length fits them better than {best_rms:.1f} px rms (× {factor:.2f}): {marks_off}"
    return ""


@dataclass(frozen=True)
class FocalFit:
    """The focal length that best fits the planes' marked points (:func:`fit_focal`).

    ``factor`` scales the camera's ``fx`` and ``fy`` (principal point,
    aspect and distortion kept); ``sigma_factor`` is its 1-σ from the
    curvature of the χ² at the points' σ (NaN when flat). Per plane, in
    ``planes`` order: the residuals (px rms) at the camera's focal length and
    at the fitted one, and the factor that fits that plane alone best (of
    :data:`FOCAL_FACTORS`), so a plane whose points no focal length fits
    shows as such rather than moving the estimate silently.
    """

    factor: float
    sigma_factor: float
    focal_px: float  # the camera's fx times factor
    camera_focal_px: float
    planes: tuple[str, ...]
    rms_camera_px: tuple[float, ...]
    rms_fit_px: tuple[float, ...]
    alone_factor: tuple[float, ...]
    alone_rms_px: tuple[float, ...]

    def lines(self) -> list[str]:
        out = [f"focal length {self.focal_px:.0f} px = × {self.factor:.3f} ± {self.sigma_factor:.3f} (1 σ) the "
               f"camera's {self.camera_focal_px:.0f} px (principal point, aspect and distortion kept)"]
        for k, name in enumerate(self.planes):
            out.append(f"  {name}: marks fit to {self.rms_camera_px[k]:.2f} px rms at the camera's focal length, "
                       f"{self.rms_fit_px[k]:.2f} px at the fitted one; alone, best × {self.alone_factor[k]:.2f} "
                       f"({self.alone_rms_px[k]:.2f} px)")
        return out


def _pose_chi2(camera: OpenCVCamera, factor: float, points: np.ndarray | None, pixels: np.ndarray,
               sigma_px: np.ndarray) -> tuple[float, float]:
    """(χ², rms px) of one plane's points fitted with the focal length scaled by ``factor`` (inf: no pose);
    ``points`` None: marks nobody measured, fitted as a rectangle's corners."""
    scaled = dataclasses.replace(camera, fx=camera.fx * factor, fy=camera.fy * factor)
    try:
        pp = (fit_plane_pose(scaled, points, pixels) if points is not None
              else fit_rectangle_pose(scaled, pixels, sigma_px))
    except (GnomonError, ValueError):
        return np.inf, np.inf
    lengths = np.linalg.norm(pp.residuals_px, axis=1)
    return float(np.sum((lengths / sigma_px) ** 2)), float(pp.rms_px)


def fit_focal(camera: OpenCVCamera, planes: list[tuple[str, np.ndarray | None, np.ndarray, np.ndarray]]) -> FocalFit:
    """The focal length that best explains several planes' marked points, each plane with its own pose.

    ``planes``: (name, points (N, 2) plane or (N, 3) coplanar world
    coordinates, or None for marks nobody measured (a rectangle's corners:
    one right angle constrains the focal length), pixels (N, 2), σ px (N,))
    with N ≥ 4. Each plane's points
    fix its pose and, beyond it, constrain the focal length (Zhang's two
    constraints per plane view; here with the principal point, the aspect
    and the distortion of ``camera`` held, so one unknown): the factor
    minimising the summed χ² over the planes is searched on
    :data:`FOCAL_FACTORS` then refined (bounded scalar search in log scale).
    For a camera whose zoom, focus or crop changed since its calibration
    (:func:`focal_diagnosis` says so); the fit reports each plane alone so
    that inconsistent marks are seen, not averaged in.
    """
    from scipy.optimize import minimize_scalar

    if not planes:
        raise ValueError("fit_focal needs at least one plane")

    def chi2(factor: float) -> float:
        return float(sum(_pose_chi2(camera, factor, pts, pix, sig)[0] for _, pts, pix, sig in planes))

    grid = np.array([chi2(k) for k in FOCAL_FACTORS])
    if not np.isfinite(grid).any():
        raise GnomonError("no focal length between × 0.5 and × 2 gives a pose for these planes' points")
    best = int(np.argmin(grid))
    lo = np.log(FOCAL_FACTORS[max(best - 1, 0)])
    hi = np.log(FOCAL_FACTORS[min(best + 1, len(FOCAL_FACTORS) - 1)])
    found = minimize_scalar(lambda x: chi2(float(np.exp(x))), bounds=(lo, hi), method="bounded",
                            options={"xatol": 1e-6})
    factor = float(np.exp(found.x)) if found.fun <= grid[best] else float(FOCAL_FACTORS[best])
    h = 1e-3 * factor
    curvature = (chi2(factor + h) - 2.0 * chi2(factor) + chi2(factor - h)) / h**2
    sigma = float(np.sqrt(2.0 / curvature)) if curvature > 0 else float("nan")
    at_camera, at_fit, alone, alone_rms = [], [], [], []
    for _, pts, pix, sig in planes:
        at_camera.append(_pose_chi2(camera, 1.0, pts, pix, sig)[1])
        at_fit.append(_pose_chi2(camera, factor, pts, pix, sig)[1])
        own = np.array([_pose_chi2(camera, k, pts, pix, sig)[0] for k in FOCAL_FACTORS])
        j = int(np.argmin(own))
        alone.append(float(FOCAL_FACTORS[j]))
        alone_rms.append(_pose_chi2(camera, float(FOCAL_FACTORS[j]), pts, pix, sig)[1])
    return FocalFit(factor, sigma, camera.fx * factor, camera.fx, tuple(p[0] for p in planes), tuple(at_camera),
                    tuple(at_fit), tuple(alone), tuple(alone_rms))


def marked_points(log: FieldLog, source: FrameSource) -> list[tuple[str, np.ndarray | None, np.ndarray, np.ndarray]]:
    """Every plane with markers: (name, its markers' world coordinates (N, 3) or None when nobody measured
    them, their pixels as found or given (N, 2), their σ px (N,)), measured on the plane's image or the
    first frame, not checked."""
    return [(plane.name, None, pp.pixels, _rectangle_sigmas(plane, pp)) if plane.unmeasured_marks
            else (plane.name, plane.marker_world(), pp.pixels, _marker_sigmas(plane, len(pp.pixels)))
            for plane, pp in _measure_planes(log, source) if plane.markers]


def _marker_sigmas(plane: PlaneSpec, n: int) -> np.ndarray:
    """The localisation σ (px) of each of a plane's ``n`` fitted points."""
    if plane.markers and len(plane.markers) == n:
        return np.array([CLICKED_SIGMA_PX if m.exact else MARKER_SIGMA_PX for m in plane.markers])
    return np.full(n, MARKER_SIGMA_PX)


def check_plane_markers(log: FieldLog, plane: PlaneSpec, pp: PlanePose, declared: Pose | None,
                        others: Callable[[], dict[str, float]] | None = None) -> str | None:
    """Whether a plane's markers fit one plane: a warning (returned) when their residuals fail a χ² test
    at the markers' localisation σ (p = :data:`MARKER_CHECK_P`); a :class:`FieldLogError` naming the
    plane and its worst marker when the plane they give would be meaningless (tilted more than
    :data:`MAX_PLANE_TILT_DEG` from the declared plane, or that uncertain on its own)."""
    n = len(pp.pixels)
    dof = 2 * n - 6
    if dof <= 0:
        return None
    sigmas = _marker_sigmas(plane, n)
    lengths = np.linalg.norm(pp.residuals_px, axis=1)
    statistic = float(np.sum((lengths / sigmas) ** 2))
    limit = chi2_isf(MARKER_CHECK_P, dof)
    # the culprit: with a declared pose, the marker farthest from where the declared plane puts it
    # (a swapped pair fits a wrong plane with every residual alike); else the largest residual
    offsets = lengths
    if declared is not None and plane.markers and len(plane.markers) == n and plane.image is None:
        predicted = log.camera.project(declared.world_to_camera(plane.marker_world()))
        offsets = np.nan_to_num(np.linalg.norm(pp.pixels - predicted, axis=1), nan=np.inf)
    worst = int(np.argmax(offsets))
    worst_name = pp.names[worst].removeprefix(f"{plane.name} ") if worst < len(pp.names) else f"point {worst}"
    tilt = (_angle_deg(declared.R @ plane.normal, pp.normal_cam) if declared is not None
            else float(pp.std_normal_deg))
    residuals = f"residuals {pp.rms_px:.1f} px rms, {lengths.max():.1f} px at most"
    expected = float(np.sqrt(np.mean(sigmas**2) * limit / (2 * n)))
    failing = statistic > limit or (np.isfinite(tilt) and tilt > MAX_PLANE_TILT_DEG)
    why = focal_diagnosis(log.camera, plane.marker_world(), pp.pixels, expected, others) if (
        failing and plane.markers and len(plane.markers) == n) else ""
    if np.isfinite(tilt) and tilt > MAX_PLANE_TILT_DEG:
        what = (f"the plane through its markers is {tilt:.0f}° from the declared one" if declared is not None
                else f"the plane through its markers is uncertain by {tilt:.0f}° (1 σ)")
        near = (f" ({offsets[worst]:.1f} px from where the declared plane puts it)"
                if declared is not None and offsets is not lengths else "")
        raise FieldLogError(f"{log.path}: [[planes]] {plane.name}: {worst_name}{near} does not fit: {what} "
                            f"({residuals}{why}); check its pixel_hint and id")
    if statistic > limit:
        return (f"{log.path}: [[planes]] {plane.name}: its markers do not fit one plane ({residuals}, worst "
                f"{worst_name}; a correct plane leaves at most {expected:.1f} px rms with markers found to "
                f"{MARKER_SIGMA_PX:g} px and clicked to {CLICKED_SIGMA_PX:g} px); the plane is {tilt:.1f}° "
                + ("from the declared one" if declared is not None else "uncertain (1 σ)")
                + f"{why}; check the markers' pixel_hint and id")
    return None


#: A plane from marks nobody measured whose 1-σ tilt moves it, across its marks, by more than this share
#: of its distance from the camera is worth a warning: the scan's own depth error on the simulated
#: captures is 0.04–0.1 % of the distance.
MAX_PLANE_DEPTH_SHARE = 0.001


def _rectangle_sigmas(plane: PlaneSpec, pp: PlanePose) -> np.ndarray:
    """Each mark's σ (px) against the rectangle: its localisation and its placement off a rectangle."""
    located = pp.located_px if pp.located_px is not None else np.full(len(pp.pixels), MARKER_SIGMA_PX)
    return np.hypot(located, plane.off_rectangle_px)


def _tilt_share(pp: PlanePose) -> float:
    """How far the plane's 1-σ tilt moves it across its marks, as a share of its distance from the camera."""
    assert pp.marks_xy is not None
    reach = float(np.max(np.linalg.norm(pp.marks_xy - pp.marks_xy.mean(axis=0), axis=1)))
    return float(np.tan(np.radians(pp.std_normal_deg)) * reach / pp.offset_cam)


def check_rectangle_marks(log: FieldLog, plane: PlaneSpec, pp: PlanePose,
                          others: Callable[[], dict[str, float]] | None = None) -> str | None:
    """Whether marks nobody measured are a rectangle's corners, and how well they fix their plane.

    A warning (returned) when their residuals fail a χ² test (p = :data:`MARKER_CHECK_P`, 1 degree of
    freedom: the rectangle's right angle) at their σ (localisation and ``off_rectangle_px``): it names the
    mark farthest off and its residual, and blames the camera's focal length only when another plane's
    marks agree on the factor (:func:`_focal_clause`); or when the plane's 1-σ tilt moves it by more than
    :data:`MAX_PLANE_DEPTH_SHARE` of its distance across its marks. A :class:`FieldLogError` when the
    plane's normal is uncertain by more than :data:`MAX_PLANE_TILT_DEG`.
    """
    sigmas = _rectangle_sigmas(plane, pp)
    corners = list(pp.corners)
    lengths = np.linalg.norm(pp.residuals_px, axis=1)
    statistic = float(np.sum((lengths[corners] / sigmas[corners]) ** 2))
    dof = 2 * len(corners) - 7
    limit = chi2_isf(MARKER_CHECK_P, dof)
    worst = corners[int(np.argmax(lengths[corners] / sigmas[corners]))]
    worst_name = pp.names[worst].removeprefix(f"{plane.name} ")
    where = f"{log.path}: [[planes]] {plane.name}"
    tilt = float(pp.std_normal_deg)
    share = _tilt_share(pp)
    placed = f"off_rectangle_px = {plane.off_rectangle_px:g}"
    advice = ("measure the marks' positions (plane_xy), or place them on a rectangle (a ruler and a square) and "
              "lower off_rectangle_px, or give this plane a chessboard")
    residuals = (f"residuals {pp.rms_px:.1f} px rms, {worst_name} {lengths[worst]:.1f} px off; 4 marks cannot "
                 "tell which corner is off")
    expected = float(np.sqrt(np.mean(sigmas[corners] ** 2) * limit / (2 * len(corners))))
    uncertain = not np.isfinite(tilt) or tilt > MAX_PLANE_TILT_DEG
    why = ""
    if statistic > limit and isinstance(log.camera, OpenCVCamera):  # the marks misfit: is the camera at fault?
        factor, best_rms, here = best_focal_factor(
            log.camera, lambda cam: fit_rectangle_pose(cam, pp.pixels, sigmas).rms_px)
        why = _focal_clause(log.camera, factor, best_rms, here, expected, False, others,
                            "the marks are not a rectangle's corners")
    if "calibration does not fit" in why:
        advice = ("calibrate the camera as it was set for the capture, or fit its focal length to the planes' "
                  f"marks with `gnomon calibrate focal {log.path.name}`")
    if uncertain:
        raise FieldLogError(f"{where}: its {len(pp.pixels)} marks taken as a rectangle's corners leave its normal "
                            f"uncertain by {tilt:.1f}° (1 σ, marks within {placed} px of a rectangle; {residuals})"
                            f"{why}: no reference plane; {advice}")
    if statistic > limit:
        return (f"{where}: its marks are not a rectangle's corners ({residuals}; marks within {placed} px of a "
                f"rectangle leave at most {expected:.1f} px rms){why}; the plane's normal is uncertain by "
                f"{tilt:.2f}° (1 σ); {advice}")
    if share > MAX_PLANE_DEPTH_SHARE:
        return (f"{where}: its {len(pp.pixels)} marks taken as a rectangle's corners (none measured) leave its "
                f"normal uncertain by {tilt:.2f}° (1 σ, marks within {placed} px of a rectangle): across its marks "
                f"that moves the plane by {100 * share:.2f} % of its distance, and the depths with it; {advice}")
    return None


def alone_focal_factor(log: FieldLog, plane: PlaneSpec, pp: PlanePose) -> float:
    """The focal factor (of :data:`FOCAL_FACTORS`) that fits one marked plane's marks best on its own
    (NaN for another camera model or a plane without marks)."""
    if not isinstance(log.camera, OpenCVCamera) or not plane.markers or len(plane.markers) != len(pp.pixels):
        return float("nan")
    if plane.unmeasured_marks:
        sigmas = _rectangle_sigmas(plane, pp)
        return best_focal_factor(log.camera, lambda cam: fit_rectangle_pose(cam, pp.pixels, sigmas).rms_px)[0]
    return best_focal_factor(log.camera, lambda cam: fit_plane_pose(cam, plane.marker_world(), pp.pixels).rms_px)[0]


def _at_distance(pp: PlanePose, point: np.ndarray, k: float) -> PlanePose:
    """A plane moved along the camera's rays, its distance times ``k``: the pose keeps its rotation and
    carries the plane's world ``point`` to ``k`` times where it was in the camera frame."""
    R, t = pp.pose.R, pp.pose.t
    return dataclasses.replace(
        pp, pose=Pose(R=R, t=k * (R @ point + t) - R @ point), offset_cam=pp.offset_cam * k,
        std_offset=pp.std_offset * k, marks_xy=None if pp.marks_xy is None else pp.marks_xy * k,
        rectangle=None if pp.rectangle is None else (pp.rectangle[0] * k, pp.rectangle[1] * k))


def provisional_distance(camera: CameraModel, first: PlanePose, pp: PlanePose) -> float:
    """A first guess of the distance of a plane whose marks fix only its orientation: where its line
    with the ``first`` plane passes half-way between their nearest marks in the image (the corner between
    a desk and a wall lies between the desk's marks and the wall's). The shadow measures it after tracking
    (:func:`gnomon.geometry.plane_tie.tie_by_corner`)."""
    gaps = np.linalg.norm(first.pixels[:, None, :] - pp.pixels[None, :, :], axis=2)
    i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
    ray = camera.rays(0.5 * (first.pixels[i] + pp.pixels[j])[None])[0]
    a, b = float(first.normal_cam @ ray), float(pp.normal_cam @ ray)
    if not (a > 1e-9 and b > 1e-9):
        return float(first.offset_cam)
    return float(first.offset_cam / a * b)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two unit normals, ignoring their sense."""
    return float(np.degrees(np.arccos(min(1.0, abs(float(a @ b))))))


def resolve_reference_planes(log: FieldLog, source: FrameSource) -> tuple[FieldLog, list[dict[str, Any]]]:
    """Measure the planes that carry markers or a chessboard, each from its own.

    A plane's markers are known in its own 2-D frame (``plane_xy``, placed in
    3-D by the plane's ``point``, ``normal`` and ``x_axis``), so finding them
    in the image gives that frame's pose in the camera; a chessboard gives its
    own frame's pose. The photo is the plane's ``image`` or the capture's
    first frame. Without a ``[camera.pose]`` the first such plane's frame is
    the world frame and every other measured plane is placed in it from its
    own pose (its declared ``point``/``normal`` then only define its own
    frame); no relative pose needs typing. With a ``[camera.pose]`` the planes
    check it (residuals and the angle between measured and declared planes go
    into report.json).
    """
    measured = _measure_planes(log, source)
    if not measured:
        return log, []
    declared = log.pose is not None
    # marks nobody measured fix a plane's orientation, not its distance: a first guess until the shadow
    # ties it to the first plane (the world frame) where they meet
    provisional = set()
    for k, (plane, pp) in enumerate(measured):
        if k > 0 and plane.unmeasured_marks and plane.mark_distance is None:
            guess = provisional_distance(log.camera, measured[0][1], pp)
            measured[k] = (plane, _at_distance(pp, plane.point, guess / pp.offset_cam))
            provisional.add(plane.name)
    pose = log.pose if log.pose is not None else measured[0][1].pose
    report: list[dict[str, Any]] = []
    placed = {}
    factors: dict[str, float] = {}

    def others(name: str) -> dict[str, float]:  # the other marked planes' focal factors, each alone
        for plane, pp in measured:  # (each computed once, and only when another plane asks for it)
            if plane.name != name and plane.name not in factors and plane.markers:
                factors[plane.name] = alone_focal_factor(log, plane, pp)
        return {n: k for n, k in factors.items() if n != name and np.isfinite(k)}

    for plane, pp in measured:
        entry = {"plane": plane.name, **pp.to_report(), "pixels": pp.pixels.tolist()}
        if plane.unmeasured_marks:
            entry["distance"] = ("provisional" if plane.name in provisional
                                 else "mark_distance" if plane.mark_distance is not None else "unit")
            entry["off_rectangle_px"] = plane.off_rectangle_px
        try:
            theirs = functools.partial(others, plane.name)
            if plane.unmeasured_marks:
                warning = check_rectangle_marks(log, plane, pp, theirs)
            else:
                warning = check_plane_markers(log, plane, pp, log.pose, theirs)
        except FieldLogError as exc:  # the planes measured before it may say why (e.g. the camera does not fit)
            earlier = [e["marker_warning"].removeprefix(f"{log.path}: ") for e in report if "marker_warning" in e]
            if not earlier:
                raise
            raise FieldLogError(f"{exc} (and {'; '.join(earlier)})") from None
        if warning is not None:
            entry["warnings"] = [*entry["warnings"], warning]
            entry["marker_warning"] = warning
        if declared:
            entry["angle_to_declared_deg"] = _angle_deg(pose.R @ plane.normal, pp.normal_cam)
        else:
            # The plane in the world frame, from its own pose: its frame's origin and normal.
            origin_cam = pp.pose.world_to_camera(plane.point)
            normal_cam = pp.pose.R @ plane.normal
            placed[plane.name] = (pose.camera_to_world(origin_cam), pose.R.T @ normal_cam,
                                  None if plane.x_axis is None else pose.R.T @ (pp.pose.R @ plane.x_axis))
            entry["world_point"] = placed[plane.name][0].tolist()
            entry["world_normal"] = placed[plane.name][1].tolist()
        report.append(entry)
    if not declared:
        planes = []
        for p in log.planes:
            if p.name in placed and _measured(p):
                point, normal, x_axis = placed[p.name]
                p = dataclasses.replace(p, point=point, normal=normal / np.linalg.norm(normal), x_axis=x_axis)
            planes.append(p)
        log = dataclasses.replace(log, pose=pose, planes=tuple(planes))
        check_geometry(log, pose)
        if len(measured) >= 2:
            report[1]["angle_to_first_deg"] = _angle_deg(measured[0][1].normal_cam, measured[1][1].normal_cam)
    return log, report


def plane_region_mask(plane: PlaneSpec, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the union of a plane's rectangles, polygons and mask image (read here, at the edge)."""
    mask = None
    if plane.mask_file is not None:
        mask = cv2.imread(str(plane.mask_file), cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise FieldLogError(f"{plane.mask_file}: not a readable image (plane {plane.name!r} mask)")
        if mask.shape != tuple(shape):
            raise FieldLogError(f"{plane.mask_file}: mask is {mask.shape[1]}x{mask.shape[0]}, "
                                f"the frames {shape[1]}x{shape[0]} (plane {plane.name!r})")
    return region_mask(shape, plane.regions, plane.polygons, mask)
