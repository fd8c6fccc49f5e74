"""The field log: one TOML file that describes one capture.

The contract (sections, keys, units) is documented in ``field_logs/README.md``.
Every path inside a field log is relative to the file. Unknown keys and
missing required keys raise :class:`FieldLogError` naming the file and the key;
the CLI prints that as one line and exits with code 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gnomon import toml_io
from gnomon.camera import CalibratedCamera, Pose
from gnomon.errors import FieldLogError
from gnomon.frames import glob_frames, image_size, video_size
from gnomon.validate import check_field_log

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm")
UNITS = ("mm", "m")
EDGES = ("enter", "leave", "both")
LIGHT_KINDS = ("lamp", "two-plane", "sun")
TIMESTAMP_MODES = ("filename", "exif", "start+fps")  # how each frame's time is known (gnomon.timestamps)


class _Table:
    """A TOML table being read: takes keys one by one, then rejects leftovers."""

    def __init__(self, path: Path, name: str, data: Any):
        if not isinstance(data, dict):
            raise FieldLogError(f"{path}: [{name}] must be a table")
        self.path, self.name, self.data = path, name, dict(data)

    def where(self, key: str) -> str:
        return f"{self.path}: [{self.name}] {key}"

    def error(self, key: str, message: str) -> FieldLogError:
        return FieldLogError(f"{self.where(key)}: {message}")

    def take(self, key: str, default: Any = ...) -> Any:
        """Pop ``key``; without a default the key is required."""
        if key in self.data:
            return self.data.pop(key)
        if default is ...:
            raise FieldLogError(f"{self.path}: [{self.name}] missing required key '{key}'")
        return default

    def number(self, key: str, default: Any = ..., *, positive: bool = False) -> float:
        v = self.take(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.error(key, f"expected a finite number, got {v!r}")
        if positive and v <= 0:
            raise self.error(key, f"must be > 0, got {v!r}")
        return float(v)

    def integer(self, key: str, default: Any = ..., *, minimum: int | None = None) -> int:
        v = self.take(key, default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(key, f"expected an integer, got {v!r}")
        if minimum is not None and v < minimum:
            raise self.error(key, f"must be ≥ {minimum}, got {v}")
        return int(v)

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        v = self.take(key, default)
        if not isinstance(v, str):
            raise self.error(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(key, f"expected one of {', '.join(map(repr, choices))}, got {v!r}")
        return v

    def vector(self, key: str, n: int, default: Any = ...) -> np.ndarray:
        v = self.take(key, default)
        ok = isinstance(v, (list, tuple)) and len(v) == n
        ok = ok and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        if not ok or not all(math.isfinite(x) for x in v):
            raise self.error(key, f"expected {n} finite numbers, got {v!r}")
        return np.asarray(v, dtype=np.float64)

    def subtable(self, key: str, *, required: bool = False) -> _Table | None:
        if key not in self.data:
            if required:
                raise FieldLogError(f"{self.path}: missing required table [{self.name}.{key}]")
            return None
        return _Table(self.path, f"{self.name}.{key}", self.data.pop(key))

    def done(self) -> None:
        if self.data:
            key = sorted(self.data)[0]
            raise FieldLogError(f"{self.path}: [{self.name}] unknown key '{key}'")


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


@dataclass(frozen=True)
class MarkerSpec:
    """A marker: its centre on the plane and its pixel.

    A printed 2×2 checker marker is given by a rough ``pixel_hint`` that the
    scan refines (``exact`` False); any other mark (a hand-drawn cross) by
    its exact ``pixel``, used as given (``exact`` True).
    """

    id: int
    plane_xy: np.ndarray  # (2,) in the plane's own 2-D frame, world units
    pixel_hint: np.ndarray  # (2,) pixels
    exact: bool = False


@dataclass(frozen=True)
class ArucoSpec:
    """ArUco markers printed on a plane (``[planes.aruco]``): found by their IDs, no pixels.

    ``dictionary``: OpenCV's predefined dictionary name; ``size``: a marker's
    side, black border included (world units); ``markers``: (id, (a, b)) the
    centres in the plane's 2-D frame. Orientation: see :mod:`gnomon.aruco`.
    """

    dictionary: str
    size: float
    markers: tuple[tuple[int, tuple[float, float]], ...]


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board lying on a plane (``[planes.charuco]``).

    ``squares``: (cols, rows) squares; ``square``, ``marker``: their sides
    (world units); ``origin``: the board's top-left corner in the plane's 2-D
    frame (its x along the plane's x, its rows down along −y; see :mod:`gnomon.aruco`).
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

    @property
    def has_regions(self) -> bool:
        return bool(self.regions or self.polygons or self.mask_file is not None)

    def region_mask(self, shape: tuple[int, int]) -> np.ndarray:
        """(H, W) bool: the union of the plane's rectangles, polygons and mask image."""
        from gnomon.reference_lines import region_mask

        mask = None
        if self.mask_file is not None:
            import cv2

            mask = cv2.imread(str(self.mask_file), cv2.IMREAD_GRAYSCALE)
            if mask is None:
                raise FieldLogError(f"{self.mask_file}: not a readable image (plane {self.name!r} mask)")
            if mask.shape != tuple(shape):
                raise FieldLogError(f"{self.mask_file}: mask is {mask.shape[1]}x{mask.shape[0]}, "
                                    f"the frames {shape[1]}x{shape[0]} (plane {self.name!r})")
        return region_mask(shape, self.regions, self.polygons, mask)

    def plane_to_world(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) coordinates in the plane's 2-D frame → (N, 3) world coordinates (needs ``x_axis``)."""
        assert self.x_axis is not None
        y_axis = np.cross(self.normal, self.x_axis)
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return self.point + xy[:, :1] * self.x_axis + xy[:, 1:] * y_axis

    def marker_world(self) -> np.ndarray:
        """(N, 3) world coordinates of the markers' centres."""
        assert self.x_axis is not None
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
MESH_FORMATS = ("ply", "obj", "stl")
DEFAULT_MESH_FORMATS = ("ply",)


