"""`gnomon fuse SCAN... --out MODEL` and ``gnomon.fuse(...)``: several scans of one object made into one model.

The stages, in order: read the scan folders (:func:`gnomon.fuse.views.read_view`) and check that
they can go together; register them (:func:`gnomon.fuse.model.register_views`); fuse their points
and make the surface (:func:`gnomon.fuse.model.fuse_surface`); write the model into a staging
folder (mesh.ply with σ per vertex, points.ply, the mesh formats asked for, report.json, fuse.rrd)
published all at once. A georeferenced survey's model is written in East-North-Up metres at the
first station's site, and its points also as points.laz in the site's projected CRS (as a sun
scan's); a desk object's model in the first scan's world frame.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.errors import GnomonError
from gnomon.fuse.model import FuseSettings, Registration, fuse_surface, prepare_view, register_views
from gnomon.fuse.o3d import open3d
from gnomon.fuse.record import record_fusion
from gnomon.fuse.registration import rotation_angle_deg
from gnomon.fuse.surface import FusedMesh, FusedPoints
from gnomon.fuse.views import View, check_views, read_view
from gnomon.outputs import ply
from gnomon.outputs.obj import write_obj
from gnomon.outputs.publish import staged_outputs
from gnomon.outputs.scan_files import json_default
from gnomon.outputs.stl import write_stl
from gnomon.recording.worker import RecordingChoice, open_recorder
from gnomon.util import atomic

__all__ = ["FuseResult", "FUSE_OUTPUTS", "FUSE_MESH_FORMATS", "Recording", "fuse_scans"]

#: The mesh formats a fused model can be written in (mesh.ply always).
FUSE_MESH_FORMATS = ("ply", "obj", "stl")
#: Every file a fusion publishes into its folder.
FUSE_OUTPUTS = ("mesh.ply", "mesh.obj", "mesh.stl", "points.ply", "points.laz", "report.json", "fuse.rrd")


@dataclass
class Recording:
    """Whether a fusion writes ``OUT/fuse.rrd`` (a :class:`gnomon.recording.worker.RecordingChoice`)."""

    rrd: bool = True
    view: bool = False
    frame_stride: int = 10


@dataclass
class FuseResult:
    """A fusion: the views, their registration, the fused points and mesh (in the model's frame:
    ``to_output`` @ reference frame), its report and where it was written."""

    views: list[View]
    registration: Registration
    points: FusedPoints
    mesh: FusedMesh
    to_output: np.ndarray
    frame: str
    report: dict[str, Any]
    folder: Path | None


def _output_frame(views: list[View]) -> tuple[np.ndarray, str, str]:
    """(4, 4) reference frame → the model's frame, its description and units."""
    ref = views[0]
    if ref.site is None:
        return np.eye(4), f"the world frame of {ref.folder} (the first scan)", ref.units
    M = np.asarray(ref.site["world_to_enu"], dtype=np.float64)
    return M, (f"East-North-Up metres at the first station's site (latitude {ref.site['latitude_deg']}, "
               f"longitude {ref.site['longitude_deg']}, altitude {ref.site['altitude_m']} m)"), "m"


def _write_survey_cloud(path: Path, fused: FusedPoints, to_enu: np.ndarray, site: dict[str, Any]) -> None:
    """The fused points of a survey in the site's projected CRS (UTM, the site's vertical datum), LAZ."""
    from gnomon.outputs.crs import survey_frame
    from gnomon.outputs.las import RESOLUTION, write_las

    metres = float(np.cbrt(abs(np.linalg.det(to_enu[:3, :3]))))
    enu = fused.points @ to_enu[:3, :3].T + to_enu[:3, 3]
    frame = survey_frame(site)
    write_las(path, frame.from_enu(enu, site), frame.crs, resolution=RESOLUTION["m"], rgb=fused.rgb,
              sigma=fused.sigma * metres,
              normals=frame.directions_from_enu(fused.normals @ (to_enu[:3, :3] / metres).T, site))


