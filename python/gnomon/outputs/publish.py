"""Publishing a run's outputs into its output folder, all at once.

A scan (or merge) writes every output into a *staging* folder on the same
filesystem as the output folder ``OUT``, fsyncs it, and only then makes it
visible:

- ``OUT`` does not exist yet: the staging folder is renamed to ``OUT``.
- ``OUT`` holds only Gnomon outputs: the staging folder and ``OUT`` are
  exchanged in one step (``renameat2(RENAME_EXCHANGE)``), so a reader sees
  either the whole previous result or the whole new one, never a mixture; the
  previous result (now in the staging folder's place) is then deleted.
- Otherwise (``OUT`` also holds other files, ``OUT`` is itself a mount point,
  or the exchange is not supported): the staging folder becomes a *commit*
  folder inside ``OUT`` by one rename, and its files are moved over the old
  ones; outputs of a previous run that the new one did not write (``scan.rrd``
  after a ``--no-rrd`` rescan) are removed. Interrupt signals are held off
  during this step, and a commit folder left by a killed process is completed
  by the next run (:func:`recover`) — the commit folder only ever exists once
  every new file is complete on disk.

Staging folders are named after the process that owns them
(``.OUT.partial-PID-…`` beside ``OUT``, or ``OUT/.gnomon-partial-PID-…``);
those of processes that no longer run are deleted by the next run.

A recording requested elsewhere (``--rrd PATH``) is staged with the rest and
moved to ``PATH`` last; when ``PATH`` is on another filesystem it is copied to
a temporary file beside ``PATH``, fsynced and renamed.

Every filesystem failure (no space, file too large, read-only filesystem,
permission denied, a file where a folder should be) becomes an
:class:`~gnomon.errors.OutputError` naming the output path.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import re
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from gnomon.errors import OutputError
from gnomon.util import interrupts
from gnomon.util.validate import check_output_file, check_output_folder

__all__ = [
    "FIXED_OUTPUT_FILES",
    "output_files",
    "fsync_tree",
    "output_error",
    "recover",
    "staged_outputs",
]

#: Files a scan or a merge of this or an earlier version may have published into its output folder
#: besides its mesh formats' (a folder written by this version also lists its own in ``.gnomon-outputs``).
FIXED_OUTPUT_FILES = ("points.ply", "points_enu.ply", "mesh.png", "depth.npz", "depth.npy", "sigma.npy",
                      "shadow_time.npy", "undersampled.npy", "coverage.npy", "preview.png", "report.json",
                      "scan.rrd", "merge.rrd")


def output_files() -> tuple[str, ...]:
    """Every file a scan or merge may publish: the fixed ones and each registered mesh format's."""
    from gnomon.outputs.formats import FORMATS

    return FIXED_OUTPUT_FILES + tuple(f for fmt in FORMATS.values() for f in fmt.files if f not in FIXED_OUTPUT_FILES)


_INSIDE_PARTIAL = ".gnomon-partial-"
_INSIDE_COMMIT = ".gnomon-commit-"
_TMP_NAME = re.compile(r"^\.(?P<name>.+)\.[A-Za-z0-9_]+\.tmp$")


# --------------------------------------------------------------------- errors


def output_error(exc: OSError, path: str | os.PathLike | None = None, *, staging: Path | None = None,
                 out: Path | None = None) -> OutputError:
    """One line for a failed write: the output's path and the system's reason.

    A path inside the staging folder (or a temporary file there) is reported as
    the output it stands for, ``OUT/name``.
    """
    where = Path(path if path is not None else (exc.filename or "?"))
    if staging is not None and out is not None:
        try:
            rel = where.relative_to(staging)
        except ValueError:
            pass
        else:
            parts = list(rel.parts)
            m = _TMP_NAME.match(parts[-1]) if parts else None
            if m:
                parts[-1] = m.group("name")
            where = out.joinpath(*parts) if parts else out
    reason = exc.strerror or str(exc)
    hint = {
        errno.ENOSPC: "; free some space or choose another --out",
        errno.EDQUOT: "; the disk quota is exhausted",
        errno.EFBIG: " (a file-size limit, `ulimit -f`?)",
        errno.EROFS: "; choose a writable --out",
        errno.EXDEV: "",
    }.get(exc.errno or 0, "")
    return OutputError(f"{where}: cannot write: {reason}{hint}")


# --------------------------------------------------------------- path checks


# ------------------------------------------------------------ low-level steps