def mesh_formats(value: object) -> tuple[str, ...] | None:
    """The mesh formats a value asks for (``"all"``, a list of names, or names joined by commas),
    ``mesh.ply`` always among them, in :data:`MESH_FORMATS` order; None if it names no known format."""
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        return None
    wanted = {n.strip().lower() for n in names} - {""}
    if wanted == {"all"}:
        return MESH_FORMATS
    if not wanted <= set(MESH_FORMATS):
        return None
    return tuple(f for f in MESH_FORMATS if f in wanted or f == "ply")


@dataclass(frozen=True)
class OutputSpec:
    """[output]: what the written outputs keep (world frame, world units).

    ``crop_box`` (2, 3) min and max corners of an axis-aligned box;
    ``crop_above`` a plane name with ``crop_min_height`` (and optionally
    ``crop_max_height``): heights above that plane, on the camera's side.
    ``mesh_formats`` the mesh's files: ``ply`` (always), ``obj`` (with its
    ``.mtl`` and ``.png`` texture), ``stl`` (:func:`mesh_formats`).
    ``max_sigma`` the largest predicted depth σ (world units) a kept point may have.
    """

    crop_box: np.ndarray | None = None
    crop_above: str | None = None
    crop_min_height: float = 0.0
    crop_max_height: float | None = None
    mesh_formats: tuple[str, ...] = ("ply",)  # the mesh's files (MESH_FORMATS); mesh.ply always
    max_sigma: float | None = None

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
    heading_deg: float | None = None  # compass heading of the world x axis (world z up)


@dataclass(frozen=True)
class PoleSpec:
    """[pole]: a vertical occluder of known geometry (world coordinates)."""

    base: np.ndarray
    top: np.ndarray
    radius: float = 0.0


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


