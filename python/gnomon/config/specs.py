"""The field log as parsed: plain, frozen values in the world frame and the field log's units.

:func:`gnomon.config.fieldlog.load_field_log` returns a :class:`FieldLog`; each section of the file
(``field_logs/README.md``) is one dataclass here. Nothing in them reads a file: what the values mean
for a scan is resolved once, at the edge (:mod:`gnomon.config.setup`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gnomon.camera.models import CalibratedCamera, Pose

LENGTH_UNITS = ("mm", "m")
UNITS = (*LENGTH_UNITS, "relative")
#: ``[capture] units = "relative"``: no length is known; the unit is the first plane's distance from the
#: camera's centre (that plane's marks nobody measured set the world frame).
RELATIVE = "relative"


EDGES = ("enter", "leave", "both")


@dataclass(frozen=True)
class CaptureSpec:
    """Where the frames are. ``frames`` is a sorted list of image files, or one video."""

    pattern: str
    image_files: tuple[Path, ...] = ()
    video: Path | None = None
    units: str = "mm"
    gamma: float | str = "srgb"
    frame_count: int | None = None
    timestamps: str | None = None  # "filename" | "exif" | "start+fps"
    time_pattern: str | None = None
    start: str | None = None
    fps: float | None = None
    on_corrupt_frame: str = "error"  # "error" | "drop": gnomon.capture.frames.ON_CORRUPT
    register: str = "auto"  # "auto" | "on" | "off": frame registration (gnomon.capture.registration)


@dataclass(frozen=True)
class MarkerSpec:
    """A marker: its centre on the plane and its pixel.

    A printed 2×2 checker marker is given by a rough ``pixel_hint`` that the
    scan refines (``exact`` False); any other mark (a hand-drawn cross) by
    its exact ``pixel``, used as given (``exact`` True). ``plane_xy`` None:
    nobody measured where it is (the plane's marks are then a rectangle's
    corners of unknown size, :func:`gnomon.camera.plane_pose.fit_rectangle_pose`).
    """

    id: int
    plane_xy: np.ndarray | None  # (2,) in the plane's own 2-D frame, world units; None: not measured
    pixel_hint: np.ndarray  # (2,) pixels
    exact: bool = False


@dataclass(frozen=True)
class ArucoSpec:
    """ArUco markers printed on a plane (``[planes.aruco]``): found by their IDs, no pixels.

    ``dictionary``: OpenCV's predefined dictionary name; ``size``: a marker's
    side, black border included (world units); ``markers``: (id, (a, b)) the
    centres in the plane's 2-D frame. Orientation: see :mod:`gnomon.camera.aruco`.
    """

    dictionary: str
    size: float
    markers: tuple[tuple[int, tuple[float, float]], ...]


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board lying on a plane (``[planes.charuco]``).

    ``squares``: (cols, rows) squares; ``square``, ``marker``: their sides
    (world units); ``origin``: the board's top-left corner in the plane's 2-D
    frame (its x along the plane's x, its rows down along −y; see :mod:`gnomon.camera.aruco`).
    """

    dictionary: str
    squares: tuple[int, int]
    square: float
    marker: float
    origin: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class PlaneSpec:
    """A reference plane in world coordinates, with the image regions where it is bare.

    The plane's own 2-D frame (for markers): origin ``point``, axes ``x_axis``
    and ``normal × x_axis``.
    """

    name: str
    point: np.ndarray
    normal: np.ndarray  # unit
    regions: tuple[tuple[int, int, int, int], ...]
    x_axis: np.ndarray | None = None
    markers: tuple[MarkerSpec, ...] = ()
    chessboard: tuple[int, int] | None = None  # inner corners (cols, rows) of a board lying on the plane
    square: float | None = None  # the board's square, world units
    image: Path | None = None  # the photo with the markers or board (default: the first frame)
    polygons: tuple[np.ndarray, ...] = ()  # (K, 2) pixel vertices each
    mask_file: Path | None = None  # an image: non-zero where the plane is bare and swept
    aruco: ArucoSpec | None = None  # ArUco markers on the plane (found by ID)
    charuco: CharucoSpec | None = None  # a ChArUco board on the plane
    # marks nobody measured (no plane_xy): a known length between two of them (ids, world units) ...
    mark_distance: tuple[int, int, float] | None = None
    # ... and how far (px, 1 σ per axis) they may lie off a true rectangle's corners
    off_rectangle_px: float = 1.0

    @property
    def unmeasured_marks(self) -> bool:
        """Marks without ``plane_xy``: a rectangle of unknown size (its orientation, not its distance)."""
        return bool(self.markers) and self.markers[0].plane_xy is None

    @property
    def has_regions(self) -> bool:
        return bool(self.regions or self.polygons or self.mask_file is not None)

    def plane_to_world(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) coordinates in the plane's 2-D frame → (N, 3) world coordinates (needs ``x_axis``)."""
        assert self.x_axis is not None
        y_axis = np.cross(self.normal, self.x_axis)
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return self.point + xy[:, :1] * self.x_axis + xy[:, 1:] * y_axis

    def marker_world(self) -> np.ndarray:
        """(N, 3) world coordinates of the markers' centres (measured marks only)."""
        assert self.x_axis is not None and not self.unmeasured_marks
        y_axis = np.cross(self.normal, self.x_axis)
        xy = np.array([m.plane_xy for m in self.markers]).reshape(-1, 2)
        return self.point + xy[:, :1] * self.x_axis + xy[:, 1:] * y_axis


