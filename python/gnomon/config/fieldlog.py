"""The field log: one TOML file that describes one capture.

The contract (sections, keys, units) is documented in ``field_logs/README.md``.
Every path inside a field log is relative to the file. Unknown keys and
missing required keys raise :class:`FieldLogError` naming the file and the key;
the CLI prints that as one line and exits with code 2.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.camera.models import CalibratedCamera, Pose
from gnomon.capture.frames import ON_CORRUPT, VIDEO_SUFFIXES, glob_frames, image_size, video_size
from gnomon.capture.registration import REGISTER_MODES
from gnomon.config.lights import LightSections, light_kind
from gnomon.config.plausibility import check_field_log
from gnomon.config.specs import (
    EDGES,
    UNITS,
    ArucoSpec,
    CaptureSpec,
    CharucoSpec,
    EdgeSpec,
    FieldLog,
    GnomonSpec,
    LightSpec,
    MarkerSpec,
    OutputSpec,
    PlaneSpec,
    PoleSpec,
    ScanSettings,
    SiteSpec,
)
from gnomon.config.tables import Table, boolean
from gnomon.errors import FieldLogError
from gnomon.light import TIMESTAMP_MODES
from gnomon.outputs.crs import ALTITUDE_DATUMS, GEOIDS
from gnomon.outputs.formats import DEFAULT_MESH_FORMATS, formats_of_kind, names_of
from gnomon.util import toml_io


def _parse_capture(t: Table, base: Path) -> CaptureSpec:
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
    on_corrupt = t.string("on_corrupt_frame", "error", ON_CORRUPT)
    register = t.string("register", "auto", REGISTER_MODES)
    if timestamps == "filename" and time_pattern is None:
        raise FieldLogError(f"{t.path}: [capture] timestamps = 'filename' needs 'time_pattern'")
    if timestamps == "start+fps" and (start is None or fps is None):
        raise FieldLogError(f"{t.path}: [capture] timestamps = 'start+fps' needs 'start' and 'fps'")
    t.done()

    def spec(files: tuple[Path, ...], video: Path | None) -> CaptureSpec:
        return CaptureSpec(pattern, files, video, units, gamma, frame_count, timestamps=timestamps,
                           time_pattern=time_pattern, start=start, fps=fps, on_corrupt_frame=on_corrupt,
                           register=register)

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


def parse_camera(t: Table, base: Path) -> tuple[CalibratedCamera, Pose | None, Path | None, dict, str | None]:
    """[camera]: a camera file (``file = ...``) or inline keys (OpenCV or Tsai model), [camera.pose], and
    ``crop`` (``"centre"``: the frames are the calibrated image's centred crop, see
    :func:`gnomon.camera.calibration.fit_camera_to_frames`)."""
    from gnomon.camera.calibration import CROPS, camera_from_table, load_calibration_info, load_camera_file

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
    from gnomon.camera.calibration import fit_camera_to_frames, other_aspect

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


def _parse_plane(t: Table, index: int, width: int, height: int) -> PlaneSpec:
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
            rt = Table(t.path, f"{t.name}.regions", r)
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
    markers: list[MarkerSpec] = []
    raw_markers = t.take("markers", [])
    if not isinstance(raw_markers, list):
        raise t.error("markers", "expected a list of { id, plane_xy = [x, y], pixel_hint = [u, v] } tables")
    for k, m in enumerate(raw_markers):
        mt = Table(t.path, f"{t.name}.markers.{k}", m)
        mid = mt.integer("id", k)
        xy = mt.vector("plane_xy", 2) if "plane_xy" in mt.data else None
        if markers and (xy is None) != (markers[0].plane_xy is None):
            raise mt.error("plane_xy", "give it for every mark of the plane or for none (marks nobody measured: "
                                       "the corners of a rectangle of unknown size)")
        if ("pixel" in mt.data) == ("pixel_hint" in mt.data):
            raise mt.error("pixel", "give either 'pixel_hint' (a printed checker marker, refined) or 'pixel' "
                                    "(an exact pixel, e.g. a clicked cross)")
        exact = "pixel" in mt.data
        markers.append(MarkerSpec(mid, xy, mt.vector("pixel" if exact else "pixel_hint", 2), exact))
        mt.done()
    unmeasured = bool(markers) and markers[0].plane_xy is None
    if markers and x_axis is None:
        if not unmeasured:
            raise FieldLogError(f"{t.path}: [{t.name}] markers need 'x_axis' (the plane's 2-D frame)")
        x_axis = _any_axis_across(normal)  # the fitted frame's x in the world: any axis across the normal
    if markers and len(markers) < 4:
        raise t.error("markers", f"a plane from markers needs at least 4, got {len(markers)}")
    ids = [m.id for m in markers]
    if len(set(ids)) != len(ids):
        raise t.error("markers", f"mark ids must differ, got {ids}")
    mark_distance = None
    if "mark_distance" in t.data:
        if not unmeasured:
            raise t.error("mark_distance", "is for marks without plane_xy (their plane_xy already give every "
                                           "distance)")
        spacing = t.subtable("mark_distance")
        assert spacing is not None
        between = spacing.take("between")
        if not (isinstance(between, list) and len(between) == 2 and all(b in ids for b in between)
                and between[0] != between[1]):
            raise spacing.error("between", f"expected two of this plane's mark ids {ids}, got {between!r}")
        mark_distance = (int(between[0]), int(between[1]), spacing.number("length", positive=True))
        spacing.done()
    off_rectangle_px = 1.0
    if "off_rectangle_px" in t.data:
        if not unmeasured:
            raise t.error("off_rectangle_px", "is for marks without plane_xy (taken as a rectangle's corners)")
        off_rectangle_px = t.number("off_rectangle_px")
        if off_rectangle_px < 0:
            raise t.error("off_rectangle_px", f"must be ≥ 0 px, got {off_rectangle_px:g}")
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
                     tuple(polygons), mask_file, aruco, charuco, mark_distance, off_rectangle_px)


def _any_axis_across(normal: np.ndarray) -> np.ndarray:
    """A unit vector across ``normal`` (unit): world x, or y when the normal is near x."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    axis = helper - (helper @ normal) * normal
    return axis / np.linalg.norm(axis)


