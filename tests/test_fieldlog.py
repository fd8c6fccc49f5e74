"""Field-log parsing: valid logs load; every user mistake names the file and key."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon import toml_io
from gnomon.errors import FieldLogError
from gnomon.fieldlog import load_field_log


def rewrite(path: Path, edit) -> Path:
    data = tomllib.loads(path.read_text())
    edit(data)
    toml_io.dump(data, path)
    return path


def test_valid_log_loads(tiny_capture: Path) -> None:
    log = load_field_log(tiny_capture)
    assert len(log.capture.image_files) == 24
    assert log.capture.units == "mm" and log.capture.gamma == 1.0
    assert log.camera.width == 48 and log.camera.height == 36
    # Camera 500 mm above the desk origin.
    np.testing.assert_allclose(log.pose.camera_centre_world, [0, 0, 500], atol=1e-9)
    assert log.planes[0].regions[1] == (0, 30, 48, 36)
    assert log.scan.edge == "both" and log.scan.min_contrast == 20


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["light"].pop("position"), "[light] missing required key 'position'"),
        (lambda d: d["light"].update(postion=[1, 2, 3]), "[light] unknown key 'postion'"),
        (lambda d: d.pop("capture"), "missing required table [capture]"),
        (lambda d: d["camera"].update(fx="wide"), "[camera] fx: expected a finite number"),
        (lambda d: d["camera"]["pose"].pop("tvec"), "[camera.pose] missing required key 'tvec'"),
        (lambda d: d["planes"][0].update(regions=[[0, 0, 480, 10]]), "outside the 48x36 image"),
        (lambda d: d["scan"].update(edge="both-ways"), "[scan] edge: expected one of"),
        (lambda d: d.update(extra={"a": 1}), "[field log] unknown key 'extra'"),
        (lambda d: d["capture"].update(frames="missing/*.png"), "frames folder"),
        (lambda d: d["capture"].update(frames="frames/*.tif"), "no files match"),
        (lambda d: d["light"].update(position=[0, 0, -300]), "below the plane 'desk'"),
    ],
)
def test_mistakes_name_file_and_key(tiny_capture: Path, edit, message: str) -> None:
    rewrite(tiny_capture, edit)
    with pytest.raises(FieldLogError) as info:
        load_field_log(tiny_capture)
    text = str(info.value)
    assert message in text
    assert str(tiny_capture) in text
    assert "\n" not in text


def test_not_toml(tmp_path: Path) -> None:
    bad = tmp_path / "log.toml"
    bad.write_text("[capture\nframes = ")
    with pytest.raises(Exception) as info:
        load_field_log(bad)
    assert "not valid TOML" in str(info.value) and str(bad) in str(info.value)
