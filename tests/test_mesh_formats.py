"""The mesh's files: mesh.ply by default, mesh.obj and mesh.stl on request ([output] mesh_formats,
--mesh-formats), a bad request named."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from gnomon import toml_io
from gnomon.cli import main
from gnomon.errors import GnomonError
from gnomon.fieldlog import MESH_FORMATS, load_field_log, mesh_formats

MESH_FILES = {"obj": {"mesh.obj", "mesh.mtl"}, "stl": {"mesh.stl"}}


def _with_output(path: Path, output: dict) -> Path:
    data = tomllib.loads(path.read_text())
    data["output"] = output
    toml_io.dump(data, path)
    return path


def test_mesh_formats_parse() -> None:
    assert mesh_formats("all") == MESH_FORMATS == ("ply", "obj", "stl")
    assert mesh_formats("stl,obj") == ("ply", "obj", "stl")  # mesh.ply always, in a fixed order
    assert mesh_formats(["STL"]) == ("ply", "stl")
    assert mesh_formats([]) == ("ply",)
    assert mesh_formats("obj,3mf") is None and mesh_formats(["all", "obj"]) is None and mesh_formats(3) is None


def test_field_log_key(tiny_capture: Path) -> None:
    assert load_field_log(tiny_capture).output.mesh_formats == ("ply",)
    assert load_field_log(_with_output(tiny_capture, {"mesh_formats": ["stl"]})).output.mesh_formats == ("ply", "stl")
    with pytest.raises(GnomonError) as err:
        load_field_log(_with_output(tiny_capture, {"mesh_formats": ["step"]}))
    assert "[output] mesh_formats" in str(err.value) and str(tiny_capture) in str(err.value)


def _mesh_files(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir() if p.name.startswith("mesh.")}


def test_default_scan_writes_the_ply_mesh_and_the_texture_only(tiny_capture: Path, tmp_path: Path) -> None:
    assert main(["scan", str(tiny_capture), "--out", str(tmp_path / "a"), "--quiet", "--no-rrd"]) == 0
    assert _mesh_files(tmp_path / "a") == {"mesh.ply", "mesh.png"}
    # the command line's choice, then the field log's
    assert main(["scan", str(tiny_capture), "--out", str(tmp_path / "b"), "--quiet", "--no-rrd",
                 "--mesh-formats", "all"]) == 0
    assert _mesh_files(tmp_path / "b") == {"mesh.ply", "mesh.png"} | MESH_FILES["obj"] | MESH_FILES["stl"]
    _with_output(tiny_capture, {"mesh_formats": ["stl"]})
    assert main(["scan", str(tiny_capture), "--out", str(tmp_path / "c"), "--quiet", "--no-rrd"]) == 0
    assert _mesh_files(tmp_path / "c") == {"mesh.ply", "mesh.png"} | MESH_FILES["stl"]


def test_bad_mesh_formats_option_is_a_usage_error(tiny_capture: Path, tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["scan", str(tiny_capture), "--out", str(tmp_path / "a"), "--mesh-formats", "fbx"])
    assert exc.value.code == 2 and "--mesh-formats" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
