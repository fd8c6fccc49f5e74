"""Publication of a run's outputs: all at once, never mixed, never half-written, stale folders cleaned."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from conftest import write_tiny_capture
from gnomon.cli import main
from gnomon.errors import OutputError
from gnomon.outputs import publish

NAMES = ("a.txt", "b.txt", "c.txt")


def dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def publish_run(out: Path, run: int, names=NAMES) -> None:
    with publish.staged_outputs(out, outputs=NAMES) as staging:
        for name in names:
            (staging / name).write_text(f"run {run}\n")


def test_new_folder_then_exchange_then_stale_output_removed(tmp_path: Path) -> None:
    out = tmp_path / "out"
    publish_run(out, 1)
    assert sorted(os.listdir(out)) == [".gnomon-outputs", *NAMES]
    publish_run(out, 2, names=("a.txt", "b.txt"))  # the new run writes no c.txt
    assert sorted(os.listdir(out)) == [".gnomon-outputs", "a.txt", "b.txt"]
    assert (out / "a.txt").read_text() == "run 2\n"
    assert [p for p in tmp_path.iterdir() if p.name != "out"] == []  # no staging left


def test_outputs_listed_by_the_previous_run_are_removed(tmp_path: Path) -> None:
    """An output name publish does not know (a newer format) is still removed when not rewritten."""
    out = tmp_path / "out"
    publish_run(out, 1, names=("a.txt", "new-format.bin"))
    assert (out / ".gnomon-outputs").read_text() == "a.txt\nnew-format.bin\n"
    (out / "notes.md").write_text("mine")
    publish_run(out, 2, names=("a.txt",))
    assert sorted(os.listdir(out)) == [".gnomon-outputs", "a.txt", "notes.md"]


def test_foreign_files_are_kept_and_stale_outputs_removed(tmp_path: Path) -> None:
    out = tmp_path / "out"
    publish_run(out, 1)
    (out / "notes.md").write_text("mine")
    (out / "sub").mkdir()
    publish_run(out, 2, names=("a.txt",))
    assert sorted(os.listdir(out)) == [".gnomon-outputs", "a.txt", "notes.md", "sub"]
    assert (out / "notes.md").read_text() == "mine"
    assert (out / "a.txt").read_text() == "run 2\n"


@pytest.mark.slow
def test_a_reader_sees_all_old_or_all_new(tmp_path: Path) -> None:
    """While runs publish over each other, every folder a reader opens holds one run's files."""
    out = tmp_path / "out"
    publish_run(out, 0)
    stop = threading.Event()
    mixed: list[tuple[str, ...]] = []
    reads = 0

    def reader() -> None:
        nonlocal reads
        while not stop.is_set():
            try:
                fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)  # one folder, as a reader would hold it
            except FileNotFoundError:
                mixed.append(("missing",))
                continue
            try:
                seen = []
                for name in NAMES:
                    try:
                        with open(name, opener=lambda p, f, fd=fd: os.open(p, f, dir_fd=fd)) as fh:
                            seen.append(fh.read())
                    except FileNotFoundError:
                        seen.append("gone")
                # A folder opened before a swap is the previous result, deleted afterwards:
                # its files may be gone, but what is there is never another run's.
                if len(set(seen) - {"gone"}) > 1:
                    mixed.append(tuple(seen))
                reads += 1
            finally:
                os.close(fd)

    t = threading.Thread(target=reader)
    t.start()
    try:
        for run in range(1, 150):
            publish_run(out, run)
    finally:
        stop.set()
        t.join()
    assert reads > 50
    assert mixed == []


def test_stale_staging_of_dead_processes_is_removed(tmp_path: Path) -> None:
    out = tmp_path / "out"
    publish_run(out, 1)
    pid = dead_pid()
    beside = tmp_path / f".out.partial-{pid}-abc123"
    beside.mkdir()
    (beside / "a.txt").write_text("half")
    inside = out / f".gnomon-partial-{pid}-xyz"
    inside.mkdir()
    old_layout = tmp_path / ".out.partial-k2j3h4g5"  # an older version's mkdtemp name
    old_layout.mkdir()
    alive = tmp_path / f".out.partial-{os.getppid()}-live"  # a running process's staging stays
    alive.mkdir()
    publish_run(out, 2)
    assert not beside.exists() and not inside.exists() and not old_layout.exists()
    assert alive.exists()
    assert sorted(os.listdir(out)) == [".gnomon-outputs", *NAMES]


