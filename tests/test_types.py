"""The type checker runs clean on ``src/pde2cad`` (issue 12, item 7).

mypy runs once, in a subprocess, with the project's ``[tool.mypy]`` configuration from
``pyproject.toml``. Modules listed in ``CLEAN_PACKAGES`` must have no error; once it holds
``"pde2cad"`` itself the whole package must pass and mypy must exit 0.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mypy")

ROOT = Path(__file__).resolve().parents[1]

# The whole package is checked clean: mypy must exit 0 on src/pde2cad.
CLEAN_PACKAGES: tuple[str, ...] = ("pde2cad",)

_ERROR = re.compile(r"^(?P<path>[^:\n]+\.py):\d+(?::\d+)?: error: ", re.MULTILINE)


def _module(path: str) -> str:
    """``src/pde2cad/surfaces/coons.py`` -> ``pde2cad.surfaces.coons``."""
    parts = Path(path).with_suffix("").parts
    parts = parts[parts.index("pde2cad") :]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_clean_module(module: str, packages: tuple[str, ...] = CLEAN_PACKAGES) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


@pytest.fixture(scope="module")
def mypy_run() -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
         "--no-color-output", "--no-error-summary", "src/pde2cad"],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )  # fmt: skip


def test_module_names_from_paths():
    assert _module("src/pde2cad/surfaces/coons.py") == "pde2cad.surfaces.coons"
    assert _module("src/pde2cad/io/__init__.py") == "pde2cad.io"
    assert _is_clean_module("pde2cad.surfaces.coons")
    # a prefix of a name is no match
    assert not _is_clean_module("pde2cad.reconstruct_jobs", ("pde2cad.reconstruct_job",))


@pytest.mark.slow
def test_mypy_clean_on_checked_packages(mypy_run):
    # 1. mypy itself ran: exit 0 (clean) or 1 (errors found), never 2 (crash, bad config).
    assert mypy_run.returncode in (0, 1), mypy_run.stderr + mypy_run.stdout
    # 2. No error in a module declared clean.
    errors = [m.group(0) for m in _ERROR.finditer(mypy_run.stdout)]
    lines = mypy_run.stdout.splitlines()
    dirty = [ln for ln in lines if _ERROR.match(ln) and _is_clean_module(_module(ln.split(":")[0]))]
    assert not dirty, "\n".join(dirty)
    # 3. Every configured module exists, so a rename cannot silently drop it from the check.
    for name in CLEAN_PACKAGES:
        where = ROOT.joinpath("src", *name.split("."))
        assert where.is_dir() or where.with_suffix(".py").is_file(), f"{name} is not in src/"
    # 4. Once the whole package is declared clean, mypy must pass outright.
    if "pde2cad" in CLEAN_PACKAGES:
        assert mypy_run.returncode == 0 and not errors, mypy_run.stdout
