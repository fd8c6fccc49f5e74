"""A facade scanned from a roof edge's shadow without a pole (issue 35, item 4), against the simulator's truth;
and the field log's ``[edge]`` refused when it contradicts itself or the light."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon.cli import main
from gnomon.runs.accuracy import GROSS_FRACTION, depth_accuracy
from gnomon.runs.scan import ScanOptions, run_scan
from gnomon.simulate import FacadeSunConfig
from gnomon.simulate.roof_edge import simulate_roof_edge
from gnomon.util import toml_io

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "field_logs" / "facade_sun_small"
EDGE = {"a": [-150.0, 40.0, 22.0], "b": [150.0, 40.0, 22.0], "body": [0.0, 40.0, 0.0]}


def edited_small(tmp_path: Path, edit) -> Path:
    """facade_sun_small's field log beside its frames, edited."""
    data = tomllib.loads((SMALL / "field_log.toml").read_text())
    edit(data)
    path = tmp_path / "field_log.toml"
    data["capture"]["frames"] = str(SMALL / data["capture"]["frames"])
    data.pop("gnomon", None)
    toml_io.dump(data, path)
    return path


@pytest.mark.parametrize("edit, needle", [
    (lambda d: d.update(edge=EDGE), "[edge] and [pole] both given"),
    (lambda d: (d.pop("pole"), d.update(edge={**EDGE, "b": EDGE["a"]})), "[edge] b: must differ from a"),
    (lambda d: (d.pop("pole"), d.update(edge={**EDGE, "body": [7.0, 40.0, 22.0]})), "[edge] body: lies on the edge"),
    (lambda d: (d.pop("pole"), d.update(edge={"a": EDGE["a"]})), "[edge] missing required key 'b'"),
    (lambda d: (d.pop("pole"), d.update(edge=EDGE, light={"kind": "two-plane"})),
     "[edge] needs [light] kind = 'sun'"),
])
def test_edge_mistakes_are_one_line_and_exit_2(tmp_path: Path, capsys, edit, needle: str) -> None:
    log = edited_small(tmp_path, edit)
    out = tmp_path / "out"
    code = main(["scan", str(log), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert needle in err[0] and str(log) in err[0], err[0]
    assert not out.exists()


def test_edge_without_ends_is_found_from_the_lines(tmp_path: Path) -> None:
    from gnomon.config.fieldlog import load_field_log

    log = load_field_log(edited_small(tmp_path, lambda d: (d.pop("pole"), d.update(edge={"body": EDGE["body"]}))))
    assert log.edge is not None and log.edge.a is None and log.edge.b is None
    assert np.array_equal(log.edge.body, EDGE["body"])


@pytest.fixture(scope="module")
def roof_edge(tmp_path_factory):
    root = tmp_path_factory.mktemp("roof_edge")
    simulate_roof_edge(root / "capture", FacadeSunConfig(width=400, height=300, roof_edge=True))
    return root, dict(np.load(root / "capture" / "ground_truth.npz"))


@pytest.mark.slow
def test_facade_from_the_roof_edge_without_a_pole(roof_edge) -> None:
    root, truth = roof_edge
    result = run_scan(root / "capture" / "field_log.toml", root / "scan", ScanOptions(progress=False, rrd=False))
    distance = float(truth["camera_distance"])
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], distance, "m", sigma=result.sigma,
                         swept_surface=truth["swept_surface"])
    calm = depth_accuracy(result.depth, truth["depth"], truth["cloud_free_passage"], distance, "m")
    print(acc.table("facade_sun --roof-edge 400x300"), f"\ncloud-free RMS {calm.rms_pct:.3f} %")
    assert result.report["sun"]["mode"] == "edge"
    # The bar of issue 35: 0.2 % of the distance over the surface the edge's shadow swept (measured 0.085 %).
    assert acc.rms_pct <= 0.2
    assert acc.median_pct <= 0.1
    # A cloud dimming the sun as the shadow arrives moves the step to its onset; those steps pile up and are
    # refused: the coverage is that of the passages no cloud touched (the truth's cloud_free_passage), most of
    # which are found (measured 83.7 % of all swept pixels, 89 % of the cloud-free ones).
    free = float(truth["cloud_free_passage"].sum() / truth["swept"].sum())
    assert acc.coverage >= 0.9 * free
    assert calm.coverage >= 0.85
    # Gross errors, > 1 % of the distance, and false points (issue 35's bars for the building's own shadows,
    # 1 % each): measured 0.19 % and 0.70 % (4.9 % before the points that saw less than half the sun were
    # refused: in a window reveal's or the ledge's penumbra as the edge passed, which the truth does not count
    # as swept).
    assert GROSS_FRACTION == 0.01 and acc.gross_rate <= 0.01
    assert acc.false_point_rate <= 0.01
    # Leaving steps are against the edge's shadow's motion here (it climbs): the checks refuse them.
    leave = next(e for e in result.edges if e.name == "leave")
    assert leave.rejected["step_against_the_edge_shadow_motion"] > 0
    assert np.isfinite(leave.depth).sum() < 0.01 * np.isfinite(result.depth).sum()
    shutil.rmtree(root / "scan")


