"""`gnomon batch` on a real Dask cluster: a `dask scheduler` and two `dask worker` processes on 127.0.0.1.

The scans run on the workers and are compared byte for byte with the same
scans run sequentially in this process; a broken field log fails alone; a
worker killed in the middle of a scan has its task rerun on the other worker
with the same outputs; a rerun skips what is up to date.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import write_tiny_capture

pytest.importorskip("distributed")

import gnomon
from gnomon.runs.scan import ScanOptions, run_scan

PYTHON_DIR = str(Path(gnomon.__file__).resolve().parent.parent)
COMPARED = ("depth.npy", "sigma.npy", "shadow_time.npy", "undersampled.npy", "points.ply", "mesh.ply", "mesh.png")
START_TIMEOUT_S = 60
BATCH_TIMEOUT_S = 180


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = PYTHON_DIR + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["DASK_DISTRIBUTED__WORKER__DAEMON"] = "False"
    return env


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """A scheduler and worker processes started here, all on loopback, all stopped by :meth:`close`."""

    def __init__(self, root: Path):
        self.root = root
        self.port = _free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen] = []
        self.workers: list[subprocess.Popen] = []
        self.logs = root / "logs"
        self.logs.mkdir(parents=True, exist_ok=True)
        self.procs.append(self._spawn("scheduler", [sys.executable, "-m", "distributed.cli.dask_scheduler",
                                                    "--host", "127.0.0.1", "--port", str(self.port),
                                                    "--no-dashboard"]))

    def _spawn(self, name: str, cmd: list[str]) -> subprocess.Popen:
        with open(self.logs / f"{name}-{len(self.procs)}.log", "wb") as out:
            return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=_env(), cwd=self.root,
                                    start_new_session=True)

    def add_worker(self) -> subprocess.Popen:
        p = self._spawn("worker", [sys.executable, "-m", "distributed.cli.dask_worker", self.address,
                                   "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                   "--memory-limit", "0", "--death-timeout", "60"])
        self.procs.append(p)
        self.workers.append(p)
        return p

    def client(self):
        from distributed import Client

        return Client(self.address, timeout=START_TIMEOUT_S)

    def ensure_workers(self, n: int) -> dict[str, int]:
        """At least ``n`` live workers; returns {address: pid} of the live ones."""
        alive = [p for p in self.workers if p.poll() is None]
        for _ in range(n - len(alive)):
            self.add_worker()
        with self.client() as c:
            c.wait_for_workers(n, timeout=START_TIMEOUT_S)
            deadline = time.monotonic() + START_TIMEOUT_S
            while True:  # a killed worker may still be listed for a moment
                pids = c.run(os.getpid)
                if len(pids) >= n or time.monotonic() > deadline:
                    return pids
                time.sleep(0.1)

    def fresh_workers(self, n: int) -> None:
        """Exactly ``n`` workers that have run nothing yet: the live ones stopped, ``n`` new ones started
        (a worker keeps the memory of what it ran: its resident set does not shrink back)."""
        for p in self.workers:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.wait(timeout=30)
        new = {self.add_worker().pid for _ in range(n)}
        deadline = time.monotonic() + START_TIMEOUT_S
        with self.client() as c:
            while set(c.run(os.getpid).values()) != new:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"the scheduler did not list the {n} new workers")
                time.sleep(0.1)

    def close(self) -> None:
        for p in reversed(self.procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in reversed(self.procs):
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    c = Cluster(tmp_path_factory.mktemp("dask"))
    try:
        for _ in range(2):
            c.add_worker()
        c.ensure_workers(2)
        yield c
    finally:
        c.close()


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> dict[str, Path]:
    """Four small captures: the simulated desk lit from the left and from the right (ground truth,
    one camera: a merge pair) and two minimal sweeps with different lamps."""
    from gnomon.simulate import DeskLampConfig, simulate_desk_lamp

    root = tmp_path_factory.mktemp("captures")
    logs = {}
    for name, side in (("left", "left"), ("right", "right")):
        cfg = DeskLampConfig(width=240, height=180, frames=80, seed=1, lamp_side=side, pencil_photos=0)
        logs[name] = simulate_desk_lamp(root / name, cfg).field_log
    logs["tiny_a"] = write_tiny_capture(root / "tiny_a")
    logs["tiny_b"] = write_tiny_capture(root / "tiny_b", n_frames=30, lamp=(-150.0, 40.0, 450.0))
    return logs


@pytest.fixture(scope="module")
def sequential(captures, tmp_path_factory) -> dict[str, Path]:
    """The same scans, one after another in this process: the reference for the workers' outputs."""
    root = tmp_path_factory.mktemp("sequential")
    out = {}
    for name, log in captures.items():
        run_scan(log, root / name, ScanOptions(progress=False))
        out[name] = root / name
    return out