def _parse_capture(t: _Table, base: Path) -> CaptureSpec:
    pattern = t.string("frames")
    units = t.string("units", "mm", UNITS)
    gamma_raw = t.take("gamma", "srgb")
    if isinstance(gamma_raw, str):
        if gamma_raw != "srgb":
            raise t.error("gamma", f"expected a number or 'srgb', got {gamma_raw!r}")
        gamma: float | str = "srgb"
    elif isinstance(gamma_raw, (int, float)) and not isinstance(gamma_raw, bool) and gamma_raw > 0:
        gamma = float(gamma_raw)
    else:
        raise t.error("gamma", f"expected a positive number or 'srgb', got {gamma_raw!r}")
    frame_count = t.integer("frame_count", minimum=2) if "frame_count" in t.data else None
    timestamps = t.string("timestamps", None, TIMESTAMP_MODES) if "timestamps" in t.data else None
    time_pattern = t.string("time_pattern") if "time_pattern" in t.data else None
    start = t.string("start") if "start" in t.data else None
    fps = t.number("fps", positive=True) if "fps" in t.data else None
    if timestamps == "filename" and time_pattern is None:
        raise FieldLogError(f"{t.path}: [capture] timestamps = 'filename' needs 'time_pattern'")
    if timestamps == "start+fps" and (start is None or fps is None):
        raise FieldLogError(f"{t.path}: [capture] timestamps = 'start+fps' needs 'start' and 'fps'")
    t.done()

    def spec(files: tuple[Path, ...], video: Path | None) -> CaptureSpec:
        return CaptureSpec(pattern, files, video, units, gamma, frame_count, timestamps=timestamps,
                           time_pattern=time_pattern, start=start, fps=fps)

    if not pattern.strip():
        raise t.error("frames", "is empty; give a glob such as 'frames/*.png' or a video file")
    if Path(pattern).is_absolute():  # an absolute glob: search from its root
        base, pattern = Path(Path(pattern).anchor), str(Path(pattern).relative_to(Path(pattern).anchor))
        if not pattern or pattern == ".":
            raise t.error("frames", "names a root folder, not frames")
    if Path(pattern).suffix.lower() in VIDEO_SUFFIXES and not any(c in pattern for c in "*?["):
        video = base / pattern
        if not video.is_file():
            raise FieldLogError(f"{t.where('frames')}: video {video} not found")
        return spec((), video)
    folder = (base / pattern).parent
    if not folder.is_dir():
        raise FieldLogError(f"{t.where('frames')}: frames folder {folder} not found")
    files = glob_frames(base, pattern)
    if not files:
        raise FieldLogError(f"{t.where('frames')}: no files match {pattern!r} in {base}")
    if len(files) < 2:
        raise FieldLogError(f"{t.where('frames')}: only one frame matches {pattern!r}; a scan needs a sequence")
    if frame_count is not None and len(files) != frame_count:
        raise FieldLogError(
            f"{t.where('frames')}: {len(files)} files match {pattern!r}, frame_count says {frame_count}"
        )
    return spec(files, None)


def _parse_camera(t: _Table, base: Path) -> tuple[CalibratedCamera, Pose | None, Path | None, dict, str | None]:
    """[camera]: a camera file (``file = ...``) or inline keys (OpenCV or Tsai model), [camera.pose], and
    ``crop`` (``"centre"``: the frames are the calibrated image's centred crop, see
    :func:`gnomon.calibration.fit_camera_to_frames`)."""
    from gnomon.calibration import CROPS, camera_from_table, load_calibration_info, load_camera_file

    crop = t.string("crop", None, CROPS) if "crop" in t.data else None
    pose_table = t.subtable("pose")
    pose = None
    if pose_table is not None:
        pose = Pose.from_rvec_tvec(pose_table.vector("rvec", 3), pose_table.vector("tvec", 3))
        pose_table.done()
    if "file" in t.data:
        camera_file = base / t.string("file")
        t.done()
        if not camera_file.is_file():
            raise FieldLogError(f"{t.where('file')}: camera file {camera_file} not found")
        return load_camera_file(camera_file), pose, camera_file, load_calibration_info(camera_file), crop
    table = dict(t.data)
    t.data.clear()
    calibration = table.get("calibration", {}) if isinstance(table.get("calibration"), dict) else {}
    return camera_from_table(table, f"{t.path}: [camera]"), pose, None, calibration, crop


