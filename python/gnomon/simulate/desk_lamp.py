"""The ``desk_lamp`` scene: a synthetic shadow-sweep capture with exact ground truth.

Scene (world frame = the desk, millimetres, z up out of the desk)
-----------------------------------------------------------------
* the desk, the plane z = 0, with a smooth albedo texture (0.45–0.75, a few
  sinusoids of 90–300 mm wavelength, phases from the seed);
* a sphere (r = 40) resting on the desk, albedo 0.70;
* a box 80 × 60 × 50 turned 25° about z, albedo 0.60;
* a cylinder (r = 25, length 120) lying on the desk, albedo 0.65;
* a camera 650 mm from the scene centre (the world origin), looking at it
  48° down from the desk, slightly turned and rolled; fx = 900, fy = 898.5 px
  at 800 × 600 (other sizes keep the field of view: fx, cx scale with the
  width and fy, cy with the height), the principal point a few pixels off the
  centre; lens k1 = −0.12, k2 = 0.05, p1 = 0.0010, p2 = −0.0008, k3 = 0
  (``--no-distortion``: all zero);
* a lamp: a sphere of radius ``lamp_radius`` (3 mm) centred at
  S = (−360, −220, 380), 568 mm from the scene centre, to the left of and in
  front of the camera, so shadow planes cut the viewing rays at a good angle.

``desk_lamp_right`` (``DeskLampConfig(lamp_side="right")``) is the same
scene, camera, objects, texture and hand motion with the lamp mirrored
across the vertical plane through the camera centre and the scene centre
(S ≈ (387.1, −167.8, 380): as far from camera, scene and desk as the left
one), and its own sensor-noise draw. The two captures share the pixel grid,
so a left and a right scan can be fused pixel by pixel; each sweeps much of
what the other's cast shadows hide. The stick sweeps the same way (left to
right in the image).

The stick
---------
A straight cylinder of radius ``stick_radius`` (2 mm; ``--stick-radius 6``
gives a 12 mm wide stick, whose two edges stay exact: each is the plane
through S tangent to the stick on its side), long enough that its ends never
shadow the view, held between the lamp and the scene at ~55 % of the way
from S to the desk. Its pose at each frame is set so that the centre
of its shadow on the desk runs along a nearly vertical image line at column
u(t), tilted by a few degrees; u(t) sweeps from beyond the left edge to beyond
the right edge with a smooth hand-like wobble in speed (±30 %), tilt (±1.5°)
and distance from the lamp (±1.5 %), all phases from the seed. The first two
and the last two frames are entirely free of the stick's shadow (verified).
Between frames the stick's pose is taken to move linearly (its two defining
axis points interpolate linearly), which is what the ground-truth times below
use.

**The stick itself is never rendered:** the camera never sees it directly, as
when it is held out of the field of view. Geometrically this is an
idealisation: with the stick at 55 % of the way to the desk, its axis would
cross the image during the later part of the sweep; the simulator simply does
not draw it (nor let it occlude anything but the lamp), so only its shadow
exists in the frames.

Rendering (per frame)
---------------------
Linear radiance at each pixel centre (point-sampled; the Gaussian blur stands
for the lens PSF and pixel integration). The scene is rendered on a grid a
few pixels larger than the image on every side and cropped after the blur, so
border pixels are blurred with the real scene beyond the border, not with a
reflection of the image::

    L = albedo · (A + E · max(n·l, 0) / |S − P|² · V · (1 − f_stick))

with ambient irradiance A = 0.1 (≈ 0.06 of full scale at the mean albedo),
V = 0 in the objects' own cast shadows (exact ray tests from the lamp's centre
against sphere, box and cylinder; the objects' shadows are hard), f_stick the
occluded fraction of the lamp's disc (:mod:`gnomon.simulate.shadow`), and E
set so that the brightest lit desk pixel is 0.8 of full scale — lowered if
needed so that no surface exceeds 0.97 (nothing clips). Then a Gaussian blur
(σ = ``blur`` px) of the linear image, gamma encoding
``DN = 255 · L^(1/gamma)``, Gaussian sensor noise (σ = ``noise`` DN),
rounding to u8, and JPEG (``jpeg_quality``, cv2) or PNG (quality 0).

Ground truth (``ground_truth.npz``)
-----------------------------------
* ``depth`` camera Z (mm, NaN = no surface), ``points_world``,
  ``object_id`` (0 desk, 1 sphere, 2 box, 3 cylinder, −1 none): the exact
  surface seen along each pixel centre's ray (the lens inverted by Newton's
  method on the 5-coefficient model);
* ``enter_time`` / ``leave_time``: the fractional frame at which the
  entering / leaving penumbra centre — the plane through S tangent to the
  stick on the leading / trailing side — passes the pixel's surface point,
  with the stick pose interpolated linearly between frames; NaN where it
  does not happen within [0, N − 1];
* ``shadow_planes_enter`` / ``shadow_planes_leave`` (N, 4): those planes at
  each integer frame, ``[nx, ny, nz, d]`` with ``n·X = d``, unit n pointing
  ahead of the moving shadow (a point not yet reached has ``n·X > d``);
* ``swept`` — the pixels a scanner can be held to:
  (1) the surface point is lit directly by the lamp: ``n·l > 0.05`` and not
  in any object's cast shadow;
  (2) both penumbra centres cross it strictly inside the sequence:
  ``1 ≤ enter_time`` and ``leave_time ≤ N − 2``;
  (3) it is not a mixed pixel: its blur footprint (the pixels within 2 px —
  3σ of the blur if that is more — the scene beyond the image border
  included, see Rendering) holds no pixel on an
  object boundary or a depth jump — a pixel whose 4-neighbour sees another
  object, no surface, or a depth differing by more than 1 % of depth — and
  no pixel that fails (1): a footprint straddling the edge of an object's
  cast shadow mixes lit and unlit surface just as one straddling a
  silhouette mixes depths, and biases the pixel's shadow time alike;
* ``swept_surface`` — (1) and (2) without (3): the surface the shadow really
  crossed while it was lit, mixed pixels included (a scanner's point
  anywhere else measured nothing: it is a false point);
* the camera (``K``, ``dist``, ``rvec``, ``tvec``, ``R``, ``t``), ``lamp``,
  ``image_size`` (W, H) and ``camera_distance_mm``;
* the stick: ``stick_axis`` (N, 2, 3), two points of its axis per frame (the
  pose moves linearly between frames), and ``stick_radius``;
* the pencil photos' truth (``pencil_*`` keys, see :mod:`gnomon.simulate.pencil`;
  length 0 with ``pencil_photos = 0``).

Pencil photos
-------------
``pencil_photos`` (default 3) photos of the same scene without the stick and
with a 150 mm pencil standing on bare desk, one position per photo, and
``pencil_log.toml`` for ``gnomon calibrate lamp``: see
:mod:`gnomon.simulate.pencil`.

The field log's desk regions are two bands (near the top and the bottom of
the image, 96 % of its width, 5 % of its height) chosen from this ground
truth so that every pixel in them is bare desk and swept.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from gnomon.errors import GnomonError
from gnomon.simulate import geometry as geo
from gnomon.simulate import sensor, shadow
from gnomon.simulate.sensor import AMBIENT, encode_image
from gnomon.util import atomic, toml_io

# ----------------------------------------------------------------- fixed scene constants

REF_WIDTH, REF_HEIGHT = 800, 600
REF_FX, REF_FY = 900.0, 898.5
REF_CX, REF_CY = 402.3, 297.6          # pixel-centre convention at 800 × 600
DISTORTION = (-0.12, 0.05, 0.0010, -0.0008, 0.0)

SCENE_CENTRE = np.array([0.0, 0.0, 0.0])
CAMERA_DISTANCE = 650.0
CAMERA_ELEVATION_DEG = 48.0             # viewing direction below the desk's plane
CAMERA_AZIMUTH_DEG = 4.0                # a slight turn about z
CAMERA_ROLL_DEG = 1.2
LAMP = np.array([-360.0, -220.0, 380.0])

DESK_PEAK = 0.8                         # brightest lit desk, fraction of full scale
SURFACE_PEAK = 0.97                     # no surface brighter than this
STICK_FRACTION = 0.55                   # stick position between S (0) and the desk (1)

DESK, SPHERE, BOX, CYLINDER = 0, 1, 2, 3
OBJECT_NAMES = {DESK: "desk", SPHERE: "sphere", BOX: "box", CYLINDER: "cylinder"}


def _objects() -> dict[int, tuple[geo.Surface, float]]:
    """The three objects and their albedos."""
    yaw = math.radians(12.0)
    return {
        SPHERE: (geo.Sphere((-100.0, 40.0, 40.0), 40.0), 0.70),
        BOX: (geo.Box((75.0, 55.0, 25.0), (80.0, 60.0, 50.0), 25.0), 0.60),
        CYLINDER: (geo.Cylinder((-5.0, -75.0, 25.0), (math.cos(yaw), math.sin(yaw), 0.0), 25.0, 120.0), 0.65),
    }


def plane_texture(ab: np.ndarray, seed: list[int]) -> np.ndarray:
    """Smooth albedo 0.45–0.75 at 2-D plane coordinates ab (..., 2), mm: four plane waves of 90–300 mm
    with random directions, amplitudes and phases drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    tex = np.zeros(ab.shape[:-1])
    amp_sum = 0.0
    for _ in range(4):
        lam = rng.uniform(90.0, 300.0)
        ang = rng.uniform(0.0, np.pi)
        amp = rng.uniform(0.5, 1.0)
        k = 2 * np.pi / lam * np.array([math.cos(ang), math.sin(ang)])
        tex += amp * np.sin(ab[..., 0] * k[0] + ab[..., 1] * k[1] + rng.uniform(0, 2 * np.pi))
        amp_sum += amp
    return 0.6 + 0.15 * tex / amp_sum


