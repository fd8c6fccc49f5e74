"""The rerun recording of a run: its layout of entities and timelines and the recorder
(:mod:`~gnomon.recording.recorder`), the one recorder interface a scan talks to and a recording on its
own thread (:mod:`~gnomon.recording.worker`), what a scan logs (:mod:`~gnomon.recording.scan_log`), and
recordings read back (:mod:`~gnomon.recording.review`). rerun is imported when a recording is opened.
"""

from typing import TYPE_CHECKING

from gnomon._lazy import attach

if TYPE_CHECKING:
    from gnomon.recording.recorder import ScanRecording as ScanRecording
    from gnomon.recording.review import summarize as summarize
    from gnomon.recording.worker import Recorder as Recorder
    from gnomon.recording.worker import RecordingWorker as RecordingWorker

#: Each name this package gives and the module it lives in (imported on first use).
_WHERE = {
    "ScanRecording": "gnomon.recording.recorder",
    "Recorder": "gnomon.recording.worker",
    "RecordingWorker": "gnomon.recording.worker",
    "summarize": "gnomon.recording.review",
}

__getattr__, __dir__, __all__ = attach(__name__, _WHERE)
