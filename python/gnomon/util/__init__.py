"""Small tools every stage uses, with no knowledge of scanning: files written atomically
(:mod:`~gnomon.util.atomic`), TOML read and written (:mod:`~gnomon.util.toml_io`), inputs validated at
the edge with one-line errors (:mod:`~gnomon.util.validate`), robust line and plane fits and a small
Levenberg–Marquardt solver (:mod:`~gnomon.util.fitting`), the χ² tail (:mod:`~gnomon.util.chi2`), a
progress bar, stage timings, signals held off a block of code (:mod:`~gnomon.util.interrupts`), a
producer thread feeding its consumer (:mod:`~gnomon.util.threads`), and a cluster's futures as they
complete, never waiting on a cluster with no worker left (:mod:`~gnomon.util.dask_wait`).
Each is loaded when first used: the command line starts without numpy.
"""

from typing import TYPE_CHECKING

from gnomon._lazy import attach

if TYPE_CHECKING:
    from gnomon.util.atomic import atomic_path as atomic_path
    from gnomon.util.atomic import save_npy as save_npy
    from gnomon.util.atomic import write_bytes as write_bytes
    from gnomon.util.atomic import write_parts as write_parts
    from gnomon.util.atomic import write_text as write_text
    from gnomon.util.chi2 import chi2_isf as chi2_isf
    from gnomon.util.chi2 import chi2_sf as chi2_sf
    from gnomon.util.fitting import fit_line_robust as fit_line_robust
    from gnomon.util.fitting import fit_plane_robust as fit_plane_robust
    from gnomon.util.fitting import levenberg_marquardt as levenberg_marquardt
    from gnomon.util.progress import Progress as Progress
    from gnomon.util.threads import ahead as ahead
    from gnomon.util.timing import timed as timed
    from gnomon.util.validate import check_output_file as check_output_file
    from gnomon.util.validate import check_output_folder as check_output_folder
    from gnomon.util.validate import input_file as input_file
    from gnomon.util.validate import input_folder as input_folder
    from gnomon.util.validate import number as number

#: Each name this package gives and the module it lives in (imported on first use).
_WHERE = {
    "atomic_path": "gnomon.util.atomic",
    "write_bytes": "gnomon.util.atomic",
    "write_text": "gnomon.util.atomic",
    "save_npy": "gnomon.util.atomic",
    "write_parts": "gnomon.util.atomic",
    "chi2_isf": "gnomon.util.chi2",
    "chi2_sf": "gnomon.util.chi2",
    "fit_line_robust": "gnomon.util.fitting",
    "fit_plane_robust": "gnomon.util.fitting",
    "levenberg_marquardt": "gnomon.util.fitting",
    "Progress": "gnomon.util.progress",
    "ahead": "gnomon.util.threads",
    "timed": "gnomon.util.timing",
    "check_output_file": "gnomon.util.validate",
    "check_output_folder": "gnomon.util.validate",
    "input_file": "gnomon.util.validate",
    "input_folder": "gnomon.util.validate",
    "number": "gnomon.util.validate",
}

__getattr__, __dir__, __all__ = attach(__name__, _WHERE)