def _fit_camera(camera: CalibratedCamera, calibration: dict, capture: CaptureSpec,
                where: str, crop: str | None = None) -> tuple[CalibratedCamera, dict]:
    """The camera rescaled to the frames' size when it was calibrated at another one (same aspect, or with
    ``crop``, their centred crop)."""
    from gnomon.calibration import fit_camera_to_frames, other_aspect

    first = capture.video if capture.video is not None else capture.image_files[0]
    size = video_size(first) if capture.video is not None else image_size(first)
    fitted, note = fit_camera_to_frames(camera, size[0], size[1], where,
                                        frame_name=f"frame 0 ({first.name})", crop=crop)
    if note is None:
        return camera, calibration
    more: dict[str, Any] = {"rescaled_from": [int(camera.width), int(camera.height)]}
    if crop is not None and other_aspect((camera.width, camera.height), size):
        more["crop"] = "centre"
    return fitted, {**calibration, **more}


def _parse_plane(t: _Table, index: int, width: int, height: int) -> PlaneSpec:
    name = t.string("name", f"plane{index}")
    point = t.vector("point", 3, [0.0, 0.0, 0.0])
    normal = t.vector("normal", 3, [0.0, 0.0, 1.0])
    if np.linalg.norm(normal) < 1e-12:
        raise t.error("normal", "must not be the zero vector")
    raw = t.take("regions", [])
    if not isinstance(raw, list):
        raise t.error("regions", "expected a list of [u0, v0, u1, v1] rectangles or { polygon = [[u, v], ...] }")
    regions, polygons = [], []
    for r in raw:
        if isinstance(r, dict):
            rt = _Table(t.path, f"{t.name}.regions", r)
            poly = rt.take("polygon")
            ok = isinstance(poly, list) and len(poly) >= 3 and all(
                isinstance(q, list) and len(q) == 2
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in q)
                for q in poly)
            if not ok:
                raise rt.error("polygon", f"expected at least 3 [u, v] vertices in pixels, got {poly!r}")
            rt.done()
            polygons.append(np.asarray(poly, dtype=np.float64))
            continue
        ok = isinstance(r, list) and len(r) == 4 and all(isinstance(x, int) and not isinstance(x, bool) for x in r)
        if not ok:
            raise t.error("regions", f"each region is [u0, v0, u1, v1] in whole pixels or "
                                     f"{{ polygon = [[u, v], ...] }}, got {r!r}")
        u0, v0, u1, v1 = r
        if not (0 <= u0 < u1 <= width and 0 <= v0 < v1 <= height):
            raise t.error("regions", f"region {r} is empty or outside the {width}x{height} image")
        regions.append((u0, v0, u1, v1))
    mask_file = None
    if "mask" in t.data:
        mask_file = t.path.resolve().parent / t.string("mask")
        if not mask_file.is_file():
            raise t.error("mask", f"{mask_file} not found")
    normal = normal / np.linalg.norm(normal)
    x_axis = None
    if "x_axis" in t.data:
        x_axis = t.vector("x_axis", 3)
        x_axis = x_axis - (x_axis @ normal) * normal
        if np.linalg.norm(x_axis) < 1e-9:
            raise t.error("x_axis", "must not be parallel to the normal")
        x_axis = x_axis / np.linalg.norm(x_axis)
    markers = []
    raw_markers = t.take("markers", [])
    if not isinstance(raw_markers, list):
        raise t.error("markers", "expected a list of { id, plane_xy = [x, y], pixel_hint = [u, v] } tables")
    for k, m in enumerate(raw_markers):
        mt = _Table(t.path, f"{t.name}.markers.{k}", m)
        mid, xy = mt.integer("id", k), mt.vector("plane_xy", 2)
        if ("pixel" in mt.data) == ("pixel_hint" in mt.data):
            raise mt.error("pixel", "give either 'pixel_hint' (a printed checker marker, refined) or 'pixel' "
                                    "(an exact pixel, e.g. a clicked cross)")
        exact = "pixel" in mt.data
        markers.append(MarkerSpec(mid, xy, mt.vector("pixel" if exact else "pixel_hint", 2), exact))
        mt.done()
    if markers and x_axis is None:
        raise FieldLogError(f"{t.path}: [{t.name}] markers need 'x_axis' (the plane's 2-D frame)")
    if markers and len(markers) < 4:
        raise t.error("markers", f"a plane from markers needs at least 4, got {len(markers)}")
    chessboard = square = None
    if "chessboard" in t.data:
        text = t.string("chessboard")
        try:
            cols, rows = (int(x) for x in text.lower().split("x"))
        except ValueError:
            raise t.error("chessboard", f"expected inner corners as 'COLSxROWS', e.g. '9x6', got {text!r}") from None
        chessboard, square = (cols, rows), t.number("square", positive=True)
    image = t.path.resolve().parent / t.string("image") if "image" in t.data else None
    if image is not None and not image.is_file():
        raise t.error("image", f"{image} not found")
    aruco = _parse_aruco(t.subtable("aruco")) if "aruco" in t.data else None
    charuco = _parse_charuco(t.subtable("charuco")) if "charuco" in t.data else None
    if (aruco or charuco) and x_axis is None:
        raise FieldLogError(f"{t.path}: [{t.name}] ArUco markers or a ChArUco board need 'x_axis' (the plane's 2-D "
                            "frame)")
    if sum(bool(x) for x in (markers, chessboard, aruco, charuco)) > 1:
        raise FieldLogError(f"{t.path}: [{t.name}] give one of markers, chessboard, aruco or charuco per plane")
    t.done()
    return PlaneSpec(name, point, normal, tuple(regions), x_axis, tuple(markers), chessboard, square, image,
                     tuple(polygons), mask_file, aruco, charuco)


