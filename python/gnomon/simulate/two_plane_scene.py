"""The ``two_plane`` scene: a desk and a wall meeting in a corner, an unknown lamp.

Bouguet & Perona's dual-space set-up (IJCV 1999; docs/method.md §3): the shadow
plane of each frame is the plane through the shadow lines on two known
planes, so the light source need not be known. The simulator knows it (the
ground truth has it), the field log does not.

Scene (world frame = the desk, millimetres, z up out of the desk)
-----------------------------------------------------------------
* the desk, z = 0 (object id 0), with a smooth albedo texture (0.45–0.75,
  sinusoids of 90–300 mm wavelength in desk x, y, phases from the seed);
* the wall, the vertical plane y = ``WALL_Y`` (160 mm) facing the camera
  (object id 4; normal (0, −1, 0)), its own texture of the same kind in wall
  (x, z); desk and wall meet in the corner line y = ``WALL_Y``, z = 0;
* a sphere (id 1, r = 32) and a box (id 2, 70 × 50 × 44, turned 20°) on the
  desk, in front of the wall, below the corner in the image;
* 4 printed 2×2 checker markers on each plane (:data:`MARKERS`): a white
  paper square of side 60 mm (albedo 0.80) carrying a 2×2 checker of side
  40 mm (black 0.06 / white 0.80; black where (a − a0)·(b − b0) > 0, the
  convention of :mod:`gnomon.simulate.marker_images`) whose centre — the
  X-junction — is the marker's position; edges aligned with the plane's 2-D
  axes (below). Drawn here rather than with that module's private texture
  function, which carries its own plane texture and albedos. Their
  albedo is box-filtered over the pixel (4 × 4 sub-samples) before the blur,
  so the X-junction is rendered at sub-pixel precision. Markers sit
  on bare plane outside the field log's regions, away from objects. With
  ``markers = "aruco"`` (``--markers aruco``) each checker is replaced by the
  ArUco marker of id 0–7 (``ARUCO_DICTIONARY``, 40 mm wide border included,
  on the same paper; see :mod:`gnomon.simulate.marker_images` for its
  orientation), and the field log gives each plane's ``[planes.aruco]``:
  dictionary, size and ``markers`` (ids and centres), no pixels;
* a camera 650 mm from ``SCENE_CENTRE`` (on the corner's side of the desk),
  looking 32° down, turned −5° about z, rolled 1°; the same lens, sizes and
  nuisance as ``desk_lamp`` (fx = 900 px at 800 × 600, distortion, blur,
  gamma, noise, JPEG);
* the lamp: a sphere of radius ``lamp_radius`` centred at ``LAMP``
  (−380, −130, 430), left of and in front of the camera, lighting desk and
  wall. **Its position is not in the field log** (``[light] kind =
  "two-plane"``); the ground truth has it.

The stick
---------
As in ``desk_lamp`` (never rendered; ~55 % of the way from the lamp; a smooth
hand-like sweep from beyond the left to beyond the right edge, the first and
last two frames free of shadow), but its pose at each frame is set so that its
central shadow plane passes through a wall point seen on the image's top row
and a desk point seen on its bottom row: **every shadow plane cuts both the
desk and the wall**, and its shadow runs from the bottom of the image up to
the corner and on up the wall to the top. The ground truth's ``cuts_both``
(N,) says, per frame, that both the entering and the leaving plane cut the
desk and the wall inside the image.

Plane coordinates
-----------------
Each ``[[planes]]`` entry of the field log carries ``point`` (the origin),
``normal`` (unit, towards the camera) and ``x_axis`` (a unit vector in the
plane, world coordinates); the second axis is ``y_axis = normal × x_axis``,
so a plane point (a, b) is the world point ``point + a·x_axis + b·y_axis``.
Desk: point (0, 0, 0), normal (0, 0, 1), x_axis (1, 0, 0) → y_axis (0, 1, 0),
plane (a, b) = world (x, y). Wall: point (0, WALL_Y, 0), normal (0, −1, 0),
x_axis (1, 0, 0) → y_axis (0, 0, 1), plane (a, b) = world (x, z).

Markers in the field log: ``markers`` on each plane, a list of
``{ id = k, plane_xy = [a, b], pixel_hint = [u, v] }`` (written as
``[[planes.markers]]`` tables): ids 0–3 on the desk and 4–7 on the wall,
``plane_xy`` exact, ``pixel_hint`` a rough position, 3 to 8 px (uniformly
random length and direction, from the seed) off the marker centre's true
projection, rounded to 0.1 px — so the true centre is always within 8.1 px
of the hint.

Regions: per plane, bands of height 5 % of the image (≥ 6 px) in which every
pixel sees that plane bare (no object, no marker paper within 3 px, no edge
in its blur footprint), lit and swept, 2 % in from the image's sides: the
band farthest from the corner (the desk's lowest, the wall's highest; at
least half the image wide) and, nearest the corner, one band in each half
of the image (each ≥ 35 % of the width; the corner runs slightly across the
image, so two half-width bands follow it more closely) — 3 per plane by
default, at least 1 (an error otherwise).

Ground truth (``ground_truth.npz``)
-----------------------------------
As ``desk_lamp`` (``depth``, ``points_world``, ``object_id`` — 0 desk, 1
sphere, 2 box, 4 wall, −1 none —, ``swept``, ``enter_time``,
``leave_time``, ``shadow_planes_enter`` / ``_leave``, ``K``, ``dist``,
``rvec``, ``tvec``, ``R``, ``t``, ``lamp``, ``image_size``,
``camera_distance_mm``, ``stick_axis``, ``stick_radius``) with ``swept``
further requiring (4) the planes of the frames bracketing both of the
pixel's crossings cut both planes inside the image (``cuts_both``) and (3)
counting printed albedo edges (marker borders) as boundaries; plus
``cuts_both`` (N,), ``wall_y``, ``plane_points`` / ``plane_normals`` /
``plane_x_axes`` (2, 3) in field-log order (desk, wall), and for the markers
(arrays (2, 4, …), plane-major in the same order): ``marker_ids``,
``marker_plane_xy``, ``marker_world``, ``marker_pixels`` (the true
projections of the centres) and ``marker_hints`` (as written in the log);
with ArUco markers also ``marker_corner_pixels`` (2, 4, 4, 2), the true
projections of each marker's corners in OpenCV's order.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gnomon.errors import GnomonError
from gnomon.simulate import geometry as geo
from gnomon.simulate import sensor
from gnomon.simulate.desk_lamp import (
    BOX,
    DESK,
    SPHERE,
    DeskLampScene,
    SimulationResult,
    SweepConfig,
    clear_previous,
    nuisance_text,
    plane_texture,
    prepare_out_dir,
    write_frames,
)
from gnomon.simulate.marker_images import aruco_bits, aruco_class, aruco_corners
from gnomon.util import toml_io

WALL = 4
OBJECT_NAMES = {DESK: "desk", SPHERE: "sphere", BOX: "box", WALL: "wall"}
WALL_Y = 160.0
LAMP = np.array([-380.0, -130.0, 430.0])
SCENE_CENTRE = np.array([0.0, 70.0, 60.0])

SPHERE_SPEC: dict[str, Any] = {"centre": (-105.0, -15.0, 32.0), "radius": 32.0, "albedo": 0.70}
BOX_SPEC: dict[str, Any] = {"centre": (85.0, -20.0, 22.0), "size": (70.0, 50.0, 44.0), "yaw_deg": 20.0,
                            "albedo": 0.60}

# Plane frames (see the module docstring): point, normal, x_axis.
PLANE_FRAMES = {
    DESK: (np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])),
    WALL: (np.array([0.0, WALL_Y, 0.0]), np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0])),
}
PLANE_ORDER = (DESK, WALL)

# Marker centres in plane coordinates, ids 0–3 (desk) and 4–7 (wall).
MARKERS = {
    DESK: ((-190.0, -80.0), (190.0, -80.0), (-215.0, 40.0), (215.0, 40.0)),
    WALL: ((-200.0, 95.0), (200.0, 95.0), (-200.0, 175.0), (200.0, 175.0)),
}
# Marks nobody measured (``marks = "unmeasured"``): the corners of a rectangle on each plane, in order
# around it, before each is moved up to ``marks_off_px`` in the image.
RECTANGLES = {
    DESK: ((-200.0, -80.0), (200.0, -80.0), (200.0, 40.0), (-200.0, 40.0)),
    WALL: ((-200.0, 95.0), (200.0, 95.0), (200.0, 175.0), (-200.0, 175.0)),
}
MARKS = ("measured", "unmeasured")
MAX_MARKS_OFF_PX = 20.0
MARKER_CHECKER = 40.0         # side of the 2×2 checker, mm
MARKER_PAPER = 1.5 * MARKER_CHECKER   # side of the white paper square, mm (as gnomon.simulate.marker_images)
MARKER_WHITE, MARKER_BLACK = 0.80, 0.06
MARKER_SUBSAMPLES = 4         # per pixel side, for the printed albedo
MARKER_KEEP_OUT_PX = 3        # regions stay this far from any marker paper
HINT_OFFSET_PX = (3.0, 8.0)
ARUCO_DICTIONARY = "DICT_4X4_50"
MARKER_KINDS = ("checker", "aruco")
STICK_MOTIONS = ("rocked", "translated")


@dataclass(frozen=True)
class TwoPlaneConfig(SweepConfig):
    """Parameters of ``gnomon simulate two_plane`` (desk_lamp's sweep, plus the kind of markers).

    ``markers``: ``"checker"`` (2×2 checkers, pixel hints in the field log) or
    ``"aruco"`` (ArUco markers of ``ARUCO_DICTIONARY``, ids 0–7, each
    ``MARKER_CHECKER`` wide on the same white paper; the field log gives their
    ids and plane coordinates only, no pixels). ``stick``: ``"rocked"`` (tilted
    by ±``TwoPlaneScene.TILT_WOBBLE_DEG`` as it sweeps, so the shadow planes
    turn about several directions and fix the lamp at a point) or
    ``"translated"`` (moved parallel to itself: every shadow plane contains
    the stick's one direction, and the planes fix the lamp only along the
    line through it in that direction). ``marks``: ``"measured"`` (the field
    log gives each checker's ``plane_xy`` and the camera's pose) or
    ``"unmeasured"`` (the checkers at the corners of a rectangle on each plane,
    :data:`RECTANGLES`, each moved on its plane so that its image moves by a
    random vector of length up to ``marks_off_px`` (uniform in that disc,
    from the seed); the field log gives neither ``plane_xy`` nor the pose, says
    ``off_rectangle_px`` = ``marks_off_px / 2``, the per-axis σ of a uniform
    disc, and has ``units = "relative"``, or with ``mark_distance`` the desk's
    first two marks' true distance in mm).
    """

    markers: str = "checker"
    stick: str = "rocked"
    marks: str = "measured"
    marks_off_px: float = 0.0
    mark_distance: bool = False

    @property
    def scene_name(self) -> str:
        return "two_plane"

    def validate(self) -> None:
        super().validate()
        if self.markers not in MARKER_KINDS:
            raise self.error(f"--markers {self.markers!r}: expected one of {', '.join(MARKER_KINDS)}")
        if self.stick not in STICK_MOTIONS:
            raise self.error(f"--stick {self.stick!r}: expected one of {', '.join(STICK_MOTIONS)}")
        if self.marks not in MARKS:
            raise self.error(f"--marks {self.marks!r}: expected one of {', '.join(MARKS)}")
        if not (0.0 <= self.marks_off_px <= MAX_MARKS_OFF_PX):
            raise self.error(f"--marks-off-px {self.marks_off_px}: must be 0 to {MAX_MARKS_OFF_PX:g} px")
        if self.marks == "unmeasured" and self.markers != "checker":
            raise self.error("--marks unmeasured: with --markers checker (ArUco markers carry their size)")
        if self.marks != "unmeasured" and (self.marks_off_px > 0 or self.mark_distance):
            raise self.error("--marks-off-px and --mark-distance: with --marks unmeasured")


def plane_y_axis(normal, x_axis) -> np.ndarray:
    return np.cross(np.asarray(normal, float), np.asarray(x_axis, float))


def plane_to_world(oid: int, xy) -> np.ndarray:
    point, normal, x_axis = PLANE_FRAMES[oid]
    xy = np.asarray(xy, dtype=np.float64)
    return point + xy[..., :1] * x_axis + xy[..., 1:2] * plane_y_axis(normal, x_axis)


def world_to_plane(oid: int, X) -> np.ndarray:
    point, normal, x_axis = PLANE_FRAMES[oid]
    rel = np.asarray(X, dtype=np.float64) - point
    return np.stack([rel @ x_axis, rel @ plane_y_axis(normal, x_axis)], axis=-1)


def marker_class(ab: np.ndarray) -> np.ndarray:
    """Printed-marker class at plane offsets ab (..., 2) from a marker centre:
    0 outside the paper, 1 white, 2 black (a 2×2 checker, black where a·b > 0)."""
    a, b = ab[..., 0], ab[..., 1]
    hp, hc = MARKER_PAPER / 2.0, MARKER_CHECKER / 2.0
    on_paper = (np.abs(a) < hp) & (np.abs(b) < hp)
    on_checker = (np.abs(a) < hc) & (np.abs(b) < hc)
    black = on_checker & (a * b > 0)
    return np.where(black, 2, np.where(on_paper, 1, 0)).astype(np.int8)


class TwoPlaneScene(DeskLampScene):
    """The two-plane scene (see the module docstring); frames as for ``DeskLampScene``."""

    # The stick is rocked by ±8° as it sweeps. With a stick that only
    # translates, every shadow plane contains one line through the lamp, and
    # the lamp — which this scene's scan must estimate from the planes — is
    # fixed only along that line.
    TILT_WOBBLE_DEG = 8.0
    config: TwoPlaneConfig

    SCENE_CENTRE = SCENE_CENTRE
    CAMERA_DISTANCE = 650.0
    CAMERA_ELEVATION_DEG = 32.0
    CAMERA_AZIMUTH_DEG = -2.0
    CAMERA_ROLL_DEG = 0.6
    REFERENCE_IDS = (DESK, WALL)

    def __init__(self, config: TwoPlaneConfig) -> None:
        super().__init__(config)
        self._setup_markers()

    def lamp_position(self) -> np.ndarray:
        return LAMP.astype(np.float64)

    def marker_centres(self, oid: int) -> np.ndarray:
        """(4, 2) the markers' centres on plane ``oid`` (plane coordinates, mm): :data:`MARKERS`, or with
        unmeasured marks the :data:`RECTANGLES`' corners each moved so that its image moves by up to
        ``marks_off_px`` (a random vector uniform in that disc, from the seed; one Newton step through the
        projection's Jacobian at the corner)."""
        cache = self.__dict__.setdefault("_marker_centres", {})
        if oid not in cache:
            if self.config.marks != "unmeasured":
                cache[oid] = np.array(MARKERS[oid], dtype=np.float64)
            else:
                corners = np.array(RECTANGLES[oid], dtype=np.float64)
                rng = np.random.default_rng([self.config.seed, 8, oid])
                radius = self.config.marks_off_px * np.sqrt(rng.uniform(0.0, 1.0, len(corners)))
                angle = rng.uniform(0.0, 2 * np.pi, len(corners))
                shift = radius[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
                moved = corners.copy()
                for k, c in enumerate(corners):
                    h = 1.0
                    base = self.project(plane_to_world(oid, c))
                    J = np.stack([(self.project(plane_to_world(oid, c + h * e)) - base) / h
                                  for e in np.eye(2)], axis=1)  # d pixel / d plane (2, 2)
                    moved[k] = c + np.linalg.solve(J, shift[k])
                cache[oid] = moved
        return np.asarray(cache[oid])

    def _stick_motion(self, u_start: float, u_end: float, tt: np.ndarray):
        """The rocked sweep's stick, or (``stick = "translated"``) one that keeps the direction it has
        half-way through the sweep: each pose keeps the rocked pose's centre and length."""
        QA, QB = super()._stick_motion(u_start, u_end, tt)
        if self.config.stick != "translated":
            return QA, QB
        mid_a, mid_b = super()._stick_motion(u_start, u_end, np.array([(self.N - 1) / 2.0]))
        axis = (mid_b[0] - mid_a[0]) / np.linalg.norm(mid_b[0] - mid_a[0])
        centre = 0.5 * (QA + QB)
        half = 0.5 * np.linalg.norm(QB - QA, axis=-1, keepdims=True)
        return centre - half * axis, centre + half * axis

    # ------------------------------------------------------------- surfaces
    def _objects(self) -> dict[int, tuple[geo.Surface, float]]:
        s, b = SPHERE_SPEC, BOX_SPEC
        return {
            SPHERE: (geo.Sphere(s["centre"], s["radius"]), s["albedo"]),
            BOX: (geo.Box(b["centre"], b["size"], b["yaw_deg"]), b["albedo"]),
        }

    def _planes(self) -> dict[int, geo.Plane]:
        return {DESK: geo.Plane((0.0, 0.0, 1.0), 0.0), WALL: geo.Plane((0.0, -1.0, 0.0), -WALL_Y)}

    def _texture(self, ab: np.ndarray, key: int) -> np.ndarray:
        """Smooth albedo 0.45–0.75 at plane coordinates ab (..., 2); phases from the seed."""
        return plane_texture(ab, [self.config.seed, key])

    def _plane_albedo(self, oid: int, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Albedo and marker class (0 none, 1 white, 2 black) of plane ``oid`` at world points X."""
        ab = world_to_plane(oid, X)
        albedo = self._texture(ab, 1 if oid == DESK else 5)
        cls = np.zeros(ab.shape[:-1], dtype=np.int8)
        for k, centre in enumerate(self.marker_centres(oid)):
            if self.config.markers == "aruco":
                bits = aruco_bits(ARUCO_DICTIONARY, 4 * PLANE_ORDER.index(oid) + k)
                cls = np.maximum(cls, aruco_class(ab - np.asarray(centre), bits, MARKER_CHECKER, MARKER_PAPER))
            else:
                cls = np.maximum(cls, marker_class(ab - np.asarray(centre)))
        albedo = np.where(cls == 1, MARKER_WHITE, np.where(cls == 2, MARKER_BLACK, albedo))
        return albedo, cls

    def _albedo(self, P: np.ndarray) -> np.ndarray:
        oid = self.object_id_f
        albedo = np.zeros(P.shape[:2])
        self.marker_lo_f = np.zeros(P.shape[:2], dtype=np.int8)   # min / max marker class over
        self.marker_hi_f = np.zeros(P.shape[:2], dtype=np.int8)   # each pixel's sub-samples
        self.near_marker_f = np.zeros(P.shape[:2], dtype=bool)
        p = self.pad
        n = MARKER_SUBSAMPLES
        offs = (np.arange(n) + 0.5) / n - 0.5
        for plane_id in PLANE_ORDER:
            m = oid == plane_id
            a, _ = self._plane_albedo(plane_id, P[m])
            albedo[m] = a
            # Pixels whose centre lies within a paper square grown by 1 mm + 1.5 px: box-filter
            # the printed albedo over the pixel (the plane is taken as the only surface there).
            ab = world_to_plane(plane_id, P)
            grow = np.zeros(P.shape[:2], dtype=bool)
            px_mm = self.camera_distance / self.lens.fx * 1.5 * 3.0   # generous: ~1.5 px at grazing view
            for centre in self.marker_centres(plane_id):
                q = np.abs(ab - np.asarray(centre))
                grow |= (q < MARKER_PAPER / 2.0 + 1.0 + px_mm).all(axis=-1)
            grow &= m
            vv, uu = np.nonzero(grow)
            if not len(vv):
                continue
            us = (uu - p)[:, None, None] + offs[None, None, :]
            vs = (vv - p)[:, None, None] + offs[None, :, None]
            us, vs = np.broadcast_arrays(us, vs)
            d = self.lens.rays_cam(us, vs) @ self.R
            t = self.planes[plane_id].intersect(self.C, d)
            sub = self.C + t[..., None] * d
            a_sub, cls_sub = self._plane_albedo(plane_id, sub)
            albedo[vv, uu] = a_sub.reshape(len(vv), -1).mean(axis=1)
            cls_sub = cls_sub.reshape(len(vv), -1)
            self.marker_lo_f[vv, uu] = cls_sub.min(axis=1)
            self.marker_hi_f[vv, uu] = cls_sub.max(axis=1)
            self.near_marker_f[vv, uu] = True
        for obj_id, (_, obj_albedo) in self.objects.items():
            albedo = np.where(oid == obj_id, obj_albedo, albedo)
        return albedo

    # ------------------------------------------------------------- the stick's reference surface
    def surface_point(self, u, v) -> np.ndarray:
        """Where the ray of pixel (u, v) first meets the desk or the wall."""
        d = self.pixel_rays_world(u, v)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_desk = np.where(d[..., 2] < -1e-9, -self.C[2] / d[..., 2], np.inf)
            t_wall = np.where(d[..., 1] > 1e-9, (WALL_Y - self.C[1]) / d[..., 1], np.inf)
        tt = np.minimum(t_desk, t_wall)
        if not np.all(np.isfinite(tt)):
            raise GnomonError(f"simulate {self.name}: a pixel ray misses both desk and wall (camera set-up)")
        return self.C + tt[..., None] * d

    def shadow_columns(self, P: np.ndarray) -> np.ndarray:
        """P projected from S onto the desk ∪ wall; its image column."""
        v = P - self.S
        with np.errstate(divide="ignore", invalid="ignore"):
            s_desk = np.where(v[:, 2] < 0, -self.S[2] / v[:, 2], np.inf)
            s_wall = np.where(v[:, 1] > 0, (WALL_Y - self.S[1]) / v[:, 1], np.inf)
        s = np.minimum(s_desk, s_wall)
        Pd = self.S + s[:, None] * v
        return self.project(Pd)[:, 0]

    # ------------------------------------------------------------- ground truth
    def _plane_lines_in_image(self, planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per shadow plane (N, 4): does its line on the desk / on the wall show inside the image?"""
        W, H = self.W, self.H
        n, d = planes[:, :3], planes[:, 3]
        out = []
        # Desk: z = 0, y up to the corner; wall: y = WALL_Y, z ≥ 0. Parametrise by y or z.
        ys = np.linspace(-600.0, WALL_Y, 241)
        zs = np.linspace(0.0, 800.0, 241)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_desk = (d[:, None] - n[:, 1:2] * ys[None, :]) / n[:, :1]
            x_wall = (d[:, None] - n[:, 1:2] * WALL_Y - n[:, 2:3] * zs[None, :]) / n[:, :1]
        for X in (np.stack([x_desk, np.broadcast_to(ys, x_desk.shape), np.zeros_like(x_desk)], axis=-1),
                  np.stack([x_wall, np.full_like(x_wall, WALL_Y), np.broadcast_to(zs, x_wall.shape)], axis=-1)):
            Xc = X @ self.R.T + self.t
            front = Xc[..., 2] > 1.0
            uv = self.lens.project_cam(np.where(front[..., None], Xc, 1.0))
            inside = front & (uv[..., 0] >= 0) & (uv[..., 0] <= W - 1) & (uv[..., 1] >= 0) & (uv[..., 1] <= H - 1)
            out.append(inside.any(axis=1))
        return out[0], out[1]

    def _refine_swept(self, swept: np.ndarray) -> np.ndarray:
        N = self.N
        ok = np.ones(N, dtype=bool)
        for planes in (self.planes_enter, self.planes_leave):
            desk, wall = self._plane_lines_in_image(planes)
            ok &= desk & wall
        self.cuts_both = ok
        good = swept.copy()
        for times in (self.enter_time, self.leave_time):
            tt = np.where(swept, times, 0.0)
            k0 = np.clip(np.floor(tt).astype(np.int64), 0, N - 1)
            k1 = np.clip(np.ceil(tt).astype(np.int64), 0, N - 1)
            good &= ok[k0] & ok[k1]
        return good

    def _extra_edges_f(self) -> np.ndarray:
        """Printed albedo edges: a pixel or a 4-neighbour whose sub-samples differ in marker class."""
        cross = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=np.uint8)
        hi = cv2.dilate(self.marker_hi_f.astype(np.uint8), cross, borderType=cv2.BORDER_REPLICATE)
        lo = cv2.erode(self.marker_lo_f.astype(np.uint8), cross, borderType=cv2.BORDER_REPLICATE)
        return hi != lo

    def _regions(self) -> dict[int, list[list[int]]]:
        """Per plane: the band farthest from the corner (≥ half the image wide) and, nearest
        the corner, one band in each half of the image (each ≥ 35 % of the width): the corner
        runs slightly across the image, so two half-width bands follow it more closely."""
        H, W = self.H, self.W
        band = max(6, int(round(0.05 * H)))
        r = MARKER_KEEP_OUT_PX
        disc = np.ones((2 * r + 1, 2 * r + 1), dtype=np.uint8)
        paper = (self.marker_hi_f > 0).astype(np.uint8)
        keep_out = cv2.dilate(paper, disc, borderType=cv2.BORDER_CONSTANT, borderValue=0)[self.crop].astype(bool)
        edge = int(round(0.02 * H))
        inset = int(round(0.02 * W))
        regions: dict[int, list[list[int]]] = {}
        for oid in PLANE_ORDER:
            good = self.swept & (self.object_id == oid) & ~keep_out
            good[:, :inset] = False
            good[:, W - inset:] = False
            cum = np.concatenate([np.zeros((1, W), dtype=np.int64), np.cumsum(good, axis=0)])
            v_range = range(edge, H - edge - band + 1)
            # Runs of columns good on every row of the band [v0, v0 + band), per half and whole.
            full = []                # (v0, u0, u1) with u1 - u0 >= W/2
            halves: tuple[list, list] = ([], [])        # (v0, u0, u1) inside each half, >= 0.35 W
            for v0 in v_range:
                cols = (cum[v0 + band] - cum[v0]) == band
                if not cols.any():
                    continue
                u0, u1 = _longest_run(cols)
                if u1 - u0 >= W / 2:
                    full.append((v0, u0, u1))
                for h, (a, b) in enumerate(((0, W // 2), (W // 2, W))):
                    s0, s1 = _longest_run(cols[a:b])
                    if s1 - s0 >= 0.35 * W:
                        halves[h].append((v0, a + s0, a + s1))
            if not full:
                raise self._no_region(oid)
            # Desk: the corner is above (small v); wall: below (large v).
            towards_corner = (lambda x: x[0]) if oid == DESK else (lambda x: -x[0])
            v0, u0, u1 = max(full, key=towards_corner)          # the farthest from the corner
            chosen = [[u0, v0, u1, v0 + band]]
            for cand in halves:
                if not cand:
                    continue
                cv0, cu0, cu1 = min(cand, key=towards_corner)   # the nearest to the corner
                if abs(cv0 - v0) >= 2 * band:                  # well apart from the far band
                    chosen.append([cu0, cv0, cu1, cv0 + band])
            for u0, v0, u1, v1 in chosen:   # belt and braces
                sl = (slice(v0, v1), slice(u0, u1))
                assert (self.object_id[sl] == oid).all() and self.swept[sl].all() and not keep_out[sl].any()
            regions[oid] = sorted(chosen, key=lambda r: (r[1], r[0]))
        return regions

    def _no_region(self, oid: int) -> GnomonError:
        return GnomonError(
            f"simulate {self.name}: this configuration leaves no bare, swept {OBJECT_NAMES[oid]} band "
            "for the field log's reference regions")

    # ------------------------------------------------------------- markers
    def _setup_markers(self) -> None:
        rng = np.random.default_rng([self.config.seed, 6])
        ids, xy, world, pix, hints, corner_pix = [], [], [], [], [], []
        for p_i, oid in enumerate(PLANE_ORDER):
            centres = self.marker_centres(oid)
            X = plane_to_world(oid, centres)
            uv = self.project(X)
            ang = rng.uniform(0.0, 2 * np.pi, len(X))
            rad = rng.uniform(*HINT_OFFSET_PX, len(X))
            hint = np.round(uv + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1), 1)
            # Every marker fully visible on its bare plane, inside the image.
            paper = self.marker_hi_f[self.crop] > 0
            for k, c in enumerate(centres):
                corners = plane_to_world(oid, c + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * MARKER_PAPER / 2)
                cuv = self.project(corners)
                if not ((cuv >= 2).all() and (cuv[:, 0] <= self.W - 3).all() and (cuv[:, 1] <= self.H - 3).all()):
                    raise GnomonError(f"simulate {self.name}: marker {p_i * 4 + k} leaves the image")
                u0, v0 = np.floor(cuv.min(axis=0)).astype(int)
                u1, v1 = np.ceil(cuv.max(axis=0)).astype(int) + 1
                box = (slice(v0, v1), slice(u0, u1))
                if not (self.object_id[box][paper[box]] == oid).all():
                    raise GnomonError(f"simulate {self.name}: marker {p_i * 4 + k} is hidden")
            corner_pix.append(np.array([self.project(plane_to_world(oid, aruco_corners(c, MARKER_CHECKER)))
                                        for c in centres]))
            ids.append(np.arange(len(X)) + 4 * p_i)
            xy.append(centres)
            world.append(X)
            pix.append(uv)
            hints.append(hint)
        self.marker_ids = np.array(ids, dtype=np.int64)
        self.marker_plane_xy = np.array(xy)
        self.marker_world = np.array(world)
        self.marker_pixels = np.array(pix)
        self.marker_hints = np.array(hints)
        self.marker_corner_pixels = np.array(corner_pix)  # (2, 4, 4, 2): an ArUco marker's corners (markers = "aruco")

    # ------------------------------------------------------------- outputs
    def ground_truth_arrays(self) -> dict[str, np.ndarray]:
        arrays = super().ground_truth_arrays()
        frames = [PLANE_FRAMES[oid] for oid in PLANE_ORDER]
        arrays.update({
            "cuts_both": self.cuts_both.copy(),
            "stick_directions": ((self.QB - self.QA) / np.linalg.norm(self.QB - self.QA, axis=1, keepdims=True)),
            "wall_y": np.array(WALL_Y, dtype=np.float64),
            "plane_points": np.array([f[0] for f in frames]),
            "plane_normals": np.array([f[1] for f in frames]),
            "plane_x_axes": np.array([f[2] for f in frames]),
            "marker_ids": self.marker_ids.copy(),
            "marker_plane_xy": self.marker_plane_xy.copy(),
            "marker_world": self.marker_world.copy(),
            "marker_pixels": self.marker_pixels.copy(),
            "marker_hints": self.marker_hints.copy(),
        })
        if self.config.marks == "unmeasured":
            arrays["marker_rectangle_xy"] = np.array([RECTANGLES[oid] for oid in PLANE_ORDER])
        if self.config.markers == "aruco":
            arrays["marker_corner_pixels"] = self.marker_corner_pixels.copy()
        return arrays

    def field_log(self) -> dict:
        planes: list[dict[str, Any]] = []
        for p_i, oid in enumerate(PLANE_ORDER):
            point, normal, x_axis = PLANE_FRAMES[oid]
            planes.append({
                "name": OBJECT_NAMES[oid],
                "point": [float(x) for x in point],
                "normal": [float(x) for x in normal],
                "x_axis": [float(x) for x in x_axis],
                "regions": [list(map(int, r)) for r in self.regions[oid]],
            })
            if self.config.markers == "aruco":
                planes[-1]["aruco"] = {
                    "dictionary": ARUCO_DICTIONARY,
                    "size": MARKER_CHECKER,
                    "markers": [
                        {"id": int(self.marker_ids[p_i, k]),
                         "plane_xy": [float(x) for x in self.marker_plane_xy[p_i, k]]}
                        for k in range(self.marker_ids.shape[1])
                    ],
                }
            elif self.config.marks == "unmeasured":  # the marks' pixels only: no plane frame, no positions
                for key in ("point", "normal", "x_axis"):
                    planes[-1].pop(key)
                planes[-1]["off_rectangle_px"] = self.config.marks_off_px / 2.0
                planes[-1]["markers"] = [
                    {"id": int(self.marker_ids[p_i, k]),
                     "pixel_hint": [float(x) for x in self.marker_hints[p_i, k]]}
                    for k in range(self.marker_ids.shape[1])
                ]
            else:
                planes[-1]["markers"] = [
                    {"id": int(self.marker_ids[p_i, k]),
                     "plane_xy": [float(x) for x in self.marker_plane_xy[p_i, k]],
                     "pixel_hint": [float(x) for x in self.marker_hints[p_i, k]]}
                    for k in range(self.marker_ids.shape[1])
                ]
        capture, camera = self.capture_table(), self.camera_table()
        if self.config.marks == "unmeasured":
            camera.pop("pose")
            if self.config.mark_distance:
                a, b = self.marker_plane_xy[0, 0], self.marker_plane_xy[0, 1]
                planes[0]["mark_distance"] = {"between": [int(self.marker_ids[0, 0]), int(self.marker_ids[0, 1])],
                                              "length": float(np.linalg.norm(a - b))}
            else:
                capture["units"] = "relative"
        return {
            "capture": capture,
            "camera": camera,
            "planes": planes,
            "light": {"kind": "two-plane"},
            "scan": {"min_contrast": 20},
        }

    def summary(self) -> dict:
        ref = self.receives_light & np.isin(self.object_id, self.REFERENCE_IDS)
        return {
            **self.summary_common(),
            "lamp_in_field_log": False,
            "stick_motion": self.config.stick,
            "brightest_lit_plane": float(np.max(np.where(ref, self.ambient + self.direct, 0.0))),
            "frames_cutting_both_planes": int(self.cuts_both.sum()),
            "planes": {
                OBJECT_NAMES[oid]: {
                    "id": oid,
                    "point": PLANE_FRAMES[oid][0].tolist(),
                    "normal": PLANE_FRAMES[oid][1].tolist(),
                    "x_axis": PLANE_FRAMES[oid][2].tolist(),
                    "y_axis": plane_y_axis(PLANE_FRAMES[oid][1], PLANE_FRAMES[oid][2]).tolist(),
                    "regions": self.regions[oid],
                    "markers": [{"id": int(self.marker_ids[p_i, k]),
                                 "plane_xy": self.marker_plane_xy[p_i, k].tolist(),
                                 "world": self.marker_world[p_i, k].tolist(),
                                 "pixel": self.marker_pixels[p_i, k].tolist(),
                                 "pixel_hint": self.marker_hints[p_i, k].tolist()}
                                for k in range(self.marker_ids.shape[1])],
                }
                for p_i, oid in enumerate(PLANE_ORDER)
            },
            "marker": {"paper_mm": MARKER_PAPER, "checker_mm": MARKER_CHECKER,
                       "white": MARKER_WHITE, "black": MARKER_BLACK,
                       "hint_offset_px": list(HINT_OFFSET_PX)},
            "objects": {
                "sphere": {"id": SPHERE, **{k: list(v) if isinstance(v, tuple) else v for k, v in SPHERE_SPEC.items()}},
                "box": {"id": BOX, **{k: list(v) if isinstance(v, tuple) else v for k, v in BOX_SPEC.items()}},
            },
            "object_ids": {str(k): v for k, v in OBJECT_NAMES.items()},
        }


def _longest_run(mask: np.ndarray) -> tuple[int, int]:
    """[start, end) of the longest run of True in a 1-D boolean array ((0, 0) if none)."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    if not len(starts):
        return 0, 0
    i = int(np.argmax(ends - starts))
    return int(starts[i]), int(ends[i])


def simulate_two_plane(out_dir, config: TwoPlaneConfig | None = None, *,
                       progress: Callable[[int, int], None] | None = None) -> SimulationResult:
    """Render the two-plane capture into ``out_dir``; return what was written.

    Writes ``frames/frame_NNNN.{jpg,png}``, ``ground_truth.npz``,
    ``ground_truth.json`` and, last, ``field_log.toml``, each atomically.
    """
    config = config or TwoPlaneConfig()
    header = (f"Synthetic capture written by `gnomon simulate two_plane` (seed {config.seed}).\n"
              "Ground truth: ground_truth.npz and ground_truth.json beside this file (the lamp is\n"
              "only there: the shadow planes come from the lines on the desk and the wall).\n"
              "Plane coordinates: point + a·x_axis + b·(normal × x_axis).\n")
    return render_two_plane(out_dir, config, TwoPlaneScene, [config.seed, 3, 2], header, OBJECT_NAMES, progress)


def render_two_plane(out_dir, config: TwoPlaneConfig, scene_class: type[TwoPlaneScene], noise_key: list[int],
                     header: str, object_names: dict[int, str],
                     progress: Callable[[int, int], None] | None) -> SimulationResult:
    """Render a scene of this family (``scene_class`` of ``config``; its sensor noise drawn from ``noise_key``)
    into ``out_dir``: frames, ground truth, and last the field log under ``header`` (the nuisance line added)."""
    config.validate()
    t0 = time.perf_counter()
    out = prepare_out_dir(out_dir)
    scene = scene_class(config)
    out.mkdir(parents=True, exist_ok=True)
    clear_previous(out)
    paths = write_frames(scene, out, np.random.default_rng(noise_key), progress)
    gt_path, json_path = sensor.write_ground_truth(out, scene.ground_truth_arrays(), scene.summary())
    log_path = out / "field_log.toml"
    toml_io.dump(scene.field_log(), log_path, header=header + nuisance_text(config))
    return SimulationResult(
        out_dir=Path(out), field_log=log_path, frames=paths, ground_truth=gt_path,
        ground_truth_json=json_path, camera_distance_mm=scene.camera_distance,
        lamp=(float(scene.S[0]), float(scene.S[1]), float(scene.S[2])),
        regions={object_names[k]: v for k, v in scene.regions.items()},
        swept_pixels=int(scene.swept.sum()), swept_fraction=float(scene.swept.mean()),
        seconds=time.perf_counter() - t0, config=config)