def mirror_across_view(X, camera_centre, scene_centre) -> np.ndarray:
    """Mirror image of X across the vertical plane through the camera and the scene centre."""
    h = np.asarray(camera_centre, dtype=np.float64) - np.asarray(scene_centre, dtype=np.float64)
    m = np.cross([0.0, 0.0, 1.0], h)
    m /= np.linalg.norm(m)
    X = np.asarray(X, dtype=np.float64)
    return X - 2.0 * float((X - scene_centre) @ m) * m


# ----------------------------------------------------------------- configuration / result

@dataclass(frozen=True)
class SweepConfig:
    """What every shadow-sweep scene shares: image, frames, nuisance, lamp and stick sizes."""

    width: int = 800
    height: int = 600
    frames: int = 240
    noise: float = 1.5            # sensor noise, DN (after gamma encoding)
    jpeg_quality: int = 90        # 0 = PNG
    seed: int = 0
    distortion: bool = True
    blur: float = 0.7             # Gaussian optical blur, σ in pixels (0 = none)
    lamp_radius: float = 3.0      # mm
    stick_radius: float = 2.0     # mm
    gamma: float = 2.2
    drift_px: float = 0.0         # the camera's slow drift by the last frame, px (sensor.camera_motion)
    bump_px: float = 0.0          # a sudden shift of the camera, px, from bump_frame on
    bump_frame: int | None = None  # None: 60 % of the way

    @property
    def scene_name(self) -> str:
        return "sweep"

    def error(self, msg: str) -> GnomonError:
        return GnomonError(f"simulate {self.scene_name}: {msg}")

    def validate(self) -> None:
        bad = self.error
        if not (128 <= self.width <= 8192 and 96 <= self.height <= 8192):
            raise bad(f"--width/--height {self.width}x{self.height}: the image size must be 128..8192 x 96..8192 px")
        if not 8 <= self.frames <= 100000:
            raise bad(f"--frames {self.frames}: need 8 to 100000 frames")
        sensor.check_sensor_options(self.noise, self.jpeg_quality, self.blur, bad)
        if not (math.isfinite(self.lamp_radius) and 0 < self.lamp_radius <= 50):
            raise bad(f"--lamp-radius {self.lamp_radius}: must be > 0 and <= 50 mm")
        if not (math.isfinite(self.stick_radius) and 0 < self.stick_radius <= 50):
            raise bad(f"--stick-radius {self.stick_radius}: must be > 0 and <= 50 mm")
        if not (math.isfinite(self.gamma) and 0.2 <= self.gamma <= 5):
            raise bad(f"--gamma {self.gamma}: must be 0.2 to 5")
        sensor.check_motion_options(self.drift_px, self.bump_px, self.bump_frame, self.frames, self.blur, bad)

    @property
    def extension(self) -> str:
        return "png" if self.jpeg_quality == 0 else "jpg"


