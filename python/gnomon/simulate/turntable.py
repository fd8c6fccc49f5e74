"""The ``desk_turns`` scene: one object scanned from several places, turned on the desk by known angles.

The set-up of ``desk_lamp`` (the desk z = 0 in millimetres, the same camera, lamp, stick and sensor;
see :mod:`gnomon.simulate.desk_lamp`) with one object in place of its three: a *figure* made of

* a box 120 × 70 × 60 mm (id 2, albedo 0.60), centred at (10, 0, 30) in the figure's own frame;
* a cylinder lying along x on top of it (id 3, albedo 0.65), r = 28 mm, 80 mm long, its axis at
  (25, 12, 60): a barrel roof off the box's middle, its upper half above the box;
* a sphere (id 1, albedo 0.70), r = 30 mm, centred at (−62, −18, 30): it stands on the desk and
  sinks 18 mm into the box's end;
* a chimney (id 4, albedo 0.55), a box 20 × 18 × 30 mm centred at (45, −22, 75), on the roof's side.

No symmetry turns the figure into itself. Between views the figure is turned on the desk about
the vertical through the world origin by ``angles_deg[k]`` and slid by a few millimetres (a hand
turning it: ``slide_mm``, directions from the seed), so view k sees it at
``X_k = R_k · F + t_k`` (F in the figure's frame, R_k a turn about z). The camera, lamp, desk and
the desk's reference bands stay: every view's field log is a ``desk_lamp`` field log, scanned on
its own.

Written into ``DIR``: one capture per view, ``view_K/`` (frames, ``field_log.toml``,
``ground_truth.npz`` and ``.json`` as ``desk_lamp``'s, the figure's own ids), and ``turns.json``:
the views (folder, angle, slide), each view's exact pose ``pose_to_reference`` — the 4 × 4 matrix
taking view K's world coordinates (mm) to view 0's, the reference frame of a fusion — the camera's
distance from the scene centre and the figure's description. :func:`figure_distance` is the
figure's exact distance function (the true surface a fusion is compared with);
:func:`seen_surface` the true surface points the views swept, in the reference frame.
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

from gnomon.simulate import geometry as geo
from gnomon.simulate import sensor
from gnomon.simulate.desk_lamp import (
    BOX,
    CYLINDER,
    SPHERE,
    DeskLampConfig,
    DeskLampScene,
    clear_previous,
    nuisance_text,
    write_frames,
)
from gnomon.util import atomic, toml_io

__all__ = ["TurnsConfig", "TurnsResult", "TurnedDeskScene", "figure_distance", "seen_surface", "simulate_turns"]

# The figure, in its own frame (mm): what each solid is, and its albedo.
FIG_BOX: dict[str, Any] = {"centre": (10.0, 0.0, 30.0), "size": (120.0, 70.0, 60.0)}
FIG_ROOF: dict[str, Any] = {"centre": (25.0, 12.0, 60.0), "axis": (1.0, 0.0, 0.0), "radius": 28.0, "length": 80.0}
FIG_SPHERE: dict[str, Any] = {"centre": (-62.0, -18.0, 30.0), "radius": 30.0}
FIG_CHIMNEY: dict[str, Any] = {"centre": (45.0, -22.0, 75.0), "size": (20.0, 18.0, 30.0)}
CHIMNEY = 4
ALBEDO = {SPHERE: 0.70, BOX: 0.60, CYLINDER: 0.65, CHIMNEY: 0.55}
MAX_VIEWS = 12


def turn(angle_deg: float, shift_mm) -> np.ndarray:
    """(4, 4) the figure's pose on the desk: a turn by ``angle_deg`` about z, then a slide (mm)."""
    a = math.radians(angle_deg)
    T = np.eye(4)
    T[:3, :3] = [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]]
    T[:2, 3] = np.asarray(shift_mm, dtype=np.float64)[:2]
    return T


def figure_solids(pose: np.ndarray) -> dict[int, tuple[geo.Surface, float]]:
    """The figure's four solids placed by ``pose`` (4 × 4, figure → world), with their albedos."""
    R, t = pose[:3, :3], pose[:3, 3]
    yaw = math.degrees(math.atan2(R[1, 0], R[0, 0]))
    return {
        SPHERE: (geo.Sphere(R @ FIG_SPHERE["centre"] + t, FIG_SPHERE["radius"]), ALBEDO[SPHERE]),
        BOX: (geo.Box(R @ FIG_BOX["centre"] + t, FIG_BOX["size"], yaw), ALBEDO[BOX]),
        CYLINDER: (geo.Cylinder(R @ FIG_ROOF["centre"] + t, R @ FIG_ROOF["axis"], FIG_ROOF["radius"],
                                FIG_ROOF["length"]), ALBEDO[CYLINDER]),
        CHIMNEY: (geo.Box(R @ FIG_CHIMNEY["centre"] + t, FIG_CHIMNEY["size"], yaw), ALBEDO[CHIMNEY]),
    }


