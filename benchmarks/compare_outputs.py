"""Compare two output folders of `gnomon demo` (or two scan folders) file by file.

    python benchmarks/compare_outputs.py BEFORE AFTER

Every file of each scan folder is compared byte for byte, except scan.rrd (it carries wall-clock
times) and report.json, which is compared as JSON without its timings (``timings_s``,
``cpu_timings_s``) and without the paths and digests of the field log (the folders differ). Prints
one line per file and exits 1 if any differs: a refactoring that claims identical results is checked
with it (e.g. on two `gnomon demo --out` folders made before and after).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

SKIP = {"scan.rrd", "merge.rrd"}


def _without_run_specifics(report: Any) -> Any:
    if isinstance(report, dict):
        return {k: _without_run_specifics(v) for k, v in report.items()
                if k not in ("timings_s", "cpu_timings_s", "field_log", "field_log_sha256")}
    if isinstance(report, list):
        return [_without_run_specifics(x) for x in report]
    return report


def _scan_folders(root: Path) -> list[Path]:
    if (root / "report.json").is_file():
        return [root]
    return sorted(p.parent for p in root.glob("*/scan/report.json"))


def compare(before: Path, after: Path) -> bool:
    same = True
    for a in _scan_folders(before):
        b = after / a.relative_to(before)
        for f in sorted(p for p in a.iterdir() if p.is_file() and p.name not in SKIP):
            g = b / f.name
            if not g.is_file():
                print(f"{f.relative_to(before)}: missing in {after}")
                same = False
                continue
            if f.name == "report.json":
                equal = (_without_run_specifics(json.loads(f.read_text()))
                         == _without_run_specifics(json.loads(g.read_text())))
            else:
                equal = f.read_bytes() == g.read_bytes()
            print(f"{f.relative_to(before)}: {'identical' if equal else 'DIFFERS'}")
            same &= equal
    return same


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(0 if compare(Path(sys.argv[1]), Path(sys.argv[2])) else 1)