def _batch(args: list[str], timeout: float = BATCH_TIMEOUT_S, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "gnomon", "batch", "--quiet", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), **kw)


def _summary(out: Path) -> dict[str, dict]:
    with open(out / "summary.csv", newline="") as fh:
        return {row["name"]: row for row in csv.DictReader(fh)}


def _assert_same_outputs(a: Path, b: Path) -> None:
    for name in COMPARED:
        assert (a / name).read_bytes() == (b / name).read_bytes(), f"{a / name} differs from {b / name}"


def _run_batch_here(args: list, capsys) -> subprocess.CompletedProcess:
    """The CLI in this process (the workers are still other processes)."""
    from gnomon.cli import main

    code = main(["batch", "--quiet", *map(str, args)])
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, out, err)


@pytest.mark.slow
def test_batch_on_scheduler_equals_sequential_and_isolates_a_broken_log(cluster, captures, sequential, tmp_path,
                                                                        capsys):
    cluster.ensure_workers(2)
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "field_log.toml").write_text('[capture]\nframes = "frames/*.png"\n')  # no frames, no camera
    out = tmp_path / "batch"
    logs = [captures[n] for n in ("left", "right", "tiny_a", "tiny_b")] + [broken / "field_log.toml"]
    res = _run_batch_here([*logs, "--merge", "left,right", "--out", out, "--scheduler", cluster.address], capsys)
    assert res.returncode == 2, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("gnomon: error:")]
    assert len(errors) == 1 and str(broken / "field_log.toml") in errors[0], res.stderr

    rows = _summary(out)
    assert rows["broken"]["status"] == "failed" and rows["broken"]["error"] in errors[0]
    assert not (out / "broken").exists()
    workers = set()
    for name in ("left", "right", "tiny_a", "tiny_b"):
        assert rows[name]["status"] == "ok", rows[name]
        _assert_same_outputs(out / name, sequential[name])
        report = json.loads((sequential[name] / "report.json").read_text())
        assert int(rows[name]["points"]) == report["coverage"]["points"]
        workers.add(rows[name]["worker"])
    assert len(workers) == 2, "both workers took scans"
    # Ground truth exists for the simulated pair: the RMS is that of a working scan (the simulator's
    # desk scans measure well under 1 % of the camera distance at this size) and absent for the others.
    for name in ("left", "right"):
        assert 0 < float(rows[name]["rms_pct"]) < 1.0, rows[name]
        assert 0.05 < float(rows[name]["coverage_of_swept"]) <= 1.0
    assert rows["tiny_a"]["rms"] == ""
    assert rows["left+right"]["status"] == "ok"
    merged = int(rows["left+right"]["points"])
    assert merged > max(int(rows["left"]["points"]), int(rows["right"]["points"]))
    summary = json.loads((out / "summary.json").read_text())
    assert [j["name"] for j in summary["jobs"]] == ["left", "right", "tiny_a", "tiny_b", "broken", "left+right"]
    assert (out / "batch.rrd").stat().st_size > 0

    # A rerun skips what is up to date and rescans what changed (one frame's bytes).
    mtimes = {n: (out / n / "depth.npy").stat().st_mtime_ns for n in ("left", "right", "tiny_a", "tiny_b")}
    frame = min((captures["tiny_b"].parent / "frames").glob("*.png"))
    original = frame.read_bytes()
    try:
        import cv2

        img = cv2.imread(str(frame), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(frame), img, [cv2.IMWRITE_PNG_COMPRESSION, 9])  # same pixels, other bytes
        assert frame.read_bytes() != original
        res2 = _run_batch_here([*logs, "--merge", "left,right", "--out", out, "--scheduler", cluster.address],
                               capsys)
    finally:
        frame.write_bytes(original)
    assert res2.returncode == 2
    rows2 = _summary(out)
    assert [rows2[n]["status"] for n in ("left", "right", "tiny_a", "tiny_b", "left+right")] == \
        ["skipped", "skipped", "skipped", "ok", "skipped"]
    for n in ("left", "right", "tiny_a"):
        assert (out / n / "depth.npy").stat().st_mtime_ns == mtimes[n]
    _assert_same_outputs(out / "tiny_b", sequential["tiny_b"])  # same pixels, same scan


