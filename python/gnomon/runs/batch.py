"""`gnomon batch`: many scans (and merges of scan pairs) as tasks on a Dask cluster.

A batch is a list of :class:`ScanJob` (one field log → one output folder) and
:class:`MergeJob` (two of those scans → one merged folder). Each job is one
Dask task; a merge task depends on its two scans' tasks. The tasks carry
*paths*, never pixels: every worker reads the frames itself from storage that
the client and all workers see under the same absolute paths (a local disk
for a LocalCluster, a shared file system on a cluster; see docs/batch.md).

Faults are per job: a scan whose input is bad (a :class:`GnomonError`) comes
back as a failed :class:`JobResult` carrying the one-line message, and the
other jobs go on. A worker that dies mid-scan is handled by the scheduler,
which runs the task again elsewhere; the scan's outputs are staged and
published only when complete, so a retried scan never leaves mixed outputs.
A job whose outputs are complete and whose recorded input digests (field log,
frames, camera file, gnomon version) still match is skipped.

Dask is an optional dependency (``pip install "gnomon[dask]"``): this module
imports it only inside :func:`run_batch`, so the job functions themselves run
anywhere (and are what the workers import).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import re
import shutil
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from gnomon import __version__
from gnomon.errors import FieldLogError, GnomonError
from gnomon.util import atomic, toml_io

__all__ = [
    "SUMMARY_COLUMNS",
    "BatchPlan",
    "JobResult",
    "MergeJob",
    "ScanJob",
    "connect_client",
    "input_digests",
    "load_batch_file",
    "plan_batch",
    "run_batch",
    "run_merge_job",
    "run_scan_job",
    "scan_outputs_complete",
    "write_summary",
]

# The files a finished scan (with and without a recording) and a finished merge leave.
SCAN_FILES = ("points.ply", "mesh.ply", "depth.npy", "sigma.npy", "shadow_time.npy",
              "undersampled.npy", "report.json")
MERGE_FILES = ("points.ply", "mesh.ply", "depth.npy", "sigma.npy", "report.json")

SUMMARY_COLUMNS = ("name", "kind", "status", "points", "coverage_of_image", "coverage_of_swept",
                   "rms", "rms_pct", "units", "warnings", "time_s", "worker", "error", "out")


@dataclass(frozen=True)
class ScanJob:
    """One `gnomon scan` of ``field_log`` into ``out`` (absolute paths, seen alike by every worker)."""

    name: str
    field_log: Path
    out: Path
    rrd: bool = True
    frame_stride: int = 10
    force: bool = False  # rescan even when the outputs are up to date


@dataclass(frozen=True)
class MergeJob:
    """One `gnomon merge` of the scans named ``scan_a`` and ``scan_b`` into ``out``."""

    name: str
    scan_a: str
    scan_b: str
    out: Path
    weights: str = "gaussian"
    beta: float = 10.0
    rrd: bool = True


@dataclass
class JobResult:
    """What one job did: one row of the summary table.

    ``status``: ``"ok"`` (ran), ``"skipped"`` (outputs up to date) or
    ``"failed"`` (``error`` is the one-line reason). ``coverage_of_image``:
    fraction of the image's pixels with a depth (0..1). ``rms`` (world units,
    ``units``) and ``coverage_of_swept`` (0..1) against the simulator's ground
    truth (``ground_truth.npz`` beside the field log), when there is one;
    ``rms_pct`` is ``rms`` in % of the camera distance. ``time_s``: wall time
    of the job on its worker, seconds.
    """

    name: str
    kind: str  # "scan" | "merge"
    status: str
    out: str
    points: int | None = None
    coverage_of_image: float | None = None
    coverage_of_swept: float | None = None
    rms: float | None = None
    rms_pct: float | None = None
    units: str | None = None
    warnings: list[str] = field(default_factory=list)
    time_s: float = 0.0
    worker: str | None = None
    error: str | None = None

    def row(self) -> dict:
        """The summary row (warnings as their count)."""
        d = asdict(self)
        d["warnings"] = len(self.warnings)
        return {k: d[k] for k in SUMMARY_COLUMNS}


@dataclass
class BatchPlan:
    scans: list[ScanJob]
    merges: list[MergeJob]


# --------------------------------------------------------------------------- planning


_NAME_OK = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


def scan_name(field_log: Path) -> str:
    """A scan's name: its field log's folder for ``field_log.toml``, else the file's stem."""
    p = Path(field_log)
    return p.parent.resolve().name if p.name == "field_log.toml" else p.stem


