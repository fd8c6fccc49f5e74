"""The README's walk-through on a capture nobody set up (issue 34, item 8): `gnomon calibrate camera` on
chessboard photos that all lie on the desk, `gnomon init` on the frames (marks found, a corrupt frame
named), `gnomon regions` (the object cut out of the marks' outline, the masks switched on), `gnomon scan`,
without editing any file; the depth against the simulator's truth.

The capture: the two_plane scene with printed checkers whose positions nobody measured (a rectangle of
unknown size), an object standing inside the marks' outline, one JPEG with 200 bytes zeroed in the
middle; the board photos rendered with the scene's own camera (the simulator's truth), all on one desk.
"""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon.cli import main


def corrupt_middle(path: Path, n: int = 200) -> None:
    """Zero ``n`` bytes in the middle of a file (what a failing card or copy does to a JPEG)."""
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid:mid + n] = bytes(n)
    path.write_bytes(bytes(data))


def walk(root: Path, sim: Path, coplanar: bool) -> dict:
    """The walk-through in ``root`` on the simulated frames (one made corrupt) and board photos rendered
    with the scene's camera: on one desk (``coplanar``) or held up tilted and turned. Returns each step's
    exit code and the folder."""
    from gnomon.simulate.chessboard import TruthPinhole, write_chessboard_views

    cam = tomllib.loads((sim / "field_log.toml").read_text())["camera"]
    shutil.copytree(sim / "frames", root / "frames")
    frames = sorted((root / "frames").iterdir())
    corrupt = frames[len(frames) // 2]
    corrupt_middle(corrupt)
    camera = TruthPinhole(int(cam["width"]), int(cam["height"]), cam["fx"], cam["fy"], cam["cx"], cam["cy"],
                          tuple(cam["dist"]))
    write_chessboard_views(root / "board", camera=camera, n_views=12, coplanar=coplanar, seed=3)
    views = sorted(str(p) for p in (root / "board").glob("view_*.png"))
    steps = {
        "calibrate": ["calibrate", "camera", *views, "--board", "9x6", "--square", "25", "--out",
                      str(root / "camera.toml"), "--quiet"],
        "init": ["init", str(root / "frames"), "--camera", str(root / "camera.toml")],
        "regions": ["regions", str(root / "field_log.toml"), "--quiet"],
        "scan": ["scan", str(root / "field_log.toml"), "--out", str(root / "scan"), "--no-rrd", "--quiet"],
    }
    return {"root": root, "codes": {name: main(argv) for name, argv in steps.items()}, "corrupt": corrupt}


@pytest.fixture(scope="module")
def walked(tmp_path_factory) -> dict:
    from gnomon.simulate import TwoPlaneConfig, simulate_two_plane

    root = tmp_path_factory.mktemp("walkthrough")
    simulate_two_plane(root / "simulated", TwoPlaneConfig(seed=2, marks="unmeasured"))
    truth = dict(np.load(root / "simulated" / "ground_truth.npz"))
    return {"truth": truth, "tilted": walk(root / "tilted", root / "simulated", False),
            "on_desk": walk(root / "on_desk", root / "simulated", True)}


def accuracy(truth: dict, scan: Path, title: str):
    """The scan's depth against the truth, scaled by the one factor units "relative" leaves free."""
    from gnomon.runs.accuracy import depth_accuracy

    depth = np.load(scan / "depth.npy").astype(np.float64)
    sigma = np.load(scan / "sigma.npy").astype(np.float64)
    ok = np.isfinite(depth) & truth["swept"]
    k = float(np.median(truth["depth"][ok] / depth[ok]))
    acc = depth_accuracy(depth * k, truth["depth"], truth["swept"], float(truth["camera_distance_mm"]),
                         sigma=sigma * k, swept_surface=truth["swept_surface"])
    print(acc.table(f"{title}, relative units scaled by {k:.3f}"))
    return acc


@pytest.mark.slow
@pytest.mark.parametrize("board", ["tilted", "on_desk"])
def test_the_walkthrough_needs_no_edit(walked: dict, board: str) -> None:
    """Every step exits 0; the field log `init` wrote (the marks found, the corrupt frame named and left
    out) and `regions` completed (the masks switched on) is what the scan read, and the scan names the
    corrupt frame."""
    w = walked[board]
    assert w["codes"] == {"calibrate": 0, "init": 0, "regions": 0, "scan": 0}
    text = (w["root"] / "field_log.toml").read_text()
    assert w["corrupt"].name in text and 'on_corrupt_frame = "drop"' in text
    log = tomllib.loads(text)
    assert [len(p["markers"]) for p in log["planes"]] == [4, 4]
    assert [p["mask"] for p in log["planes"]] == ["regions/desk_mask.png", "regions/wall_mask.png"]
    report = json.loads((w["root"] / "scan" / "report.json").read_text())
    assert any(w["corrupt"].name in m for m in report["warnings"]), report["warnings"]
    assert (w["root"] / "camera.rrd").stat().st_size > 0  # the calibration's recording, by default
    method = tomllib.loads((w["root"] / "camera.toml").read_text())["calibration"]["method"]
    assert method == ("zhang-coplanar" if board == "on_desk" else "zhang")


@pytest.mark.slow
def test_the_walkthrough_gives_the_depth(walked: dict) -> None:
    """Board photos held up tilted: the depth within 0.1 % of the distance (RMS) of the truth over ≥ 95 %
    of the swept pixels, ≤ 1 % false points. Board photos all on the desk (the paper's calibration: the
    principal point taken at the image's centre, k1 only): the simulated camera's principal point is
    (2.8, 1.9) px off the centre and it has k2, p1, p2, which that model cannot hold; the depth is then
    within 0.2 % (measured: 0.116 % against 0.036 % with the true camera on the same frames)."""
    truth = walked["truth"]
    for board, bar in (("tilted", 0.1), ("on_desk", 0.2)):
        acc = accuracy(truth, walked[board]["root"] / "scan", f"walk-through, board {board}")
        assert acc.rms_pct <= bar, board
        assert acc.coverage >= 0.95, board
        assert acc.false_point_rate <= 0.01, board