def _dictionary_name(t: _Table) -> str:
    import cv2

    name = t.string("dictionary", "DICT_4X4_50")
    if not name.upper().startswith("DICT_") or not hasattr(cv2.aruco, name.upper()):
        raise t.error("dictionary", f"unknown ArUco dictionary {name!r} (e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250)")
    return name.upper()


def _parse_aruco(t: _Table | None) -> ArucoSpec:
    assert t is not None
    dictionary = _dictionary_name(t)
    size = t.number("size", positive=True)
    raw = t.take("markers")
    if not isinstance(raw, list) or len(raw) < 2:
        raise t.error("markers", "expected a list of at least 2 { id = N, plane_xy = [x, y] } tables")
    markers, seen = [], set()
    for k, m in enumerate(raw):
        mt = _Table(t.path, f"{t.name}.markers.{k}", m)
        mid = mt.integer("id", minimum=0)
        if mid in seen:
            raise mt.error("id", f"ArUco id {mid} is listed twice on this plane")
        seen.add(mid)
        xy = mt.vector("plane_xy", 2)
        mt.done()
        markers.append((mid, (float(xy[0]), float(xy[1]))))
    t.done()
    return ArucoSpec(dictionary, float(size), tuple(markers))


def _parse_charuco(t: _Table | None) -> CharucoSpec:
    assert t is not None
    dictionary = _dictionary_name(t)
    raw = t.take("squares")
    if not (isinstance(raw, list) and len(raw) == 2
            and all(isinstance(x, int) and not isinstance(x, bool) and x >= 2 for x in raw)):
        raise t.error("squares", f"expected [cols, rows] squares of the board, each >= 2, got {raw!r}")
    square = t.number("square", positive=True)
    marker = t.number("marker", positive=True)
    if not marker < square:
        raise t.error("marker", f"the marker ({marker}) must be smaller than the square ({square})")
    origin = t.vector("origin", 2, [0.0, 0.0])
    t.done()
    return CharucoSpec(dictionary, (int(raw[0]), int(raw[1])), float(square), float(marker),
                       (float(origin[0]), float(origin[1])))


def _parse_light(t: _Table, base: Path) -> LightSpec:
    kind = t.string("kind")
    if kind not in LIGHT_KINDS:
        raise t.error("kind", f"expected one of {', '.join(map(repr, LIGHT_KINDS))}, got {kind!r}")
    position = None
    if kind == "lamp":
        if "file" in t.data:
            # the output of `gnomon calibrate lamp`: its [light] table
            lamp_file = base / t.string("file")
            data = toml_io.load(lamp_file)
            position = _Table(lamp_file, "light", data.get("light", {})).vector("position", 3)
        else:
            position = t.vector("position", 3)
    t.done()
    return LightSpec(kind, position)


