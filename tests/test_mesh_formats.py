"""The mesh's files: mesh.ply by default, mesh.obj and mesh.stl on request ([output] mesh_formats,
--mesh-formats), a bad request named."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gnomon.cli import main
from gnomon.config.fieldlog import load_field_log
from gnomon.errors import GnomonError
from gnomon.outputs.formats import MESH_FORMATS, mesh_formats
from gnomon.util import toml_io

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


def test_a_new_format_is_one_module_and_one_registry_line(tiny_capture: Path, tmp_path: Path, monkeypatch) -> None:
    """tests/xyz_format.py and the one line below: the field log, the command line, the writers and the
    publishing of the folder all take the new format from the registry."""
    from gnomon.outputs.formats import FORMATS, MeshFormat
    from gnomon.outputs.ply import read_ply
    from xyz_format import write_scan_xyz

    monkeypatch.setitem(FORMATS, "xyz", MeshFormat("xyz", ("mesh.xyz",), write_scan_xyz))  # the registry line

    assert mesh_formats("XYZ") == ("ply", "xyz") and "xyz" in mesh_formats("all")
    assert load_field_log(_with_output(tiny_capture, {"mesh_formats": ["xyz"]})).output.mesh_formats == ("ply", "xyz")
    out = tmp_path / "scan"
    assert main(["scan", str(tiny_capture), "--out", str(out), "--quiet", "--no-rrd"]) == 0
    assert _mesh_files(out) == {"mesh.ply", "mesh.png", "mesh.xyz"}
    xyz = [line.split() for line in (out / "mesh.xyz").read_text().splitlines()[1:]]
    vertices = read_ply(out / "mesh.ply")["xyz"]
    assert len(xyz) == len(vertices) > 0
    assert np.abs(np.array(xyz, dtype=np.float64) - vertices).max() < 1e-5
    # a rescan into the same folder without the format drops the stale file: publishing knows it too
    assert main(["scan", str(tiny_capture), "--out", str(out), "--quiet", "--no-rrd", "--mesh-formats", "ply"]) == 0
    assert _mesh_files(out) == {"mesh.ply", "mesh.png"}
