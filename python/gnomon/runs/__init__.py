"""The runs, each a short sequence of the stages: a scan (:mod:`~gnomon.runs.scan`), a live scan
(:mod:`~gnomon.runs.live`), many scans on Dask (:mod:`~gnomon.runs.batch`), two scans merged
(:mod:`~gnomon.runs.merge`), the benchmarks (:mod:`~gnomon.runs.bench`), regions proposed
(:mod:`~gnomon.runs.regions`), the set-up drawn before a scan (:mod:`~gnomon.runs.setup_preview`), the lamp
calibrated (:mod:`~gnomon.runs.calibrate_lamp`) and a scan scored against ground truth
(:mod:`~gnomon.runs.accuracy`). Each is loaded when first used: a scan never loads Dask or the live viewer.
"""

from typing import TYPE_CHECKING

from gnomon._lazy import attach

if TYPE_CHECKING:
    from gnomon.runs.accuracy import depth_accuracy as depth_accuracy
    from gnomon.runs.batch import plan_batch as plan_batch
    from gnomon.runs.batch import run_batch as run_batch
    from gnomon.runs.live import LiveOptions as LiveOptions
    from gnomon.runs.live import run_live as run_live
    from gnomon.runs.merge import merge_scans as merge_scans
    from gnomon.runs.regions import propose_regions as propose_regions
    from gnomon.runs.scan import ScanOptions as ScanOptions
    from gnomon.runs.scan import ScanResult as ScanResult
    from gnomon.runs.scan import run_scan as run_scan

#: Each name this package gives and the module it lives in (imported on first use).
_WHERE = {
    "ScanOptions": "gnomon.runs.scan",
    "ScanResult": "gnomon.runs.scan",
    "run_scan": "gnomon.runs.scan",
    "LiveOptions": "gnomon.runs.live",
    "run_live": "gnomon.runs.live",
    "plan_batch": "gnomon.runs.batch",
    "run_batch": "gnomon.runs.batch",
    "merge_scans": "gnomon.runs.merge",
    "propose_regions": "gnomon.runs.regions",
    "depth_accuracy": "gnomon.runs.accuracy",
}

__getattr__, __dir__, __all__ = attach(__name__, _WHERE)
