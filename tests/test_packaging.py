"""Packaging: one version, declared dependencies, a licence, TOML that round-trips."""

from __future__ import annotations

import ast
import math
import sys
import tomllib
from pathlib import Path

import numpy as np

import gnomon
from gnomon import toml_io

ROOT = Path(__file__).resolve().parents[1]


def test_version_has_one_home() -> None:
    cargo = tomllib.loads((ROOT / "Cargo.toml").read_text())["workspace"]["package"]["version"]
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert gnomon.__version__ == cargo
    for crate in ("rust/core", "rust/py"):
        package = tomllib.loads((ROOT / crate / "Cargo.toml").read_text())["package"]
        assert package["version"] == {"workspace": True}
    # no other file spells a version out
    for path in (ROOT / "python" / "gnomon").rglob("*.py"):
        assert f'"{cargo}"' not in path.read_text(), path


def test_licence_is_declared_and_shipped() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    assert any(c.startswith("Programming Language :: Python :: 3.11") for c in project["classifiers"])


def _imported_top_level(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_every_imported_package_is_declared() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    # the dependencies, and the extras for the modules only they use (dask for `gnomon batch`)
    requirements = project["dependencies"] + [d for extra in project["optional-dependencies"].values()
                                              for d in extra]
    declared = {d.split(">")[0].split("<")[0].split("=")[0].split("[")[0].strip().lower() for d in requirements}
    # import name → distribution name
    dist = {"cv2": "opencv-python-headless", "PIL": "pillow", "rerun": "rerun-sdk", "tomli_w": "tomli-w"}
    imported: set[str] = set()
    for path in (ROOT / "python" / "gnomon").rglob("*.py"):
        imported |= _imported_top_level(path)
    third_party = {m for m in imported if m not in sys.stdlib_module_names and m not in ("gnomon", "__future__")}
    missing = {m for m in third_party if dist.get(m, m).lower() not in declared}
    assert not missing, f"imported but not declared in pyproject.toml: {sorted(missing)}"


def test_toml_round_trips_awkward_keys_and_strings(tmp_path) -> None:
    data = {
        "plain": 1,
        "a key with spaces": "value",
        "control": "tab\there, bell\x07, newline\nquote\" backslash\\",
        "unicode ключ": "ü",
        "floats": np.array([0.1, 1e-300, -2.5]),
        "f32": np.float32(0.1),
        "nan": float("nan"),
        "table": {"nested key": [[1, 2], [3, 4]], "flag": np.bool_(True)},
        "planes": [{"name": "desk top", "regions": [(0, 0, 10, 10)]}],
    }
    path = tmp_path / "x.toml"
    toml_io.dump(data, path, header="line one\nline two")
    back = tomllib.loads(path.read_text())
    assert path.read_text().startswith("# line one\n# line two\n")
    assert back["a key with spaces"] == "value"
    assert back["control"] == data["control"]
    assert back["unicode ключ"] == "ü"
    assert back["floats"] == [0.1, 1e-300, -2.5]
    assert back["f32"] == float(np.float32(0.1))
    assert math.isnan(back["nan"])
    assert back["table"] == {"nested key": [[1, 2], [3, 4]], "flag": True}
    assert back["planes"] == [{"name": "desk top", "regions": [[0, 0, 10, 10]]}]
