"""Start-up cost: what `import gnomon.runs.scan`, `import gnomon.api` and `gnomon --version` load.

A scan with a lamp or two planes needs neither pandas (the sun's clock, through pvlib)
nor scipy.optimize nor scipy.stats (a plane's pose refined and checked from its markers): together
≈ 1 s of imports. Each check runs in a fresh interpreter, since this one has loaded them already.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

import gnomon
from gnomon.cli import build_parser
from gnomon.commands import COMMANDS

PACKAGE_ROOT = Path(gnomon.__file__).resolve().parents[1]


def _loaded_after(code: str, modules: list[str]) -> dict[str, bool]:
    """Which of ``modules`` are in sys.modules after running ``code`` in a fresh interpreter."""
    script = f"{code}\nimport json, sys\nprint(json.dumps({{m: m in sys.modules for m in {modules!r}}}))"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(PACKAGE_ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_pipeline_import_loads_neither_pandas_nor_scipy_optimize() -> None:
    loaded = _loaded_after("import gnomon.runs.scan", ["gnomon.runs.scan", "pandas", "scipy.optimize", "pvlib"])
    assert loaded == {"gnomon.runs.scan": True, "pandas": False, "scipy.optimize": False, "pvlib": False}


def test_the_api_loads_no_scene_until_one_is_asked_for() -> None:
    """`gnomon scan` imports gnomon.api (for SCENES and scan): no scene module, and so not pandas (the facade's
    and pvlib's, ≈ 0.45 s) until a scene's name is asked for."""
    loaded = _loaded_after("import gnomon.api\nimport gnomon.simulate as s\nassert 'chessboard' in s.SCENES",
                           ["gnomon.api", "gnomon.simulate.facade_sun", "gnomon.simulate.desk_lamp", "pandas", "pvlib"])
    assert loaded == {"gnomon.api": True, "gnomon.simulate.facade_sun": False, "gnomon.simulate.desk_lamp": False,
                      "pandas": False, "pvlib": False}
    loaded = _loaded_after("from gnomon.simulate import FacadeSunConfig, simulate_two_plane\n"
                           "from gnomon.simulate.facade_sun import FacadeSunConfig as direct\n"
                           "assert FacadeSunConfig is direct and callable(simulate_two_plane)",
                           ["gnomon.simulate.facade_sun", "gnomon.simulate.two_plane_scene", "gnomon.simulate.room"])
    assert loaded == {"gnomon.simulate.facade_sun": True, "gnomon.simulate.two_plane_scene": True,
                      "gnomon.simulate.room": False}


def test_sun_names_load_on_first_use() -> None:
    """gnomon.light still gives the sun's classes: asking for one loads them (and pandas) then."""
    loaded = _loaded_after("import gnomon.light\nassert 'gnomon.light.sun' not in __import__('sys').modules\n"
                           "from gnomon.light import SunClock, SunWithLines, SunWithPole\n"
                           "from gnomon.light.sun import SunClock as direct\nassert SunClock is direct",
                           ["gnomon.light.sun", "pandas"])
    assert loaded == {"gnomon.light.sun": True, "pandas": True}


def test_a_plane_from_its_markers_loads_neither_scipy_optimize_nor_stats() -> None:
    """A plane's pose refined from its markers (gnomon.util.fitting.levenberg_marquardt) and checked by its χ²
    (gnomon.util.chi2): neither scipy.optimize (≈ 0.35 s) nor scipy.stats (0.4–0.9 s) is imported."""
    code = ("import numpy as np, cv2\nfrom gnomon.camera.models import OpenCVCamera\n"
            "from gnomon.camera.plane_pose import fit_plane_pose\nfrom gnomon.util.chi2 import chi2_isf\n"
            "cam = OpenCVCamera(640, 480, 500.0, 500.0, 320.0, 240.0)\n"
            "ab = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 70.0]])\n"
            "obj = np.concatenate([ab, np.zeros((5, 1))], axis=1)\n"
            "R = cv2.Rodrigues(np.array([2.5, 0.1, 0.05]))[0]\n"
            "pix = cam.project(obj @ R.T + np.array([-100.0, -50.0, 700.0]))\n"
            "pose = fit_plane_pose(cam, ab, pix)\nassert pose.rms_px < 1e-6, pose.rms_px\n"
            "assert chi2_isf(0.01, 2 * len(ab) - 6) > 0")
    loaded = _loaded_after(code, ["gnomon.camera.plane_pose", "scipy.optimize", "scipy.stats"])
    assert loaded == {"gnomon.camera.plane_pose": True, "scipy.optimize": False, "scipy.stats": False}


def test_version_loads_no_command() -> None:
    """`gnomon --version` (and --help) build the parser from the commands' names and help lines alone."""
    code = ("import contextlib, io\nfrom gnomon import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        cli.main(['--version'])\n    except SystemExit:\n        pass")
    modules = ["numpy", "cv2", *(f"gnomon.commands.{name}" for name in COMMANDS)]
    loaded = _loaded_after(code, modules)
    assert not any(loaded.values()), [m for m, v in loaded.items() if v]


def _subparsers(parser):
    return next(a for a in parser._actions if a.dest == "command")


def test_listed_commands_are_the_registered_ones() -> None:
    """The help listing built without importing the commands is the one their modules register."""
    full, listed = _subparsers(build_parser()), _subparsers(build_parser(["--help"]))
    assert list(full.choices) == list(listed.choices) == list(COMMANDS)
    assert [(a.dest, a.help) for a in full._choices_actions] == [(a.dest, a.help) for a in listed._choices_actions]
    # the command asked for is built in full (its own options), the others only listed
    scan_only = _subparsers(build_parser(["scan", "log.toml"]))
    assert "--out" in scan_only.choices["scan"]._option_string_actions
    assert "--out" not in scan_only.choices["merge"]._option_string_actions
    args = build_parser(["scan", "log.toml", "--out", "o"]).parse_args(["scan", "log.toml", "--out", "o"])
    assert args.command == "scan" and args.out == Path("o") and callable(args.func)


def _frozen_at_exit(call: str) -> bool:
    """Whether the interpreter's objects were exempt from garbage collection at its teardown after
    ``call`` (an atexit handler registered before it runs after the CLI's)."""
    script = ("import atexit, contextlib, gc, io, sys\n"
              "atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0))\n"
              "from gnomon.cli import main\nsys.argv = ['gnomon', '--version']\n"
              f"with contextlib.redirect_stdout(io.StringIO()):\n    try:\n        {call}\n"
              "    except SystemExit:\n        pass\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(PACKAGE_ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.split() == ["frozen", "True"]


def test_the_command_line_skips_the_teardown_collections() -> None:
    """`gnomon ...` (main() on the process's arguments) leaves its objects out of the teardown's garbage
    collections; main(argv) called by a program does not touch the program's collector."""
    assert _frozen_at_exit("main()")
    assert not _frozen_at_exit("main(['--version'])")


ARENAS = """
import ctypes, sys, threading
import numpy as np
from gnomon import cli
took = cli.one_malloc_arena() if sys.argv[1] == "one" else False
barrier = threading.Barrier(4)
def work():
    barrier.wait()  # all four alive at once: none can take over an exited thread's arena
    keep = [np.ones(100) for _ in range(64)]  # small blocks: from the thread's arena
    barrier.wait()
    del keep
threads = [threading.Thread(target=work) for _ in range(4)]
for t in threads:
    t.start()
for t in threads:
    t.join()
print(took, flush=True)
ctypes.CDLL(None).malloc_stats()  # glibc: one "Arena N:" block per arena, on stderr
"""


def _arenas(mode: str, **env: str) -> tuple[str, int]:
    """(one_malloc_arena's result, the arenas glibc reports) after four threads allocated at once."""
    full_env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    full_env.update(env, PYTHONPATH=os.pathsep.join([str(PACKAGE_ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", ARENAS, mode], capture_output=True, text=True, env=full_env,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip(), sum(line.startswith("Arena ") for line in proc.stderr.splitlines())


@pytest.mark.skipif(not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
                    reason="glibc's malloc arenas")
def test_command_line_process_allocates_from_one_arena() -> None:
    """The `gnomon` process's threads share glibc's main arena (cli.one_malloc_arena); by default
    glibc gives concurrent threads arenas of their own; MALLOC_ARENA_MAX set by the user is left alone."""
    assert _arenas("default")[1] > 1
    assert _arenas("one") == ("True", 1)
    assert _arenas("one", MALLOC_ARENA_MAX="4")[0] == "False"