def _dictionary_name(t: Table) -> str:
    import cv2

    name = t.string("dictionary", "DICT_4X4_50")
    if not name.upper().startswith("DICT_") or not hasattr(cv2.aruco, name.upper()):
        raise t.error("dictionary", f"unknown ArUco dictionary {name!r} (e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250)")
    return name.upper()


def _parse_aruco(t: Table | None) -> ArucoSpec:
    assert t is not None
    dictionary = _dictionary_name(t)
    size = t.number("size", positive=True)
    raw = t.take("markers")
    if not isinstance(raw, list) or len(raw) < 2:
        raise t.error("markers", "expected a list of at least 2 { id = N, plane_xy = [x, y] } tables")
    markers, seen = [], set()
    for k, m in enumerate(raw):
        mt = Table(t.path, f"{t.name}.markers.{k}", m)
        mid = mt.integer("id", minimum=0)
        if mid in seen:
            raise mt.error("id", f"ArUco id {mid} is listed twice on this plane")
        seen.add(mid)
        xy = mt.vector("plane_xy", 2)
        mt.done()
        markers.append((mid, (float(xy[0]), float(xy[1]))))
    t.done()
    return ArucoSpec(dictionary, float(size), tuple(markers))


def _parse_charuco(t: Table | None) -> CharucoSpec:
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