def _check_name(name: str, where: str) -> str:
    if not _NAME_OK.match(name):
        raise GnomonError(f"{where}: name {name!r} is not usable as an output folder "
                          "(letters, digits, '.', '_', '-', '+'; not starting with '.')")
    return name


def plan_batch(field_logs: Sequence[Path], out: Path, *, merges: Sequence[str] = (),
               batch_file: Path | None = None, rrd: bool = True, frame_stride: int = 10,
               force: bool = False, weights: str = "gaussian", beta: float = 10.0) -> BatchPlan:
    """The jobs of a batch: scans of ``field_logs`` (and of the batch file), merges of scan pairs.

    ``merges``: ``"A,B"`` items naming two scans; the merge is written to
    ``OUT/A+B``. Names must be unique (rename a folder, or give ``name`` in a
    batch file).
    """
    out = Path(out).resolve()
    entries: list[tuple[str, Path, str]] = []  # name, field log, where it came from
    merge_specs: list[tuple[str | None, str, str, str, float, str]] = []
    if batch_file is not None:
        b_scans, b_merges = load_batch_file(batch_file)
        entries += b_scans
        merge_specs += [(n, a, b, w if w else weights, bt if bt is not None else beta, where)
                        for n, a, b, w, bt, where in b_merges]
    for f in field_logs:
        entries.append((scan_name(Path(f)), Path(f), str(f)))
    for item in merges:
        parts = [s.strip() for s in item.split(",")]
        if len(parts) != 2 or not all(parts):
            raise GnomonError(f"--merge {item!r}: expected two scan names, e.g. --merge left,right")
        merge_specs.append((None, parts[0], parts[1], weights, beta, f"--merge {item}"))
    if not entries:
        raise GnomonError("gnomon batch: no field logs given (and no [[scan]] in a batch file)")

    scans: list[ScanJob] = []
    seen: dict[str, str] = {}
    for name, log, where in entries:
        _check_name(name, where)
        if name in seen:
            raise GnomonError(f"{where}: scan name {name!r} is also that of {seen[name]}; "
                              "give unique folder names (or names in a batch file)")
        seen[name] = where
        scans.append(ScanJob(name, Path(log).resolve(), out / name, rrd=rrd, frame_stride=frame_stride,
                             force=force))
    jobs: list[MergeJob] = []
    for mname_given, a, b, w, bt, where in merge_specs:
        for s in (a, b):
            if s not in seen:
                raise GnomonError(f"{where}: no scan named {s!r} in this batch (scans: {', '.join(seen)})")
        if a == b:
            raise GnomonError(f"{where}: a merge needs two different scans")
        if w not in ("gaussian", "sigmoid"):
            raise GnomonError(f"{where}: weights {w!r}: expected 'gaussian' or 'sigmoid'")
        mname = _check_name(mname_given or f"{a}+{b}", where)
        if mname in seen:
            raise GnomonError(f"{where}: output name {mname!r} is already used by {seen[mname]}")
        seen[mname] = where
        jobs.append(MergeJob(mname, a, b, out / mname, weights=w, beta=float(bt), rrd=rrd))
    return BatchPlan(scans, jobs)


