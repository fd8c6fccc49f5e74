"""Planes whose marks fix only their orientation, given their distance by the shadow once it is tracked.

A plane whose marks nobody measured (no ``plane_xy``) and that carries no known length is resolved at a
provisional distance (:func:`gnomon.config.setup.provisional_distance`). Where it meets the first plane
(the world frame: a wall and the desk), each frame's shadow bends; the frames' lines on the two planes
give its distance (:func:`gnomon.geometry.plane_tie.tie_by_corner`), which :func:`tie_planes` puts into the
scan's set-up before anything is measured against the planes. ``gnomon regions`` ties its planes the
same way on its first lines.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gnomon.config.setup import FOCAL_BLAME, MAX_PLANE_DEPTH_SHARE, ScanSetup
from gnomon.errors import GnomonError
from gnomon.geometry.plane_tie import MIN_TIE_FRAMES, CornerTie, tie_by_corner
from gnomon.geometry.reference_lines import LineMemo, PlaneInCamera, ReferenceLines, measure_reference_lines

__all__ = ["apply_ties", "combined_tie", "moved", "tie_camera_planes", "tie_lines", "tie_message", "tie_planes"]

#: The corner the shadow traces may be this many combined 1-σ of the two planes' normals off the line
#: where their marks put them before a warning (and never less than MIN_CORNER_ANGLE_DEG).
CORNER_SIGMAS = 3.0
MIN_CORNER_ANGLE_DEG = 0.1


def combined_tie(ties: list[CornerTie]) -> CornerTie:
    """Several edges' ties of one plane as one: their distances weighted by inverse variance."""
    if len(ties) == 1:
        return ties[0]
    w = np.array([1.0 / max(t.sigma, 1e-300) ** 2 for t in ties])
    offset = float(np.sum(w * [t.offset for t in ties]) / w.sum())
    best = ties[int(np.argmax(w))]
    return dataclasses.replace(best, offset=offset, sigma=float(1.0 / np.sqrt(w.sum())),
                               frames=sum(t.frames for t in ties))


def moved(plane: PlaneInCamera, offset: float) -> PlaneInCamera:
    """The same plane at another distance from the camera's centre (along the rays)."""
    k = offset / plane.offset
    return PlaneInCamera(plane.normal, float(offset), plane.origin * k, plane.e1, plane.e2)


def corner_limit_deg(sigmas_deg: tuple[float, float]) -> float:
    """How far (degrees) the shadow's corner may lie from the line where two planes' marks put them:
    CORNER_SIGMAS of their normals' σ combined, at least MIN_CORNER_ANGLE_DEG."""
    return max(CORNER_SIGMAS * float(np.hypot(*sigmas_deg)), MIN_CORNER_ANGLE_DEG)


def tie_message(name: str, anchor: str, tie: CornerTie | None, sigmas_deg: tuple[float, float]) -> tuple[str, str]:
    """(error, warning) about one plane's tie to its anchor ('' when none): no tie is an error; a distance
    uncertain by more than MAX_PLANE_DEPTH_SHARE, or a corner off the planes' own line, a warning."""
    if tie is None:
        return (f"[[planes]] {name}: its marks have no plane_xy, and fewer than {MIN_TIE_FRAMES} frames' "
                f"shadow lines cross both it and {anchor} where the two meet, so nothing measures its distance: "
                "make the regions of both reach the corner, or give it mark_distance or plane_xy"), ""
    notes = []
    if tie.sigma / abs(tie.offset) > MAX_PLANE_DEPTH_SHARE:
        notes.append(f"its distance is uncertain by {100 * tie.sigma / abs(tie.offset):.2f} % (1 σ, over {tie.frames} "
                     "frames)")
    limit = corner_limit_deg(sigmas_deg)
    if np.isfinite(limit) and tie.corner_angle_deg > limit:
        notes.append(f"the corner its shadow traces with {anchor} is {tie.corner_angle_deg:.2f}° off the line "
                     f"where their marks put the two planes (more than {limit:.2f}°, {CORNER_SIGMAS:g} σ of "
                     f"their normals): a normal is off")
    if not notes:
        return "", ""
    return "", (f"[[planes]] {name}: placed by where it meets {anchor}, but " + "; ".join(notes)
                + ": measure its marks' positions (plane_xy) or give it mark_distance")


def focal_blame_doubt(name: str, anchor: str, tie: CornerTie, sigmas_deg: tuple[float, float],
                      marker_warnings: list[str]) -> str:
    """A warning ('' for none) for marks that blame the focal length (``marker_warnings``, the two planes')
    while the shadow's corner lies where the planes at the camera's own focal length meet: the corner is
    evidence the marks are not, and a focal length wrong by the factor they suggest would move that line."""
    if tie.corner_angle_deg > corner_limit_deg(sigmas_deg) or not any(FOCAL_BLAME in w for w in marker_warnings):
        return ""
    return (f"[[planes]] {name}: the corner its shadow traces with {anchor} lies {tie.corner_angle_deg:.2f}° from "
            f"the line where their marks put the two planes at the camera's own focal length (their normals "
            f"{sigmas_deg[0]:.2f}° and {sigmas_deg[1]:.2f}° uncertain): the shadow does not call for another focal "
            "length, so the marks are more likely off a rectangle than the camera off its calibration; before "
            "using `gnomon calibrate focal`'s camera, scan with it and check this corner (the scan warns when "
            "it is off), or measure the marks' positions (plane_xy)")


