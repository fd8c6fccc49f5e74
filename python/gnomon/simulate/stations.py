"""The ``facade_stations`` scene: one building scanned by the sun from several stations, each georeferenced.

The ``facade_sun`` scene (:mod:`gnomon.simulate.facade_sun`: the facade, the street, the pole and
the real sun at Zurich) filmed by a camera at each station at the same time: station 0 is
``facade_sun``'s tripod, station 1 stands 40 m to its left and further back, (−10, 40, 2.5), looking at (10, 2, 3),
so that both see the part of the facade and ground the pole's shadow sweeps (from opposite sides).

Each station's field log has a world frame of its own, as a surveyor's two set-ups have: station
k's coordinates are ``X_k = R_z(α_k) · X + t_k`` (X the scene's frame, station 0's), its heading
``heading + α_k`` (exact: it sets the sun's direction in the scan), and its ``[site]`` the position
of its own origin, computed exactly and then moved by a *georeference error* of ``error_m`` metres
in a direction drawn from the seed (a phone's GNSS fix), with ``position_sigma_m`` stated. The
truth, ``stations.json``: every station's folder, ``world_from_scene`` (4 × 4) and
``pose_to_reference`` (station k's world → station 0's: what a fusion must find), the georeference
error, and the camera's distance from the facade. The field logs state ``heading_sigma_deg`` 0.1°.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.errors import GnomonError
from gnomon.simulate import geometry as geo
from gnomon.simulate import sensor
from gnomon.simulate.facade_sun import (
    CAMERA_EYE,
    CAMERA_ROLL_DEG,
    CAMERA_TARGET,
    DISTORTION,
    FACADE_CENTRE,
    REF_CX,
    REF_CY,
    REF_FX,
    REF_FY,
    REF_HEIGHT,
    REF_WIDTH,
    FacadeSunConfig,
    FacadeSunScene,
    encode_frame,
)
from gnomon.util import atomic, toml_io

__all__ = ["StationsConfig", "StationsResult", "simulate_stations", "STATIONS"]

#: Each station: camera eye and target (scene frame, m), its frame's turn α (degrees about z) and shift (m).
STATIONS: tuple[dict[str, Any], ...] = (
    {"eye": tuple(CAMERA_EYE), "target": tuple(CAMERA_TARGET), "turn_deg": 0.0, "shift": (0.0, 0.0, 0.0)},
    {"eye": (-10.0, 40.0, 2.5), "target": (10.0, 2.0, 3.0), "turn_deg": 37.0, "shift": (4.0, -9.0, 0.0)},
)
#: The heading's σ the field logs state (degrees): the simulated heading is exact, a surveyed one this good.
HEADING_SIGMA_DEG = 0.1
WGS84_A = 6378137.0
WGS84_E2 = 0.00669437999014


@dataclass(frozen=True)
class StationsConfig(FacadeSunConfig):
    """``facade_sun``'s settings and the stations': ``stations`` (2), ``error_m`` each station's
    georeference error (m, but station 0's: the reference keeps its own), ``position_sigma_m`` the
    uncertainty the field logs state."""

    stations: int = 2
    error_m: float = 1.5
    position_sigma_m: float = 2.0

    def validate(self) -> None:
        super().validate()
        bad = "simulate facade_stations: "
        if not 2 <= self.stations <= len(STATIONS):
            raise GnomonError(f"{bad}stations {self.stations}: 2 to {len(STATIONS)}")
        if not (math.isfinite(self.error_m) and 0 <= self.error_m <= 100):
            raise GnomonError(f"{bad}error_m {self.error_m}: 0 to 100 m")
        if not (math.isfinite(self.position_sigma_m) and 0 < self.position_sigma_m <= 100):
            raise GnomonError(f"{bad}position_sigma_m {self.position_sigma_m}: > 0 and <= 100 m")


class StationScene(FacadeSunScene):
    """``facade_sun`` seen from another place (``eye``, ``target``, scene frame, m)."""

    def __init__(self, config: FacadeSunConfig, eye, target) -> None:
        self.eye, self.target = np.asarray(eye, float), np.asarray(target, float)
        super().__init__(config)

    def _setup_camera(self) -> None:
        self.camera = geo.SceneCamera.scaled(
            self.W, self.H, ref_size=(REF_WIDTH, REF_HEIGHT), ref_focal_px=(REF_FX, REF_FY),
            ref_centre_px=(REF_CX, REF_CY), dist=DISTORTION if self.config.distortion else (0.0,) * 5,
            eye=self.eye, target=self.target, roll_deg=CAMERA_ROLL_DEG)
        self.lens, self.R, self.t = self.camera.lens, self.camera.R, self.camera.t
        self.rvec, self.C = self.camera.rvec, self.camera.centre
        self.camera_distance = float(np.linalg.norm(self.C - FACADE_CENTRE))


def frame_transform(turn_deg: float, shift) -> np.ndarray:
    """(4, 4) scene frame → a station's frame: a turn about z by ``turn_deg``, then ``shift`` (m)."""
    a = math.radians(turn_deg)
    T = np.eye(4)
    T[:3, :3] = [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = shift
    return T


def _move(p, T: np.ndarray) -> list[float]:
    return [float(x) for x in T[:3, :3] @ np.asarray(p, float) + T[:3, 3]]


def offset_site(lat: float, lon: float, alt: float, east: float, north: float, up: float) -> tuple[float, float, float]:
    """The geodetic position ``(east, north, up)`` metres from a site (WGS 84 radii of curvature; the
    Earth's curvature over tens of metres is below 0.1 mm)."""
    phi = math.radians(lat)
    w = math.sqrt(1.0 - WGS84_E2 * math.sin(phi) ** 2)
    n_radius = WGS84_A / w
    m_radius = WGS84_A * (1.0 - WGS84_E2) / w**3
    return (lat + math.degrees(north / (m_radius + alt)),
            lon + math.degrees(east / ((n_radius + alt) * math.cos(phi))), alt + up)


def station_field_log(log: dict, T: np.ndarray, error_enu: np.ndarray, sigma_m: float) -> dict:
    """A ``facade_sun`` field log (scene frame) in a station's frame (``T``: scene → station), its
    ``[site]`` the station origin's position plus ``error_enu`` (m), with ``position_sigma_m``."""
    out = json.loads(json.dumps(log))
    R = T[:3, :3]
    cam = out["camera"]["pose"]
    Rc = geo.rotation_from_rodrigues(cam["rvec"])
    Rn = Rc @ R.T
    cam["rvec"] = [float(x) for x in geo.rodrigues_from_rotation(Rn)]
    cam["tvec"] = [float(x) for x in np.asarray(cam["tvec"]) - Rn @ T[:3, 3]]
    for plane in out["planes"]:
        plane["point"] = _move(plane["point"], T)
        plane["normal"] = [float(x) for x in R @ np.asarray(plane["normal"], float)]
    out["pole"]["base"] = _move(out["pole"]["base"], T)
    out["pole"]["top"] = _move(out["pole"]["top"], T)
    site = out["site"]
    heading = float(site["heading_deg"])
    turn = math.degrees(math.atan2(R[1, 0], R[0, 0]))
    # The station's origin in the scene frame, then in ENU at the scene's site (rows of R_we: world axes).
    h = math.radians(heading)
    R_we = np.array([[math.sin(h), math.cos(h), 0.0], [-math.cos(h), math.sin(h), 0.0], [0.0, 0.0, 1.0]])
    origin = -R.T @ T[:3, 3]
    enu = R_we.T @ origin + error_enu
    lat, lon, alt = offset_site(site["latitude"], site["longitude"], site["altitude"], *enu)
    site.update(latitude=lat, longitude=lon, altitude=alt, heading_deg=(heading + turn) % 360.0,
                position_sigma_m=float(sigma_m), heading_sigma_deg=HEADING_SIGMA_DEG)
    return out


@dataclass
class StationsResult:
    out_dir: Path
    field_logs: list[Path]
    poses_to_reference: list[np.ndarray]
    camera_distance: float
    seconds: float


def simulate_stations(out_dir, config: StationsConfig | None = None, *,
                      progress: Callable[[int, int], None] | None = None) -> StationsResult:
    """Render every station's capture into ``out_dir/station_K/`` and ``stations.json`` (last)."""
    config = config or StationsConfig()
    t0 = time.perf_counter()
    out = sensor.start_captures(out_dir, config, "stations.json")
    rng = np.random.default_rng([config.seed, 29])
    logs, to_ref, entries = [], [], []
    distance = 0.0
    for k in range(config.stations):
        st = STATIONS[k]
        scene = StationScene(config, st["eye"], st["target"])
        folder = out / f"station_{k}"
        frames = folder / "frames"
        frames.mkdir(parents=True, exist_ok=True)
        noise = np.random.default_rng([config.seed, 3, 20 + k])
        for i in range(config.frames):
            img = scene.frame(i, noise)
            atomic.write_bytes(frames / scene.frame_name(i), encode_frame(img, scene.local_time(i),
                                                                         config.jpeg_quality))
            if progress is not None:
                progress(k * config.frames + i + 1, config.stations * config.frames)
        arrays = scene.ground_truth_arrays()
        T = frame_transform(st["turn_deg"], st["shift"])
        phi = rng.uniform(0.0, 2.0 * np.pi)
        error = np.zeros(3) if k == 0 else config.error_m * np.array([math.cos(phi), math.sin(phi), 0.0])
        arrays["world_from_scene"] = T
        sensor.write_ground_truth(folder, arrays, scene.summary())
        log = station_field_log(scene.field_log(), T, error, config.position_sigma_m)
        toml_io.dump(log, folder / "field_log.toml",
                     header=f"Synthetic capture written by gnomon.simulate.stations (seed {config.seed}), station {k}: "
                            "facade_sun seen from another place, in the station's own world frame.")
        logs.append(folder / "field_log.toml")
        T0 = frame_transform(STATIONS[0]["turn_deg"], STATIONS[0]["shift"])
        to_ref.append(T0 @ np.linalg.inv(T))
        entries.append({"folder": folder.name, "eye": list(st["eye"]), "target": list(st["target"]),
                        "world_from_scene": T.tolist(), "pose_to_reference": to_ref[-1].tolist(),
                        "georeference_error_enu_m": error.tolist(), "camera_distance": scene.camera_distance})
        distance = max(distance, scene.camera_distance)
    summary = {"scene": "facade_stations", "units": "m", "seed": config.seed, "config": dataclasses.asdict(config),
               "stations": entries, "position_sigma_m": config.position_sigma_m,
               "pose_to_reference_note": "X_station0 (m) = M[:3, :3] @ X_stationK + M[:3, 3]"}
    atomic.write_text(out / "stations.json", json.dumps(summary, indent=2) + "\n")
    return StationsResult(out, logs, to_ref, distance, time.perf_counter() - t0)