@pytest.mark.slow
def test_worker_killed_mid_scan_is_retried_with_the_same_outputs(cluster, tmp_path):
    """Frame 5 of the capture is a FIFO that nobody writes: the scan blocks there, so the kill
    certainly lands in the middle of it. The real frame replaces the FIFO's name first; the
    blocked reader keeps waiting on the FIFO until its worker dies."""
    pids = cluster.ensure_workers(2)
    log = write_tiny_capture(tmp_path / "killme")
    reference = tmp_path / "reference"
    run_scan(log, reference, ScanOptions(progress=False))
    frame = log.parent / "frames" / "frame_0005.png"
    real = tmp_path / "frame_0005.png"
    frame.replace(real)
    os.mkfifo(frame)

    out = tmp_path / "batch"
    proc = _batch([log, "--out", out, "--scheduler", cluster.address])
    try:
        killed = None
        with cluster.client() as c:
            deadline = time.monotonic() + BATCH_TIMEOUT_S
            while killed is None:
                assert time.monotonic() < deadline, "the scan never started"
                assert proc.poll() is None, proc.communicate()
                busy = [addr for addr, keys in c.processing().items() if any("scan-killme" in str(k) for k in keys)]
                if busy and list(out.glob(".killme.partial-*")):
                    killed = busy[0]
                else:
                    time.sleep(0.05)
        real.replace(frame)  # the retry reads the real frame; the blocked reader still waits on the FIFO
        os.kill(pids[killed], signal.SIGKILL)
        _, stderr = proc.communicate(timeout=BATCH_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, stderr
    row = _summary(out)["killme"]
    assert row["status"] == "ok" and row["worker"] != killed
    _assert_same_outputs(out / "killme", reference)
    assert not list(out.glob(".*partial*")), "the killed attempt's staging folder is gone"


@pytest.mark.slow
def test_batch_plan_errors_are_one_line_before_any_cluster_starts(tmp_path, capsys):
    from gnomon.cli import main

    a = write_tiny_capture(tmp_path / "a")
    b = write_tiny_capture(tmp_path / "other" / "a")
    cases = [
        ([a, "--merge", "a,zz"], "--merge a,zz: no scan named 'zz'"),
        ([a, b], "scan name 'a' is also that of"),
        ([a, "--batch-file", tmp_path / "none.toml"], "none.toml: no such batch file"),
        ([], "no field logs given"),
    ]
    for args, message in cases:
        assert main(["batch", *map(str, args), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "out").exists()


def test_batch_file_names_scans_and_merges(tmp_path):
    from gnomon.runs.batch import plan_batch

    write_tiny_capture(tmp_path / "d1")
    write_tiny_capture(tmp_path / "d2")
    (tmp_path / "survey.toml").write_text(
        '[[scan]]\nfield_log = "d1/field_log.toml"\nname = "nov12"\n'
        '[[scan]]\nfield_log = "d2/field_log.toml"\n'
        '[[merge]]\nscans = ["nov12", "d2"]\nweights = "sigmoid"\nbeta = 4.0\n')
    plan = plan_batch([], tmp_path / "out", batch_file=tmp_path / "survey.toml")
    assert [(s.name, s.field_log) for s in plan.scans] == [("nov12", (tmp_path / "d1/field_log.toml").resolve()),
                                                          ("d2", (tmp_path / "d2/field_log.toml").resolve())]
    (m,) = plan.merges
    assert (m.name, m.scan_a, m.scan_b, m.weights, m.beta) == ("nov12+d2", "nov12", "d2", "sigmoid", 4.0)
    assert m.out == (tmp_path / "out" / "nov12+d2").resolve()


_UNTILED = """
import json, sys
from gnomon.runs.scan import ScanOptions, run_scan
from gnomon.capture.tiles import current_rss_bytes, peak_rss_bytes, reset_peak_rss
reset_peak_rss()
start = current_rss_bytes()
run_scan(sys.argv[1], sys.argv[2], ScanOptions(progress=False))
print(json.dumps({"start": start, "peak": peak_rss_bytes()}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("normalize", [False, True], ids=["plain", "normalize_illumination"])
def test_tiled_scan_equals_untiled_with_less_memory_per_worker(cluster, tmp_path, normalize):
    """2x2 tiles tracked on the two workers, stitched: the untiled scan's outputs, byte for byte,
    and every worker's peak memory below the untiled scan's, in total and above its starting
    point. With illumination normalisation (whose gain is a whole-frame statistic) the capture
    is the minimal one: equality is the point there, not memory. The workers are fresh: one that ran
    the module's earlier scans keeps their memory (a worker peaked at 294.6 MB during a tile in one
    run of the whole suite, against the untiled process's 294.0 MB; fresh workers peak at 92-102 MB,
    the untiled process at 289 MB)."""
    if normalize:
        cluster.ensure_workers(2)
    else:
        cluster.fresh_workers(2)
    if normalize:
        log = write_tiny_capture(tmp_path / "cap", extra={"scan": {"normalize_illumination": True}})
        w, h = 48, 36
    else:
        log = write_tiny_capture(tmp_path / "cap", width=400, height=300, n_frames=24)
        w, h = 400, 300
    from gnomon.cli import main

    if normalize:
        run_scan(log, tmp_path / "untiled", ScanOptions(progress=False))
    else:  # in a fresh process, to measure its memory
        untiled = subprocess.run([sys.executable, "-c", _UNTILED, str(log), str(tmp_path / "untiled")],
                                 capture_output=True, text=True, env=_env(), timeout=BATCH_TIMEOUT_S, check=True)
        mem = json.loads(untiled.stdout.strip().splitlines()[-1])
    assert main(["scan", str(log), "--out", str(tmp_path / "tiled"), "--tiles", "2x2",
                 "--scheduler", cluster.address, "--quiet"]) == 0
    _assert_same_outputs(tmp_path / "tiled", tmp_path / "untiled")

    info = json.loads((tmp_path / "tiled" / "report.json").read_text())["tracking"]
    assert info["tiles"] == "2x2"
    assert sorted(map(tuple, info["tile_bounds"])) == [(0, h // 2, 0, w // 2), (0, h // 2, w // 2, w),
                                                        (h // 2, h, 0, w // 2), (h // 2, h, w // 2, w)]
    assert len(set(info["workers"])) == 2
    if normalize:
        return
    for peak, start in zip(info["worker_peak_rss_bytes"], info["worker_rss_at_start_bytes"], strict=True):
        assert peak < mem["peak"], (peak, mem)
        assert peak - start < mem["peak"] - mem["start"], (peak, start, mem)


@pytest.mark.slow
def test_a_tiled_scan_with_no_worker_left_stops_in_one_line(cluster, tmp_path, capsys, monkeypatch):
    """Every worker gone (killed, crashed) and none coming back: the scan does not wait for ever on its
    tiles; once the scheduler has listed no worker for NO_WORKER_TIMEOUT_S (here 3 s) it stops with one
    line naming the scheduler, exit code 2, nothing written."""
    from gnomon.cli import main
    from gnomon.util import dask_wait

    log = write_tiny_capture(tmp_path / "cap")
    monkeypatch.setattr(dask_wait, "NO_WORKER_TIMEOUT_S", 3.0)
    try:
        for p in cluster.workers:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                p.wait(timeout=30)
        capsys.readouterr()
        t0 = time.monotonic()
        code = main(["scan", str(log), "--out", str(tmp_path / "out"), "--tiles", "2x2",
                     "--scheduler", cluster.address, "--quiet"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, err
        assert "no worker for 3 s" in err[0] and cluster.address.split("//")[1] in err[0], err
        assert time.monotonic() - t0 < 60 and not (tmp_path / "out").exists()
    finally:
        cluster.fresh_workers(2)


def test_tiles_flag_errors_are_one_line(tmp_path, capsys):
    from gnomon.cli import main

    log = write_tiny_capture(tmp_path / "cap")
    for args, message in ((["--tiles", "2by2"], "--tiles '2by2': expected ROWSxCOLS"),
                          (["--scheduler", "tcp://127.0.0.1:1"], "add --tiles RxC"),
                          (["--tiles", "100x1", "--workers", "1"], "more tiles than pixels")):
        assert main(["scan", str(log), "--out", str(tmp_path / "out"), "--quiet", *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "out").exists()


def _children(pid: int) -> set[int]:
    """The processes whose parent is ``pid`` (Linux /proc)."""
    kids = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                kids.add(int(entry.name))
    return kids


def _running(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc to find the worker processes")
def test_a_terminated_local_batch_stops_its_workers_and_publishes_nothing(tmp_path):
    """SIGTERM to `gnomon batch` on its own LocalCluster while the scans run: one line, exit 143, the
    worker processes gone, no scan published after the stop and no staging folder left. (It used to close
    the cluster gracefully: the workers ran on for the nanny's grace period and published their scans,
    and Dask logged a warning per cancelled task.)"""
    logs = [write_tiny_capture(tmp_path / name, n_frames=400, width=320, height=240) for name in ("a", "b")]
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "gnomon", "batch", "--quiet", *map(str, logs), "--out", str(out),
                          "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and p.poll() is None and not (
            out.exists() and any(".partial-" in q.name for q in out.iterdir())):
        time.sleep(0.01)
    assert p.poll() is None, p.communicate()
    workers = {k for c in _children(p.pid) for k in _children(c) | {c}}  # spawn's helpers and their workers
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=BATCH_TIMEOUT_S)
    assert p.returncode == 128 + signal.SIGTERM, err
    assert err.strip().splitlines() == ["gnomon: terminated (SIGTERM)"], err
    time.sleep(2.0)  # a worker left running would publish its scan by now
    assert not any(_running(k) for k in workers)
    assert sorted(q.name for q in out.iterdir()) == [], "published or staged after the stop"