def _parse_site(t: Table | None) -> SiteSpec | None:
    if t is None:
        return None
    opt = lambda key, fn: fn(key) if key in t.data else None  # noqa: E731
    latitude, longitude, altitude = t.number("latitude"), t.number("longitude"), t.number("altitude", 0.0)
    timezone = opt("timezone", t.string)
    pressure = opt("pressure_pa", lambda k: t.number(k, positive=True))
    temperature = opt("temperature_c", t.number)
    heading = opt("heading_deg", t.number)
    north = t.string("heading_north", "true", ("true", "magnetic"))
    declination = opt("declination_deg", t.number)
    if north == "magnetic":
        if declination is None:
            raise t.error("declination_deg", "missing: a heading from magnetic north needs the site's magnetic "
                                              "declination (degrees, east positive; e.g. from NOAA's calculator)")
        if heading is not None:
            heading = (heading + declination) % 360.0  # from true north, as the scan uses it
    elif declination is not None:
        raise t.error("declination_deg", "is for heading_north = \"magnetic\" (heading_deg is from true north)")
    site = SiteSpec(
        latitude_deg=latitude,
        longitude_deg=longitude,
        altitude_m=altitude,
        timezone=timezone,
        pressure_pa=pressure,
        temperature_c=temperature,
        heading_deg=heading,
        altitude_datum=t.string("altitude_datum", "orthometric", ALTITUDE_DATUMS),
        geoid=t.string("geoid", "EGM2008", tuple(GEOIDS)),
        heading_north=north,
        declination_deg=declination,
        position_sigma_m=opt("position_sigma_m", lambda k: t.number(k, positive=True)),
        heading_sigma_deg=opt("heading_sigma_deg", lambda k: t.number(k, positive=True)),
    )
    if not -90.0 <= site.latitude_deg <= 90.0:
        raise t.error("latitude", f"{site.latitude_deg} is outside ±90°")
    if not -180.0 <= site.longitude_deg <= 360.0:
        raise t.error("longitude", f"{site.longitude_deg} is outside ±180°")
    t.done()
    return site


def _parse_pole(t: Table | None) -> PoleSpec | None:
    if t is None:
        return None
    pole = PoleSpec(t.vector("base", 3), t.vector("top", 3), t.number("radius", 0.0))
    if np.linalg.norm(pole.top - pole.base) <= 0:
        raise t.error("top", "must differ from base")
    t.done()
    return pole


def _parse_edge(t: Table | None) -> EdgeSpec | None:
    """[edge]: ``a``, ``b`` (the edge's ends; neither: found from the shadow's lines on the reference planes) and
    optionally ``body`` (a point of the occluder off the edge)."""
    if t is None:
        return None
    body = t.vector("body", 3) if "body" in t.data else None
    if "a" not in t.data and "b" not in t.data:  # found from the shadow's lines on the reference planes
        t.done()
        return EdgeSpec(None, None, body)
    a, b = t.vector("a", 3), t.vector("b", 3)
    length = float(np.linalg.norm(b - a))
    if length <= 0:
        raise t.error("b", "must differ from a")
    if body is not None and np.linalg.norm(np.cross(b - a, body - a)) <= 1e-6 * length * length:
        raise t.error("body", "lies on the edge's line; give a point of the occluder away from the edge")
    t.done()
    return EdgeSpec(a, b, body)


def _parse_gnomon(t: Table | None) -> GnomonSpec | None:
    if t is None:
        return None
    g = GnomonSpec(t.string("frame"), t.vector("base_px", 2), t.vector("shadow_px", 2))
    t.take("top_px", None)  # informational: the pole's top, often outside the image
    t.done()
    return g


def _parse_scan(t: Table | None) -> ScanSettings:
    if t is None:
        return ScanSettings()
    s = ScanSettings(
        min_contrast=t.number("min_contrast", positive=True) if "min_contrast" in t.data else None,
        window=t.integer("window", 4, minimum=1),
        edge=t.string("edge", "both", EDGES),
        max_depth_jump=t.number("max_depth_jump", 0.02, positive=True),
        normalize_illumination=boolean(t, "normalize_illumination", False),
        max_dip_frames=None if t.data.get("max_dip_frames", "auto") == "auto" else t.integer("max_dip_frames"),
    )
    t.take("max_dip_frames", None)  # "auto"
    t.done()
    return s


def _parse_output(t: Table | None, planes: tuple[PlaneSpec, ...]) -> OutputSpec:
    if t is None:
        return OutputSpec()
    formats = _formats_key(t, "mesh_formats", "mesh") or DEFAULT_MESH_FORMATS
    clouds = _formats_key(t, "cloud_formats", "cloud")
    crs = None
    if "crs" in t.data:
        crs = t.string("crs")
        _check_crs(t, crs)
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
    return OutputSpec(box, above, low, high, formats, max_sigma, clouds, crs)


def _formats_key(t: Table, key: str, kind: str) -> tuple[str, ...] | None:
    """[output] mesh_formats / cloud_formats: the registry's formats of ``kind`` it names (None: absent)."""
    if key not in t.data:
        return None
    raw = t.take(key)
    chosen = formats_of_kind(raw, kind)
    if chosen is None:
        raise t.error(key, f"expected \"all\" or a list of {', '.join(map(repr, names_of(kind)))}, got {raw!r}")
    return chosen


