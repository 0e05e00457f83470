"""The CAD side of the public API type-checks: bspline/, occ/ and the package's functions."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mypy")
ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_mypy_is_clean_on_the_cad_modules() -> None:
    # OCP ships no stubs: its names are Any to mypy, ours are checked in full.
    targets = ["src/pde2cad/bspline", "src/pde2cad/occ", "src/pde2cad/__init__.py"]
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--ignore-missing-imports", "--no-incremental", *targets],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:]
