"""Bad input and faults, tried as a user would: the table of how `gnomon` answers.

Run (from the repository root; a few minutes, small synthetic captures only):

    PYTHONPATH=python python tests/fault_matrix.py [--only SUBSTRING] [--json FILE]

Every case runs the real CLI in a subprocess (``python -m gnomon ...``) with a
time limit, then is classified:

- ``one line``: exit code 2 and exactly one stderr line ``gnomon: error: ...``
  (or, for signals, exit 128+n and one line) — the expected answer to bad input;
- ``ok``: a case that must succeed did, and its result checks out;
- ``traceback``: a Python traceback on stderr;
- ``hang``: the time limit was reached;
- ``silent``: bad input accepted (exit 0) — a silently wrong result;
- ``lost/mixed``: after the run, an output folder holds a mixture of two runs,
  a staging folder is left behind, or a file that must not change changed;
- ``other``: anything else (another exit code, several lines).

Faults that need privileges (a full tmpfs, a read-only mount, a second
filesystem) are skipped where mounting is not allowed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "python"))

from conftest import write_tiny_capture  # noqa: E402
from gnomon.util import toml_io  # noqa: E402

PY = sys.executable
TIME_LIMIT_S = 120.0


@dataclass
class Case:
    klass: str  # the class of bad input or fault (a row of the table)
    name: str
    argv: list[str]
    expect: str = "error"  # "error": one line + exit 2; "ok": exit 0; "signal": killed by a signal, clean
    check: Callable[[], str | None] | None = None  # after the run: None, or what is lost/mixed/wrong
    needle: str | None = None  # the error line must contain this (the file, key or frame)
    send: tuple[float, int] | None = None  # (seconds after start, signal)
    wait_for: Callable[[], bool] | None = None  # send the signal once this holds (polled)
    preexec: Callable[[], None] | None = None
    stdout_pipe_close: bool = False  # read one line of stdout, then close it (`| head -1`)
    env: dict = field(default_factory=dict)


@dataclass
class Outcome:
    case: Case
    verdict: str
    detail: str
    seconds: float


# ----------------------------------------------------------------------------- fixtures


def edit_toml(path: Path, edit: Callable[[dict], None], dest: Path | None = None) -> Path:
    data = tomllib.loads(path.read_text())
    edit(data)
    dest = dest or path
    toml_io.dump(data, dest)
    return dest


def copy_capture(src: Path, dest: Path) -> Path:
    shutil.copytree(src, dest)
    return dest / "field_log.toml"


def digest_tree(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir()
                  if ".partial-" in p.name or p.name.startswith((".gnomon-partial-", ".gnomon-commit-")))


def unchanged(folder: Path, before: dict[str, str]) -> Callable[[], str | None]:
    def check() -> str | None:
        now = digest_tree(folder) if folder.exists() else {}
        if now != before:
            changed = sorted(set(now.items()) ^ set(before.items()))
            return f"{folder} changed: {changed[:3]}"
        return None
    return check


def absent(out: Path) -> Callable[[], str | None]:
    def check() -> str | None:
        if out.exists() and any(out.iterdir()):
            return f"{out} holds {sorted(p.name for p in out.iterdir())[:5]}"
        left = leftovers(out.parent) if out.parent.exists() else []
        return f"staging left in {out.parent}: {left}" if left else None
    return check


def can_mount() -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    d = Path(tempfile.mkdtemp(prefix="gnomon-mnt-probe-"))
    ok = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(d)], capture_output=True).returncode == 0
    if ok:
        subprocess.run(["umount", str(d)], capture_output=True)
    d.rmdir()
    return ok


class Mounts:
    def __init__(self) -> None:
        self.points: list[Path] = []

    def tmpfs(self, where: Path, size: str, ro: bool = False) -> Path:
        where.mkdir(parents=True, exist_ok=True)
        opts = f"size={size}" + (",ro" if ro else "")
        subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)], check=True)
        self.points.append(where)
        return where

    def release(self) -> None:
        for p in reversed(self.points):
            subprocess.run(["umount", "-l", str(p)], capture_output=True)


def gnomon(*args: str) -> list[str]:
    return [PY, "-m", "gnomon", *args]


def prepare(root: Path) -> dict:
    """Small captures and scans every case starts from."""
    fx: dict = {}
    fx["cap"] = write_tiny_capture(root / "cap")
    fx["scan_a"] = root / "scan_a"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "python")}
    subprocess.run(gnomon("scan", str(fx["cap"]), "--out", str(fx["scan_a"]), "--quiet", "--no-rrd"),
                   check=True, env=env, capture_output=True)
    fx["scan_b"] = root / "scan_b"
    shutil.copytree(fx["scan_a"], fx["scan_b"])
    # a larger capture, for signals mid-scan and a full disk
    subprocess.run(gnomon("simulate", "desk_lamp", "--out", str(root / "desk"), "--width", "400", "--height", "300",
                          "--frames", "120", "--quiet"), check=True, env=env, capture_output=True)
    fx["desk"] = root / "desk" / "field_log.toml"
    # the desk scan's outputs, to size a filesystem on which all but the recording fit
    subprocess.run(gnomon("scan", str(fx["desk"]), "--out", str(root / "desk_scan"), "--quiet"), check=True, env=env,
                   capture_output=True)
    sizes = {p.name: p.stat().st_size for p in (root / "desk_scan").iterdir()}
    fx["all_but_rrd_mb"] = (sum(sizes.values()) - sizes["scan.rrd"] // 2) / 2**20 + 1
    subprocess.run(gnomon("simulate", "facade_sun", "--out", str(root / "sun"), "--width", "160", "--height", "120",
                          "--frames", "40", "--quiet"), check=True, env=env, capture_output=True)
    fx["sun"] = root / "sun" / "field_log.toml"
    subprocess.run(gnomon("simulate", "chessboard", "--out", str(root / "chess"), "--width", "640", "--height",
                          "480"), check=True, env=env, capture_output=True)
    fx["chess"] = root / "chess"
    # a two-plane capture whose markers place the desk and the wall
    subprocess.run(gnomon("simulate", "two_plane", "--out", str(root / "two"), "--width", "400", "--height", "300",
                          "--frames", "120", "--seed", "4", "--quiet"), check=True, env=env, capture_output=True)
    fx["two"] = root / "two" / "field_log.toml"
    # a capture cropped to a few points: the recording is its biggest output (sizes a limit only it outgrows)
    fx["cropped"] = write_tiny_capture(root / "cropped", n_frames=60, width=160, height=120,
                                       extra={"output": {"crop_box": [[-10, -10, -5], [10, 10, 5]]}})
    subprocess.run(gnomon("scan", str(fx["cropped"]), "--out", str(root / "cropped_scan"), "--quiet",
                          "--frame-stride", "1"), check=True, env=env, capture_output=True)
    sizes = {p.name: p.stat().st_size for p in (root / "cropped_scan").iterdir() if p.is_file()}
    fx["cropped_limit"] = (sizes["scan.rrd"] + max(v for n, v in sizes.items() if n != "scan.rrd")) // 2
    return fx


# ----------------------------------------------------------------------------- cases


def cases(root: Path, fx: dict, mounts: Mounts | None) -> list[Case]:  # noqa: C901 - a long list, on purpose
    out: list[Case] = []
    k = 0

    def fresh(name: str) -> Path:
        nonlocal k
        k += 1
        d = root / f"case{k:03d}-{re.sub(r'[^A-Za-z0-9]+', '-', name)}"
        d.mkdir()
        return d

    def scan_case(klass: str, name: str, edit: Callable[[dict], None] | None = None, *, needle: str | None = None,
                  prepare_files: Callable[[Path], None] | None = None, expect: str = "error",
                  source: Path | None = None, extra: tuple[str, ...] = ()) -> None:
        d = fresh(name)
        log = copy_capture((source or fx["cap"]).parent, d / "cap")
        if prepare_files is not None:
            prepare_files(log.parent)
        if edit is not None:
            edit_toml(log, edit)
        o = d / "out"
        out.append(Case(klass, name, gnomon("scan", str(log), "--out", str(o), "--quiet", *extra), expect=expect,
                        check=absent(o) if expect == "error" else None, needle=needle))

    # --- frames
    def zero_byte(c: Path) -> None:
        (c / "frames" / "frame_0005.png").write_bytes(b"")
    scan_case("frames", "zero-byte frame", prepare_files=zero_byte, needle="frame_0005")

    def huge_header(c: Path) -> None:
        import struct
        import zlib
        ihdr = struct.pack(">IIBBBBB", 60000, 60000, 8, 0, 0, 0, 0)
        chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))  # noqa: E731
        data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 100)) + \
            chunk(b"IEND", b"")
        (c / "frames" / "frame_0003.png").write_bytes(data)
    scan_case("frames", "PNG header claiming 60000x60000", prepare_files=huge_header, needle="frame_0003")

    def huge_first(c: Path) -> None:
        huge_header(c)
        os.replace(c / "frames" / "frame_0003.png", c / "frames" / "frame_0000.png")
    scan_case("frames", "first frame claims 60000x60000", prepare_files=huge_first, needle="frame_0000")

    def truncated(c: Path) -> None:
        p = c / "frames" / "frame_0007.png"
        p.write_bytes(p.read_bytes()[:60])
    scan_case("frames", "truncated PNG", prepare_files=truncated, needle="frame_0007")

    # a JPEG with 200 bytes zeroed in the middle (a failing card or copy): libjpeg only warns and decodes garbage
    desk_jpeg = ROOT / "field_logs" / "desk_lamp_small" / "field_log.toml"

    def corrupt_middle(c: Path) -> None:
        p = c / "frames" / "frame_0041.jpg"
        b = bytearray(p.read_bytes())
        b[len(b) // 2:len(b) // 2 + 200] = bytes(200)
        p.write_bytes(bytes(b))
    scan_case("frames", "JPEG with 200 bytes zeroed in the middle", prepare_files=corrupt_middle, needle="frame_0041",
              source=desk_jpeg)
    d = fresh("corrupt JPEG dropped on request")
    log = copy_capture(desk_jpeg.parent, d / "cap")
    corrupt_middle(log.parent)
    edit_toml(log, lambda dd: dd["capture"].update(on_corrupt_frame="drop"))
    o_drop = d / "out"

    def dropped_named(o=o_drop) -> str | None:
        w = json.loads((o / "report.json").read_text())["warnings"]
        return None if any("frame 41 (frame_0041.jpg)" in x for x in w) else "no warning naming frame 41"
    out.append(Case("frames", "corrupt JPEG dropped on request (warning)",
                    gnomon("scan", str(log), "--out", str(o_drop), "--quiet", "--no-rrd"), expect="ok",
                    check=dropped_named))

    def natural(c: Path) -> None:
        for p in sorted((c / "frames").glob("*.png")):
            i = int(p.stem.split("_")[1])
            p.rename(p.with_name(f"frame_{i}.png"))
    d_nat = fresh("natural")
    log_nat = copy_capture(fx["cap"].parent, d_nat / "cap")
    natural(log_nat.parent)
    o_nat = d_nat / "out"

    def natural_check() -> str | None:
        depth = np.load(o_nat / "depth.npy")
        ref = np.load(fx["scan_a"] / "depth.npy")
        same = np.isfinite(depth) == np.isfinite(ref)
        if not same.all() or not np.allclose(depth[np.isfinite(depth)], ref[np.isfinite(ref)], rtol=1e-6):
            return "frame_0 … frame_23 scanned in another order than frame_0000 … frame_0023"
        return None
    out.append(Case("frames", "frames frame_0 … frame_23 (natural order)",
                    gnomon("scan", str(log_nat), "--out", str(o_nat), "--quiet", "--no-rrd"), expect="ok",
                    check=natural_check))

    # --- field log as a file
    d = fresh("binary-log")
    (d / "field_log.toml").write_bytes(bytes(range(256)) * 4)
    out.append(Case("paths", "field log is binary", gnomon("scan", str(d / "field_log.toml"), "--out", str(d / "o")),
                    needle="field_log.toml", check=absent(d / "o")))
    d = fresh("latin1-log")
    (d / "field_log.toml").write_bytes(fx["cap"].read_text().replace("[scan]", "# caf\xe9\n[scan]").encode("latin-1"))
    out.append(Case("paths", "field log not UTF-8", gnomon("scan", str(d / "field_log.toml"), "--out", str(d / "o")),
                    needle="field_log.toml", check=absent(d / "o")))
    d = fresh("dir-log")
    (d / "field_log.toml").mkdir()
    out.append(Case("paths", "field log is a folder", gnomon("scan", str(d / "field_log.toml"), "--out", str(d / "o")),
                    needle="field_log.toml", check=absent(d / "o")))

    def camera_file(content: bytes | None, name: str, is_dir: bool = False) -> None:
        def prep(c: Path) -> None:
            if is_dir:
                (c / "cam.toml").mkdir()
            else:
                (c / "cam.toml").write_bytes(content or b"")

        def edit(data: dict) -> None:
            data["camera"] = {"file": "cam.toml", "pose": data["camera"]["pose"]}
        scan_case("paths", name, edit, prepare_files=prep, needle="cam.toml")
    camera_file(b"\xff\xfe\x00binary\x00\x01", "camera file binary")
    camera_file("fx = 60.0 # caf\xe9\n".encode("latin-1"), "camera file not UTF-8")
    camera_file(None, "camera file is a folder", is_dir=True)

    def light_file(content: bytes | None, name: str, is_dir: bool = False) -> None:
        def prep(c: Path) -> None:
            if is_dir:
                (c / "lamp.toml").mkdir()
            else:
                (c / "lamp.toml").write_bytes(content or b"")
        scan_case("paths", name, lambda dd: dd["light"].update(file="lamp.toml") or dd["light"].pop("position"),
                  prepare_files=prep, needle="lamp.toml")
    light_file(None, "[light] file is a folder", is_dir=True)
    light_file(b"\x00\x01\x02\xff", "[light] file binary")
    scan_case("paths", "absolute frames glob", lambda dd: dd["capture"].update(frames="/nonexistent-gnomon/*.png"),
              needle="frames")
    scan_case("paths", "empty frames glob", lambda dd: dd["capture"].update(frames=""), needle="frames")
    scan_case("paths", "frames glob '/'", lambda dd: dd["capture"].update(frames="/"), needle="frames")

    # --- numbers in the field log
    num = "numbers"
    scan_case(num, "window = 65", lambda dd: dd["scan"].update(window=65), needle="window")
    scan_case(num, "window = 100000", lambda dd: dd["scan"].update(window=100000), needle="window")
    scan_case(num, "gamma = inf", lambda dd: dd["capture"].update(gamma=float("inf")), needle="gamma")
    scan_case(num, "gamma = nan", lambda dd: dd["capture"].update(gamma=float("nan")), needle="gamma")
    scan_case(num, "gamma = 1e300", lambda dd: dd["capture"].update(gamma=1e300), needle="gamma")
    scan_case(num, "fx = 1e300", lambda dd: dd["camera"].update(fx=1e300), needle="fx")
    scan_case(num, "fx = -60", lambda dd: dd["camera"].update(fx=-60.0), needle="fx")
    scan_case(num, "fy = 0", lambda dd: dd["camera"].update(fy=0.0), needle="fy")
    scan_case(num, "cx = nan", lambda dd: dd["camera"].update(cx=float("nan")), needle="cx")
    scan_case(num, "dist = [1e10, ...]", lambda dd: dd["camera"].update(dist=[1e10, 0.0, 0.0, 0.0, 0.0]),
              needle="dist")
    scan_case(num, "dist k1 = -5 (folds over the image)",
              lambda dd: dd["camera"].update(dist=[-5.0, 0.0, 0.0, 0.0, 0.0]), needle="dist")
    scan_case(num, "width = 0", lambda dd: dd["camera"].update(width=0), needle="width")
    scan_case(num, "min_contrast = inf", lambda dd: dd["scan"].update(min_contrast=float("inf")),
              needle="min_contrast")
    scan_case(num, "max_depth_jump = -1", lambda dd: dd["scan"].update(max_depth_jump=-1.0), needle="max_depth_jump")
    scan_case(num, "pose tvec = [inf, 0, 0]",
              lambda dd: dd["camera"]["pose"].update(tvec=[float("inf"), 0.0, 500.0]), needle="tvec")
    scan_case(num, "lamp position 1e300",
              lambda dd: dd["light"].update(position=[1e300, 0.0, 400.0]), needle="position")
    scan_case(num, "chessboard = '0x0'",
              lambda dd: dd["planes"][0].update(chessboard="0x0", square=25.0), needle="chessboard")
    scan_case(num, "chessboard = '-3x4'",
              lambda dd: dd["planes"][0].update(chessboard="-3x4", square=25.0), needle="chessboard")
    scan_case(num, "frame_count = 10**30", lambda dd: dd["capture"].update(frame_count=10**18), needle="frame_count")
    scan_case(num, "normal = [1e-300, 0, 0]",
              lambda dd: dd["planes"][0].update(normal=[1e-300, 0.0, 0.0]), needle="normal")

    # --- geometry
    geo = "geometry"
    scan_case(geo, "lamp at the camera centre", lambda dd: dd["light"].update(position=[0.0, 0.0, 500.0]),
              needle="position")
    scan_case(geo, "two planes with one name",
              lambda dd: dd["planes"].append({**dd["planes"][0]}), needle="desk")
    scan_case(geo, "camera in the plane", lambda dd: dd["camera"]["pose"].update(tvec=[0.0, 0.0, 0.0]),
              needle="camera")

    def swap_hints(dd: dict) -> None:
        m = dd["planes"][0]["markers"]
        m[0]["pixel_hint"], m[1]["pixel_hint"] = m[1]["pixel_hint"], m[0]["pixel_hint"]
    scan_case(geo, "two markers with each other's pixel_hint (26 px, 42° off)", swap_hints, needle="desk: marker",
              source=fx["two"])
    d_click = fresh("marker-clicked-off")
    log_click = copy_capture(fx["two"].parent, d_click / "cap")

    def click_off(dd: dict) -> None:  # a clicked pixel 12 px right of where marker 2 is found
        from gnomon.config.fieldlog import load_field_log
        from gnomon.config.setup import frame_source, resolve_reference_planes
        fl = load_field_log(fx["two"])
        found = resolve_reference_planes(fl, frame_source(fl))[1][0]["pixels"][2]
        m = dd["planes"][0]["markers"][2]
        m.pop("pixel_hint")
        m["pixel"] = [found[0] + 12.0, found[1]]
    edit_toml(log_click, click_off)
    o_click = d_click / "out"

    def warned(o=o_click) -> str | None:
        w = json.loads((o / "report.json").read_text())["warnings"]
        return None if any("do not fit one plane" in x for x in w) else "no marker warning in report.json"
    out.append(Case(geo, "a marker clicked 12 px off (warning)", gnomon("scan", str(log_click), "--out", str(o_click),
                                                                      "--quiet", "--no-rrd"),
                    expect="ok", check=warned))

    def sun_case(name: str, edit: Callable[[dict], None], needle: str) -> None:
        scan_case(geo, name, edit, needle=needle, source=fx["sun"])
    sun_case("horizontal [pole]", lambda dd: dd["pole"].update(top=[dd["pole"]["base"][0] + 3.0,
                                                                   dd["pole"]["base"][1], dd["pole"]["base"][2]]),
             "pole")
    sun_case("[capture] register = 'maybe'", lambda dd: dd["capture"].update(register="maybe"), "register")

    def knocked(c: Path) -> None:  # the camera knocked by 24 px from frame 20 on: more than a scan follows
        import cv2
        for f in sorted((c / "frames").glob("*.jpg"))[20:]:
            img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
            cv2.imwrite(str(f), cv2.warpAffine(img, np.float32([[1, 0, 24], [0, 1, 0]]), img.shape[::-1],
                                               borderMode=cv2.BORDER_REPLICATE))
    scan_case(geo, "sun capture whose camera was knocked 24 px", prepare_files=knocked, needle="camera",
              source=fx["sun"])

    def fps_edit(dd: dict) -> None:
        dd["capture"].update(timestamps="start+fps", start="2026-11-12T11:40:00", fps=1e300)
        dd["capture"].pop("time_pattern", None)
    sun_case("fps = 1e300", fps_edit, "fps")

    def fps_zero_edit(dd: dict) -> None:
        dd["capture"].update(timestamps="start+fps", start="2026-11-12T11:40:00", fps=1e-300)
        dd["capture"].pop("time_pattern", None)
    sun_case("fps = 1e-300", fps_zero_edit, "fps")
    sun_case("latitude = nan", lambda dd: dd["site"].update(latitude=float("nan")), "latitude")
    sun_case("altitude = 1e6", lambda dd: dd["site"].update(altitude=1e6), "[site] altitude")
    sun_case("pressure_pa = 950 (mbar)", lambda dd: dd["site"].update(pressure_pa=950.0), "[site] pressure_pa")
    sun_case("temperature_c = 99", lambda dd: dd["site"].update(temperature_c=99.0), "[site] temperature_c")
    scan_case(geo, "timezone 'Mars/Olympus' in a lamp scan",
              lambda dd: dd.update(site={"latitude": 47.0, "longitude": 8.0, "timezone": "Mars/Olympus"}),
              needle="timezone")

    # --- output paths
    pth = "output paths"
    d = fresh("out-file")
    (d / "f").write_text("keep me")
    out.append(Case(pth, "scan --out is a file", gnomon("scan", str(fx["cap"]), "--out", str(d / "f"), "--quiet"),
                    needle=str(d / "f"), check=unchanged(d, digest_tree(d))))
    d = fresh("out-under-file")
    (d / "f").write_text("keep me")
    out.append(Case(pth, "scan --out under a file",
                    gnomon("scan", str(fx["cap"]), "--out", str(d / "f" / "sub"), "--quiet"),
                    needle="f", check=unchanged(d, digest_tree(d))))
    d = fresh("rrd-dir")
    (d / "recs").mkdir()
    out.append(Case(pth, "scan --rrd is a folder",
                    gnomon("scan", str(fx["cap"]), "--out", str(d / "o"), "--rrd", str(d / "recs"), "--quiet"),
                    needle="--rrd", check=absent(d / "o")))
    d = fresh("demo-file")
    (d / "f").write_text("keep me")
    out.append(Case(pth, "demo --out is a file", gnomon("demo", "--out", str(d / "f"), "--small", "--quiet"),
                    needle=str(d / "f"), check=unchanged(d, digest_tree(d))))
    d = fresh("sim-file")
    (d / "f").write_text("keep me")
    out.append(Case(pth, "simulate --out is a file", gnomon("simulate", "two_plane", "--out", str(d / "f"), "--quiet"),
                    needle=str(d / "f"), check=unchanged(d, digest_tree(d))))
    d = fresh("review-export-dir")
    out.append(Case(pth, "review --export DIR", gnomon("review", str(root / "rec.rrd"), "--export", str(d)),
                    needle=str(d)))
    d = fresh("bench-json-dir")
    out.append(Case(pth, "bench --json DIR", gnomon("bench", "--frames", "4", "--numpy-frames", "2", "--width", "32",
                                                    "--height", "16", "--no-memory", "--json", str(d)),
                    needle=str(d)))
    d = fresh("calib-out-dir")
    out.append(Case(pth, "calibrate camera --out DIR",
                    gnomon("calibrate", "camera", str(fx["chess"]), "--board", "9x6", "--square", "25", "--out",
                           str(d), "--no-rrd"), needle=str(d)))

    # --- merge
    mg = "merge"
    out.append(Case(mg, "merge A B --out A", gnomon("merge", str(fx["scan_a"]), str(fx["scan_b"]), "--out",
                                                    str(fx["scan_a"]), "--no-rrd"),
                    needle=str(fx["scan_a"]), check=unchanged(fx["scan_a"], digest_tree(fx["scan_a"]))))
    for beta in ("nan", "inf", "-5", "0"):
        d = fresh(f"merge-beta{beta}")
        out.append(Case(mg, f"merge --beta {beta}", gnomon("merge", str(fx["scan_a"]), str(fx["scan_b"]), "--out",
                                                          str(d / "o"), "--weights", "sigmoid", f"--beta={beta}",
                                                          "--no-rrd"), needle="--beta", check=absent(d / "o")))

    def second_scan_bad(command: str, name: str, spoil: Callable[[Path], None], needle: str) -> None:
        """`gnomon COMMAND A B --out O` with B a spoiled copy of scan_b: one line naming it, O absent."""
        d = fresh(f"{command}-" + name.replace(" ", "-"))
        b = d / "b"
        shutil.copytree(fx["scan_b"], b)
        spoil(b)
        out.append(Case(command, f"{command}: {name}", gnomon(command, str(fx["scan_a"]), str(b), "--out",
                                                              str(d / "o"), "--no-rrd"),
                        needle=needle, check=absent(d / "o")))

    def merge_bad(name: str, spoil: Callable[[Path], None], needle: str) -> None:
        second_scan_bad(mg, name, spoil, needle)
    merge_bad("truncated depth.npy", lambda b: (b / "depth.npy").write_bytes((b / "depth.npy").read_bytes()[:100]),
              "depth.npy")
    merge_bad("empty depth.npy", lambda b: (b / "depth.npy").write_bytes(b""), "depth.npy")
    merge_bad("text depth.npy", lambda b: (b / "depth.npy").write_text("hello"), "depth.npy")
    merge_bad("object depth.npy", lambda b: np.save(b / "depth.npy", np.array([{"a": 1}], dtype=object),
                                                    allow_pickle=True), "depth.npy")
    merge_bad("int depth.npy of the right shape",
              lambda b: np.save(b / "depth.npy", np.zeros(np.load(b / "depth.npy").shape, np.int64)), "depth.npy")
    merge_bad("report.json not JSON", lambda b: (b / "report.json").write_text("{"), "report.json")
    merge_bad("report.json binary", lambda b: (b / "report.json").write_bytes(b"\xff\xfe\x00"), "report.json")

    def bad_uv(b: Path) -> None:
        from gnomon.outputs import ply
        pts = ply.read_ply(b / "points.ply")
        n = len(pts["xyz"]) if "xyz" in pts else len(next(iter(pts.values())))
        uv = np.full((n, 2), 1e6, np.float32)
        ply.write_points_ply(b / "points.ply", np.zeros((n, 3), np.float32), np.zeros((n, 3), np.uint8),
                             np.ones(n, np.float32), uv)
    merge_bad("points.ply u out of range", bad_uv, "points.ply")
    merge_bad("points.ply truncated", lambda b: (b / "points.ply").write_bytes((b / "points.ply").read_bytes()[:300]),
              "points.ply")
    merge_bad("a file, not a folder", lambda b: (shutil.rmtree(b), b.write_text("x")), str(root))

    # --- fuse (several scans into one model): the bad scan is named, nothing is written
    fu = "fuse"
    out.append(Case(fu, "fuse A B --out A", gnomon("fuse", str(fx["scan_a"]), str(fx["scan_b"]), "--out",
                                                  str(fx["scan_a"]), "--no-rrd"),
                    needle=str(fx["scan_a"]), check=unchanged(fx["scan_a"], digest_tree(fx["scan_a"]))))

    def fuse_bad(name: str, spoil: Callable[[Path], None], needle: str) -> None:
        second_scan_bad(fu, name, spoil, needle)

    def other_units(b: Path) -> None:
        report = json.loads((b / "report.json").read_text())
        report["units"] = "m"
        (b / "report.json").write_text(json.dumps(report))
    fuse_bad("units that differ", other_units, "units")
    fuse_bad("report.json not JSON", lambda b: (b / "report.json").write_text("{"), "report.json")
    fuse_bad("points.ply truncated", lambda b: (b / "points.ply").write_bytes((b / "points.ply").read_bytes()[:300]),
             "points.ply")
    fuse_bad("no points.ply", lambda b: (b / "points.ply").unlink(), "points.ply")
    fuse_bad("a file, not a folder", lambda b: (shutil.rmtree(b), b.write_text("x")), str(root))

    # --- calibrate camera
    cal = "calibrate"
    chess = str(fx["chess"])

    def calib(name: str, *args: str, needle: str) -> None:
        d = fresh("cal-" + name.replace(" ", "-"))
        (d / "camera.toml").write_text("# a good camera file, kept\n")
        out.append(Case(cal, name, gnomon("calibrate", "camera", chess, "--square", "25", "--out",
                                          str(d / "camera.toml"), "--no-rrd", *args), needle=needle,
                        check=unchanged(d, digest_tree(d))))
    calib("--board 2x2", "--board", "2x2", needle="--board")
    calib("--board 1x6", "--board", "1x6", needle="--board")
    calib("--board 0x0", "--board", "0x0", needle="--board")
    calib("--reject nan", "--board", "9x6", "--reject", "nan", needle="--reject")
    calib("--reject -1", "--board", "9x6", "--reject", "-1", needle="--reject")
    calib("tsai --pixel-pitch inf", "--board", "9x6", "--model", "tsai", "--pixel-pitch", "inf",
          needle="--pixel-pitch")
    calib("tsai --pixel-pitch nan", "--board", "9x6", "--model", "tsai", "--pixel-pitch", "nan",
          needle="--pixel-pitch")
    calib("tsai --sx 0", "--board", "9x6", "--model", "tsai", "--pixel-pitch", "0.005", "--sx", "0", needle="--sx")
    calib("tsai --sx nan", "--board", "9x6", "--model", "tsai", "--pixel-pitch", "0.005", "--sx", "nan",
          needle="--sx")
    d = fresh("cal-square")
    out.append(Case(cal, "--square inf", gnomon("calibrate", "camera", chess, "--board", "9x6", "--square", "inf",
                                               "--out", str(d / "c.toml"), "--no-rrd"), needle="--square",
                    check=absent(d / "c.toml")))

    # calibrate camera from a video of the board: broken, boardless and one-pose videos
    import cv2

    d = fresh("cal-video")
    (d / "camera.toml").write_text("# a good camera file, kept\n")
    writer = cv2.VideoWriter(str(d / "blank.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (64, 48))
    for _ in range(12):
        writer.write(np.full((48, 64, 3), 120, np.uint8))
    writer.release()
    board = cv2.imread(str(sorted(Path(chess).glob("*.png"))[0]))
    writer = cv2.VideoWriter(str(d / "still.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30.0,
                             (board.shape[1], board.shape[0]))
    for _ in range(12):
        writer.write(board)
    writer.release()
    good = (d / "still.avi").read_bytes()
    (d / "truncated.avi").write_bytes(good[: len(good) // 3])
    (d / "text.mp4").write_text("not a video\n")
    # (the truncated AVI has lost its index: its 4 readable frames are counted and used, one view)
    for video, needle in (("blank.avi", "chessboard"), ("still.avi", "1 distinct view"),
                          ("truncated.avi", "truncated.avi"), ("text.mp4", "text.mp4")):
        out.append(Case(cal, f"board video: {video}",
                        gnomon("calibrate", "camera", str(d / video), "--board", "9x6", "--square", "25",
                               "--out", str(d / "camera.toml"), "--no-rrd", "--quiet"),
                        needle=needle, check=unchanged(d, digest_tree(d))))
    out.append(Case(cal, "--video-views 1", gnomon("calibrate", "camera", str(d / "still.avi"), "--board", "9x6",
                                                   "--square", "25", "--out", str(d / "camera.toml"), "--no-rrd",
                                                   "--video-views", "1"),
                    needle="--video-views", check=unchanged(d, digest_tree(d))))

    # init: the lamp's and the sun's options
    ini = "init"
    frames_glob = str(fx["cap"].parent / "frames" / "*.png")
    d = fresh("init-options")
    for name, args, needle in (
        ("--pencil without --light lamp", ["--pencil", frames_glob], "--pencil"),
        ("--board 9by6", ["--light", "lamp", "--board", "9by6"], "--board"),
        ("--square -1", ["--light", "lamp", "--square", "-1"], "--square"),
        ("--square nan", ["--light", "lamp", "--square", "nan"], "--square"),
        ("--pencil missing.jpg", ["--light", "lamp", "--pencil", str(d / "missing.jpg")], "missing.jpg"),
        ("--pencil no match", ["--light", "lamp", "--pencil", str(d / "none*.jpg")], "none*.jpg"),
        ("--board-image missing", ["--light", "lamp", "--board-image", str(d / "board.jpg")], "board.jpg"),
    ):
        out.append(Case(ini, name, gnomon("init", frames_glob, "--out", str(d / "log.toml"), *args),
                        needle=needle, check=absent(d / "log.toml")))

    # calibrate lamp: collinear pencils (degenerate) must not overwrite a good lamp.toml
    d = fresh("lamp-degenerate")
    shutil.copytree(fx["desk"].parent, d / "desk")
    pencil = d / "desk" / "pencil_log.toml"
    (d / "desk" / "lamp.toml").write_text("# a good lamp file, kept\n[light]\nposition = [1.0, 2.0, 3.0]\n")

    def collinear(dd: dict) -> None:
        photos = dd["pencil"]["photos"]
        b0, t0 = np.array(photos[0]["base"]), np.array(photos[0]["tip"])
        for k, p in enumerate(photos[1:], 1):  # every shadow on one line: the lamp is anywhere along it
            p["base"] = (b0 - 0.4 * k * (t0 - b0)).tolist()
            p["tip"] = (t0 - 0.3 * k * (t0 - b0)).tolist()
    if pencil.is_file():
        edit_toml(pencil, collinear)
        out.append(Case(cal, "calibrate lamp, degenerate pencils", gnomon("calibrate", "lamp", str(pencil)),
                        needle="lamp", check=lambda lamp=d / "desk" / "lamp.toml": (
                            None if lamp.read_text().startswith("# a good") else
                            "lamp.toml overwritten by a degenerate estimate")))

    # --- other commands' numbers
    oth = "other commands"
    d = fresh("sim-seed")
    out.append(Case(oth, "simulate --seed -1", gnomon("simulate", "two_plane", "--out", str(d / "o"), "--seed", "-1",
                                                      "--quiet"), needle="--seed", check=absent(d / "o")))
    for arg, val in (("--noise", "nan"), ("--width", "0"), ("--frames", "1"), ("--gamma", "inf"),
                     ("--blur", "-1"), ("--jpeg-quality", "101")):
        needle = arg
        d = fresh("sim" + arg)
        out.append(Case(oth, f"simulate {arg} {val}", gnomon("simulate", "desk_lamp", "--out", str(d / "o"),
                                                             f"{arg}={val}", "--quiet"), needle=needle,
                        check=absent(d / "o")))
    for args, needle in ((("--lat", "nan", "--lon", "8", "--time", "2026-06-01T12:00Z"), "--lat"),
                         (("--lat", "47", "--lon", "inf", "--time", "2026-06-01T12:00Z"), "--lon"),
                         (("--lat", "95", "--lon", "8", "--time", "2026-06-01T12:00Z"), "--lat"),
                         (("--lat", "47", "--lon", "8", "--time", "2026-06-01T12:00Z", "--alt", "1e6"), "--alt"),
                         (("--lat", "47", "--lon", "8", "--time", "2026-06-01T12:00Z", "--tz", "Mars/Olympus"),
                          "--tz"),
                         (("--lat", "47", "--lon", "8", "--time", "2026-06-01T12:00Z", "--heading", "nan"),
                          "--heading"),
                         (("--lat", "47", "--lon", "8", "--time", "2026-06-01T12:00Z", "--pressure", "-5"),
                          "--pressure"),
                         (("--lat", "47", "--lon", "8", "--time", "not a time"), "time")):
        out.append(Case(oth, "sun " + " ".join(args[:6]), gnomon("sun", *args), needle=needle))
    out.append(Case(oth, "gnomon sun ... | head -1",
                    gnomon("sun", "--lat", "47", "--lon", "8", "--time", "2026-06-01T12:00Z", "--time",
                           "2026-06-01T13:00Z"), expect="pipe", stdout_pipe_close=True))
    for args in (("--frames", "0"), ("--width", "-5"), ("--window", "1000")):
        out.append(Case(oth, "bench " + " ".join(args), gnomon("bench", "--no-memory", *args), needle=args[0]))
    d = fresh("review-missing")
    out.append(Case(oth, "review a missing recording", gnomon("review", str(d / "nope.rrd")), needle="nope.rrd"))
    (d / "text.rrd").write_text("not a recording")
    out.append(Case(oth, "review a text file", gnomon("review", str(d / "text.rrd")), needle="text.rrd"))
    out.append(Case(oth, "review a folder", gnomon("review", str(d)), needle=str(d)))

    # --- signals
    sig = "signals"
    for s in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        d = fresh(f"sig{s.name}")
        o = d / "out"
        staging_glob = d

        def started(dd=staging_glob) -> bool:
            return any(".partial-" in p.name for p in dd.iterdir())
        out.append(Case(sig, f"{s.name} mid-scan", gnomon("scan", str(fx["desk"]), "--out", str(o), "--quiet"),
                        expect="signal", send=(30.0, s), wait_for=started, check=absent(o)))
    d = fresh("sigint-startup")
    out.append(Case(sig, "SIGINT during start-up", gnomon("scan", str(fx["cap"]), "--out", str(d / "o")),
                    expect="signal", send=(0.15, signal.SIGINT), check=absent(d / "o")))

    # --- faults
    flt = "faults"
    d = fresh("ulimit")
    o = d / "out"

    def fsize_limit() -> None:
        import resource
        resource.setrlimit(resource.RLIMIT_FSIZE, (4 << 20, 4 << 20))
    out.append(Case(flt, "file-size limit (ulimit -f 4 MiB)", gnomon("scan", str(fx["desk"]), "--out", str(o),
                                                                     "--quiet"),
                    needle=str(o), preexec=fsize_limit, check=absent(o)))
    d = fresh("view-ulimit")
    o = d / "out"

    def rrd_limit() -> None:
        import resource
        resource.setrlimit(resource.RLIMIT_FSIZE, (fx["cropped_limit"], fx["cropped_limit"]))
    out.append(Case(flt, "--view without a display, a file-size limit only scan.rrd outgrows",
                    gnomon("scan", str(fx["cropped"]), "--out", str(o), "--quiet", "--frame-stride", "1", "--view"),
                    needle="scan.rrd", preexec=rrd_limit, check=absent(o)))
    d = fresh("rescan-no-rrd")
    o = d / "out"
    subprocess.run(gnomon("scan", str(fx["cap"]), "--out", str(o), "--quiet"), check=True, capture_output=True)

    def no_stale_rrd(o=o) -> str | None:
        return f"{o}/scan.rrd of the previous scan is still there" if (o / "scan.rrd").exists() else None
    out.append(Case(flt, "rescan with --no-rrd", gnomon("scan", str(fx["cap"]), "--out", str(o), "--quiet",
                                                        "--no-rrd"), expect="ok", check=no_stale_rrd))
    # a kill (SIGKILL) during publication: the next run completes or discards it; never mixed
    d = fresh("kill-publication")
    o = d / "out"
    subprocess.run(gnomon("scan", str(fx["cap"]), "--out", str(o), "--quiet", "--no-rrd"), check=True,
                   capture_output=True)
    (o / "notes.txt").write_text("mine")  # the per-file (commit folder) path
    before = digest_tree(o)

    def commit_started(o=o) -> bool:
        return any(p.name.startswith(".gnomon-commit-") for p in o.iterdir())

    def not_mixed(o=o, before=before, log=fx["desk"]) -> str | None:
        from gnomon.outputs.publish import recover
        recover(o)
        now = digest_tree(o)
        if (o / "notes.txt").read_text() != "mine":
            return "notes.txt lost"
        shapes = {np.load(o / n).shape for n in ("depth.npy", "sigma.npy", "shadow_time.npy")}
        if now == before:
            return None
        if len(shapes) != 1:
            return f"mixed: maps of shapes {shapes}"
        rep = json.loads((o / "report.json").read_text())
        if rep["inputs"]["image_size"][::-1] != list(next(iter(shapes))):
            return "mixed: report.json and depth.npy from different scans"
        return None
    out.append(Case(flt, "SIGKILL during publication", gnomon("scan", str(fx["desk"]), "--out", str(o), "--quiet"),
                    expect="killed", send=(60.0, signal.SIGKILL), wait_for=commit_started, check=not_mixed))

    if mounts is not None:
        full = mounts.tmpfs(root / "mnt-full", "14m")
        out.append(Case(flt, "full disk (14 MB tmpfs)", gnomon("scan", str(fx["desk"]), "--out", str(full / "scan"),
                                                              "--quiet"), needle=str(full / "scan"),
                        check=absent(full / "scan")))
        mb = int(fx["all_but_rrd_mb"])
        full2 = mounts.tmpfs(root / "mnt-full2", f"{mb}m")
        out.append(Case(flt, f"full disk ({mb} MB tmpfs: the recording overflows it)",
                        gnomon("scan", str(fx["desk"]), "--out", str(full2 / "scan"), "--quiet"),
                        needle=str(full2 / "scan"), check=absent(full2 / "scan")))
        ro = mounts.tmpfs(root / "mnt-ro", "4m", ro=True)
        out.append(Case(flt, "read-only filesystem", gnomon("scan", str(fx["cap"]), "--out", str(ro / "scan"),
                                                           "--quiet"), needle=str(ro / "scan")))
        other = mounts.tmpfs(root / "mnt-other", "64m")
        out.append(Case(flt, "--out is a mount point", gnomon("scan", str(fx["cap"]), "--out", str(other), "--quiet"),
                        expect="ok", check=lambda other=other: None if (other / "depth.npy").is_file() and
                        not leftovers(other) else "not published into the mount point"))
        other2 = mounts.tmpfs(root / "mnt-rrd", "64m")
        d = fresh("rrd-other-fs")
        out.append(Case(flt, "--rrd on another filesystem",
                        gnomon("scan", str(fx["cap"]), "--out", str(d / "o"), "--rrd", str(other2 / "r.rrd"),
                               "--quiet"), expect="ok",
                        check=lambda other2=other2, d=d: None if (other2 / "r.rrd").stat().st_size > 0 and
                        not (d / "o" / "scan.rrd").exists() else "recording lost"))
    return out


# ----------------------------------------------------------------------------- running


def run_case(case: Case, env: dict) -> Outcome:
    t0 = time.monotonic()
    proc = subprocess.Popen(case.argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**env, **case.env},
                            preexec_fn=case.preexec, cwd=str(ROOT))
    hung = False
    try:
        if case.stdout_pipe_close:
            proc.stdout.readline()
            proc.stdout.close()
            _, err_b = proc.communicate(timeout=TIME_LIMIT_S)
            out_b = b""
        elif case.send is not None:
            delay, sig = case.send
            deadline = time.monotonic() + delay
            while time.monotonic() < deadline and proc.poll() is None:
                if case.wait_for is not None and case.wait_for():
                    break
                time.sleep(0.002 if case.wait_for is not None else 0.01)
            if proc.poll() is None:
                proc.send_signal(sig)
            out_b, err_b = proc.communicate(timeout=TIME_LIMIT_S)
        else:
            out_b, err_b = proc.communicate(timeout=TIME_LIMIT_S)
    except subprocess.TimeoutExpired:
        hung = True
        proc.kill()
        out_b, err_b = proc.communicate()
    secs = time.monotonic() - t0
    err = err_b.decode("utf-8", "replace").strip()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    rc = proc.returncode
    problem = None
    if case.check is not None and not hung:
        try:
            problem = case.check()
        except Exception as exc:  # the check itself failing means the result is unusable
            problem = f"check failed: {type(exc).__name__}: {exc}"
    if hung:
        return Outcome(case, "hang", f"no answer in {TIME_LIMIT_S:.0f} s", secs)
    if "Traceback (most recent call last)" in err:
        return Outcome(case, "traceback", lines[-1] if lines else "", secs)
    if problem is not None:
        return Outcome(case, "lost/mixed" if case.expect != "ok" or "mixed" in problem or "lost" in problem
                       else "silent", problem, secs)
    if case.expect == "error":
        if rc == 2 and len(lines) == 1 and lines[0].startswith("gnomon: error: "):
            if case.needle and case.needle not in lines[0]:
                return Outcome(case, "other", f"one line, but not naming {case.needle!r}: {lines[0]}", secs)
            return Outcome(case, "one line", lines[0], secs)
        if rc == 0:
            return Outcome(case, "silent", "accepted (exit 0)", secs)
        return Outcome(case, "other", f"exit {rc}: {' | '.join(lines[-3:])}", secs)
    if case.expect == "signal":
        # exit 128+n from gnomon, or killed by the signal itself before Python could handle it (start-up)
        by_signal = rc is not None and case.send is not None and rc == -case.send[1]
        if rc is not None and (rc > 128 or by_signal) and len(lines) <= 1:
            return Outcome(case, "one line", f"exit {rc}: {lines[0] if lines else '(quiet)'}", secs)
        if rc == 0:
            return Outcome(case, "other", "finished before the signal", secs)
        return Outcome(case, "other", f"exit {rc}: {' | '.join(lines[-3:])}", secs)
    if case.expect == "killed":
        return Outcome(case, "one line" if rc in (-9, 0) else "other", f"exit {rc}; result not mixed", secs)
    if case.expect == "pipe":
        return Outcome(case, "one line" if not lines else "other", f"exit {rc}, stderr {len(lines)} lines", secs)
    if rc == 0:
        return Outcome(case, "ok", "", secs)
    return Outcome(case, "other", f"exit {rc}: {' | '.join(lines[-2:])}", secs)


COLUMNS = ("one line", "ok", "traceback", "hang", "silent", "lost/mixed", "other")


def table(outcomes: list[Outcome]) -> str:
    rows: dict[str, dict[str, int]] = {}
    for o in outcomes:
        rows.setdefault(o.case.klass, {c: 0 for c in COLUMNS})[o.verdict] += 1
    head = "| class | cases | " + " | ".join(COLUMNS) + " |"
    lines = [head, "|" + " --- |" * (len(COLUMNS) + 2)]
    total = {c: 0 for c in COLUMNS}
    for klass, counts in rows.items():
        n = sum(counts.values())
        lines.append(f"| {klass} | {n} | " + " | ".join(str(counts[c]) for c in COLUMNS) + " |")
        for c in COLUMNS:
            total[c] += counts[c]
    lines.append(f"| **all** | {sum(total.values())} | " + " | ".join(str(total[c]) for c in COLUMNS) + " |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", help="run the cases whose name or class contains this")
    ap.add_argument("--json", type=Path, help="write every case's outcome here")
    ap.add_argument("--keep", action="store_true", help="keep the working folder")
    args = ap.parse_args()
    env = {**os.environ, "PYTHONPATH": str(ROOT / "python"), "CI": "1", "TELEMETRY_ENABLED": "false"}
    env.pop("DISPLAY", None)
    root = Path(tempfile.mkdtemp(prefix="gnomon-faults-"))
    mounts = Mounts() if can_mount() else None
    try:
        fx = prepare(root)
        # a recording for review cases
        subprocess.run(gnomon("scan", str(fx["cap"]), "--out", str(root / "rec_scan"), "--quiet", "--rrd",
                              str(root / "rec.rrd")), check=True, env=env, capture_output=True)
        todo = cases(root, fx, mounts)
        if args.only:
            todo = [c for c in todo if args.only in c.name or args.only in c.klass]
        outcomes = []
        for c in todo:
            o = run_case(c, env)
            outcomes.append(o)
            print(f"{o.verdict:10s} {o.seconds:6.1f}s  [{c.klass}] {c.name}: {o.detail[:160]}", flush=True)
        print()
        print(table(outcomes))
        if mounts is None:
            print("\n(mount not allowed here: full-disk, read-only and second-filesystem cases skipped)")
        if args.json:
            args.json.write_text(json.dumps([{"class": o.case.klass, "case": o.case.name, "verdict": o.verdict,
                                              "detail": o.detail, "seconds": round(o.seconds, 2)}
                                             for o in outcomes], indent=2))
        bad = [o for o in outcomes if o.verdict in ("traceback", "hang", "silent", "lost/mixed", "other")]
        return 1 if bad else 0
    finally:
        if mounts is not None:
            mounts.release()
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
