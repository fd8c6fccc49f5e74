"""How good are a two-plane scan's shadow planes at the sweep's ends? Measures it on a scanned capture.

    PYTHONPATH=python python benchmarks/plane_sequence.py FIELD_LOG [--frog] [--block 20] [--ends 30]

A two-plane frame whose shadow crossed one reference plane only gets the
plane through that line and the located light (docs/method.md §3); a frame
whose lines are short takes their directions from the neighbouring frames.
This script scans the capture in memory and prints:

* per frame at the sweep's ends (the first and last ``ends`` frames with a
  plane), each edge's source (``D``/``W``: desk/wall line found, ``x``:
  too short to set its own direction, ``C``: completed from one line and the
  light), the shadow speed at a point of the scene (the change per frame of
  the signed distance of the frame's plane to the median scan point, world
  units) and the plane's tilt ε about the direction all planes nearly share
  (the smallest singular vector of the measured normals of both edges; ε is
  the angle between the normal and the plane normal to that direction), with
  the same frame's enter − leave gap of ε: the two edges of one frame are one
  stick pose;
* a completion test on the measured frames: the first and the last ``block``
  two-plane frames of each edge completed as if one-line, from the line the
  real completed frames use, (a) through the light located from the other
  measured frames (the scan's own completion, :func:`gnomon.light.shadow_planes.completion_light`),
  (b) with ε extrapolated linearly from the 10 nearest kept frames, (c) from
  the other edge's plane of the same frame, turned about the line by the
  median turn between the two edges over the 10 nearest kept frames; the
  median and largest angle to the measured plane over the block's frames
  whose lines are full;
* with ``--frog``: per box face of ``benchmarks/real_captures.py``, the
  median Z_enter − Z_leave of the pixels timed in each entering frame (both
  edges triangulated on their planes, before the fusion's tests), and which
  planes those frames have (a completed or short-line plane on either edge).

Run real_captures.py first for the frog's field log (``OUT/frog/field_log.toml``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from gnomon.geometry.reference_lines import ReferenceLines
from gnomon.geometry.triangulation import triangulate
from gnomon.light.shadow_planes import complete_from_light, completion_light, two_plane_shadow_planes
from gnomon.reconstruct.edges import EdgeResult
from score import scan_field_log


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rotate(n: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``n`` turned about the unit ``axis`` by ``angle`` (radians, right-handed)."""
    return n * np.cos(angle) + np.cross(axis, n) * np.sin(angle) + axis * (axis @ n) * (1 - np.cos(angle))


def turn_about(axis: np.ndarray, normal: np.ndarray, other: np.ndarray) -> float:
    """Signed angle about the unit ``axis`` from ``other`` to ``normal`` (both projected normal to it)."""
    m, n = other - (other @ axis) * axis, normal - (normal @ axis) * axis
    return float(np.arctan2(np.cross(m, n) @ axis, m @ n))


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(unit(a) @ unit(b)))))))


def short_lines(lines: list[ReferenceLines]) -> np.ndarray:
    return np.any([ln.found & ln.extrapolated for ln in lines], axis=0)


def completing_plane(lines: list[ReferenceLines], rows: np.ndarray) -> int:
    """The reference plane whose line completes most of ``rows`` (the best-supported line found)."""
    votes = np.zeros(len(lines), dtype=int)
    for t in np.flatnonzero(rows):
        found = [k for k, ln in enumerate(lines) if ln.found[t]]
        if found:
            votes[max(found, key=lambda k: lines[k].count[t])] += 1
    return int(np.argmax(votes))


