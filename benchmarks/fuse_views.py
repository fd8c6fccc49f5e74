"""One desk object scanned from several places and fused, against the simulator's truth.

For each number of views: ``gnomon simulate desk_turns`` (the figure turned on the desk by
360°/views and slid by up to 8 mm, 800 × 600), ``gnomon scan`` of every view, ``gnomon fuse`` of the
scans (no hints), each run as its own process (wall time and peak memory from ``/usr/bin/time``).
Then, against the truth (``turns.json``, :func:`gnomon.simulate.turntable.figure_distance`):

* every view's pose error: the rotation (degrees) and the displacement of the view's object points'
  centre (% of the cameras' distance to the object);
* the fused mesh's RMS distance from the true surface (% of the distance), over all its vertices;
* the coverage: the share of the true surface points the views swept (the pixels' exact surface
  points, desk left out) within 0.1 % of the distance of the mesh (Open3D's exact point-to-triangle
  distance);
* watertightness: the mesh's holes, on the set-up (the desk under the object) or where no view saw;
* the time of ``gnomon fuse`` against the time of the scans.

With ``--stations``: the facade scanned from two georeferenced stations
(:mod:`gnomon.simulate.stations`, the second station's georeference 1.5 m off, 2 m stated), both
scanned and fused; the second station's points' displacement from the truth (RMS and largest, % of
the distance) as its georeference placed them and after the registration.

    python benchmarks/fuse_views.py --views 4 6 --stations --out /tmp/fuse_bench
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from gnomon.outputs.ply import read_ply
from gnomon.simulate.stations import StationsConfig, simulate_stations
from gnomon.simulate.turntable import TurnsConfig, figure_distance, seen_surface, simulate_turns


def timed(cmd: list[str]) -> tuple[float, int]:
    """Run a command; its wall time (s) and peak resident memory (kB)."""
    t0 = time.perf_counter()
    out = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{out.stderr}")
    return wall, int(out.stderr.strip().splitlines()[-1])


def rotation_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))))


def evaluate(turns: Path, model: Path) -> dict:
    import open3d as o3d

    truth = json.loads((turns / "turns.json").read_text())
    report = json.loads((model / "report.json").read_text())
    distance = report["distance"]
    poses = []
    for k, v in enumerate(truth["views"]):
        T = np.asarray(v["pose_to_reference"])
        P = np.asarray(report["views"][k]["pose"])
        E = np.linalg.inv(T) @ P
        with np.load(turns / v["folder"] / "ground_truth.npz") as gt:
            c = gt["points_world"][gt["swept"] & (gt["object_id"] > 0)].astype(np.float64).mean(axis=0)
        moved = float(np.linalg.norm(E[:3, :3] @ c + E[:3, 3] - c))
        poses.append((rotation_deg(E), 100.0 * moved / distance))
    mesh = read_ply(model / "mesh.ply")
    V = np.asarray(mesh["xyz"], dtype=np.float64)
    F0 = np.linalg.inv(np.asarray(truth["views"][0]["figure_pose"]))
    d = figure_distance(V @ F0[:3, :3].T + F0[:3, 3])
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(np.asarray(mesh["faces"], np.uint32)))
    seen, _ = seen_surface(turns)
    gap = scene.compute_distance(o3d.core.Tensor(seen.astype(np.float32))).numpy()
    holes = report["model"]["holes"]
    return {
        "distance": distance,
        "pose_deg_max": max(p[0] for p in poses), "pose_pct_max": max(p[1] for p in poses),
        "poses": poses,
        "rms_pct": 100.0 * float(np.sqrt(np.mean(d**2))) / distance,
        "p95_pct": 100.0 * float(np.percentile(d, 95)) / distance,
        "coverage": float(np.mean(gap < 0.001 * distance)),
        "watertight": report["model"]["watertight"],
        "holes_setup": sum(h["where"] == "on the set-up" for h in holes),
        "holes_unseen": sum(h["where"] == "unseen" for h in holes),
        "unseen_perimeter": sum(h["perimeter"] for h in holes if h["where"] == "unseen"),
        "loop": report["registration"]["loop_closure"],
        "pairs": len(report["registration"]["pairs"]),
    }


def stations(base: Path, gnomon: list[str]) -> None:
    """The two-station facade: placement by georeference and after registration, against the truth."""
    from gnomon.fuse.georeference import station_priors
    from gnomon.fuse.views import read_view

    capture = base / "capture"
    if not (capture / "stations.json").is_file():
        simulate_stations(capture, StationsConfig())
    truth = json.loads((capture / "stations.json").read_text())
    scans, scan_s = [], []
    for k, st in enumerate(truth["stations"]):
        out = base / "scans" / f"station_{k}"
        wall, _ = timed([*gnomon, "scan", str(capture / st["folder"] / "field_log.toml"), "--out", str(out),
                         "--no-rrd", "--quiet"])
        scans.append(str(out))
        scan_s.append(wall)
    fuse_s, fuse_kb = timed([*gnomon, "fuse", *scans, "--out", str(base / "model")])
    report = json.loads((base / "model" / "report.json").read_text())
    views = [read_view(s) for s in scans]
    priors = station_priors(views)
    d = report["distance"]
    for k in range(1, len(views)):
        T = np.asarray(truth["stations"][k]["pose_to_reference"])
        X = views[k].points
        for name, P in (("georeference", priors[k].pose), ("registered", np.asarray(report["views"][k]["pose"]))):
            D = np.linalg.norm(X @ P[:3, :3].T + P[:3, 3] - (X @ T[:3, :3].T + T[:3, 3]), axis=1)
            print(f"station {k}, {name}: points off by {np.sqrt(np.mean(D**2)):.4f} m RMS "
                  f"({100 * np.sqrt(np.mean(D**2)) / d:.4f} % of {d:.1f} m), {D.max():.4f} m at most "
                  f"({100 * D.max() / d:.4f} %); stated georeference σ {truth['position_sigma_m']} m")
    st = report["registration"]["stations"][1]
    print(f"stations: ICP moved station 1 by {st['moved']:.3f} m (3σ allowed {st['allowed_3sigma']:.2f} m); "
          f"model frame: {report['frame']}; warnings: {report['warnings']}; fuse {fuse_s:.1f} s "
          f"({fuse_kb / 1024:.0f} MB) vs the scans {sum(scan_s):.1f} s", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, nargs="+", default=[4, 6])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--width", type=int, default=800)
    ap.add_argument("--height", type=int, default=600)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stations", action="store_true", help="also the two-station facade")
    args = ap.parse_args()
    gnomon = [sys.executable, "-m", "gnomon"]
    if args.stations:
        stations(args.out / "stations", gnomon)
    for n in args.views:
        base = args.out / f"views_{n}"
        turns = base / "capture"
        if not (turns / "turns.json").is_file():
            t = time.perf_counter()
            simulate_turns(turns, TurnsConfig(views=n, width=args.width, height=args.height, seed=args.seed))
            print(f"{n} views: simulated in {time.perf_counter() - t:.0f} s", flush=True)
        scans, scan_s, scan_kb = [], [], []
        for k in range(n):
            out = base / "scans" / f"view_{k}"
            wall, kb = timed([*gnomon, "scan", str(turns / f"view_{k}" / "field_log.toml"), "--out", str(out),
                              "--no-rrd", "--quiet"])
            scans.append(str(out))
            scan_s.append(wall)
            scan_kb.append(kb)
        fuse_s, fuse_kb = timed([*gnomon, "fuse", *scans, "--out", str(base / "model")])
        e = evaluate(turns, base / "model")
        loop = e["loop"]
        print(f"{n} views ({args.width}x{args.height}), object at {e['distance']:.0f} mm: "
              f"pose error ≤ {e['pose_deg_max']:.4f}° and {e['pose_pct_max']:.4f} % of the distance; "
              f"mesh RMS {e['rms_pct']:.4f} % (p95 {e['p95_pct']:.4f} %) of the true surface; "
              f"coverage {e['coverage']:.1%} of the seen true surface within 0.1 %; "
              f"{'watertight' if e['watertight'] else 'holes'}: {e['holes_setup']} on the set-up, "
              f"{e['holes_unseen']} unseen ({e['unseen_perimeter']:.0f} mm of edge); "
              f"{e['pairs']} pairs, loop before adjustment {loop['rotation_deg']:.3f}° "
              f"{loop['displacement']:.3f} mm; "
              f"fuse {fuse_s:.1f} s ({fuse_kb / 1024:.0f} MB peak) vs the {n} scans {sum(scan_s):.1f} s "
              f"({max(scan_kb) / 1024:.0f} MB peak each)", flush=True)
        for k, (deg, pct) in enumerate(e["poses"]):
            print(f"    view {k}: {deg:.4f}°, {pct:.4f} %")


if __name__ == "__main__":
    main()