def _fsync_path(path: Path, directory: bool = False) -> None:
    fd = os.open(path, (os.O_RDONLY | os.O_DIRECTORY) if directory else os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as exc:  # some filesystems cannot fsync a directory
        if not directory or exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise
    finally:
        os.close(fd)


def fsync_tree(folder: Path) -> None:
    """fsync every file in ``folder`` (recursively) and the folders themselves."""
    for root, _dirs, files in os.walk(folder):
        for name in files:
            _fsync_path(Path(root) / name)
        _fsync_path(Path(root), directory=True)


_libc = None


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths on one filesystem (Linux renameat2). False when unsupported."""
    global _libc
    if not hasattr(os, "uname") or os.uname().sysname != "Linux":
        return False
    if _libc is None:
        _libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    fn = getattr(_libc, "renameat2", None)
    if fn is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    if fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EXDEV):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _owner_alive(name: str, prefix: str) -> bool:
    """Whether the process that named a staging folder ``prefix + PID-…`` still runs."""
    m = re.match(re.escape(prefix) + r"(\d+)-", name)
    if m is None:
        return False  # an older layout without a pid: a leftover
    pid = int(m.group(1))
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


_MANIFEST = ".gnomon-outputs"


def _read_names(path: Path) -> set[str]:
    try:
        return set(path.read_text(encoding="utf-8").split("\n")) - {""}
    except (FileNotFoundError, NotADirectoryError, UnicodeDecodeError):
        return set()


def _write_manifest(staging: Path) -> None:
    """The names a run publishes: ``OUT/.gnomon-outputs`` once published (the next run removes
    those it does not write again), and the list a commit folder is completed from."""
    names = sorted(n for n in os.listdir(staging) if not n.startswith("."))
    with open(staging / _MANIFEST, "w", encoding="utf-8") as fh:
        fh.write("".join(f"{n}\n" for n in names))
        fh.flush()
        os.fsync(fh.fileno())


def _roll_forward(out: Path, commit: Path, outputs: Iterable[str]) -> None:
    """Move a complete commit folder's files over ``out``'s and drop earlier outputs it does not have."""
    if not (commit / _MANIFEST).is_file():  # killed before the manifest: an incomplete stage, not a commit
        shutil.rmtree(commit, ignore_errors=True)
        return
    new = _read_names(commit / _MANIFEST)
    old = _read_names(out / _MANIFEST) | set(outputs)
    for name in sorted(new):
        if (commit / name).exists() or (commit / name).is_symlink():
            os.replace(commit / name, out / name)
    for name in sorted(old - new):
        if (out / name).is_file():
            (out / name).unlink()
    os.replace(commit / _MANIFEST, out / _MANIFEST)  # last: until here, recovery can redo all of it
    _fsync_path(out, directory=True)
    shutil.rmtree(commit, ignore_errors=True)


def recover(out: str | os.PathLike, outputs: Iterable[str] | None = None) -> None:
    """Finish or clean up after runs that were killed while writing into ``out``.

    A commit folder inside ``out`` (complete, fsynced) is rolled forward; staging
    folders of processes that no longer run are deleted, beside and inside ``out``.
    Best effort: a folder that cannot be removed is left for a later run.
    """
    out = Path(out)
    outputs = output_files() if outputs is None else tuple(outputs)
    if out.is_dir():
        try:
            entries = os.listdir(out)
        except OSError:
            entries = []
        for name in sorted(entries):
            path = out / name
            if name.startswith(_INSIDE_COMMIT) and not _owner_alive(name, _INSIDE_COMMIT):
                try:
                    _roll_forward(out, path, outputs)
                except OSError:
                    pass
            elif name.startswith(_INSIDE_PARTIAL) and not _owner_alive(name, _INSIDE_PARTIAL):
                shutil.rmtree(path, ignore_errors=True)
    prefix = f".{out.name}.partial-"
    try:
        siblings = os.listdir(out.parent)
    except OSError:
        siblings = []
    for name in siblings:
        if name.startswith(prefix) and not _owner_alive(name, prefix):
            shutil.rmtree(out.parent / name, ignore_errors=True)
    _remove_stale_files(out.parent)


def _remove_stale_files(folder: Path) -> None:
    """Delete recordings staged beside ``--rrd`` (``.NAME.partial-PID-….tmp``) by runs that were killed."""
    try:
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        m = re.match(r"^\.(.+)\.partial-(\d+)-[A-Za-z0-9_]+\.tmp$", name)
        if m and not _owner_alive(name, f".{m.group(1)}.partial-"):
            (folder / name).unlink(missing_ok=True)


def _only_outputs(out: Path, outputs: Iterable[str]) -> bool:
    allowed = set(outputs) | _read_names(out / _MANIFEST) | {_MANIFEST}
    for name in os.listdir(out):
        if name in allowed or name.startswith((_INSIDE_PARTIAL, _INSIDE_COMMIT)):
            continue
        return False
    return True


def _same_filesystem(a: Path, b: Path) -> bool:
    return a.stat().st_dev == b.stat().st_dev


def _mkstaging(parent: Path, prefix: str) -> Path:
    path = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-", dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o777 & ~umask)
    return path


def _stage_file_at(src: Path, target: Path) -> Path:
    """Move or copy ``src`` to a temporary file beside ``target`` (same filesystem as target), fsynced."""
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.partial-{os.getpid()}-", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        try:
            os.rename(src, tmp_path)
        except OSError as exc:
            if exc.errno != errno.EXDEV:
                raise
            with open(src, "rb") as fi, open(tmp_path, "wb") as fo:
                shutil.copyfileobj(fi, fo, 1 << 20)
                fo.flush()
                os.fsync(fo.fileno())
            src.unlink()
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        return tmp_path
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


# ------------------------------------------------------------------ the stage


class staged_outputs:
    """Context manager: a staging folder whose content becomes ``out`` on success only.

    ``rrd_path`` the recording's own destination (``--rrd``): ``scan.rrd`` from
    the staging folder goes there instead of into ``out``. ``outputs`` the
    file names this kind of run publishes; those of an earlier run that the new
    one did not write are removed. On an exception nothing is published and the
    staging folder is deleted; ``OSError`` leaves as :class:`OutputError`.
    """

    def __init__(self, out: str | os.PathLike, rrd_path: str | os.PathLike | None = None,
                 outputs: Iterable[str] | None = None):
        self.out_arg = out
        self.rrd_arg = rrd_path
        self.outputs = output_files() if outputs is None else tuple(outputs)
        self.staging: Path | None = None
        self._committed = False

    # -- entering: checks, recovery, the staging folder
    def __enter__(self) -> Path:
        self.out = check_output_folder(self.out_arg)
        self.rrd_path = None
        if self.rrd_arg is not None:
            rrd = check_output_file(self.rrd_arg, "--rrd")
            if rrd != self.out / "scan.rrd":
                self.rrd_path = rrd
        recover(self.out, self.outputs)
        if self.rrd_path is not None:
            _remove_stale_files(self.rrd_path.parent)
        try:
            if self.out.exists() and not (_same_filesystem(self.out, self.out.parent)
                                          and os.access(self.out.parent, os.W_OK | os.X_OK)):
                # OUT is a mount point (or its parent is not ours): stage inside it.
                self.inside = True
                where, prefix = self.out, _INSIDE_PARTIAL
            else:
                self.inside = False
                self.out.parent.mkdir(parents=True, exist_ok=True)
                where, prefix = self.out.parent, f".{self.out.name}.partial-"
            # A signal that comes while the folder is made, or before this returns (when the with
            # statement would not yet remove it on the way out), removes it here: with them held, the
            # folder exists only once it is known, and one delivered on their release is caught below.
            with interrupts.held():
                self.staging = _mkstaging(where, prefix)
            return self.staging
        except BaseException as exc:
            if self.staging is not None:
                shutil.rmtree(self.staging, ignore_errors=True)
                self.staging = None
            if isinstance(exc, OSError):
                raise output_error(exc, exc.filename or self.out) from None
            raise

    # -- leaving: publish or discard
    def __exit__(self, exc_type, exc, tb) -> None:
        assert self.staging is not None
        if exc_type is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            if isinstance(exc, OSError) and not isinstance(exc, (BlockingIOError, ChildProcessError)):
                raise output_error(exc, staging=self.staging, out=self.out) from None
            return
        staging = self.staging
        try:
            self._publish()
        except OSError as err:
            if not self._committed:  # a commit folder is complete: the next run finishes it
                shutil.rmtree(self.staging, ignore_errors=True)
            raise output_error(err, staging=staging, out=self.out) from None

    def _publish(self) -> None:
        staging = self.staging
        assert staging is not None
        rrd_tmp = None
        if self.rrd_path is not None and (staging / "scan.rrd").exists():
            try:
                rrd_tmp = _stage_file_at(staging / "scan.rrd", self.rrd_path)
            except OSError as exc:
                raise output_error(exc, self.rrd_path) from None
        try:
            _write_manifest(staging)
            fsync_tree(staging)
            with interrupts.held():
                self._swap_in(staging)
                if rrd_tmp is not None and self.rrd_path is not None:
                    os.replace(rrd_tmp, self.rrd_path)
                    rrd_tmp = None
                    _fsync_path(self.rrd_path.parent, directory=True)
        finally:
            if rrd_tmp is not None:
                rrd_tmp.unlink(missing_ok=True)

    def _swap_in(self, staging: Path) -> None:
        out = self.out
        if not self.inside and not out.exists():
            os.rename(staging, out)
            _fsync_path(out.parent, directory=True)
            return
        if not self.inside and _only_outputs(out, self.outputs) and _exchange(staging, out):
            # ``staging`` now holds the previous result.
            _fsync_path(out.parent, directory=True)
            shutil.rmtree(staging, ignore_errors=True)
            return
        commit = out / f"{_INSIDE_COMMIT}{os.getpid()}-{staging.name.rsplit('-', 1)[-1]}"
        os.rename(staging, commit)
        self._committed = True
        _fsync_path(out, directory=True)
        self.staging = commit
        _roll_forward(out, commit, self.outputs)