def _report(views: list[View], reg: Registration, fused: FusedPoints, mesh: FusedMesh, frame: str, units: str,
            scale: float, seconds: dict[str, float], mesh_formats: tuple[str, ...]) -> dict[str, Any]:
    d = reg.distance
    rel = 100.0 / d

    def pair(i: int, j: int, p, residual=None) -> dict[str, Any]:
        out = {"views": [i, j], "overlap": p.overlap, "rms": p.rms * scale, "rms_sigma": p.rms_sigma,
               "partners": p.pairs}
        if residual is not None:
            out.update(residual_deg=residual.rotation_deg, residual_displacement=residual.displacement * scale,
                       residual_percent_of_distance=residual.displacement * rel)
        return out

    residual = {(r.source, r.target): r for r in reg.residuals}
    holes = [{"edges": h.edges, "perimeter": h.perimeter * scale, "centre": h.centre, "where": h.where}
             for h in mesh.holes]
    unseen = [h for h in mesh.holes if h.where == "unseen"]
    loop = None
    if reg.loop is not None:
        loop = {**reg.loop, "displacement": reg.loop["displacement"] * scale,
                "percent_of_distance": reg.loop["displacement"] * rel}
    return {
        "inputs": [str(v.folder) for v in views],
        "units": units,
        "frame": frame,
        "reference_view": 0,
        "distance": d * scale,
        "distance_note": "the cameras' median distance to the object; the relative figures are of it",
        "views": [{"folder": str(v.folder), "pose": P.tolist(), "rotation_deg": rotation_angle_deg(P),
                   "translation": float(np.linalg.norm(P[:3, 3])) * scale, "object_points": int(v.object_mask.sum()),
                   "setup_points": v.setup_points,
                   "setup_planes": [{"normal": pl.normal.tolist(), "offset": pl.offset, "share": pl.share}
                                    for pl in v.planes]}
                  for v, P in zip(views, reg.poses, strict=True)],
        "views_note": "pose: X_reference = M[:3, :3] @ X_view + M[:3, 3], the first scan's world frame and units",
        "registration": {
            "pairs": [pair(i, j, p, residual.get((i, j))) for (i, j), p in reg.pairs.items()],
            "left_out_little_overlap": [pair(i, j, p) for (i, j), p in reg.rejected.items()],
            "left_out_disagreeing_with_loop": [pair(i, j, p) for (i, j), p in reg.inconsistent.items()],
            "loop_closure": loop,
            "loop_closure_note": "the pairs' transforms composed around the views in order, before the pose graph",
            "stations": reg.stations,
            "spacing": reg.spacing * scale,
        },
        "model": {
            "points": int(len(fused.points)), "vertices": int(len(mesh.vertices)), "faces": int(len(mesh.faces)),
            "pieces": mesh.pieces, "watertight": mesh.watertight, "edge_manifold": mesh.edge_manifold,
            "closed_where_seen": not unseen,
            "holes": holes,
            "sigma_median": float(np.median(mesh.sigma)) * scale if len(mesh.sigma) else None,
            "points_seen_by_views": {str(k): int(np.count_nonzero(fused.views == k))
                                     for k in range(1, len(views) + 1)},
            "mesh_formats": list(mesh_formats),
        },
        "warnings": list(reg.warnings),
        "timings_s": seconds,
    }


