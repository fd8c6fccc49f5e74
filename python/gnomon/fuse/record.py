"""What a fusion logs to its recording (``fuse.rrd``): each view's pose and object points, the pairs'
residuals, the loop's closure, and the fused points and mesh.

Entities: ``world/views/<name>`` each view's pose (a transform: its world frame → the reference frame)
with its object points below it in its own frame (``…/points``, σ per point), ``world/points`` and
``world/mesh`` the fused model, ``metrics/pairs/<i>-<j>/…`` every accepted pair's overlap, RMS and
residual against the adjusted poses, ``metrics/loop/…`` the loop's closure before adjustment,
``summary`` a table of every figure, ``log`` the warnings.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gnomon.fuse.model import Registration
from gnomon.fuse.surface import FusedMesh, FusedPoints
from gnomon.fuse.views import View
from gnomon.recording.recorder import ScanRecording

__all__ = ["record_fusion", "VIEW_ENTITY"]

VIEW_ENTITY = "world/views"


def record_fusion(rec: ScanRecording, views: list[View], reg: Registration, fused: FusedPoints, mesh: FusedMesh,
                  to_output: np.ndarray, report: dict[str, Any]) -> None:
    """Log the fusion (see the module); ``to_output`` (4, 4) the reference frame → the model's frame."""
    if not rec.enabled or rec.stream is None:
        return
    import rerun as rr

    stream = rec.stream
    for v, pose in zip(views, reg.poses, strict=True):
        T = to_output @ pose
        entity = f"{VIEW_ENTITY}/{v.name}"
        stream.log(entity, rr.Transform3D(translation=T[:3, 3].astype(np.float32),
                                          mat3x3=T[:3, :3].astype(np.float32)), static=True)
        m = v.object_mask
        rec.log_points(v.points[m].astype(np.float32), None if v.rgb is None else v.rgb[m], v.sigma[m],
                       entity=f"{entity}/points")
    R, t = to_output[:3, :3], to_output[:3, 3]
    rec.log_points((fused.points @ R.T + t).astype(np.float32), fused.rgb, fused.sigma)
    rec.log_mesh((mesh.vertices @ R.T + t).astype(np.float32), mesh.faces, mesh.rgb)
    rec.log_metrics({"pairs": {f"{p['views'][0]}-{p['views'][1]}": {k: p[k] for k in
                                                                   ("overlap", "rms", "rms_sigma",
                                                                    "residual_deg", "residual_displacement")}
                               for p in report["registration"]["pairs"]},
                     "loop": report["registration"]["loop_closure"] or {},
                     "poses": {f"view_{k}": {"rotation_deg": p["rotation_deg"], "translation": p["translation"]}
                               for k, p in enumerate(report["views"])},
                     "model": {"vertices": report["model"]["vertices"], "faces": report["model"]["faces"],
                               "holes": len(report["model"]["holes"])}})
    for w in report["warnings"]:
        rec.log_warning(w)
