"""The ``facade_sun`` scene: a pole's shadow swept by the sun over ground and a facade.

An outdoor time-lapse with exact ground truth (the "sun" case of Bouguet &
Perona): a tripod camera watches a building facade and the street in front
of it for a few hours while the shadow of a tall vertical pole, cast by the
real sun for a real site and date (pvlib's SPA), turns about the pole like a
sundial's and sweeps the ground and the facade.

World frame (metres)
--------------------
Tied to local East-North-Up by a heading (:mod:`gnomon.light.ephemeris`):
world z is up, world x points at compass heading ``HEADING_DEG`` = 295°
(WNW) and y = z × x at 205° (SSW). The facade is the plane y = 0 (the
building behind it, y < 0, its outward normal +y facing 205°, so it is in
the sun from late morning to late afternoon); the ground is z = 0 (y ≥ 0).
``v_world = R · v_enu`` with R's rows the world axes in ENU:
x = (sin h, cos h, 0), y = (−cos h, sin h, 0), z = (0, 0, 1). The simulator
builds R itself; it does not use the pipeline's :func:`gnomon.light.ephemeris.R_world_from_enu`.

Scene
-----
* ground: z = 0, paving with a smooth albedo texture (0.24–0.36);
* the facade: y = 0 up to the roof line z = 16.5 m (sky above), plaster
  albedo 0.52–0.68 (textured), with
  - recessed windows, 0.25 m deep (reveals 0.25 m, pane albedo 0.16),
    1.3 m wide, on five floors, every 3.5 m along x;
  - a ledge (string course) along the whole facade at z 2.90–3.15 m,
    protruding 0.25 m (albedo 0.70);
  - two balconies, solid-parapet boxes 3.2 m wide protruding 1.1 m, at
    x 17.65–20.85, z 3.40–4.45 and x 10.65–13.85, z 6.60–7.65 m (albedo 0.60);
* the pole: a vertical cylinder of radius ``pole_radius`` (5 cm), base
  (12, 16, 0), 16 m in front of the facade, 14 m tall (albedo 0.35). It is
  rendered (its base is in view, its top above the image) and casts the
  swept shadow; its ground shadow runs to the facade and climbs it to 5–9 m;
* the camera on a tripod at (26, 25, 1.8), looking at the facade point
  (6.5, 0, 3.2) — the "facade centre" of ``camera_distance`` (31.7 m) —
  obliquely (≈ 38° from its normal) so that its rays cross the shadow planes
  at ≥ 20°; fx = 900, fy = 899 px at 800 × 600 (other sizes keep the field of
  view), lens k1 = −0.06, k2 = 0.012, p1 = 4e-4, p2 = −3e-4. The pole stands
  near the right edge of the image; the shadow sweeps the left half of the
  facade (from the left, towards the pole) and a strip of ground in front of
  it, which a 1.8 m tripod 25 m away sees at a grazing angle (3–5°).

The sun
-------
Site: Zürich (47.3769 N, 8.5417 E, 408 m, Europe/Zurich). Frames from
``start`` (local time, default 2026-11-12 11:40 CET) every
``round(duration_s / (frames − 1))`` seconds (60 s for the default 200 frames
over 3 h 19 min, 10:40–13:59 UTC); the sun goes from azimuth 172° to 221°,
elevation 25° → 15° (a low winter sun, so that the 14 m pole's shadow reaches
the facade and climbs it).
Its direction per frame is pvlib's SPA (``nrel_numpy``, ΔT = 67 s), apparent
(refracted) elevation, pressure from the altitude (``alt2pres``), 12 °C — the
same settings :mod:`gnomon.light.ephemeris` uses for a site without pressure/temperature.
The sun is a uniform disc of angular diameter 0.533°.

Between frames the sun direction is taken to move along the chord between
its frame directions, renormalised (``d(k + τ) ∝ (1 − τ)·d_k + τ·d_{k+1}``);
the true path differs by < 3e-6 rad at 60 s steps (0.05 mm at 15 m).

Shadows
-------
* The pole (exact, analytic): the occluded fraction of the sun's disc seen
  from each surface point, for the infinite cylinder, is
  :func:`gnomon.simulate.shadow.occluded_fraction` with a "lamp" of radius
  sin ρ at unit distance along the sun direction — the same disc.
  Beyond r/ρ = 10.7 m from the pole the umbra vanishes: the shadow is an
  antumbra hiding only part of the disc (``pole_occlusion_peak``). The pole's
  top end softens the shadow's tip: there the band fraction is multiplied by
  the disc fraction below the top's edge (an approximation, used only near
  the tip, which is never counted as swept).
* The building (balconies, ledge, window reveals): soft. A point's ray
  towards the sun is tested against the occluders inflated and deflated by
  the disc's spread at the occluder (ρ·s): where both tests agree the point
  is fully lit or fully shadowed; elsewhere (the penumbra bands, about a
  pixel wide at this distance: 1.1 m × 0.0093 ≈ 1 cm) the visible fraction
  is averaged over 24 directions spread uniformly over the disc.

Each pixel is point-sampled at its centre (as ``desk_lamp``; the blur stands
for the lens PSF and pixel integration), so the ground truth is exact for the
pixel-centre points. On the ground, seen at 3–5°, a pixel's footprint is far
longer than the pole's shadow is wide (0.1–0.3 m): in a single frame the
thin ground shadow looks dashed (aliased), while each pixel's temporal
profile is the exact one of its centre point.

Radiometry (linear, per pixel centre, per frame k)::

    L = g_k · albedo · ( S_k · a(n) · ao  +  E_k · c_k · max(n·d_k, 0) · V_k · (1 − f_k) )

* E_k the direct sun (Meinel's clear-sky beam model, ``0.7^(AM^0.678)``
  with pvlib's Kasten–Young air mass), c_k the cloud transmission: 1, except
  in ``clouds`` dips of a few frames where it falls smoothly by 40–80 %
  (``cloud``, ``direct_factor``);
* S_k the sky: 0.22·E at the start, slowly changing (±5 %, following the
  sun's elevation) and 30 % brighter per unit of cloud dip; a(n) =
  (1 + n_z)/2 + 0.25·(1 − n_z)/2 (sky + ground bounce), ao = 0.7 inside the
  window recesses; with ``bounce`` (``--bounce``) a(n) = (1 + n_z)/2 and the
  ground bounce is computed instead, per frame, between the street, the facade,
  its balconies and ledge (two bounces, the pole's shadow on the street
  included: :mod:`gnomon.simulate.outdoor_bounce`), added to the brackets as
  ``E_ind,k``; the truth then has ``bounce_share``, ``bounce_dip``,
  ``bounce_dip_frame`` and ``bounce_only``;
* V_k the building visibility, f_k the pole's occluded fraction;
* g_k the camera's auto-exposure gain, 1 ± 20 % along two slow sinusoids;
* sky pixels (no surface): 0.85 · g_k/max g · S_k/max S.

The scale is set so that the brightest surface over all frames is 0.88 of
full scale (nothing clips). Then, like ``desk_lamp``: Gaussian blur
(σ = ``blur`` px) on a padded grid, gamma encoding ``DN = 255·L^(1/γ)``,
sensor noise (σ = ``noise`` DN), u8, JPEG (``jpeg_quality``, Pillow) or PNG.

Frames are named by their UTC time, ``frames/20261008T094000Z.jpg``
(``%Y%m%dT%H%M%SZ``), and carry EXIF ``DateTimeOriginal`` (local time,
``2026:10:08 11:40:00``), ``OffsetTimeOriginal`` (``+02:00``) and
``SubSecTimeOriginal`` (``000``).

Field log (``field_log.toml``)
------------------------------
``[capture]`` frames, units = "m", gamma, frame_count, ``timestamps =
"filename"``, ``time_pattern = "%Y%m%dT%H%M%SZ"`` (a literal Z: UTC);
``[camera]`` + ``[camera.pose]`` as for ``desk_lamp``;
``[[planes]]`` ``ground`` (point [0, 0, 0], normal [0, 0, 1]) and ``facade``
(point [0, 0, 0], normal [0, 1, 0]), each with ``regions`` — image rectangles
``[u0, v0, u1, v1]`` of bare, swept ground / bare, swept wall (no window, no
ledge, no balcony, never in a building shadow);
``[site]`` latitude, longitude, altitude (m), timezone, heading_deg;
``[light]`` ``kind = "sun"``;
``[pole]`` base, top (world, m), radius (m): the occluder whose shadow is
swept; the shadow plane at time t contains the pole's axis and d(t);
``[gnomon]`` for estimating the heading from the pole's shadow in one frame:
``frame`` (a path relative to the field log), ``base_px``, ``top_px`` (the
pixels of the pole's base and top; the top may lie outside the image) and
``shadow_px`` (a pixel on the centre line of the pole's shadow on the ground
in that frame, 70 % of the way from the base to where the shadow meets the
facade or ends). With base_px and shadow_px back-projected onto the ground,
the shadow's world direction φ (anticlockwise from world x) and the sun's
azimuth A at that time give ``heading = A + 180° + φ`` (mod 360);
``[scan]`` ``normalize_illumination = true`` and no min_contrast (the contrast floor then comes
from the measured image noise; the drift and
clouds must be divided out before thresholding).

Ground truth (``ground_truth.npz``; arrays H × W unless noted)
-------------------------------------------------------------
* ``depth`` (camera Z, m, NaN = sky), ``points_world``, ``normals_world``,
  ``object_id`` (0 ground, 1 wall, 2 window pane, 3 window reveal,
  4 balcony, 5 ledge, 6 pole, −1 sky);
* ``center_time``: the fractional frame at which the central shadow plane —
  through the pole's axis, containing the sun direction — passes the point;
  ``enter_time`` / ``leave_time``: the planes parallel to it tangent to the
  pole on the leading / trailing side (where the sun's centre grazes the
  pole's silhouette: the penumbra centres when an umbra exists); NaN where
  the crossing is not within [0, N − 1] or falls on the sunward side;
* ``shadow_planes_center`` / ``_enter`` / ``_leave`` (N, 4): those planes at
  each frame, ``[nx, ny, nz, d]``, ``n·X = d``, unit n horizontal, pointing
  ahead of the moving shadow;
* ``pole_occlusion_peak``: the occluded fraction of the sun's disc when the
  centre plane passes (the shadow's depth; < 1 beyond 10.7 m);
* ``sunlit``: n·d > 0.05 and no building shadow (not even partial) at every
  frame;
* ``swept`` (the definition of ``desk_lamp``): (1) ``sunlit``; (2) both
  tangent planes cross the point strictly inside the sequence,
  ``1 ≤ enter_time`` and ``leave_time ≤ N − 2``, on the shadow side, with
  the sun's ray passing the pole's axis at least 2 disc radii (angular)
  below its top; (3) not mixed: no pixel within the blur footprint (2 px, or
  3σ) sees another object, no surface or another surface (a neighbour with
  another normal or off the pixel's plane — ``desk_lamp``'s depth change
  > 1 % would flag the whole grazing ground), or fails (1);
* ``swept_surface``: (2), and from a frame before ``enter_time`` to a frame
  after ``leave_time`` lit (the sun above the horizon — the frames render
  its dip down to there, where ``sunlit`` of a full day wants 2° —, n·d >
  0.05, at least half the sun's disc seen past the building, no lamp post
  shadow), without (3): a surface the
  pole's shadow really crossed while it was lit, mixed pixels included (a
  scanner's point anywhere else measured nothing: it is a false point);
* ``cloud_free_passage``: swept and no cloud frame within
  [enter_time − 1, leave_time + 1];
* per frame (N): ``frame_times_utc`` (ISO 8601 strings), ``frame_times_utc_ns``
  (int64), ``sun_enu`` / ``sun_world`` (N, 3), ``sun_azimuth_deg``,
  ``sun_elevation_deg`` (apparent), ``gain``, ``cloud`` (bool),
  ``direct_factor``, ``sun_strength``, ``sky``;
* ``heading_deg``, ``R_world_from_enu``, ``K``, ``dist``, ``rvec``, ``tvec``,
  ``R``, ``t``, ``image_size`` (W, H), ``camera_distance`` (m, camera centre
  to the facade centre (0, 0, 5)), ``units`` ("m"), ``pole_base``,
  ``pole_top``, ``pole_radius``, ``sun_angular_radius_rad``.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import io
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd

from gnomon.errors import GnomonError
from gnomon.simulate import geometry as geo
from gnomon.simulate import outdoor_bounce, sensor, shadow
from gnomon.util import atomic, toml_io

# ----------------------------------------------------------------- fixed scene constants

SITE_LATITUDE = 47.3769
SITE_LONGITUDE = 8.5417
SITE_ALTITUDE = 408.0
SITE_TIMEZONE = "Europe/Zurich"
HEADING_DEG = 295.0
SUN_ANGULAR_DIAMETER_DEG = 0.533
RHO = math.radians(SUN_ANGULAR_DIAMETER_DEG / 2.0)   # angular radius, rad
DELTA_T_S = 67.0
TEMPERATURE_C = 12.0

REF_WIDTH, REF_HEIGHT = 800, 600
REF_FX, REF_FY = 900.0, 899.0
REF_CX, REF_CY = 398.7, 302.1
DISTORTION = (-0.06, 0.012, 0.0004, -0.0003, 0.0)

CAMERA_EYE = np.array([26.0, 25.0, 1.8])
CAMERA_TARGET = np.array([6.5, 0.0, 3.2])
CAMERA_ROLL_DEG = 0.8
FACADE_CENTRE = CAMERA_TARGET                 # the facade point at the image centre

POLE_BASE = np.array([12.0, 16.0, 0.0])
POLE_HEIGHT = 14.0

ROOF_Z = 16.5
RECESS_DEPTH = 0.25
WINDOW_WIDTH = 1.3
WINDOW_PITCH = 3.5
WINDOW_X0 = -1.75 - 14 * WINDOW_PITCH        # window centres at x = -1.75 + k·3.5
WINDOW_COLUMNS = 40
WINDOW_ROWS = ((0.9, 2.4), (4.0, 5.6), (7.2, 8.8), (10.4, 12.0), (13.4, 15.0))
LEDGE = ((-300.0, 300.0), (0.0, 0.25), (2.90, 3.15))
BALCONIES = (((17.65, 20.85), (0.0, 1.1), (3.40, 4.45)),
             ((10.65, 13.85), (0.0, 1.1), (6.60, 7.65)))
OCCLUDER_Y_MAX = 1.1                               # no building occluder reaches beyond this y

GROUND, WALL, WINDOW, REVEAL, BALCONY, LEDGE_ID, POLE, POST = 0, 1, 2, 3, 4, 5, 6, 7
OBJECT_NAMES = {GROUND: "ground", WALL: "wall", WINDOW: "window", REVEAL: "reveal",
                BALCONY: "balcony", LEDGE_ID: "ledge", POLE: "pole", POST: "post"}
ALBEDO = {WINDOW: 0.16, BALCONY: 0.60, LEDGE_ID: 0.70, POLE: 0.35, POST: 0.30}
# facade_day's other moving shadow: a street-lamp post (vertical cylinder) left of the pole.
POST_BASE = np.array([3.0, 9.0, 0.0])
POST_HEIGHT = 5.0
POST_RADIUS = 0.07
# facade_day: the sun lights a surface (for the ground truth) only this high above the horizon.
MIN_LIT_ELEVATION_DEG = 2.0

SKY_FRACTION = 0.22          # sky irradiance on a horizontal surface / direct sun at the start
GROUND_BOUNCE = 0.25
RECESS_AO = 0.7
SURFACE_PEAK = 0.88
SKY_RADIANCE = 0.85
DISC_SAMPLES = 24

TIME_PATTERN = "%Y%m%dT%H%M%SZ"
_NAME_RE = re.compile(r"^\d{8}T\d{6}Z$")


def R_world_from_enu(heading_deg: float) -> np.ndarray:
    """ENU → world rotation, the simulator's own (rows: world x, y, z in ENU)."""
    h = math.radians(heading_deg)
    return np.array([[math.sin(h), math.cos(h), 0.0], [-math.cos(h), math.sin(h), 0.0], [0.0, 0.0, 1.0]])


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