@dataclass(frozen=True)
class LightSpec:
    kind: str
    position: np.ndarray | None = None  # lamp centre, world units


@dataclass(frozen=True)
class ScanSettings:
    min_contrast: float | None = None  # DN of the input; None: MIN_CONTRAST_SIGMAS × the measured image noise
    window: int = 4
    edge: str = "both"
    max_depth_jump: float = 0.02
    normalize_illumination: bool = False
    max_dip_frames: int | None = None  # the widest dip (frames); None: "auto", widened as the capture needs


# The mesh's file formats: mesh.ply is always written (load_scan, merge and the recording's readers
# take it); mesh.obj (+ .mtl, .png) and mesh.stl on request (`[output] mesh_formats`, `--mesh-formats`).
@dataclass(frozen=True)
class OutputSpec:
    """[output]: what the written outputs keep (world frame, world units).

    ``crop_box`` (2, 3) min and max corners of an axis-aligned box;
    ``crop_above`` a plane name with ``crop_min_height`` (and optionally
    ``crop_max_height``): heights above that plane, on the camera's side.
    ``mesh_formats`` the mesh's files: ``ply`` (always), ``obj`` (with its
    ``.mtl`` and ``.png`` texture), ``stl`` (:func:`mesh_formats`).
    ``max_sigma`` the largest predicted depth σ (world units) a kept point may have.
    ``cloud_formats`` the cloud's survey files, ``las`` and ``laz`` (None: LAZ for a georeferenced
    scan, none for a desk scan); ``crs`` their coordinate reference system, anything pyproj reads
    (None: the site's UTM zone; georeferenced scans only).
    """

    crop_box: np.ndarray | None = None
    crop_above: str | None = None
    crop_min_height: float = 0.0
    crop_max_height: float | None = None
    mesh_formats: tuple[str, ...] = ("ply",)  # the mesh's files (gnomon.outputs.formats); mesh.ply always
    max_sigma: float | None = None
    cloud_formats: tuple[str, ...] | None = None
    crs: str | None = None

    @property
    def crops(self) -> bool:
        return self.crop_box is not None or self.crop_above is not None or self.max_sigma is not None


@dataclass(frozen=True)
class SiteSpec:
    """[site]: where a sun capture happens, and how the world frame sits in East-North-Up."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float = 0.0
    timezone: str | None = None
    pressure_pa: float | None = None
    temperature_c: float | None = None
    heading_deg: float | None = None  # heading of the world x axis from true north, clockwise (world z up)
    altitude_datum: str = "orthometric"  # altitude above the geoid ("orthometric") or the WGS 84 ellipsoid
    geoid: str = "EGM2008"  # the geoid an orthometric altitude is above (gnomon.outputs.crs.GEOIDS)
    heading_north: str = "true"  # [site] heading_deg was given from true north, or from magnetic north
    declination_deg: float | None = None  # magnetic declination (east positive), with heading_north = "magnetic"
    position_sigma_m: float | None = None  # how well the site's position is known, m (1σ): gnomon fuse's stations
    heading_sigma_deg: float | None = None  # how well heading_deg is known, degrees (1σ)


@dataclass(frozen=True)
class PoleSpec:
    """[pole]: a vertical occluder of known geometry (world coordinates)."""

    base: np.ndarray
    top: np.ndarray
    radius: float = 0.0


@dataclass(frozen=True)
class EdgeSpec:
    """[edge]: a straight occluding edge whose shadow the sun sweeps (a roof line; world coordinates, the
    capture's units): its ends ``a`` and ``b`` (None: found from the shadow's lines on the reference planes), and
    optionally ``body``, a point of the occluder away from the edge (the side its shadow falls on)."""

    a: np.ndarray | None
    b: np.ndarray | None
    body: np.ndarray | None = None


@dataclass(frozen=True)
class GnomonSpec:
    """[gnomon]: a vertical pole seen in one frame, to find the world frame's heading."""

    frame: str
    base_px: np.ndarray
    shadow_px: np.ndarray


@dataclass(frozen=True)
class FieldLog:
    path: Path
    capture: CaptureSpec
    camera: CalibratedCamera  # OpenCVCamera or TsaiCamera
    pose: Pose | None  # None: measured from the planes' markers by the scan
    planes: tuple[PlaneSpec, ...]
    light: LightSpec
    scan: ScanSettings
    camera_file: Path | None = None
    calibration: dict = field(default_factory=dict)
    site: SiteSpec | None = None
    pole: PoleSpec | None = None
    gnomon: GnomonSpec | None = None
    output: OutputSpec = field(default_factory=OutputSpec)
    edge: EdgeSpec | None = None