def load_batch_file(path: Path) -> tuple[list[tuple[str, Path, str]], list[tuple]]:
    """A batch file (TOML): ``[[scan]] field_log = "...", name = "..."`` (name optional) and
    ``[[merge]] scans = ["A", "B"], name, weights, beta`` (all but scans optional).
    Relative paths are relative to the batch file."""
    path = Path(path)
    if not path.is_file():
        raise GnomonError(f"{path}: no such batch file")
    try:
        data = toml_io.load(path)
    except (ValueError, OSError) as exc:
        raise GnomonError(f"{path}: not a readable TOML batch file ({exc})") from None
    unknown = set(data) - {"scan", "merge"}
    if unknown:
        raise FieldLogError(f"{path}: unknown table(s) {sorted(unknown)} (expected [[scan]] and [[merge]])")
    scans = []
    for i, entry in enumerate(data.get("scan", [])):
        where = f"{path}: [[scan]] #{i + 1}"
        if not isinstance(entry, dict) or "field_log" not in entry:
            raise FieldLogError(f"{where}: missing key field_log")
        extra = set(entry) - {"field_log", "name"}
        if extra:
            raise FieldLogError(f"{where}: unknown key(s) {sorted(extra)}")
        log = Path(entry["field_log"])
        log = log if log.is_absolute() else path.parent / log
        scans.append((str(entry.get("name") or scan_name(log)), log, where))
    merges = []
    for i, entry in enumerate(data.get("merge", [])):
        where = f"{path}: [[merge]] #{i + 1}"
        if not isinstance(entry, dict) or "scans" not in entry:
            raise FieldLogError(f"{where}: missing key scans (two scan names)")
        extra = set(entry) - {"scans", "name", "weights", "beta"}
        if extra:
            raise FieldLogError(f"{where}: unknown key(s) {sorted(extra)}")
        pair = entry["scans"]
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(s, str) for s in pair)):
            raise FieldLogError(f"{where}: scans must be two scan names")
        merges.append((entry.get("name"), pair[0], pair[1], entry.get("weights"), entry.get("beta"), where))
    return scans, merges


# --------------------------------------------------------------------------- up-to-date check


def input_digests(field_log: Path) -> dict:
    """The digests ``report.json`` records under ``inputs``, computed without scanning.

    ``frames_sha256`` hashes every frame file's bytes in order (a video: the file),
    as the scan does while decoding.
    """
    from gnomon.capture.frames import sha256_file
    from gnomon.config.fieldlog import load_field_log

    log = load_field_log(field_log)
    if log.capture.video is not None:
        frames = sha256_file(log.capture.video)
    else:
        h = hashlib.sha256()
        for f in log.capture.image_files:
            with open(f, "rb") as fh:
                while block := fh.read(1 << 20):
                    h.update(block)
        frames = h.hexdigest()
    return {
        "field_log_sha256": sha256_file(log.path),
        "frames_sha256": frames,
        "camera_file_sha256": sha256_file(log.camera_file) if log.camera_file else None,
    }


def scan_outputs_complete(job: ScanJob) -> dict | None:
    """The report of ``job.out`` if its outputs are complete and were made by this gnomon
    version from the same inputs (digests), else None."""
    files = SCAN_FILES + (("scan.rrd",) if job.rrd else ())
    if not all((job.out / f).is_file() for f in files):
        return None
    try:
        report = json.loads((job.out / "report.json").read_text())
        recorded = report["inputs"]
        if report.get("gnomon_version") != __version__:
            return None
        now = input_digests(job.field_log)
    except (GnomonError, OSError, ValueError, KeyError, TypeError):
        return None  # unreadable report or input: scan again (and report the problem then)
    if any(recorded.get(k) != v for k, v in now.items()):
        return None
    return report


def _remove_stale_staging(out: Path) -> None:
    """Staging folders a killed worker left for this output (``.NAME.partial-*``)."""
    if out.parent.is_dir():
        for p in out.parent.glob(f".{out.name}.partial-*"):
            shutil.rmtree(p, ignore_errors=True)


# --------------------------------------------------------------------------- the tasks


def _worker_name() -> str | None:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return None


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if isinstance(exc, GnomonError) else f"{type(exc).__name__}: {text}"


def _ground_truth_row(result: JobResult, depth: np.ndarray, field_log: Path, units: str) -> None:
    """RMS and coverage against ``ground_truth.npz`` beside the field log, when there is one."""
    from gnomon.runs.accuracy import depth_accuracy

    gt = field_log.parent / "ground_truth.npz"
    if not gt.is_file():
        return
    with np.load(gt) as truth:
        if "depth" not in truth or "swept" not in truth or truth["depth"].shape != depth.shape:
            return
        key = "camera_distance_mm" if units == "mm" or "camera_distance" not in truth else "camera_distance"
        if key not in truth:
            return
        acc = depth_accuracy(depth, truth["depth"], truth["swept"], float(truth[key]), units)
    result.rms, result.rms_pct, result.coverage_of_swept = acc.rms, acc.rms_pct, float(acc.coverage)