LAMP_SIDES = ("left", "right")
MAX_PENCIL_PHOTOS = 12


@dataclass(frozen=True)
class DeskLampConfig(SweepConfig):
    """Parameters of ``gnomon simulate desk_lamp`` / ``desk_lamp_right`` (see the module docstring).

    ``lamp_side``: ``"left"`` (the lamp at ``LAMP``) or ``"right"`` (mirrored
    to the other side of the camera; everything else unchanged).
    ``pencil_photos``: how many pencil photos (and ``pencil_log.toml``) to
    write beside the capture; 0 for none, else 2 to 12.
    ``lamp_height``: the lamp's height above the desk, mm (default: ``LAMP``'s,
    380); a lower lamp casts longer object shadows (scenes for dual-scan fusion).
    ``lamp_above_camera``: put the lamp this many mm straight above the camera's
    centre instead (the light nearly in line with the camera: every shadow
    plane passes within that distance of it, and the rays graze the planes).
    ``pencil_albedo``: the pencil's albedo in its photos (default
    ``gnomon.simulate.pencil.PENCIL_ALBEDO``, 0.55; a dark marker pen: 0.05–0.1).
    """

    lamp_side: str = "left"
    pencil_photos: int = 3
    lamp_height: float | None = None
    lamp_above_camera: float | None = None
    pencil_albedo: float | None = None

    @property
    def scene_name(self) -> str:
        return "desk_lamp" if self.lamp_side == "left" else f"desk_lamp_{self.lamp_side}"

    def validate(self) -> None:
        if self.lamp_side not in LAMP_SIDES:
            raise GnomonError(f"simulate desk_lamp: lamp_side {self.lamp_side!r}: must be 'left' or 'right'")
        super().validate()
        if self.lamp_height is not None and not (math.isfinite(self.lamp_height) and 120 <= self.lamp_height <= 2000):
            raise self.error(f"lamp_height {self.lamp_height}: must be 120 to 2000 mm")
        if self.lamp_above_camera is not None and not (
                math.isfinite(self.lamp_above_camera) and 10 <= self.lamp_above_camera <= 500):
            raise self.error(f"lamp_above_camera {self.lamp_above_camera}: must be 10 to 500 mm")
        if self.lamp_above_camera is not None and (self.lamp_height is not None or self.lamp_side != "left"):
            raise self.error("lamp_above_camera places the lamp itself: give neither lamp_height nor lamp_side")
        if self.pencil_albedo is not None and not (math.isfinite(self.pencil_albedo) and 0 < self.pencil_albedo <= 1):
            raise self.error(f"pencil_albedo {self.pencil_albedo}: must be in (0, 1]")
        if not (self.pencil_photos == 0 or 2 <= self.pencil_photos <= MAX_PENCIL_PHOTOS):
            raise self.error(f"--pencil-photos {self.pencil_photos}: must be 0 (none) or 2 to "
                             f"{MAX_PENCIL_PHOTOS}")


@dataclass
class SimulationResult:
    """What :func:`simulate_desk_lamp` wrote, and the headline numbers."""

    out_dir: Path
    field_log: Path
    frames: list[Path]
    ground_truth: Path
    ground_truth_json: Path
    camera_distance_mm: float
    lamp: tuple[float, float, float]
    regions: list[list[int]] | dict[str, list[list[int]]]   # per plane name for several planes
    swept_pixels: int
    swept_fraction: float              # of all pixels
    seconds: float
    config: SweepConfig = field(default_factory=DeskLampConfig)
    pencil_log: Path | None = None     # DIR/pencil_log.toml (desk_lamp scenes with pencil photos)
    pencil_photos: list[Path] = field(default_factory=list)


# ----------------------------------------------------------------- the scene