@pytest.mark.slow
def test_facade_from_the_edge_found_in_the_shadow_lines(roof_edge) -> None:
    """[edge] without a and b: the edge is the line all the frames' planes share, each plane through the shadow's
    line on the facade regions and the sun; then the same table through it."""
    root, truth = roof_edge
    data = tomllib.loads((root / "capture" / "field_log.toml").read_text())
    for key in ("a", "b"):
        data["edge"].pop(key)
    log = root / "capture" / "field_log_found.toml"
    toml_io.dump(data, log)
    result = run_scan(log, root / "scan_found", ScanOptions(progress=False, rrd=False))
    distance = float(truth["camera_distance"])
    acc = depth_accuracy(result.depth, truth["depth"], truth["swept"], distance, "m", sigma=result.sigma,
                         swept_surface=truth["swept_surface"])
    edge = result.report["sun"]["edge"]
    print(acc.table("facade_sun --roof-edge 400x300, edge found"), edge)
    assert edge["found_from_lines"] and edge["leave"] is None  # the shadow only climbs: no leaving lines
    found = edge["enter"]
    a, b = truth["edge_a"], truth["edge_b"]
    e = (b - a) / np.linalg.norm(b - a)
    direction = np.asarray(found["direction"]) / np.linalg.norm(found["direction"])
    rel = np.asarray(found["point"]) - a
    off = np.linalg.norm(rel - (rel @ e) * e)
    # A line found δ off moves each plane by at most δ along its normal, a point along its ray by δ / sin 25°
    # (the rays meet these planes at about 25°): the depth bar below binds; these bounds catch a line found
    # elsewhere (measured 4.7 cm and 0.04°, the fit absorbing part of the steps' 0.1-frame timing bias).
    assert off <= 0.1
    assert np.degrees(np.arccos(min(1.0, abs(direction @ e)))) <= 0.1
    assert acc.rms_pct <= 0.2  # measured 0.078 %
    assert acc.coverage >= 0.9 * float(truth["cloud_free_passage"].sum() / truth["swept"].sum())
    assert acc.gross_rate <= 0.01 and acc.false_point_rate <= 0.01
    shutil.rmtree(root / "scan_found")


@pytest.mark.slow
def test_regions_from_the_edge_steps(roof_edge, tmp_path: Path, capsys) -> None:
    """`gnomon regions` tracks an [edge] capture's steps (not dips) and grows the facade's mask along its lines."""
    import cv2

    root, truth = roof_edge
    log = tmp_path / "field_log.toml"
    data = tomllib.loads((root / "capture" / "field_log.toml").read_text())
    data["capture"]["frames"] = str(root / "capture" / data["capture"]["frames"])
    toml_io.dump(data, log)
    assert main(["regions", str(log), "--out", str(tmp_path / "regions"), "--quiet"]) == 0
    print(capsys.readouterr().out)
    mask = cv2.imread(str(tmp_path / "regions" / "facade_mask.png"), cv2.IMREAD_GRAYSCALE) > 0
    wall = truth["object_id"] == 1
    # grown from the field log's three rectangles (6,580 px) along the wall the edge's shadow swept (measured
    # 15,803 px)
    assert mask.sum() > 2 * sum((u1 - u0) * (v1 - v0) for u0, v0, u1, v1 in data["planes"][0]["regions"])
    assert (mask & wall & truth["swept_surface"]).sum() >= 0.95 * mask.sum()