def completion_test(name: str, edge: EdgeResult, other: EdgeResult, measured: dict[str, np.ndarray],
                    u: np.ndarray, block: int) -> None:
    lines, planes = edge.lines, measured[name]
    other_planes = measured[other.name]
    rows = np.flatnonzero(np.isfinite(planes[:, 0]))
    completed = np.isfinite(edge.planes[:, 0]) & ~np.isfinite(planes[:, 0])
    k_line = completing_plane(lines, completed)
    line = lines[k_line]
    full = ~short_lines(lines)
    for where, chosen in (("first", rows[:block]), ("last", rows[-block:])):
        kept = planes.copy()
        kept[chosen] = np.nan
        light = completion_light(kept, lines, measure=False)
        only = [ln if ln is line else _without(ln, chosen) for ln in lines]
        by_light, _ = complete_from_light(kept, only, light.point, light.direction)
        keep_rows = np.flatnonzero(np.isfinite(kept[:, 0]))
        both = np.flatnonzero(np.isfinite(kept[:, 0]) & np.isfinite(other_planes[:, 0]))
        errors: dict[str, list[float]] = {"light": [], "tilt extrapolated": [], "other edge turned": []}
        for t in chosen.tolist():
            if not (full[t] and line.found[t]):
                continue
            w = unit(line.direction[t])
            truth = planes[t, :3]
            errors["light"].append(angle_deg(by_light[t, :3], truth))
            near = keep_rows[np.argsort(np.abs(keep_rows - t))[:10]]
            eps = np.arcsin(np.clip(unit(kept[near, :3]) @ u, -1, 1))
            target = np.polyval(np.polyfit(near, eps, 1), t)
            n = unit(by_light[t, :3])
            for _ in range(5):  # turn about the line until n·u = sin(target)
                n = unit(rotate(n, w, (np.sin(target) - n @ u) / (np.cross(w, n) @ u)))
            errors["tilt extrapolated"].append(angle_deg(n, truth))
            if np.isfinite(other_planes[t, 0]) and both.size:
                near = both[np.argsort(np.abs(both - t))[:10]]
                sign = np.sign(np.median(np.sum(unit(other_planes[near, :3]) * unit(kept[near, :3]), axis=1)))
                axes = [unit(line.direction[s]) if line.found[s] else w for s in near]
                turns = [turn_about(a * np.sign(a @ w), unit(kept[s, :3]), sign * unit(other_planes[s, :3]))
                         for a, s in zip(axes, near, strict=True)]
                m = sign * unit(other_planes[t, :3])
                m = unit(m - (m @ w) * w)
                errors["other edge turned"].append(angle_deg(rotate(m, w, float(np.median(turns))), truth))
        parts = [f"{k} {np.median(v):.3f}/{np.max(v):.3f}" for k, v in errors.items() if v]
        print(f"  {name} edge, its {where} {block} two-plane frames completed from the {line.plane_name} line "
              f"({len(errors['light'])} with full lines), median/max angle to the measured plane (deg): "
              + ", ".join(parts))