class DeskLampScene:
    # Amplitude of the hand's rocking of the stick (degrees of the shadow's tilt).
    TILT_WOBBLE_DEG = 1.5
    """The desk-lamp scene for one configuration: geometry, lighting, stick, ground truth.

    Building it does the ray casting and computes the ground truth; frames
    are produced by :meth:`linear_image` / :meth:`encode`.
    """

    # Camera placement (overridden by other scenes that reuse this machinery).
    SCENE_CENTRE = SCENE_CENTRE
    CAMERA_DISTANCE = CAMERA_DISTANCE
    CAMERA_ELEVATION_DEG = CAMERA_ELEVATION_DEG
    CAMERA_AZIMUTH_DEG = CAMERA_AZIMUTH_DEG
    CAMERA_ROLL_DEG = CAMERA_ROLL_DEG
    # Surfaces whose brightest lit pixel sets the irradiance scale (DESK_PEAK).
    REFERENCE_IDS: tuple[int, ...] = (DESK,)

    def __init__(self, config: SweepConfig) -> None:
        config.validate()
        self.config = config
        self.name = config.scene_name
        self.W, self.H, self.N = config.width, config.height, config.frames
        self._setup_camera()
        self.S = self.lamp_position()
        # Everything per pixel is computed on a grid padded by ``pad`` pixels on
        # each side (the scene beyond the image border is real: the blur and
        # the mixed-pixel test see it), then cropped to the image.
        # The blur footprint used by the mixed-pixel test: 2 px (3σ at the default
        # σ = 0.7 px), 3σ for stronger blurs.
        self.footprint_radius = max(2, int(round(3.0 * config.blur)))
        self.pad = max(int(math.ceil(4.0 * config.blur)), self.footprint_radius) + 3
        # The camera's motion per frame (px; zero unless it drifts): the padding holds the moved frames.
        self.camera_motion = sensor.camera_motion(self.N, config.drift_px, config.bump_px, config.bump_frame)
        if self.camera_motion.any():
            self.pad = max(self.pad, sensor.shift_margin(config.blur, self.camera_motion))
        p = self.pad
        self.crop = (slice(p, p + self.H), slice(p, p + self.W))
        self._cast_primary_rays()
        self._light()
        # The per-pixel maps on the image proper (the *_f maps cover the padded grid).
        c = self.crop
        self.hit, self.object_id, self.points = self.hit_f[c], self.object_id_f[c], self.points_f[c]
        self.depth, self.normals, self.albedo = self.depth_f[c], self.normals_f[c], self.albedo_f[c]
        self.direct, self.ambient, self.lit = self.direct_f[c], self.ambient_f[c], self.lit_f[c]
        self.receives_light, self.in_cast_shadow = self.receives_light_f[c], self.in_cast_shadow_f[c]
        self.cos_incidence, self.dist_to_lamp = self.cos_incidence_f[c], self.dist_to_lamp_f[c]
        self._setup_stick()
        self._ground_truth()

    # ------------------------------------------------------------- camera
    def _setup_camera(self) -> None:
        el, az = math.radians(self.CAMERA_ELEVATION_DEG), math.radians(self.CAMERA_AZIMUTH_DEG)
        centre = np.asarray(self.SCENE_CENTRE, dtype=np.float64)
        eye = centre + self.CAMERA_DISTANCE * np.array(
            [math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
        self.camera = geo.SceneCamera.scaled(
            self.W, self.H, ref_size=(REF_WIDTH, REF_HEIGHT), ref_focal_px=(REF_FX, REF_FY),
            ref_centre_px=(REF_CX, REF_CY), dist=DISTORTION if self.config.distortion else (0.0,) * 5,
            eye=eye, target=centre, roll_deg=self.CAMERA_ROLL_DEG)
        self.lens, self.R, self.t = self.camera.lens, self.camera.R, self.camera.t
        self.rvec, self.C = self.camera.rvec, self.camera.centre
        self.camera_distance = float(np.linalg.norm(self.C - centre))

    def lamp_position(self) -> np.ndarray:
        """The lamp's centre: ``LAMP``, or its mirror image for ``lamp_side="right"``.

        The mirror is the vertical plane through the camera centre and the
        scene centre, so the right lamp is exactly as far from the camera, the
        scene and the desk as the left one, on the other side of the view.
        """
        S = LAMP.astype(np.float64)
        c = self.config
        if isinstance(c, DeskLampConfig):
            if c.lamp_above_camera is not None:
                return np.asarray(self.C, dtype=np.float64) + np.array([0.0, 0.0, c.lamp_above_camera])
            if c.lamp_height is not None:
                S[2] = float(c.lamp_height)
            if c.lamp_side == "right":
                S = mirror_across_view(S, self.C, self.SCENE_CENTRE)
        return S

    def project(self, X_world: np.ndarray) -> np.ndarray:
        """World points (..., 3) → pixels (..., 2) through the distorted lens."""
        Xc = np.asarray(X_world, dtype=np.float64) @ self.R.T + self.t
        return self.lens.project_cam(Xc)

    def pixel_rays_world(self, u, v) -> np.ndarray:
        """Unit world-frame rays through pixel positions (u, v)."""
        return self.lens.rays_cam(u, v) @ self.R

    def desk_point(self, u, v) -> np.ndarray:
        """Where the ray of pixel (u, v) meets the desk plane z = 0."""
        d = self.pixel_rays_world(u, v)
        if np.any(d[..., 2] >= -1e-9):
            raise GnomonError(f"simulate {self.name}: a pixel ray misses the desk (camera set-up)")
        tt = -self.C[2] / d[..., 2]
        return self.C + tt[..., None] * d

    def surface_point(self, u, v) -> np.ndarray:
        """Where the ray of pixel (u, v) meets the reference surface (here: the desk).

        The stick's motion is defined by two such points per frame (see
        ``_stick_motion``); scenes with other reference surfaces override this.
        """
        return self.desk_point(u, v)

    def shadow_columns(self, P: np.ndarray) -> np.ndarray:
        """Image column of the central shadow line on the reference surface when it
        falls on each lit point P (M, 3): P projected from S onto the desk."""
        k = self.S[2] / (self.S[2] - P[:, 2])
        Pd = self.S + k[:, None] * (P - self.S)
        return self.project(Pd)[:, 0]

    # ------------------------------------------------------------- geometry
    def _cast_primary_rays(self) -> None:
        p = self.pad
        uu, vv = np.meshgrid(np.arange(-p, self.W + p, dtype=np.float64),
                             np.arange(-p, self.H + p, dtype=np.float64))
        d_cam = self.lens.rays_cam(uu, vv)                    # (H, W, 3)
        d = d_cam @ self.R                                    # world directions
        self.rays_world_f = d
        self.objects = self._objects()                        # solids: cast shadows, fixed albedo
        self.planes = self._planes()                          # large textured planes
        surfaces = {**{oid: pl for oid, pl in self.planes.items()},
                    **{oid: obj for oid, (obj, _) in self.objects.items()}}
        id_list = np.array(list(surfaces), dtype=np.int8)
        ts = np.stack([s.intersect(self.C, d) for s in surfaces.values()])   # (n, H, W)
        ids = np.argmin(ts, axis=0)
        t_hit = np.take_along_axis(ts, ids[None], axis=0)[0]
        hit = np.isfinite(t_hit)
        self.hit_f = hit
        self.object_id_f = np.where(hit, id_list[ids], -1).astype(np.int8)
        t_safe = np.where(hit, t_hit, 0.0)
        P = self.C + t_safe[..., None] * d
        self.points_f = np.where(hit[..., None], P, np.nan)
        self.depth_f = np.where(hit, t_safe * d_cam[..., 2], np.nan)
        n = np.zeros_like(P)
        for oid, surf in surfaces.items():
            m = self.object_id_f == oid
            n[m] = surf.normal(P[m])
        self.normals_f = n
        self.albedo_f = np.where(hit, self._albedo(P), 0.0)

    def _objects(self) -> dict[int, tuple[geo.Surface, float]]:
        return _objects()

    def _planes(self) -> dict[int, geo.Plane]:
        return {DESK: geo.Plane((0.0, 0.0, 1.0), 0.0)}

    def _albedo(self, P: np.ndarray) -> np.ndarray:
        """Albedo at the (padded) grid's surface points: the desk texture, objects uniform."""
        albedo = plane_texture(P[..., :2], [self.config.seed, 1])
        for oid, (_, a) in self.objects.items():
            albedo = np.where(self.object_id_f == oid, a, albedo)
        return albedo

    def _lamp_geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """On the padded grid: the surface points (0 where none), the vectors to the lamp's centre, their
        squared lengths, the cosine of incidence and whether the surface faces the lamp."""
        P, n, hit = self.points_f, self.normals_f, self.hit_f
        Pz = np.where(hit[..., None], P, 0.0)
        to_s = self.S - Pz
        dist2 = np.einsum("...i,...i->...", to_s, to_s)
        cos_i = np.einsum("...i,...i->...", n, to_s) / np.sqrt(dist2)
        return Pz, to_s, dist2, cos_i, hit & (cos_i > 0.0)

    def _light(self) -> None:
        n, hit = self.normals_f, self.hit_f
        Pz, to_s, dist2, cos_i, facing = self._lamp_geometry()
        # Cast shadows: a ray from just above the surface towards S, blocked by an object.
        blocked = np.zeros_like(hit)
        idx = np.nonzero(facing)
        o = Pz[idx] + 1e-6 * n[idx]
        dirs = to_s[idx]
        b = np.zeros(len(o), dtype=bool)
        for obj, _ in self.objects.values():
            tt = obj.intersect(o, dirs)
            b |= tt < 1.0
        blocked[idx] = b
        self.in_cast_shadow_f = facing & blocked
        visible_light = facing & ~blocked
        raw = np.where(visible_light, self.albedo_f * np.maximum(cos_i, 0.0) / dist2, 0.0)
        amb = self.albedo_f * AMBIENT
        # Normalise on the image proper (not the padding).
        raw_c, amb_c = raw[self.crop], amb[self.crop]
        desk_lit = (visible_light & np.isin(self.object_id_f, self.REFERENCE_IDS))[self.crop]
        if not desk_lit.any():
            raise GnomonError(f"simulate {self.name}: no lit reference surface in view")
        i_desk = np.argmax(np.where(desk_lit, raw_c, -1.0))
        E = (DESK_PEAK - amb_c.flat[i_desk]) / raw_c.flat[i_desk]
        peak = np.max(amb + E * raw)
        if peak > SURFACE_PEAK:
            i_all = np.argmax(amb + E * raw)
            E = (SURFACE_PEAK - amb.flat[i_all]) / raw.flat[i_all]
        self.E = float(E)
        self.cos_incidence_f = np.where(hit, cos_i, np.nan)
        self.direct_f = E * raw                               # direct radiance, fully lit
        self.ambient_f = amb
        self.lit_f = visible_light & (cos_i > 0.05)           # ground-truth "lit directly"
        self.receives_light_f = visible_light                  # any direct light at all
        self.dist_to_lamp_f = np.sqrt(dist2)

    # ------------------------------------------------------------- the stick
    def _stick_motion(self, u_start: float, u_end: float, tt: np.ndarray):
        """Stick axis points (QA, QB) at (fractional) times tt along the smooth motion."""
        rng = np.random.default_rng([self.config.seed, 2])
        a1 = rng.uniform(0.10, 0.18) * rng.choice([-1, 1])
        a2 = rng.uniform(0.06, 0.12) * rng.choice([-1, 1])
        ph_t, ph_l = rng.uniform(0, 2 * np.pi, 2)
        tilt0 = rng.uniform(-3.0, 3.0)
        s = np.asarray(tt, dtype=np.float64) / (self.N - 1)
        s_w = (s + a1 * np.sin(2 * np.pi * 2 * s) / (2 * np.pi * 2)
               + a2 * np.sin(2 * np.pi * 3 * s) / (2 * np.pi * 3))
        u = u_start + (u_end - u_start) * s_w
        tilt = np.radians(tilt0 + self.TILT_WOBBLE_DEG * np.sin(2 * np.pi * 1.3 * s + ph_t))
        lam = STICK_FRACTION * (1.0 + 0.015 * np.sin(2 * np.pi * 0.8 * s + ph_l))
        half = np.tan(tilt) * (self.H - 1) / 2.0
        A = self.surface_point(u + half, np.zeros_like(u))
        B = self.surface_point(u - half, np.full_like(u, self.H - 1.0))
        QA = self.S + lam[..., None] * (A - self.S)
        QB = self.S + lam[..., None] * (B - self.S)
        return QA, QB

    def _setup_stick(self) -> None:
        c = self.config
        frames = np.arange(self.N, dtype=np.float64)
        # Where would the shadow's centre line be (image column) when it falls on
        # each lit point? Project the point from S onto the desk and read its column.
        cols = self.shadow_columns(self.points_f[self.receives_light_f])
        lo, hi = float(cols.min()), float(cols.max())
        self.motion = self.surface_point(np.array(hi), np.array((self.H - 1) / 2.0)) - \
            self.surface_point(np.array(lo), np.array((self.H - 1) / 2.0))
        tilt_px = math.tan(math.radians(3.0 + self.TILT_WOBBLE_DEG)) * (self.H - 1) / 2.0
        margin = 0.03 * self.W + tilt_px + 2.0
        for _ in range(12):
            u_start, u_end = lo - margin, hi + margin
            QA, QB = self._stick_motion(u_start, u_end, frames)
            # The first two and last two frames see no shadow at all, so every
            # lit point is entered after frame 1 and left before frame N - 2.
            if all(self._occlusion_pose(QA[k], QB[k], restrict=False).max() == 0.0
                   for k in (0, 1, self.N - 2, self.N - 1)):
                break
            margin *= 1.4
        else:  # pragma: no cover - geometry guarantees convergence
            raise RuntimeError("could not place the sweep so that the first and last two frames are lit")
        self.u_range = (u_start, u_end)
        self.QA, self.QB = QA, QB
        self.planes_enter, self.planes_leave = shadow.tangent_planes(
            self.S, QA, QB, c.stick_radius, self.motion)

    def stick_pose(self, t):
        """Stick axis points at fractional time(s) t: linear between the frames' poses."""
        t = np.clip(np.asarray(t, dtype=np.float64), 0.0, self.N - 1.0)
        k = np.minimum(np.floor(t).astype(int), self.N - 2)
        f = (t - k)[..., None]
        QA = self.QA[k] * (1 - f) + self.QA[k + 1] * f
        QB = self.QB[k] * (1 - f) + self.QB[k + 1] * f
        return QA, QB

    def _occlusion_pose(self, QA, QB, *, restrict: bool = True) -> np.ndarray:
        """Occluded fraction of the lamp (H, W) for one stick pose."""
        c = self.config
        P = self.points_f
        out = np.zeros(P.shape[:2])
        mask = self.receives_light_f
        if restrict:
            # Only points near the central shadow plane can be touched (a loose bound).
            _, _, w, h = shadow.stick_axes(self.S, QA, QB, self.motion)
            g = np.abs(np.einsum("...i,i->...", np.where(mask[..., None], P, 0.0) - self.S, w))
            band = 1.5 * (c.stick_radius + c.lamp_radius) * self.dist_to_lamp_f / h + 0.5
            mask = mask & (g <= band)
        if mask.any():
            out[mask] = shadow.occluded_fraction(P[mask], self.S, c.lamp_radius, QA, QB, c.stick_radius)
        return out

    def _occlusion_full(self, t: float, *, restrict: bool = True) -> np.ndarray:
        QA, QB = self.stick_pose(t)
        return self._occlusion_pose(QA, QB, restrict=restrict)

    def occlusion(self, t: float, *, restrict: bool = True) -> np.ndarray:
        """Occluded fraction of the lamp at (fractional) time t, per pixel of the image."""
        return self._occlusion_full(t, restrict=restrict)[self.crop]

    # ------------------------------------------------------------- ground truth
    def _plane_value(self, planes: np.ndarray, P: np.ndarray) -> np.ndarray:
        return np.einsum("...i,...i->...", planes[..., :3], P) - planes[..., 3]

    def _crossing_times(self, side: str, P: np.ndarray) -> np.ndarray:
        """Fractional time at which the ``side`` plane passes each point P (M, 3)."""
        planes = self.planes_enter if side == "enter" else self.planes_leave
        N = self.N
        g_first = self._plane_value(planes[0], P)
        g_last = self._plane_value(planes[N - 1], P)
        ok = (g_first > 0) & (g_last <= 0)
        times = np.full(len(P), np.nan)
        P = P[ok]
        lo = np.zeros(len(P), dtype=np.int64)
        hi = np.full(len(P), N - 1, dtype=np.int64)
        while True:  # bisection over frames: g(lo) > 0 >= g(hi)
            active = hi - lo > 1
            if not active.any():
                break
            mid = (lo + hi) // 2
            gm = self._plane_value(planes[mid], P)
            lo = np.where(active & (gm > 0), mid, lo)
            hi = np.where(active & (gm <= 0), mid, hi)
        # Inside [lo, lo + 1]: the pose moves linearly; Illinois-safeguarded regula falsi.
        a = np.zeros(len(P))
        b = np.ones(len(P))
        ga = self._plane_value(planes[lo], P)
        gb = self._plane_value(planes[lo + 1], P)

        def g_at(tau):
            QA = self.QA[lo] * (1 - tau[:, None]) + self.QA[lo + 1] * tau[:, None]
            QB = self.QB[lo] * (1 - tau[:, None]) + self.QB[lo + 1] * tau[:, None]
            en, le = shadow.tangent_planes(self.S, QA, QB, self.config.stick_radius, self.motion)
            return self._plane_value(en if side == "enter" else le, P)

        side_kept = np.zeros(len(P), dtype=np.int8)
        x = a.copy()
        for _ in range(60):
            x = (a * gb - b * ga) / (gb - ga)
            x = np.clip(x, a, b)
            gx = g_at(x)
            pos = gx > 0
            # Replace the endpoint with the same sign; halve the other's value if it was kept twice.
            a_new = np.where(pos, x, a)
            b_new = np.where(pos, b, x)
            ga_new = np.where(pos, gx, np.where(side_kept == -1, ga / 2, ga))
            gb_new = np.where(pos, np.where(side_kept == 1, gb / 2, gb), gx)
            side_kept = np.where(pos, 1, -1).astype(np.int8)
            a, b, ga, gb = a_new, b_new, ga_new, gb_new
            if np.all((b - a < 1e-12) | (np.abs(gx) < 1e-10)):
                break
        res = np.where(np.abs(gx) < 1e-7, x, np.nan)
        if np.isnan(res).any():  # pragma: no cover
            raise RuntimeError("shadow-time root finding did not converge")
        times[ok] = lo + res
        return times

    def _ground_truth(self) -> None:
        H, W, N = self.H, self.W, self.N
        P = self.points[self.hit]
        enter = np.full((H, W), np.nan)
        leave = np.full((H, W), np.nan)
        enter[self.hit] = self._crossing_times("enter", P)
        leave[self.hit] = self._crossing_times("leave", P)
        self.enter_time, self.leave_time = enter, leave
        crossed = (enter >= 1.0) & (leave <= N - 2.0)
        # Mixed pixels: the blur footprint (radius 2 px) reaches a pixel that sits
        # on an object boundary or a depth jump (a 4-neighbour with another
        # object, no surface, or a depth differing by more than 1 % of depth).
        Z = np.where(self.hit_f, self.depth_f, np.nan)
        oid = self.object_id_f
        edge = ~self.hit_f
        Hf, Wf = oid.shape
        for a, b in (((slice(None), slice(0, Wf - 1)), (slice(None), slice(1, Wf))),
                     ((slice(0, Hf - 1), slice(None)), (slice(1, Hf), slice(None)))):
            with np.errstate(invalid="ignore"):
                jump = ((oid[a] != oid[b]) | ~self.hit_f[a] | ~self.hit_f[b]
                        | (np.abs(Z[a] - Z[b]) > 0.01 * np.fmin(Z[a], Z[b])))
            edge[a] |= jump
            edge[b] |= jump
        # Pixels not lit directly count as boundaries too: a footprint that is partly
        # in an object's cast shadow mixes lit and unlit surface.
        edge |= ~self.lit_f
        extra = self._extra_edges_f()
        if extra is not None:
            edge |= extra
        r = self.footprint_radius
        dv, du = np.mgrid[-r:r + 1, -r:r + 1]
        disc = (du * du + dv * dv <= r * r).astype(np.uint8)
        near_edge = cv2.dilate(edge.astype(np.uint8), disc, borderType=cv2.BORDER_CONSTANT,
                               borderValue=0).astype(bool)
        clean = (self.hit_f & ~near_edge)[self.crop]
        self.unmixed = clean
        # Lit and crossed, mixed or not: where a shadow event was really there to measure.
        self.swept_surface = self.lit & crossed
        self.swept = self._refine_swept(self.lit & crossed & clean)
        self.regions = self._regions()

    def _refine_swept(self, swept: np.ndarray) -> np.ndarray:
        """Further conditions a scene puts on ``swept`` (none here)."""
        return swept

    def _extra_edges_f(self) -> np.ndarray | None:
        """More pixels (padded grid) that mix what they see, e.g. printed albedo edges."""
        return None

    def _regions(self):
        return self._desk_regions()

    def _desk_regions(self) -> list[list[int]]:
        H, W = self.H, self.W
        good = self.swept & (self.object_id == DESK)
        band = max(6, int(round(0.05 * H)))
        # Full width: a pixel whose shadow time falls before the line reaches
        # a region (or after it leaves) has no shadow plane.
        u0, u1 = 0, W
        edge = int(round(0.02 * H))
        top = bottom = None
        for v0 in range(edge, H // 2 - band + 1):
            if good[v0:v0 + band, u0:u1].all():
                top = v0
                break
        for v1 in range(H - edge, H // 2 + band - 1, -1):
            if good[v1 - band:v1, u0:u1].all():
                bottom = v1
                break
        if top is None or bottom is None or top + band > bottom - band:
            raise GnomonError(
                f"simulate {self.name}: this configuration leaves no bare, swept desk band near the "
                "top and bottom of the image for the field log's reference regions")
        regions = [[u0, top, u1, top + band], [u0, bottom - band, u1, bottom]]
        for r in regions:  # belt and braces: desk only, swept, never in a cast shadow
            sl = (slice(r[1], r[3]), slice(r[0], r[2]))
            assert (self.object_id[sl] == DESK).all() and self.swept[sl].all()
        return regions

    # ------------------------------------------------------------- images
    def linear_image(self, t: float, *, blur: bool = True, shift: np.ndarray | None = None) -> np.ndarray:
        """Linear radiance (H, W) at (fractional) time t, optionally with the optical blur; ``shift``: the
        camera's motion (px; with the blur)."""
        f = self._occlusion_full(t)
        return self._finish(self.ambient_f + self.direct_f * (1.0 - f), blur, shift)

    def lit_image(self, *, blur: bool = True) -> np.ndarray:
        """The image with the lamp unobstructed by the stick."""
        return self._finish(self.ambient_f + self.direct_f, blur)

    def shadowed_image(self, *, blur: bool = True) -> np.ndarray:
        """The image with the whole lamp hidden (ambient only)."""
        return self._finish(self.ambient_f, blur)

    def _finish(self, L_full: np.ndarray, blur: bool, shift: np.ndarray | None = None) -> np.ndarray:
        """Blur the padded linear image (the padding holds the real scene) and crop it; ``shift``: the
        camera's motion (px) in that frame."""
        return sensor.blur_and_crop(L_full, self.config.blur if blur else 0.0, self.crop, shift)

    def encode(self, L_blurred: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Gamma-encode, add sensor noise, quantise: linear (blurred) radiance → u8."""
        return sensor.encode_dn(L_blurred, self.config.gamma, self.config.noise, rng)

    def frame(self, k: int, rng: np.random.Generator) -> np.ndarray:
        """Frame k as the (possibly moving, ``camera_motion[k]``) camera saw it."""
        return self.encode(self.linear_image(float(k), shift=self.camera_motion[k]), rng)

    # ------------------------------------------------------------- summaries
    def ground_truth_arrays(self) -> dict[str, np.ndarray]:
        return {
            "depth": self.depth.astype(np.float32),
            "points_world": self.points.astype(np.float32),
            "object_id": self.object_id,
            "swept": self.swept,
            "swept_surface": self.swept_surface,
            "enter_time": self.enter_time.astype(np.float32),
            "leave_time": self.leave_time.astype(np.float32),
            "shadow_planes_enter": self.planes_enter,
            "shadow_planes_leave": self.planes_leave,
            "K": self.lens.K,
            "dist": self.lens.dist.copy(),
            "rvec": self.rvec.copy(),
            "tvec": self.t.copy(),
            "R": self.R.copy(),
            "t": self.t.copy(),
            "lamp": self.S.copy(),
            "image_size": np.array([self.W, self.H], dtype=np.int64),
            "camera_distance_mm": np.float64(self.camera_distance),
            "stick_axis": np.stack([self.QA, self.QB], axis=1),
            "stick_radius": np.float64(self.config.stick_radius),
            "camera_motion_px": self.camera_motion.copy(),
        }

    def capture_table(self) -> dict:
        c = self.config
        return {"frames": f"frames/*.{c.extension}", "units": "mm", "gamma": float(c.gamma),
                "frame_count": int(self.N)}

    def camera_table(self) -> dict:
        """``[camera]`` with ``[camera.pose]``: the true intrinsics, lens and pose."""
        L = self.lens
        return {
            "model": "opencv", "width": int(self.W), "height": int(self.H),
            "fx": L.fx, "fy": L.fy, "cx": L.cx, "cy": L.cy, "dist": [float(x) for x in L.dist],
            "pose": {"rvec": [float(x) for x in self.rvec], "tvec": [float(x) for x in self.t]},
        }

    def field_log(self) -> dict:
        return {
            "capture": self.capture_table(),
            "camera": self.camera_table(),
            "planes": [{"name": "desk", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0],
                        "regions": [list(map(int, r)) for r in self.regions]}],
            "light": {"kind": "lamp", "position": [float(x) for x in self.S]},
            "scan": {"min_contrast": 20},
        }

    def summary_common(self) -> dict:
        """The ground-truth entries every lamp-and-stick scene has (see :meth:`summary`)."""
        c = self.config
        return {
            "scene": self.name,
            "seed": c.seed,
            "config": dataclasses.asdict(c),
            "units": "mm",
            "image_size": [self.W, self.H],
            "frame_count": self.N,
            "camera_distance_mm": self.camera_distance,
            **self.camera.summary(),
            "scene_centre_world": np.asarray(self.SCENE_CENTRE).tolist(),
            "lamp": self.S.tolist(),
            "lamp_distance_mm": float(np.linalg.norm(self.S - self.SCENE_CENTRE)),
            "lamp_radius_mm": c.lamp_radius,
            "stick_radius_mm": c.stick_radius,
            "stick_fraction_from_lamp": STICK_FRACTION,
            "irradiance_scale_E": self.E,
            "ambient_irradiance": AMBIENT,
            "brightest_surface": float(np.max(self.ambient + self.direct)),
            "sweep_columns": list(self.u_range),
            "swept_pixels": int(self.swept.sum()),
            "swept_fraction": float(self.swept.mean()),
        }

    def summary(self) -> dict:
        lit_desk = self.receives_light & (self.object_id == DESK)
        c = self.config
        return {
            **self.summary_common(),
            "lamp_side": c.lamp_side if isinstance(c, DeskLampConfig) else "left",
            "brightest_lit_desk": float(np.max(np.where(lit_desk, self.ambient + self.direct, 0.0))),
            "regions": self.regions,
            "objects": {
                "sphere": {"id": SPHERE, "centre": [-100.0, 40.0, 40.0], "radius": 40.0, "albedo": 0.70},
                "box": {"id": BOX, "centre": [75.0, 55.0, 25.0], "size": [80.0, 60.0, 50.0],
                        "yaw_deg": 25.0, "albedo": 0.60},
                "cylinder": {"id": CYLINDER, "centre": [-5.0, -75.0, 25.0], "axis_yaw_deg": 12.0,
                             "radius": 25.0, "length": 120.0, "albedo": 0.65},
            },
            "object_ids": {str(k): v for k, v in OBJECT_NAMES.items()},
        }


# ----------------------------------------------------------------- writing a capture

def clear_previous(out: Path) -> None:
    """Make a half-written or stale capture in ``out`` unrunnable and remove old frames."""
    (out / "field_log.toml").unlink(missing_ok=True)
    (out / "pencil_log.toml").unlink(missing_ok=True)
    for sub, prefix in (("frames", "frame_"), ("pencil", "pencil_")):
        folder = out / sub
        if folder.is_dir():
            for p in folder.iterdir():
                if p.is_file() and p.name.startswith(prefix) and p.suffix in (".jpg", ".png"):
                    p.unlink()


_clear_previous = clear_previous  # the old private name


def prepare_out_dir(out_dir) -> Path:
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise GnomonError(f"{out}: exists and is not a directory")
    return out


def write_frames(scene: DeskLampScene, out: Path, rng: np.random.Generator,
                 progress: Callable[[int, int], None] | None) -> list[Path]:
    """Render and write ``frames/frame_NNNN.ext`` (atomically, one by one)."""
    config = scene.config
    frames_dir = out / "frames"
    frames_dir.mkdir(exist_ok=True)
    digits = max(4, len(str(config.frames - 1)))
    paths: list[Path] = []
    for k in range(config.frames):
        path = frames_dir / f"frame_{k:0{digits}d}.{config.extension}"
        atomic.write_bytes(path, encode_image(scene.frame(k, rng), config))
        paths.append(path)
        if progress is not None:
            progress(k + 1, config.frames)
    return paths


def nuisance_text(config: SweepConfig) -> str:
    ext = config.extension
    return (f"{config.width}x{config.height}, {config.frames} frames, noise {config.noise} DN, "
            f"{'PNG' if ext == 'png' else f'JPEG q{config.jpeg_quality}'}, blur {config.blur} px, "
            f"lamp radius {config.lamp_radius} mm, stick radius {config.stick_radius} mm.")


def simulate_desk_lamp(out_dir, config: DeskLampConfig | None = None, *,
                       progress: Callable[[int, int], None] | None = None) -> SimulationResult:
    """Render the desk-lamp capture into ``out_dir``; return what was written.

    Writes ``frames/frame_NNNN.{jpg,png}``, the pencil photos
    ``pencil/pencil_K.{jpg,png}`` (``config.pencil_photos``, see
    :mod:`gnomon.simulate.pencil`), ``ground_truth.npz``,
    ``ground_truth.json``, ``pencil_log.toml`` and, last, ``field_log.toml`` —
    every file atomically, so an interrupted run never leaves a runnable half
    capture. ``progress(done, total)`` is called after each frame.
    ``config.lamp_side = "right"`` gives the ``desk_lamp_right`` capture: the
    same scene and pixel grid with the lamp mirrored (independent sensor noise).
    """
    from gnomon.simulate import pencil as pencil_mod

    config = config or DeskLampConfig()
    config.validate()
    t0 = time.perf_counter()
    out = prepare_out_dir(out_dir)
    scene = DeskLampScene(config)
    out.mkdir(parents=True, exist_ok=True)
    clear_previous(out)

    # The right-hand capture is another recording: its own sensor noise.
    noise_key = [config.seed, 3] if config.lamp_side == "left" else [config.seed, 3, 1]
    paths = write_frames(scene, out, np.random.default_rng(noise_key), progress)

    arrays = scene.ground_truth_arrays()
    summary = scene.summary()
    pencil = None
    if config.pencil_photos:
        pencil = pencil_mod.write_pencil_photos(scene, out, config.pencil_photos)
    arrays.update(pencil_mod.ground_truth_arrays(pencil))
    summary["pencil"] = pencil_mod.ground_truth_summary(pencil)
    gt_path, json_path = sensor.write_ground_truth(out, arrays, summary)
    if pencil is not None:
        pencil_mod.write_pencil_log(scene, pencil, out / "pencil_log.toml")
    log_path = out / "field_log.toml"
    header = (f"Synthetic capture written by `gnomon simulate {scene.name}` (seed {config.seed}).\n"
              "Ground truth: ground_truth.npz and ground_truth.json beside this file.\n"
              + nuisance_text(config))
    toml_io.dump(scene.field_log(), log_path, header=header)
    return SimulationResult(
        out_dir=out, field_log=log_path, frames=paths, ground_truth=gt_path,
        ground_truth_json=json_path, camera_distance_mm=scene.camera_distance,
        lamp=(float(scene.S[0]), float(scene.S[1]), float(scene.S[2])), regions=scene.regions,
        swept_pixels=int(scene.swept.sum()), swept_fraction=float(scene.swept.mean()),
        seconds=time.perf_counter() - t0, config=config,
        pencil_log=(out / "pencil_log.toml") if pencil is not None else None,
        pencil_photos=list(pencil.paths) if pencil is not None else [])