def fuse_scans(scans: Sequence[str | os.PathLike], out_dir: str | os.PathLike | None = None, *,
               voxel: float | None = None, mesh_formats: tuple[str, ...] = ("ply",), rrd: bool = True,
               settings: FuseSettings | None = None, recording: RecordingChoice | None = None) -> FuseResult:
    """Fuse scan folders (2 or more) into one model; write it into ``out_dir`` (None: in memory only).

    ``voxel`` the fusion's grid (world units; default the scans' median point spacing), ``mesh_formats``
    of :data:`FUSE_MESH_FORMATS`, ``rrd`` write ``fuse.rrd``; ``settings`` all of
    :class:`~gnomon.fuse.model.FuseSettings` (its ``voxel`` is overridden by ``voxel``). Bad input (a
    folder that is not a scan, units that differ, a scan that overlaps none of the others) raises a
    :class:`GnomonError` naming it, and nothing is written.
    """
    opts: RecordingChoice = recording or Recording(rrd=rrd)
    if voxel is not None:
        settings = dataclasses.replace(settings or FuseSettings(), voxel=float(voxel))
    open3d()  # the one-line install hint before anything is read
    t0 = time.perf_counter()
    for f in mesh_formats:
        if f not in FUSE_MESH_FORMATS:
            raise GnomonError(f"--mesh-formats {f}: a fused model is written as {', '.join(FUSE_MESH_FORMATS)}")
    if len(scans) < 2:
        raise GnomonError("fuse: needs at least two scans")
    # Every input is read and checked before any is worked on, so that a bad one is named first;
    # then read again one at a time: a desk scan keeps only its object (memory: the object, not the desk).
    first = read_view(scans[0])
    for scan in scans[1:]:
        check_views([first, read_view(scan)])
    del first
    views: list[View] = []
    for scan in scans:
        view = read_view(scan)
        prepare_view(view, settings)
        views.append(view)
    check_views(views)
    t1 = time.perf_counter()
    reg = register_views(views, settings)
    t2 = time.perf_counter()
    fused, mesh = fuse_surface(views, reg, None if settings is None else settings.voxel)
    t3 = time.perf_counter()
    to_output, frame, units = _output_frame(views)
    scale = float(np.cbrt(abs(np.linalg.det(to_output[:3, :3]))))
    seconds = {"read": t1 - t0, **{f"register_{k}": v for k, v in reg.seconds.items()}, "fuse": t3 - t2}
    report = _report(views, reg, fused, mesh, frame, units, scale, seconds, mesh_formats)
    result = FuseResult(views, reg, fused, mesh, to_output, frame, report, None)
    if out_dir is None:
        return result
    R, t = to_output[:3, :3], to_output[:3, 3]
    V = (mesh.vertices @ R.T + t).astype(np.float32)
    comments = [ply.units_comment(units), f"gnomon fuse of {len(views)} scans; frame: {frame}"]
    with staged_outputs(Path(out_dir), outputs=FUSE_OUTPUTS) as staging:
        recorder = open_recorder(staging, opts, f"fuse {len(views)} scans", "fuse.rrd")
        try:
            normals = (mesh.normals @ (R / scale).T).astype(np.float32)
            ply.write_mesh_ply(staging / "mesh.ply", V, mesh.faces, mesh.rgb, comments, normals,
                               (mesh.sigma * scale).astype(np.float32))
            ply.write_points_ply(staging / "points.ply", (fused.points @ R.T + t).astype(np.float32), fused.rgb,
                                 (fused.sigma * scale).astype(np.float32), None, comments,
                                 (fused.normals @ (R / scale).T).astype(np.float32))
            if "obj" in mesh_formats:
                write_obj(staging / "mesh.obj", V, mesh.faces, normals=normals)
            if "stl" in mesh_formats:
                write_stl(staging / "mesh.stl", V, mesh.faces, header=f"gnomon fuse, {units}")
            site = views[0].site
            if site is not None:  # a survey's cloud also in its projected CRS, as a sun scan's (points.laz)
                _write_survey_cloud(staging / "points.laz", fused, to_output, site)
            if recorder is not None:
                record_fusion(recorder, views, reg, fused, mesh, to_output, report)
                recorder.close()
                recorder = None
            report["timings_s"]["total_s"] = time.perf_counter() - t0
            atomic.write_text(staging / "report.json", json.dumps(report, indent=2, default=json_default) + "\n")
        finally:
            if recorder is not None:
                recorder.abort()
    result.folder = Path(out_dir)
    return result
