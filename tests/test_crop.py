"""[output] crop: parsing, the per-point test, and a desk scan cropped at 2 mm above the desk."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon.config.fieldlog import load_field_log
from gnomon.errors import GnomonError
from gnomon.geometry.crop import Crop, crop_mask
from gnomon.util import toml_io


def _with_output(path: Path, output: dict) -> Path:
    data = tomllib.loads(path.read_text())
    data["output"] = output
    toml_io.dump(data, path)
    return path


def test_output_table_parses(tiny_capture: Path) -> None:
    assert not load_field_log(tiny_capture).output.crops
    log = load_field_log(_with_output(tiny_capture, {"crop_above": "desk", "crop_min_height": 2.0,
                                                      "crop_box": [[-10, -10, -1], [10, 10, 50]]}))
    assert log.output.crop_above == "desk" and log.output.crop_min_height == 2.0
    np.testing.assert_array_equal(log.output.crop_box, [[-10, -10, -1], [10, 10, 50]])
    only_sigma = load_field_log(_with_output(tiny_capture, {"max_sigma": 1.5}))
    assert only_sigma.output.crops and only_sigma.output.max_sigma == 1.5 and only_sigma.output.crop_box is None


@pytest.mark.parametrize("output, message", [
    ({"crop_above": "table"}, "[output] crop_above: expected one of 'desk'"),
    ({"crop_min_height": 2.0}, "crop_above"),
    ({"crop_box": [[0, 0, 0], [1, 1]]}, "crop_box"),
    ({"crop_box": [[0, 0, 0], [1, -1, 1]]}, "each max must exceed its min"),
    ({"crop_above": "desk", "crop_min_height": 5, "crop_max_height": 2}, "crop_max_height"),
    ({"crop": 1}, "unknown key 'crop'"),
    ({"max_sigma": 0}, "[output] max_sigma: must be > 0"),
    ({"max_sigma": "1 mm"}, "[output] max_sigma: expected a finite number"),
])
def test_bad_output_tables_name_the_key(tiny_capture: Path, output: dict, message: str) -> None:
    with pytest.raises(GnomonError) as err:
        load_field_log(_with_output(tiny_capture, output))
    assert message in str(err.value) and str(tiny_capture) in str(err.value)


def test_crop_mask_by_height_and_box() -> None:
    p = np.array([[0, 0, 0.5], [0, 0, 3.0], [50, 0, 3.0], [0, 0, np.nan], [0, 0, -3.0]])
    above = Crop(plane_name="desk", plane_point=np.zeros(3), plane_normal=np.array([0, 0, -1.0]), min_height=2.0)
    # the normal is turned towards the camera (above the desk), whatever its sign in the field log
    np.testing.assert_array_equal(crop_mask(p, above, np.array([0, 0, 500.0])), [0, 1, 1, 0, 0])
    box = Crop(box_min=np.array([-10, -10, -10.0]), box_max=np.array([10, 10, 10.0]))
    np.testing.assert_array_equal(crop_mask(p, box, np.array([0, 0, 500.0])), [1, 1, 0, 0, 1])
    both = Crop(box_min=box.box_min, box_max=box.box_max, plane_name="desk", plane_point=np.zeros(3),
                plane_normal=np.array([0, 0, 1.0]), min_height=2.0, max_height=2.5)
    np.testing.assert_array_equal(crop_mask(p, both, np.array([0, 0, 500.0])), [0, 0, 0, 0, 0])


def test_crop_mask_by_sigma() -> None:
    p = np.array([[0, 0, 1.0], [0, 0, 2.0], [0, 0, 3.0], [0, 0, np.nan], [0, 0, 4.0]])
    sigma = np.array([0.5, 1.5, 1.6, 0.1, np.nan])
    crop = Crop(max_sigma=1.5)
    # at the bound kept, above it or unknown dropped, a NaN point never kept
    np.testing.assert_array_equal(crop_mask(p, crop, np.zeros(3), sigma), [1, 1, 0, 0, 0])
    box = Crop(box_min=np.array([-1, -1, 1.5]), box_max=np.array([1, 1, 5.0]), max_sigma=1.5)
    np.testing.assert_array_equal(crop_mask(p, box, np.zeros(3), sigma), [0, 1, 0, 0, 0])
    assert crop.to_report() == {"max_sigma": 1.5}
    with pytest.raises(ValueError, match="one sigma per point"):
        crop_mask(p, crop, np.zeros(3))


@pytest.mark.slow
def test_two_plane_scan_with_max_sigma_keeps_the_certain_points(two_plane_small, tmp_path) -> None:
    """``[output] max_sigma`` at the median σ of a scan without it: the same points less exactly those
    whose σ exceeds it (the crop comes after fusion and neighbour support, so the others are untouched),
    counted as cropped; and the points it drops are the less accurate ones (truth of the simulator: their
    RMS depth error exceeds the kept points')."""
    from conftest import copy_capture
    from gnomon.outputs.images import CROPPED
    from gnomon.runs.scan import ScanOptions, run_scan

    options = ScanOptions(progress=False, rrd=False)
    capture = copy_capture(two_plane_small, tmp_path / "capture")
    every = run_scan(capture / "field_log.toml", tmp_path / "every", options)
    bound = float(np.median(every.sigma[every.valid]))
    _with_output(capture / "field_log.toml", {"max_sigma": bound})
    certain = run_scan(capture / "field_log.toml", tmp_path / "certain", options)
    expected = every.valid & (every.sigma <= bound)
    np.testing.assert_array_equal(certain.valid, expected)
    np.testing.assert_array_equal(certain.depth[expected], every.depth[expected])
    assert np.all(certain.sigma[certain.valid] <= bound) and len(certain.points_world) == expected.sum()
    dropped = every.valid & ~expected
    assert (certain.coverage == CROPPED).sum() == dropped.sum() == certain.report["coverage"]["cropped"]
    assert certain.report["output"]["crop"] == {"max_sigma": bound}
    truth = np.load(capture / "ground_truth.npz")["depth"]
    error = every.depth - truth

    def rms(m: np.ndarray) -> float:
        return float(np.sqrt(np.nanmean(error[m] ** 2)))

    print(f"max_sigma {bound:.3f}: dropped {dropped.sum()} points, RMS {rms(dropped):.3f}; kept {expected.sum()}, "
          f"RMS {rms(expected):.3f}")
    assert dropped.sum() > 1000 and rms(dropped) > rms(expected), (rms(dropped), rms(expected))


@pytest.fixture(scope="module")
def cropped_desk(tmp_path_factory):
    """A 400×300 desk capture with 300 frames (σ ≈ 0.2 mm on the desk: a 2 mm cut is ≈ 10 σ),
    scanned in memory with ``[output] crop_above = "desk"``, ``crop_min_height = 2``."""
    import gnomon

    root = tmp_path_factory.mktemp("crop")
    log = gnomon.simulate("desk_lamp", root, width=400, height=300, frames=300, seed=5, pencil_photos=0)
    _with_output(log, {"crop_above": "desk", "crop_min_height": 2.0})
    return root, gnomon.scan(log)


@pytest.mark.slow
def test_desk_scan_cropped_2mm_above_the_desk_keeps_the_objects(cropped_desk) -> None:
    """≥ 99 % of the objects' points stay, ≤ 0.5 % of the desk's (the simulator's object ids).

    Before the crop = the points kept plus those it removed (the coverage map's classes). The
    objects' points are those on an object (truth's object id) whose true height above the desk
    is at least the crop height: a height crop cannot keep the few lower ones (where the box
    and the cylinder stand on the desk), and must not.
    """
    from gnomon.outputs.images import CROPPED, POINT, UNDERSAMPLED

    root, scan = cropped_desk
    gt = np.load(root / "ground_truth.npz")
    on_object = (gt["object_id"] > 0) & (gt["points_world"][..., 2] >= 2.0)
    on_desk = gt["object_id"] == 0
    kept = np.isin(scan.coverage, (POINT, UNDERSAMPLED))
    before = kept | (scan.coverage == CROPPED)
    assert (on_object & before).sum() > 5000 and (on_desk & before).sum() > 50_000
    objects_kept = (on_object & kept).sum() / (on_object & before).sum()
    desk_kept = (on_desk & kept).sum() / (on_desk & before).sum()
    assert objects_kept >= 0.99, objects_kept
    assert desk_kept <= 0.005, desk_kept
    assert kept.sum() == len(scan.points) and scan.report["coverage"]["cropped"] == (scan.coverage == CROPPED).sum()
    assert scan.report["output"]["crop"] == {"above": "desk", "min_height": 2.0, "max_height": None}
    # the points and the mesh hold nothing below the cut
    assert np.all(scan.points[:, 2] >= 2.0) and np.all(scan.mesh.vertices[:, 2] >= 2.0)