def _fill_from_report(result: JobResult, report: dict, depth: np.ndarray) -> None:
    cov = report["coverage"]
    result.points = int(cov["points"])
    result.coverage_of_image = float(cov["points"]) / float(depth.size)
    result.units = report.get("units")
    result.warnings = list(report.get("warnings", []))


def run_scan_job(job: ScanJob) -> JobResult:
    """Run (or skip) one scan; never raises for a problem with the input.

    Input problems (:class:`GnomonError`) and bugs alike come back as a failed
    result with a one-line error, so one bad scan never stops a batch. A worker
    that dies here is the scheduler's business (it reruns the task elsewhere).
    """
    from gnomon.runs.scan import ScanOptions, run_scan

    t0 = time.perf_counter()
    result = JobResult(job.name, "scan", "ok", str(job.out), worker=_worker_name())
    try:
        report = None if job.force else scan_outputs_complete(job)
        if report is not None:
            result.status = "skipped"
        else:
            _remove_stale_staging(job.out)
            scan = run_scan(job.field_log, job.out, ScanOptions(rrd=job.rrd, progress=False,
                                                                frame_stride=job.frame_stride))
            report = scan.report
        depth = np.load(job.out / "depth.npy")
        _fill_from_report(result, report, depth)
        _ground_truth_row(result, depth, job.field_log, result.units or "mm")
    except GnomonError as exc:
        # Keep the message as is when it names a file of this capture; else say which field log.
        text = _one_line(exc)
        result.status = "failed"
        result.error = text if str(job.field_log.parent) in text else f"{job.field_log}: {text}"
    except Exception as exc:  # noqa: BLE001 - a bug: one line here, the traceback in the worker's log
        traceback.print_exc()
        result.status, result.error = "failed", f"{job.field_log}: {_one_line(exc)}"
    result.time_s = time.perf_counter() - t0
    return result


def _newer_than(path: Path, *others: Path) -> bool:
    """``path`` was written after every one of ``others`` (a merge made from these scans)."""
    return all(path.stat().st_mtime_ns >= o.stat().st_mtime_ns for o in others)


def run_merge_job(job: MergeJob, a: JobResult, b: JobResult) -> JobResult:
    """Merge two scans' outputs once both succeeded; skipped when neither was rescanned and
    the merged outputs are complete."""
    from gnomon.runs.merge import merge_scans
    from gnomon.runs.scan import ScanOptions

    t0 = time.perf_counter()
    result = JobResult(job.name, "merge", "ok", str(job.out), worker=_worker_name())
    try:
        bad = [r for r in (a, b) if r.status == "failed"]
        if bad:
            raise GnomonError(f"not merged: scan {bad[0].name!r} failed")
        files = MERGE_FILES + (("merge.rrd",) if job.rrd else ())
        up_to_date = (a.status == b.status == "skipped" and all((job.out / f).is_file() for f in files)
                      and _newer_than(job.out / "report.json", Path(a.out) / "report.json",
                                      Path(b.out) / "report.json"))
        if up_to_date:
            result.status = "skipped"
            report = json.loads((job.out / "report.json").read_text())
        else:
            _remove_stale_staging(job.out)
            _, report = merge_scans(a.out, b.out, job.out, method=job.weights, beta=job.beta,
                                    options=ScanOptions(rrd=job.rrd, progress=False))
        depth = np.load(job.out / "depth.npy")
        _fill_from_report(result, report, depth)
    except GnomonError as exc:
        result.status, result.error = "failed", f"{job.name}: {_one_line(exc)}"
    except Exception as exc:  # noqa: BLE001 - as in run_scan_job
        traceback.print_exc()
        result.status, result.error = "failed", f"{job.name}: {_one_line(exc)}"
    result.time_s = time.perf_counter() - t0
    return result


# --------------------------------------------------------------------------- the batch


