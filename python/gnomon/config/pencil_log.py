"""The pencil log: the field log of ``gnomon calibrate lamp`` (photos of a standing pencil).

The same ``[camera]`` (with ``[camera.pose]``) and ``[[planes]]`` tables as a
scan's field log (see ``field_logs/README.md``; a plane's ``regions`` are
optional here and ignored), or, without ``[camera.pose]``, a scan's
``[capture]`` and planes with markers or a chessboard (optionally in their own
``image``): the pose is then measured from them as a scan measures it, the
first such plane's frame being the world's (the paper's set-up: a board on
the desk photographed from the scan's place), plus::

    [pencil]
    height = 80.0          # pencil height, world units (required, > 0)
    sigma_px = 0.3         # 1σ of each clicked pixel coordinate (default 0.3)
    sigma_height = 0.0     # 1σ of the height, world units (default 0)
    plane = "desk"         # the [[planes]] name it stands on (default: the first plane)
    units = "mm"           # world units, "mm" or "m" (default: [capture] units, else "mm")
    empty = "empty.jpg"    # optional: the desk without the pencil (same camera and lamp)
    gamma = 2.2            # the photos' encoding (default: [capture] gamma, else "srgb")
    photos = [             # ≥ 2 photos; pixels, centre of the top-left pixel = (0, 0)
        { base = [412.3, 310.8], tip = [301.0, 355.2], image = "pencil1.jpg" },
        { base = [220.5, 280.1], image = "pencil2.jpg" },   # tip found against `empty`
    ]

``image`` is informational when both pixels are given. A photo without
``tip`` needs its ``image`` and ``[pencil] empty`` (or, without it, at least
3 photos with their ``image``: their per-pixel median is the empty desk): the
shadow's tip is then found by comparing the two photos' irradiance, and the
base (a hint, a few pixels off at most) is moved onto the shadow's axis
(:mod:`gnomon.light.pencil_detection`). A photo without ``base`` either (its
``image`` alone) has its pencil found too: its own image and its shadow, two
arms meeting at the foot, the pencil's arm predicted from the foot, the
desk's pose and ``height``. ``[capture]``, ``[light]``,
``[scan]`` and ``[site]`` tables are ignored, so a scan's own field log may
carry the ``[pencil]`` table; any other table is an error. The result is
written to ``lamp.toml`` beside the field log: a ``[light]`` table
(``kind = "lamp"``, ``position``) ready to paste into a scan's field log, and a
``[lamp_calibration]`` table with the covariance, 1σ per axis, residuals, χ²
and warnings.
"""


from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.camera.models import CameraModel, Pose
from gnomon.config.fieldlog import parse_camera
from gnomon.config.specs import LENGTH_UNITS
from gnomon.config.tables import Table
from gnomon.errors import FieldLogError
from gnomon.util import toml_io

MEDIAN_PHOTOS = 3
"""Without ``[pencil] empty``, this many photos (or more) stand for the empty desk: their median."""


@dataclass(frozen=True)
class PencilLog:
    """A parsed lamp-calibration field log (see the module docstring)."""

    path: Path
    camera: CameraModel
    pose: Pose
    plane_name: str
    plane_point: np.ndarray
    plane_normal: np.ndarray
    height: float
    sigma_px: float
    sigma_height: float
    units: str
    bases_px: np.ndarray  # NaN rows: found with the tip (from the pencil's image and shadow)
    tips_px: np.ndarray  # NaN rows: to be found against the empty-desk photo
    images: tuple[str | None, ...]
    empty: Path | None = None  # photo of the desk without the pencil
    gamma: float | str = "srgb"  # the photos' encoding, to compare irradiance


# Tables of a scan's field log that a lamp calibration does not read.
_IGNORED_SECTIONS = ("capture", "light", "scan", "site")


# What measures a plane in a scan's field log (gnomon.config.setup.resolve_reference_planes).
_MARK_KEYS = ("markers", "chessboard", "square", "image", "x_axis", "aruco", "charuco", "mark_distance",
              "off_rectangle_px")