def figure_distance(points) -> np.ndarray:
    """Distance (mm) of points (N, 3), given in the figure's frame, from the figure's true surface.

    The union of the four solids' exact distance functions; a point inside the figure is measured
    to the nearest surface of the solid it lies deepest in (exact wherever one solid's surface is
    the figure's, which is everywhere but within a distance of the lines where two solids meet).
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)

    def box_sdf(box: dict) -> np.ndarray:
        q = np.abs(P - box["centre"]) - np.asarray(box["size"]) / 2.0
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    sphere = np.linalg.norm(P - FIG_SPHERE["centre"], axis=1) - FIG_SPHERE["radius"]
    c = np.asarray(FIG_ROOF["centre"])
    along = np.abs(P[:, 0] - c[0]) - FIG_ROOF["length"] / 2.0
    radial = np.hypot(P[:, 1] - c[1], P[:, 2] - c[2]) - FIG_ROOF["radius"]
    d2 = np.stack([radial, along], axis=1)
    roof = np.linalg.norm(np.maximum(d2, 0.0), axis=1) + np.minimum(d2.max(axis=1), 0.0)
    return np.abs(np.minimum.reduce([box_sdf(FIG_BOX), sphere, roof, box_sdf(FIG_CHIMNEY)]))


@dataclass(frozen=True)
class TurnsConfig(DeskLampConfig):
    """Parameters of ``gnomon simulate desk_turns``: the desk-lamp capture's (no pencil photos by
    default) and the turns.

    ``views``: how many places (2 to 12); ``angles_deg``: the figure's turn in each view about the
    desk's normal (default: evenly spaced, 360°/views apart, starting at 0); ``slide_mm``: how far
    the figure is slid on the desk between views (each view's slide is drawn from the seed, up to this).
    """

    views: int = 4
    angles_deg: tuple[float, ...] | None = None
    slide_mm: float = 8.0
    pencil_photos: int = 0

    @property
    def scene_name(self) -> str:
        return "desk_turns"

    def turns(self) -> list[float]:
        if self.angles_deg is not None:
            return [float(a) for a in self.angles_deg]
        return [360.0 * k / self.views for k in range(self.views)]

    def validate(self) -> None:
        super().validate()
        if not 2 <= self.views <= MAX_VIEWS:
            raise self.error(f"--views {self.views}: must be 2 to {MAX_VIEWS}")
        if self.angles_deg is not None and (len(self.angles_deg) != self.views
                                            or not all(math.isfinite(a) for a in self.angles_deg)):
            raise self.error(f"angles_deg {self.angles_deg}: one finite angle per view ({self.views})")
        if not (math.isfinite(self.slide_mm) and 0 <= self.slide_mm <= 30):
            raise self.error(f"slide_mm {self.slide_mm}: must be 0 to 30 mm")
        if self.lamp_side != "left" or self.lamp_above_camera is not None:
            raise self.error("the turns keep desk_lamp's lamp (left of the camera)")

    def poses(self) -> list[np.ndarray]:
        """Each view's figure → world pose (4 × 4, mm): the turn and the slide (from the seed)."""
        rng = np.random.default_rng([self.seed, 17])
        out = []
        for k, a in enumerate(self.turns()):
            phi = rng.uniform(0.0, 2.0 * np.pi)
            r = 0.0 if k == 0 else self.slide_mm * rng.uniform(0.5, 1.0)
            out.append(turn(a, (r * math.cos(phi), r * math.sin(phi))))
        return out


class TurnedDeskScene(DeskLampScene):
    """The desk-lamp set-up with the figure placed by ``pose`` (figure → world, 4 × 4, mm)."""

    def __init__(self, config: TurnsConfig, pose: np.ndarray) -> None:
        self.pose = np.asarray(pose, dtype=np.float64)
        super().__init__(config)

    def _objects(self) -> dict[int, tuple[geo.Surface, float]]:
        return figure_solids(self.pose)

    def summary(self) -> dict:
        out = self.summary_common()
        out.update(regions=self.regions, figure_pose=self.pose.tolist(), objects=figure_summary(),
                   object_ids={"0": "desk", str(SPHERE): "sphere", str(BOX): "box", str(CYLINDER): "roof",
                               str(CHIMNEY): "chimney"})
        return out


def figure_summary() -> dict:
    return {"box": {"id": BOX, **FIG_BOX, "albedo": ALBEDO[BOX]},
            "roof": {"id": CYLINDER, **FIG_ROOF, "albedo": ALBEDO[CYLINDER]},
            "sphere": {"id": SPHERE, **FIG_SPHERE, "albedo": ALBEDO[SPHERE]},
            "chimney": {"id": CHIMNEY, **FIG_CHIMNEY, "albedo": ALBEDO[CHIMNEY]},
            "frame": "the figure's own; view K's world = pose_K · figure"}


@dataclass
class TurnsResult:
    """What :func:`simulate_turns` wrote."""

    out_dir: Path
    views: list[Path]          # view_K/ folders, each with field_log.toml
    field_logs: list[Path]
    poses_to_reference: list[np.ndarray]  # (4, 4) view K's world → view 0's world, mm
    camera_distance_mm: float
    seconds: float
    config: TurnsConfig


def simulate_turns(out_dir, config: TurnsConfig | None = None, *,
                   progress: Callable[[int, int], None] | None = None) -> TurnsResult:
    """Render ``config.views`` captures of the figure turned on the desk into ``out_dir`` (see the module).

    Each view is written atomically file by file, its field log last; ``turns.json`` is written last
    of all, so a folder with ``turns.json`` holds every view. ``progress(done, total)`` counts frames
    over all views.
    """
    config = config or TurnsConfig()
    t0 = time.perf_counter()
    out = sensor.start_captures(out_dir, config, "turns.json")
    poses = config.poses()
    total = config.views * config.frames
    folders, logs, to_ref = [], [], []
    distance = 0.0
    for k, pose in enumerate(poses):
        scene = TurnedDeskScene(config, pose)
        folder = out / f"view_{k}"
        folder.mkdir(exist_ok=True)
        clear_previous(folder)
        done = k * config.frames

        def step(i: int, n: int, done: int = done) -> None:
            if progress is not None:
                progress(done + i, total)
        write_frames(scene, folder, np.random.default_rng([config.seed, 3, 10 + k]), step)
        arrays = scene.ground_truth_arrays()
        arrays["figure_pose"] = pose
        sensor.write_ground_truth(folder, arrays, scene.summary())
        header = (f"Synthetic capture written by `gnomon simulate desk_turns` (seed {config.seed}), view {k} of "
                  f"{config.views}: the figure turned by {config.turns()[k]:g} deg.\n"
                  "Ground truth: ground_truth.npz and ground_truth.json beside this file, ../turns.json.\n"
                  + nuisance_text(config))
        toml_io.dump(scene.field_log(), folder / "field_log.toml", header=header)
        folders.append(folder)
        logs.append(folder / "field_log.toml")
        to_ref.append(poses[0] @ np.linalg.inv(pose))
        distance = scene.camera_distance
    summary = {
        "scene": "desk_turns", "units": "mm", "seed": config.seed, "config": dataclasses.asdict(config),
        "camera_distance_mm": distance,
        "reference_view": 0,
        "views": [{"folder": f.name, "angle_deg": a, "figure_pose": p.tolist(), "pose_to_reference": T.tolist()}
                  for f, a, p, T in zip(folders, config.turns(), poses, to_ref, strict=True)],
        "pose_to_reference_note": "X_view0 (mm) = M[:3, :3] @ X_viewK + M[:3, 3]",
        "figure": figure_summary(),
    }
    atomic.write_text(out / "turns.json", json.dumps(summary, indent=2) + "\n")
    return TurnsResult(out, folders, logs, to_ref, distance, time.perf_counter() - t0, config)


def seen_surface(turns_dir) -> tuple[np.ndarray, np.ndarray]:
    """The true surface points of the figure the views swept (pixels' exact surface points, desk left
    out), in the reference frame (view 0's world, mm), and in the figure's frame: ``(reference, figure)``."""
    folder = Path(turns_dir)
    summary = json.loads((folder / "turns.json").read_text())
    ref, fig = [], []
    for v in summary["views"]:
        with np.load(folder / v["folder"] / "ground_truth.npz") as gt:
            m = gt["swept"] & (gt["object_id"] > 0)
            P = gt["points_world"][m].astype(np.float64)
        T = np.asarray(v["pose_to_reference"])
        F = np.linalg.inv(np.asarray(v["figure_pose"]))
        ref.append(P @ T[:3, :3].T + T[:3, 3])
        fig.append(P @ F[:3, :3].T + F[:3, 3])
    return np.concatenate(ref), np.concatenate(fig)