def _without(ln: ReferenceLines, rows: np.ndarray) -> ReferenceLines:
    """``ln`` without its lines in ``rows`` (as if the shadow had not crossed that plane there)."""
    point, direction = ln.point.copy(), ln.direction.copy()
    point[rows] = np.nan
    direction[rows] = np.nan
    points = [np.zeros((0, 3)) if t in set(rows.tolist()) else p for t, p in enumerate(ln.points)]
    return ReferenceLines(ln.plane_name, ln.plane, point, direction, ln.rms, ln.count, ln.pixels, ln.extrapolated,
                          points, ln.extent)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("field_log", type=Path)
    ap.add_argument("--frog", action="store_true", help="Z_enter - Z_leave per box face of real_captures.py")
    ap.add_argument("--block", type=int, default=20, help="two-plane frames completed as if one-line")
    ap.add_argument("--ends", type=int, default=30, help="frames shown at each end of the sweep")
    args = ap.parse_args(argv)
    log, setup, result = scan_field_log(args.field_log)
    edges = {e.name: e for e in result.edges}
    if set(edges) != {"enter", "leave"} or setup.light.kind != "two-plane":
        print(f"{args.field_log}: needs a two-plane scan with enter and leave edges")
        return 2
    ray_map = setup.camera.ray_map()
    measured = {name: two_plane_shadow_planes(e.lines)[0] for name, e in edges.items()}
    normals = np.concatenate([unit(m[np.isfinite(m[:, 0]), :3]) for m in measured.values()])
    u = np.linalg.svd(normals, full_matrices=False)[2][2]
    depth = np.nanmedian(np.where(np.isfinite(edges["enter"].depth), edges["enter"].depth, np.nan))
    probe = np.array([0.0, 0.0, float(depth)])
    print(f"{args.field_log}: shared direction (camera frame) {np.round(u, 4).tolist()}; shadow speed at "
          f"{np.round(probe, 1).tolist()}")
    source_of = {}
    for name, e in edges.items():
        completed = np.isfinite(e.planes[:, 0]) & ~np.isfinite(measured[name][:, 0])
        short = short_lines(e.lines) & ~completed
        source_of[name] = (completed, short)
    with_plane = np.flatnonzero(np.any([np.isfinite(e.planes[:, 0]) for e in edges.values()], axis=0))
    show = sorted(set(with_plane[:args.ends].tolist()) | set(with_plane[-args.ends:].tolist()))
    eps = {name: np.degrees(np.arcsin(np.clip(unit(e.planes[:, :3]) @ u, -1, 1))) for name, e in edges.items()}
    print(" frame | enter: src   speed   eps   | leave: src   speed   eps   | eps enter-leave (deg)")
    for t in show:
        row = f" {t:5d} |"
        for name, e in edges.items():
            p = e.planes
            if not np.isfinite(p[t, 0]):
                row += "   -                         |"
                continue
            src = "".join((ln.plane_name[0].upper() if ln.found[t] else "-") + ("x" if ln.extrapolated[t] else " ")
                          for ln in e.lines[:2]) + ("C" if source_of[name][0][t] else " ")
            distance = p[:, :3] @ probe - p[:, 3]  # each row's signed distance to the probe
            speed = float(distance[t] - distance[t - 1]) if t > 0 else np.nan
            row += f" {src} {speed:7.2f} {eps[name][t]:+7.3f} |"
        row += f" {eps['enter'][t] - eps['leave'][t]:+7.3f}"
        print(row)
    for name, other in (("enter", "leave"), ("leave", "enter")):
        completion_test(name, edges[name], edges[other], measured, u, args.block)
    if args.frog:
        from real_captures import FROG_OTHER_FACES
        from score import _polygon_mask
        te, tl = edges["enter"].times, edges["leave"].times
        ze = triangulate(ray_map, te, edges["enter"].planes).depth
        zl = triangulate(ray_map, tl, edges["leave"].planes).depth
        weak_rows = {name: c | s for name, (c, s) in source_of.items()}
        for face, outline in FROG_OTHER_FACES.items():
            m = _polygon_mask(ze.shape, [outline], -3) & np.isfinite(ze) & np.isfinite(zl)
            if not m.any():
                continue
            print(f"{face}: {int(m.sum())} pixels with both edges, Z_enter - Z_leave median "
                  f"{np.median((ze - zl)[m]):+.1f}; by entering frame (frame: median, '*' where either edge's "
                  "plane is completed or on short lines):")
            parts = []
            for t0 in range(int(np.nanmin(te[m])), int(np.nanmax(te[m])) + 1):
                s = m & (te >= t0) & (te < t0 + 1)
                if s.sum() < 30:
                    continue
                tl0 = int(np.clip(np.floor(np.nanmedian(tl[s])), 0, len(weak_rows["leave"]) - 1))
                star = "*" if weak_rows["enter"][t0] or weak_rows["leave"][tl0] else ""
                parts.append(f"{t0}{star}: {np.median((ze - zl)[s]):+.1f}")
            print("   " + ", ".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
