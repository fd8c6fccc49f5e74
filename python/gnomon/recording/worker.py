"""The one recorder interface a scan talks to, and a recording on its own thread.

A scan hands its recorder calls ``fn(recording)`` through :meth:`Recorder.submit` and says
:meth:`Recorder.scan_done` when it has logged everything. Two kinds answer:

* :class:`~gnomon.recording.recorder.ScanRecording` runs each call at once, and stays open for whoever
  opened it (`gnomon live`, a script);
* :class:`RecordingWorker` runs the calls in order on a thread of its own (rerun's time is per
  thread), so that the recording is logged and encoded while the scan goes on, and closes the
  recording when the scan is done.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Protocol

from gnomon.recording.recorder import ScanRecording


class Recorder(Protocol):
    """What a scan needs of its recorder."""

    notes: list[str]  # what the user should know of the recording (a viewer that did not start)

    def submit(self, fn: Callable[[ScanRecording], object]) -> None:
        """Run ``fn(recording)``: now, or queued in order."""

    def scan_done(self) -> None:
        """The scan has logged everything it will."""


class RecordingChoice(Protocol):
    """A run's choice of recording (:class:`gnomon.runs.scan.ScanOptions` is one)."""

    rrd: bool  # write OUT/<name>.rrd
    view: bool  # stream to a viewer
    frame_stride: int  # every n-th frame's image kept


class RecordingWorker:
    """A scan's recording on its own thread: opened there, then fed calls in order.

    ``open_recorder`` builds the :class:`~gnomon.recording.recorder.ScanRecording` (importing rerun, ≈ 1 s)
    on the worker thread, so the frames are decoded and tracked meanwhile; :meth:`submit` queues a
    call ``fn(recorder)`` (frames to log, the result to log), run in order on that thread (rerun's
    time is per thread: every log of the recording comes from this one). :meth:`finish` closes the
    recorder there (encodes and writes the file), waits, and re-raises the first failure in the
    caller's thread; :meth:`abort` waits and removes the unfinished file. After a failure the
    remaining calls are skipped. ``notes`` are the recorder's (a viewer that did not start): an
    already opened recorder can be given instead (its notes are then known at once).
    """

    def __init__(self, open_recorder: Callable[[], ScanRecording | None] | ScanRecording) -> None:
        self._queue: queue.SimpleQueue[Callable[[ScanRecording], object] | None] = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._recorder: ScanRecording | None = None
        self.notes: list[str] = []
        if isinstance(open_recorder, ScanRecording):
            self._recorder = open_recorder
            self.notes = list(open_recorder.notes)
            opener = None
        else:
            opener = open_recorder
        self._done = False
        self._thread = threading.Thread(target=self._run, args=(opener,), name="gnomon-recording", daemon=True)
        self._thread.start()

    def _run(self, opener: Callable[[], ScanRecording | None] | None) -> None:
        try:
            if opener is not None:
                self._recorder = opener()
        except BaseException as exc:  # re-raised by finish, in the caller's thread
            self._error = exc
        while (task := self._queue.get()) is not None:
            if self._error is None and self._recorder is not None:
                try:
                    task(self._recorder)
                except BaseException as exc:
                    self._error = exc

    def submit(self, fn: Callable[[ScanRecording], object]) -> None:
        """Queue ``fn(recorder)`` (skipped once a call has failed)."""
        if not self._done:
            self._queue.put(fn)

    def _stop(self) -> None:
        if not self._done:
            self._done = True
            self._queue.put(None)
        self._thread.join()

    def close_soon(self) -> None:
        """Queue the recording's close after the calls queued so far: it encodes and writes the file
        on the worker thread while the caller goes on (nothing may be logged after it). rerun's
        in-memory sink encodes the whole recording only then (≈ 0.3 s of CPU for 50 MB), so a caller
        with other work left (the mesh files) saves that much of :meth:`finish`'s wait."""
        self.submit(lambda rec: rec.close())

    def finish(self) -> None:
        """Close the recording (encode and write its file), wait, re-raise the first failure."""
        if not self._done:
            self.close_soon()
        self._stop()
        if self._error is not None:
            error, self._error = self._error, None
            if self._recorder is not None:
                self._recorder.abort()
            raise error

    def scan_done(self) -> None:
        """The scan logged everything: :meth:`finish`."""
        self.finish()

    def abort(self) -> None:
        """Wait for the thread and drop the unfinished recording (its file is removed)."""
        self._stop()
        if self._recorder is not None:
            self._recorder.abort()


def open_recorder(staging: Path, opts: RecordingChoice, name: str, filename: str = "scan.rrd", *,
                  image_scale: float = 0.5, full: bool = True) -> ScanRecording | None:
    """The run's recording (into ``staging``), or None when neither a file nor a viewer is wanted.

    ``image_scale`` 1 when the input video is stored as it is (its frames keep their size); ``full``
    :class:`~gnomon.recording.recorder.ScanRecording`'s (the maps at full size, a scan's mesh).
    """
    if not (opts.rrd or opts.view):
        return None
    return ScanRecording(staging / filename if opts.rrd else None, recording_name=name,
                         spawn_viewer=opts.view, frame_stride=opts.frame_stride, image_scale=image_scale,
                         log_notes=False, full=full)  # the scan's warnings report them


@contextmanager
def recording(staging: Path, opts: RecordingChoice, name: str, *,
               image_scale: float = 0.5, full: bool = True) -> Iterator[RecordingWorker | None]:
    """open_recorder on a :class:`RecordingWorker` (a viewer's recorder is opened here, for its notes),
    finished on success and aborted on failure."""
    if not (opts.rrd or opts.view):
        yield None
        return
    if opts.view:
        recorder = open_recorder(staging, opts, name, image_scale=image_scale, full=full)
        worker = RecordingWorker(recorder) if recorder is not None else None
    else:
        worker = RecordingWorker(lambda: open_recorder(staging, opts, name, image_scale=image_scale, full=full))
    try:
        yield worker
    except BaseException:
        if worker is not None:
            worker.abort()
        raise
    if worker is not None:
        worker.finish()
