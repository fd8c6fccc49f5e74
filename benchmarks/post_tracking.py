"""Time a scan's stages after tracking alone, over a capture tracked once (a script, not a test).

    PYTHONPATH=python python benchmarks/post_tracking.py FIELD_LOG CACHE.pkl [--runs N] [--save OUT.npz]
    python benchmarks/post_tracking.py --compare A.npz B.npz

The first run tracks the capture as a scan does (its reader, the kernel tracker with the field log's
settings, the colour samples, the ray map) and pickles the tracked sequence, the tracker's settings, the
ray map and the colours into CACHE.pkl (hundreds of MB at 1080p; never committed); later runs load it. Then
the stages that follow tracking in :func:`gnomon.runs.scan.reconstruct` run ``--runs`` times in its order
(the regions held to their planes and the planes tied, the shadow planes and triangulation, the fusion with
its screening and crop, the surface's points, the mesh; the colours on a thread as there; the coverage map
untimed), each timed in wall and CPU seconds (the process's, all threads), and the minimum and median are
printed: a change to these stages is measured
here without the noise of decoding and tracking (docs/performance.md).

``--save`` writes the last run's arrays (held regions, planes, depths, σ, fused maps, points, normals, mesh,
coverage, the warnings' text) to an .npz; ``--compare`` says which arrays of two such files differ (NaN
equal to NaN): two runs of different code on the same cache are the same bit for bit when none differs.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import pickle
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from gnomon.capture.colours import COLOUR_SAMPLES, frame_hook, lit_colours
from gnomon.capture.texture import LitColour, sample_indices
from gnomon.capture.tracking import track_source, track_widening
from gnomon.geometry.surface import mesh_surface, surface_points
from gnomon.outputs.images import coverage_map
from gnomon.reconstruct.bare import hold_regions
from gnomon.reconstruct.corners import tie_planes
from gnomon.reconstruct.edges import Levels, edge_time_maps, min_contrast_dn, reconstruct_edges
from gnomon.reconstruct.fused import crop_fused, fuse_edges, screen_direct_light
from gnomon.runs.scan import prepare_scan


def tracked_once(field_log: str, cache: Path):
    """The set-up and (tracked, ray map, colours), tracked now and pickled, or loaded from ``cache``."""
    setup, source = prepare_scan(field_log)
    if cache.exists():
        with cache.open("rb") as fh:
            tracked, tracker, ray_map, colours = pickle.load(fh)
        return dataclasses.replace(setup, tracker=tracker), tracked, ray_map, colours
    skip = setup.light.skipped_frames(source.count)
    colour = LitColour(sample_indices(np.flatnonzero(~skip), COLOUR_SAMPLES))
    source.color_frames = source.color_frames | frozenset(int(i) for i in colour.indices)
    tracked, tracker, _ = track_widening(track_source, source, setup.tracker, (setup.camera.height, setup.camera.width),
                                         dip_width=setup.dip_width, skip=skip, on_frame=frame_hook(colour, None),
                                         progress=False, where=field_log)
    ray_map = setup.camera.ray_map()
    colours = lit_colours(colour, tracked)
    with cache.open("wb") as fh:
        pickle.dump((tracked, tracker, ray_map, colours), fh, protocol=5)
    return dataclasses.replace(setup, tracker=tracker), tracked, ray_map, colours


def after_tracking(setup, tracked, ray_map, colours, times: dict[str, list[tuple[float, float]]]) -> dict:
    """One pass of the stages after tracking (as gnomon.runs.scan.reconstruct runs them), timed into ``times``."""
    warnings: list = []

    def timed(name, fn, *args):
        t, c = time.perf_counter(), time.process_time()
        out = fn(*args)
        times.setdefault(name, []).append((time.perf_counter() - t, time.process_time() - c))
        return out

    def regions():
        levels = Levels(tracked)
        maps = edge_time_maps(tracked, setup.edge, levels)
        held = hold_regions(setup, maps, tracked.n_frames, ray_map, warnings, levels.lines)
        return tie_planes(held, maps, tracked.n_frames, warnings, levels.lines), levels

    setup, levels = timed("regions", regions)
    warnings += setup.light.choose_dips(tracked, ray_map, setup.planes, setup.max_depth_jump,
                                        min_contrast_dn(setup.tracker.min_contrast, tracked.noise_dn))
    if setup.light.chooses_dips:
        levels = Levels(tracked)
    with ThreadPoolExecutor(max_workers=1) as pool:
        rgb = pool.submit(lambda: colours)
        edges = timed("planes", reconstruct_edges, setup, tracked, ray_map, warnings, levels)

        def fusion():
            fused = fuse_edges(edges, tracked, setup.max_depth_jump, levels)
            if setup.light.occluder_hides_light:
                warnings.extend(screen_direct_light(fused, edges, tracked, levels))
            return fused, crop_fused(fused, setup, ray_map)

        fused, cropped = timed("fusion", fusion)
        points = timed("points", surface_points, ray_map, setup.pose, fused.depth, fused.sigma, fused.keep,
                       rgb.result(), setup.max_depth_jump)
        surface = timed("mesh", mesh_surface, points, setup.max_depth_jump)
    times_of = tracked.times
    coverage = coverage_map(times_of.valid, fused.keep, fused.undersampled, cropped, ambiguous=times_of.ambiguous,
                            conflict=fused.conflict, unsupported=fused.unsupported,
                            no_direct_light=fused.no_direct_light)
    return {"masks": np.stack([p.mask for p in setup.planes]), "planes": np.stack([e.planes for e in edges]),
            "depths": np.stack([e.depth for e in edges]), "sigmas": np.stack([e.sigma for e in edges]),
            "depth": fused.depth, "sigma": fused.sigma, "keep": fused.keep, "shadow_time": fused.shadow_time,
            "points": points.points_world, "normals": points.normals, "uv": points.uv,
            "vertices": surface.mesh.vertices, "faces": surface.mesh.faces, "pixel_index": surface.mesh.pixel_index,
            "mesh_normals": surface.mesh.normals, "coverage": coverage,
            "warnings": np.array(["\n".join(str(w) for w in warnings)])}


def compare(a: Path, b: Path) -> int:
    x, y = np.load(a), np.load(b)
    differ = [k for k in sorted(set(x.files) | set(y.files))
              if k not in x.files or k not in y.files or x[k].shape != y[k].shape or x[k].dtype != y[k].dtype
              or not np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind in "fc")]
    for k in differ:
        print(f"{k}: differs")
    print("identical" if not differ else f"{len(differ)} of {len(set(x.files) | set(y.files))} arrays differ")
    return 1 if differ else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("field_log", nargs="?")
    parser.add_argument("cache", nargs="?", type=Path)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--save", type=Path)
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = parser.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    if args.field_log is None or args.cache is None:
        parser.error("FIELD_LOG and CACHE are needed (or --compare A B)")
    setup, tracked, ray_map, colours = tracked_once(args.field_log, args.cache)
    times: dict[str, list[tuple[float, float]]] = {}
    arrays: dict = {}
    for _ in range(max(args.runs, 1)):
        arrays = after_tracking(setup, copy.deepcopy(tracked), ray_map, colours, times)
    for name, runs in times.items():
        wall, cpu = sorted(w for w, _ in runs), sorted(c for _, c in runs)
        print(f"{name:8s} wall min {wall[0]:.3f} median {wall[len(wall) // 2]:.3f} s, "
              f"CPU min {cpu[0]:.3f} median {cpu[len(cpu) // 2]:.3f} s ({len(runs)} runs)")
    if args.save:
        np.savez(args.save, **arrays)
        print(f"saved {args.save}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