# ----------------------------------------------------------------- configuration / result

@dataclass(frozen=True)
class FacadeSunConfig:
    """Parameters of ``gnomon simulate facade_sun`` (see the module docstring)."""

    width: int = 800
    height: int = 600
    frames: int = 200
    start: str = "2026-11-12T11:40:00"   # local time at the site (Europe/Zurich), or with an offset
    duration_s: float = 11940.0          # first to last frame; the interval is rounded to whole seconds
    noise: float = 1.5                   # sensor noise, DN
    jpeg_quality: int = 90               # 0 = PNG
    seed: int = 0
    distortion: bool = True
    blur: float = 0.7                    # σ, px
    pole_radius: float = 0.05            # m
    gamma: float = 2.2
    clouds: int = 3                      # number of cloud dips
    gain_drift: float = 0.2              # auto-exposure gain amplitude (±)
    soft_shadows: bool = True            # building shadows with the sun's disc (False: hard, from its centre)
    full_day: bool = False               # sunrise to sunset and night at both ends (facade_day)
    post: bool = False                   # a street-lamp post casting another moving shadow (facade_day)
    drift_px: float = 0.0                # the camera's slow drift by the last frame, px (sensor.camera_motion)
    bump_px: float = 0.0                 # a sudden shift of the camera, px, from bump_frame on
    bump_frame: int | None = None        # None: 60 % of the way
    # No pole: the roof line across the street sweeps its shadow up the facade (gnomon.simulate.roof_edge).
    roof_edge: bool = False
    bounce: bool = False                 # interreflection between street, facade and balconies (outdoor_bounce)

    @classmethod
    def day(cls, **overrides) -> FacadeSunConfig:
        """The ``facade_day`` scene: a whole November day (06:40–17:40 local, night at both ends),
        six cloud dips, a lamp post's shadow besides the pole's, 8-bit JPEG."""
        base: dict[str, Any] = {"start": "2026-11-12T06:40:00", "duration_s": 11 * 3600.0, "frames": 400, "clouds": 6,
                "full_day": True, "post": True}
        base.update(overrides)
        return cls(**base)

    def validate(self) -> None:
        def bad(msg: str) -> GnomonError:
            return GnomonError(f"simulate {'facade_day' if self.full_day else 'facade_sun'}: {msg}")

        if not (128 <= self.width <= 8192 and 96 <= self.height <= 8192):
            raise bad(f"--width/--height {self.width}x{self.height}: the image size must be 128..8192 x 96..8192 px")
        if not 8 <= self.frames <= 20000:
            raise bad(f"--frames {self.frames}: need 8 to 20000 frames")
        longest = 24 if self.full_day else 6
        if not (math.isfinite(self.duration_s) and 600 <= self.duration_s <= longest * 3600):
            raise bad(f"duration_s {self.duration_s}: must be 600 s to {longest} h")
        if round(self.duration_s / (self.frames - 1)) < 1:
            raise bad(f"--frames {self.frames} over duration_s {self.duration_s:g} s: "
                      "frames must be at least 1 s apart")
        sensor.check_sensor_options(self.noise, self.jpeg_quality, self.blur, bad)
        sensor.check_motion_options(self.drift_px, self.bump_px, self.bump_frame, self.frames, self.blur, bad)
        if not (math.isfinite(self.pole_radius) and 0.005 <= self.pole_radius <= 0.5):
            raise bad(f"--pole-radius {self.pole_radius}: must be 0.005 to 0.5 m")
        if not (math.isfinite(self.gamma) and 0.2 <= self.gamma <= 5):
            raise bad(f"--gamma {self.gamma}: must be 0.2 to 5")
        if not 0 <= self.clouds <= 10:
            raise bad(f"--clouds {self.clouds}: must be 0 to 10")
        if not (math.isfinite(self.gain_drift) and 0 <= self.gain_drift <= 0.5):
            raise bad(f"gain_drift {self.gain_drift}: must be 0 to 0.5")
        self.start_time()

    def start_time(self) -> pd.Timestamp:
        """The first frame's time, UTC."""
        try:
            t = pd.Timestamp(dt.datetime.fromisoformat(str(self.start).strip()))
        except ValueError:
            raise GnomonError(f"simulate {'facade_day' if self.full_day else 'facade_sun'}: --start {self.start!r} "
                              "is not an ISO 8601 time") from None
        if t.tzinfo is None:
            t = t.tz_localize(SITE_TIMEZONE, ambiguous="raise", nonexistent="raise")
        return t.tz_convert("UTC").floor("s")

    @property
    def interval_s(self) -> int:
        return int(round(self.duration_s / (self.frames - 1)))

    @property
    def extension(self) -> str:
        return "png" if self.jpeg_quality == 0 else "jpg"