def _check_crs(t: Table, crs: str) -> None:
    """[output] crs: a coordinate reference system pyproj knows, with a horizontal part in length units."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        parsed = CRS.from_user_input(crs)
    except CRSError as exc:
        raise t.error("crs", f"{crs!r} is not a coordinate reference system pyproj knows ({exc})") from None
    if parsed.is_vertical and not parsed.is_compound:
        raise t.error("crs", f"{crs!r} is a vertical CRS only; give a projected one (e.g. EPSG:2056)")


def load_field_log(path: str | Path, *, without_light: bool = False) -> FieldLog:
    """Read and validate a field log. Raises :class:`FieldLogError` on any problem.

    ``without_light``: the ``[light]`` table is optional and not read (a lamp with no position: for
    ``gnomon calibrate lamp``, which measures the position the table will hold)."""
    p = Path(path)
    if not p.exists():
        raise FieldLogError(f"{p}: field log not found")
    root = Table(p, "field log", toml_io.load(p))
    base = p.resolve().parent

    def optional_section(name: str) -> Table | None:
        return Table(p, name, root.data.pop(name)) if name in root.data else None

    def section(name: str) -> Table:
        table = optional_section(name)
        if table is None:
            raise FieldLogError(f"{p}: missing required table [{name}]")
        return table

    capture = _parse_capture(section("capture"), base)
    camera, pose, camera_file, calibration, crop = parse_camera(section("camera"), base)
    camera, calibration = _fit_camera(camera, calibration, capture, f"{p}: [camera]", crop)
    raw_planes = root.data.pop("planes", None)
    if not isinstance(raw_planes, list) or not raw_planes:
        raise FieldLogError(f"{p}: missing required [[planes]] (at least one reference plane)")
    planes = tuple(
        _parse_plane(Table(p, f"planes.{i}", d), i, camera.width, camera.height) for i, d in enumerate(raw_planes)
    )
    if without_light:
        root.data.pop("light", None)
        light, kind = LightSpec("lamp"), None
    else:
        light_table = section("light")
        kind = light_kind(light_table)
        light = kind.parse(light_table, base)
    scan = _parse_scan(optional_section("scan"))
    site = _parse_site(optional_section("site"))
    pole = _parse_pole(optional_section("pole"))
    edge = _parse_edge(optional_section("edge"))
    if edge is not None and pole is not None:
        raise FieldLogError(f"{p}: [edge] and [pole] both given: a sun scan follows one occluder's shadow; "
                            "remove one of the two tables")
    if edge is not None and not without_light and light.kind != "sun":
        raise FieldLogError(f"{p}: [edge] needs [light] kind = 'sun' (the edge's shadow planes contain the sun's "
                            f"direction), got {light.kind!r}")
    gnomon = _parse_gnomon(optional_section("gnomon"))
    output = _parse_output(optional_section("output"), planes)
    if kind is not None:  # what the light needs beside its own table ([site] for the sun, two planes, …)
        kind.check(LightSections(p, capture, planes, site, gnomon))
    # Sections read by other commands (`gnomon calibrate lamp` reads [pencil]).
    root.data.pop("pencil", None)
    root.done()

    if pose is None and not any(pl.markers or pl.chessboard or pl.aruco or pl.charuco for pl in planes):
        raise FieldLogError(
            f"{p}: missing required table [camera.pose] (the world → camera transform), "
            "or markers or a chessboard on a [[planes]] entry to measure it"
        )
    log = FieldLog(p, capture, camera, pose, planes, light, scan, camera_file, calibration, site, pole, gnomon,
                   output, edge)
    if pose is not None:
        check_geometry(log, pose)
    check_field_log(log)  # plausible numbers and geometry (gnomon.config.plausibility)
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
            board = (f"; a chessboard's z points towards the camera (up from the {plane.name}): a lamp.toml "
                     "written when it pointed into the desk needs `gnomon calibrate lamp` again"
                     if plane.chessboard is not None else "")
            raise FieldLogError(
                f"{log.path}: [light] position {log.light.position.tolist()} is below the plane "
                f"'{plane.name}' (not on the camera's side): the surface the camera sees would be unlit{board}"
            )
