"""`gnomon fuse SCAN... --out MODEL`: several scans of one object (or building) made into one model."""

from __future__ import annotations

import argparse
from pathlib import Path

from gnomon.commands import COMMANDS
from gnomon.recording.recorder import add_recording_arguments


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "fuse",
        help=COMMANDS["fuse"],
        description="Register scan output folders of one object taken from several places (the object turned "
        "on the desk, or the camera moved; sun scans from several stations) and fuse them into one model: "
        "the set-up's planes left out, a coarse alignment from the geometry (no hints; sun scans: their "
        "georeference), ICP weighted by each point's sigma, a pose graph over every pair, screened Poisson "
        "surface of the sigma-weighted points, cut to what the views saw. Writes OUT/mesh.ply (sigma per "
        "vertex), points.ply, report.json (poses, residuals, loop closure, holes) and fuse.rrd. Needs "
        'Open3D: pip install "gnomon[fuse]".',
    )
    p.add_argument("scans", nargs="+", type=Path, metavar="SCAN", help="output folders of `gnomon scan` (2 or more)")
    p.add_argument("--out", type=Path, required=True, help="output folder of the model")
    p.add_argument("--mesh-formats", default="ply", metavar="LIST",
                   help="mesh files besides mesh.ply: ply, obj, stl, joined by commas (or all)")
    p.add_argument("--voxel", type=float, default=None, metavar="LENGTH",
                   help="the fusion's grid, world units of the scans (default: their median point spacing)")
    add_recording_arguments(p, what="OUT/fuse.rrd", rrd_path=False, view=False, frame_stride=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gnomon.errors import GnomonError
    from gnomon.fuse.run import FUSE_MESH_FORMATS, fuse_scans
    from gnomon.util import validate

    out = validate.check_output_folder(args.out)
    for scan in args.scans:
        folder = validate.input_folder(scan, "SCAN (a scan output folder)").resolve()
        if out == folder or folder in out.parents or out in folder.parents:
            raise GnomonError(f"--out {args.out}: would write into the input {scan}; choose another folder")
    names = {n.strip().lower() for n in args.mesh_formats.split(",")} - {""}
    formats = FUSE_MESH_FORMATS if names == {"all"} else tuple(f for f in FUSE_MESH_FORMATS
                                                              if f in names or f == "ply")
    unknown = names - set(FUSE_MESH_FORMATS) - {"all"}
    if unknown:
        raise GnomonError(f"--mesh-formats {args.mesh_formats}: unknown {', '.join(sorted(unknown))} "
                          f"(one of {', '.join(FUSE_MESH_FORMATS)}, or all)")
    voxel = None if args.voxel is None else validate.number(args.voxel, "--voxel", positive=True)
    result = fuse_scans(args.scans, args.out, voxel=voxel, mesh_formats=formats, rrd=not args.no_rrd)
    r = result.report
    m = r["model"]
    holes = m["holes"]
    unseen = [h for h in holes if h["where"] == "unseen"]
    loop = r["registration"]["loop_closure"]
    loop_text = (f"; loop closed within {loop['rotation_deg']:.3f}° and {loop['displacement']:.3g} {r['units']} "
                 "before adjustment") if loop else ""
    print(f"{len(result.views)} scans, {len(r['registration']['pairs'])} pairs{loop_text}; "
          f"{m['vertices']} vertices, {m['faces']} faces, "
          f"{'watertight' if m['watertight'] else f'{len(holes)} holes ({len(unseen)} where no view saw)'} "
          f"-> {args.out}")
    for w in r["warnings"]:
        print(f"gnomon: warning: {w}")
    return 0