@dataclass
class FacadeSunResult:
    """What :func:`simulate_facade_sun` wrote, and the headline numbers."""

    out_dir: Path
    field_log: Path
    frames: list[Path]
    ground_truth: Path
    ground_truth_json: Path
    camera_distance: float               # m, camera centre to the facade centre
    frame_times: pd.DatetimeIndex        # UTC
    regions: dict[str, list[list[int]]]  # plane name → rectangles
    swept_pixels: int
    swept_fraction: float
    seconds: float
    config: FacadeSunConfig = field(default_factory=FacadeSunConfig)
    units: str = "m"
    # Duck-typing with desk_lamp's SimulationResult (what `gnomon simulate` prints).
    pencil_log: Path | None = None
    pencil_photos: list[Path] = field(default_factory=list)

    @property
    def camera_distance_mm(self) -> float:
        return 1000.0 * self.camera_distance


# ----------------------------------------------------------------- the building

class _Building:
    """The facade with its recessed windows, ledge and balconies: ray casting and sun visibility."""

    def __init__(self) -> None:
        self.boxes = [geo.Box(((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2), (x1 - x0, y1 - y0, z1 - z0), 0.0)
                      for (x0, x1), (y0, y1), (z0, z1) in (*BALCONIES, LEDGE)]
        self.box_ids = [BALCONY] * len(BALCONIES) + [LEDGE_ID]
        self.lo = np.array([[b[0][0], b[1][0], b[2][0]] for b in (*BALCONIES, LEDGE)])
        self.hi = np.array([[b[0][1], b[1][1], b[2][1]] for b in (*BALCONIES, LEDGE)])
        self.win_z = np.array(WINDOW_ROWS)

    # ---------------------------------------------------------------- windows
    def window_at(self, x: np.ndarray, z: np.ndarray, grow: np.ndarray | float = 0.0):
        """Which window opening (column centre, row) contains (x, z) on y = 0, the openings grown by ``grow``.

        Returns (inside, xc, z0, z1) with the opening's centre column and row limits (NaN outside).
        """
        grow = np.asarray(grow, dtype=np.float64)
        k = np.rint((x - WINDOW_X0) / WINDOW_PITCH)
        k = np.clip(k, 0, WINDOW_COLUMNS - 1)
        xc = WINDOW_X0 + k * WINDOW_PITCH
        in_x = np.abs(x - xc) <= WINDOW_WIDTH / 2 + grow
        z0 = np.full(np.shape(x), np.nan)
        z1 = np.full(np.shape(x), np.nan)
        in_z = np.zeros(np.shape(x), dtype=bool)
        for a, b in WINDOW_ROWS:
            m = (z >= a - grow) & (z <= b + grow)
            in_z |= m
            z0 = np.where(m, a, z0)
            z1 = np.where(m, b, z1)
        inside = in_x & in_z
        return inside, np.where(inside, xc, np.nan), np.where(inside, z0, np.nan), np.where(inside, z1, np.nan)

    # ---------------------------------------------------------------- primary rays
    def cast(self, o: np.ndarray, d: np.ndarray):
        """First surface along rays o + t·d (o one point, d (..., 3) unit): (t, id, normal, box index).

        The box index is the protruding box (balcony or ledge) hit, −1 for other surfaces."""
        shape = d.shape[:-1]
        # ground z = 0, in front of the facade
        with np.errstate(divide="ignore", invalid="ignore"):
            tg = -o[2] / d[..., 2]
        yg = o[1] + tg * d[..., 1]
        tg = np.where(np.isfinite(tg) & (tg > geo.EPS_T) & (yg >= 0.0), tg, np.inf)
        # facade plane y = 0 (the camera is at y > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            tw = -o[1] / d[..., 1]
        tw = np.where(np.isfinite(tw) & (tw > geo.EPS_T), tw, np.inf)
        xw = o[0] + np.where(np.isfinite(tw), tw, 0.0) * d[..., 0]
        zw = o[2] + np.where(np.isfinite(tw), tw, 0.0) * d[..., 2]
        on_wall = np.isfinite(tw) & (zw >= 0.0) & (zw <= ROOF_Z)
        tw = np.where(on_wall, tw, np.inf)
        inside, xc, z0, z1 = self.window_at(xw, zw)
        inside &= on_wall
        # inside an opening: the ray goes on into the recess box and stops where it leaves it
        t_rec = np.full(shape, np.inf)
        n_rec = np.zeros(shape + (3,))
        if inside.any():
            di = d[inside]
            lo = np.stack([xc[inside] - WINDOW_WIDTH / 2, np.full(inside.sum(), -RECESS_DEPTH), z0[inside]], -1)
            hi = np.stack([xc[inside] + WINDOW_WIDTH / 2, np.zeros(inside.sum()), z1[inside]], -1)
            with np.errstate(divide="ignore", invalid="ignore"):
                t1 = (lo - o) / di
                t2 = (hi - o) / di
            far = np.fmax(t1, t2)
            axis = np.argmin(far, axis=-1)
            t_far = np.take_along_axis(far, axis[:, None], -1)[:, 0]
            nl = np.zeros_like(di)
            # The inner face's normal points into the recess's open space, against the ray.
            np.put_along_axis(nl, axis[:, None], -np.sign(np.take_along_axis(di, axis[:, None], -1)), -1)
            t_rec[inside] = t_far
            n_rec[inside] = nl
            back = axis == 1
            rec_id = np.where(back, WINDOW, REVEAL)
        ts = np.stack([tg, np.where(inside, np.inf, tw), t_rec] + [b.intersect(o, d) for b in self.boxes])
        k = np.argmin(ts, axis=0)
        t = np.take_along_axis(ts, k[None], 0)[0]
        ids = np.full(shape, -1, dtype=np.int8)
        ids[k == 0] = GROUND
        ids[k == 1] = WALL
        if inside.any():
            rid = np.full(shape, REVEAL, dtype=np.int8)
            rid[inside] = rec_id
            ids = np.where(k == 2, rid, ids)
        for j, bid in enumerate(self.box_ids):
            ids[k == 3 + j] = bid
        ids[~np.isfinite(t)] = -1
        P = o + np.where(np.isfinite(t), t, 0.0)[..., None] * d
        n = np.zeros(shape + (3,))
        n[k == 0] = (0.0, 0.0, 1.0)
        n[k == 1] = (0.0, 1.0, 0.0)
        n[k == 2] = n_rec[k == 2]
        for j, b in enumerate(self.boxes):
            m = k == 3 + j
            if m.any():
                n[m] = b.normal(P[m])
        box = np.where((k >= 3) & np.isfinite(t), k - 3, -1).astype(np.int8)
        return t, ids, n, box

    # ---------------------------------------------------------------- shadow rays
    def blocked(self, P: np.ndarray, in_recess: np.ndarray, own: np.ndarray, d: np.ndarray,
                grow: np.ndarray) -> np.ndarray:
        """Is the ray P + s·d (s > 0) blocked by the building, with every occluder grown by ``grow``
        (per point; negative shrinks)? P (M, 3), d one direction (3,) with d_y > 0 (towards the
        street) and d_z > 0; ``own`` the box each point lies on (−1: none), which cannot shadow its
        own lit faces (boxes are convex)."""
        dx, dy, dz = (float(c) for c in d)
        px, py, pz = P[:, 0], P[:, 1], P[:, 2]
        out = np.zeros(len(P), dtype=bool)
        # Recess points: the ray must leave through the opening (grown openings block less).
        if in_recess.any():
            r = np.nonzero(in_recess)[0]
            gr = grow[r]
            s0 = -py[r] / dy
            x = px[r] + s0 * dx
            z = pz[r] + s0 * dz
            # The opening this point belongs to: the one nearest its own (x, z).
            _, xc, z0, z1 = self.window_at(px[r], pz[r], grow=0.3)
            through = (np.abs(x - xc) <= WINDOW_WIDTH / 2 + gr) & (z >= z0 - gr) & (z <= z1 + gr)
            out[r] = ~through
        # Protruding boxes, axis-aligned in the world frame. The ray rises and heads into the
        # street, so only points below a box's top and behind its front can meet it.
        for j, (lo, hi) in enumerate(zip(self.lo, self.hi, strict=True)):
            s_out = (hi[1] + grow - py) / dy                 # where the ray leaves the box's y slab
            reach_x = px + np.maximum(s_out, 0.0) * dx
            cand = ((own != j) & (s_out > 0) & (pz <= hi[2] + grow)
                    & (pz + np.maximum(s_out, 0.0) * dz >= lo[2] - grow)
                    & (np.maximum(px, reach_x) >= lo[0] - grow) & (np.minimum(px, reach_x) <= hi[0] + grow))
            c = np.nonzero(cand & ~out)[0]
            if len(c) == 0:
                continue
            g = grow[c]
            t_near = np.zeros(len(c))
            t_far = np.full(len(c), np.inf)
            for axis, dc in ((0, dx), (1, dy), (2, dz)):
                p = P[c, axis]
                if dc == 0.0:
                    inside = (p >= lo[axis] - g) & (p <= hi[axis] + g)
                    t_far = np.where(inside, t_far, -np.inf)
                    continue
                t1 = (lo[axis] - g - p) / dc
                t2 = (hi[axis] + g - p) / dc
                t_near = np.maximum(t_near, np.minimum(t1, t2))
                t_far = np.minimum(t_far, np.maximum(t1, t2))
            out[c] = (t_near <= t_far) & (t_far > 1e-7)
        return out


def _disc_samples(k: int) -> np.ndarray:
    """k points spread evenly over the unit disc (a Vogel spiral), (k, 2)."""
    j = np.arange(k) + 0.5
    r = np.sqrt(j / k)
    a = j * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


# ----------------------------------------------------------------- the scene

class FacadeSunScene:
    """The facade scene for one configuration: geometry, sun, lighting, pole, ground truth.

    Building it does the ray casting and computes the ground truth; frames are
    produced by :meth:`linear_image` / :meth:`encode`.
    """

    def __init__(self, config: FacadeSunConfig) -> None:
        config.validate()
        self.config = config
        self.W, self.H, self.N = config.width, config.height, config.frames
        self.footprint_radius = max(2, int(round(3.0 * config.blur)))
        self.pad = max(int(math.ceil(4.0 * config.blur)), self.footprint_radius) + 3
        # The camera's motion per frame (px; zero unless it drifts): the padding holds the moved frames.
        self.motion = sensor.camera_motion(self.N, config.drift_px, config.bump_px, config.bump_frame)
        if self.motion.any():
            self.pad = max(self.pad, sensor.shift_margin(config.blur, self.motion))
        p = self.pad
        self.crop = (slice(p, p + self.H), slice(p, p + self.W))
        self.building = _Building()
        self.Q = POLE_BASE.astype(np.float64)
        self.Qtop = self.Q + np.array([0.0, 0.0, POLE_HEIGHT])
        self.pole = geo.Cylinder(self.Q + np.array([0.0, 0.0, POLE_HEIGHT / 2]), (0.0, 0.0, 1.0),
                                 config.pole_radius, POLE_HEIGHT)
        self.post = (geo.Cylinder(POST_BASE + np.array([0.0, 0.0, POST_HEIGHT / 2]), (0.0, 0.0, 1.0),
                                  POST_RADIUS, POST_HEIGHT) if config.post else None)
        self._setup_camera()
        self._setup_sun()
        self._cast_primary_rays()
        self._illumination_series()
        self._pole_planes()
        self._ground_truth()

    # ------------------------------------------------------------- camera
    def _setup_camera(self) -> None:
        self.camera = geo.SceneCamera.scaled(
            self.W, self.H, ref_size=(REF_WIDTH, REF_HEIGHT), ref_focal_px=(REF_FX, REF_FY),
            ref_centre_px=(REF_CX, REF_CY), dist=DISTORTION if self.config.distortion else (0.0,) * 5,
            eye=CAMERA_EYE, target=CAMERA_TARGET, roll_deg=CAMERA_ROLL_DEG)
        self.lens, self.R, self.t = self.camera.lens, self.camera.R, self.camera.t
        self.rvec, self.C = self.camera.rvec, self.camera.centre
        self.camera_distance = float(np.linalg.norm(self.C - FACADE_CENTRE))

    def project(self, X_world: np.ndarray) -> np.ndarray:
        """World points (..., 3) → pixels (..., 2) through the distorted lens."""
        Xc = np.asarray(X_world, dtype=np.float64) @ self.R.T + self.t
        return self.lens.project_cam(Xc)

    # ------------------------------------------------------------- sun
    def _setup_sun(self) -> None:
        from pvlib.atmosphere import alt2pres, get_relative_airmass
        from pvlib.solarposition import get_solarposition

        c = self.config
        t0 = c.start_time()
        self.times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=k * c.interval_s)
                                       for k in range(self.N)]).as_unit("ns")
        sp = get_solarposition(self.times, SITE_LATITUDE, SITE_LONGITUDE, altitude=SITE_ALTITUDE,
                               pressure=float(alt2pres(SITE_ALTITUDE)), method="nrel_numpy",
                               temperature=TEMPERATURE_C, delta_t=DELTA_T_S)
        self.azimuth = sp["azimuth"].to_numpy(np.float64)
        self.elevation = sp["apparent_elevation"].to_numpy(np.float64)
        a, e = np.radians(self.azimuth), np.radians(self.elevation)
        self.sun_enu = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
        self.R_we = R_world_from_enu(HEADING_DEG)
        self.sun_world = self.sun_enu @ self.R_we.T
        if not c.full_day and (self.elevation.min() < 3.0 or (self.sun_world[:, 1] <= 0.05).any()):
            raise GnomonError(
                f"simulate facade_sun: --start {c.start} (for duration_s {c.duration_s:g} s): the sun is below 3° "
                "or behind the facade (it faces 205°); choose a start nearer midday")
        up = self.elevation > 0.0
        am = np.asarray(get_relative_airmass(90.0 - np.where(up, self.elevation, 45.0), model="kastenyoung1989"),
                        dtype=np.float64)
        strength = np.where(up, np.power(0.7, np.power(am, 0.678)), 0.0)
        self.sun_strength = strength / strength[np.argmax(up)] if up.any() else strength

    def sun_at(self, tau) -> np.ndarray:
        """World sun direction at fractional frame(s) tau: the renormalised chord between frames."""
        tau = np.clip(np.asarray(tau, dtype=np.float64), 0.0, self.N - 1.0)
        k = np.minimum(np.floor(tau).astype(int), self.N - 2)
        f = (tau - k)[..., None]
        d = self.sun_world[k] * (1 - f) + self.sun_world[k + 1] * f
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    # ------------------------------------------------------------- geometry
    def _cast_primary_rays(self) -> None:
        p = self.pad
        uu, vv = np.meshgrid(np.arange(-p, self.W + p, dtype=np.float64),
                             np.arange(-p, self.H + p, dtype=np.float64))
        d_cam = self.lens.rays_cam(uu, vv)
        d = d_cam @ self.R
        t, ids, n, box = self.building.cast(self.C, d)
        tp = np.full(t.shape, np.inf) if self.config.roof_edge else self.pole.intersect(self.C, d)
        pole = tp < t
        t = np.where(pole, tp, t)
        ids = np.where(pole, POLE, ids).astype(np.int8)
        if self.post is not None:
            tq = self.post.intersect(self.C, d)
            post = tq < t
            t = np.where(post, tq, t)
            ids = np.where(post, POST, ids).astype(np.int8)
            if post.any():
                n[post] = self.post.normal((self.C + np.where(post, tq, 0.0)[..., None] * d)[post])
            pole = pole | post
        self._own_box_f = np.where(pole, -1, box).astype(np.int8)
        hit = np.isfinite(t)
        ts = np.where(hit, t, 0.0)
        P = self.C + ts[..., None] * d
        if pole.any():
            n[pole] = self.pole.normal(P[pole])
        self.hit_f = hit
        self.object_id_f = np.where(hit, ids, -1).astype(np.int8)
        self.points_f = np.where(hit[..., None], P, np.nan)
        self.depth_f = np.where(hit, ts * d_cam[..., 2], np.nan)
        self.normals_f = np.where(hit[..., None], n, np.nan)
        self._P0 = np.where(hit[..., None], P, 0.0)
        self._depth0 = np.where(hit, ts * d_cam[..., 2], 0.0)
        self._n0 = np.where(hit[..., None], n, 0.0)
        # albedo: smooth textures on the ground (x, y) and the wall and reveals (x, z)
        rng = np.random.default_rng([self.config.seed, 1])

        def texture(a, b, lam_lo, lam_hi):
            tex = np.zeros(a.shape)
            total = 0.0
            for _ in range(4):
                lam = rng.uniform(lam_lo, lam_hi)
                ang = rng.uniform(0.0, np.pi)
                amp = rng.uniform(0.5, 1.0)
                phase = rng.uniform(0, 2 * np.pi)
                tex += amp * np.sin(2 * np.pi / lam * (a * math.cos(ang) + b * math.sin(ang)) + phase)
                total += amp
            return tex / total

        P0 = self._P0
        ground_tex = 0.30 + 0.06 * texture(P0[..., 0], P0[..., 1], 0.7, 3.0)
        wall_tex = 0.60 + 0.08 * texture(P0[..., 0], P0[..., 2], 0.8, 4.0)
        albedo = np.where(ids == GROUND, ground_tex, wall_tex)
        for oid, a in ALBEDO.items():
            albedo = np.where(ids == oid, a, albedo)
        self.albedo_f = np.where(hit, albedo, 0.0)
        self.in_recess_f = hit & ((ids == WINDOW) | (ids == REVEAL))
        nz = self._n0[..., 2]
        ground_bounce = 0.0 if self.config.bounce else GROUND_BOUNCE   # computed instead (outdoor_bounce)
        self.ambient_coef_f = np.where(hit, ((1 + nz) / 2 + ground_bounce * (1 - nz) / 2)
                                       * np.where(self.in_recess_f, RECESS_AO, 1.0), 0.0)
        # Points whose sun ray may meet a building occluder (the others never do).
        self._occ_candidates = hit & (self._P0[..., 1] <= OCCLUDER_Y_MAX + 1e-9) & (ids != POLE)

    # ------------------------------------------------------------- building visibility
    def _spread(self, P: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Distance the disc's rays spread apart before they leave the occluders' zone (y ≤ 1.1)."""
        s_max = np.maximum(OCCLUDER_Y_MAX - P[:, 1], 0.0) / d[1] + 0.05
        return 1.05 * math.tan(RHO) * s_max + 1e-6

    def building_visibility(self, k: int, *, soft: bool | None = None) -> np.ndarray:
        """Visible fraction of the sun's disc past the building at frame k, on the padded grid."""
        soft = self.config.soft_shadows if soft is None else soft
        d = self.sun_world[k]
        vis = np.ones(self.hit_f.shape)
        m = self._occ_candidates & (_dot(self._n0, d) > 0.0)
        if not m.any():
            return vis
        P = self._P0[m] + 1e-6 * self._n0[m]
        rec = self.in_recess_f[m]
        own = self._own_box_f[m]
        if not soft:
            vis[m] = np.where(self.building.blocked(P, rec, own, d, np.zeros(len(P))), 0.0, 1.0)
            return vis
        g = self._spread(P, d)
        surely_dark = self.building.blocked(P, rec, own, d, -g)
        maybe_dark = self.building.blocked(P, rec, own, d, g)
        v = np.where(maybe_dark, 0.0, 1.0)
        unsure = maybe_dark & ~surely_dark
        if unsure.any():
            Pu, ru, ou = P[unsure], rec[unsure], own[unsure]
            e1 = np.cross([0.0, 0.0, 1.0], d)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(d, e1)
            acc = np.zeros(len(Pu))
            zeros = np.zeros(len(Pu))
            for a, b in _disc_samples(DISC_SAMPLES):
                dj = d + math.tan(RHO) * (a * e1 + b * e2)
                dj /= np.linalg.norm(dj)
                acc += ~self.building.blocked(Pu, ru, ou, dj, zeros)
            v[unsure] = acc / DISC_SAMPLES
        vis[m] = v
        return vis

    def _surely_lit(self, k: int) -> np.ndarray:
        """Points (padded grid) that see the whole sun disc past the building at frame k, n·d > 0.05."""
        d = self.sun_world[k]
        if self.elevation[k] < MIN_LIT_ELEVATION_DEG and self.config.full_day:
            return np.zeros(self.hit_f.shape, dtype=bool)
        cos_i = _dot(self._n0, d)
        lit = self.hit_f & (cos_i > 0.05)
        m = self._occ_candidates & lit
        if m.any():
            P = self._P0[m] + 1e-6 * self._n0[m]
            lit[m] = ~self.building.blocked(P, self.in_recess_f[m], self._own_box_f[m], d, self._spread(P, d))
        return lit

    # ------------------------------------------------------------- illumination over time
    def _illumination_series(self) -> None:
        c = self.config
        N = self.N
        s = np.arange(N) / max(N - 1, 1)
        rng = np.random.default_rng([c.seed, 2])
        # auto-exposure gain: two slow sinusoids, ±gain_drift
        f1, f2 = rng.uniform(0.6, 1.2), rng.uniform(1.5, 2.5)
        p1, p2 = rng.uniform(0, 2 * np.pi, 2)
        g = np.sin(2 * np.pi * f1 * s + p1) + 0.5 * np.sin(2 * np.pi * f2 * s + p2)
        g = g / max(np.abs(g).max(), 1e-9)
        self.gain = 1.0 + c.gain_drift * g
        # clouds: smooth dips of the direct sun
        direct = np.ones(N)
        centres: list[float] = []
        for _ in range(c.clouds):
            for _attempt in range(100):
                width = max(2.0, rng.uniform(3.0, 8.0) * N / 200.0)
                k0 = rng.uniform(0.08 * N, 0.92 * N - width)
                if all(abs(k0 - o) > 2.5 * width + 4 for o in centres):
                    break
            centres.append(k0)
            depth = rng.uniform(0.4, 0.8)
            x = (np.arange(N) - k0) / width
            bump = np.where((x > 0) & (x < 1), np.sin(np.pi * np.clip(x, 0, 1)) ** 2, 0.0)
            if bump.max() < 0.5:  # a very short dip still covers a frame fully
                bump[int(round(k0 + width / 2))] = 1.0
            direct *= 1.0 - depth * bump
        self.direct_factor = direct
        self.cloud = direct < 0.99
        # sky: follows the sun's elevation a little, a slow drift, brighter under clouds
        ph = rng.uniform(0, 2 * np.pi)
        el = np.sin(np.radians(np.maximum(self.elevation, 0.0)))
        if c.full_day:  # dusk: the sky fades to 3 % between 0° and −6°
            fade = np.clip((self.elevation + 6.0) / 6.0, 0.03, 1.0)
        else:
            fade = np.ones(N)
        self.sky = SKY_FRACTION * (0.9 + 0.1 * el / el.max()) * (1 + 0.05 * np.sin(2 * np.pi * 0.7 * s + ph)) \
            * (1 + 0.3 * (1 - direct)) * fade
        self.bounce = self._setup_bounce() if c.bounce else None
        # Scale: the brightest surface over all frames (building shadows ignored: a bound) is SURFACE_PEAK.
        peak = 0.0
        for k in range(N):
            cos_i = np.maximum(_dot(self._n0, self.sun_world[k]), 0.0)
            L = self.albedo_f * (self.sky[k] * self.ambient_coef_f + self.sun_strength[k] * direct[k] * cos_i
                                 + self.indirect(k, pole=False))
            peak = max(peak, float(L[self.crop].max()) * self.gain[k])
        self.scale = SURFACE_PEAK / peak

    def _setup_bounce(self) -> outdoor_bounce.FacadeBounce:
        b = self.building
        post = None
        if self.post is not None:
            post = (POST_BASE, POST_BASE + np.array([0.0, 0.0, POST_HEIGHT]), POST_RADIUS)
        layout = outdoor_bounce.FacadeLayout(
            roof_z=ROOF_Z, window_albedo=ALBEDO[WINDOW], boxes=b.boxes,
            box_albedo=[ALBEDO[i] for i in b.box_ids], building=b, pole_base=self.Q, pole_top=self.Qtop,
            pole_radius=self.config.pole_radius, post=post, sun_angular_radius=RHO)
        return outdoor_bounce.FacadeBounce(self, layout)

    def indirect(self, k: int, *, pole: bool = True) -> np.ndarray | float:
        """The bounced irradiance at frame k on the padded grid (the scene's units; 0 without ``bounce``)."""
        return 0.0 if self.bounce is None else self.bounce.irradiance(k, pole=pole)

    # ------------------------------------------------------------- the pole
    def _pole_planes(self) -> None:
        d = self.sun_world
        n = np.cross(np.array([0.0, 0.0, 1.0]), d)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        # Oriented ahead of the moving shadow: where the shadow goes next, n·(X − Q) > 0 now.
        shadow_next = -d[-1] * np.array([1.0, 1.0, 0.0])
        if np.dot(n[0], shadow_next) < 0:
            n = -n
        self.motion_sign = 1.0 if np.dot(np.cross([0.0, 0.0, 1.0], d[0]), n[0]) > 0 else -1.0
        r = self.config.pole_radius
        off = n @ self.Q
        self.planes_center = np.concatenate([n, off[:, None]], axis=-1)
        self.planes_enter = np.concatenate([n, (off + r)[:, None]], axis=-1)
        self.planes_leave = np.concatenate([n, (off - r)[:, None]], axis=-1)

    def pole_occlusion(self, k: int, *, restrict: bool = True) -> np.ndarray:
        """Occluded fraction of the sun's disc by the pole at frame k, on the padded grid."""
        return self._pole_occlusion(self.sun_world[k], restrict=restrict)

    def _pole_occlusion(self, d: np.ndarray, restrict: bool = True, mask: np.ndarray | None = None) -> np.ndarray:
        r = self.config.pole_radius
        P = self._P0
        out = np.zeros(P.shape[:-1])
        m = self.hit_f & (self.object_id_f != POLE) if mask is None else mask.copy()
        rel = P - self.Q
        dh = np.hypot(d[0], d[1])
        along = -(rel[..., 0] * d[0] + rel[..., 1] * d[1]) / dh     # horizontal distance towards the pole
        m &= along > 0
        if restrict:
            n = np.array([-d[1], d[0], 0.0]) / dh
            s = along / dh
            m &= np.abs(rel @ n) <= r + 2.0 * math.tan(RHO) * s + 1e-3
        if not m.any():
            return out
        Pm = P[m]
        f = shadow.occluded_fraction(Pm, Pm + d, math.sin(RHO), self.Q, self.Qtop, r)
        out[m] = f * self._tip_factor(Pm, d)
        return out

    def post_occlusion(self, k: int) -> np.ndarray | float:
        """Occluded fraction of the sun's disc by the lamp post at frame k (padded grid); 0 without one."""
        if self.post is None:
            return 0.0
        d = self.sun_world[k]
        out = np.zeros(self.hit_f.shape)
        m = self.hit_f & (self.object_id_f != POST)
        rel = self._P0 - POST_BASE
        dh = math.hypot(d[0], d[1])
        along = -(rel[..., 0] * d[0] + rel[..., 1] * d[1]) / dh
        n = np.array([-d[1], d[0], 0.0]) / dh
        m &= (along > 0) & (np.abs(rel @ n) <= POST_RADIUS + 2.0 * math.tan(RHO) * along / dh + 1e-3)
        if m.any():
            Pm = self._P0[m]
            out[m] = shadow.occluded_fraction(Pm, Pm + d, math.sin(RHO), POST_BASE,
                                              POST_BASE + np.array([0.0, 0.0, POST_HEIGHT]), POST_RADIUS)
        return out

    def _tip_margin(self, P: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Angular distance (units of ρ) of the pole's top above the sun ray from P, where it passes the axis."""
        rel = P - self.Q
        dh = np.hypot(d[..., 0], d[..., 1])
        along = -(rel[..., 0] * d[..., 0] + rel[..., 1] * d[..., 1]) / dh   # horizontal distance
        s = np.maximum(along / dh, 1e-9)                                     # ray length to the axis
        zc = P[..., 2] + s * d[..., 2]
        return (POLE_HEIGHT - zc) * dh / s / RHO

    def _tip_factor(self, P: np.ndarray, d: np.ndarray) -> np.ndarray:
        return shadow._disc_fraction(self._tip_margin(P, d))

    # ------------------------------------------------------------- ground truth
    def _crossing_times(self, planes_offset: float, P: np.ndarray) -> np.ndarray:
        """Fractional frame at which the plane family n(t)·(X − Q) = offset passes each point P (M, 3)."""
        N = self.N
        n = self.planes_center[:, :3]
        rel = P - self.Q
        g_first = rel @ n[0] - planes_offset
        g_last = rel @ n[N - 1] - planes_offset
        ok = (g_first > 0) & (g_last <= 0)
        times = np.full(len(P), np.nan)
        rel = rel[ok]
        lo = np.zeros(len(rel), dtype=np.int64)
        hi = np.full(len(rel), N - 1, dtype=np.int64)
        while True:
            active = hi - lo > 1
            if not active.any():
                break
            mid = (lo + hi) // 2
            gm = _dot(rel, n[mid]) - planes_offset
            lo = np.where(active & (gm > 0), mid, lo)
            hi = np.where(active & (gm <= 0), mid, hi)
        # Inside [lo, lo + 1]: d ∝ (1 − τ)·d_lo + τ·d_hi, n ∝ s·(z × d), and the condition
        # (1 − τ)·a0 + τ·a1 = offset·|m_h(τ)| with a = s·(z × d)·(X − Q): a fixed point in τ.
        d0, d1 = self.sun_world[lo], self.sun_world[lo + 1]
        z = np.array([0.0, 0.0, 1.0])
        sgn = self.motion_sign
        a0 = sgn * _dot(np.cross(z, d0), rel)
        a1 = sgn * _dot(np.cross(z, d1), rel)
        tau = np.clip(a0 / (a0 - a1), 0.0, 1.0)
        for _ in range(8):
            m = d0 * (1 - tau[:, None]) + d1 * tau[:, None]
            mh = np.hypot(m[:, 0], m[:, 1])
            tau = np.clip((planes_offset * mh - a0) / (a1 - a0), 0.0, 1.0)
        m = d0 * (1 - tau[:, None]) + d1 * tau[:, None]
        resid = (1 - tau) * a0 + tau * a1 - planes_offset * np.hypot(m[:, 0], m[:, 1])
        if np.abs(resid).max(initial=0.0) > 1e-9:  # pragma: no cover
            raise RuntimeError("shadow-time root finding did not converge")
        times[ok] = lo + tau
        return times

    def _ground_truth(self) -> None:
        H, W, N = self.H, self.W, self.N
        r = self.config.pole_radius
        hit = self.hit_f[self.crop]
        P = self._P0[self.crop][hit]
        center = np.full((H, W), np.nan)
        enter = np.full((H, W), np.nan)
        leave = np.full((H, W), np.nan)
        center[hit] = self._crossing_times(0.0, P)
        enter[hit] = self._crossing_times(r, P)
        leave[hit] = self._crossing_times(-r, P)
        # Shadow side only: at the centre time the sun ray from P must run towards the pole.
        tc = center[hit]
        valid = np.isfinite(tc)
        dc = self.sun_at(np.where(valid, tc, 0.0))
        toward = -((P[:, 0] - self.Q[0]) * dc[:, 0] + (P[:, 1] - self.Q[1]) * dc[:, 1]) > 0
        tip = self._tip_margin(P, dc)
        good = valid & toward
        for arr in (center, enter, leave):
            vals = arr[hit]
            vals[~good] = np.nan
            arr[hit] = vals
        not_pole = (self.object_id_f[self.crop] != POLE) & (self.object_id_f[self.crop] != POST)
        for arr in (center, enter, leave):
            arr[~not_pole] = np.nan
        self.center_time, self.enter_time, self.leave_time = center, enter, leave
        # The shadow's depth when the centre plane passes.
        peak = np.full((H, W), np.nan)
        idx = np.nonzero(hit)
        sel = good & not_pole[idx]
        Ps, ds = P[sel], dc[sel]
        f = shadow.occluded_fraction(Ps, Ps + ds, math.sin(RHO), self.Q, self.Qtop, r) * self._tip_factor(Ps, ds)
        pk = np.full(len(P), np.nan)
        pk[sel] = f
        peak[idx] = pk
        self.pole_occlusion_peak = peak
        tip_ok = np.zeros((H, W), dtype=bool)
        tipv = np.zeros(len(P), dtype=bool)
        tipv[good] = tip[good] >= 2.0
        tip_ok[idx] = tipv
        crossed = (enter >= 1.0) & (leave <= N - 2.0) & tip_ok
        # Sunlit at every frame: n·d > 0.05 and the whole disc seen past the building.
        lit = self.hit_f & (self.object_id_f != POLE) & (self.object_id_f != POST)
        # Lit while the pole's shadow passes (a frame either side): the pixel measured it.
        lit_passage = lit[self.crop].copy()
        strict_passage = lit[self.crop].copy()  # the whole disc seen, while the shadow passes
        first = np.floor(np.nan_to_num(enter, nan=np.inf)) - 1
        last = np.ceil(np.nan_to_num(leave, nan=-np.inf)) + 1
        for k in range(N):
            lit_k = self._surely_lit(k)
            lit &= lit_k
            passing = ~((k < first) | (k > last))
            if passing.any():
                # Lit enough for the pole's dip to be there: the sun rendered (above the horizon: the
                # frames draw its dip down to there; MIN_LIT_ELEVATION_DEG is the strict mask's margin),
                # n·d > 0.05 and at least half the sun's disc seen past the building (a building
                # penumbra makes the dip shallower, not absent); the lamp post's shadow at the same
                # time mixes two events: not a clean measurement.
                up = self.sun_strength[k] > 0.0 or not self.config.full_day
                seen_k = (up & (_dot(self._n0, self.sun_world[k]) > 0.05)
                          & (self.building_visibility(k) >= 0.5))[self.crop]
                if self.post is not None:
                    seen_k &= np.asarray(self.post_occlusion(k))[self.crop] < 1e-3
                lit_passage &= seen_k | ~passing
                strict_passage &= (seen_k & lit_k[self.crop]) | ~passing
        if self.config.full_day:
            # A day has nights: "lit at every frame" means nothing; lit while swept is what counts.
            lit = np.zeros_like(lit)
            lit[self.crop] = strict_passage
        self.sunlit_f = lit
        self.sunlit = lit[self.crop]
        # Mixed pixels (as desk_lamp): boundaries, depth jumps, sky and not-sunlit pixels nearby.
        # A depth jump here is a change of surface — another object, another face (normals differ)
        # or a point off the neighbour's plane — not a depth change > 1 %: the ground is seen at a
        # grazing angle, where neighbouring pixels of one plane differ by several per cent.
        oid = self.object_id_f
        Pn, nn = self._P0, self._n0
        edge = ~self.hit_f
        Hf, Wf = oid.shape
        for a, b in (((slice(None), slice(0, Wf - 1)), (slice(None), slice(1, Wf))),
                     ((slice(0, Hf - 1), slice(None)), (slice(1, Hf), slice(None)))):
            off_plane = np.abs(_dot(nn[a], Pn[a] - Pn[b])) > 1e-6 * (1.0 + np.abs(self._depth0[a]))
            jump = ((oid[a] != oid[b]) | ~self.hit_f[a] | ~self.hit_f[b]
                    | (_dot(nn[a], nn[b]) < 0.9999) | off_plane)
            edge[a] |= jump
            edge[b] |= jump
        edge |= ~lit
        rad = self.footprint_radius
        dv, du = np.mgrid[-rad:rad + 1, -rad:rad + 1]
        disc = (du * du + dv * dv <= rad * rad).astype(np.uint8)
        near_edge = cv2.dilate(edge.astype(np.uint8), disc, borderType=cv2.BORDER_CONSTANT,
                               borderValue=0).astype(bool)
        self.unmixed = (self.hit_f & ~near_edge)[self.crop]
        self.swept = self.sunlit & crossed & self.unmixed
        # Crossed while sunlit, mixed or not: where a shadow event was really there to measure.
        self.swept_surface = lit_passage & crossed
        # No cloud frame while the shadow passes.
        cloud_frames = np.nonzero(self.cloud)[0]
        free = self.swept.copy()
        if len(cloud_frames):
            e_in, e_out = enter[self.swept], leave[self.swept]
            clash = np.zeros(len(e_in), dtype=bool)
            for kc in cloud_frames:
                clash |= (kc >= e_in - 1) & (kc <= e_out + 1)
            vals = free[self.swept]
            vals[clash] = False
            free[self.swept] = vals
        self.cloud_free_passage = free
        self.regions = {"ground": self._regions(GROUND), "facade": self._regions(WALL)}
        self.gnomon_obs = self._gnomon_observation()
        if self.bounce is not None:
            self.bounce_truth = self.bounce.truth(
                lambda k: (self.linear_image(k, blur=False, pole=False), self.scale * self.gain[k]), self.crop)
            self.bounce_only = (self.hit_f[self.crop] & ~self.swept_surface
                                & (self.bounce_truth.dip >= outdoor_bounce.BOUNCE_ONLY_DIP))

    # ------------------------------------------------------------- reference regions
    def _regions(self, oid: int, max_regions: int = 3) -> list[list[int]]:
        good = self.swept & (self.object_id == oid)
        min_side = max(3, int(round(0.01 * min(self.W, self.H))))
        min_area = max(30, int(round(0.001 * self.W * self.H)))
        regions: list[list[int]] = []
        mask = good.copy()
        for _ in range(max_regions):
            best = _largest_rectangle(mask)
            if best is None:
                break
            u0, v0, u1, v1 = best
            if (u1 - u0) < min_side or (v1 - v0) < min_side or (u1 - u0) * (v1 - v0) < min_area:
                break
            regions.append([int(u0), int(v0), int(u1), int(v1)])
            mask[max(v0 - 2, 0):v1 + 2, max(u0 - 2, 0):u1 + 2] = False
        if not regions:
            raise GnomonError(
                f"simulate facade_sun: this configuration leaves no bare, swept {OBJECT_NAMES[oid]} "
                "region for the field log's reference planes")
        for u0, v0, u1, v1 in regions:  # belt and braces
            sl = (slice(v0, v1), slice(u0, u1))
            assert (self.object_id[sl] == oid).all() and self.swept[sl].all()
        return regions

    def _gnomon_observation(self) -> dict:
        """The pole's base, top and a point of its ground shadow in one frame (for the heading)."""
        N = self.N
        best = None
        for k in range(N // 5, N - N // 5 + 1):
            d = self.sun_world[k]
            sh = -np.array([d[0], d[1], 0.0]) / math.hypot(d[0], d[1])
            length = POLE_HEIGHT * math.hypot(d[0], d[1]) / d[2]           # shadow length on flat ground
            if sh[1] < 0:
                length = min(length, self.Q[1] / -sh[1])                  # it meets the facade first
            X = self.Q + 0.7 * length * sh
            uv = self.project(np.stack([self.Q, X]))
            if not (np.all(uv >= 0) and uv[:, 0].max() <= self.W - 1 and uv[:, 1].max() <= self.H - 1):
                continue
            span = float(np.hypot(*(uv[1] - uv[0])))
            if best is None or span > best[0]:
                best = (span, k, X)
        if best is None:
            raise GnomonError("simulate facade_sun: the pole's ground shadow is never in view")
        _, k, X = best
        uv = self.project(np.stack([self.Q, self.Qtop, X])) + self.motion[k]   # as seen in that frame
        return {"k": k, "base_px": uv[0].tolist(), "top_px": uv[1].tolist(), "shadow_px": uv[2].tolist(),
                "shadow_world": X.tolist()}

    # ------------------------------------------------------------- images
    def linear_image(self, k: int, *, blur: bool = True, pole: bool = True) -> np.ndarray:
        """Linear radiance (H, W) at frame k, as the camera saw it (moved by ``motion[k]``; without the
        blur, on the still camera's grid)."""
        d = self.sun_world[k]
        cos_i = np.maximum(_dot(self._n0, d), 0.0)
        vis = self.building_visibility(k)
        f = self.pole_occlusion(k) if pole else 0.0
        direct = self.sun_strength[k] * self.direct_factor[k] * cos_i * vis * (1.0 - f) \
            * (1.0 - self.post_occlusion(k))
        L = self.albedo_f * (self.sky[k] * self.ambient_coef_f + direct + self.indirect(k, pole=pole)) * self.scale
        sky_level = SKY_RADIANCE * (self.sky[k] / self.sky.max())
        L = np.where(self.hit_f, L, sky_level / (self.gain.max()))
        return self._finish(L * self.gain[k], blur, self.motion[k] if blur else None)

    def _finish(self, L_full: np.ndarray, blur: bool, shift: np.ndarray | None = None) -> np.ndarray:
        """Blur the padded linear image (the padding holds the real scene) and crop it; ``shift``: the
        camera's motion (px) in that frame (without the blur: the still camera's frame)."""
        return sensor.blur_and_crop(L_full, self.config.blur if blur else 0.0, self.crop, shift)

    def encode(self, L_blurred: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Gamma-encode, add sensor noise, quantise: linear (blurred) radiance → u8."""
        return sensor.encode_dn(L_blurred, self.config.gamma, self.config.noise, rng)

    def frame(self, k: int, rng: np.random.Generator) -> np.ndarray:
        return self.encode(self.linear_image(k), rng)

    # ------------------------------------------------------------- names and times
    def frame_name(self, k: int) -> str:
        return f"{self.times[k]:{TIME_PATTERN}}.{self.config.extension}"

    def local_time(self, k: int) -> pd.Timestamp:
        return self.times[k].tz_convert(SITE_TIMEZONE)

    # ------------------------------------------------------------- crop accessors
    @property
    def object_id(self) -> np.ndarray:
        return self.object_id_f[self.crop]

    @property
    def points(self) -> np.ndarray:
        return self.points_f[self.crop]

    @property
    def depth(self) -> np.ndarray:
        return self.depth_f[self.crop]

    @property
    def normals(self) -> np.ndarray:
        return self.normals_f[self.crop]

    # ------------------------------------------------------------- summaries
    def ground_truth_arrays(self) -> dict[str, np.ndarray]:
        iso = np.array([t.strftime("%Y-%m-%dT%H:%M:%SZ") for t in self.times])
        return {
            "depth": self.depth.astype(np.float32),
            "points_world": self.points.astype(np.float32),
            "normals_world": self.normals.astype(np.float32),
            "object_id": self.object_id,
            "swept": self.swept,
            "swept_surface": self.swept_surface,
            "sunlit": self.sunlit,
            "cloud_free_passage": self.cloud_free_passage,
            "enter_time": self.enter_time.astype(np.float32),
            "leave_time": self.leave_time.astype(np.float32),
            "center_time": self.center_time.astype(np.float32),
            "pole_occlusion_peak": self.pole_occlusion_peak.astype(np.float32),
            "shadow_planes_center": self.planes_center,
            "shadow_planes_enter": self.planes_enter,
            "shadow_planes_leave": self.planes_leave,
            "frame_times_utc": iso,
            "frame_times_utc_ns": self.times.asi8.astype(np.int64),
            "sun_enu": self.sun_enu,
            "sun_world": self.sun_world,
            "sun_azimuth_deg": self.azimuth,
            "sun_elevation_deg": self.elevation,
            "sun_angular_radius_rad": np.float64(RHO),
            "gain": self.gain,
            "cloud": self.cloud,
            "direct_factor": self.direct_factor,
            "sun_strength": self.sun_strength,
            "sky": self.sky,
            "heading_deg": np.float64(HEADING_DEG),
            "R_world_from_enu": self.R_we,
            "K": self.lens.K,
            "dist": self.lens.dist.copy(),
            "rvec": self.rvec.copy(),
            "tvec": self.t.copy(),
            "R": self.R.copy(),
            "t": self.t.copy(),
            "image_size": np.array([self.W, self.H], dtype=np.int64),
            "camera_distance": np.float64(self.camera_distance),
            "units": np.array("m"),
            "pole_base": self.Q.copy(),
            "pole_top": self.Qtop.copy(),
            "pole_radius": np.float64(self.config.pole_radius),
            "camera_motion_px": self.motion.copy(),
            **({"bounce_share": self.bounce_truth.share, "bounce_dip": self.bounce_truth.dip,
                "bounce_dip_frame": self.bounce_truth.dip_frame, "bounce_only": self.bounce_only}
               if self.bounce is not None else {}),
        }

    def field_log(self) -> dict:
        c = self.config
        L = self.lens
        g = self.gnomon_obs
        return {
            "capture": {"frames": f"frames/*.{c.extension}", "units": "m", "gamma": float(c.gamma),
                        "frame_count": int(self.N), "timestamps": "filename", "time_pattern": TIME_PATTERN},
            "camera": {
                "model": "opencv", "width": int(self.W), "height": int(self.H),
                "fx": L.fx, "fy": L.fy, "cx": L.cx, "cy": L.cy, "dist": [float(x) for x in L.dist],
                "pose": {"rvec": [float(x) for x in self.rvec], "tvec": [float(x) for x in self.t]},
            },
            "planes": [
                {"name": "ground", "point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0],
                 "regions": self.regions["ground"]},
                {"name": "facade", "point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0],
                 "regions": self.regions["facade"]},
            ],
            "site": {"latitude": SITE_LATITUDE, "longitude": SITE_LONGITUDE, "altitude": SITE_ALTITUDE,
                     "timezone": SITE_TIMEZONE, "heading_deg": HEADING_DEG},
            "light": {"kind": "sun"},
            "pole": {"base": [float(x) for x in self.Q], "top": [float(x) for x in self.Qtop],
                     "radius": float(c.pole_radius)},
            "gnomon": {"frame": f"frames/{self.frame_name(g['k'])}",
                       "base_px": [round(float(x), 3) for x in g["base_px"]],
                       "top_px": [round(float(x), 3) for x in g["top_px"]],
                       "shadow_px": [round(float(x), 3) for x in g["shadow_px"]]},
            "scan": {"normalize_illumination": True},
        }

    def summary(self) -> dict:
        c = self.config
        sw = self.swept
        by_object = {OBJECT_NAMES[o]: int((sw & (self.object_id == o)).sum()) for o in OBJECT_NAMES}
        return {
            "scene": "facade_day" if c.full_day else "facade_sun",
            "seed": c.seed,
            "config": dataclasses.asdict(c),
            "units": "m",
            "image_size": [self.W, self.H],
            "frame_count": self.N,
            "interval_s": c.interval_s,
            "first_frame_utc": self.times[0].isoformat(),
            "last_frame_utc": self.times[-1].isoformat(),
            "site": {"latitude": SITE_LATITUDE, "longitude": SITE_LONGITUDE, "altitude": SITE_ALTITUDE,
                     "timezone": SITE_TIMEZONE},
            "heading_deg": HEADING_DEG,
            "sun_azimuth_range_deg": [float(self.azimuth.min()), float(self.azimuth.max())],
            "sun_elevation_range_deg": [float(self.elevation.min()), float(self.elevation.max())],
            "sun_angular_diameter_deg": SUN_ANGULAR_DIAMETER_DEG,
            "camera_distance": self.camera_distance,
            **self.camera.summary(),
            "facade_centre_world": FACADE_CENTRE.tolist(),
            "pole": {"base": self.Q.tolist(), "top": self.Qtop.tolist(), "radius": c.pole_radius},
            "gnomon_observation": {"frame": self.frame_name(self.gnomon_obs["k"]), **self.gnomon_obs},
            "cloud_frames": [int(k) for k in np.nonzero(self.cloud)[0]],
            "camera_motion": {"drift_px": c.drift_px, "bump_px": c.bump_px,
                              "bump_frame": sensor.bump_index(self.N, c.bump_frame) if c.bump_px else None,
                              "last_frame_px": self.motion[-1].tolist()},
            "gain_range": [float(self.gain.min()), float(self.gain.max())],
            "radiance_scale": self.scale,
            "regions": self.regions,
            "swept_pixels": int(sw.sum()),
            "swept_fraction": float(sw.mean()),
            "swept_by_object": by_object,
            "cloud_free_passage_pixels": int(self.cloud_free_passage.sum()),
            "object_ids": {str(k): v for k, v in OBJECT_NAMES.items()},
            **({"bounce": {**self.bounce.summary(), "bounce_only_pixels": int(self.bounce_only.sum())}}
               if self.bounce is not None else {}),
            "facade": {"plane": "y = 0", "roof_z": ROOF_Z, "recess_depth": RECESS_DEPTH,
                       "window_width": WINDOW_WIDTH, "window_pitch": WINDOW_PITCH,
                       "window_rows_z": [list(r) for r in WINDOW_ROWS],
                       "ledge": [list(a) for a in LEDGE], "balconies": [[list(a) for a in b] for b in BALCONIES]},
        }


def _largest_rectangle(mask: np.ndarray):
    """The largest axis-aligned all-True rectangle in a boolean image: (u0, v0, u1, v1) or None.

    The classic histogram method, row by row, on the mask's bounding box.
    """
    rows = np.nonzero(mask.any(axis=1))[0]
    cols = np.nonzero(mask.any(axis=0))[0]
    if len(rows) == 0:
        return None
    r0, c0 = int(rows[0]), int(cols[0])
    sub = mask[r0:rows[-1] + 1, c0:cols[-1] + 1]
    H, W = sub.shape
    heights = np.zeros(W, dtype=np.int64)
    best, best_rect = 0, None
    for v in range(H):
        heights = np.where(sub[v], heights + 1, 0)
        hs = heights.tolist() + [0]
        stack: list[int] = []
        for u, h in enumerate(hs):
            left = u
            while stack and hs[stack[-1]] >= h:
                top = stack.pop()
                left = stack[-1] + 1 if stack else 0
                area = hs[top] * (u - left)
                if area > best:
                    best = area
                    best_rect = (c0 + left, r0 + v - hs[top] + 1, c0 + u, r0 + v + 1)
            stack.append(u)
    return best_rect


# ----------------------------------------------------------------- writing a capture

def _exif_bytes(local: pd.Timestamp) -> bytes:
    from PIL import Image

    exif = Image.Exif()
    exif[0x0131] = "gnomon simulate facade_sun"        # Software
    exif[0x0132] = local.strftime("%Y:%m:%d %H:%M:%S")  # DateTime
    ifd = exif.get_ifd(0x8769)
    ifd[0x9003] = local.strftime("%Y:%m:%d %H:%M:%S")   # DateTimeOriginal
    ifd[0x9291] = f"{local.microsecond // 1000:03d}"    # SubSecTimeOriginal
    off = local.utcoffset()
    minutes = int(off.total_seconds() // 60)
    sign = "+" if minutes >= 0 else "-"
    ifd[0x9011] = f"{sign}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}"  # OffsetTimeOriginal
    return exif.tobytes()


def encode_frame(img: np.ndarray, local: pd.Timestamp, jpeg_quality: int) -> bytes:
    """A grey u8 frame → JPEG (or PNG for quality 0) bytes with the EXIF capture time."""
    from PIL import Image

    buf = io.BytesIO()
    im = Image.fromarray(img)
    if jpeg_quality == 0:
        im.save(buf, format="PNG", compress_level=1, exif=_exif_bytes(local))
    else:
        im.save(buf, format="JPEG", quality=int(jpeg_quality), exif=_exif_bytes(local))
    return buf.getvalue()


def _clear_previous(out: Path) -> None:
    """Make a half-written or stale capture in ``out`` unrunnable and remove old frames."""
    (out / "field_log.toml").unlink(missing_ok=True)
    frames = out / "frames"
    if frames.is_dir():
        for p in frames.iterdir():
            if p.is_file() and _NAME_RE.match(p.stem) and p.suffix in (".jpg", ".png"):
                p.unlink()


def simulate_facade_sun(out_dir, config: FacadeSunConfig | None = None, *,
                        progress: Callable[[int, int], None] | None = None,
                        scene: FacadeSunScene | None = None) -> FacadeSunResult:
    """Render the facade/sun time-lapse into ``out_dir``; return what was written.

    Writes ``frames/<UTC time>.{jpg,png}`` (EXIF capture times inside),
    ``ground_truth.npz``, ``ground_truth.json`` and, last, ``field_log.toml``,
    every file atomically. ``progress(done, total)`` is called after each frame. ``scene``: the scene built
    from ``config`` already (a subclass's: :func:`gnomon.simulate.roof_edge.simulate_roof_edge`).
    """
    config = config or FacadeSunConfig()
    config.validate()
    t0 = time.perf_counter()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise GnomonError(f"{out}: exists and is not a directory")
    if scene is None:
        if config.roof_edge:
            raise GnomonError("simulate facade_sun: roof_edge scenes are rendered by "
                              "gnomon.simulate.roof_edge.simulate_roof_edge")
        scene = FacadeSunScene(config)
    out.mkdir(parents=True, exist_ok=True)
    _clear_previous(out)
    frames_dir = out / "frames"
    frames_dir.mkdir(exist_ok=True)
    rng = np.random.default_rng([config.seed, 3])
    paths: list[Path] = []
    for k in range(config.frames):
        img = scene.frame(k, rng)
        path = frames_dir / scene.frame_name(k)
        atomic.write_bytes(path, encode_frame(img, scene.local_time(k), config.jpeg_quality))
        paths.append(path)
        if progress is not None:
            progress(k + 1, config.frames)
    gt_path, json_path = sensor.write_ground_truth(out, scene.ground_truth_arrays(), scene.summary())
    log_path = out / "field_log.toml"
    ext = config.extension
    header = (f"Synthetic capture written by `gnomon simulate facade_sun` (seed {config.seed}).\n"
              "Ground truth: ground_truth.npz and ground_truth.json beside this file.\n"
              f"{config.width}x{config.height}, {config.frames} frames every {config.interval_s} s from "
              f"{scene.times[0]:%Y-%m-%d %H:%M:%S} UTC, noise {config.noise} DN, "
              f"{'PNG' if ext == 'png' else f'JPEG q{config.jpeg_quality}'}, blur {config.blur} px, "
              f"pole radius {config.pole_radius} m, {config.clouds} cloud dips.")
    toml_io.dump(scene.field_log(), log_path, header=header)
    return FacadeSunResult(
        out_dir=out, field_log=log_path, frames=paths, ground_truth=gt_path, ground_truth_json=json_path,
        camera_distance=scene.camera_distance, frame_times=scene.times, regions=scene.regions,
        swept_pixels=int(scene.swept.sum()), swept_fraction=float(scene.swept.mean()),
        seconds=time.perf_counter() - t0, config=config)