def connect_client(scheduler: str | None, workers: int | None, timeout_s: float = 30.0):
    """``(client, cluster)``: a distributed Client of ``scheduler`` (an address, cluster None), or of a new
    LocalCluster of ``workers`` processes on 127.0.0.1 (close both when done)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise GnomonError('gnomon batch needs Dask: pip install "gnomon[dask]"') from None
    if scheduler:
        try:
            return Client(scheduler, timeout=timeout_s), None
        except (OSError, TimeoutError) as exc:
            raise GnomonError(f"--scheduler {scheduler}: cannot connect ({_one_line(exc)})") from None
    n = workers or max(1, min(os.cpu_count() or 1, 4))
    # dashboard_address ":0": a free port (None still serves HTTP on 8787, and warns over three lines on
    # stderr when another Dask cluster or a notebook's dashboard already holds it)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=":0")
    return Client(cluster, timeout=timeout_s), cluster


def _task_key(kind: str, name: str) -> str:
    # Unique per batch run: a rerun must not pick up a previous run's cached result.
    return f"gnomon-{kind}-{name}-{os.getpid()}-{time.time_ns()}"


def run_batch(plan: BatchPlan, *, scheduler: str | None = None, workers: int | None = None,
              retries: int = 2, progress: bool = True, timeout_s: float = 30.0,
              on_result: Callable[[JobResult], None] | None = None) -> list[JobResult]:
    """Run the plan's jobs on Dask and return one result per job (scans first, then merges).

    ``scheduler``: the address of a running scheduler (``tcp://host:port``);
    None starts a LocalCluster of ``workers`` processes (one thread each) for
    the duration of the batch. ``retries``: extra attempts of a task that
    raised (not of a bad input, which is a result); a worker lost mid-task is
    rescheduled by the scheduler (``distributed.scheduler.allowed-failures``).
    """
    from gnomon.util.dask_wait import completed
    from gnomon.util.progress import Progress

    client, cluster = connect_client(scheduler, workers, timeout_s)
    interrupted = False
    try:
        futures = {}
        for job in plan.scans:
            futures[job.name] = client.submit(run_scan_job, job, key=_task_key("scan", job.name),
                                              retries=retries, pure=False)
        for m in plan.merges:
            futures[m.name] = client.submit(run_merge_job, m, futures[m.scan_a], futures[m.scan_b],
                                            key=_task_key("merge", m.name), retries=retries, pure=False)
        results: dict[str, JobResult] = {}
        names = {f.key: n for n, f in futures.items()}
        jobs: dict[str, ScanJob | MergeJob] = {j.name: j for j in plan.scans}
        jobs.update({m.name: m for m in plan.merges})
        with Progress("batch", len(futures), enabled=progress) as bar:
            for fut in completed(client, list(futures.values()), what="the batch"):
                name = names[fut.key]
                try:
                    res = fut.result()
                except Exception as exc:  # noqa: BLE001 - the task died (KilledWorker after repeated losses)
                    lost = jobs[name]
                    kind = "merge" if isinstance(lost, MergeJob) else "scan"
                    res = JobResult(name, kind, "failed", str(lost.out), error=f"{name}: {_one_line(exc)}")
                results[name] = res
                if on_result is not None:
                    on_result(res)
                bar.update(len(results))
        return [results[n] for n in jobs]
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM/SIGHUP (gnomon.cli.Terminated)
        interrupted = True
        if cluster is not None:
            stop_local_workers(cluster)
        raise
    finally:
        close_client(client, cluster)
        if interrupted and cluster is not None:  # the killed workers are reaped by now
            remove_staging([j.out for j in plan.scans] + [m.out for m in plan.merges])


def stop_local_workers(cluster) -> None:
    """An interrupted batch stops its LocalCluster's workers at once (SIGKILL), so that no scan they were
    running publishes after the user said stop (a graceful close lets them run on for the nanny's grace
    period: measured, a batch of three real captures terminated 4-7 s in published two of them seconds
    later, and Dask logged a warning per cancelled task). A worker the nanny restarts meanwhile is closed
    with the cluster. A running scheduler's workers (``--scheduler``) are not ours to kill: their tasks
    are cancelled with the client."""
    import logging
    import signal

    # the deaths below are meant: nothing Dask logs about them (the comms they close included, which
    # "distributed.batched" reported at INFO on a terminated batch's stderr) is the user's to read
    for name in ("distributed", "distributed.nanny", "distributed.worker", "distributed.core", "distributed.scheduler",
                 "distributed.batched", "distributed.comm"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    for nanny in list(getattr(cluster, "workers", {}).values()):
        pid = getattr(getattr(getattr(nanny, "process", None), "process", None), "pid", None)
        if pid:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:  # already gone
                pass


def remove_staging(outs: Sequence[Path]) -> None:
    """The staging folders workers killed by :func:`stop_local_workers` left beside or inside each job's
    output folder (:func:`gnomon.outputs.publish.recover`; once the cluster is closed, their processes are reaped,
    so their owners are known not to run)."""
    from gnomon.outputs.publish import recover

    for out in outs:
        try:
            recover(out)
        except OSError:
            pass


def close_client(client, cluster) -> None:
    """Close a :func:`connect_client` pair. A local worker still busy after the nanny's grace period is
    killed on purpose (our scan tasks hold no state worth saving), so that warning is not shown."""
    import logging

    client.close()
    if cluster is not None:
        nanny = logging.getLogger("distributed.nanny")
        level = nanny.level
        nanny.setLevel(logging.ERROR)
        try:
            cluster.close()
        finally:
            nanny.setLevel(level)


# --------------------------------------------------------------------------- the summary


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def summary_markdown(results: Sequence[JobResult]) -> str:
    head = "| name | kind | status | points | coverage | RMS | warnings | time s | error |\n" \
           "|---|---|---|---|---|---|---|---|---|\n"
    rows = []
    for r in results:
        cov = "" if r.coverage_of_image is None else f"{100 * r.coverage_of_image:.1f} %"
        rms = "" if r.rms is None else f"{r.rms:.4g} {r.units} ({r.rms_pct:.3f} %)"
        rows.append(f"| {r.name} | {r.kind} | {r.status} | {_fmt(r.points)} | {cov} | {rms} | "
                    f"{len(r.warnings)} | {r.time_s:.2f} | {r.error or ''} |")
    return head + "\n".join(rows) + "\n"


def write_summary(results: Sequence[JobResult], out: Path, *, rrd: bool = True, wall_s: float | None = None) -> None:
    """``OUT/summary.csv``, ``OUT/summary.json`` and (``rrd``) ``OUT/batch.rrd``, each atomically."""
    out = Path(out)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(SUMMARY_COLUMNS), lineterminator="\n")
    w.writeheader()
    for r in results:
        w.writerow({k: _fmt(v) for k, v in r.row().items()})
    atomic.write_text(out / "summary.csv", buf.getvalue())
    doc = {"gnomon_version": __version__, "wall_time_s": wall_s,
           "jobs": [asdict(r) for r in results]}
    atomic.write_text(out / "summary.json", json.dumps(doc, indent=2))
    if rrd:
        _write_batch_recording(results, out / "batch.rrd")


def _write_batch_recording(results: Sequence[JobResult], path: Path) -> None:
    """One rerun recording of the batch: the table, each job's numbers, warnings and errors."""
    import uuid

    import rerun as rr

    rec = rr.RecordingStream("gnomon", recording_id=uuid.uuid4())
    # Encoded in memory and written by us (as gnomon.recording.recorder does): rerun's own file writer
    # can hang on a full disk, an atomic write fails at once naming the file.
    stream = rr.binary_stream(recording=rec)
    try:
        rec.send_recording_name("gnomon batch")
        rec.log("batch/summary", rr.TextDocument(summary_markdown(results), media_type=rr.MediaType.MARKDOWN),
                static=True)
        for r in results:
            base = f"batch/jobs/{r.name}"
            for key in ("points", "coverage_of_image", "coverage_of_swept", "rms", "rms_pct", "time_s"):
                v = getattr(r, key)
                if v is not None and np.isfinite(v):
                    rec.log(f"{base}/{key}", rr.Scalars(float(v)), static=True)
            for text in r.warnings:
                rec.log(f"{base}/log", rr.TextLog(text, level="WARN"), static=False)
            if r.error:
                rec.log(f"{base}/log", rr.TextLog(r.error, level="ERROR"), static=False)
        data = stream.read(flush=True) or b""
    finally:
        rec.disconnect()
    atomic.write_bytes(path, data + (stream.read(flush=False) or b""))