def _boolean(t: _Table, key: str, default: bool) -> bool:
    v = t.take(key, default)
    if not isinstance(v, bool):
        raise t.error(key, f"expected true or false, got {v!r}")
    return v


def _parse_site(t: _Table | None) -> SiteSpec | None:
    if t is None:
        return None
    opt = lambda key, fn: fn(key) if key in t.data else None  # noqa: E731
    site = SiteSpec(
        latitude_deg=t.number("latitude"),
        longitude_deg=t.number("longitude"),
        altitude_m=t.number("altitude", 0.0),
        timezone=opt("timezone", t.string),
        pressure_pa=opt("pressure_pa", lambda k: t.number(k, positive=True)),
        temperature_c=opt("temperature_c", t.number),
        heading_deg=opt("heading_deg", t.number),
    )
    if not -90.0 <= site.latitude_deg <= 90.0:
        raise t.error("latitude", f"{site.latitude_deg} is outside ±90°")
    if not -180.0 <= site.longitude_deg <= 360.0:
        raise t.error("longitude", f"{site.longitude_deg} is outside ±180°")
    t.done()
    return site


def _parse_pole(t: _Table | None) -> PoleSpec | None:
    if t is None:
        return None
    pole = PoleSpec(t.vector("base", 3), t.vector("top", 3), t.number("radius", 0.0))
    if np.linalg.norm(pole.top - pole.base) <= 0:
        raise t.error("top", "must differ from base")
    t.done()
    return pole


def _parse_gnomon(t: _Table | None) -> GnomonSpec | None:
    if t is None:
        return None
    g = GnomonSpec(t.string("frame"), t.vector("base_px", 2), t.vector("shadow_px", 2))
    t.take("top_px", None)  # informational: the pole's top, often outside the image
    t.done()
    return g


def _parse_scan(t: _Table | None) -> ScanSettings:
    if t is None:
        return ScanSettings()
    s = ScanSettings(
        min_contrast=t.number("min_contrast", positive=True) if "min_contrast" in t.data else None,
        window=t.integer("window", 4, minimum=1),
        edge=t.string("edge", "both", EDGES),
        max_depth_jump=t.number("max_depth_jump", 0.02, positive=True),
        normalize_illumination=_boolean(t, "normalize_illumination", False),
        max_dip_frames=None if t.data.get("max_dip_frames", "auto") == "auto" else t.integer("max_dip_frames"),
    )
    t.take("max_dip_frames", None)  # "auto"
    t.done()
    return s


def _parse_output(t: _Table | None, planes: tuple[PlaneSpec, ...]) -> OutputSpec:
    if t is None:
        return OutputSpec()
    formats: tuple[str, ...] = DEFAULT_MESH_FORMATS
    if "mesh_formats" in t.data:
        raw = t.take("mesh_formats")
        chosen = mesh_formats(raw)
        if chosen is None:
            raise t.error("mesh_formats", f"expected \"all\" or a list of {', '.join(map(repr, MESH_FORMATS))}, "
                                          f"got {raw!r}")
        formats = chosen
    box = None
    if "crop_box" in t.data:
        raw = t.take("crop_box")
        try:
            box = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError):
            box = None
        if box is None or box.shape != (2, 3) or not np.all(np.isfinite(box)):
            raise t.error("crop_box", f"expected [[xmin, ymin, zmin], [xmax, ymax, zmax]], got {raw!r}")
        if np.any(box[1] <= box[0]):
            raise t.error("crop_box", "each max must exceed its min")
    above = None
    low, high = 0.0, None
    if "crop_above" in t.data:
        names = [pl.name for pl in planes]
        above = t.string("crop_above", None, tuple(names))
        low = t.number("crop_min_height", 0.0)
        high = t.number("crop_max_height") if "crop_max_height" in t.data else None
        if high is not None and high <= low:
            raise t.error("crop_max_height", f"must exceed crop_min_height ({low})")
    elif "crop_min_height" in t.data or "crop_max_height" in t.data:
        raise t.error("crop_above", "crop_min_height/crop_max_height need crop_above (a [[planes]] name)")
    max_sigma = t.number("max_sigma", positive=True) if "max_sigma" in t.data else None
    t.done()
    return OutputSpec(box, above, low, high, formats, max_sigma)