def test_commit_folder_of_a_killed_run_is_completed(tmp_path: Path) -> None:
    """A run killed while moving its committed files in: the next run (or a reader) finishes it."""
    out = tmp_path / "out"
    publish_run(out, 1)
    (out / "foreign").write_text("x")  # forces the per-file path
    commit = out / f".gnomon-commit-{dead_pid()}-q1"
    commit.mkdir()
    (commit / ".gnomon-outputs").write_text("a.txt\nb.txt\n")
    (commit / "a.txt").write_text("run 2\n")
    (commit / "b.txt").write_text("run 2\n")
    os.replace(commit / "a.txt", out / "a.txt")  # killed after the first move
    publish.recover(out, NAMES)
    assert not commit.exists()
    assert (out / "a.txt").read_text() == (out / "b.txt").read_text() == "run 2\n"
    assert not (out / "c.txt").exists()  # run 2 did not write it


def test_failure_publishes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    publish_run(out, 1)
    with pytest.raises(RuntimeError), publish.staged_outputs(out, outputs=NAMES) as staging:
        (staging / "a.txt").write_text("run 2\n")
        raise RuntimeError("scan failed")
    assert all((out / n).read_text() == "run 1\n" for n in NAMES)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_out_is_a_file_or_under_a_file(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(OutputError, match="is a file"):
        publish.staged_outputs(f).__enter__()
    with pytest.raises(OutputError, match="is a file"):
        publish.staged_outputs(f / "sub").__enter__()
    assert f.read_text() == "x"


def test_rrd_on_another_filesystem_is_copied(tmp_path: Path, monkeypatch) -> None:
    """A rename across filesystems (EXDEV) falls back to copy + fsync + rename beside --rrd."""
    out, rrd = tmp_path / "out", tmp_path / "elsewhere" / "rec.rrd"
    real_rename = os.rename
    crossed = []

    def rename(src, dst, *a, **k):
        if Path(dst).parent == rrd.parent:
            crossed.append(dst)
            raise OSError(errno.EXDEV, os.strerror(errno.EXDEV), str(src), None, str(dst))
        return real_rename(src, dst, *a, **k)

    monkeypatch.setattr(os, "rename", rename)
    with publish.staged_outputs(out, rrd) as staging:
        (staging / "points.ply").write_text("p")
        (staging / "scan.rrd").write_bytes(b"R" * 100_000)
    assert crossed
    assert rrd.read_bytes() == b"R" * 100_000
    assert sorted(os.listdir(out)) == [".gnomon-outputs", "points.ply"]
    assert sorted(os.listdir(rrd.parent)) == ["rec.rrd"]


@pytest.mark.slow
def test_rrd_naming_a_folder_is_refused_before_the_scan(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    (tmp_path / "recs").mkdir()
    code = main(["scan", str(log), "--out", str(tmp_path / "out"), "--rrd", str(tmp_path / "recs"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--rrd" in err[0] and "folder" in err[0], err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_rescan_with_no_rrd_drops_the_old_recording(tmp_path: Path, capsys) -> None:
    log = write_tiny_capture(tmp_path / "cap")
    out = tmp_path / "out"
    assert main(["scan", str(log), "--out", str(out), "--quiet"]) == 0
    assert (out / "scan.rrd").is_file()
    old_depth = np.load(out / "depth.npy")
    assert main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"]) == 0
    assert not (out / "scan.rrd").exists()
    np.testing.assert_array_equal(np.load(out / "depth.npy"), old_depth)  # same input, same result
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap", "out"]


def _can_mount_tmpfs(where: Path) -> bool:
    if os.geteuid() != 0:
        return False
    where.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(where)], capture_output=True)
    return r.returncode == 0


@pytest.mark.slow
def test_out_is_a_mount_point(tmp_path: Path, capsys) -> None:
    """--out is its own filesystem (a Docker volume, a USB drive): stage inside it."""
    out = tmp_path / "mnt"
    if not _can_mount_tmpfs(out):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        log = write_tiny_capture(tmp_path / "cap")
        assert os.stat(out).st_dev != os.stat(tmp_path).st_dev
        assert main(["scan", str(log), "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
        assert main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"]) == 0, capsys.readouterr().err
        names = set(os.listdir(out))
        assert "scan.rrd" not in names and {"points.ply", "depth.npy", "report.json"} <= names
        assert not [n for n in names if n.startswith(".gnomon-") and n != ".gnomon-outputs"]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["cap", "mnt"]
    finally:
        subprocess.run(["umount", str(out)], check=False)
