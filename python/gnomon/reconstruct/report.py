"""report.json's content: what a scan measured, how, from which inputs, with which warnings."""

from __future__ import annotations

from typing import Any

import numpy as np

from gnomon import __version__
from gnomon.camera.calibration import camera_to_table
from gnomon.capture.frames import FrameSource, sha256_file
from gnomon.capture.tracking import (
    MIN_CONTRAST_SIGMAS,
    TrackedSequence,
)
from gnomon.config.setup import ScanSetup
from gnomon.errors import Remark
from gnomon.geometry.meshing import (
    GridMesh,
)
from gnomon.reconstruct.edges import EdgeResult, min_contrast_dn
from gnomon.reconstruct.fused import FusedMaps


def scan_report(setup: ScanSetup, source: FrameSource, tracked: TrackedSequence, edges: list[EdgeResult],
            fused: FusedMaps, mesh: GridMesh, timings: dict[str, float], warnings: list[str]) -> dict[str, Any]:
    cam, inputs, tr = setup.camera, setup.inputs, setup.tracker
    times, keep, sigma = tracked.times, fused.keep, fused.sigma
    return {
        "gnomon_version": __version__,
        "field_log": str(inputs.field_log),
        "units": setup.units,
        "inputs": {
            "field_log_sha256": sha256_file(inputs.field_log),
            "frames_sha256": source.frames_digest(),
            "camera_file_sha256": sha256_file(inputs.camera_file) if inputs.camera_file else None,
            "frames": tracked.n_frames,
            "image_size": [cam.width, cam.height],
            # capture frames of sudden illumination dips (clouds) tracked levelled pixel by pixel
            "levelled_frames": [int(i) for i in tracked.levelled],
        },
        "camera": camera_report(setup),
        "calibration": inputs.calibration,
        **setup.light.report([e.planes for e in edges], warnings),
        "settings": {
            "min_contrast_dn": min_contrast_dn(tr.min_contrast, tracked.noise_dn),
            "min_contrast_from": ("field log" if tr.min_contrast is not None
                                  and tr.min_contrast >= MIN_CONTRAST_SIGMAS * tracked.noise_dn else "image noise"),
            "window": tr.window, "max_dip_frames": tr.max_width,
            "max_dip_frames_from": setup.dip_width, "edge": setup.edge,
            "max_depth_jump": setup.max_depth_jump, "gamma": tr.gamma, "register": tr.register,
        },
        "noise": {"image_noise_dn": tracked.noise_dn,
                  "median_sigma_z": float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else None},
        # the edges as the fusion saw them: the points refused afterwards for want of direct light included
        "edges": edges_report(edges, keep if fused.no_direct_light is None else keep | fused.no_direct_light),
        "coverage": {
            "pixels": cam.width * cam.height,
            "contrast_ok": int(times.valid.sum()),
            "points": int(keep.sum()),
            "fraction_of_image": float(keep.mean()),
            "fraction_of_contrast_ok": float(keep.sum() / max(int(times.valid.sum()), 1)),
            "edge_conflicts": int(fused.conflict.sum()),
            # points (kept) whose σZ exceeds max_depth_jump·Z / (5·√2) (gnomon.reconstruct.fusion.beyond_trust)
            "sigma_beyond_jump": int(fused.untrusted.sum()),
            "undersampled": int(fused.undersampled.sum()),
            # points refused because the light's own shadow did not make their dip, by reason
            # (gnomon.reconstruct.fused.screen_direct_light; a lamp's light only)
            **({"no_direct_light": fused.direct_light_refused} if fused.direct_light_refused is not None else {}),
            # pixels whose lit level is at the input's full scale (clipped: the shadow's edges
            # look steeper and its width narrower there)
            "saturated": int((times.imax >= len(tracked.lut) - 1).sum()),
            # pixels with two comparable dips (no point), and with clipped samples
            "ambiguous": int(np.count_nonzero(
                times.ambiguous & (times.contrast >= min_contrast_dn(tr.min_contrast, tracked.noise_dn)))),
            "clipped": int(np.count_nonzero(times.clipped)),
            "mesh_vertices": int(len(mesh.vertices)),
            "mesh_faces": int(len(mesh.faces)),
        },
        "timings_s": timings,
        "reference_planes": inputs.reference_planes,
        **({"tracking": tracked.info} if tracked.info else {}),
        # each frame's motion against the reference frame (gnomon.capture.registration)
        **({"registration": tracked.registration.report()} if tracked.registration is not None else {}),
    }


def camera_report(setup: ScanSetup) -> dict[str, Any]:
    """report.json's camera: the camera table and its pose (world → camera)."""
    pose = setup.pose
    return {**camera_to_table(setup.camera), "pose": {"rvec": pose.rvec.tolist(), "tvec": pose.t.tolist()}}


def edges_report(edges: list[EdgeResult], keep: np.ndarray) -> dict[str, Any]:
    report: dict[str, Any] = {}
    for e in edges:
        report[e.name] = {
            "shadow_planes": int(np.isfinite(e.planes[:, 0]).sum()),
            "degenerate_frames": e.degenerate,
            "rejected": e.rejected,
            "triangulated": int(np.isfinite(e.depth).sum()),
            "ray_plane_angle_deg": (None if e.ray_plane_angle_deg is None
                                    else dict(zip(("p10", "p50", "p90"), e.ray_plane_angle_deg, strict=True))),
            "grazing_share": None if e.grazing is None else e.grazing[0],  # under GRAZING_DEG
            "unmodelled_sigma_t_frames": e.unmodelled_sigma_t,
            "reference_lines": [
                {"plane": ln.plane_name, "frames_with_line": int(ln.found.sum()),
                 "extrapolated": int(ln.extrapolated.sum()),
                 "median_rms": float(np.nanmedian(ln.rms)) if ln.found.any() else None}
                for ln in e.lines
            ],
        }
    if len(edges) == 2:
        # Over the pixels where both edges were fused into an output point: a
        # pair in conflict (beyond max_depth_jump) is an outlier, not noise, and
        # is counted apart (its squared σ-distance would swamp the statistic).
        measured = np.isfinite(edges[0].depth) & np.isfinite(edges[1].depth)
        both = measured & keep
        diff = (edges[0].depth - edges[1].depth)[both]
        comb = np.sqrt(edges[0].sigma ** 2 + edges[1].sigma ** 2)[both]
        if diff.size:
            report["disagreement"] = {
                "pixels": int(both.sum()),
                "not_fused": int((measured & ~keep).sum()),
                "mean": float(np.mean(diff)),
                "rms": float(np.sqrt(np.mean(diff**2))),
                "median_abs": float(np.median(np.abs(diff))),
                "rms_in_sigmas": float(np.sqrt(np.nanmean((diff / comb) ** 2))),
            }
    return report


def report_outputs(report: dict[str, Any], setup: ScanSetup, cropped: np.ndarray, cpu: dict[str, float],
                    warnings: list[str]) -> None:
    """The crop, where the light knows it the site (georeferencing), the stages' CPU seconds and the warnings
    in the report."""
    report["cpu_timings_s"] = cpu
    report["warnings"] = [w for w in warnings if not isinstance(w, Remark)]  # each says what to do
    report["notes"] = [w for w in warnings if isinstance(w, Remark)]  # facts, nothing to do
    if setup.crop is not None:
        report["output"] = {"crop": setup.crop.to_report(), "cropped_points": int(cropped.sum())}
        report["coverage"]["cropped"] = int(cropped.sum())
    site = setup.georeference()
    if site is not None:
        report["site"] = site