def load_field_log(path: str | Path, *, without_light: bool = False) -> FieldLog:
    """Read and validate a field log. Raises :class:`FieldLogError` on any problem.

    ``without_light``: the ``[light]`` table is optional and not read (a lamp with no position: for
    ``gnomon calibrate lamp``, which measures the position the table will hold)."""
    p = Path(path)
    if not p.exists():
        raise FieldLogError(f"{p}: field log not found")
    root = _Table(p, "field log", toml_io.load(p))
    base = p.resolve().parent

    def optional_section(name: str) -> _Table | None:
        return _Table(p, name, root.data.pop(name)) if name in root.data else None

    def section(name: str) -> _Table:
        table = optional_section(name)
        if table is None:
            raise FieldLogError(f"{p}: missing required table [{name}]")
        return table

    capture = _parse_capture(section("capture"), base)
    camera, pose, camera_file, calibration, crop = _parse_camera(section("camera"), base)
    camera, calibration = _fit_camera(camera, calibration, capture, f"{p}: [camera]", crop)
    raw_planes = root.data.pop("planes", None)
    if not isinstance(raw_planes, list) or not raw_planes:
        raise FieldLogError(f"{p}: missing required [[planes]] (at least one reference plane)")
    planes = tuple(
        _parse_plane(_Table(p, f"planes.{i}", d), i, camera.width, camera.height) for i, d in enumerate(raw_planes)
    )
    if without_light:
        root.data.pop("light", None)
        light = LightSpec("lamp")
    else:
        light = _parse_light(section("light"), base)
    scan = _parse_scan(optional_section("scan"))
    site = _parse_site(optional_section("site"))
    pole = _parse_pole(optional_section("pole"))
    gnomon = _parse_gnomon(optional_section("gnomon"))
    output = _parse_output(optional_section("output"), planes)
    if light.kind == "sun":
        if site is None:
            raise FieldLogError(f"{p}: [light] kind 'sun' needs a [site] table (latitude, longitude, ...)")
        if capture.timestamps is None:
            raise FieldLogError(f"{p}: [capture] a sun scan needs 'timestamps' (filename, exif or start+fps)")
        if site.heading_deg is None and gnomon is None:
            raise FieldLogError(f"{p}: [site] a sun scan needs 'heading_deg', or a [gnomon] table to measure it")
    # Sections read by other commands (`gnomon calibrate lamp` reads [pencil]).
    root.data.pop("pencil", None)
    root.done()
    if light.kind == "two-plane" and len(planes) < 2:
        raise FieldLogError(f"{p}: [light] kind 'two-plane' needs two [[planes]] (e.g. desk and wall)")

    if pose is None and not any(pl.markers or pl.chessboard or pl.aruco or pl.charuco for pl in planes):
        raise FieldLogError(
            f"{p}: missing required table [camera.pose] (the world → camera transform), "
            "or markers or a chessboard on a [[planes]] entry to measure it"
        )
    log = FieldLog(p, capture, camera, pose, planes, light, scan, camera_file, calibration, site, pole, gnomon,
                   output)
    if pose is not None:
        check_geometry(log, pose)
    check_field_log(log)  # plausible numbers and geometry (gnomon.validate)
    return log


def check_geometry(log: FieldLog, pose: Pose) -> None:
    """The camera and the lamp must both be on the visible side of the first plane."""
    plane = log.planes[0]
    cam_side = float(np.dot(pose.camera_centre_world - plane.point, plane.normal))
    if abs(cam_side) < 1e-9:
        raise FieldLogError(f"{log.path}: [camera.pose] puts the camera in the plane '{plane.name}'")
    if log.light.kind == "lamp" and log.light.position is not None:
        lamp_side = float(np.dot(log.light.position - plane.point, plane.normal))
        if lamp_side * cam_side <= 0:
            raise FieldLogError(
                f"{log.path}: [light] position {log.light.position.tolist()} is below the plane "
                f"'{plane.name}' (not on the camera's side): the surface the camera sees would be unlit"
            )
