"""[output] crop: parsing, the per-point test, and a desk scan cropped at 2 mm above the desk."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon import toml_io
from gnomon.crop import Crop, crop_mask
from gnomon.errors import GnomonError
from gnomon.fieldlog import load_field_log


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


@pytest.mark.parametrize("output, message", [
    ({"crop_above": "table"}, "[output] crop_above: expected one of 'desk'"),
    ({"crop_min_height": 2.0}, "crop_above"),
    ({"crop_box": [[0, 0, 0], [1, 1]]}, "crop_box"),
    ({"crop_box": [[0, 0, 0], [1, -1, 1]]}, "each max must exceed its min"),
    ({"crop_above": "desk", "crop_min_height": 5, "crop_max_height": 2}, "crop_max_height"),
    ({"crop": 1}, "unknown key 'crop'"),
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
