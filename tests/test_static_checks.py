"""Static checks on the checkout's sources: mypy and ruff report nothing.

Both read their configuration from pyproject.toml ([tool.mypy], [tool.ruff]);
both are in the ``test`` extra, so CI runs them through the README's test
command. The sources are the checkout's (``python/gnomon``, ``tests``,
``benchmarks`` beside this folder), not the installed package.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str) -> subprocess.CompletedProcess:
    assert (ROOT / "python" / "gnomon" / "__init__.py").is_file(), f"no checkout at {ROOT}"
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=900)


def test_ruff_reports_nothing():
    p = _run("ruff", "check", "--no-cache", "python/gnomon", "tests", "benchmarks")
    assert p.returncode == 0, p.stdout + p.stderr


@pytest.mark.slow
def test_mypy_reports_nothing(tmp_path):
    # A fresh cache: the result must not depend on an earlier run (a cold run takes ~20-40 s).
    p = _run("mypy", "--cache-dir", str(tmp_path / "mypy_cache"))
    assert p.returncode == 0 and "Success: no issues found" in p.stdout, p.stdout + p.stderr
