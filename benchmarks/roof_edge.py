"""A facade scanned from a roof edge's shadow without a pole (issue 35, item 4): a script, not a test.

    PYTHONPATH=python python benchmarks/roof_edge.py [--out DIR] [--width 800 --height 600] [--seed 0]

``gnomon simulate facade_sun --roof-edge``: no pole; the roof line of the building across the street (world
y 40 m, z 22 m) casts a shadow that climbs the facade from 0.2 m to 9.7 m over 3 h 19 min, every point in
that band going into the shadow once (a step). The field log names the edge in ``[edge]`` (a, b, body). The
capture is scanned as written and judged against the simulator's truth (``gnomon.runs.accuracy``): depth
RMS over the surface the edge's shadow swept (the truth's ``swept``), the same over the passages no cloud
frame touched (``cloud_free_passage``), coverage of the swept surface, false points (on a pixel the edge's
shadow never crossed while lit, or > 5 σ and > 1 % of the distance off) and gross errors (> 1 % off) over
every output point, and what the edge's checks refused. Then again with ``[edge]`` without ``a`` and ``b``:
the edge found from the shadow's lines on the facade's reference regions, and how far it is from the truth.

``--register off`` scans with ``[capture] register = "off"`` (the simulated camera is still): at 800×600 the
frame registration refuses the capture once the edge's shadow covers most of its patches (26 of 200 frames
not measured, the first frame 172), which ``--register on`` (the field log as written) shows.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from building_shadows import facade_arguments  # noqa: E402
from gnomon.runs.accuracy import depth_accuracy  # noqa: E402
from gnomon.runs.scan import ScanOptions, run_scan  # noqa: E402
from gnomon.simulate import FacadeSunConfig  # noqa: E402
from gnomon.simulate.roof_edge import simulate_roof_edge  # noqa: E402
from gnomon.util import toml_io  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = facade_arguments(__doc__.split("\n")[0])
    ap.add_argument("--register", choices=("on", "off"), default="off",
                    help="off: [capture] register = \"off\" (the camera is still); on: the field log as written")
    args = ap.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="gnomon-roof-edge-"))
    capture = root / "capture"
    if not (capture / "field_log.toml").exists():
        t0 = time.perf_counter()
        simulate_roof_edge(capture, FacadeSunConfig(width=args.width, height=args.height, seed=args.seed,
                                                    roof_edge=True))
        print(f"simulated in {time.perf_counter() - t0:.0f} s: {capture}")
    truth = dict(np.load(capture / "ground_truth.npz"))
    data = toml_io.load(capture / "field_log.toml")
    if args.register == "off":
        data["capture"]["register"] = "off"
    for mode in ("given", "found"):
        if mode == "found":  # [edge] without a and b: found from the shadow's lines on the facade regions
            data["edge"] = {k: v for k, v in data["edge"].items() if k not in ("a", "b")}
        log = capture / f"field_log_{mode}.toml"
        toml_io.dump(data, log)
        scan(log, root / f"scan_{mode}", truth, f"{args.width}x{args.height} seed {args.seed}, register "
             f"{args.register}, edge {mode}")
    return 0


def scan(log: Path, out: Path, truth: dict[str, np.ndarray], title: str) -> None:
    """Scan ``log`` into ``out`` and print its figures against the truth."""
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    result = run_scan(log, out, ScanOptions(progress=False, rrd=False))
    seconds = time.perf_counter() - t0
    distance = float(truth["camera_distance"])
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], distance, "m", sigma=result.sigma,
                         swept_surface=truth["swept_surface"])
    calm = depth_accuracy(result.depth, truth["depth"], truth["cloud_free_passage"], distance, "m",
                          sigma=result.sigma, swept_surface=truth["swept_surface"])
    print(acc.table(f"facade_sun --roof-edge {title}, scanned in {seconds:.0f} s"))
    print(f"  over cloud-free passages: RMS {calm.rms_pct:.3f} %, median {calm.median_pct:.3f} %, "
          f"coverage {100 * calm.coverage:.2f} % of {calm.swept_pixels} px")
    print(f"  swept surface (mixed pixels included): {int(truth['swept_surface'].sum())} px; strict swept: "
          f"{int(truth['swept'].sum())} px")
    edge = result.report["sun"]["edge"]
    if edge["found_from_lines"]:
        a, b = truth["edge_a"], truth["edge_b"]
        e = (b - a) / np.linalg.norm(b - a)
        for name in ("enter", "leave"):
            found = edge.get(name)
            if found is None:
                print(f"  {name} edge: none found")
                continue
            rel = np.asarray(found["point"]) - a
            d = np.asarray(found["direction"]) / np.linalg.norm(found["direction"])
            print(f"  {name} edge found {np.linalg.norm(rel - (rel @ e) * e):.3f} m from the true one, "
                  f"{np.degrees(np.arccos(min(1.0, abs(float(d @ e))))):.3f}° off its direction, from "
                  f"{found['planes']} of {found['planes_offered']} planes turning {found['turn_deg']:.1f}°")
    for e_result in result.edges:
        if e_result.rejected:
            print(f"  {e_result.name} edge refused: {e_result.rejected}")
    for w in result.warnings:
        print(f"  warning: {w}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
