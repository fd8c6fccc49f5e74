"""Packaging: one version, declared dependencies, a licence, TOML that round-trips."""

from __future__ import annotations

import ast
import math
import re
import sys
import tomllib
from pathlib import Path

import numpy as np

import gnomon
from gnomon.util import toml_io

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


def _imports(path: Path) -> tuple[set[str], set[str]]:
    """Top-level names of the absolute imports in ``path``: ``(at module level, anywhere)``."""
    tree = ast.parse(path.read_text())

    def names(nodes) -> set[str]:
        out = set()
        for node in nodes:
            if isinstance(node, ast.Import):
                out |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                out.add(node.module.split(".")[0])
        return out

    module_level = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    module_level += [n for block in tree.body if isinstance(block, (ast.If, ast.Try))
                     for n in ast.walk(block) if isinstance(n, (ast.Import, ast.ImportFrom))]
    return names(module_level), names(ast.walk(tree))


def _distribution(requirement: str) -> str:
    return re.split(r"[<>=!~;\[ ]", requirement, maxsplit=1)[0].strip().lower().replace("_", "-")


def test_every_imported_package_is_declared() -> None:
    """Every third-party package the code imports is a dependency; one imported only inside the
    functions that need it may instead be in a feature extra (dask), never only in the test extra."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    required = {_distribution(d) for d in project["dependencies"]}
    extras = {_distribution(d) for name, reqs in project["optional-dependencies"].items() if name != "test"
              for d in reqs}
    # import name → distribution name
    dist = {"cv2": "opencv-python-headless", "PIL": "pillow", "rerun": "rerun-sdk", "tomli_w": "tomli-w"}
    eager: set[str] = set()
    anywhere: set[str] = set()
    for path in (ROOT / "python" / "gnomon").rglob("*.py"):
        top, every = _imports(path)
        eager |= top
        anywhere |= every

    def third_party(mods: set[str]) -> set[str]:
        return {m for m in mods if m not in sys.stdlib_module_names and m not in ("gnomon", "__future__")}

    assert {"numpy", "cv2", "rerun", "pvlib", "pandas", "pyarrow", "tomli_w"} <= third_party(anywhere)
    missing = {m for m in third_party(eager) if dist.get(m, m).lower() not in required}
    assert not missing, f"imported at module level but not a dependency in pyproject.toml: {sorted(missing)}"
    missing = {m for m in third_party(anywhere) if dist.get(m, m).lower() not in required | extras}
    assert not missing, f"imported but declared in neither the dependencies nor an extra: {sorted(missing)}"


def test_metadata_is_complete() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    for key in ("name", "description", "readme", "requires-python", "license", "license-files", "authors",
                "keywords", "classifiers", "dependencies", "scripts"):
        assert project.get(key), key
    assert "Typing :: Typed" in project["classifiers"] and (ROOT / "python" / "gnomon" / "py.typed").is_file()


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