def _pose_from_marked_planes(path: Path, data: dict[str, Any]
                             ) -> tuple[Any, Pose, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Without ``[camera.pose]``: the field log at ``path`` (``data``: its tables, as read) read as a scan's
    and its planes measured from their own markers or board (the first one's frame is the world's). Returns
    the camera (fitted to the frames), the pose and each plane's point and unit normal in that world."""
    from gnomon.config.fieldlog import load_field_log
    from gnomon.config.setup import frame_source, resolve_reference_planes

    marked = [pl for pl in data.get("planes", []) if isinstance(pl, dict) and any(k in pl for k in _MARK_KEYS)]
    if "capture" not in data or not marked:
        raise FieldLogError(f"{path}: missing required table [camera.pose] (the world → camera transform), or a "
                            "[capture] and a plane with markers or a chessboard to measure it from")
    log = load_field_log(path, without_light=True)
    log, _ = resolve_reference_planes(log, frame_source(log))
    assert log.pose is not None  # a marked plane was measured
    planes = {pl.name: (np.asarray(pl.point, float), np.asarray(pl.normal, float) / np.linalg.norm(pl.normal))
              for pl in log.planes}
    return log.camera, log.pose, planes


def load_pencil_log(path: str | Path) -> PencilLog:
    """Read ``[camera]``, ``[camera.pose]``, ``[[planes]]`` and ``[pencil]``; errors name file and key.

    Without ``[camera.pose]`` the pose comes from the planes' own markers or chessboard, measured as a scan
    of the same field log measures them (it then needs its ``[capture]``): the paper's set-up, a board on
    the desk photographed from the scan's place."""
    p = Path(path)
    if not p.is_file():
        raise FieldLogError(f"{p}: field log not found")
    root = Table(p, "field log", toml_io.load(p))
    base = p.resolve().parent

    if "camera" not in root.data:
        raise FieldLogError(f"{p}: missing required table [camera]")
    camera, pose, _, _, _ = parse_camera(Table(p, "camera", root.data.pop("camera")), base)
    measured: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
    if pose is None:
        # no pose typed: the planes' own markers or board place the camera, as in a scan of this field log
        camera, pose, measured = _pose_from_marked_planes(p, root.data)

    raw_planes = root.data.pop("planes", None)
    if not isinstance(raw_planes, list) or not raw_planes:
        raise FieldLogError(f"{p}: missing required [[planes]] (the plane the pencil stands on)")
    planes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for i, raw in enumerate(raw_planes):
        t = Table(p, f"planes.{i}", raw)
        name = t.string("name", f"plane{i}")
        point = t.vector("point", 3, [0.0, 0.0, 0.0])
        normal = t.vector("normal", 3, [0.0, 0.0, 1.0])
        if np.linalg.norm(normal) < 1e-12:
            raise t.error("normal", "must not be the zero vector")
        for key in ("regions", "mask") + (_MARK_KEYS if measured is not None else ()):
            t.take(key, None)  # the scan's bare regions, and what measured the plane: not needed here
        t.done()
        planes.setdefault(name, measured[name] if measured is not None and name in measured
                          else (point, normal / np.linalg.norm(normal)))

    capture_units = None
    capture = root.data.get("capture")
    if isinstance(capture, dict) and capture.get("units") in LENGTH_UNITS:
        capture_units = capture["units"]
    for name in _IGNORED_SECTIONS:
        root.data.pop(name, None)

    if "pencil" not in root.data:
        raise FieldLogError(f"{p}: missing required table [pencil] (the pencil photos)")
    t = Table(p, "pencil", root.data.pop("pencil"))
    height = t.number("height", positive=True)
    sigma_px = t.number("sigma_px", 0.3)
    if sigma_px < 0:
        raise t.error("sigma_px", f"must be ≥ 0, got {sigma_px:g}")
    sigma_height = t.number("sigma_height", 0.0)
    if sigma_height < 0:
        raise t.error("sigma_height", f"must be ≥ 0, got {sigma_height:g}")
    plane_name = t.string("plane", next(iter(planes)))
    if plane_name not in planes:
        raise t.error("plane", f"no [[planes]] entry is named {plane_name!r} (have: {', '.join(map(repr, planes))})")
    units = t.string("units", capture_units or "mm", LENGTH_UNITS)
    empty = base / t.string("empty") if "empty" in t.data else None
    if empty is not None and not empty.is_file():
        raise t.error("empty", f"{empty} not found")
    gamma: float | str = "srgb"
    if isinstance(capture, dict) and isinstance(capture.get("gamma"), (int, float, str)):
        gamma = capture["gamma"]
    if "gamma" in t.data:
        gamma = t.take("gamma")
    if not (gamma == "srgb" or (isinstance(gamma, (int, float)) and not isinstance(gamma, bool) and gamma > 0)):
        raise t.error("gamma", f"expected a positive number or 'srgb', got {gamma!r}")
    photos = t.take("photos")
    if not isinstance(photos, list) or not all(isinstance(x, dict) for x in photos):
        raise t.error("photos", "expected a list of { base = [u, v], tip = [u, v] } tables")
    if len(photos) < 2:
        raise t.error("photos", f"the lamp needs at least 2 pencil photos, got {len(photos)}")
    t.done()
    bases: list[np.ndarray] = []
    tips: list[np.ndarray] = []
    images: list[str | None] = []
    w, h = camera.width, camera.height
    for i, raw in enumerate(photos):
        pt = Table(p, f"pencil.photos.{i}", raw)
        image = pt.string("image") if "image" in pt.data else None
        for key, out in (("base", bases), ("tip", tips)):
            if key == "base" and "base" not in pt.data and "tip" in pt.data:
                raise pt.error("base", "missing: a photo with its tip given needs its base too (leave both "
                                       "out to have them found)")
            if key not in pt.data:
                # found automatically: needs this photo and the empty desk (or the photos' median)
                median = len(photos) >= MEDIAN_PHOTOS and all(isinstance(x.get("image"), str) for x in photos)
                if image is None or (empty is None and not median):
                    raise pt.error(key, f"missing: give the {key}'s pixel, or the photo's 'image' and "
                                          "[pencil] 'empty' (a photo of the desk without the pencil; or at "
                                          f"least {MEDIAN_PHOTOS} photos, each with its 'image')")
                out.append(np.array([np.nan, np.nan]))
                continue
            uv = pt.vector(key, 2)
            if not (-0.5 <= uv[0] <= w - 0.5 and -0.5 <= uv[1] <= h - 0.5):
                raise pt.error(key, f"pixel {uv.tolist()} is outside the {w}x{h} image")
            out.append(uv)
        images.append(image)
        pt.done()
    root.done()
    point, normal = planes[plane_name]
    return PencilLog(
        p, camera, pose, plane_name, point, normal, height, sigma_px, sigma_height, units,
        np.array(bases), np.array(tips), tuple(images), empty, gamma,
    )