def tie_lines(untied: tuple[tuple[str, str], ...],
              lines_of: dict[str, list[ReferenceLines]]) -> dict[str, CornerTie | None]:
    """Each untied plane's tie from its own and its anchor's lines (one list per time map)."""
    out: dict[str, CornerTie | None] = {}
    for name, anchor in untied:
        ties = [t for a, b in zip(lines_of[anchor], lines_of[name], strict=True)
                if (t := tie_by_corner(a, b)) is not None]
        out[name] = combined_tie(ties) if ties else None
    return out


def tie_planes(setup: ScanSetup, maps: list[np.ndarray], n_frames: int, warnings: list[str],
               memo: LineMemo | None = None) -> ScanSetup:
    """``setup`` with each untied plane (:attr:`ScanSetup.untied`) at the distance the shadow's corner gives
    it, its report entry saying how (``tie``: distance, σ, frames, corner angle), from the edges' time
    ``maps`` (:func:`gnomon.reconstruct.edges.edge_time_maps`); a plane that cannot be tied is a
    :class:`GnomonError`. Appends a warning per plane whose tie is uncertain or inconsistent. ``memo``: lines
    already measured on the same maps (:class:`~gnomon.geometry.reference_lines.LineMemo`)."""
    if not setup.untied:
        return setup
    refs = {p.name: p for p in setup.planes}
    names = {n for pair in setup.untied for n in pair}
    measure = measure_reference_lines if memo is None else memo.measure
    lines_of = {n: [measure(t, n_frames, refs[n], setup.camera) for t in maps] for n in names}
    ties = tie_lines(setup.untied, lines_of)
    return apply_ties(setup, ties, warnings)


def apply_ties(setup: ScanSetup, ties: dict[str, CornerTie | None], warnings: list[str]) -> ScanSetup:
    """``setup`` with its untied planes moved to their ties' distances (see :func:`tie_planes`)."""
    entries = [dict(e) for e in setup.inputs.reference_planes]
    by_name = {e["plane"]: e for e in entries}
    planes = list(setup.planes)
    crop = setup.crop
    for name, anchor in setup.untied:
        tie = ties[name]
        sigmas = (float(by_name[name].get("std_normal_deg", np.nan)),
                  float(by_name[anchor].get("std_normal_deg", np.nan)))
        error, warning = tie_message(name, anchor, tie, sigmas)
        if error:
            raise GnomonError(f"{setup.inputs.field_log}: {error}")
        assert tie is not None
        if warning:
            warnings.append(f"{setup.inputs.field_log}: {warning}")
        doubt = focal_blame_doubt(name, anchor, tie, sigmas, [str(by_name[n].get("marker_warning", ""))
                                                              for n in (name, anchor)])
        if doubt:
            warnings.append(f"{setup.inputs.field_log}: {doubt}")
        k = next(i for i, p in enumerate(planes) if p.name == name)
        plane = moved(planes[k].plane, tie.offset)
        planes[k] = dataclasses.replace(planes[k], plane=plane)
        entry = by_name[name]
        # the marks' rays meet the moved plane at their points scaled about the camera centre: the rectangle's
        # pose and size in the report scale with the distance (they were the provisional plane's)
        ratio = abs(tie.offset) / float(entry["offset_cam"]) if entry.get("offset_cam") else 1.0
        if "tvec" in entry:
            entry["tvec"] = [ratio * float(x) for x in entry["tvec"]]
        if "rectangle" in entry:
            entry["rectangle"] = [ratio * float(x) for x in entry["rectangle"]]
        if "marks_xy" in entry:
            entry["marks_xy"] = {m: [ratio * float(x) for x in xy] for m, xy in entry["marks_xy"].items()}
        entry.update(offset_cam=abs(tie.offset), std_offset=tie.sigma, std_offset_relative=tie.sigma / abs(tie.offset),
                     distance=f"tied to {anchor}",
                     world_point=setup.pose.camera_to_world(plane.origin).tolist(),
                     tie={"anchor": anchor, "offset_cam": abs(tie.offset), "sigma": tie.sigma, "frames": tie.frames,
                          "sigma_relative": tie.sigma / abs(tie.offset), "corner_angle_deg": tie.corner_angle_deg})
        if crop is not None and crop.plane_name == name:
            crop = dataclasses.replace(crop, plane_point=setup.pose.camera_to_world(plane.origin))
    inputs = dataclasses.replace(setup.inputs, reference_planes=entries)
    return dataclasses.replace(setup, planes=tuple(planes), inputs=inputs, crop=crop, untied=())


def tie_camera_planes(planes: list[PlaneInCamera], names: list[str], untied: tuple[tuple[str, str], ...],
                      lines_of: dict[str, list[ReferenceLines]]) -> tuple[list[PlaneInCamera],
                                                                         dict[str, CornerTie | None]]:
    """Plain planes (camera frame) with their untied ones moved to the distance their lines give (for
    ``gnomon regions``, which has no scan set-up); planes that cannot be tied are kept as they were."""
    ties = tie_lines(untied, lines_of)
    out = list(planes)
    for name, tie in ties.items():
        if tie is not None:
            k = names.index(name)
            out[k] = moved(out[k], tie.offset)
    return out, ties
